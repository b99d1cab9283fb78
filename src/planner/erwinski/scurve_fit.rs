//! Fitting a seven-phase S-curve between two feeds over a given distance (Erwinski et al. 2022, eq. 15-21).

use super::tuning::*;
use nurbs_rtcore::scurve::{SCurve, PHASES};

/// Durations (T1, T2, T3) of a jerk-limited change of feed by `dv >= 0`: trapezoidal
/// acceleration when `dv >= A^2/J` (eq. 15-17), triangular otherwise (eq. 18-19). A ramp may
/// have a jerk of its own for its first and last phase: the acceleration builds up at
/// `start_jerk` and falls back to zero at `end_jerk`; those two phases change the feed by
/// `a^2 / 2 (1 / start_jerk + 1 / end_jerk)` at peak acceleration `a`.
pub fn ramp_times(dv: f64, ramp: Ramp) -> [f64; 3] {
    if dv <= 0.0 {
        return [0.0; 3];
    }
    let (accel, j1, j3) = (ramp.accel, ramp.start_jerk, ramp.end_jerk);
    if j1 == j3 {
        // The paper's symmetric forms, so that symmetric ramps keep their rounding.
        return if dv * j1 >= accel * accel {
            let t1 = accel / j1;
            [t1, dv / accel - t1, t1]
        } else {
            let t1 = (dv / j1).sqrt();
            [t1, 0.0, t1]
        };
    }
    let compliance = 0.5 * (1.0 / j1 + 1.0 / j3);
    if dv >= accel * accel * compliance {
        [accel / j1, dv / accel - accel * compliance, accel / j3]
    } else {
        let peak = (dv / compliance).sqrt();
        [peak / j1, 0.0, peak / j3]
    }
}

/// Distance covered while changing feed from `va` to `vb` with one jerk (mean feed times
/// duration).
pub fn ramp_distance(va: f64, vb: f64, accel: f64, jerk: f64) -> f64 {
    ramp_distance_with(va, vb, Ramp::new(accel, jerk))
}

/// Distance covered by `ramp` from feed `va` to `vb` (either way; `start_jerk` acts first).
pub fn ramp_distance_with(va: f64, vb: f64, ramp: Ramp) -> f64 {
    let t = ramp_times((vb - va).abs(), ramp);
    let mean = 0.5 * (va + vb) * (t[0] + t[1] + t[2]);
    if ramp.start_jerk == ramp.end_jerk {
        return mean;
    }
    // The mean feed times the duration is off by dv (T/2 - c), c the centroid in time of the
    // trapezoidal acceleration of peak a: a ((t3^2 - t1^2) / 12 + t2 (t3 - t1) / 4), zero for
    // a symmetric ramp; added rising, subtracted falling.
    let a = t[0] * ramp.start_jerk;
    let skew = a * ((t[2] * t[2] - t[0] * t[0]) / 12.0 + t[1] * (t[2] - t[0]) / 4.0);
    if vb >= va {
        mean + skew
    } else {
        mean - skew
    }
}

/// Highest feed reachable from `v_from` within `length` (also: the highest feed from which
/// `v_from` can be reached) with the symmetric ramp of `accel` and `jerk`: the root of the
/// monotone ramp distance, in closed form (a cubic without a constant-acceleration phase, a
/// quadratic with one), then stepped down by ulps until its distance fits `length`. The
/// look-ahead calls it for every node a few times per window; a 60-step bisection was most of
/// the planning time on dense G1 programs.
pub fn reachable_feed(v_from: f64, length: f64, accel: f64, jerk: f64, cap: f64) -> f64 {
    if ramp_distance(v_from, cap, accel, jerk) <= length {
        return cap;
    }
    let plain = v_from >= 0.0 && cap > v_from && length >= 0.0 && accel > 0.0 && jerk > 0.0;
    if !(plain && (v_from + cap + length + accel + jerk).is_finite()) {
        return reachable_by_bisection(v_from, length, accel, jerk, cap);
    }
    // No constant acceleration: d = (2 v0 + x^2) x / sqrt(J) with x = sqrt(v - v0), so
    // x^3 + 2 v0 x - L sqrt(J) = 0 (one real root, the cubic rising): Cardano, then Newton.
    let (p, q) = (2.0 * v_from, -length * jerk.sqrt());
    let root = (q * q / 4.0 + p * p * p / 27.0).sqrt();
    let mut x = (-q / 2.0 + root).cbrt() - (q / 2.0 + root).cbrt();
    for _ in 0..3 {
        x -= (x * x * x + p * x + q) / (3.0 * x * x + p);
    }
    let mut v = v_from + x * x;
    if (v - v_from) * jerk > accel * accel {
        // With a constant-acceleration phase: d = (v^2 - v0^2) / (2A) + (v0 + v) A / (2J),
        // a quadratic in v.
        let b = accel * accel / jerk;
        let c = v_from * b - v_from * v_from - 2.0 * accel * length;
        v = 0.5 * (-b + (b * b - 4.0 * c).sqrt());
    }
    let mut v = v.clamp(v_from, cap);
    for _ in 0..64 {
        if v <= v_from || ramp_distance(v_from, v, accel, jerk) <= length {
            return v;
        }
        v = f64::from_bits(v.to_bits() - 1);
    }
    reachable_by_bisection(v_from, length, accel, jerk, cap)
}

