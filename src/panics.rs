//! Panics of the userspace programs as errors: a panic anywhere (in a dependency too: a reader
//! library that panics on a malformed file) must not end `nurbs-plan` or `nurbs-planner` with a
//! backtrace and no message a user can act on. [`install`] keeps the message of the last panic
//! instead of printing it; [`catch`] runs a part that may panic and turns a panic into an error
//! carrying that message. Nothing here runs on the servo thread (the realtime module aborts).

use std::panic::{catch_unwind, AssertUnwindSafe};
use std::sync::Mutex;

static LAST: Mutex<Option<String>> = Mutex::new(None);

/// Replaces the panic hook: the message and place of a panic are kept for [`catch`] (and
/// printed by the program that reports it), not written to stderr at once.
pub fn install() {
    std::panic::set_hook(Box::new(|info| {
        let message = info
            .payload()
            .downcast_ref::<&str>()
            .map(|s| s.to_string())
            .or_else(|| info.payload().downcast_ref::<String>().cloned())
            .unwrap_or_else(|| "unknown panic".into());
        let place = info
            .location()
            .map_or(String::new(), |l| format!(" at {}:{}", l.file(), l.line()));
        if let Ok(mut last) = LAST.lock() {
            *last = Some(format!("{message}{place}"));
        }
    }));
}

/// Runs `f`; a panic in it becomes `Err` with the panic's message (as [`install`] kept it).
pub fn catch<T>(f: impl FnOnce() -> T) -> Result<T, String> {
    catch_unwind(AssertUnwindSafe(f)).map_err(|_| take_last().unwrap_or_else(|| "a panic".into()))
}

/// The message of the last panic not reported yet (one in another thread, say), if any.
pub fn take_last() -> Option<String> {
    LAST.lock().ok().and_then(|mut last| last.take())
}
