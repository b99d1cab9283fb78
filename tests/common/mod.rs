//! Helpers shared by the planner test suites: loading bundled examples, planning and verifying
//! with the project's own checker, and the random-curve generator of the property tests.
#![allow(dead_code)] // each test crate uses a different subset

use nurbs_motion::geometry::{ElementKind, Nurbs, Toolpath};
use nurbs_motion::planner::simulate::{run_segment, SimState};
use nurbs_motion::planner::verify::{Row, Verifier};
use nurbs_motion::planner::{Limits, PathCurves, PlanError, PlanOptions, Planner};
use nurbs_motion::readers::read_toolpath;
use proptest::prelude::*;
use std::path::{Path, PathBuf};

pub mod limits;
pub use limits::*;

pub fn example(name: &str) -> Toolpath {
    read_toolpath(&example_path(name)).unwrap()
}

/// The workspace's root folder (these helpers serve the root package's tests and the CLI's).
pub fn root() -> PathBuf {
    let here = Path::new(env!("CARGO_MANIFEST_DIR"));
    match here.join("examples").is_dir() {
        true => here.to_path_buf(),
        false => here.parent().expect("a package folder of the workspace").to_path_buf(),
    }
}

/// Path of a bundled example.
pub fn example_path(name: &str) -> PathBuf {
    root().join("examples").join(name)
}

