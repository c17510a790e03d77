//! The serial port, behind one module so that replacing the `serialport` crate touches one
//! file: opening it raw at 8N1 without flow control, writing frames with the host's sequence
//! numbers, and reading whatever bytes have arrived into the protocol's [`Decoder`] without
//! ever waiting.

use std::io::{self, Read as _, Write as _};
use std::os::fd::{AsRawFd as _, RawFd};
use std::path::{Path, PathBuf};
use std::time::Duration;

use serial_protocol::{Decoder, DecoderStats, Frame, FrameDecodeError, MAX_ENCODED_LEN, Message, encode};
use serialport::{DataBits, FlowControl, Parity, StopBits, TTYPort};

/// Why a serial port could not be opened.
#[derive(Debug, thiserror::Error)]
#[error("cannot open serial port {path}: {source}")]
pub struct PortOpenError {
    /// The device path.
    pub path: PathBuf,
    /// What the system said.
    pub source: serialport::Error,
}

/// An open serial port speaking the protocol.
#[derive(Debug)]
pub struct Port {
    port: TTYPort,
    /// The host's sequence number: one counter for everything sent on this port, from 0.
    seq: u8,
    decoder: Decoder,
}

impl Port {
    /// Opens `path` at `baud` (8N1, no flow control, raw). A pty's slave side opens like any
    /// port. Reads and writes never wait: what cannot be done at once is not done.
    pub fn open(path: &Path, baud: u32) -> Result<Port, PortOpenError> {
        let path_text = path.to_string_lossy();
        let port = serialport::new(path_text, baud)
            .data_bits(DataBits::Eight)
            .parity(Parity::None)
            .stop_bits(StopBits::One)
            .flow_control(FlowControl::None)
            // The wait before each read and write: none, so the tick loop never blocks.
            .timeout(Duration::ZERO)
            .open_native()
            .map_err(|source| PortOpenError { path: path.to_owned(), source })?;
        Ok(Port { port, seq: 0, decoder: Decoder::new() })
    }

    /// The port's file descriptor, for `poll(2)`.
    pub fn fd(&self) -> RawFd {
        self.port.as_raw_fd()
    }

    /// Sends one message with the next sequence number, which it returns. `Ok(None)` when the
    /// port's output buffer is full (nothing is queued: the next tick sends afresh); an error
    /// means the port is gone.
    pub fn send(&mut self, message: &Message) -> io::Result<Option<u8>> {
        let mut wire = [0u8; MAX_ENCODED_LEN];
        let n = encode(message, self.seq, &mut wire)
            .map_err(|e| io::Error::new(io::ErrorKind::InvalidInput, format!("cannot encode {message:?}: {e}")))?;
        match self.port.write_all(&wire[..n]) {
            Ok(()) => {}
            Err(e) if matches!(e.kind(), io::ErrorKind::TimedOut | io::ErrorKind::WouldBlock) => return Ok(None),
            Err(e) => return Err(e),
        }
        let seq = self.seq;
        self.seq = self.seq.wrapping_add(1);
        Ok(Some(seq))
    }

    /// Reads what has arrived (without waiting) and decodes it, calling `on_frame` for each
    /// frame or refused chunk. An error means the port is gone (a hang-up, an I/O error, end of
    /// file).
    pub fn receive(&mut self, mut on_frame: impl FnMut(Result<Frame, FrameDecodeError>)) -> io::Result<()> {
        let mut buf = [0u8; 1024];
        // Bounded, so a board flooding the line cannot keep the loop from the hub.
        for _ in 0..16 {
            match self.port.read(&mut buf) {
                Ok(0) => return Err(io::Error::new(io::ErrorKind::UnexpectedEof, "end of file")),
                Ok(n) => {
                    self.decoder.feed(&buf[..n], &mut on_frame);
                    if n < buf.len() {
                        return Ok(());
                    }
                }
                Err(e) if matches!(e.kind(), io::ErrorKind::TimedOut | io::ErrorKind::WouldBlock) => return Ok(()),
                Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
                Err(e) => return Err(e),
            }
        }
        Ok(())
    }

    /// What this port's decoder has seen.
    pub fn stats(&self) -> DecoderStats {
        *self.decoder.stats()
    }
}

/// Waits up to `timeout` for any of `fds` (negative entries are skipped) to become readable
/// or hang up; returns at once when one is.
pub fn wait_readable(fds: &[RawFd], timeout: Duration) {
    // Whatever woke it (or a failed wait), the caller looks at every source next.
    let _ = os::poll::Poller::default().wait(fds, Some(timeout));
}

/// Adds `b`'s counters to `a`'s (a port's decoder ends with its port; the adapter's totals
/// go on).
pub fn add_stats(a: &mut DecoderStats, b: &DecoderStats) {
    for (x, y) in [
        (&mut a.frames, b.frames),
        (&mut a.oversize, b.oversize),
        (&mut a.malformed, b.malformed),
        (&mut a.crc_errors, b.crc_errors),
        (&mut a.bad_version, b.bad_version),
        (&mut a.unknown_type, b.unknown_type),
        (&mut a.bad_length, b.bad_length),
        (&mut a.invalid_field, b.invalid_field),
        (&mut a.missed, b.missed),
    ] {
        *x = x.saturating_add(y);
    }
}
