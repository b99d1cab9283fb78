//! Seven-phase jerk-limited feed profile of one segment (Erwinski et al. 2022, eq. 15-21 and 28-29).
//!
//! The profile is stored as plain phase durations and constant phase jerks, starting at feed
//! `feed_start` with zero tangential acceleration. The printed eq. 28 mislabels its last two
//! phases; here every phase is integrated from the exact state at its start, so there is no
//! table of closed forms to get wrong.

/// Number of phases: jerk up, constant acceleration, jerk down, cruise, and the mirror image.
pub const PHASES: usize = 7;

/// Phase durations (s) and phase jerks (mm/s^3) of one segment, starting at `feed_start`.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct SCurve {
    pub feed_start: f64,
    pub durations: [f64; PHASES],
    pub jerks: [f64; PHASES],
}

/// Path state along a profile: distance from the segment start, feed, tangential acceleration
/// and jerk.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct SCurveState {
    pub s: f64,
    pub v: f64,
    pub a: f64,
    pub j: f64,
}

impl SCurveState {
    /// State after moving `t` seconds at constant jerk `j` from `self`.
    #[inline]
    pub fn advance(&self, j: f64, t: f64) -> SCurveState {
        SCurveState {
            s: self.s + t * (self.v + t * (self.a / 2.0 + t * j / 6.0)),
            v: self.v + t * (self.a + t * j / 2.0),
            a: self.a + t * j,
            j,
        }
    }
}

/// A profile with the state at every phase boundary precomputed, for O(1) evaluation.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct SCurveTable {
    pub profile: SCurve,
    /// Time at the start of each phase; `starts[7]` is the total duration.
    pub starts: [f64; PHASES + 1],
    /// State at the start of each phase; `states[7]` is the end state.
    pub states: [SCurveState; PHASES + 1],
}

impl SCurve {
    /// Symmetric-shape profile: jerk `+ja, 0, -ja` while accelerating, `-jd, 0, +jd` while
    /// decelerating (the paper's Fig. 2).
    pub fn from_phases(feed_start: f64, durations: [f64; PHASES], jerk_acc: f64, jerk_dec: f64) -> Self {
        SCurve {
            feed_start,
            durations,
            jerks: [jerk_acc, 0.0, -jerk_acc, 0.0, -jerk_dec, 0.0, jerk_dec],
        }
    }

    pub fn total_time(&self) -> f64 {
        self.durations.iter().sum()
    }

    pub fn table(&self) -> SCurveTable {
        self.table_from(0.0)
    }

    /// The table of this profile started with tangential acceleration `accel_start` instead of
    /// zero (a stop from the middle of a motion whose acceleration is not zero).
    pub fn table_from(&self, accel_start: f64) -> SCurveTable {
        let mut starts = [0.0; PHASES + 1];
        let mut states = [SCurveState::default(); PHASES + 1];
        states[0] = SCurveState {
            s: 0.0,
            v: self.feed_start,
            a: accel_start,
            j: self.jerks[0],
        };
        for k in 0..PHASES {
            starts[k + 1] = starts[k] + self.durations[k];
            states[k + 1] = states[k].advance(self.jerks[k], self.durations[k]);
        }
        states[PHASES].j = 0.0;
        SCurveTable {
            profile: *self,
            starts,
            states,
        }
    }
}

impl SCurveTable {
    pub fn total_time(&self) -> f64 {
        self.starts[PHASES]
    }
    pub fn length(&self) -> f64 {
        self.states[PHASES].s
    }
    pub fn end(&self) -> SCurveState {
        self.states[PHASES]
    }

    /// State at time `t` from the segment start; clamped to `[0, total_time]`.
    #[inline]
    pub fn state_at(&self, t: f64) -> SCurveState {
        self.state_at_from(t, &mut 0)
    }

    /// [`SCurveTable::state_at`] for times that do not decrease from call to call: the search
    /// for the phase starts at `phase` (0 at first) and leaves it there for the next call.
    #[inline]
    pub fn state_at_from(&self, t: f64, phase: &mut usize) -> SCurveState {
        if t <= 0.0 {
            return self.states[0];
        }
        if t >= self.starts[PHASES] {
            return self.states[PHASES];
        }
        let mut k = *phase;
        while k + 1 < PHASES && t >= self.starts[k + 1] {
            k += 1;
        }
        *phase = k;
        self.states[k].advance(self.profile.jerks[k], t - self.starts[k])
    }
}

