//! The realtime module's checks of what it reads from shared memory, on the mock HAL: see
//! `planner/tests/common/channel_play.rs`, shared with the regression tests of its findings.
#![no_main]
use libfuzzer_sys::fuzz_target;

#[path = "../../planner/tests/common/channel_play.rs"]
mod channel_play;

// The plans are made once, before the inputs (they take seconds under the sanitizer and are the
// same for every input).
fuzz_target!(init: { channel_play::plans(); }, |data: &[u8]| channel_play::play(data));
