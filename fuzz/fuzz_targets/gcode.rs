//! The G-code reader on any text, streamed as `nurbs-plan` and `nurbs-planner` read a file: a
//! line at a time, each element checked for its sizes, the corners of its G1 runs rounded as
//! they come.
#![no_main]
use libfuzzer_sys::fuzz_target;
use nurbs_motion::planner::corner::CornerRounder;
use nurbs_motion::readers::{check_element, gcode::GcodeStream};

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else { return };
    let lines = text.lines().map(|l| Ok(l.to_owned()));
    let mut index = 0;
    let checked = GcodeStream::new("fuzz.ngc", lines).map(|e| {
        let e = e?;
        check_element("fuzz.ngc", index, &e)?;
        index += 1;
        Ok(e)
    });
    let Ok(rounded) = CornerRounder::new("fuzz.ngc", checked, 0.001, false) else { return };
    for element in rounded {
        if element.is_err() {
            break;
        }
    }
});
