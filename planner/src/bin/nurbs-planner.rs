//! `nurbs-planner`: the userspace planner component (`loadusr -W nurbs-planner ...`).
//!
//! Reads a toolpath (JSON, G-code or DXF), plans it, and streams it to the realtime module
//! `nurbs_interp` through the shared-memory channel while the motion runs: the curves as the
//! records need them, and the records in groups that end at a checked stop, keeping at most
//! `--margin` seconds of motion queued ahead of the module (and never more than the ring
//! holds). Memory stays bounded by that look-ahead whatever the program's length.
//!
//! ```text
//! nurbs-planner TOOLPATH --feed F --accel A[,A..] --jerk J[,J..] --chord-tol E [--vel V[,V..]]
//!               (--period S | --ini FILE) [--margin S] [--planner erwinski|vpop|reach]
//!               [--round-corners auto|on|off] [--stop-fraction F]
//! ```
//! The default `erwinski` planner runs as a stream in a thread of its own
//! (`nurbs-plan plan --stream` plans the same records): each record goes out once it is final,
//! with the stop after the last record of each group (the next segment re-planned to rest,
//! checked by the planner like every segment). The motion starts as soon as the plan can stay
//! ahead of it. `--planner reach` plans with the reachability planner in look-ahead windows
//! (`nurbs-plan plan --planner reach --stream` plans the same positions), also in a thread of
//! its own reading the file as it plans: one tool-tip position per servo period (2-/3-axis
//! paths), sent as path blocks, which the module outputs exactly, in groups that end where the
//! module's stop from the block end was checked within the limits. `--planner vpop` plans with
//! VPOp the same way but whole, before the motion. Every planner refuses a 5-axis toolpath
//! before touching HAL: the module drives the tool tip's joints only.
//! The limit flags and `--ini` are `nurbs-plan`'s (`nurbs_cli::LimitArgs`): with
//! `--ini`, `[EMCMOT]SERVO_PERIOD` (ns) gives the period and `[AXIS_X|Y|Z]MAX_VELOCITY`,
//! `MAX_ACCELERATION`, `MAX_JERK`, `[NURBS]FEED`, `CHORD_TOLERANCE` give the limits; flags given
//! on the command line win. The period travels in the stream's header: the module refuses a
//! plan made for another period than its thread's (fault 11), whose motion would not be the one
//! the planner checked.
//!
//! Pins: `nurbs-planner.ready` (bit out: first records queued), `.running` (bit out: records
//! remain to be sent), `.error` (bit out), `.records-sent` (u32 out), `.buffered` (float out,
//! s: motion time queued in the ring), `.feed-override` (float in, 1 unconnected: wire
//! `halui.feed-override.value`).
//!
//! Feed override: the Erwinski plan is planned again at a new override (at most
//! `--max-feed-override`, else `[DISPLAY]MAX_FEED_OVERRIDE` of `--ini`, else 1) from the end of
//! the last group sent into the ring, and the motion runs into the new plan there: it takes
//! effect once the motion queued in the ring (at most `--margin` plus a group) has run, with a
//! ramp within the axis limits. 0 keeps the plan (wire the same signal to
//! `nurbs_interp.feed-override`, which holds). VPOp plans keep the programmed feed.
//! Exits on SIGTERM/SIGINT (what `halcmd unload` and halrun's shutdown send), at any stage;
//! with `--exit-when-done`, also once the module is done with the motion.
//!
//! Resume after a hold or an underrun: when the module has stopped on the path it publishes the
//! stop point in the channel. A planner that starts then, or that is running when it happens,
//! plans the rest of the path from rest at exactly that point and streams it; the module runs
//! it when `nurbs_interp.hold` is released (hold) or on a rising edge of `nurbs_interp.resume`
//! (underrun). (To start a different job instead, abort first: `nurbs_interp.abort` clears the
//! stop point.)

use std::process::ExitCode;
use std::sync::Arc;
use std::time::{Duration, Instant};

