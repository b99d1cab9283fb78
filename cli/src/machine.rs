//! `--machine`, the geometry flags (`--rot-point`, `--kins-offset`, `--tool-offset`: the pins of
//! LinuxCNC's `xyzac-trt-kins` / `xyzbc-trt-kins`) and `--negative-tilt`: the kinematics a
//! 5-axis toolpath (tool tip and top curve on every element) is planned and verified on. Built
//! here, in one place, for `plan` and `verify`, so that `verify` recovers the tool tip with the
//! kinematics `plan` used.

use nurbs_motion::geometry::Toolpath;
use nurbs_motion::kinematics::{TableTilting, Tilt, TrtGeometry};

/// Machine structures by name. Another structure is another variant here and another arm in
/// [`MachineArgs::kinematics`].
#[derive(clap::ValueEnum, Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum MachineKind {
    /// Table-tilting XYZAC (Mikron UCP 710 type, LinuxCNC `xyzac-trt-kins`): the tool stays
    /// along Z, the table tilts about X (A) and rotates about its own normal (C).
    #[default]
    Xyzac,
    /// Table-tilting XYZBC (LinuxCNC `xyzbc-trt-kins`): the table tilts about Y (B) and rotates
    /// about its own normal (C). Joints and limits in order x, y, z, b, c.
    Xyzbc,
}

/// A point or offset `X,Y,Z` (mm).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Xyz(pub [f64; 3]);

impl std::str::FromStr for Xyz {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let values: Vec<f64> = s
            .split(',')
            .map(|v| v.trim().parse::<f64>().ok().filter(|x| x.is_finite()))
            .collect::<Option<_>>()
            .ok_or_else(|| format!("expected three finite numbers X,Y,Z (mm), got '{s}'"))?;
        let xyz: [f64; 3] = values
            .try_into()
            .map_err(|v: Vec<f64>| format!("expected three numbers X,Y,Z (mm), got {}", v.len()))?;
        Ok(Xyz(xyz))
    }
}

/// Machine flags shared by `plan` and `verify`; they apply to 5-axis toolpaths only.
#[derive(clap::Args, Clone, Debug, Default)]
pub struct MachineArgs {
    /// Kinematics of the 5-axis machine (default `xyzac`) for a toolpath with a top curve on
    /// every element (--planner vpop); refused for 2-/3-axis paths.
    #[arg(long, value_enum, value_name = "NAME")]
    pub machine: Option<MachineKind>,
    /// A point on the C axis in the workpiece frame at zero angles, mm: the kinematics'
    /// `x/y/z-rot-point` pins (default 0,0,0: the program origin on the rotary centre). With
    /// zero offsets the tilt (A or B) axis passes through it too. `verify` needs the same value.
    #[arg(long, value_name = "X,Y,Z", allow_hyphen_values = true)]
    pub rot_point: Option<Xyz>,
    /// The tilt axis's offset from the rotation point, mm: the kinematics' `x/y/z-offset` pins
    /// (XYZAC uses y and z, XYZBC x and z; default 0,0,0).
    #[arg(long, value_name = "X,Y,Z", allow_hyphen_values = true)]
    pub kins_offset: Option<Xyz>,
    /// The kinematics' `tool-offset` pin, mm (the loaded tool's length, `motion.tooloffset.z`;
    /// LinuxCNC adds it to the z offset; default 0).
    #[arg(long, value_name = "MM", allow_hyphen_values = true, value_parser = finite)]
    pub tool_offset: Option<f64>,
    /// Use the second solution of the inverse kinematics: tilt angle (A or B) <= 0 and C turned
    /// by 180° (default: tilt >= 0). `verify` accepts either: the joints' forward kinematics
    /// are the same on both branches.
    #[arg(long)]
    pub negative_tilt: bool,
}

impl MachineArgs {
    /// The flags given on the command line, for messages (`None`: none given).
    pub fn given(&self) -> Option<String> {
        let flags: Vec<&str> = [
            (self.machine.is_some(), "--machine"),
            (self.rot_point.is_some(), "--rot-point"),
            (self.kins_offset.is_some(), "--kins-offset"),
            (self.tool_offset.is_some(), "--tool-offset"),
            (self.negative_tilt, "--negative-tilt"),
        ]
        .into_iter()
        .filter_map(|(given, name)| given.then_some(name))
        .collect();
        (!flags.is_empty()).then(|| flags.join(", "))
    }

