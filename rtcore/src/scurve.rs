//! Seven-phase jerk-limited feed profile of one segment (paper 000, eq. 15-21 and 28-29).
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
        let mut starts = [0.0; PHASES + 1];
        let mut states = [SCurveState::default(); PHASES + 1];
        states[0] = SCurveState {
            s: 0.0,
            v: self.feed_start,
            a: 0.0,
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
        if t <= 0.0 {
            return self.states[0];
        }
        if t >= self.starts[PHASES] {
            return self.states[PHASES];
        }
        let mut k = 0;
        while k + 1 < PHASES && t >= self.starts[k + 1] {
            k += 1;
        }
        self.states[k].advance(self.profile.jerks[k], t - self.starts[k])
    }
}

#[cfg(test)]
mod tests {
    use super::*;

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
