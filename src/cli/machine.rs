//! `--machine` and `--pivot`: the kinematics a 5-axis toolpath (tool tip and top curve on
//! every element) is planned and verified on. Built here, in one place, for `plan` and
//! `verify`, so that `verify` recovers the tool tip with the kinematics `plan` used.

use crate::geometry::Toolpath;
use crate::kinematics::Xyzac;

/// Machine structures by name. Another structure is another variant here and another arm in
/// [`MachineArgs::kinematics`].
#[derive(clap::ValueEnum, Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum MachineKind {
    /// Table-tilting XYZAC (Mikron UCP 710 type): the tool stays along Z, the table tilts about
    /// X (A) and rotates about its own normal (C).
    #[default]
    Xyzac,
}

/// `--pivot X,Y,Z` (mm).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Pivot(pub [f64; 3]);

impl std::str::FromStr for Pivot {
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
        Ok(Pivot(xyz))
    }
}

/// Machine flags shared by `plan` and `verify`; they apply to 5-axis toolpaths only.
#[derive(clap::Args, Clone, Debug, Default)]
pub struct MachineArgs {
    /// Kinematics of the 5-axis machine (default `xyzac`) for a toolpath with a top curve on
    /// every element (--planner vpop); refused for 2-/3-axis paths.
    #[arg(long, value_enum, value_name = "NAME")]
    pub machine: Option<MachineKind>,
    /// xyzac: the point where the A and C axes meet, in workpiece (program) coordinates, mm
    /// (default 0,0,0: the program origin on the rotary centre). `verify` needs the same value.
    #[arg(long, value_name = "X,Y,Z", allow_hyphen_values = true)]
    pub pivot: Option<Pivot>,
}

impl MachineArgs {
    /// The flags given on the command line, for messages (`None`: none given).
    fn given(&self) -> Option<&'static str> {
        match (self.machine.is_some(), self.pivot.is_some()) {
            (false, false) => None,
            (true, false) => Some("--machine"),
            (false, true) => Some("--pivot"),
            (true, true) => Some("--machine and --pivot"),
        }
    }

    /// The machine the flags describe.
    pub fn kinematics(&self) -> Xyzac {
        match self.machine.unwrap_or_default() {
            MachineKind::Xyzac => Xyzac {
                pivot: self.pivot.map_or([0.0; 3], |p| p.0),
                ..Xyzac::default()
            },
        }
    }

    /// Summary JSON fields: the machine's name and geometry.
    pub fn summary_fields(&self) -> serde_json::Value {
        use clap::ValueEnum;
        let kind = self.machine.unwrap_or_default();
        let name = kind.to_possible_value().map(|v| v.get_name().to_owned());
        match kind {
            MachineKind::Xyzac => serde_json::json!({ "machine": name, "pivot_mm": self.kinematics().pivot }),
        }
    }

    /// Fails with `reason` when a machine flag was given (where no kinematics is used, a
    /// silently ignored pivot would hide a mistake).
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

/// A tool tip and a top curve (tool axis), both 3-D, on every element.
pub fn is_five_axis(toolpath: &Toolpath) -> bool {
    !toolpath.elements.is_empty()
        && toolpath
            .elements
            .iter()
            .all(|e| e.curve.dim() == 6 && e.curve.tip_dim() == 3)
}
