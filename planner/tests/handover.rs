//! The hand-over between LinuxCNC's motion and our path on the mock HAL: the module's
//! `joint.N.*` pins driven as motion and a drive would drive them (motion standing at our start
//! with a motor offset, a drive whose feedback is its command of the previous period), with
//! `enable` wired from `engaged` as the halfiles wire it. No step in the drive command at either
//! edge, the drive following our path exactly, motion seeing only the drive's lag, the catch-up
//! move leaving the drive still, and a machine switched off mid-path.

#![allow(clippy::needless_range_loop)] // per-joint arrays, indexed by joint number as HAL names them

mod common;

use common::*;
use nurbs_hal::mock::{self, Value};

const MOTOR_OFFSET: [f64; 3] = [2.5, -1.25, 0.75];

fn set_float(name: &str, v: f64) {
    assert!(mock::set_pin(name, Value::Float(v)), "{name}");
}

/// Motion's side and the drive of the test machine, per joint (joint N = axis N).
struct Machine {
    /// Motion's `joint.N.pos-cmd`.
    pos_cmd: [f64; 3],
    /// The drive's position (motor coordinates): last period's command.
    drive: [f64; 3],
    on: bool,
}

impl Machine {
    /// Machine on, motion at 0, the drive at the motor offset; the module loaded with `enable`
    /// low (it follows `engaged` from here on, as wired).
    fn at_home() -> Machine {
        set_bit("nurbs_interp.enable", false);
        Machine {
            pos_cmd: [0.0; 3],
            drive: MOTOR_OFFSET,
            on: true,
        }
    }
}

/// One period as the servo thread runs it: the drive's feedback, `nurbs_interp.feedback`,
/// motion's outputs, `nurbs_interp.update` (enable = engaged, as wired), the drive takes its
/// command. Returns (module sample or not, drive command, motion's feedback, offsets).
fn machine_period(m: &mut Machine) -> (bool, [f64; 3], [f64; 3], [f64; 3]) {
    set_bit("nurbs_interp.machine-on", m.on);
    set_bit("nurbs_interp.enable", bit("nurbs_interp.engaged"));
    for j in 0..3 {
        set_float(&format!("nurbs_interp.joint.{j}.drive-fb"), m.drive[j]);
    }
    let feedback = mock::funct("nurbs_interp.feedback").unwrap();
    // SAFETY: the exported function with its instance, called as a servo thread would.
    unsafe { mock::call(feedback, PERIOD_NS as _) };
    let pin = |j: usize, name: &str| float(&format!("nurbs_interp.joint.{j}.{name}"));
    let fb = [0, 1, 2].map(|j| pin(j, "motor-pos-fb"));
    for j in 0..3 {
        set_float(&format!("nurbs_interp.joint.{j}.pos-cmd"), m.pos_cmd[j]);
        set_float(
            &format!("nurbs_interp.joint.{j}.motor-pos-cmd"),
            m.pos_cmd[j] + MOTOR_OFFSET[j],
        );
    }
    assert!(!period(), "the update path allocated");
    let cmd = [0, 1, 2].map(|j| pin(j, "drive-cmd"));
    let offset = [0, 1, 2].map(|j| pin(j, "offset"));
    m.drive = cmd;
    (bit("nurbs_interp.active"), cmd, fb, offset)
}

/// Largest |Δ|, |Δ²| of a sequence of drive commands (per joint).
fn steps(cmds: &[[f64; 3]]) -> (f64, f64) {
    let mut d1 = 0.0f64;
    let mut d2 = 0.0f64;
    for w in cmds.windows(3) {
        for j in 0..3 {
            d1 = d1.max((w[2][j] - w[1][j]).abs());
            d2 = d2.max((w[2][j] - 2.0 * w[1][j] + w[0][j]).abs());
        }
    }
    (d1, d2)
}

