//! Any bytes on a viewer's port decode to a command or an error, never a panic.
#![no_main]
libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    let _ = udp_bridge::codec::decode_viewer(data);
});