    /// The machine the flags describe.
    pub fn kinematics(&self) -> TableTilting {
        TableTilting {
            geometry: TrtGeometry {
                tilt: match self.machine.unwrap_or_default() {
                    MachineKind::Xyzac => Tilt::X,
                    MachineKind::Xyzbc => Tilt::Y,
                },
                rot_point: self.rot_point.map_or([0.0; 3], |p| p.0),
                offset: self.kins_offset.map_or([0.0; 3], |p| p.0),
                tool_offset: self.tool_offset.unwrap_or(0.0),
            },
            negative_tilt: self.negative_tilt,
        }
    }

    /// Summary JSON fields: the machine's name and geometry.
    pub fn summary_fields(&self) -> serde_json::Value {
        use clap::ValueEnum;
        let name = self
            .machine
            .unwrap_or_default()
            .to_possible_value()
            .map(|v| v.get_name().to_owned());
        let k = self.kinematics();
        let g = k.geometry;
        serde_json::json!({
            "machine": name,
            "rot_point_mm": g.rot_point,
            "kins_offset_mm": g.offset,
            "tool_offset_mm": g.tool_offset,
            "negative_tilt": k.negative_tilt,
        })
    }

    /// Fails with `reason` when a machine flag was given (where no kinematics is used, a
    /// silently ignored geometry would hide a mistake).
    pub fn refuse(&self, reason: &str) -> Result<(), String> {
        match self.given() {
            Some(flags) => Err(format!("{flags}: {reason}")),
            None => Ok(()),
        }
    }

    /// Fails when a machine flag was given for a toolpath that is not 5-axis.
    pub fn refuse_unless_five_axis(&self, toolpath: &Toolpath, file: &std::path::Path) -> Result<(), String> {
        if is_five_axis(toolpath) {
            return Ok(());
        }
        self.refuse(&format!(
            "{} is a {}-axis tool-tip path; machine kinematics apply only to 5-axis toolpaths (a top curve on every element)",
            file.display(),
            toolpath.tip_dim()
        ))
    }
}

/// `--tool-offset`: a finite number.
fn finite(s: &str) -> Result<f64, String> {
    s.trim()
        .parse::<f64>()
        .ok()
        .filter(|x| x.is_finite())
        .ok_or_else(|| format!("expected a finite number (mm), got '{s}'"))
}

/// A tool tip and a top curve (tool axis), both 3-D, on every element.
pub fn is_five_axis(toolpath: &Toolpath) -> bool {
    !toolpath.elements.is_empty()
        && toolpath
            .elements
            .iter()
            .all(|e| e.curve.dim() == 6 && e.curve.tip_dim() == 3)
}

/// `nurbs-plan kinematics`: poses from stdin through the machine's inverse (or forward)
/// kinematics to stdout.
pub fn run_kinematics(machine: &MachineArgs, forward: bool) -> Result<(), String> {
    use std::io::{BufRead, Write};
    if machine.negative_tilt {
        return Err("--negative-tilt: a world pose names its angles, so no branch is chosen here".into());
    }
    let geometry = machine.kinematics().geometry;
    let stdout = std::io::stdout();
    let mut out = std::io::BufWriter::new(stdout.lock());
    for (n, line) in std::io::stdin().lock().lines().enumerate() {
        let line = line.map_err(|e| format!("stdin: {e}"))?;
        if line.trim().is_empty() {
            continue;
        }
        let pose: [f64; 5] = line
            .split_whitespace()
            .map(|v| v.parse::<f64>().ok().filter(|x| x.is_finite()))
            .collect::<Option<Vec<f64>>>()
            .and_then(|v| v.try_into().ok())
            .ok_or_else(|| {
                format!(
                    "stdin line {}: expected five finite numbers x y z tilt c, got '{line}'",
                    n + 1
                )
            })?;
        let result = if forward {
            geometry.world(pose)
        } else {
            geometry.joints(pose)
        };
        let text: Vec<String> = result.iter().map(f64::to_string).collect();
        writeln!(out, "{}", text.join(" ")).map_err(|e| format!("stdout: {e}"))?;
    }
    out.flush().map_err(|e| format!("stdout: {e}"))
}
