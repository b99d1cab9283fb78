//! `nurbs-planner`: the userspace planner component (`loadusr -W nurbs-planner ...`).
//!
//! Reads a toolpath (JSON, G-code or DXF), plans it with `nurbs_motion::planner::plan`, publishes
//! the curve geometry to the realtime module `nurbs_interp` through the shared-memory channel and
//! streams the segment records into the channel's ring while motion runs, keeping at most
//! `--margin` seconds of motion queued ahead of the module (and never more than the ring holds).
//! Each record goes out with the stop the module makes if nothing follows it (underrun, hold,
//! abort), checked by simulation against the axis limits; the stops are checked as the records
//! go out (as fast as they run, ahead of the records pushed), so the motion starts once the plan
//! is done and the first records' stops are checked, not after every stop of a long program.
//!
//! ```text
//! nurbs-planner TOOLPATH --feed F --accel A[,A..] --jerk J[,J..] --chord-tol E [--vel V[,V..]]
//!               (--period S | --ini FILE) [--margin S] [--planner erwinski|vpop] [--stream]
//!               [--round-corners auto|on|off] [--stop-fraction F]
//! ```
//! `--planner vpop` plans with VPOp (one tool-tip position per servo period, 2-/3-axis paths)
//! and sends the positions as path blocks, which the module outputs exactly; the default
//! `erwinski` sends S-curve segment records. `--stream` (Erwinski) plans in a thread of its own
//! and sends each record as soon as it is final and checked, so the motion starts before the
//! plan ends.
//! With `--ini`, `[EMCMOT]SERVO_PERIOD` (ns) gives the period and `[AXIS_X|Y|Z]MAX_VELOCITY`,
//! `MAX_ACCELERATION`, `MAX_JERK`, `[NURBS]FEED`, `CHORD_TOLERANCE` give the limits; flags given on
//! the command line win. The period must equal the servo thread's for the motion to be the one
//! the planner checked.
//!
//! Pins: `nurbs-planner.ready` (bit out: geometry published, first records queued), `.running`
//! (bit out: records remain to be sent), `.error` (bit out), `.records-sent` (u32 out),
//! `.buffered` (float out, s: motion time queued in the ring).
//! Exits on SIGTERM/SIGINT (what `halcmd unload` and halrun's shutdown send).
//!
//! Resume after a hold or an underrun: when the module has stopped on the path it publishes the
//! stop point in the channel. A planner that starts then, or that is running when it happens,
//! plans the rest of the path from rest at exactly that point and publishes it; the module runs
//! it when `nurbs_interp.hold` is released (hold) or on a rising edge of `nurbs_interp.resume`
//! (underrun). (To start a different job instead, abort
//! first: `nurbs_interp.abort` clears the stop point.)

use std::collections::VecDeque;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::sync::mpsc::{self, Receiver, TryRecvError};
use std::sync::Arc;
use std::time::{Duration, Instant};

use clap::Parser;
use nurbs_hal::channel::{Channel, ChannelError, Slot, StopPoint, SEGMENT_SLOTS};
use nurbs_hal::sys::HAL_OUT;
use nurbs_hal::user::{install_signal_handlers, stopped, ArenaAppender, Component};

#[path = "../plan_geometry.rs"]
mod plan_geometry;
use nurbs_motion::cli::corners::{prepare, RoundCorners};
use nurbs_motion::geometry::Toolpath;
use nurbs_motion::planner::Limits;
use nurbs_motion::readers::read_toolpath;
use plan_geometry::{Motion, Next, PlanEvent, PlannerKind};