/// [`reachable_feed`] by bisection on the ramp distance (for arguments outside its closed
/// form's: a cap below the start feed, non-finite values).
fn reachable_by_bisection(v_from: f64, length: f64, accel: f64, jerk: f64, cap: f64) -> f64 {
    let (mut lo, mut hi) = (v_from, cap);
    for _ in 0..60 {
        let mid = 0.5 * (lo + hi);
        if ramp_distance(v_from, mid, accel, jerk) <= length {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    lo
}

/// Why no profile fits.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum FitError {
    /// Even without any cruise the change from start to end feed needs more than the length.
    TooShort,
}

/// Acceleration and jerks of one ramp of a profile (rise to the peak or fall from it).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Ramp {
    pub accel: f64,
    /// Jerk of the ramp's first phase (phase 1 of the rise, 5 of the fall) and its last (3, 7).
    pub start_jerk: f64,
    pub end_jerk: f64,
}

impl Ramp {
    /// The paper's ramp: one jerk for both phases.
    pub fn new(accel: f64, jerk: f64) -> Self {
        Ramp {
            accel,
            start_jerk: jerk,
            end_jerk: jerk,
        }
    }
}

/// Profile from `v0` to `v1` over `length` with peak feed at most `v_max`, acceleration `accel`
/// and jerk `jerk` on both ramps.
pub fn fit(v0: f64, v1: f64, length: f64, v_max: f64, accel: f64, jerk: f64) -> Result<SCurve, FitError> {
    let r = Ramp::new(accel, jerk);
    fit_ramps(v0, v1, length, v_max, r, r)
}

