//! Any text decodes to a lab, grid or parameters file or to an error with its position, and
//! a lab that decodes builds a world or is refused, never a panic.
#![no_main]
libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else { return };
    if let Ok(hub::map::xml::MapFile::Lab(lab)) = hub::map::xml::parse_any(text) {
        let _ = hub::world::World::new(&lab, hub::map::Params::default(), 0);
    }
});