/// Jerk-limited stop from feed `v0` and tangential acceleration `a0` to rest: jerk `-jerk` until
/// the deceleration reaches its peak (at most `accel`), constant deceleration, jerk `+jerk` back
/// to zero acceleration as the feed reaches zero. Returns the profile (phases 0-2, run with
/// [`SCurve::table_from`]`(a0)`). Where even releasing at once would cross zero feed (already
/// braking harder than `jerk` can release), the release jerk is raised to `a0^2 / (2 v0)`:
/// the only stop without reversing. No feed: a stop of zero length.
pub fn stop_from(v0: f64, a0: f64, accel: f64, jerk: f64) -> SCurve {
    let mut p = SCurve {
        feed_start: v0.max(0.0),
        ..SCurve::default()
    };
    let (v0, a0) = (v0.max(0.0), if v0 > 0.0 { a0 } else { 0.0 });
    if !(v0 > 0.0 && accel > 0.0 && jerk > 0.0 && a0.is_finite() && v0.is_finite()) {
        return p;
    }
    // Feed reached if the acceleration were released to zero from a0 with jerk `jerk` (a0 < 0).
    let peak = libm::sqrt(jerk * v0 + 0.5 * a0 * a0);
    if a0 < 0.0 && v0 - a0 * a0 / (2.0 * jerk) <= 0.0 {
        let j = a0 * a0 / (2.0 * v0);
        p.durations[2] = -a0 / j;
        p.jerks[2] = j;
        return p;
    }
    let x = peak.min(accel).max(-a0.min(0.0));
    let t1 = (a0 + x) / jerk;
    let t3 = x / jerk;
    // Feed left after the two ramps; the rest is covered at constant deceleration x.
    let rest = v0 + (a0 * a0 - x * x) / (2.0 * jerk) - x * x / (2.0 * jerk);
    let t2 = if x > 0.0 { (rest / x).max(0.0) } else { 0.0 };
    p.durations[0] = t1.max(0.0);
    p.durations[1] = t2;
    p.durations[2] = t3;
    p.jerks[0] = -jerk;
    p.jerks[2] = jerk;
    p
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The stop from a non-zero acceleration ends at rest with zero acceleration, its feed never
    /// negative, within the deceleration and jerk it was given.
    #[test]
    fn stop_from_any_acceleration_ends_at_rest() {
        let (a, j) = (1.0e4, 6.0e4);
        for v0 in [0.01, 1.0, 50.0, 400.0, 2500.0] {
            for a0 in [-9.0e3, -3.0e3, -100.0, 0.0, 100.0, 3.0e3, 9.0e3] {
                let p = stop_from(v0, a0, a, j);
                let t = p.table_from(a0);
                let end = t.end();
                assert!(end.v.abs() < 1e-9 * (1.0 + v0), "v0 {v0} a0 {a0}: end feed {}", end.v);
                assert!(
                    end.a.abs() < 1e-6 * (1.0 + a0.abs()),
                    "v0 {v0} a0 {a0}: end accel {}",
                    end.a
                );
                let n = 2000;
                for k in 0..=n {
                    let st = t.state_at(t.total_time() * k as f64 / n as f64);
                    assert!(st.v >= -1e-9 * (1.0 + v0), "v0 {v0} a0 {a0}: feed {}", st.v);
                    assert!(
                        st.a >= -a * (1.0 + 1e-12) || st.a >= a0 - 1e-9,
                        "v0 {v0} a0 {a0}: accel {}",
                        st.a
                    );
                }
                assert!(p.jerks.iter().all(|x| x.abs() <= j * (1.0 + 1e-12)) || a0 * a0 / (2.0 * v0) > j);
            }
        }
        // Zero feed: nothing to do.
        assert_eq!(stop_from(0.0, 5.0, a, j).table().total_time(), 0.0);
    }

    /// For times that do not decrease, a phase cursor carried from call to call gives exactly
    /// what the search from the first phase gives, zero-length phases and times past the end
    /// included.
    #[test]
    fn state_at_from_a_phase_cursor_is_state_at() {
        let (j, a) = (6.0e4, 1.0e4);
        let t1 = a / j;
        let p = SCurve::from_phases(10.0, [t1, 0.0, t1, 0.05, 0.5 * t1, 0.0, 2.0 * t1], j, j);
        let tab = p.table();
        let mut phase = 0;
        let n = 997;
        for k in 0..=n + 3 {
            let t = tab.total_time() * k as f64 / n as f64;
            assert_eq!(tab.state_at_from(t, &mut phase), tab.state_at(t), "t = {t}");
        }
    }

    #[test]
    fn symmetric_profile_reaches_peak_and_returns() {
        let (j, a) = (6.0e4, 1.0e4);
        let t1 = a / j;
        let p = SCurve::from_phases(10.0, [t1, 0.1, t1, 0.2, t1, 0.1, t1], j, j);
        let tab = p.table();
        let end = tab.end();
        assert!((end.v - 10.0).abs() < 1e-9, "end feed {}", end.v);
        assert!(end.a.abs() < 1e-9);
        let peak = tab.states[3];
        assert!((peak.v - (10.0 + a * t1 + a * 0.1)).abs() < 1e-9);
        // Continuity across every phase boundary.
        for k in 1..PHASES {
            let before = tab.state_at(tab.starts[k] - 1e-12);
            let after = tab.state_at(tab.starts[k] + 1e-12);
            assert!(
                (before.s - after.s).abs() < 1e-8 && (before.v - after.v).abs() < 1e-6,
                "phase {k}"
            );
        }
    }
}
