//! Axial limit check by finite differences of sampled positions, exactly as a user measures it:
//! v_j = (q_j - q_{j-1})/dt, a_j = (v_j - v_{j-1})/dt, jerk_j = (a_j - a_{j-1})/dt, with the
//! machine at rest before the first sample and after the last.
//!
//! The planner checks every segment with this code on the samples the realtime interpolator
//! will produce, and `nurbs-plan verify` runs it on the CSV; one implementation for both.

use super::Limits;

/// Largest axis count checked (x, y, z, a, c).
pub const MAX_AXES: usize = 6;

/// Peak |v|, |a|, |jerk| seen per axis and the paper's summed violations (eq. 22-23).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct AxialPeaks {
    pub vel: [f64; MAX_AXES],
    pub acc: [f64; MAX_AXES],
    pub jerk: [f64; MAX_AXES],
    /// Path speed: the norm of the axis velocities (what `verify` compares with the feed).
    pub feed: f64,
    /// Sum over samples and axes of the relative excess of acceleration / jerk (eq. 22-23,
    /// positive parts only; eq. 23's last term is divided by the Y jerk limit, not acceleration).
    pub acc_violation: f64,
    pub jerk_violation: f64,
    pub vel_violation: f64,
    pub samples: usize,
    /// The largest acceleration or jerk ratio to its limit of any sample and axis, and the path
    /// speed at that sample: whether an excess comes with the highest feed of a profile tells
    /// a lower peak from a gentler ramp as its cure.
    pub worst_ramp_ratio: f64,
    pub speed_at_worst: f64,
}

/// Rolling finite differences over a stream of positions.
#[derive(Clone, Copy, Debug)]
pub struct FiniteDifferences {
    axes: usize,
    dt: f64,
    /// Last three positions, newest last; before the first sample they repeat it (at rest).
    history: [[f64; MAX_AXES]; 3],
    started: bool,
    pub peaks: AxialPeaks,
}

impl FiniteDifferences {
    pub fn new(axes: usize, dt: f64) -> Self {
        FiniteDifferences {
            axes: axes.min(MAX_AXES),
            dt,
            history: [[0.0; MAX_AXES]; 3],
            started: false,
            peaks: AxialPeaks::default(),
        }
    }

    /// Adds the next sampled position and updates the peaks against `limits`.
    pub fn push(&mut self, q: &[f64], limits: &Limits) {
        let n = self.axes;
        let mut p = [0.0; MAX_AXES];
        p[..n].copy_from_slice(&q[..n]);
        if !self.started {
            self.history = [p; 3];
            self.started = true;
        }
        let [q3, q2, q1] = self.history;
        let dt = self.dt;
        let mut speed2 = 0.0;
        let mut ramp_ratio: f64 = 0.0;
        for i in 0..n {
            let v0 = (p[i] - q1[i]) / dt;
            speed2 += v0 * v0;
            let v1 = (q1[i] - q2[i]) / dt;
            let v2 = (q2[i] - q3[i]) / dt;
            let a0 = (v0 - v1) / dt;
            let a1 = (v1 - v2) / dt;
            let j0 = (a0 - a1) / dt;
            let pk = &mut self.peaks;
            pk.vel[i] = pk.vel[i].max(v0.abs());
            pk.acc[i] = pk.acc[i].max(a0.abs());
            pk.jerk[i] = pk.jerk[i].max(j0.abs());
            let (acc_ratio, jerk_ratio) = (a0.abs() / limits.acceleration[i], j0.abs() / limits.jerk[i]);
            pk.vel_violation += (v0.abs() / limits.velocity[i] - 1.0).max(0.0);
            pk.acc_violation += (acc_ratio - 1.0).max(0.0);
            pk.jerk_violation += (jerk_ratio - 1.0).max(0.0);
            ramp_ratio = ramp_ratio.max(acc_ratio).max(jerk_ratio);
        }
        let speed = speed2.sqrt();
        if ramp_ratio > self.peaks.worst_ramp_ratio {
            self.peaks.worst_ramp_ratio = ramp_ratio;
            self.peaks.speed_at_worst = speed;
        }
        self.peaks.feed = self.peaks.feed.max(speed);
        self.peaks.samples += 1;
        self.history = [q2, q1, p];
    }

    /// The machine stays at the last position: three more samples close the differences.
    pub fn finish(&mut self, limits: &Limits) {
        let last = self.history[2];
        for _ in 0..3 {
            self.push(&last, limits);
        }
    }

    /// Largest ratio of a measured peak to its limit over all axes.
    pub fn worst_ratio(&self, limits: &Limits) -> f64 {
        let pk = &self.peaks;
        (0..self.axes)
            .map(|i| {
                (pk.vel[i] / limits.velocity[i])
                    .max(pk.acc[i] / limits.acceleration[i])
                    .max(pk.jerk[i] / limits.jerk[i])
            })
            .fold(0.0, f64::max)
    }

    /// Resets the peaks (not the history) to measure the next stretch on its own.
    pub fn reset_peaks(&mut self) {
        self.peaks = AxialPeaks::default();
    }
}