use clap::Parser;
use nurbs_cli::corners::{open, prepare};
use nurbs_cli::{PlannerArgs as Args, PlannerKind};
use nurbs_hal::channel::{Channel, StopPoint};
use nurbs_hal::sys::{HAL_IN, HAL_OUT};
use nurbs_motion::geometry::Toolpath;
use nurbs_motion::planner::{Limits, PathCurves};
use nurbs_planner::feed::{self, Source, Streamer};
use nurbs_planner::hal_user::{install_signal_handlers, stopped, Component};
use nurbs_planner::say;
use nurbs_planner::shared_path::SharedPath;

/// The toolpath file read as a stream, its G1 corners rounded as `nurbs-plan plan` does with
/// the same tolerance (and `verify` checks), shared by the plans of the motion.
fn open_path(args: &Args) -> Result<SharedPath, String> {
    let mut stream = open(&args.toolpath, args.round_corners, &args.limits).map_err(|e| e.to_string())?;
    Ok(SharedPath::new(stream.take_elements()))
}

/// What a motion runs on: the file read as a stream, once, by the plans (the Erwinski and the
/// reachability planner), or the whole path, read before (VPOp plans it whole).
enum PathSource {
    Stream(SharedPath),
    Whole(Arc<Toolpath>),
}

/// Plans the path, or the rest of it from the module's stop point `from` (the Erwinski
/// and the reachability planner as streams over `curves`, VPOp over the whole path, read here), begins its
/// geometry stream once the module runs no motion, and queues the first records.
fn start_motion<'a>(
    args: &Args,
    path: &PathSource,
    limits: &Limits,
    channel: &'a Channel,
    from: Option<&StopPoint>,
    feed_override: f64,
) -> Result<Streamer<'a>, String> {
    if let Some(p) = from {
        say!(
            "nurbs-planner: the module stopped ({}) at curve {} u = {} (after record {}): planning the rest from there",
            match p.cause {
                1 => "underrun",
                2 => "hold",
                _ => "?",
            },
            p.curve,
            p.u,
            p.seq
        );
    }
    let began = Instant::now();
    let (source, first_curve, tip) = match path {
        // The planner runs in a thread of its own, reading the file as it plans; its groups
        // wait until the stream has begun.
        PathSource::Stream(shared) => {
            let mut curves = shared.open()?;
            let first = from.map_or(0, |p| feed::plan_start(&mut curves, p).curve);
            let tip = curves.tip_dim();
            let source = match args.planner {
                PlannerKind::Reach => {
                    Source::streamed_blocks(shared.clone(), limits.clone(), from.copied(), args.stop_fraction)
                }
                _ => Source::streamed(shared.clone(), limits.clone(), from.copied(), feed_override),
            };
            (source, first, tip)
        }
        PathSource::Whole(path) => {
            let first = from.map_or(0, |p| feed::plan_start(&mut PathCurves::new(path), p).curve);
            let tip = path.tip_dim();
            let path = Arc::clone(path);
            if limits.hold_reserve > 0.0 {
                say!("nurbs-planner: {}", nurbs_motion::planner::vpop::HOLD_RESERVE_IGNORED);
            }
            // The whole plan and its stop checks come before the motion: in a thread, so that a
            // signal still ends the planner at once.
            let (plan_limits, start, fraction) = (limits.clone(), from.copied(), args.stop_fraction);
            let (sender, receiver) = std::sync::mpsc::channel();
            std::thread::spawn(move || {
                let planned = feed::vpop_plan(&path, &plan_limits, start.as_ref()).and_then(|plan| {
                    feed::block_plan(&path, (&plan.points, &plan.limits), start.as_ref(), fraction)
                        .map(|blocks| (plan, blocks))
                });
                let _ = sender.send(planned);
            });
            let (plan, blocks) = loop {
                match receiver.recv_timeout(Duration::from_millis(20)) {
                    Ok(planned) => break planned?,
                    Err(std::sync::mpsc::RecvTimeoutError::Timeout) if stopped() => {
                        return Err("stopped by signal while planning".into())
                    }
                    Err(std::sync::mpsc::RecvTimeoutError::Timeout) => {}
                    Err(e) => return Err(format!("the planner thread ended: {e}")),
                }
            };
            let (ends, stored, worst) = blocks.stops;
            say!(
                "nurbs-planner: {:?}: {} periods in {} path blocks, motion {:.6} s, planned in {:.3} s; stops within the limits at {ends} block ends ({stored} stored sequences, worst {worst:.4} x an axis limit), checked in {:.3} s",
                args.planner,
                plan.points.len(),
                blocks.blocks().count(),
                plan.motion_time,
                plan.plan_time,
                began.elapsed().as_secs_f64() - plan.plan_time
            );
            (Source::blocks(blocks), first, tip)
        }
    };
    // A motion of an earlier planner may still be queued or running: the module empties the
    // ring once that motion is over (finished, aborted or stopped), and refuses a new stream
    // while it runs.
    let waited = Instant::now();
    while !channel.segments.is_empty() || channel.progress.read().moving {
        if stopped() {
            return Err("stopped by signal before the motion started".into());
        }
        if waited.elapsed() > Duration::from_secs(10) {
            return Err("the module still runs a motion (records queued or moving)".into());
        }
        std::thread::sleep(Duration::from_millis(5));
    }
    if let Some(p) = from {
        // An abort while we planned withdraws the stop point: then the plan is not wanted.
        if channel.stop.read().is_none_or(|now| now.epoch != p.epoch) {
            return Err("the stop point was withdrawn (abort) while planning from it".into());
        }
    }
    let mut streamer = Streamer::new(channel, tip, source, first_curve, args.margin, began)?;
    // Queue what the start rule asks for before hal_ready: `loadusr -W` returns with the
    // motion ready to go; the queue grows to the margin as it runs.
    while !streamer.done() && !streamer.started() {
        if stopped() {
            return Err("stopped by signal before the motion started".into());
        }
        if !streamer.fill()? {
            std::thread::sleep(Duration::from_millis(1));
        }
    }
    let queued = streamer.buffered();
    say!(
        "nurbs-planner: first {} records ({queued:.3} s of motion) queued after {:.3} s",
        streamer.pushed,
        began.elapsed().as_secs_f64()
    );
    Ok(streamer)
}