#[derive(Parser, Debug)]
#[command(
    name = "nurbs-planner",
    about = "Plan a NURBS toolpath and stream it to nurbs_interp"
)]
struct Args {
    /// Toolpath (.json, .ngc/.nc/.gcode/.tap, .dxf).
    toolpath: PathBuf,
    /// Programmed feed F (mm/s).
    #[arg(long)]
    feed: Option<f64>,
    /// Axial acceleration limit(s) (mm/s^2), comma-separated in axis order.
    #[arg(long, value_delimiter = ',')]
    accel: Option<Vec<f64>>,
    /// Axial jerk limit(s) (mm/s^3).
    #[arg(long, value_delimiter = ',')]
    jerk: Option<Vec<f64>>,
    /// Axial velocity limit(s) (mm/s); default: the feed.
    #[arg(long, value_delimiter = ',')]
    vel: Option<Vec<f64>>,
    /// Chord error tolerance (mm).
    #[arg(long = "chord-tol")]
    chord_tol: Option<f64>,
    /// Servo period (s); must equal the servo thread's.
    #[arg(long)]
    period: Option<f64>,
    /// LinuxCNC INI file for the period and limits not given as flags.
    #[arg(long)]
    ini: Option<PathBuf>,
    /// Motion time (s) to keep queued ahead of the module.
    #[arg(long, default_value_t = 2.0)]
    margin: f64,
    /// Largest tangential deceleration and jerk of the module's underrun stop, as a fraction of
    /// the smallest axis acceleration and jerk. The planner runs the stop from every segment
    /// boundary and lowers it where the axis limits need it.
    #[arg(long, default_value_t = 1.0)]
    stop_fraction: f64,
    /// Planner: `erwinski` (S-curve segments, streamed as records) or `vpop` (per-period
    /// positions of 2-/3-axis tool-tip paths, streamed as path blocks).
    #[arg(long, value_enum, default_value_t = Planner::Erwinski)]
    planner: Planner,
    /// G1 corners: `auto` rounds them within the chord tolerance when the whole path is a
    /// straight-line program (as `nurbs-plan plan` does), `on` requires that, `off` stops at
    /// every corner.
    #[arg(long, value_enum, default_value_t = RoundCorners::Auto)]
    round_corners: RoundCorners,
    /// Erwinski planner: plan as a stream (`nurbs-plan plan --stream` plans the same) in a
    /// thread of its own, and start the motion once the first records and their stops are
    /// checked instead of after the whole plan: a long program starts at once. Each record goes
    /// out once the stop points of its curve are known (the scan has passed the curve's end), so
    /// a path of one long curve waits for its scan. The price of a streamed plan: a plan that
    /// fails does so during the motion (the module then stops on the path, within the limits),
    /// and rarely a back-tracking cascade makes a stop the whole-path plan would not make.
    #[arg(long)]
    stream: bool,
}

#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
enum Planner {
    Erwinski,
    Vpop,
}

impl From<Planner> for PlannerKind {
    fn from(p: Planner) -> PlannerKind {
        match p {
            Planner::Erwinski => PlannerKind::Erwinski,
            Planner::Vpop => PlannerKind::Vpop,
        }
    }
}

/// `[SECTION]KEY` lookup in a LinuxCNC INI file (first occurrence wins, as in LinuxCNC).
struct Ini {
    entries: Vec<(String, String, String)>,
}

impl Ini {
    fn read(path: &Path) -> Result<Ini, String> {
        let text = std::fs::read_to_string(path).map_err(|e| format!("{}: {e}", path.display()))?;
        let mut section = String::new();
        let mut entries = Vec::new();
        for line in text.lines() {
            let line = line.trim();
            if line.starts_with('#') || line.starts_with(';') || line.is_empty() {
                continue;
            }
            if let Some(name) = line.strip_prefix('[').and_then(|l| l.strip_suffix(']')) {
                section = name.trim().to_owned();
            } else if let Some((k, v)) = line.split_once('=') {
                entries.push((section.clone(), k.trim().to_owned(), v.trim().to_owned()));
            }
        }
        Ok(Ini { entries })
    }

    fn number(&self, section: &str, key: &str) -> Result<Option<f64>, String> {
        match self.entries.iter().find(|(s, k, _)| s == section && k == key) {
            None => Ok(None),
            Some((_, _, v)) => v
                .parse()
                .map(Some)
                .map_err(|_| format!("[{section}]{key} = {v} is not a number")),
        }
    }

    /// One value per axis (X, Y[, Z]) if every axis has it.
    fn per_axis(&self, key: &str, axes: usize) -> Result<Option<Vec<f64>>, String> {
        let mut out = Vec::new();
        for axis in ["AXIS_X", "AXIS_Y", "AXIS_Z"].iter().take(axes) {
            match self.number(axis, key)? {
                Some(v) => out.push(v),
                None => return Ok(None),
            }
        }
        Ok(Some(out))
    }
}

