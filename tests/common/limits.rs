//! The limit sets of the test suites and the benches: the library's named presets
//! (`nurbs_motion::planner::presets`), as `Limits` and as `nurbs-plan` arguments.
#![allow(dead_code)] // each crate that includes this file uses a different subset

use nurbs_motion::planner::presets::named;
use nurbs_motion::planner::Limits;

/// The VPOp paper's limits of the trident (X, Y).
pub fn trident_vpop() -> Limits {
    named("vpop-trident").on(2)
}

/// `trident_vpop` as `nurbs-plan` arguments.
pub const TRIDENT_VPOP: [&str; 2] = ["--limits", "vpop-trident"];

/// The VPOp paper's Table 1 limits of the XYZAC machine (joint order x, y, z, a, c).
pub fn table1() -> Limits {
    named("vpop-table1").on(5)
}

/// `table1` as `nurbs-plan` arguments.
pub const TABLE1: [&str; 2] = ["--limits", "vpop-table1"];

/// Table 1's linear axes as tool-tip limits (`nurbs-plan` arguments).
pub const TABLE1_TIP: [&str; 2] = ["--limits", "vpop-table1-tip"];

/// The VPOp paper's limits of a 3-axis tool-tip path (X, Y, Z of Table 1 at the trident's feed).
pub fn tip_vpop() -> Limits {
    named("vpop-tip").on(3)
}

/// `tip_vpop` as `nurbs-plan` arguments.
pub const TIP_VPOP: [&str; 2] = ["--limits", "vpop-tip"];

/// Lab set 1 of Erwinski et al. 2022 on `dim` axes.
pub fn lab1(dim: usize) -> Limits {
    named("lab1").on(dim)
}

/// `lab1` as `nurbs-plan` arguments.
pub const LAB1: [&str; 2] = ["--limits", "lab1"];
