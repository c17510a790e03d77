//! Any bytes a page can send on an open WebSocket are read with the viewer's own limits and
//! every text message goes through the viewer's command parser: an error or a command, never a
//! panic, and never more memory than the message bound.
#![no_main]

use std::io::{Read, Write};

use tungstenite::protocol::{Role, WebSocket};
use tungstenite::Message;

/// The client's bytes in, the server's replies dropped.
struct Wire(std::io::Cursor<Vec<u8>>);

impl Read for Wire {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        self.0.read(buf)
    }
}

impl Write for Wire {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        Ok(buf.len())
    }
    fn flush(&mut self) -> std::io::Result<()> {
        Ok(())
    }
}

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    let wire = Wire(std::io::Cursor::new(data.to_vec()));
    let mut ws = WebSocket::from_raw_socket(wire, Role::Server, Some(viewer::server::websocket_config()));
    while let Ok(message) = ws.read() {
        if let Message::Text(text) = message {
            let _ = viewer::server::parse_command(text.as_str());
        }
    }
});
