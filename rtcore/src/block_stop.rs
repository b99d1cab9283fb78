//! The module's stop after a path block (VPOp plans: per-period positions), as pure functions:
//! the realtime module runs them on the servo thread and the planner runs the same code to
//! check the stop from every block end.

use crate::records::{PathBlock, SegmentRecord, FLAG_LAST};
use crate::scurve::{stop_from, SCurve, SCurveTable};

/// Distance into a stop profile at which its (falling) feed has come down to `v` (a 60-step
/// bisection).
fn distance_at_feed(table: &SCurveTable, v: f64) -> f64 {
    let (mut lo, mut hi) = (0.0, table.total_time());
    for _ in 0..60 {
        let mid = 0.5 * (lo + hi);
        if table.state_at(mid).v > v {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    table.state_at(hi).s
}

/// Largest ratio of a path-block step's arc length to its chord: a step turns less than a half
/// circle (arc / chord of a semicircle = pi / 2). Only catches arc lengths that do not belong to
/// the positions; the planner's own arc lengths are exact.
const ARC_PER_CHORD: f64 = core::f64::consts::FRAC_PI_2;

/// A step's chord fits its arc length: no longer (to rounding), and not shorter than 2/pi of it.
pub fn step_fits(chord: f64, ds: f64) -> bool {
    chord <= ds * (1.0 + 1e-9) + 1e-9 && ds <= ARC_PER_CHORD * chord + 1e-9
}

/// The state a stop after `block` starts from: arc length, feed and tangential acceleration at
/// its last sample, from the quadratic through its last three arc lengths (backward
/// differences of period `dt`, centred at the last sample).
pub fn block_end_state(block: &PathBlock, dt: f64) -> (f64, f64, f64) {
    let n = block.len() + 1; // index of the last sample in `s_history`
    let (s0, s1, s2) = (
        block.s_history(n),
        block.s_history(n.saturating_sub(1)),
        block.s_history(n.saturating_sub(2)),
    );
    let a = (s0 - 2.0 * s1 + s2) / (dt * dt);
    let v = (3.0 * s0 - 4.0 * s1 + s2) / (2.0 * dt);
    (s0, v, a)
}

/// The stop the module runs after `block` (an underrun, hold or abort at its end): from the
/// block's end state ([`block_end_state`]) to rest along its curve with the block's checked
/// deceleration and jerk, both raised (deceleration by `k`, jerk by `k^2`) just enough to pass
/// every stop point of the curve (`points`, `(s, feed cap)` pairs) no faster than its cap.
/// Returns the stop as a record (start, curve, profile) and its start acceleration (for
/// [`SCurve::table_from`](crate::SCurve::table_from)). Bounded work: for each stop point the
/// stop reaches too fast, a 40-step bisection of `k` with a 60-step bisection inside.
pub fn block_stop(points: &[f64], block: &PathBlock, dt: f64) -> (SegmentRecord, f64) {
    let (s0, v0, a0) = block_end_state(block, dt);
    let (accel, jerk) = (block.stop_accel, block.stop_jerk);
    let profile = |k: f64| stop_from(v0, a0, accel * k, jerk * k * k);
    let reach = profile(1.0).table_from(a0).length();
    let mut k = 1.0f64;
    for pair in points.chunks_exact(2) {
        if let [s, cap] = *pair {
            let d = s - s0;
            let fits = |k: f64| distance_at_feed(&profile(k).table_from(a0), cap) <= 0.999 * d;
            if d > 1e-9 && d < reach && cap < v0 && !fits(k) {
                let (mut lo, mut hi) = (k, k * 2.0);
                for _ in 0..40 {
                    if fits(hi) {
                        break;
                    }
                    lo = hi;
                    hi *= 2.0;
                }
                for _ in 0..40 {
                    let mid = 0.5 * (lo + hi);
                    if fits(mid) {
                        hi = mid;
                    } else {
                        lo = mid;
                    }
                }
                k = hi;
            }
        }
    }
    let last = block.len().saturating_sub(1);
    let u = block.u.get(last).copied().unwrap_or(0.0);
    let from = StopStart {
        seq: block.seq,
        flags: block.flags & !FLAG_LAST,
        curve: block.curve,
        u,
        s: s0,
        feed: v0,
        accel: a0,
    };
    stop_record(&from, accel * k, jerk * k * k)
}

/// Where a stop starts: a sample of a running motion (its element, parameter, arc length, feed
/// and tangential acceleration), and the sequence number and flags its record carries.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StopStart {
    pub seq: u32,
    pub flags: u32,
    pub curve: u32,
    pub u: f64,
    pub s: f64,
    pub feed: f64,
    pub accel: f64,
}

/// The stop from `from` to rest along its element with deceleration `accel` and jerk `jerk`
/// ([`stop_from`]), as a record and its start acceleration (for
/// [`SCurve::table_from`](crate::SCurve::table_from)): what the module runs from a block end or,
/// on a hold, from a checked point inside a segment, and what the planner checks.
pub fn stop_record(from: &StopStart, accel: f64, jerk: f64) -> (SegmentRecord, f64) {
    let a0 = from.accel;
    let p = stop_from(from.feed, a0, accel, jerk);
    (record_from(from, p, a0), if p.feed_start > 0.0 { a0 } else { 0.0 })
}

/// The record of profile `p` run from `from` with start acceleration `a0`: on `from`'s element
/// from its parameter and arc length, as long as the profile runs.
fn record_from(from: &StopStart, p: SCurve, a0: f64) -> SegmentRecord {
    SegmentRecord {
        seq: from.seq,
        flags: from.flags,
        curve: from.curve,
        reserved: 0,
        u_start: from.u,
        u_end: from.u,
        s_start: from.s,
        length: p.table_from(a0).length().max(0.0),
        feed_start: p.feed_start,
        durations: p.durations,
        jerks: p.jerks,
    }
}

/// The change of feed from `from` (a sample of a running motion) to at most `feed`, ending with
/// zero tangential acceleration, along its element: what a plan at another feed override starts
/// with where it cuts into a record that is running (the module runs it from that sample with
/// [`SCurve::table_from`]`(from.accel)`, the planner checked exactly that). Down to `feed` with
/// deceleration `accel` and jerk `jerk` ([`stop_from`] of the difference) where that is below
/// the feed reached by releasing the acceleration at once; otherwise that release alone (jerk
/// `jerk` against the acceleration until it is zero; where that would reverse, the record
/// fails its check). Returns the record and its start acceleration, as [`stop_record`] does.
pub fn ramp_record(from: &StopStart, feed: f64, accel: f64, jerk: f64) -> (SegmentRecord, f64) {
    let (v0, a0) = (from.feed.max(0.0), from.accel);
    let released = v0 + a0 * libm::fabs(a0) / (2.0 * jerk);
    let p = if feed < released && feed < v0 && feed >= 0.0 {
        SCurve {
            feed_start: v0,
            ..stop_from(v0 - feed, a0, accel, jerk)
        }
    } else {
        let mut p = SCurve {
            feed_start: v0,
            ..SCurve::default()
        };
        if a0 != 0.0 && jerk > 0.0 {
            p.durations[0] = libm::fabs(a0) / jerk;
            p.jerks[0] = if a0 > 0.0 { -jerk } else { jerk };
        }
        p
    };
    (record_from(from, p, a0), a0)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A ramp ends at the feed asked for (or, where releasing the acceleration already ends
    /// below it, at that release's feed) with zero acceleration, and passes its own record check.
    #[test]
    fn a_ramp_ends_at_its_feed_with_zero_acceleration() {
        let (a, j) = (1.0e4, 6.0e4);
        for v0 in [1.0, 50.0, 400.0] {
            for a0 in [-3.0e3, -100.0, 0.0, 100.0, 3.0e3] {
                for feed in [0.0, 0.1 * v0, 0.5 * v0, v0, 2.0 * v0] {
                    let from = StopStart {
                        seq: 7,
                        flags: 0,
                        curve: 2,
                        u: 0.25,
                        s: 3.0,
                        feed: v0,
                        accel: a0,
                    };
                    let (r, a_start) = ramp_record(&from, feed, a, j);
                    assert_eq!(a_start, a0);
                    let end = r.profile().table_from(a0).end();
                    let released = v0 + a0 * a0.abs() / (2.0 * j);
                    if released < 0.0 {
                        // Releasing at once reverses: no ramp (the planner's check refuses it).
                        assert!(r.check_from(a0).is_err());
                        continue;
                    }
                    let expected = if feed < released && feed < v0 { feed } else { released };
                    let what = format!("v0 {v0} a0 {a0} feed {feed}");
                    assert!(
                        (end.v - expected).abs() < 1e-9 * (1.0 + v0),
                        "{what}: end feed {}",
                        end.v
                    );
                    assert!(end.a.abs() < 1e-6 * (1.0 + a0.abs()), "{what}: end accel {}", end.a);
                    assert!(r.jerks.iter().all(|x| x.abs() <= j * (1.0 + 1e-12)), "{what}");
                    assert_eq!(r.check_from(a0), Ok(()), "{what}");
                }
            }
        }
    }
}
