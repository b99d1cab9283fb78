//! `nurbs-planner` refuses what the machine cannot run before it touches HAL: run here without
//! a HAL session, a refusal is its message and a failing exit, not a component that fails to
//! start.
#![cfg(feature = "linuxcnc")]

use std::path::Path;
use std::process::Command;

/// A 5-axis toolpath (tip and tool axis) is refused by every planner: the module drives the tool
/// tip's joints only and would run the tip with the rotary axes standing still. Its tool tip
/// alone, the same curve as a 3-axis path, gets past that check as far as the channel, which no
/// module made here.
#[test]
fn a_five_axis_toolpath_is_refused_before_hal() {
    let examples = Path::new(env!("CARGO_MANIFEST_DIR")).join("../examples");
    for planner in ["erwinski", "vpop", "reach"] {
        let run = |file: &str| {
            Command::new(env!("CARGO_BIN_EXE_nurbs-planner"))
                .arg(examples.join(file))
                .args(["--limits", "lab1", "--planner", planner])
                .env("RTAPI_FIFO_PATH", std::env::temp_dir().join("nurbs-refusals-no-rtapi"))
                .output()
                .unwrap()
        };
        let refused = run("open_pocket.json");
        let said = String::from_utf8_lossy(&refused.stderr).into_owned() + &String::from_utf8_lossy(&refused.stdout);
        assert!(
            !refused.status.success(),
            "{planner}: a 5-axis path was not refused: {said}"
        );
        assert!(
            said.contains("this is a 5-axis toolpath") && said.contains("rotary axes standing still"),
            "{planner}: {said}"
        );
        let tip = run("open_pocket_tip.json");
        let said = String::from_utf8_lossy(&tip.stderr).into_owned() + &String::from_utf8_lossy(&tip.stdout);
        assert!(
            !said.contains("5-axis") && said.contains("channel"),
            "{planner}: the tool tip alone did not get as far as the channel: {said}"
        );
    }
}
