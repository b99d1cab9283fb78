//! `nurbs-hal-record`: write every sample of a LinuxCNC `sampler` stream at full precision.
//!
//! `halsampler` prints floats with `%f` (6 decimals); this reader attaches to the same stream and
//! prints Rust's shortest round-trip form, so a check can compare positions bit for bit.
//! Output: one line per sample, `SAMPLENO v0 v1 ...` (bits as 0/1).
//!
//! `loadusr -w nurbs-hal-record (--samples N | --until-idle SECONDS) --out FILE [--channel C]
//! [--timeout SECONDS]`: stop after N samples, or once no sample came for SECONDS after the
//! first one (for runs whose sample count is not known in advance, e.g. an underrun stop).

use std::io::Write;
use std::process::ExitCode;
use std::time::{Duration, Instant};

use nurbs_planner::hal_user::{install_signal_handlers, stopped, Component, StreamReader, StreamValue};
use nurbs_planner::say;

/// `SAMPLER_SHMEM_KEY` of LinuxCNC's streamer.h; channel n uses key + n.
const SAMPLER_SHMEM_KEY: i32 = 0x4853_4130;

fn run() -> Result<(), String> {
    let (mut samples, mut out, mut channel, mut timeout) = (None, None, 0i32, 30.0f64);
    let mut until_idle: Option<f64> = None;
    let mut it = std::env::args().skip(1);
    while let Some(a) = it.next() {
        let mut value = || it.next().ok_or(format!("{a} needs a value"));
        match a.as_str() {
            "--samples" => samples = Some(value()?.parse::<u64>().map_err(|e| e.to_string())?),
            "--out" => out = Some(value()?),
            "--until-idle" => {
                until_idle = Some(value()?.parse().map_err(|e: std::num::ParseFloatError| e.to_string())?)
            }
            "--channel" => channel = value()?.parse().map_err(|e: std::num::ParseIntError| e.to_string())?,
            "--timeout" => timeout = value()?.parse().map_err(|e: std::num::ParseFloatError| e.to_string())?,
            other => return Err(format!("unknown argument {other}")),
        }
    }
    let samples = match (samples, until_idle) {
        (Some(n), _) => n,
        (None, Some(_)) => u64::MAX,
        (None, None) => return Err("--samples N or --until-idle SECONDS is required".into()),
    };
    let path = out.ok_or("--out FILE is required")?;
    let mut file = std::io::BufWriter::new(std::fs::File::create(&path).map_err(|e| format!("{path}: {e}"))?);

    let comp = Component::new(&format!("nurbs-hal-record{channel}"))?;
    comp.ready()?;
    let mut reader = StreamReader::attach(&comp, SAMPLER_SHMEM_KEY + channel)?;
    let mut got = 0u64;
    let mut last_data = Instant::now();
    while got < samples {
        if stopped() {
            return Err(format!("stopped after {got} of {samples} samples"));
        }
        match reader.read()? {
            Some((n, values)) => {
                write!(file, "{n}").map_err(|e| e.to_string())?;
                for v in values {
                    match v {
                        StreamValue::Float(x) => write!(file, " {x:?}"),
                        StreamValue::Bit(b) => write!(file, " {}", b as u8),
                        StreamValue::U32(u) => write!(file, " {u}"),
                        StreamValue::S32(s) => write!(file, " {s}"),
                    }
                    .map_err(|e| e.to_string())?;
                }
                writeln!(file).map_err(|e| e.to_string())?;
                got += 1;
                last_data = Instant::now();
            }
            None => {
                if got > 0 && until_idle.is_some_and(|idle| last_data.elapsed().as_secs_f64() > idle) {
                    break;
                }
                if last_data.elapsed().as_secs_f64() > timeout {
                    return Err(format!(
                        "no data for {timeout} s after {got} of {samples} samples (rtapi_app dead?)"
                    ));
                }
                std::thread::sleep(Duration::from_micros(500));
            }
        }
    }
    file.flush().map_err(|e| e.to_string())
}

fn main() -> ExitCode {
    install_signal_handlers();
    match run() {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            say!("nurbs-hal-record: {e}");
            ExitCode::FAILURE
        }
    }
}
