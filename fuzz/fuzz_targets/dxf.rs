//! The DXF reader (and the dxf library under it) on any bytes.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    // The reader contains the dxf library's panics (a read error); only a panic that escapes
    // it is a finding: libFuzzer's hook would abort on the contained ones too.
    static HOOK: std::sync::Once = std::sync::Once::new();
    HOOK.call_once(nurbs_motion::panics::install);
    if let Ok(toolpath) = nurbs_motion::readers::dxf::parse("fuzz.dxf", data) {
        let _ = nurbs_motion::readers::check_sizes("fuzz.dxf", &toolpath);
    }
});