fn limits(args: &Args, axes: usize) -> Result<Limits, String> {
    let ini = args.ini.as_deref().map(Ini::read).transpose()?;
    let from_ini = |section: &str, key: &str| -> Result<Option<f64>, String> {
        ini.as_ref().map_or(Ok(None), |i| i.number(section, key))
    };
    let axis_ini =
        |key: &str| -> Result<Option<Vec<f64>>, String> { ini.as_ref().map_or(Ok(None), |i| i.per_axis(key, axes)) };
    let period = match args.period {
        Some(p) => p,
        None => from_ini("EMCMOT", "SERVO_PERIOD")?
            .map(|ns| ns / 1e9)
            .ok_or("no period: give --period or --ini with [EMCMOT]SERVO_PERIOD")?,
    };
    let need = |v: Option<Vec<f64>>, what: &str| v.ok_or(format!("no {what} limit given"));
    let vel = args.vel.clone().or(axis_ini("MAX_VELOCITY")?);
    let feed = match args.feed.or(from_ini("NURBS", "FEED")?) {
        Some(f) => f,
        None => vel
            .as_ref()
            .and_then(|v| v.iter().copied().reduce(f64::min))
            .ok_or("no feed: give --feed, [NURBS]FEED or axis velocities")?,
    };
    Limits {
        feed,
        velocity: vel.unwrap_or_else(|| vec![feed]),
        acceleration: need(args.accel.clone().or(axis_ini("MAX_ACCELERATION")?), "acceleration")?,
        jerk: need(args.jerk.clone().or(axis_ini("MAX_JERK")?), "jerk")?,
        chord_tolerance: args
            .chord_tol
            .or(from_ini("NURBS", "CHORD_TOLERANCE")?)
            .ok_or("no chord tolerance: give --chord-tol or [NURBS]CHORD_TOLERANCE")?,
        period,
    }
    .for_axes(axes)
    .map_err(|e| e.to_string())
}

/// Streams a planned motion's records into the ring within the time margin, checking the stop
/// after each record as it goes: a record is pushed once its stop is known, so motion can start
/// long before every stop of a long program is checked.
struct Streamer<'a> {
    channel: &'a Channel,
    motion: Motion<'a>,
    arena: ArenaAppender<'a>,
    /// A streamed plan's events (records, stop points), from the planner thread.
    plan_events: Option<Receiver<PlanEvent>>,
    /// Slots whose stops are checked, not pushed yet, with their motion times.
    ready: VecDeque<(Slot, f64)>,
    ready_time: f64,
    /// `ends[k]`: motion time of the first k pushed slots.
    ends: Vec<f64>,
    margin: f64,
    /// Records may go into the ring: the module takes the first one as soon as it is there, so
    /// this is when the motion starts (once the start rule holds).
    started: bool,
    /// Every slot has come out of the motion.
    all_checked: bool,
    /// Worst stop ratio to an axis limit so far, and how many stops are stored sequences.
    worst: f64,
    stored: usize,
}

/// Longest the stop checks may hold up one pass of the main loop (which also watches for
/// stops and signals).
const CHECK_SLICE: Duration = Duration::from_millis(20);

impl<'a> Streamer<'a> {
    fn sent(&self) -> usize {
        self.ends.len() - 1
    }

    /// Motion time of the sent records the module has not taken yet.
    fn buffered(&self) -> f64 {
        let sent = self.sent();
        let taken = sent.saturating_sub(self.channel.segments.len());
        self.ends[sent] - self.ends[taken.min(sent)]
    }

    /// Motion time of the records whose stops are checked (pushed or ready).
    fn checked_time(&self) -> f64 {
        self.ends[self.sent()] + self.ready_time
    }

    /// Takes what a streamed plan has handed out so far.
    fn receive(&mut self) -> Result<(), String> {
        let Some(events) = &self.plan_events else {
            return Ok(());
        };
        loop {
            match events.try_recv() {
                Ok(event) => {
                    if let Some(line) = self.motion.records.take(event)? {
                        eprintln!("nurbs-planner: {line}");
                    }
                }
                Err(TryRecvError::Empty) => return Ok(()),
                Err(TryRecvError::Disconnected) => {
                    self.plan_events = None;
                    if !self.motion.records.is_complete() {
                        return Err("the planner thread ended before the plan did".into());
                    }
                    return Ok(());
                }
            }
        }
    }

