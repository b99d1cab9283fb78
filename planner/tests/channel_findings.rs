//! Findings of the fuzz target `channel` (fuzz/), replayed on stable by the same harness: each
//! input as libFuzzer wrote it.

#[path = "common/channel_play.rs"]
mod channel_play;

/// A slot byte and the top byte of an arena value changed (the fuzzer's first finding): the
/// interpolator met a record that no longer fits its curve and produced positions that are not
/// numbers, and the module wrote them to its pins. It now faults (`NonFinite`) and holds its
/// last finite position.
#[test]
fn a_record_that_does_not_fit_its_curve_faults_instead_of_writing_nan() {
    channel_play::play(&[0, 243, 177, 85, 38, 166, 223, 11, 38, 38, 255]);
}
