//! The `nurbs-plan` binary as users run it: inspect figures, exit codes, plan then verify, and
//! verify catching a tampered setpoint file.

mod common;

use common::{
    assert_tighter_limit_fails, assert_verifies, example_path as example, nurbs_plan as bin, plan_and_verify_cli,
    plan_cli, scratch_dir, verify_cli, LAB1, TABLE1, TABLE1_TIP, TIP_VPOP, TRIDENT_VPOP,
};
use std::path::{Path, PathBuf};
use std::process::Command;

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
    let dir = scratch_dir("nurbs-cli");
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

/// `nurbs-plan plan program args --out csv --summary summary` must succeed; returns the summary.
fn plan_with_summary(program: &Path, args: &[&str], csv: &Path, summary: &Path) -> serde_json::Value {
    let out = bin()
        .arg("plan")
        .arg(program)
        .args(args)
        .arg("--out")
        .arg(csv)
        .arg("--summary")
        .arg(summary)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{} {args:?}: {}",
        program.display(),
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_str(&std::fs::read_to_string(summary).unwrap()).unwrap()
}

#[test]
fn plan_then_verify_and_verify_catches_a_jump() {
    let dir = scratch_dir("nurbs-cli-plan");
    let csv = dir.join("trident.csv");
    let summary = dir.join("summary.json");
    let limits = LAB1;
    let s = plan_with_summary(&example("trident.json"), &limits, &csv, &summary);
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

/// `plan --interp` (Erwinski et al. 2022, Table I): `rk2pc` is the default output bit for bit; `sot`, `tot`
/// and `fcp` give the same periods with positions computed their way, off the planned arc length
/// (but near it); `--stream` plans a motion of the same length on the trident that passes
/// `verify`; VPOp refuses both flags.
#[test]
fn plan_interpolation_methods_and_streaming() {
    let dir = scratch_dir("nurbs-cli-interp");
    let run = |name: &str, extra: &[&str]| -> (Vec<Vec<f64>>, serde_json::Value) {
        let csv = dir.join(format!("{name}.csv"));
        let args: Vec<&str> = LAB1.iter().chain(extra).copied().collect();
        let s = plan_with_summary(&example("trident.json"), &args, &csv, &dir.join(format!("{name}.json")));
        (csv_columns(&csv, &["u", "x", "y"]), s)
    };
    let (default, _) = run("default", &[]);
    let (rk2pc, s) = run("rk2pc", &["--interp", "rk2pc"]);
    assert_eq!(rk2pc, default);
    assert_eq!(s["interpolation"], "rk2pc");
    for method in ["sot", "tot", "fcp"] {
        let (other, s) = run(method, &["--interp", method]);
        assert_eq!(s["interpolation"], method);
        assert_eq!(other.len(), default.len(), "{method}: another period count");
        let worst = other
            .iter()
            .zip(&default)
            .flat_map(|(a, b)| (1..3).map(|c| (a[c] - b[c]).abs()))
            .fold(0.0, f64::max);
        println!("{method}: largest distance from the RK2-PC setpoints {worst:.3e} mm");
        assert!(worst > 0.0 && worst < 0.05, "{method}: {worst}");
    }
    let (streamed, s) = run("stream", &["--stream"]);
    assert_eq!(s["streamed"], true);
    assert!(s["first_segment_time_s"].as_f64().is_some_and(|t| t > 0.0));
    assert_eq!(streamed.len(), default.len());
    // The streamed plan passes the same check as the whole-path one.
    assert_verifies(&dir.join("stream.csv"), &example("trident.json"), &LAB1);
    let out = bin()
        .arg("plan")
        .arg(example("trident.json"))
        .args(LAB1)
        .args(["--interp", "sot", "--planner", "vpop"])
        .arg("--out")
        .arg(dir.join("refused.csv"))
        .output()
        .unwrap();
    assert!(!out.status.success(), "--interp accepted with vpop");
    assert!(String::from_utf8_lossy(&out.stderr).contains("erwinski planner"));
    // A streamed plan that fails says how much of it had already been handed out (on the
    // machine, running): the property test's case 1246, refused at u = 0, before any.
    let refused = common::root().join("tests/hal/refused_stream.json");
    let limits = [
        "--feed",
        "4191.755008993316",
        "--accel",
        "1462.5546584086417",
        "--jerk",
        "1654.3689664315684",
        "--chord-tol",
        "0.00153557848570954",
        "--period",
        "0.00016582130356203076",
    ];
    for (flags, told) in [(&["--stream"][..], true), (&[][..], false)] {
        let out = bin()
            .arg("plan")
            .arg(&refused)
            .args(limits)
            .args(flags)
            .arg("--out")
            .arg(dir.join("refused.csv"))
            .output()
            .unwrap();
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success(), "{flags:?}: {stderr}");
        assert!(stderr.contains("no feed profile within the limits"), "{stderr}");
        assert_eq!(
            stderr.contains("0 records had been handed out: 0.000 s of motion"),
            told,
            "{flags:?}: {stderr}"
        );
    }
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

/// Limits of the plot tests: VPOp's for VPOp (coarse period, per-axis accelerations, a fast
/// run), lab set 1 at a 1 ms period for the Erwinski planner.
fn plot_limits(planner: &str) -> &'static [&'static str] {
    if planner == "vpop" {
        &[
            "--feed",
            "166.667",
            "--vel",
            "500",
            "--accel",
            "2500,3000",
            "--jerk",
            "5000",
            "--chord-tol",
            "0.02",
            "--period",
            "0.006",
        ]
    } else {
        &[
            "--feed",
            "2500",
            "--accel",
            "1e4",
            "--jerk",
            "6e4",
            "--chord-tol",
            "0.001",
            "--period",
            "0.001",
        ]
    }
}

fn plot_args(planner: &str, csv: &Path, png: &Path) -> Command {
    let mut cmd = bin();
    cmd.arg("plan")
        .arg(example("trident.json"))
        .args(["--planner", planner]);
    cmd.args(plot_limits(planner));
    cmd.arg("--out").arg(csv).arg("--plot").arg(png);
    cmd
}