    /// Pushes checked slots while the margin allows, and checks more stops (for at most `slice`:
    /// they run until all are checked, so that they stay as far ahead of the motion as the start
    /// rule, [`plan_geometry::checked_far_enough`], counted on). Returns whether it
    /// did anything (false: waiting for a streamed plan, or nothing left to do).
    fn fill(&mut self, slice: Duration) -> Result<bool, String> {
        let started = Instant::now();
        let mut progressed = false;
        loop {
            self.receive()?;
            while self.started && self.buffered() < self.margin {
                let Some(&(slot, time)) = self.ready.front() else {
                    break;
                };
                match self.channel.segments.push(&slot) {
                    Ok(()) => {
                        progressed = true;
                        self.ready.pop_front();
                        self.ready_time -= time;
                        let end = self.ends[self.sent()] + time;
                        self.ends.push(end);
                        self.channel.set_planned_time(end);
                    }
                    Err(ChannelError::Full) => break,
                    Err(e) => return Err(format!("channel: {e:?}")),
                }
            }
            if self.all_checked || started.elapsed() >= slice {
                return Ok(progressed);
            }
            let Streamer { motion, arena, .. } = self;
            match motion.records.next(&mut |values| arena.put(values))? {
                Next::Slot(slot, time, choice) => {
                    progressed = true;
                    self.ready.push_back((slot, time));
                    self.ready_time += time;
                    self.worst = self.worst.max(choice.ratio);
                    self.stored += usize::from(choice.stored > 0);
                }
                Next::Working => progressed = true,
                Next::Waiting => return Ok(progressed),
                Next::Done => {
                    self.all_checked = true;
                    self.report();
                }
            }
        }
    }

    fn report(&self) {
        eprintln!(
            "nurbs-planner: underrun stops checked after every record: worst {:.4} x an axis limit{}{}",
            self.worst,
            if self.stored > 0 {
                format!(
                    " ({} of them stored stop sequences, VPOp's deceleration at the end)",
                    self.stored
                )
            } else {
                String::new()
            },
            // The verifier's rounding slack: stored VPOp positions are evaluated by the module's
            // de Boor code, which rounds differently from VPOp's power basis.
            if self.worst <= 1.0 + nurbs_motion::planner::verify::SLACK {
                ""
            } else {
                " (EXCEEDS the limits at some boundary)"
            }
        );
    }

    fn done(&self) -> bool {
        self.all_checked && self.ready.is_empty()
    }
}

