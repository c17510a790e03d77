//! Any bytes on a robot's port decode to actions or an error, never a panic; decoded actions
//! map onto the hub's registration without panicking either.
#![no_main]
libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    let _ = udp_bridge::codec::decode_actions(data);
    if let Ok(udp_bridge::codec::Registration::Robot(r)) = udp_bridge::codec::decode_registration(data) {
        let _ = udp_bridge::server::hub_registration(&r, 50, 0.0);
    }
});