/// Profile from `v0` to `v1` over `length` with peak feed at most `v_max`, the rise with `up`
/// and the fall with `down`. When the full peak does not fit, the peak is found by bisection
/// (eq. 20-21; at most 30 iterations or until the step is below 0.001 mm/s, more only for a sliver whose peak is below that) and the remaining
/// distance is cruised at that peak.
pub fn fit_ramps(v0: f64, v1: f64, length: f64, v_max: f64, up: Ramp, down: Ramp) -> Result<SCurve, FitError> {
    let v_floor = v0.max(v1);
    let v_max = v_max.max(v_floor);
    let total = |vp: f64| ramp_distance_with(v0, vp, up) + ramp_distance_with(vp, v1, down);
    if total(v_floor) > length * (1.0 + 1e-12) + 1e-12 {
        return Err(FitError::TooShort);
    }
    let peak = if total(v_max) <= length {
        v_max
    } else {
        // Eq. 20-21: F_k = F_{k-1} +- dF / 2^k, starting from the midpoint.
        let delta = v_max - v_floor;
        let mut f = 0.5 * (v_max + v_floor);
        let mut best = v_floor;
        for k in 1..=MAX_HALVINGS {
            if total(f) <= length {
                best = best.max(f);
                f += delta / 2f64.powi(k + 1);
            } else {
                f -= delta / 2f64.powi(k + 1);
            }
            // The paper stops at 0.001 mm/s; a segment too short to reach that above its floor
            // (a sliver between two corners) needs more halvings, or its peak would stay at the
            // floor and the profile would not cover its length.
            if delta / 2f64.powi(k + 1) < 1e-3 && best > v_floor {
                break;
            }
        }
        if total(f) <= length {
            best = best.max(f);
        }
        best
    };
    let rise = ramp_times(peak - v0, up);
    let fall = ramp_times(peak - v1, down);
    let mut durations = [rise[0], rise[1], rise[2], 0.0, fall[0], fall[1], fall[2]];
    let jerks = [
        up.start_jerk,
        0.0,
        -up.end_jerk,
        0.0,
        -down.start_jerk,
        0.0,
        down.end_jerk,
    ];
    let with = |durations| SCurve {
        feed_start: v0,
        durations,
        jerks,
    };
    let ramps = with(durations).table().length();
    // Cruise fills the rest exactly, so the profile length equals the segment length.
    durations[3] = if peak > 0.0 {
        ((length - ramps) / peak).max(0.0)
    } else {
        0.0
    };
    let mut profile = with(durations);
    for k in 0..PHASES {
        if profile.durations[k] == 0.0 {
            profile.jerks[k] = 0.0;
        }
    }
    Ok(profile)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `p` covers `len` and ends at `v1` with zero acceleration.
    fn assert_fits(p: &SCurve, v0: f64, v1: f64, len: f64) {
        let t = p.table();
        assert!(
            (t.length() - len).abs() < 1e-9 * (1.0 + len),
            "{v0} {v1} {len}: {}",
            t.length()
        );
        assert!((t.end().v - v1).abs() < 1e-6, "end feed {}", t.end().v);
        assert!(t.end().a.abs() < 1e-6);
    }

    #[test]
    fn fits_cover_the_length_and_end_at_the_end_feed() {
        for &(v0, v1, len) in &[
            (0.0, 0.0, 10.0),
            (100.0, 20.0, 5.0),
            (0.0, 500.0, 300.0),
            (50.0, 50.0, 0.2),
        ] {
            let p = fit(v0, v1, len, 2500.0, 1e4, 6e4).unwrap();
            assert_fits(&p, v0, v1, len);
            let t = p.table();
            for k in 0..8 {
                assert!(t.states[k].v <= 2500.0 + 1e-9 && t.states[k].a.abs() <= 1e4 + 1e-6);
            }
        }
        assert_eq!(fit(0.0, 1000.0, 1.0, 2500.0, 1e4, 6e4), Err(FitError::TooShort));
    }

    /// Ramps with a jerk per phase: the fitted profile covers the length, ends at the end feed
    /// with zero acceleration, keeps each phase's jerk and the acceleration limit, and the
    /// closed-form ramp distance is the integrated one.
    #[test]
    fn ramps_with_a_jerk_per_phase_fit_exactly() {
        let ramps = [
            Ramp {
                accel: 1e4,
                start_jerk: 6e4,
                end_jerk: 2e4,
            },
            Ramp {
                accel: 1e4,
                start_jerk: 1.5e4,
                end_jerk: 6e4,
            },
            Ramp {
                accel: 2e3,
                start_jerk: 1e5,
                end_jerk: 3e4,
            },
        ];
        let mut fitted = 0;
        for up in ramps {
            for down in ramps {
                for &(v0, v1, len) in &[
                    (0.0, 0.0, 10.0),
                    (100.0, 20.0, 5.0),
                    (0.0, 500.0, 300.0),
                    (50.0, 50.0, 0.2),
                    (0.0, 0.0, 500.0),
                ] {
                    for (va, vb) in [(v0, 900.0f64), (900.0, v1)] {
                        let r = if vb > va { up } else { down };
                        let t = ramp_times((vb - va).abs(), r);
                        let sign = if vb > va { 1.0 } else { -1.0 };
                        let p = SCurve {
                            feed_start: va,
                            durations: [t[0], t[1], t[2], 0.0, 0.0, 0.0, 0.0],
                            jerks: [sign * r.start_jerk, 0.0, -sign * r.end_jerk, 0.0, 0.0, 0.0, 0.0],
                        };
                        let tab = p.table();
                        assert!((tab.end().v - vb).abs() < 1e-9 * (1.0 + vb), "{r:?} {va} {vb}");
                        assert!(tab.end().a.abs() < 1e-9 * r.accel);
                        let d = ramp_distance_with(va, vb, r);
                        assert!(
                            (tab.length() - d).abs() < 1e-9 * (1.0 + d),
                            "{r:?} {va} {vb}: {} vs {d}",
                            tab.length()
                        );
                    }
                    let Ok(p) = fit_ramps(v0, v1, len, 2500.0, up, down) else {
                        continue;
                    };
                    assert_fits(&p, v0, v1, len);
                    fitted += 1;
                    let t = p.table();
                    let limits = [
                        up.start_jerk,
                        0.0,
                        up.end_jerk,
                        0.0,
                        down.start_jerk,
                        0.0,
                        down.end_jerk,
                    ];
                    for k in 0..PHASES {
                        assert!(p.jerks[k].abs() <= limits[k] * (1.0 + 1e-12));
                        assert!(t.states[k].a.abs() <= up.accel.max(down.accel) * (1.0 + 1e-9));
                    }
                }
            }
        }
        // Only the 0.2 mm case at 50 mm/s may be too short for some ramps.
        assert!(fitted >= 4 * ramps.len() * ramps.len(), "{fitted} fitted");
    }
}