/// Plans the whole path, or the rest of it from the module's underrun stop point `from`,
/// publishes the geometry once the module has emptied the ring, and queues the first records.
fn start_motion<'a>(
    args: &Args,
    shared: &'a Arc<Toolpath>,
    limits: &Limits,
    channel: &'a Channel,
    from: Option<&StopPoint>,
) -> Result<Streamer<'a>, String> {
    if let Some(p) = from {
        eprintln!(
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
    let toolpath: &'a Toolpath = shared;
    let (motion, plan_events) = if args.stream {
        // The planner runs in a thread of its own; its events wait in the channel until the
        // geometry is published and the checks take them.
        let (sender, receiver) = mpsc::channel();
        let (path, plan_limits, start) = (Arc::clone(shared), limits.clone(), from.copied());
        std::thread::spawn(move || {
            plan_geometry::stream_plan(&path, &plan_limits, start.as_ref(), &mut |e| sender.send(e).is_ok())
        });
        let motion = plan_geometry::streamed_motion(toolpath, limits, args.stop_fraction)?;
        (motion, Some(receiver))
    } else {
        let motion = plan_geometry::motion(toolpath, limits, args.planner.into(), from, args.stop_fraction)?;
        (motion, None)
    };
    eprintln!("nurbs-planner: {}", motion.summary);
    // A motion of an earlier planner may still be queued: the module empties the ring once
    // that motion is over (finished, aborted or stopped), and refuses a new geometry before.
    let waited = Instant::now();
    while !channel.segments.is_empty() {
        if stopped() || waited.elapsed() > Duration::from_secs(10) {
            return Err("the channel still holds records of a running motion".into());
        }
        std::thread::sleep(Duration::from_millis(5));
    }
    if let Some(p) = from {
        // An abort while we planned withdraws the stop point: then the plan is not wanted.
        if channel.stop.read().is_none_or(|now| now.epoch != p.epoch) {
            return Err("the stop point was withdrawn (abort) while planning from it".into());
        }
    }
    let arena = motion.geometry.publish(channel)?;
    let total = motion.motion_time;
    let mut streamer = Streamer {
        channel,
        motion,
        arena,
        plan_events,
        ready: VecDeque::new(),
        ready_time: 0.0,
        ends: vec![0.0],
        margin: args.margin,
        started: false,
        all_checked: false,
        worst: 0.0,
        stored: 0,
    };
    // Check stops until the checks can stay ahead of the motion to its end (nothing goes into the
    // ring before: a plan that fails by then moves nothing), then queue what the margin allows,
    // before hal_ready: `loadusr -W` returns with data in place.
    let began = Instant::now();
    loop {
        if !streamer.fill(CHECK_SLICE)? {
            if stopped() {
                return Err("stopped by signal before the motion started".into());
            }
            std::thread::sleep(Duration::from_millis(1));
        }
        let checked = streamer.checked_time();
        let rate = checked / began.elapsed().as_secs_f64().max(1e-9);
        if streamer.all_checked || plan_geometry::checked_far_enough(checked, total, rate, args.margin) {
            break;
        }
    }
    streamer.started = true;
    while !streamer.done() && streamer.buffered() < streamer.margin && streamer.channel.segments.len() < SEGMENT_SLOTS {
        if !streamer.fill(CHECK_SLICE)? {
            std::thread::sleep(Duration::from_millis(1));
        }
    }
    let elapsed = began.elapsed().as_secs_f64();
    eprintln!(
        "nurbs-planner: first {} records ({:.3} s of motion) queued; stops of {:.3} s of motion{} checked in {:.3} s ({:.0} x the motion's pace)",
        streamer.sent(),
        streamer.buffered(),
        streamer.checked_time(),
        if total.is_finite() {
            format!(" of {total:.3} s")
        } else {
            " (planned so far)".into()
        },
        elapsed,
        streamer.checked_time() / elapsed.max(1e-9)
    );
    Ok(streamer)
}

fn run(args: &Args) -> Result<(), String> {
    let programmed = read_toolpath(&args.toolpath).map_err(|e| e.to_string())?;
    let limits = limits(args, programmed.tip_dim())?;
    // The same path `nurbs-plan plan` plans with the same chord tolerance (and `verify` checks).
    let prepared = prepare(&args.toolpath, args.round_corners, limits.chord_tolerance).map_err(|e| e.to_string())?;
    if let Some(r) = &prepared.rounding {
        eprintln!(
            "nurbs-planner: {} G1 corners rounded within {} mm (deviation {:.6} mm)",
            r.corners, limits.chord_tolerance, r.max_deviation
        );
    }
    let toolpath = Arc::new(prepared.toolpath);
    if args.stream && args.planner != Planner::Erwinski {
        return Err("--stream is for the erwinski planner (VPOp plans the whole path)".into());
    }
    if args.planner == Planner::Vpop {
        // Before touching HAL: a clear refusal, not a half-started component.
        plan_geometry::check_tip_path(&toolpath)?;
    }

    let comp = Component::new("nurbs-planner")?;
    let ready = comp.pin::<bool>("ready", HAL_OUT)?;
    let running = comp.pin::<bool>("running", HAL_OUT)?;
    let error = comp.pin::<bool>("error", HAL_OUT)?;
    let sent_pin = comp.pin::<u32>("records-sent", HAL_OUT)?;
    let buffered_pin = comp.pin::<f64>("buffered", HAL_OUT)?;
    let result = (|| {
        let channel = comp.attach_channel(Duration::from_secs(5))?;
        // The module may be standing where an underrun stopped it: then plan from there.
        let mut from = channel.stop.read();
        let mut streamer = start_motion(args, &toolpath, &limits, channel, from.as_ref())?;
        let show = |s: &Streamer| {
            sent_pin.set(s.sent() as u32);
            running.set(!s.done());
            buffered_pin.set(s.buffered());
        };
        show(&streamer);
        ready.set(true);
        comp.ready()?;
        while !stopped() {
            // A stop while we stream (hold, or an underrun: we were too slow): re-plan from where
            // the module stands; the module runs it after the command.
            if let Some(p) = channel.stop.read() {
                if from.is_none_or(|f| f.epoch != p.epoch) {
                    from = Some(p);
                    streamer = start_motion(args, &toolpath, &limits, channel, from.as_ref())?;
                }
            }
            streamer.fill(CHECK_SLICE)?;
            show(&streamer);
            std::thread::sleep(Duration::from_millis(1));
        }
        Ok(())
    })();
    if result.is_err() {
        error.set(true);
        running.set(false);
    }
    result
}

fn main() -> ExitCode {
    install_signal_handlers();
    let args = Args::parse();
    match run(&args) {
        Ok(()) => {
            eprintln!("nurbs-planner: stopped by signal, exiting cleanly");
            ExitCode::SUCCESS
        }
        Err(e) => {
            eprintln!("nurbs-planner: {e}");
            ExitCode::FAILURE
        }
    }
}
