//! Any text decodes to a lab, grid or parameters file or to an error with its position, and
//! a lab that decodes builds a world or is refused, never a panic.
#![no_main]
libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else { return };
    if let Ok(world::map::xml::MapFile::Lab(lab)) = world::map::xml::parse_any(text) {
        let _ = world::World::new(&lab, world::map::Params::default(), 0);
    }
});