/// The module has taken stream `generation` and is done with it: nothing queued, nothing
/// moving, and no stop point newer than `from` to plan from (the module publishes a stop before
/// it reports the motion at rest, so reading the stop last sees it).
fn motion_over(channel: &Channel, generation: u32, from: Option<StopPoint>) -> bool {
    let report = channel.progress.read();
    let idle = report.generation == generation && !report.moving && channel.segments.is_empty();
    idle && channel
        .stop
        .read()
        .is_none_or(|p| from.is_some_and(|f| f.epoch == p.epoch))
}

/// Plans and streams until a signal (or, with `--exit-when-done`, the motion's end); why it
/// ended, or the error.
fn run(args: &Args) -> Result<&'static str, String> {
    // The chord tolerance first (the G1 rounding needs it), then the path as `nurbs-plan plan`
    // prepares it with the same tolerance (and `verify` checks it).
    // The Erwinski and the reachability planner read the file as they plan (here only its first
    // element, for the dimension); VPOp plans the whole path. Before touching HAL: a clear refusal, not a
    // half-started component.
    let (path, tip) = match args.planner {
        PlannerKind::Erwinski | PlannerKind::Reach => {
            let shared = open_path(args)?;
            let first = shared.open()?;
            let tip = first.tip_dim();
            // A 5-axis path is one from its first element on (the readers refuse rotary moves
            // on a path that began as 3-axis).
            if let Some(element) = first.get(0) {
                feed::check_tip_path(&Toolpath {
                    elements: vec![element.clone()],
                })?;
            }
            (PathSource::Stream(shared), tip)
        }
        PlannerKind::Vpop => {
            let prepared = prepare(&args.toolpath, args.round_corners, &args.limits).map_err(|e| e.to_string())?;
            feed::check_tip_path(&prepared.toolpath)?;
            let tip = prepared.toolpath.tip_dim();
            (PathSource::Whole(Arc::new(prepared.toolpath)), tip)
        }
    };
    let limits = args.limits.limits(tip)?;
    let max_feed_override = args.max_feed_override()?;
    // Until here a signal ends the process at once (nothing to clean up); from here on it is
    // a request the loops below honour, so that the component and the channel are released.
    install_signal_handlers();

    let comp = Component::new("nurbs-planner")?;
    let ready = comp.pin::<bool>("ready", HAL_OUT)?;
    let running = comp.pin::<bool>("running", HAL_OUT)?;
    let error = comp.pin::<bool>("error", HAL_OUT)?;
    let sent_pin = comp.pin::<u32>("records-sent", HAL_OUT)?;
    let buffered_pin = comp.pin::<f64>("buffered", HAL_OUT)?;
    let override_pin = comp.pin::<f64>("feed-override", HAL_IN)?;
    // Unconnected, the programmed feed.
    override_pin.set(1.0);
    // The override the plans are made with: the operator's, within the machine's maximum; 0 (a
    // hold, carried out by the module) keeps the last one.
    let mut feed_override = 1.0;
    let mut read_override = || {
        let asked = override_pin.get();
        if asked.is_finite() && asked > 0.0 {
            feed_override = asked.min(max_feed_override);
        }
        feed_override
    };
    let result = (|| {
        let channel = comp.attach_channel(Duration::from_secs(5))?;
        // The module may be standing where an underrun stopped it: then plan from there.
        let mut from = channel.stop.read();
        let mut streamer = start_motion(args, &path, &limits, channel, from.as_ref(), read_override())?;
        let show = |s: &mut Streamer| {
            sent_pin.set(s.pushed as u32);
            running.set(!s.done());
            let b = s.buffered();
            buffered_pin.set(b);
        };
        show(&mut streamer);
        ready.set(true);
        comp.ready()?;
        let mut reported = false;
        while !stopped() {
            // A stop while we stream (hold, or an underrun: we were too slow): re-plan from where
            // the module stands; the module runs it after the command.
            if let Some(p) = channel.stop.read() {
                if from.is_none_or(|f| f.epoch != p.epoch) {
                    from = Some(p);
                    drop(streamer);
                    streamer = start_motion(args, &path, &limits, channel, from.as_ref(), read_override())?;
                    reported = false;
                }
            }
            streamer.set_feed_override(read_override());
            let progressed = streamer.fill()?;
            show(&mut streamer);
            if streamer.done() && !reported {
                let (curves, values, wraps) = streamer.writer().usage();
                say!(
                    "nurbs-planner: all {} records sent ({:.3} s of motion; longest group {:.3} s); {curves} path elements and {values} arena values streamed, the arena reused from its start {wraps} times",
                    streamer.pushed, streamer.pushed_time, streamer.longest_group
                );
                if let Some(e) = streamer.plan_error() {
                    // The motion ends at rest where the file could not be read further.
                    say!("nurbs-planner: {e}");
                    error.set(true);
                }
                reported = true;
            }
            if args.exit_when_done && streamer.done() && motion_over(channel, streamer.writer().generation(), from) {
                return Ok("the motion is over (--exit-when-done)");
            }
            if !progressed {
                std::thread::sleep(Duration::from_millis(1));
            }
        }
        Ok("stopped by signal")
    })();
    if result.is_err() {
        error.set(true);
        running.set(false);
    }
    result
}

fn main() -> ExitCode {
    let args = Args::parse();
    // A panic (ours or a dependency's, in this thread or the planning one) is an error: the
    // component and the channel are released as it unwinds, and the module, getting no more
    // records, stops on the path with the stop it already has.
    nurbs_motion::panics::install();
    let result = nurbs_motion::panics::catch(|| run(&args)).unwrap_or_else(|panic| {
        Err(format!(
            "internal error (please report it with the toolpath and the command): {panic}"
        ))
    });
    match result {
        Ok(why) => {
            say!("nurbs-planner: {why}, exiting cleanly");
            ExitCode::SUCCESS
        }
        Err(e) => {
            say!("nurbs-planner: {e}");
            ExitCode::FAILURE
        }
    }
}