#[test]
fn plan_draws_the_profile_as_a_png() {
    let dir = scratch_dir("nurbs-cli-plot");
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
        assert_verifies(&csv, &example("trident.json"), plot_limits(planner));
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
        .args(plot_limits("erwinski"))
        .arg("--out")
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
    assert_verifies(&dir.join("multi.csv"), &ngc, plot_limits("erwinski"));
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
    let dir = scratch_dir("nurbs-cli-plot-bad");
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

/// A G1 program through `points` (2-D or 3-D) at F 150000 mm/min (2500 mm/s).
fn g1_program(points: &[Vec<f64>]) -> String {
    let word = |p: &[f64]| {
        ["X", "Y", "Z"]
            .iter()
            .zip(p)
            .map(|(a, v)| format!("{a}{v:.6}"))
            .collect::<Vec<_>>()
            .join(" ")
    };
    let mut s = String::from("G21 G90 G17 G94 G64\n");
    s += &format!("G0 {}\nF150000\n", word(&points[0]));
    for p in &points[1..] {
        s += &format!("G1 {}\n", word(p));
    }
    s + "M2\n"
}

/// The dense G1 polyline of the butterfly (points 0.5 mm apart along the curve) and the
/// fan_5axis tool tip path (25 points), written as G-code where the binary can read them
/// (`CARGO_TARGET_TMPDIR`, kept for re-running the commands by hand).
fn g1_examples() -> Vec<(&'static str, PathBuf)> {
    use nurbs_motion::readers::read_toolpath;
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR"));
    let butterfly = read_toolpath(&example("butterfly.json")).unwrap();
    let curve = &butterfly.elements[0].curve;
    let (u0, u1) = (curve.u_min(), curve.u_max());
    let n = 400_000;
    let at = |k: usize| curve.point(u0 + (u1 - u0) * k as f64 / n as f64)[..2].to_vec();
    let mut pts = vec![at(0)];
    for k in 1..n {
        let p = at(k);
        let last = pts.last().unwrap();
        if (p[0] - last[0]).hypot(p[1] - last[1]) >= 0.5 {
            pts.push(p);
        }
    }
    pts.push(at(n));
    assert!(pts.len() > 700, "{} butterfly points", pts.len());
    let b = dir.join("butterfly_g1.ngc");
    std::fs::write(&b, g1_program(&pts)).unwrap();
    let fan = read_toolpath(&example("fan_5axis.json")).unwrap();
    let c = &fan.elements[0].curve;
    let tip: Vec<Vec<f64>> = (0..c.control_point_count())
        .map(|k| c.control_point(k)[..3].to_vec())
        .collect();
    let f = dir.join("fan_5axis_tip_g1.ngc");
    std::fs::write(&f, g1_program(&tip)).unwrap();
    vec![("butterfly", b), ("fan_5axis tip", f)]
}

fn plan_summary(program: &Path, planner: &str, corners: &str, csv: &Path, limits: &[&str]) -> serde_json::Value {
    let summary = csv.with_extension("json");
    let out = bin()
        .arg("plan")
        .arg(program)
        .args(limits)
        .args(["--planner", planner, "--round-corners", corners])
        .arg("--out")
        .arg(csv)
        .arg("--summary")
        .arg(&summary)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}: {}",
        program.display(),
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_str(&std::fs::read_to_string(&summary).unwrap()).unwrap()
}

