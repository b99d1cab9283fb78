//! Limit sets shared by the test suites and the benches, as `Limits` and as `nurbs-plan`
//! arguments: the VPOp paper's trident limits, its Table 1 limits of the XYZAC
//! machine, and lab set 1 of Erwinski et al. 2022.
#![allow(dead_code)] // each crate that includes this file uses a different subset

use nurbs_motion::planner::Limits;

/// The VPOp paper's limits of the trident (F 166.667 mm/s, per-axis X/Y limits, chord tolerance
/// 0.02 mm, dt 6 ms).
pub fn trident_vpop() -> Limits {
    Limits {
        feed: 166.667,
        velocity: vec![500.0, 500.0],
        acceleration: vec![2500.0, 3000.0],
        jerk: vec![5000.0, 5000.0],
        chord_tolerance: 0.02,
        period: 0.006,
    }
}

/// `trident_vpop` as `nurbs-plan` arguments.
pub const TRIDENT_VPOP: [&str; 12] = [
    "--feed",
    "166.667",
    "--vel",
    "500,500",
    "--accel",
    "2500,3000",
    "--jerk",
    "5000,5000",
    "--chord-tol",
    "0.02",
    "--period",
    "0.006",
];

/// The paper's Table 1 limits of the XYZAC machine (joint order x, y, z, a, c; rotary in
/// degrees).
pub fn table1() -> Limits {
    Limits {
        feed: 83.333,
        velocity: vec![500.0, 500.0, 500.0, 90.0, 120.0],
        acceleration: vec![2500.0, 3000.0, 2100.0, 298.8, 298.8],
        jerk: vec![5000.0, 5000.0, 50000.0, 1800.0, 36000.0],
        chord_tolerance: 0.02,
        period: 0.006,
    }
}

/// `table1` as `nurbs-plan` arguments.
pub const TABLE1: [&str; 12] = [
    "--feed",
    "83.333",
    "--vel",
    "500,500,500,90,120",
    "--accel",
    "2500,3000,2100,298.8,298.8",
    "--jerk",
    "5000,5000,50000,1800,36000",
    "--chord-tol",
    "0.02",
    "--period",
    "0.006",
];

/// Table 1's linear axes as tool-tip limits (`nurbs-plan` arguments): X, Y, Z of the XYZAC
/// machine applied to the tool tip.
pub const TABLE1_TIP: [&str; 12] = [
    "--feed",
    "83.333",
    "--vel",
    "500",
    "--accel",
    "2500,3000,2100",
    "--jerk",
    "5000,5000,50000",
    "--chord-tol",
    "0.02",
    "--period",
    "0.006",
];

/// The VPOp paper's limits of a 3-axis tool-tip path (F 166.667 mm/s; X, Y, Z of Table 1).
pub fn tip_vpop() -> Limits {
    Limits {
        feed: 166.667,
        velocity: vec![500.0, 500.0, 500.0],
        acceleration: vec![2500.0, 3000.0, 2100.0],
        jerk: vec![5000.0, 5000.0, 50000.0],
        chord_tolerance: 0.02,
        period: 0.006,
    }
}

/// `tip_vpop` as `nurbs-plan` arguments.
pub const TIP_VPOP: [&str; 12] = [
    "--feed",
    "166.667",
    "--vel",
    "500",
    "--accel",
    "2500,3000,2100",
    "--jerk",
    "5000,5000,50000",
    "--chord-tol",
    "0.02",
    "--period",
    "0.006",
];

/// Lab set 1 of Erwinski et al. 2022 (F 2500 mm/s, A 1e4, J 6e4, chord 1 µm, dt 0.25 ms) on `dim` axes.
pub fn lab1(dim: usize) -> Limits {
    Limits::uniform(dim, 2500.0, 1e4, 6e4, 0.001, 0.00025)
}

/// `lab1` as `nurbs-plan` arguments.
pub const LAB1: [&str; 10] = [
    "--feed",
    "2500",
    "--accel",
    "1e4",
    "--jerk",
    "6e4",
    "--chord-tol",
    "0.001",
    "--period",
    "0.00025",
];
