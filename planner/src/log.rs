//! The planners' log lines on stderr. A halfile's `loadusr` programs and `rtapi_app` share one
//! log (halrun's, LinuxCNC's), and Rust's unbuffered stderr writes a formatted line in pieces: a
//! line of another process could land inside one of ours (seen: rtapi_app's "Running with
//! fallback_uid" between "nurbs-planner: " and the rest). Each line here is one write.

use std::io::Write;

/// Writes `line` and a newline to stderr in one `write` call (a failed write is dropped: there
/// is nowhere else to say it).
pub fn line(line: &str) {
    let mut bytes = Vec::with_capacity(line.len() + 1);
    bytes.extend_from_slice(line.as_bytes());
    bytes.push(b'\n');
    let _ = std::io::stderr().lock().write_all(&bytes);
}

/// `eprintln!` as one write ([`line`]).
#[macro_export]
macro_rules! say {
    ($($arg:tt)*) => {
        $crate::log::line(&format!($($arg)*))
    };
}
