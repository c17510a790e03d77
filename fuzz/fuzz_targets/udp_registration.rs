//! Any bytes on the registration port decode to a registration or an error, never a panic.
#![no_main]
libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    let _ = udp_bridge::codec::decode_registration(data);
});