/// A fresh scratch folder `name-<pid>` in the system's temporary folder.
pub fn scratch_dir(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("{name}-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// Why a plan did not pass.
#[derive(Debug)]
pub enum Failure {
    /// The planner refused with a clear error (no plan emitted).
    Refused(PlanError),
    /// A plan was emitted and the checker found a violation: always a defect.
    Violation(String),
}

/// Plans, samples and verifies; returns the sampled motion time, or why it failed.
pub fn try_plan_and_verify(toolpath: &Toolpath, limits: &Limits) -> Result<f64, Failure> {
    try_plan_and_verify_with(toolpath, limits, &PlanOptions::default())
}

/// [`try_plan_and_verify`] with planner options (e.g. streaming). Each record's setpoints go
/// to the verifier as it is handed out, so a motion of any length is checked in constant
/// memory.
pub fn try_plan_and_verify_with(toolpath: &Toolpath, limits: &Limits, options: &PlanOptions) -> Result<f64, Failure> {
    let mut planner = Planner::new(toolpath, limits, options).map_err(Failure::Refused)?;
    let tip = toolpath.tip_dim();
    let check_limits = limits.for_axes(tip).map_err(|e| Failure::Refused(PlanError::from(e)))?;
    let mut curves = PathCurves::new(toolpath);
    let mut verifier = Verifier::new(&mut curves, &check_limits);
    let mut state = SimState::start(tip, limits.period);
    let mut rows = 0usize;
    while let Some(next) = planner.next_final() {
        let record = next.map_err(Failure::Refused)?.record;
        let ok = run_segment(planner.curves(), &check_limits, &mut state, record, &mut |s| {
            verifier.push(&Row {
                t: rows as f64 * limits.period,
                curve: s.curve,
                u: s.u,
                q: s.point[..tip].to_vec(),
            });
            rows += 1;
        });
        if !ok {
            return Err(Failure::Violation(format!(
                "the interpolator refused record {}",
                record.seq
            )));
        }
    }
    let report = verifier.finish();
    let plan = planner.finish();
    if !report.violations.is_empty() {
        return Err(Failure::Violation(format!("{:?}", report.violations)));
    }
    // The plan's own profile time and the sampled motion agree to one period.
    let motion = rows.saturating_sub(1) as f64 * limits.period;
    if (motion - plan.motion_time).abs() > limits.period + 1e-9 {
        return Err(Failure::Violation(format!(
            "sampled {motion} s vs planned {} s",
            plan.motion_time
        )));
    }
    Ok(motion)
}

/// Plans, samples and verifies (panics on any failure); returns the motion time.
pub fn plan_and_verify(toolpath: &Toolpath, limits: &Limits) -> f64 {
    try_plan_and_verify(toolpath, limits).unwrap_or_else(|e| panic!("{e:?}"))
}

/// Cases `cases` of the random curves of `seed` (see [`random_curve`]), each with its number;
/// the cases before are drawn and passed over, so case `k` is the same in every run of `seed`.
pub fn random_cases(seed: u64, cases: std::ops::Range<u64>) -> impl Iterator<Item = (u64, Toolpath, Limits)> {
    use proptest::strategy::ValueTree;
    use proptest::test_runner::{Config, RngAlgorithm, TestRng, TestRunner};
    let mut key = [0u8; 32];
    key[..8].copy_from_slice(&seed.to_le_bytes());
    let mut runner = TestRunner::new_with_rng(Config::default(), TestRng::from_seed(RngAlgorithm::ChaCha, &key));
    let strategy = random_curve();
    (0..cases.end).filter_map(move |case| {
        let (tp, limits) = strategy.new_tree(&mut runner).expect("generate").current();
        (case >= cases.start).then_some((case, tp, limits))
    })
}

/// A random clamped curve: degree 1-7, 2-D or 3-D, weights 0.2-5, some near-repeated control
/// points and straight stretches, scaled to `size` mm.
pub fn random_curve() -> impl Strategy<Value = (Toolpath, Limits)> {
    (
        1usize..=7,
        2usize..=3,
        0usize..6,
        any::<u64>(),
        -3.0f64..3.3,
        0.0f64..1.0,
        0.0f64..1.0,
        0.0f64..1.0,
        0.0f64..1.0,
        0.0f64..1.0,
    )
        .prop_map(|(degree, dim, extra, seed, log_size, rf, ra, rj, re, rdt)| {
            let n = degree + 1 + extra;
            let mut rng = seed;
            let mut next = move || {
                rng ^= rng << 13;
                rng ^= rng >> 7;
                rng ^= rng << 17;
                (rng >> 11) as f64 / (1u64 << 53) as f64
            };
            let size = 10f64.powf(log_size.clamp(0.0, 3.3)); // 1 mm .. 2 m
            let mut points: Vec<Vec<f64>> = Vec::new();
            for i in 0..n {
                let kind = next();
                let p: Vec<f64> = if i > 0 && kind < 0.15 {
                    // Near-repeated control point.
                    points[i - 1].iter().map(|c| c + 1e-7 * size * next()).collect()
                } else if i > 1 && kind < 0.3 {
                    // Straight stretch: continue the previous direction.
                    points[i - 1]
                        .iter()
                        .zip(&points[i - 2])
                        .map(|(a, b)| 2.0 * a - b)
                        .collect()
                } else {
                    (0..dim).map(|_| size * next()).collect()
                };
                points.push(p);
            }
            let weights: Vec<f64> = (0..n).map(|_| 0.2 + 4.8 * next()).collect();
            let mut knots = vec![0.0; degree + 1];
            let interior = n - degree - 1;
            let mut inner: Vec<f64> = (0..interior).map(|_| 0.05 + 0.9 * next()).collect();
            inner.sort_by(f64::total_cmp);
            knots.extend(inner);
            knots.extend(vec![1.0; degree + 1]);
            let curve = Nurbs::new(degree, knots, &points, Some(weights)).unwrap();
            let feed = 10f64.powf(rf * 3.7); // 1 .. 5000
            let accel = 10f64.powf(2.0 + 3.0 * ra);
            let jerk = 10f64.powf(3.0 + 4.0 * rj);
            let eps = 10f64.powf(-4.0 + 3.0 * re);
            let dt = 1e-4 * 10f64.powf(rdt * 1.778); // 1e-4 .. 6e-3
            let tp = Toolpath::single(ElementKind::Nurbs, curve);
            (tp.clone(), Limits::uniform(dim, feed, accel, jerk, eps, dt))
        })
}
