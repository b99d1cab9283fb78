//! How soon a feed override change takes effect: at random samples of the bundled curves, a G1
//! program, a dense G1 program and a long straight line, the operator's override goes from 100 %
//! to 50 % while the streamed plan runs through the module at the servo thread's real pace; the
//! planner plans the rest again and the module runs into it, cutting into the running record at
//! a checked hold stop ([`nurbs_planner::cut`]) or joining at a group end. Every run stays
//! within the axis limits (the project's check over every sample), and the latency from the
//! change to the first sample that leaves the plan at 100 % is collected and its distribution
//! printed. `OVERRIDE_INSTANTS` (default 2 per path) selects a longer run, `HOLD_RESERVE` plans
//! every path with that hold reserve (`--hold-reserve`); docs/testing.md records one.

mod common;

use common::test_paths::{g1_zigzag, line};
use common::*;

/// Runs `job`'s streamed plan through the module at the real pace, the override going to
/// `low` at sample `at`, to the path end.
/// Returns the samples, the latency in samples from the change to the first sample off the
/// plan at 100 % (`None`: none left it), and how the joins went.
fn change_at(job: &Job, at: usize, low: f64) -> (Vec<Out>, Option<usize>, String) {
    let l = load();
    let periods = job.samples.len() + 200_000;
    let (got, s) = paced_run(&l, &job.toolpath, &job.limits, 1.0, periods, |s, samples| {
        if samples == at {
            s.set_feed_override(low);
        }
    });
    assert!(
        !bit("nurbs_interp.fault"),
        "fault {}",
        u32_pin("nurbs_interp.fault-code")
    );
    assert!(
        bit("nurbs_interp.done"),
        "not at the path end (underruns {})",
        u32_pin("nurbs_interp.underruns")
    );
    let left = got
        .iter()
        .zip(&job.samples)
        .position(|(o, e)| o.q[0] != e.point[0] || o.q[1] != e.point[1]);
    let joins = format!(
        "{} cut, {} at a group end, {} at the end of the slots sent",
        s.cuts, s.joins_in_ring, s.joins_at_end
    );
    (got, left.map(|k| k.saturating_sub(at)), joins)
}

#[test]
fn a_feed_override_change_takes_effect_within_milliseconds_within_the_limits() {
    let _guard = lock_module();
    let per_path: usize = std::env::var("OVERRIDE_INSTANTS")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(2);
    let jobs = [
        ("trident", job("trident.json")),
        ("butterfly", job("butterfly.json")),
        ("G1 zigzag", job_of(g1_zigzag(40))),
        (
            "dense G1 rounded (600 lines)",
            job_rounded(&dense_g1(600, &std::env::temp_dir())),
        ),
        ("2000 mm line", job_of(line(2000.0))),
        ("dense G1 (2000 lines)", job_at(&dense_g1(2000, &std::env::temp_dir()))),
    ];
    let mut instants = Instants::new(0x9e37_79b9_7f4a_7c15);
    // `OVERRIDE_AT`: every change at this sample (to reproduce one).
    let fixed: Option<usize> = std::env::var("OVERRIDE_AT").ok().and_then(|v| v.parse().ok());
    let mut all = Vec::new();
    // `OVERRIDE_PATHS`: only the paths whose names contain it.
    let only = std::env::var("OVERRIDE_PATHS").unwrap_or_default();
    for (name, job) in jobs.iter().filter(|(name, _)| name.contains(only.as_str())) {
        let n = job.samples.len();
        let mut latencies = Vec::new();
        let mut unchanged = 0;
        for _ in 0..per_path {
            // In the first 90 % of the motion (a change in its last moments may find nothing
            // left to change).
            let at = fixed.unwrap_or_else(|| instants.next(n * 9 / 10));
            let (got, latency, joins) = change_at(job, at, 0.5);
            assert_eq!(
                violations(job, &got, true),
                Vec::<String>::new(),
                "{name}: override 50 % at sample {at} ({joins})"
            );
            if std::env::var("OVERRIDE_VERBOSE").is_ok() {
                println!("  {name}: at sample {at}: latency {latency:?} samples; {joins}");
            }
            match latency {
                Some(l) => latencies.push(l),
                None => unchanged += 1,
            }
        }
        latencies.sort_unstable();
        let q = |p: f64| quantile(&latencies, p);
        println!(
            "{name}: {per_path} changes to 50 %: latency (ms) median {:.1}, 90 % {:.1}, worst {:.1}; within 50 ms: {} of them; {unchanged} left the plan unchanged",
            q(0.5) as f64 * PERIOD * 1e3,
            q(0.9) as f64 * PERIOD * 1e3,
            latencies.last().copied().unwrap_or(0) as f64 * PERIOD * 1e3,
            latencies.iter().filter(|&&l| l as f64 * PERIOD <= 0.05).count()
        );
        all.extend(latencies);
    }
    all.sort_unstable();
    println!(
        "all paths: {} changes, median {:.1} ms, worst {:.1} ms",
        all.len(),
        all.get(all.len() / 2).copied().unwrap_or(0) as f64 * PERIOD * 1e3,
        all.last().copied().unwrap_or(0) as f64 * PERIOD * 1e3
    );
    assert!(!all.is_empty(), "no change took effect");
}