/// G1 polylines are rounded by default within --chord-tol, planned as one motion by both
/// planners, and verified against the same rounded path; the setpoints stay within the
/// tolerance of the programmed polyline, and the motion is much shorter than stopping at
/// every corner (`--round-corners off`).
#[test]
fn g1_polylines_are_rounded_planned_and_verified() {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("g1-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let tol = 0.001;
    for (name, program) in g1_examples() {
        for planner in ["erwinski", "vpop"] {
            let csv = dir.join(format!("{}-{planner}.csv", name.replace(' ', "_")));
            let s = plan_summary(&program, planner, "auto", &csv, &LAB1);
            let corners = s["rounding_corners"].as_u64().unwrap();
            let rounding = s["rounding_max_deviation_mm"].as_f64().unwrap();
            let dev = s["max_deviation_from_program_mm"].as_f64().unwrap();
            let time = s["motion_time_s"].as_f64().unwrap();
            eprintln!(
                "{name} {planner}: {corners} corners, rounding {rounding:.6} mm, setpoints {dev:.6} mm, motion {time:.4} s, plan {:.1} ms",
                s["plan_time_s"].as_f64().unwrap() * 1e3
            );
            assert!(corners >= 20, "{name} {planner}: {corners} corners");
            assert!(rounding <= tol && rounding > 0.0, "{name}: rounding {rounding}");
            assert!(dev <= tol * (1.0 + 1e-6), "{name} {planner}: {dev} mm");
            let verify = |corners: &str| {
                bin()
                    .arg("verify")
                    .arg(&csv)
                    .arg(&program)
                    .args(LAB1)
                    .args(["--round-corners", corners])
                    .output()
                    .unwrap()
            };
            let ok = verify("auto");
            let text = String::from_utf8_lossy(&ok.stdout);
            assert!(ok.status.success(), "{name} {planner}: {text}");
            assert!(text.contains("of the programmed polyline"), "{text}");
            // Against the unrounded polyline the setpoints are off the path.
            let bad = verify("off");
            assert!(
                !bad.status.success(),
                "{name} {planner}: verify --round-corners off passed"
            );
            if planner == "erwinski" && name == "butterfly" {
                // Exact stop at every corner of the dense polyline takes far longer.
                let stop = plan_summary(&program, planner, "off", &dir.join("stop.csv"), &LAB1);
                let stop_time = stop["motion_time_s"].as_f64().unwrap();
                eprintln!("{name} {planner} without rounding: motion {stop_time:.4} s");
                assert_eq!(stop["rounding_corners"].as_u64(), Some(0));
                assert!(time < 0.6 * stop_time, "{name}: {time} s vs {stop_time} s");
            }
        }
        if name == "fan_5axis tip" {
            // The paper's limits (VPOp, tolerance 0.02 mm): VPOp flows through the rounded
            // corners faster than it stops at the programmed ones.
            let lim = TIP_VPOP;
            let csv = dir.join("fan-paper.csv");
            let round = plan_summary(&program, "vpop", "auto", &csv, &lim);
            let stop = plan_summary(&program, "vpop", "off", &dir.join("fan-stop.csv"), &lim);
            let (t1, t0) = (
                round["motion_time_s"].as_f64().unwrap(),
                stop["motion_time_s"].as_f64().unwrap(),
            );
            let dev = round["max_deviation_from_program_mm"].as_f64().unwrap();
            eprintln!("fan_5axis tip, paper limits, vpop: {t1:.3} s rounded, {t0:.3} s stopping; {dev:.5} mm");
            assert!(dev <= 0.02 * (1.0 + 1e-6), "{dev}");
            assert!(t1 < 0.95 * t0, "{t1} s vs {t0} s");
            let ok = bin().arg("verify").arg(&csv).arg(&program).args(lim).output().unwrap();
            assert!(ok.status.success(), "{}", String::from_utf8_lossy(&ok.stdout));
        }
    }
    std::fs::remove_dir_all(&dir).ok();
}

/// `--round-corners on` refuses a path that is not a tool-tip polyline; `auto` leaves a NURBS
/// path as programmed.
#[test]
fn round_corners_on_needs_a_polyline() {
    let dir = scratch_dir("nurbs-cli-corners");
    let run = |corners: &str| {
        bin()
            .arg("plan")
            .arg(example("trident.json"))
            .args(["--feed", "2500", "--accel", "1e4", "--jerk", "6e4"])
            .args(["--chord-tol", "0.001", "--period", "0.001"])
            .args(["--round-corners", corners])
            .arg("--out")
            .arg(dir.join("t.csv"))
            .arg("--summary")
            .arg(dir.join("t.json"))
            .output()
            .unwrap()
    };
    let out = run("on");
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("needs a polyline"));
    let out = run("auto");
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let s: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(dir.join("t.json")).unwrap()).unwrap();
    assert_eq!(s["rounding_corners"].as_u64(), Some(0));
    assert!(s["max_deviation_from_program_mm"].is_null());
    std::fs::remove_dir_all(&dir).ok();
}

/// Columns `names` of a setpoint CSV, row by row.
fn csv_columns(path: &Path, names: &[&str]) -> Vec<Vec<f64>> {
    let text = std::fs::read_to_string(path).unwrap();
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let cols: Vec<usize> = names
        .iter()
        .map(|n| {
            header
                .iter()
                .position(|h| h == n)
                .unwrap_or_else(|| panic!("no column {n}"))
        })
        .collect();
    lines
        .map(|l| {
            let f: Vec<&str> = l.split(',').collect();
            cols.iter().map(|&c| f[c].parse().unwrap()).collect()
        })
        .collect()
}

/// The geometry flags (LinuxCNC's `xyzac-trt-kins` pins: rotation point, tilt axis offset, tool
/// offset) move the rotary axes: the joints planned with them put the tool tip and the tool
/// axis, by forward kinematics on that geometry, on the programmed curves; `verify` passes with
/// the same flags and fails with another geometry (or none).
#[test]
fn five_axis_geometry_is_planned_and_verified_with_the_same_kinematics() {
    use nurbs_motion::kinematics::{TableTilting, TrtGeometry};
    let dir = scratch_dir("nurbs-cli-geometry");
    let program = example("open_pocket.json");
    let geometry = TrtGeometry {
        rot_point: [-15.0, 40.0, -60.0],
        offset: [0.0, 20.0, -10.0],
        tool_offset: 30.0,
        ..TrtGeometry::default()
    };
    let flags = ["--rot-point=-15,40,-60", "--kins-offset=0,20,-10", "--tool-offset=30"];
    let csv = dir.join("geometry.csv");
    let summary = dir.join("geometry.json");
    let args = [&TABLE1[..], &["--planner", "vpop", "--machine", "xyzac"], &flags].concat();
    let s = plan_with_summary(&program, &args, &csv, &summary);
    assert_eq!(s["machine"], "xyzac");
    assert_eq!(s["rot_point_mm"], serde_json::json!(geometry.rot_point));
    assert_eq!(s["kins_offset_mm"], serde_json::json!(geometry.offset));
    assert_eq!(s["tool_offset_mm"], serde_json::json!(geometry.tool_offset));
    // Every row: the joints' tool tip and tool axis on the programmed tip and top curves.
    let toolpath = nurbs_motion::readers::read_toolpath(&program).unwrap();
    let machine = TableTilting {
        geometry,
        ..TableTilting::default()
    };
    let rows = csv_columns(&csv, &["x", "y", "z", "a", "c", "element", "u"]);
    assert!(rows.len() > 100);
    let (mut tip_error, mut axis_error, mut default_error): (f64, f64, f64) = (0.0, 0.0, 0.0);
    for r in &rows {
        let p = toolpath.elements[r[5] as usize].curve.point(r[6]);
        let d = [p[3] - p[0], p[4] - p[1], p[5] - p[2]];
        let n = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
        let (tip, axis) = machine.forward(&r[..5]);
        let (tip0, _) = TableTilting::default().forward(&r[..5]);
        for i in 0..3 {
            tip_error = tip_error.max((tip[i] - p[i]).abs());
            axis_error = axis_error.max((axis[i] - d[i] / n).abs());
            default_error = default_error.max((tip0[i] - p[i]).abs());
        }
    }
    eprintln!(
        "{geometry:?}: tip {tip_error:.2e} mm, axis {axis_error:.2e}; on the default geometry {default_error:.3} mm off"
    );
    assert!(tip_error < 1e-6, "{tip_error}");
    assert!(axis_error < 1e-9, "{axis_error}");
    assert!(default_error > 1.0, "the geometry changed nothing: {default_error}");
    let verify = |flags: &[&str]| {
        let mut cmd = bin();
        cmd.arg("verify").arg(&csv).arg(&program).args(TABLE1).args(flags);
        cmd.output().unwrap()
    };
    let ok = verify(&flags);
    assert!(ok.status.success(), "{}", String::from_utf8_lossy(&ok.stdout));
    for other in [
        &[][..],
        &["--rot-point=-15,40,-60", "--kins-offset=0,20,-10"],
        &["--rot-point=-15,40,-59", "--kins-offset=0,20,-10", "--tool-offset=30"],
        &["--rot-point=-15,40,-60", "--kins-offset=0,21,-10", "--tool-offset=30"],
    ] {
        let bad = verify(other);
        let text = String::from_utf8_lossy(&bad.stdout);
        assert!(!bad.status.success(), "{other:?}: {text}");
        assert!(text.contains("off the joints' tool tip"), "{other:?}: {text}");
    }
    std::fs::remove_dir_all(&dir).ok();
}

