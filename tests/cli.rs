//! The `nurbs-plan` binary as users run it: inspect figures, exit codes, plan then verify, and
//! verify catching a tampered setpoint file.

use std::path::{Path, PathBuf};
use std::process::Command;

fn bin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_nurbs-plan"))
}

fn example(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("examples").join(name)
}

#[test]
fn inspect_json_gives_the_independent_arc_lengths() {
    for name in [
        "butterfly.json",
        "trident.json",
        "fan.json",
        "open_pocket.json",
        "fan_5axis.json",
        "trident.ngc",
        "trident.dxf",
    ] {
        let out = bin().args(["inspect", "--json"]).arg(example(name)).output().unwrap();
        assert!(out.status.success(), "{name}: {}", String::from_utf8_lossy(&out.stderr));
        let report: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
        let json_name = name.split('.').next().unwrap().to_string() + ".json";
        let stats: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(example(&json_name)).unwrap()).unwrap();
        let expected = stats["stats"]["control_points"]["arc_length_mm"].as_f64().unwrap();
        let got = report["arc_length_mm"].as_f64().unwrap();
        assert!((got - expected).abs() < 1e-6, "{name}: {got} vs {expected}");
        assert!(report["elements"].as_array().is_some_and(|e| !e.is_empty()));
    }
}

#[test]
fn bad_input_exits_non_zero_with_a_message() {
    let dir = std::env::temp_dir().join(format!("nurbs-cli-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let bad = dir.join("bad.json");
    std::fs::write(
        &bad,
        r#"{"degree": 3, "knots": [0,0,0,0,1,0.5,1,1,1], "control_points": [[0,0],[1,0],[1,1],[0,1],[2,2]]}"#,
    )
    .unwrap();
    let out = bin().arg("inspect").arg(&bad).output().unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("bad.json") && err.contains("non-decreasing"), "{err}");
    let empty = dir.join("empty.ngc");
    std::fs::write(&empty, "").unwrap();
    let out = bin().arg("inspect").arg(&empty).output().unwrap();
    assert!(!out.status.success());
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn plan_then_verify_and_verify_catches_a_jump() {
    let dir = std::env::temp_dir().join(format!("nurbs-cli-plan-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let csv = dir.join("trident.csv");
    let summary = dir.join("summary.json");
    let limits = [
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
    let out = bin()
        .arg("plan")
        .arg(example("trident.json"))
        .args(limits)
        .arg("--out")
        .arg(&csv)
        .arg("--summary")
        .arg(&summary)
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let s: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&summary).unwrap()).unwrap();
    for key in [
        "motion_time_s",
        "plan_time_s",
        "segments",
        "critical_points",
        "max_axial_jerk",
    ] {
        assert!(!s[key].is_null(), "summary lacks {key}");
    }
    let verify = |path: &Path| {
        bin()
            .arg("verify")
            .arg(path)
            .arg(example("trident.json"))
            .args(limits)
            .output()
            .unwrap()
    };
    let ok = verify(&csv);
    assert!(ok.status.success(), "{}", String::from_utf8_lossy(&ok.stdout));
    // Move one setpoint by 1 micrometre: the jerk check must fail.
    let text = std::fs::read_to_string(&csv).unwrap();
    let mut lines: Vec<String> = text.lines().map(String::from).collect();
    let mid = lines.len() / 2;
    let mut f: Vec<String> = lines[mid].split(',').map(String::from).collect();
    let x: f64 = f[2].parse().unwrap();
    f[2] = format!("{:?}", x + 1e-3);
    lines[mid] = f.join(",");
    let tampered = dir.join("tampered.csv");
    std::fs::write(&tampered, lines.join("\n")).unwrap();
    let bad = verify(&tampered);
    assert!(!bad.status.success());
    assert!(String::from_utf8_lossy(&bad.stdout).contains("VIOLATION"));
    std::fs::remove_dir_all(&dir).ok();
}
