//! Machine limits a plan must respect.

use std::fmt;

/// Feed, per-axis velocity/acceleration/jerk limits, chord tolerance and servo period
/// (units mm and s). Axis vectors are in machine axis order (x, y, z, ...).
#[derive(Clone, Debug, PartialEq)]
pub struct Limits {
    /// Programmed feed cap F (mm/s).
    pub feed: f64,
    pub velocity: Vec<f64>,
    pub acceleration: Vec<f64>,
    pub jerk: Vec<f64>,
    /// Maximum chord error between consecutive setpoints (mm).
    pub chord_tolerance: f64,
    /// Interpolation (servo) period (s).
    pub period: f64,
    /// Share of every axis' jerk limit the Erwinski planner leaves unused (0 <= r < 1), so that
    /// a hold can brake at once where the plan would otherwise ride an axis' jerk limit through
    /// the curvature; the stops and every check keep the full limits ([`Limits::planned`]).
    pub hold_reserve: f64,
}

/// A limit set that cannot be planned with.
#[derive(Clone, Debug, PartialEq)]
pub struct LimitsError(pub String);

impl fmt::Display for LimitsError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "invalid limits: {}", self.0)
    }
}
impl std::error::Error for LimitsError {}

impl Limits {
    /// Limits with the same velocity (= feed), acceleration and jerk on every axis.
    pub fn uniform(axes: usize, feed: f64, accel: f64, jerk: f64, chord_tolerance: f64, period: f64) -> Self {
        Limits {
            feed,
            velocity: vec![feed; axes],
            acceleration: vec![accel; axes],
            jerk: vec![jerk; axes],
            chord_tolerance,
            period,
            hold_reserve: 0.0,
        }
    }

    /// Checks every number is finite and positive and that there is one value per axis
    /// (a single value is spread over all axes).
    pub fn for_axes(&self, axes: usize) -> Result<Limits, LimitsError> {
        let spread = |name: &str, v: &[f64]| -> Result<Vec<f64>, LimitsError> {
            let v = match v.len() {
                1 => vec![v[0]; axes],
                n if n == axes => v.to_vec(),
                n => return Err(LimitsError(format!("{n} {name} values for {axes} axes"))),
            };
            if let Some(bad) = v.iter().find(|x| !(x.is_finite() && **x > 0.0)) {
                return Err(LimitsError(format!("{name} {bad} must be a finite number > 0")));
            }
            Ok(v)
        };
        for (name, x) in [
            ("feed", self.feed),
            ("chord tolerance", self.chord_tolerance),
            ("period", self.period),
        ] {
            if !(x.is_finite() && x > 0.0) {
                return Err(LimitsError(format!("{name} {x} must be a finite number > 0")));
            }
        }
        if !(0.0..1.0).contains(&self.hold_reserve) {
            return Err(LimitsError(format!(
                "hold reserve {} must be at least 0 and below 1",
                self.hold_reserve
            )));
        }
        Ok(Limits {
            feed: self.feed,
            velocity: spread("velocity", &self.velocity)?,
            acceleration: spread("acceleration", &self.acceleration)?,
            jerk: spread("jerk", &self.jerk)?,
            chord_tolerance: self.chord_tolerance,
            period: self.period,
            hold_reserve: self.hold_reserve,
        })
    }

    /// The limits a plan is made within: every axis' jerk less the hold reserve (the limits
    /// themselves where it is 0).
    pub fn planned(&self) -> Limits {
        if self.hold_reserve == 0.0 {
            return self.clone();
        }
        Limits {
            jerk: self.jerk.iter().map(|j| j * (1.0 - self.hold_reserve)).collect(),
            hold_reserve: 0.0,
            ..self.clone()
        }
    }

    /// Smallest acceleration and jerk over the axes: the tangential values a plan starts from
    /// (any direction can be taken at these without exceeding an axis).
    pub fn min_accel(&self) -> f64 {
        self.acceleration.iter().copied().fold(f64::INFINITY, f64::min)
    }
    pub fn min_jerk(&self) -> f64 {
        self.jerk.iter().copied().fold(f64::INFINITY, f64::min)
    }

    /// Tangential acceleration and jerk the axes allow along `direction` (of any length, one
    /// entry per tool-tip axis): each axis sees its share of them, so the axis that runs out
    /// first sets them. Never below [`Self::min_accel`] and [`Self::min_jerk`].
    pub fn along(&self, direction: &[f64]) -> (f64, f64) {
        let norm = direction.iter().map(|x| x * x).sum::<f64>().sqrt();
        let (mut accel, mut jerk) = (f64::INFINITY, f64::INFINITY);
        for ((d, a), j) in direction.iter().zip(&self.acceleration).zip(&self.jerk) {
            let share = if norm > 0.0 { (d / norm).abs() } else { 1.0 };
            if share > 0.0 {
                accel = accel.min(a / share);
                jerk = jerk.min(j / share);
            }
        }
        (accel.max(self.min_accel()), jerk.max(self.min_jerk()))
    }
}
