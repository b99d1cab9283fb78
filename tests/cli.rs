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

/// Width, height and colour type from a PNG's signature and IHDR chunk.
fn png_header(bytes: &[u8]) -> (u32, u32, u8) {
    assert_eq!(&bytes[..8], b"\x89PNG\r\n\x1a\n", "not a PNG");
    assert_eq!(&bytes[12..16], b"IHDR");
    let be = |i: usize| u32::from_be_bytes(bytes[i..i + 4].try_into().unwrap());
    (be(16), be(20), bytes[25])
}

/// RGB pixels of a PNG (8-bit RGB, as `--plot` writes).
fn png_pixels(path: &Path) -> Vec<[u8; 3]> {
    let mut reader = png::Decoder::new(std::fs::File::open(path).unwrap())
        .read_info()
        .unwrap();
    let mut buf = vec![0; reader.output_buffer_size()];
    let info = reader.next_frame(&mut buf).unwrap();
    assert_eq!(info.color_type, png::ColorType::Rgb);
    buf[..info.buffer_size()]
        .chunks(3)
        .map(|c| [c[0], c[1], c[2]])
        .collect()
}

fn plot_args(planner: &str, csv: &Path, png: &Path) -> Command {
    let mut cmd = bin();
    cmd.arg("plan")
        .arg(example("trident.json"))
        .args(["--planner", planner]);
    if planner == "vpop" {
        // Seed 003's limits (coarse period, per-axis accelerations): a fast VPOp run.
        cmd.args([
            "--feed",
            "166.667",
            "--vel",
            "500",
            "--accel",
            "2500,3000",
            "--jerk",
            "5000",
        ]);
        cmd.args(["--chord-tol", "0.02", "--period", "0.006"]);
    } else {
        cmd.args([
            "--feed",
            "2500",
            "--accel",
            "1e4",
            "--jerk",
            "6e4",
            "--chord-tol",
            "0.001",
        ]);
        cmd.args(["--period", "0.001"]);
    }
    cmd.arg("--out").arg(csv).arg("--plot").arg(png);
    cmd
}

#[test]
fn plan_draws_the_profile_as_a_png() {
    let dir = std::env::temp_dir().join(format!("nurbs-cli-plot-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    const FEED: [u8; 3] = [31, 119, 180];
    const CRITICAL: [u8; 3] = [128, 0, 128];
    const CHORD_CAP: [u8; 3] = [255, 127, 14];
    for planner in ["erwinski", "vpop"] {
        let (csv, png) = (dir.join(format!("{planner}.csv")), dir.join(format!("{planner}.png")));
        let out = plot_args(planner, &csv, &png).output().unwrap();
        assert!(
            out.status.success(),
            "{planner}: {}",
            String::from_utf8_lossy(&out.stderr)
        );
        assert!(std::fs::metadata(&csv).unwrap().len() > 1000);
        let bytes = std::fs::read(&png).unwrap();
        assert_eq!(png_header(&bytes), (1600, 1800, 2), "{planner}: 1600x1800 RGB");
        // Three panels of curves, grids and text compress to far more than a blank image.
        assert!(bytes.len() > 30_000, "{planner}: {} bytes", bytes.len());
        let pixels = png_pixels(&png);
        assert_eq!(pixels.len(), 1600 * 1800);
        let count = |c: [u8; 3]| pixels.iter().filter(|p| **p == c).count();
        let ink = pixels.iter().filter(|p| **p != [255, 255, 255]).count();
        assert!(ink > pixels.len() / 50, "{planner}: only {ink} non-white pixels");
        assert!(count(FEED) > 2000, "{planner}: feed curve / x axis missing");
        assert!(count(CHORD_CAP) > 50, "{planner}: FLF chord cap missing");
        let critical = count(CRITICAL);
        if planner == "erwinski" {
            assert!(critical > 50, "critical points missing");
        } else {
            assert_eq!(critical, 0, "VPOp has no critical points");
        }
    }
    // Several path elements (NURBS, lines, NURBS): plotted over element index + normalised u.
    let ngc = dir.join("multi.ngc");
    std::fs::write(
        &ngc,
        "G21 G90 G17\nG0 X0 Y0\nF3000\nG5.2 X10 Y10 P1\nX20 Y0 P1\nX30 Y10 P1\nX35 Y0 P1\nG5.3\n\
         G1 X40 Y10\nG1 X40 Y0\nG5.2 X45 Y-10 P2\nX50 Y0 P1\nX55 Y5 P1\nX60 Y0 P1\nG5.3\n",
    )
    .unwrap();
    let png = dir.join("multi.png");
    let out = bin()
        .arg("plan")
        .arg(&ngc)
        .args([
            "--feed",
            "2500",
            "--accel",
            "1e4",
            "--jerk",
            "6e4",
            "--chord-tol",
            "0.001",
        ])
        .args(["--period", "0.001", "--out"])
        .arg(dir.join("multi.csv"))
        .arg("--plot")
        .arg(&png)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "multi.ngc: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert_eq!(png_header(&std::fs::read(&png).unwrap()), (1600, 1800, 2));
    let pixels = png_pixels(&png);
    assert!(
        pixels.iter().filter(|p| **p == FEED).count() > 2000,
        "multi.ngc: feed curve missing"
    );
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn an_unwritable_plot_fails_after_the_csv_is_written() {
    let dir = std::env::temp_dir().join(format!("nurbs-cli-plot-bad-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let csv = dir.join("trident.csv");
    let png = dir.join("no-such-dir").join("profile.png");
    let out = plot_args("erwinski", &csv, &png).output().unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("cannot write plot") && err.contains("profile.png"),
        "{err}"
    );
    assert!(
        std::fs::metadata(&csv).unwrap().len() > 1000,
        "the CSV is still written"
    );
    std::fs::remove_dir_all(&dir).ok();
}