/// `nurbs-plan kinematics`: world poses to joints and back on the geometry the flags give
/// (tests/hal/test_machine_kins.sh checks the same command against LinuxCNC's own modules); a
/// malformed line fails with its number, and a branch flag (poses name their angles) is refused.
#[test]
fn kinematics_command_turns_poses_into_joints_and_back() {
    use std::io::Write;
    let run = |args: &[&str], input: &str| {
        let mut child = bin()
            .arg("kinematics")
            .args(args)
            .stdin(std::process::Stdio::piped())
            .stdout(std::process::Stdio::piped())
            .stderr(std::process::Stdio::piped())
            .spawn()
            .unwrap();
        child.stdin.take().unwrap().write_all(input.as_bytes()).unwrap();
        child.wait_with_output().unwrap()
    };
    let flags = [
        "--machine=xyzbc",
        "--rot-point=1,2,3",
        "--kins-offset=4,5,6",
        "--tool-offset=7",
    ];
    let poses = "10 -20 5 30 45\n-3.5 0 12 -60 725\n";
    let joints = run(&flags, poses);
    assert!(joints.status.success(), "{}", String::from_utf8_lossy(&joints.stderr));
    let joints = String::from_utf8(joints.stdout).unwrap();
    assert_eq!(joints.lines().count(), 2, "{joints}");
    let back = run(&[&flags[..], &["--forward"]].concat(), &joints);
    let back = String::from_utf8(back.stdout).unwrap();
    let numbers = |t: &str| -> Vec<f64> { t.split_whitespace().map(|v| v.parse().unwrap()).collect() };
    for (a, b) in numbers(poses).iter().zip(numbers(&back)) {
        assert!((a - b).abs() < 1e-12, "{poses} -> {joints} -> {back}");
    }
    assert_ne!(numbers(&joints)[..3], numbers(poses)[..3]);
    let bad = run(&flags, "1 2 3 4 5\n1 2 x 4 5\n");
    assert!(!bad.status.success());
    assert!(String::from_utf8_lossy(&bad.stderr).contains("stdin line 2"));
    let branch = run(&[&flags[..], &["--negative-tilt"]].concat(), poses);
    assert!(!branch.status.success());
    assert!(String::from_utf8_lossy(&branch.stderr).contains("--negative-tilt"));
}

