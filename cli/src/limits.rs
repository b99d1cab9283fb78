//! The limit flags `nurbs-plan` and `nurbs-planner` share, and the LinuxCNC INI file they may come
//! from: one set of names, one way to read them.

use crate::placement::PlacementArgs;
use nurbs_motion::planner::fit::CORNER_ANGLE;
use nurbs_motion::planner::presets::{preset, Preset};
use nurbs_motion::planner::Limits;
use std::path::{Path, PathBuf};

/// Limits (mm, s) from flags; where a flag is not given, from a named limit set (`--limits`),
/// else from a LinuxCNC INI file (`--ini`). Axis lists are comma-separated in axis order; one
/// value applies to all axes.
#[derive(clap::Args, Clone, Debug, Default)]
pub struct LimitArgs {
    /// Programmed feed F (mm/s); default: `[NURBS]FEED` of --ini, else the lowest axis
    /// velocity.
    #[arg(long)]
    pub feed: Option<f64>,
    /// Axial acceleration limit(s) (mm/s^2); default: `[AXIS_X|Y|Z]MAX_ACCELERATION`.
    #[arg(long, value_delimiter = ',')]
    pub accel: Option<Vec<f64>>,
    /// Axial jerk limit(s) (mm/s^3); default: `[AXIS_X|Y|Z]MAX_JERK`.
    #[arg(long, value_delimiter = ',')]
    pub jerk: Option<Vec<f64>>,
    /// Axial velocity limit(s) (mm/s); default: `[AXIS_X|Y|Z]MAX_VELOCITY`, else the feed.
    #[arg(long, value_delimiter = ',')]
    pub vel: Option<Vec<f64>>,
    /// Chord error tolerance (mm); default: `[NURBS]CHORD_TOLERANCE`.
    #[arg(long = "chord-tol")]
    pub chord_tol: Option<f64>,
    /// Corner angle (degrees): a G1 corner that turns more, between lines long enough for the
    /// turn to be programmed, ends a run of short lines fitted by `--round-corners auto` (it
    /// stays rounded); default: `[NURBS]CORNER_ANGLE`, else 35.
    #[arg(long = "corner-angle", value_name = "DEG")]
    pub corner_angle: Option<f64>,
    /// Interpolation period (s): the servo thread's; default: `[EMCMOT]SERVO_PERIOD` (ns).
    #[arg(long)]
    pub period: Option<f64>,
    /// Share of every axis' jerk the (Erwinski) plan leaves unused so that a hold can brake at
    /// once where the plan would ride a jerk limit through the curvature; the stops and checks
    /// keep the full limits (0 <= R < 1; 0.13 brings a stop within 5 ms everywhere on the
    /// trident and the butterfly at lab set 1, for some 4.5 % more motion time); default:
    /// `[NURBS]HOLD_RESERVE`, else 0.
    #[arg(long = "hold-reserve", value_name = "R")]
    pub hold_reserve: Option<f64>,
    /// A named limit set for the limits not given as flags (`nurbs-plan presets` lists them).
    #[arg(long = "limits", value_name = "NAME")]
    pub preset: Option<String>,
    /// LinuxCNC INI file for the limits given neither as flags nor by --limits.
    #[arg(long)]
    pub ini: Option<PathBuf>,
    /// Where the toolpath's coordinates sit on the machine (default: they are machine
    /// coordinates).
    #[command(flatten)]
    pub placement: PlacementArgs,
}

impl LimitArgs {
    fn ini(&self) -> Result<Option<Ini>, String> {
        self.ini.as_deref().map(Ini::read).transpose()
    }

