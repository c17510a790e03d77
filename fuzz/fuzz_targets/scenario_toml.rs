//! Any text as a scenario file gives a scenario or an error naming what is wrong, never a panic.
#![no_main]
libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else { return };
    let _ = runner::scenario::Scenario::parse(text, "fuzz.toml", std::path::Path::new("."));
});