/// `--machine xyzbc --negative-tilt`: the joints are x, y, z, b, c with B <= 0, their forward
/// kinematics put the tool tip and axis on the programmed curves, and `verify` passes with the
/// same machine (either branch: the forward kinematics are the same) and fails with XYZAC.
#[test]
fn xyzbc_machine_on_the_negative_branch_is_planned_and_verified() {
    use nurbs_motion::kinematics::{TableTilting, Tilt, TrtGeometry};
    let dir = scratch_dir("nurbs-cli-xyzbc");
    let program = example("open_pocket.json");
    let with = |extra: &[&'static str]| [&TABLE1[..], extra].concat();
    let flags = ["--machine", "xyzbc", "--negative-tilt"];
    let csv = plan_cli(&program, "vpop", &with(&flags), &dir.join("bc.csv"));
    let toolpath = nurbs_motion::readers::read_toolpath(&program).unwrap();
    let machine = TableTilting {
        geometry: TrtGeometry {
            tilt: Tilt::Y,
            ..TrtGeometry::default()
        },
        negative_tilt: true,
    };
    let rows = csv_columns(&csv, &["x", "y", "z", "b", "c", "element", "u"]);
    assert!(rows.len() > 100);
    let (mut tip_error, mut axis_error, mut b_max) = (0.0f64, 0.0f64, f64::NEG_INFINITY);
    for r in &rows {
        let p = toolpath.elements[r[5] as usize].curve.point(r[6]);
        let d = [p[3] - p[0], p[4] - p[1], p[5] - p[2]];
        let n = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
        let (tip, axis) = machine.forward(&r[..5]);
        for i in 0..3 {
            tip_error = tip_error.max((tip[i] - p[i]).abs());
            axis_error = axis_error.max((axis[i] - d[i] / n).abs());
        }
        b_max = b_max.max(r[3]);
    }
    assert!(tip_error < 1e-6 && axis_error < 1e-9, "{tip_error} {axis_error}");
    assert!(b_max <= 1e-9, "B on the negative branch reached {b_max}");
    let verify = |extra: &[&'static str]| verify_cli(&csv, &program, &with(extra));
    for same in [&flags[..], &["--machine", "xyzbc"]] {
        let ok = verify(same);
        let text = String::from_utf8_lossy(&ok.stdout);
        assert!(ok.status.success(), "{same:?}: {text}");
        assert!(text.contains("joints x y z b c"), "{text}");
    }
    // XYZAC reads an `a` column, which this file does not have.
    let other_machine = verify(&["--machine", "xyzac", "--negative-tilt"]);
    assert!(!other_machine.status.success());
    std::fs::remove_dir_all(&dir).ok();
}

/// Bad `--machine` / geometry values, and the flags where no kinematics is used, fail with a
/// message naming the flag.
#[test]
fn machine_options_refuse_bad_values_and_tool_tip_paths() {
    let dir = scratch_dir("nurbs-cli-machine");
    let plan = |program: &str, planner: &str, extra: &[&str]| {
        bin()
            .arg("plan")
            .arg(example(program))
            .args(TABLE1)
            .args(["--planner", planner])
            .args(extra)
            .arg("--out")
            .arg(dir.join("m.csv"))
            .output()
            .unwrap()
    };
    for (program, planner, extra, expected) in [
        ("open_pocket.json", "vpop", &["--rot-point", "1,2"][..], "three numbers"),
        (
            "open_pocket.json",
            "vpop",
            &["--kins-offset", "1,2,3,4"],
            "three numbers",
        ),
        ("open_pocket.json", "vpop", &["--tool-offset", "inf"], "a finite number"),
        (
            "open_pocket.json",
            "vpop",
            &["--rot-point", "1,y,3"],
            "three finite numbers",
        ),
        (
            "open_pocket.json",
            "vpop",
            &["--kins-offset", "nan,0,0"],
            "three finite numbers",
        ),
        (
            "open_pocket.json",
            "vpop",
            &["--machine", "hexapod"],
            "possible values: xyzac, xyzbc",
        ),
        (
            "trident.json",
            "vpop",
            &["--rot-point", "1,2,3"],
            "2-axis tool-tip path",
        ),
        (
            "trident.json",
            "erwinski",
            &["--machine", "xyzac"],
            "2-axis tool-tip path",
        ),
        (
            "open_pocket.json",
            "erwinski",
            &["--tool-offset", "1"],
            "--planner vpop",
        ),
    ] {
        let out = plan(program, planner, extra);
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success(), "{program} {planner} {extra:?} passed");
        assert!(err.contains(expected), "{program} {planner} {extra:?}: {err}");
        assert!(
            ["--rot-point", "--kins-offset", "--tool-offset", "--machine"]
                .iter()
                .any(|flag| err.contains(flag)),
            "{err}"
        );
    }
    // verify: tool-tip setpoints (the Erwinski planner on the same path) have no kinematics
    // to check.
    let tip_limits = TABLE1_TIP;
    let csv = dir.join("tip.csv");
    let out = bin()
        .arg("plan")
        .arg(example("open_pocket.json"))
        .args(tip_limits)
        .arg("--out")
        .arg(&csv)
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    assert_verifies(&csv, &example("open_pocket.json"), &tip_limits);
    let out = bin()
        .arg("verify")
        .arg(&csv)
        .arg(example("open_pocket.json"))
        .args(tip_limits)
        .args(["--rot-point", "1,2,3"])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(
        err.contains("--rot-point") && err.contains("tool-tip setpoints"),
        "{err}"
    );
    std::fs::remove_dir_all(&dir).ok();
}

/// A line and an arc at F1200 (20 mm/s), then a line at F3000 (50 mm/s): the same geometry in
/// both programs, `one_feed` programs F3000 throughout.
fn two_feed_program(one_feed: bool) -> String {
    let slow = if one_feed { "F3000" } else { "F1200" };
    format!("G21 G90 G17 G94 G64\nG0 X0 Y0\n{slow}\nG1 X30 Y0\nG3 X40 Y10 R10\nF3000\nG1 X40 Y60\nM2\n")
}

/// Both planners keep every element at or below its programmed G-code feed (never above
/// --feed), and reach it; `verify` checks the programmed feed per element, so a plan of the
/// same geometry at a single feed fails against the two-feed program.
#[test]
fn programmed_gcode_feeds_cap_each_element() {
    let dir = scratch_dir("nurbs-cli-feeds");
    let (two, one) = (dir.join("two_feeds.ngc"), dir.join("one_feed.ngc"));
    std::fs::write(&two, two_feed_program(false)).unwrap();
    std::fs::write(&one, two_feed_program(true)).unwrap();
    let limits = [
        "--feed",
        "100",
        "--accel",
        "1000",
        "--jerk",
        "1e4",
        "--chord-tol",
        "0.001",
        "--period",
        "0.001",
    ];
    let plan = |program: &Path, planner: &str, csv: &Path| plan_cli(program, planner, &limits, csv);
    for planner in ["erwinski", "vpop"] {
        let csv = dir.join(format!("{planner}-two.csv"));
        plan(&two, planner, &csv);
        assert_verifies(&csv, &two, &limits);
        // Feed of every step from the positions: within the slow elements (line, arc) at most
        // 20 mm/s, at most 50 mm/s anywhere, and both feeds reached.
        let rows = csv_columns(&csv, &["x", "y", "element"]);
        let (mut slow, mut fast): (f64, f64) = (0.0, 0.0);
        for w in rows.windows(2) {
            let feed = (w[1][0] - w[0][0]).hypot(w[1][1] - w[0][1]) / 0.001;
            if w[1][2] <= 1.0 {
                slow = slow.max(feed);
            } else {
                fast = fast.max(feed);
            }
        }
        eprintln!("{planner}: max feed {slow:.4} mm/s at F1200, {fast:.4} mm/s at F3000");
        assert!(slow <= 20.0 * (1.0 + 1e-6) && slow > 19.0, "{planner}: {slow}");
        assert!(fast <= 50.0 * (1.0 + 1e-6) && fast > 45.0, "{planner}: {fast}");
        // The single-feed plan is fine for its own program, not for the two-feed one.
        let csv_one = dir.join(format!("{planner}-one.csv"));
        plan(&one, planner, &csv_one);
        assert_verifies(&csv_one, &one, &limits);
        let bad = bin()
            .arg("verify")
            .arg(&csv_one)
            .arg(&two)
            .args(limits)
            .output()
            .unwrap();
        let text = String::from_utf8_lossy(&bad.stdout);
        assert!(!bad.status.success(), "{planner}: {text}");
        assert!(text.contains("exceeds the programmed feed 20"), "{planner}: {text}");
    }
    std::fs::remove_dir_all(&dir).ok();
}

/// Slow spots of a setpoint CSV: stretches where the feed column dips below `below` mm/s
/// (away from the start and the end).
fn slow_spots(csv: &Path, below: f64) -> usize {
    let feed: Vec<f64> = csv_columns(csv, &["feed"]).iter().map(|r| r[0]).collect();
    let inner = &feed[5..feed.len() - 5];
    inner.windows(2).filter(|w| w[0] >= below && w[1] < below).count()
}

/// fan_5axis is a 5-axis G1 path (tool tip and tool axis, 25 points): `--round-corners auto`
/// rounds tip and top curve on one parameter within --chord-tol, so the rotary joints turn
/// through the corners instead of stopping at every one. Both planners' plans verify against
/// the rounded path (and fail against the programmed one), VPOp's within the tolerance of the
/// programmed polyline and faster than with exact stops.
#[test]
fn five_axis_g1_corners_are_rounded_tip_and_axis_together() {
    let dir = scratch_dir("nurbs-cli-fan5");
    let program = example("fan_5axis.json");
    let tol = 0.02;
    let verify = |csv: &Path, limits: &[&str], corners: &str| {
        bin()
            .arg("verify")
            .arg(csv)
            .arg(&program)
            .args(limits)
            .args(["--round-corners", corners])
            .output()
            .unwrap()
    };
    let (round_csv, stop_csv) = (dir.join("vpop-auto.csv"), dir.join("vpop-off.csv"));
    let round = plan_summary(&program, "vpop", "auto", &round_csv, &TABLE1);
    let stop = plan_summary(&program, "vpop", "off", &stop_csv, &TABLE1);
    let corners = round["rounding_corners"].as_u64().unwrap();
    let tip_dev = round["rounding_max_deviation_mm"].as_f64().unwrap();
    let top_dev = round["rounding_max_top_deviation_mm"].as_f64().unwrap();
    let dev = round["max_deviation_from_program_mm"].as_f64().unwrap();
    let (t1, t0) = (
        round["motion_time_s"].as_f64().unwrap(),
        stop["motion_time_s"].as_f64().unwrap(),
    );
    let (slow1, slow0) = (slow_spots(&round_csv, 5.0), slow_spots(&stop_csv, 5.0));
    eprintln!(
        "fan_5axis, Table 1, vpop: {corners} corners (tip {tip_dev:.5} mm, top {top_dev:.5} mm), setpoints {dev:.5} mm; \
         {t1:.3} s rounded ({slow1} slow spots) vs {t0:.3} s stopping ({slow0})"
    );
    assert!(corners >= 20, "{corners}");
    assert!(tip_dev <= tol && top_dev <= tol && dev <= tol * (1.0 + 1e-6));
    assert!(tip_dev.max(top_dev) > 0.9 * tol);
    assert!(t1 < 0.95 * t0, "{t1} s vs {t0} s");
    assert!(slow0 >= 20 && slow1 * 3 < slow0, "{slow1} vs {slow0}");
    let ok = verify(&round_csv, &TABLE1, "auto");
    let text = String::from_utf8_lossy(&ok.stdout);
    assert!(ok.status.success() && text.contains("top curve"), "{text}");
    assert!(!verify(&round_csv, &TABLE1, "off").status.success());
    assert!(verify(&stop_csv, &TABLE1, "off").status.success());
    // The Erwinski planner plans the tool tip of the same rounded path.
    let tip_limits = TABLE1_TIP;
    let csv = dir.join("erwinski-auto.csv");
    let s = plan_summary(&program, "erwinski", "auto", &csv, &tip_limits);
    assert_eq!(s["rounding_corners"].as_u64(), Some(corners));
    assert!(verify(&csv, &tip_limits, "auto").status.success());
    assert!(!verify(&csv, &tip_limits, "off").status.success());
    std::fs::remove_dir_all(&dir).ok();
}

/// The limits may come from a LinuxCNC INI file (`--ini`, as `nurbs-planner` reads it): the
/// plan is the one of the same limits given as flags, bit for bit, and a flag wins over the INI.
#[test]
fn limits_from_an_ini_file_are_the_flags_limits() {
    let dir = scratch_dir("nurbs-cli-ini");
    let ini = common::root().join("halfiles/sim.ini");
    let plan = |args: &[&str], out: &str| {
        let o = bin()
            .arg("plan")
            .arg(example("trident.json"))
            .args(args)
            .arg("--out")
            .arg(dir.join(out))
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        std::fs::read(dir.join(out)).unwrap()
    };
    let flags = plan(&LAB1, "flags.csv");
    let from_ini = plan(&["--ini", ini.to_str().unwrap()], "ini.csv");
    assert!(flags == from_ini, "the INI's limits plan differently");
    // A flag wins: a lower feed than the INI's gives a longer motion.
    let slower = plan(&["--ini", ini.to_str().unwrap(), "--feed", "100"], "slow.csv");
    assert!(slower.len() > flags.len());
    // Missing everything: a clear error naming the flag and the INI key.
    let o = bin()
        .arg("plan")
        .arg(example("trident.json"))
        .args(["--feed", "100", "--out"])
        .arg(dir.join("none.csv"))
        .output()
        .unwrap();
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("--chord-tol") && err.contains("CHORD_TOLERANCE"), "{err}");
    std::fs::remove_dir_all(&dir).ok();
}