    fn preset(&self) -> Result<Option<&'static Preset>, String> {
        self.preset
            .as_deref()
            .map(|name| {
                preset(name).ok_or_else(|| {
                    let names: Vec<&str> = nurbs_motion::planner::presets::PRESETS.iter().map(|p| p.name).collect();
                    format!("no limit set {name}: one of {}", names.join(", "))
                })
            })
            .transpose()
    }

    /// `[section]key` of the INI as text, with the INI's name, if it has one.
    pub fn ini_text(&self, section: &str, key: &str) -> Result<Option<(String, String)>, String> {
        Ok(self
            .ini()?
            .and_then(|i| Some((i.text(section, key)?.to_owned(), i.file.display().to_string()))))
    }

    /// `[DISPLAY]MAX_FEED_OVERRIDE` of the INI, if it has one.
    pub fn ini_max_feed_override(&self) -> Result<Option<f64>, String> {
        self.ini()?
            .map_or(Ok(None), |i| i.number("DISPLAY", "MAX_FEED_OVERRIDE"))
    }

    /// The chord tolerance: `--chord-tol`, else the --limits set's, else
    /// `[NURBS]CHORD_TOLERANCE` of the INI.
    pub fn chord_tolerance(&self) -> Result<f64, String> {
        if let Some(t) = self.chord_tol.or(self.preset()?.map(|p| p.chord_tolerance)) {
            return Ok(t);
        }
        self.ini()?
            .map_or(Ok(None), |i| i.number("NURBS", "CHORD_TOLERANCE"))?
            .ok_or_else(|| "no chord tolerance: give --chord-tol or [NURBS]CHORD_TOLERANCE in --ini".into())
    }

    /// The corner angle (degrees): `--corner-angle`, else `[NURBS]CORNER_ANGLE` of the INI,
    /// else [`CORNER_ANGLE`]; an error outside 0..180.
    pub fn corner_angle(&self) -> Result<f64, String> {
        let angle = match self.corner_angle {
            Some(a) => a,
            None => self
                .ini()?
                .map_or(Ok(None), |i| i.number("NURBS", "CORNER_ANGLE"))?
                .unwrap_or(CORNER_ANGLE),
        };
        if !(angle > 0.0 && angle < 180.0) {
            return Err(format!("corner angle {angle}: more than 0 and less than 180 degrees"));
        }
        Ok(angle)
    }

    /// The machine's travel from `--ini` (`[AXIS_X|Y|Z]MIN_LIMIT`, `MAX_LIMIT`; an axis without
    /// them is not bounded); `None` without `--ini`.
    pub fn travel(&self) -> Result<Option<Travel>, String> {
        let Some(ini) = self.ini()? else {
            return Ok(None);
        };
        let (mut min, mut max) = (Vec::new(), Vec::new());
        for axis in ["AXIS_X", "AXIS_Y", "AXIS_Z"] {
            min.push(ini.number(axis, "MIN_LIMIT")?.unwrap_or(f64::NEG_INFINITY));
            max.push(ini.number(axis, "MAX_LIMIT")?.unwrap_or(f64::INFINITY));
        }
        Ok(Some(Travel {
            min,
            max,
            source: ini
                .file
                .file_name()
                .map_or_else(|| ini.file.display().to_string(), |f| f.to_string_lossy().into_owned()),
        }))
    }

    /// The limits of an `axes`-axis path (flags first, then the named set, then the INI),
    /// checked.
    pub fn limits(&self, axes: usize) -> Result<Limits, String> {
        let named = self.preset()?;
        let list = |v: &'static [f64]| (!v.is_empty()).then(|| v.to_vec());
        let flags = LimitArgs {
            feed: self.feed.or(named.map(|p| p.feed)),
            accel: self.accel.clone().or(named.and_then(|p| list(p.acceleration))),
            jerk: self.jerk.clone().or(named.and_then(|p| list(p.jerk))),
            vel: self.vel.clone().or(named.and_then(|p| list(p.velocity))),
            chord_tol: self.chord_tol.or(named.map(|p| p.chord_tolerance)),
            corner_angle: self.corner_angle,
            period: self.period.or(named.map(|p| p.period)),
            hold_reserve: self.hold_reserve,
            preset: None,
            ini: self.ini.clone(),
            placement: self.placement.clone(),
        };
        flags.resolve(axes)
    }

    /// [`LimitArgs::limits`] of the flags and the INI alone.
    fn resolve(&self, axes: usize) -> Result<Limits, String> {
        let ini = self.ini()?;
        let section = |section: &str, key: &str| ini.as_ref().map_or(Ok(None), |i| i.number(section, key));
        let per_axis = |key: &str| ini.as_ref().map_or(Ok(None), |i| i.per_axis(key, axes));
        let period = match self.period {
            Some(p) => p,
            None => section("EMCMOT", "SERVO_PERIOD")?
                .map(|ns| ns / 1e9)
                .ok_or("no period: give --period or [EMCMOT]SERVO_PERIOD in --ini")?,
        };
        let vel = match &self.vel {
            Some(v) => Some(v.clone()),
            None => per_axis("MAX_VELOCITY")?,
        };
        let feed = match self.feed {
            Some(f) => f,
            None => match section("NURBS", "FEED")? {
                Some(f) => f,
                None => vel
                    .as_ref()
                    .and_then(|v| v.iter().copied().reduce(f64::min))
                    .ok_or("no feed: give --feed, [NURBS]FEED or the axis velocities")?,
            },
        };
        let need = |flag: &Option<Vec<f64>>, key: &str, name: &str| -> Result<Vec<f64>, String> {
            match flag {
                Some(v) => Ok(v.clone()),
                None => per_axis(key)?.ok_or(format!("no {name} limit: give --{name} or [AXIS_X|Y|Z]{key} in --ini")),
            }
        };
        Limits {
            feed,
            velocity: vel.unwrap_or_else(|| vec![feed]),
            acceleration: need(&self.accel, "MAX_ACCELERATION", "accel")?,
            jerk: need(&self.jerk, "MAX_JERK", "jerk")?,
            chord_tolerance: self.chord_tolerance()?,
            period,
            hold_reserve: match self.hold_reserve {
                Some(r) => r,
                None => section("NURBS", "HOLD_RESERVE")?.unwrap_or(0.0),
            },
        }
        .for_axes(axes)
        .map_err(|e| e.to_string())
    }
}

/// The machine's travel per axis X, Y, Z (mm; infinite where the INI does not bound an axis).
#[derive(Clone, Debug)]
pub struct Travel {
    pub min: Vec<f64>,
    pub max: Vec<f64>,
    /// The INI file's name, for messages.
    pub source: String,
}

/// `[SECTION]KEY` lookup in a LinuxCNC INI file (first occurrence wins, as in LinuxCNC).
struct Ini {
    file: PathBuf,
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
        Ok(Ini {
            file: path.to_owned(),
            entries,
        })
    }

    fn text(&self, section: &str, key: &str) -> Option<&str> {
        self.entries
            .iter()
            .find(|(s, k, _)| s == section && k == key)
            .map(|(_, _, v)| v.as_str())
    }

    fn number(&self, section: &str, key: &str) -> Result<Option<f64>, String> {
        match self.text(section, key) {
            None => Ok(None),
            Some(v) => v
                .parse()
                .map(Some)
                .map_err(|_| format!("{}: [{section}]{key} = {v} is not a number", self.file.display())),
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
