//! The JSON toolpath reader on any text.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else { return };
    if let Ok(toolpath) = nurbs_motion::readers::json::parse("fuzz.json", text) {
        let _ = nurbs_motion::readers::check_sizes("fuzz.json", &toolpath);
    }
});