/// With `--ini`, the machine's travel (`[AXIS_*]MIN_LIMIT/MAX_LIMIT`) bounds the path: a control
/// point outside it (of the tool tip, after corner rounding) is refused with the point, the
/// axis, the limits and the line; inside, the plan is the one without the travel.
#[test]
fn a_path_outside_the_machines_travel_is_refused() {
    let dir = scratch_dir("nurbs-cli-travel");
    let sim = std::fs::read_to_string(common::root().join("halfiles/sim.ini")).unwrap();
    let ini = |y_max: f64| {
        let path = dir.join(format!("travel-{y_max}.ini"));
        let text = sim.replace(
            "[AXIS_Y]\n",
            &format!("[AXIS_Y]\nMIN_LIMIT = -1\nMAX_LIMIT = {y_max}\n"),
        );
        assert!(text.contains("MAX_LIMIT"));
        std::fs::write(&path, text).unwrap();
        path
    };
    let plan = |toolpath: &Path, ini: &Path| {
        bin()
            .arg("plan")
            .arg(toolpath)
            .arg("--ini")
            .arg(ini)
            .arg("--out")
            .arg(dir.join("out.csv"))
            .output()
            .unwrap()
    };
    // The trident's control points reach Y 27.
    let o = plan(&example("trident.json"), &ini(20.0));
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("leaves the machine's travel: Y -1 .. 20 mm") && err.contains("MIN_LIMIT/MAX_LIMIT"),
        "{err}"
    );
    let inside = ini(30.0);
    assert!(plan(&example("trident.json"), &inside).status.success());
    let checked = bin()
        .arg("verify")
        .arg(dir.join("out.csv"))
        .arg(example("trident.json"))
        .arg("--ini")
        .arg(&inside)
        .output()
        .unwrap();
    assert!(checked.status.success(), "{}", String::from_utf8_lossy(&checked.stdout));
    // A G-code program that leaves it on its fourth line: refused, naming the file and axis.
    let ngc = dir.join("leaves.ngc");
    std::fs::write(&ngc, "G21 G90\nG0 X0 Y0\nG1 X10 Y0 F6000\nG1 X10 Y50\nG1 X0 Y0\nM2\n").unwrap();
    let o = plan(&ngc, &inside);
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("leaves.ngc") && err.contains("travel: Y"), "{err}");
    std::fs::remove_dir_all(&dir).ok();
}

