//! `nurbs-planner`: the userspace planner component (`loadusr -W nurbs-planner ...`).
//!
//! SPIKE: streams synthetic segment records to the realtime module `nurbs_interp` through the
//! shared-memory channel, keeping it full. INTEGRATION POINT: the planner of `nurbs_motion`
//! produces the records (and the curve geometry) instead of `synthetic_record`.
//!
//! Pins: `nurbs-planner.ready` (bit out: attached, first records queued), `.running` (bit out:
//! records remain to be sent), `.error` (bit out), `.records-sent` (u32 out).
//! Exits on SIGTERM/SIGINT (what `halcmd unload` and halrun's shutdown send).

use std::io::Write;
use std::process::ExitCode;
use std::time::Duration;

use nurbs_hal::channel::{ChannelError, SegmentRecord};
use nurbs_hal::sys::HAL_OUT;
use nurbs_hal::user::{install_signal_handlers, stopped, Component};

struct Args {
    records: u32,
    dump: Option<String>,
}

fn parse_args() -> Result<Args, String> {
    let mut args = Args {
        records: 1000,
        dump: None,
    };
    let mut it = std::env::args().skip(1);
    while let Some(a) = it.next() {
        match a.as_str() {
            "--records" => {
                args.records = it
                    .next()
                    .and_then(|v| v.parse().ok())
                    .ok_or("--records N")?
            }
            "--dump" => args.dump = Some(it.next().ok_or("--dump FILE")?),
            other => return Err(format!("unknown argument {other}")),
        }
    }
    Ok(args)
}

/// Deterministic values whose decimal expansions need all 17 digits.
fn synthetic_record(seq: u32) -> SegmentRecord {
    let k = seq as f64;
    SegmentRecord {
        seq,
        s_start: k * 0.001 + k.sqrt() * 1e-7,
        u_start: k / 3.0,
        feed_start: 10.0 + k,
        ..SegmentRecord::default()
    }
}

fn run(args: &Args) -> Result<(), String> {
    let comp = Component::new("nurbs-planner")?;
    let ready = comp.pin::<bool>("ready", HAL_OUT)?;
    let running = comp.pin::<bool>("running", HAL_OUT)?;
    let error = comp.pin::<bool>("error", HAL_OUT)?;
    let sent_pin = comp.pin::<u32>("records-sent", HAL_OUT)?;
    let result = (|| {
        let channel = comp.attach_channel(Duration::from_secs(5))?;
        let mut dump = match &args.dump {
            Some(path) => Some(std::io::BufWriter::new(
                std::fs::File::create(path).map_err(|e| format!("{path}: {e}"))?,
            )),
            None => None,
        };
        let mut sent = 0u32;
        let mut fill = |sent: &mut u32| -> Result<(), String> {
            while *sent < args.records {
                let record = synthetic_record(*sent);
                match channel.segments.push(&record) {
                    Ok(()) => {}
                    Err(ChannelError::Full) => break,
                    Err(e) => return Err(format!("channel: {e:?}")),
                }
                if let Some(d) = dump.as_mut() {
                    writeln!(
                        d,
                        "{} {:?} {:?} {:?}",
                        record.seq, record.s_start, record.u_start, record.feed_start
                    )
                    .map_err(|e| e.to_string())?;
                }
                *sent += 1;
            }
            Ok(())
        };
        // Queue what fits before hal_ready, so `loadusr -W` returns with data in place.
        fill(&mut sent)?;
        sent_pin.set(sent);
        running.set(sent < args.records);
        ready.set(true);
        comp.ready()?;
        while !stopped() {
            fill(&mut sent)?;
            sent_pin.set(sent);
            running.set(sent < args.records);
            std::thread::sleep(Duration::from_millis(1));
        }
        if let Some(d) = dump.as_mut() {
            d.flush().map_err(|e| e.to_string())?;
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
    let args = match parse_args() {
        Ok(a) => a,
        Err(e) => {
            eprintln!("nurbs-planner: {e}");
            return ExitCode::from(2);
        }
    };
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
