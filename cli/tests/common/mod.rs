//! The shared helpers of the test suites (`tests/common/` of the workspace root) and those that
//! run the `nurbs-plan` binary, which only this package's tests can name.
#![allow(dead_code)] // each test file uses a different subset

#[path = "../../../tests/common/mod.rs"]
mod shared;
pub use shared::*;

use std::path::{Path, PathBuf};
use std::process::Command;

/// The `nurbs-plan` binary.
pub fn nurbs_plan() -> Command {
    Command::new(env!("CARGO_BIN_EXE_nurbs-plan"))
}

/// `nurbs-plan verify csv program limits`.
pub fn verify_cli(csv: &Path, program: &Path, limits: &[&str]) -> std::process::Output {
    nurbs_plan()
        .arg("verify")
        .arg(csv)
        .arg(program)
        .args(limits)
        .output()
        .unwrap()
}

/// `nurbs-plan verify` passes on `csv` planned from `program` under `limits`.
pub fn assert_verifies(csv: &Path, program: &Path, limits: &[&str]) {
    let out = verify_cli(csv, program, limits);
    assert!(
        out.status.success(),
        "{}: {}{}",
        csv.display(),
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
}

/// `nurbs-plan plan program --planner planner limits --out csv` must succeed; returns `csv`.
pub fn plan_cli(program: &Path, planner: &str, limits: &[&str], csv: &Path) -> PathBuf {
    let out = nurbs_plan()
        .arg("plan")
        .arg(program)
        .args(["--planner", planner])
        .arg("--out")
        .arg(csv)
        .args(limits)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{} {planner}: {}",
        program.display(),
        String::from_utf8_lossy(&out.stderr)
    );
    csv.to_path_buf()
}

/// [`plan_cli`], and `nurbs-plan verify` must accept its setpoints under the same limits;
/// returns `csv`.
pub fn plan_and_verify_cli(program: &Path, planner: &str, limits: &[&str], csv: &Path) -> PathBuf {
    plan_cli(program, planner, limits, csv);
    assert_verifies(csv, program, limits);
    csv.to_path_buf()
}

/// `verify` must refuse `csv` of `program` under `limits` with `flag` made tighter (`tighter`,
/// given after them: a flag wins over a named set).
pub fn assert_tighter_limit_fails(csv: &Path, program: &Path, limits: &[&str], flag: &str, tighter: &str) {
    let tight = [limits, &[flag, tighter]].concat();
    let bad = verify_cli(csv, program, &tight);
    assert!(
        !bad.status.success(),
        "verify passed with {tight:?}: {}",
        String::from_utf8_lossy(&bad.stdout)
    );
}