/// `nurbs-plan plan --planner vpop` writes a CSV that `nurbs-plan verify` accepts, and rejects
/// against a tighter jerk limit; a two-curve toolpath is planned on the XYZAC machine
/// (columns t,u,x,y,z,a,c,tip_x,tip_y,tip_z,feed,element) and verified per joint.
#[test]
fn cli_plan_vpop_and_verify() {
    let dir = scratch_dir("vpop-cli");
    let trident = example("trident.json");
    let out = plan_and_verify_cli(&trident, "vpop", &TRIDENT_VPOP, &dir.join("trident.csv"));
    let head = std::fs::read_to_string(&out).unwrap();
    assert!(head.starts_with("t,u,x,y,feed,element\n"));
    assert_tighter_limit_fails(&out, &trident, &TRIDENT_VPOP, "--jerk", "4950,4950");

    let pocket = example("open_pocket.json");
    let out5 = plan_and_verify_cli(&pocket, "vpop", &TABLE1, &dir.join("pocket.csv"));
    assert!(std::fs::read_to_string(&out5)
        .unwrap()
        .starts_with("t,u,x,y,z,a,c,tip_x,tip_y,tip_z,feed,element\n"));
    assert_tighter_limit_fails(&out5, &pocket, &TABLE1, "--vel", "500,500,500,90,100");
    std::fs::remove_dir_all(&dir).ok();
}

/// `scripts/dense-g1.py --lines lines` written to `dir/dense.ngc`.
fn dense_program(dir: &Path, lines: usize) -> PathBuf {
    let program = dir.join("dense.ngc");
    let generated = Command::new("python3")
        .arg(common::root().join("scripts/dense-g1.py"))
        .args(["--lines", &lines.to_string()])
        .output()
        .expect("python3 runs scripts/dense-g1.py");
    assert!(
        generated.status.success(),
        "{}",
        String::from_utf8_lossy(&generated.stderr)
    );
    std::fs::write(&program, generated.stdout).unwrap();
    program
}