#[test]
fn the_drive_runs_our_path_with_no_step_at_either_edge_and_the_catch_up_leaves_it_still() {
    let _guard = lock_module();
    let job = job("open_pocket.json");
    let l = load();
    let mut m = Machine::at_home();
    // Released, before any path: both outputs pass straight through, from the first period.
    let (_, cmd, fb, _) = machine_period(&mut m);
    assert_eq!((cmd, fb), (MOTOR_OFFSET, MOTOR_OFFSET));
    set_bit("nurbs_interp.engage", true);
    machine_period(&mut m);
    assert_eq!(u32_pin("nurbs_interp.handover-refused"), 2, "no path loaded");

    let mut s = streamer(&l, &job.toolpath, job.groups.clone(), 0);
    set_bit("nurbs_interp.engage", false);
    for _ in 0..20 {
        s.fill().unwrap();
        machine_period(&mut m);
    }
    // The path is loaded and waits: its start is on the position pins, nothing moves.
    assert!(bit("nurbs_interp.path-ready") && !bit("nurbs_interp.engaged"));
    let start = out().q;
    let first = job.samples[0].point;
    assert!(
        (0..3).all(|j| (start[j] - first[j]).abs() < 1e-9),
        "{start:?} {first:?}"
    );
    // Engage asked where motion does not stand: refused (4), nothing moves.
    set_bit("nurbs_interp.engage", true);
    machine_period(&mut m);
    assert_eq!(u32_pin("nurbs_interp.handover-refused"), 4);
    assert!(!bit("nurbs_interp.engaged"));
    // Motion moves to the start (as `G53 G0` to the values `M66` read): refused while it
    // moves (3), engaged once it stands there.
    let mut drive_cmds = Vec::new();
    let from = m.pos_cmd;
    for k in 1..=50 {
        m.pos_cmd = [0, 1, 2].map(|j| from[j] + (start[j] - from[j]) * k as f64 / 50.0);
        let (_, cmd, _, _) = machine_period(&mut m);
        if k < 50 {
            assert_eq!(u32_pin("nurbs_interp.handover-refused"), 3, "{k}");
        }
        drive_cmds.push(cmd);
    }
    m.pos_cmd = start;
    // The drive's commands from here on (the test's own approach ramp above is not a
    // jerk-limited move): two periods at rest at the start, then the edge.
    drive_cmds.drain(..drive_cmds.len() - 1);
    drive_cmds.push(machine_period(&mut m).1);
    let mut ours = Vec::new();
    let mut fes = Vec::new();
    for k in 0..job.samples.len() + 100 {
        s.fill().unwrap();
        let (active, cmd, fb, _) = machine_period(&mut m);
        drive_cmds.push(cmd);
        if active {
            ours.push(out());
            // The drive follows our position exactly (less rounding of the offset sums).
            for j in 0..3 {
                assert!((cmd[j] - MOTOR_OFFSET[j] - out().q[j]).abs() < 1e-9, "{k} {j}");
            }
        }
        // Motion's following error, as motion computes it: its command less the feedback.
        fes.push(
            (0..3)
                .map(|j| (m.pos_cmd[j] - (fb[j] - MOTOR_OFFSET[j])).abs())
                .fold(0.0, f64::max),
        );
        if bit("nurbs_interp.done") {
            break;
        }
    }
    assert!(bit("nurbs_interp.done") && bit("nurbs_interp.engaged") && !bit("nurbs_interp.fault"));
    assert_exact("open pocket through the hand-over", &ours, &job.samples, 3);
    assert_eq!(violations(&job, &ours, true), Vec::<String>::new());
    // The drive tracks its command of the last period: motion, standing, sees no following
    // error at all (to the rounding of the offset sums).
    let vmax = job.limits.feed * PERIOD * (1.0 + 1e-9);
    let worst_fe = fes.iter().copied().fold(0.0, f64::max);
    assert!(worst_fe <= 1e-9, "following error {worst_fe}");

    // Release asked before the catch-up move: refused (5), still engaged.
    set_bit("nurbs_interp.engage", false);
    machine_period(&mut m);
    assert_eq!(u32_pin("nurbs_interp.handover-refused"), 5);
    assert!(bit("nurbs_interp.engaged"));
    // The catch-up move: motion's command goes to our end, the drive stands still; released
    // when motion arrives.
    let end = out().q;
    let held = *drive_cmds.last().unwrap();
    let from = m.pos_cmd;
    for k in 1..=80 {
        m.pos_cmd = [0, 1, 2].map(|j| from[j] + (end[j] - from[j]) * k as f64 / 80.0);
        let (_, cmd, _, _) = machine_period(&mut m);
        for j in 0..3 {
            assert!((cmd[j] - held[j]).abs() < 1e-9, "catch-up {k}: {cmd:?} {held:?}");
        }
        drive_cmds.push(cmd);
    }
    m.pos_cmd = end;
    let (_, cmd, _, offset) = machine_period(&mut m);
    drive_cmds.push(cmd);
    assert!(!bit("nurbs_interp.engaged"));
    assert_eq!(offset, [0.0; 3]);
    assert_eq!(cmd, [0, 1, 2].map(|j| end[j] + MOTOR_OFFSET[j]));
    // Across both edges the drive command never stepped: its largest change in a period is the
    // path's own (feed × period) and its second difference within the acceleration.
    let (d1, d2) = steps(&drive_cmds);
    let amax = job.limits.acceleration.iter().copied().fold(0.0, f64::max) * PERIOD * PERIOD * (1.0 + 1e-6);
    assert!(d1 <= vmax && d2 <= amax, "steps {d1} {d2} > {vmax} {amax}");
}

#[test]
fn machine_off_mid_path_releases_to_the_drive_and_ends_the_motion() {
    let _guard = lock_module();
    let job = job("trident.json");
    let l = load();
    let mut m = Machine::at_home();
    let mut s = streamer(&l, &job.toolpath, job.groups.clone(), 0);
    for _ in 0..20 {
        s.fill().unwrap();
        machine_period(&mut m);
    }
    m.pos_cmd = out().q;
    machine_period(&mut m);
    set_bit("nurbs_interp.engage", true);
    let mut samples = 0;
    while samples < job.samples.len() / 2 {
        s.fill().unwrap();
        samples += machine_period(&mut m).0 as usize;
    }
    m.on = false;
    let drive_before = m.drive;
    // (`enable` still holds this period's `engaged`: the module may make one more sample.)
    let (_, cmd, _, offset) = machine_period(&mut m);
    let here = out().q;
    // The drives are off: command = feedback (no jump), and from the next period motion takes
    // the drive's position.
    assert!(!bit("nurbs_interp.engaged"));
    assert_eq!((cmd, offset), (drive_before, [0.0; 3]));
    assert_eq!(machine_period(&mut m).2, drive_before);
    // Our motion is over where it stands; on again, nothing of it moves, and a new stream may
    // begin (the planner sees no motion running).
    m.on = true;
    for _ in 0..100 {
        assert!(!machine_period(&mut m).0);
    }
    assert_eq!(out().q, here);
    assert!(!bit("nurbs_interp.done") && !bit("nurbs_interp.fault"));
    assert!(!l.channel.progress.read().moving);
}