/// A dense CAM-like G1 program (2,000 lines of 0.02 mm) by default (`--round-corners auto`):
/// its runs of short pieces become fitted splines, the setpoints stay within the chord
/// tolerance of the programmed polyline and pass `verify`, and the motion takes a fraction of
/// the time it takes with the corners only rounded (`--round-corners round`; measured: 1/10 on
/// 5,000 lines). `smooth` (the name the fit had before it became the default) is `auto`.
#[test]
fn smoothing_a_dense_program_keeps_the_tolerance_and_shortens_the_motion() {
    let dir = scratch_dir("dense-smooth");
    let program = dense_program(&dir, 2000);
    let limits = ["--limits", "lab1", "--feed", "500", "--stream"];
    let (csv, summary) = (dir.join("auto.csv"), dir.join("auto.json"));
    let smooth = plan_with_summary(&program, &limits, &csv, &summary);
    assert!(smooth["fitted_runs"].as_u64().unwrap() >= 2, "{smooth}");
    let deviation = smooth["max_deviation_from_program_mm"].as_f64().unwrap();
    assert!(deviation <= 0.001, "setpoints {deviation} mm from the program");
    assert_verifies(&csv, &program, &limits[..4]);
    let (csv_round, summary_round) = (dir.join("round.csv"), dir.join("round.json"));
    let rounded = plan_with_summary(
        &program,
        &[&limits[..], &["--round-corners", "round"]].concat(),
        &csv_round,
        &summary_round,
    );
    assert_eq!(rounded["fitted_runs"].as_u64(), Some(0), "{rounded}");
    assert_verifies(
        &csv_round,
        &program,
        &[&limits[..4], &["--round-corners", "round"]].concat(),
    );
    let (fast, slow) = (
        smooth["motion_time_s"].as_f64().unwrap(),
        rounded["motion_time_s"].as_f64().unwrap(),
    );
    assert!(fast < 0.3 * slow, "smoothed {fast} s, rounded {slow} s");
    let (csv_alias, summary_alias) = (dir.join("smooth.csv"), dir.join("smooth.json"));
    plan_with_summary(
        &program,
        &[&limits[..], &["--round-corners", "smooth"]].concat(),
        &csv_alias,
        &summary_alias,
    );
    assert_eq!(std::fs::read(&csv_alias).unwrap(), std::fs::read(&csv).unwrap());
    // The mode may come from the INI (as `M101` starts `nurbs-planner` with it): the same plan.
    let ini = dir.join("round.ini");
    std::fs::write(&ini, "[NURBS]\nROUND_CORNERS = round\n").unwrap();
    let (csv_ini, summary_ini) = (dir.join("ini.csv"), dir.join("ini.json"));
    plan_with_summary(
        &program,
        &[&limits[..], &["--ini", ini.to_str().unwrap()]].concat(),
        &csv_ini,
        &summary_ini,
    );
    assert_eq!(std::fs::read(&csv_ini).unwrap(), std::fs::read(&csv_round).unwrap());
    // A corner angle outside 0..180 degrees is refused, from the flag or the INI.
    for (args, said_what) in [
        (vec!["--corner-angle", "180"], "corner angle 180"),
        (vec!["--ini", ini.to_str().unwrap()], "corner angle -5"),
    ] {
        std::fs::write(&ini, "[NURBS]\nCORNER_ANGLE = -5\n").unwrap();
        let refused = bin()
            .arg("plan")
            .arg(&program)
            .args(["--limits", "lab1"])
            .args(&args)
            .arg("--out")
            .arg(dir.join("refused.csv"))
            .output()
            .unwrap();
        let said = String::from_utf8_lossy(&refused.stderr);
        assert!(!refused.status.success() && said.contains(said_what), "{said}");
    }
    std::fs::write(&ini, "[NURBS]\nROUND_CORNERS = smoothest\n").unwrap();
    let refused = bin()
        .arg("plan")
        .arg(&program)
        .args(["--limits", "lab1", "--ini", ini.to_str().unwrap(), "--out"])
        .arg(dir.join("refused.csv"))
        .output()
        .unwrap();
    let said = String::from_utf8_lossy(&refused.stderr);
    assert!(
        !refused.status.success() && said.contains("[NURBS]ROUND_CORNERS = smoothest"),
        "{said}"
    );
    std::fs::remove_dir_all(&dir).ok();
}

/// A dense CAM-like G1 program (`scripts/dense-g1.py`, 7,000 lines of 0.02 mm) streamed as the
/// machine runs it: where back-tracking reaches the records already handed out, the plan
/// follows the stop chain they rest on only as far as it must, and runs on at the chain's
/// slower feed, so the motion comes to rest nowhere but at the end; the setpoints pass
/// `verify`.
#[test]
fn a_streamed_dense_program_rests_only_at_its_end() {
    let dir = scratch_dir("dense-stream");
    let program = dense_program(&dir, 7000);
    let (csv, summary) = (dir.join("dense.csv"), dir.join("dense.json"));
    let limits = ["--limits", "lab1", "--feed", "500"];
    let s = plan_with_summary(&program, &[&limits[..], &["--stream"]].concat(), &csv, &summary);
    assert_eq!(s["streamed"], true);
    assert_eq!(s["stops_made"], 0, "the streamed plan came to rest on the way");
    assert_verifies(&csv, &program, &limits);
}

/// A 5-axis G-code program (`G93` inverse time, A and C turning, C past 180°, as LinuxCNC's
/// `impeller-7bl-xyzac.ngc` writes them): planned by VPOp in joint space on the negative-tilt
/// branch and verified (joint limits, tip and axis by forward kinematics, within the
/// tolerance of the programmed polyline, no faster than each move's inverse time allows); the
/// joints start and end at the program's first and last pose, angles included.
#[test]
fn five_axis_gcode_program_is_planned_in_joint_space() {
    let dir = scratch_dir("nurbs-cli-5axis-gcode");
    let program = dir.join("xyzac.ngc");
    let mut text = String::from("G21 G90 G94\nG0 X20 Y0 Z5 A-20 C-30\nG93\n");
    let poses: Vec<[f64; 5]> = (0..=40)
        .map(|k| {
            let t = k as f64 / 40.0;
            let angle = 2.0 * std::f64::consts::PI * t;
            [
                20.0 * angle.cos(),
                20.0 * angle.sin(),
                5.0 - 3.0 * t,
                -20.0 - 20.0 * t,
                -30.0 + 240.0 * t,
            ]
        })
        .collect();
    for p in &poses[1..] {
        text += &format!(
            "G1 X{:.4} Y{:.4} Z{:.4} A{:.4} C{:.4} F600\n",
            p[0], p[1], p[2], p[3], p[4]
        );
    }
    text += "M2\n";
    std::fs::write(&program, text).unwrap();
    let flags = [&TABLE1[..], &["--machine", "xyzac", "--negative-tilt"]].concat();
    let csv = plan_and_verify_cli(&program, "vpop", &flags, &dir.join("xyzac.csv"));
    let rows = csv_columns(&csv, &["x", "y", "z", "a", "c"]);
    let (first, last) = (&rows[0], &rows[rows.len() - 1]);
    // The rotary joints are the program's angles (C from its start within ±180°, then
    // continuous); the linear joints follow from them and the tip.
    for (row, [a, c]) in [(first, [-20.0, -30.0]), (last, [-40.0, 210.0])] {
        assert!(
            (row[3] - a).abs() < 1e-9 && (row[4] - c).abs() < 1e-9,
            "{row:?} vs A{a} C{c}"
        );
    }
    std::fs::remove_dir_all(&dir).ok();
}
