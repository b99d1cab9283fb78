//! LinuxCNC G-code reader: geometry, units, feeds and every malformed-input case.

use nurbs_motion::geometry::*;
use nurbs_motion::readers::{gcode, json, read_toolpath, ReadError};
use std::path::Path;

fn ok(text: &str) -> Toolpath {
    gcode::parse("t.ngc", text).unwrap_or_else(|e| panic!("unexpected error: {e}"))
}

/// Asserts an error on `line` whose message contains `needle`.
fn fails(text: &str, line: usize, needle: &str) -> ReadError {
    let e = gcode::parse("t.ngc", text).expect_err("expected an error");
    assert_eq!(e.file, "t.ngc");
    assert_eq!(e.line, Some(line), "wrong line in: {e}");
    assert!(
        e.message.contains(needle),
        "message {:?} does not contain {needle:?}",
        e.message
    );
    e
}

fn pt(c: &Nurbs, u: f64) -> Vec<f64> {
    c.point(u)[..c.dim()].to_vec()
}

fn close(a: &[f64], b: &[f64], tol: f64) -> bool {
    a.len() == b.len() && a.iter().zip(b).all(|(x, y)| (x - y).abs() <= tol)
}

#[test]
fn trident_gcode_matches_json_geometry() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let g = read_toolpath(&root.join("examples/trident.ngc")).unwrap();
    let j = json::parse(
        "trident.json",
        &std::fs::read_to_string(root.join("examples/trident.json")).unwrap(),
    )
    .unwrap();
    assert_eq!(g.elements.len(), 1);
    let (ge, je) = (&g.elements[0], &j.elements[0]);
    assert_eq!(ge.kind, ElementKind::Nurbs);
    assert_eq!(ge.feed, Some(10.0));
    assert_eq!(ge.source_line, Some(8));
    let (gc, jc) = (&ge.curve, &je.curve);
    assert_eq!(gc.degree(), 3);
    assert_eq!(gc.knots(), &[0.0, 0.0, 0.0, 0.0, 1.0, 2.0, 3.0, 4.0, 4.0, 4.0, 4.0]);
    assert_eq!(gc.points(), jc.points());
    assert_eq!(gc.weights(), jc.weights());
    // Same curve up to the parameter map u_json = u_gcode / 4.
    let n = 1000;
    for i in 0..=n {
        let s = i as f64 / n as f64;
        let ug = gc.u_min() + s * (gc.u_max() - gc.u_min());
        let uj = jc.u_min() + s * (jc.u_max() - jc.u_min());
        assert!(close(&pt(gc, ug), &pt(jc, uj), 1e-12), "at s = {s}");
    }
    let lg = analyze(gc).arc_length_mm;
    let lj = analyze(jc).arc_length_mm;
    assert!((lg - lj).abs() < 1e-9, "{lg} vs {lj}");
}

#[test]
fn linuxcnc_knot_vector_is_reproduced() {
    // knot_vector_creator(n = 6, k = 4) and (n = 3, k = 3) from nurbs_additional_functions.cc.
    assert_eq!(
        gcode::linuxcnc_knot_vector(7, 4),
        vec![0., 0., 0., 0., 1., 2., 3., 4., 4., 4., 4.]
    );
    assert_eq!(gcode::linuxcnc_knot_vector(4, 3), vec![0., 0., 0., 1., 2., 2., 2.]);
}

#[test]
fn nurbs_block_weights_order_and_first_point() {
    // The LinuxCNC manual's example: default order 3, P on every point.
    let t = ok("G0 X0 Y0\nF10\nG5.2 X0 Y1 P1 L3\nX2 Y2 P1\nX2 Y0 P1\nX0 Y0 P2\nG5.3\n");
    let c = &t.elements[0].curve;
    assert_eq!(c.degree(), 2);
    assert_eq!(c.control_point_count(), 5);
    assert_eq!(c.weights(), &[1.0, 1.0, 1.0, 1.0, 2.0]);
    assert_eq!(c.control_point(0), &[0.0, 0.0]);
    assert_eq!(c.knots(), &[0., 0., 0., 1., 2., 3., 3., 3.]);
    assert!((t.elements[0].feed.unwrap() - 10.0 / 60.0).abs() < 1e-15);
    // P without X Y on the opening line weights the start point; L > 3 on a later line counts.
    let t = ok("G0 X0 Y0\nF60\nG5.2 P3\nX1 Y1 P1\nX2 Y0 P1 L4\nX3 Y1 P1\nG5.3\n");
    let c = &t.elements[0].curve;
    assert_eq!(c.weights(), &[3.0, 1.0, 1.0, 1.0]);
    assert_eq!(c.degree(), 3);
    // L <= 3 is ignored (LinuxCNC only takes L > 3).
    let t = ok("G0 X0 Y0\nF60\nG5.2 X1 Y1 P1 L2\nX2 Y0 P1\nG5.3\n");
    assert_eq!(t.elements[0].curve.degree(), 2);
    // Repeating G5.2 on every line continues the block; the position after G5.3 is the last point.
    let t = ok("G0 X0 Y0\nF60\nG5.2 X1 Y1 P1\nG5.2 X2 Y0 P1\nG5.3\nG1 X5\n");
    assert_eq!(t.elements.len(), 2);
    assert_eq!(t.elements[1].curve.control_point(0), &[2.0, 0.0]);
    assert_eq!(t.elements[1].curve.control_point(1), &[5.0, 0.0]);
}

#[test]
fn nurbs_in_g91_is_relative_to_block_start() {
    // find_ends adds settings->current_x, which convert_nurbs only updates at G5.3.
    let t = ok("G0 X10 Y10\nG91 F60\nG5.2 X1 Y1 P1\nX2 Y0 P1\nG5.3\n");
    let c = &t.elements[0].curve;
    assert_eq!(c.control_point(1), &[11.0, 11.0]);
    assert_eq!(c.control_point(2), &[12.0, 10.0]);
}

#[test]
fn g1_moves_become_one_polyline_with_chord_length_knots() {
    let t =
        ok("N10 G21 G90 G17 G94 (setup)\nG0 X0 Y0 ; rapid\nG1 X3 Y4 F600\nX3 Y0\nG1 X3 Y0 (zero length, skipped)\n");
    assert_eq!(t.elements.len(), 1);
    let e = &t.elements[0];
    assert_eq!(e.kind, ElementKind::Polyline);
    assert_eq!(e.feed, Some(10.0));
    assert_eq!(e.source_line, Some(3));
    assert_eq!(e.curve.degree(), 1);
    assert_eq!(e.curve.knots(), &[0.0, 0.0, 5.0, 9.0, 9.0]);
    assert_eq!(e.curve.points(), &[0.0, 0.0, 3.0, 4.0, 3.0, 0.0]);
    assert_eq!(t.tip_dim(), 2);
    // A feed change splits the polyline.
    let t = ok("G0 X0 Y0\nG1 X1 F60\nX2 F120\nX3\n");
    assert_eq!(t.elements.len(), 2);
    assert_eq!(t.elements[0].feed, Some(1.0));
    assert_eq!(t.elements[1].feed, Some(2.0));
    assert_eq!(t.elements[1].curve.control_point_count(), 3);
}

#[test]
fn g20_inches_and_feed_conversion() {
    let t = ok("G20\nG0 X0 Y0\nG1 X1 Y2 F60\n");
    let e = &t.elements[0];
    assert_eq!(e.curve.control_point(1), &[25.4, 50.8]);
    assert!((e.feed.unwrap() - 25.4).abs() < 1e-12); // 60 in/min = 1 in/s
                                                     // F runs before G20 on the same line (order of execution): F60 is mm/min here.
    let t = ok("G0 X0 Y0\nG20 F60 G1 X1\n");
    assert!((t.elements[0].feed.unwrap() - 1.0).abs() < 1e-12);
    assert_eq!(t.elements[0].curve.control_point(1), &[25.4, 0.0]);
    // A feed keeps its physical value across a later unit change.
    let t = ok("G20\nF60\nG0 X0 Y0\nG21\nG1 X10\n");
    assert!((t.elements[0].feed.unwrap() - 25.4).abs() < 1e-12);
}

#[test]
fn g91_incremental() {
    let t = ok("G0 X1 Y1\nG91\nG1 X1 F60\nY2\nX-1 Y-1\n");
    let c = &t.elements[0].curve;
    assert_eq!(c.points(), &[1.0, 1.0, 2.0, 1.0, 2.0, 3.0, 1.0, 2.0]);
}

fn check_arc(c: &Nurbs, center: [f64; 2], r: f64, start: [f64; 2], end: [f64; 2]) {
    assert_eq!(c.degree(), 2);
    assert!(close(&pt(c, c.u_min()), &start, 1e-12));
    assert!(close(&pt(c, c.u_max()), &end, 1e-12));
    let n = 2000;
    for i in 0..=n {
        let u = c.u_min() + (c.u_max() - c.u_min()) * i as f64 / n as f64;
        let p = pt(c, u);
        let d = (p[0] - center[0]).hypot(p[1] - center[1]);
        assert!((d - r).abs() < 1e-12, "radius {d} at u = {u}");
    }
}

#[test]
fn arcs_are_exact_rational_quadratics() {
    // Quarter circle CCW, radius 10, centre (0,0).
    let t = ok("G0 X10 Y0\nG3 X0 Y10 I-10 J0 F600\n");
    let e = &t.elements[0];
    assert_eq!(e.kind, ElementKind::Arc);
    check_arc(&e.curve, [0.0, 0.0], 10.0, [10.0, 0.0], [0.0, 10.0]);
    assert_eq!(e.curve.control_point_count(), 3);
    assert!((e.curve.weights()[1] - (std::f64::consts::FRAC_PI_4).cos()).abs() < 1e-15);
    // Arc-length knots: quarter circle of radius 10.
    assert!((e.curve.u_max() - 5.0 * std::f64::consts::PI).abs() < 1e-12);
    assert!((analyze(&e.curve).arc_length_mm - 5.0 * std::f64::consts::PI).abs() < 1e-9);
    // Mid point goes counter-clockwise (through 45 degrees).
    let mid = pt(&e.curve, e.curve.u_max() / 2.0);
    assert!(mid[0] > 0.0 && mid[1] > 0.0);

    // Clockwise three-quarter circle about (5,5): split into three 90-degree pieces.
    let t = ok("G0 X8 Y5\nG2 X5 Y8 I-3 J0 F600\n");
    let c = &t.elements[0].curve;
    check_arc(c, [5.0, 5.0], 3.0, [8.0, 5.0], [5.0, 8.0]);
    assert_eq!(c.control_point_count(), 7);
    let q = pt(c, c.u_max() / 3.0);
    assert!(close(&q, &[5.0, 2.0], 1e-12), "{q:?}");
    assert!((analyze(c).arc_length_mm - 4.5 * std::f64::consts::PI).abs() < 1e-9);

    // Full circle (start = end) with I J, and P2 = two full turns.
    let t = ok("G0 X1 Y0\nG3 I-1 J0 F60\n");
    assert!((analyze(&t.elements[0].curve).arc_length_mm - 2.0 * std::f64::consts::PI).abs() < 1e-9);
    let t = ok("G0 X1 Y0\nG2 X1 Y0 I-1 P2 F60\n");
    let c = &t.elements[0].curve;
    check_arc(c, [0.0, 0.0], 1.0, [1.0, 0.0], [1.0, 0.0]);
    assert!((analyze(c).arc_length_mm - 4.0 * std::f64::consts::PI).abs() < 1e-9);

    // R format: positive R the short way, negative R the long way.
    let t = ok("G0 X0 Y0\nG2 X10 Y0 R5 F60\n");
    let c = &t.elements[0].curve;
    check_arc(c, [5.0, 0.0], 5.0, [0.0, 0.0], [10.0, 0.0]);
    assert!(pt(c, c.u_max() / 2.0)[1] > 4.99); // CW from (0,0) to (10,0) goes over the top
    let t = ok("G0 X0 Y0\nG3 X5 Y5 R-5 F60\n");
    let c = &t.elements[0].curve;
    check_arc(c, [5.0, 0.0], 5.0, [0.0, 0.0], [5.0, 5.0]);
    assert!((analyze(c).arc_length_mm - 7.5 * std::f64::consts::PI).abs() < 1e-9);

    // Absolute centre with G90.1.
    let t = ok("G90.1\nG0 X10 Y0\nG3 X0 Y10 I0 J0 F60\n");
    check_arc(&t.elements[0].curve, [0.0, 0.0], 10.0, [10.0, 0.0], [0.0, 10.0]);

    // Rounded centre (radii differ by 5e-5 mm): the circle goes exactly through both end points.
    let t = ok("G0 X10 Y0\nG3 X0 Y10.00005 I-10 J0 F60\n");
    let c = &t.elements[0].curve;
    assert!(close(&pt(c, c.u_max()), &[0.0, 10.00005], 1e-12));
    assert!(close(&pt(c, 0.0), &[10.0, 0.0], 1e-12));
}

#[test]
fn three_d_when_z_is_known_where_the_feed_motion_begins() {
    let t = ok("G0 X0 Y0 Z5\nG1 Z-1 F60\nG1 X10\nG2 X20 Y0 R5\nG5.2 X25 Y5 P1\nX30 Y0 P1\nG5.3\nG0 Z5\nM30\nG1 X99\n");
    assert_eq!(t.tip_dim(), 3);
    assert_eq!(t.elements.len(), 3);
    assert_eq!(
        t.elements[0].curve.points(),
        &[0.0, 0.0, 5.0, 0.0, 0.0, -1.0, 10.0, 0.0, -1.0]
    );
    assert_eq!(t.elements[1].curve.control_point(0), &[10.0, 0.0, -1.0]);
    assert_eq!(t.elements[2].curve.control_point(2), &[30.0, 0.0, -1.0]);
    // Z known where the feed motion begins (positioned by rapids only): 3-D at that Z, decided
    // at the first feed move so that a program streams.
    let t = ok("G0 X0 Y0 Z5\nG0 Z-1\nG1 X10 F60\nG0 Z5\n");
    assert_eq!(t.tip_dim(), 3);
    assert_eq!(t.elements.len(), 1);
    assert_eq!(t.elements[0].curve.points(), &[0.0, 0.0, -1.0, 10.0, 0.0, -1.0]);
    // Z never programmed: 2-D.
    let t = ok("G0 X0 Y0\nG1 X10 F60\nG2 X20 Y0 R5\n");
    assert_eq!(t.tip_dim(), 2);
    assert_eq!(t.elements.len(), 2);
}

#[test]
fn accepted_modal_codes_and_syntax() {
    let t = ok("%\n(header)\nn0010 g21 g17 g40 g49 g54 g64 p0.01 q0.01 g80 g90 g94 g97 g98\n\
                M3 S1000 T1 M6 M8\nG43 H1\nG0 x 1 0 y0\n  G01 X+20 Y-.5 f 1200 ( inline ) ; trailing\nM9 M5\nM2\n%\nG1 X100\n");
    assert_eq!(t.elements.len(), 1);
    assert_eq!(t.elements[0].curve.points(), &[10.0, 0.0, 20.0, -0.5]);
    assert_eq!(t.elements[0].feed, Some(20.0));
}

#[test]
fn read_toolpath_picks_gcode_by_extension() {
    let dir = std::env::temp_dir().join(format!("nm_gcode_{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let p = dir.join("square.nc");
    std::fs::write(&p, "G0 X0 Y0\nG1 X1 F60\nY1\nX0\nY0\n").unwrap();
    let t = read_toolpath(&p).unwrap();
    assert_eq!(t.elements[0].curve.control_point_count(), 5);
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn malformed_inputs_give_specific_errors() {
    // Empty file and a program without feed moves.
    let e = gcode::parse("t.ngc", "  \n\n").unwrap_err();
    assert!(e.message.contains("empty"), "{e}");
    let e = gcode::parse("t.ngc", "G0 X0 Y0\nM2\n").unwrap_err();
    assert!(e.message.contains("no feed moves"), "{e}");

    // Truncated NURBS block (no G5.3 at end of file, or M2 inside it).
    fails("G0 X0 Y0\nF60\nG5.2 X1 Y1 P1 L3\nX2 Y0 P1\n", 4, "opened at line 3");
    fails(
        "G0 X0 Y0\nF60\nG5.2 X1 Y1 P1 L3\nX2 Y0 P1\nM2\n",
        5,
        "M2 is not allowed inside a G5.2",
    );
    // Unknown / other G-codes inside a NURBS block.
    let e = fails(
        "G0 X0 Y0\nF60\nG5.2 X1 Y1 P1\nG7.7 X2 Y0 P1\nG5.3\n",
        4,
        "unknown G-code G7.7",
    );
    assert_eq!(e.column, Some(1));
    fails(
        "G0 X0 Y0\nF60\nG5.2 X1 Y1 P1\nG1 X2 Y0\nG5.3\n",
        4,
        "G1 is not allowed inside a G5.2 NURBS block",
    );
    fails(
        "G0 X0 Y0\nF60\nG5.2 X1 Y1 P1\nX2 Y0 Z1 P1\nG5.3\n",
        4,
        "Z word is not allowed inside a G5.2",
    );
    // NURBS rules from convert_nurbs.
    fails("G0 X0 Y0\nF60\nG5.2 X1 P1\nG5.3\n", 3, "both X and Y");
    fails("G0 X0 Y0\nF60\nG5.2 X1 Y1 P1\nX2 Y0\nG5.3\n", 4, "positive weight P");
    fails("G0 X0 Y0\nF60\nG5.2 X1 Y1 P1\nX2 Y0 P0\nG5.3\n", 4, "positive weight P");
    fails("G0 X0 Y0\nF60\nG5.2 X1 Y1\nG5.3\n", 3, "positive weight P");
    fails(
        "G0 X0 Y0\nF60\nG5.2 X1 Y1 P1\nG5.2 P2\nG5.3\n",
        4,
        "P without X and Y only for the first",
    );
    fails(
        "G0 X0 Y0\nF60\nG5.2 X1 Y1 P1 L4\nX2 Y0 P1\nG5.3\n",
        5,
        "at least equal to the order L = 4",
    );
    fails("G0 X0 Y0\nG5.2 X1 Y1 P1\nX2 Y0 P1\nG5.3\n", 2, "0 feedrate");
    fails("G0 X0 Y0\nF60\nG5.3\n", 3, "G5.3 without G5.2");
    fails("G0 X0 Y0\nF60\nG5.2 X1 Y1 P1 L9\nG5.3\n", 3, "order L = 9");
    fails("G0 X0 Y0\nF60\nG5.2 X1 Y1 P1\nX2 Y0 P1\nG5.3 X3 Y3\n", 5, "G5.3 line");
    fails("F60\nG5.2 X1 Y1 P1\n", 2, "current X position is unknown");

    // Unsupported path-changing codes name line and column.
    let e = fails("G0 X0 Y0\nG41 D1\n", 2, "cutter radius compensation");
    assert_eq!(e.column, Some(1));
    let e = fails("G0 X0 Y0\nG1 X1 F60\n  G42\n", 3, "G42");
    assert_eq!(e.column, Some(3));
    fails("G18\n", 1, "only the XY plane");
    fails("G19\n", 1, "only the XY plane");
    fails("G0 X0 Y0\nG5 X1 Y1 I0 J1 P0 Q1\n", 2, "G5/G5.1");
    fails("G0 X0 Y0\nG5.1 X1 Y1 I0 J1\n", 2, "G5/G5.1");
    fails(
        "G0 X0 Y0\nG93 G2 X2 Y0 I1 J0 F10\n",
        2,
        "inverse time (G93) is not supported",
    );
    fails("G95\n", 1, "feed per revolution");
    fails("G92 X0\n", 1, "G92");
    fails("G81 X0 Y0 Z-1 R1\n", 1, "canned cycles");
    fails("G4 P1\n", 1, "dwell");
    fails("G0 X0 Y0\nG1 X1 U10 F60\n", 2, "axis U is not supported");
    let e = fails("G0 X0 Y0\nG12.5\n", 2, "unknown G-code G12.5");
    assert_eq!(e.column, Some(1));
    fails("M100\n", 1, "M100 is not supported");
    fails("#1=5\n", 1, "parameters");
    fails("G1 X[1+2]\n", 1, "expressions");
    fails("o100 sub\n", 1, "O-words");
    fails("/G1 X1\n", 1, "block delete");
    // Syntax errors.
    let e = fails("G0 X0 Y0\nG1 X1 (unclosed F60\n", 2, "unclosed comment");
    assert_eq!(e.column, Some(7));
    fails("G1 X1 (a (b) c)\n", 1, "nested comment");
    fails("G0 X\n", 1, "bad number format");
    fails("G0 X1 X2\n", 1, "multiple X words");
    fails("G0 G1 X1\n", 1, "same modal group");
    fails("G0 X0 Y0 N5\n", 1, "N line number");
    fails("G0 X0 Y0\nX1 $\n", 2, "bad character");
    fails("%\nG0 X0 Y0\nG1 X1 F60\n", 3, "no closing percent");
    // Motion rules.
    fails("X1 Y1\n", 1, "without a G-code that uses them");
    fails("G0 X0 Y0\nG1 X1\n", 2, "zero feed rate");
    fails("G1 X1 F60\n", 1, "current X position is unknown");
    fails("G0 X0\nG1 X1 F60\n", 2, "current Y position is unknown");
    fails("G91 G0 X1\n", 1, "current X position is unknown");
    fails("G0 X0 Y0\nG1 X1 F60\nG55\n", 3, "coordinate system");
    fails("G0 X0 Y0\nG1 X1 F60\nG0 X5\nG1 X6\n", 3, "G0 rapid between feed moves");
    fails("G0 X0 Y0\nG1 X1 I1 F60\n", 2, "I word with no G2 or G3");
    fails("G0 X0 Y0\nG1 X1 L2 F60\n", 2, "L word with no G5.2");
    fails("G0 X0 Y0\nF-1\n", 2, "negative F");
    // Arc errors (interp_arc.cc).
    fails("G0 X0 Y0\nG2 X1 Y0 F60\n", 2, "R, I, J, and K words all missing");
    fails("G0 X0 Y0\nG2 X1 Y0 R1 I1 F60\n", 2, "mixed radius-ijk");
    fails("G0 X0 Y0\nG2 X10 Y0 R4 F60\n", 2, "radius too small");
    fails("G0 X0 Y0\nG2 X0 Y0 R4 F60\n", 2, "same as end point");
    fails("G0 X0 Y0\nG2 X2.1 Y0 I1 J0 F60\n", 2, "radius to end of arc differs");
    fails("G0 X0 Y0\nG2 X0 Y0 I0 J0 F60\n", 2, "zero-radius arc");
    fails("G0 X0 Y0 Z0\nG2 X2 Y0 Z1 I1 F60\n", 2, "helical");
    fails("G0 X0 Y0\nG2 X2 Y0 I1 K1 F60\n", 2, "K word");
    fails("G0 X0 Y0\nG2 X2 Y0 I1 P1.5 F60\n", 2, "number of turns");
    fails("G0 X0 Y0\nG2 X2 Y0 I1 P1e9 F60\n", 2, "E word is not supported");
    fails("G0 X0 Y0\nG2 X2 Y0 I1 P1000000000 F60\n", 2, "turns is not supported");
    fails(
        "G90.1\nG0 X0 Y0\nG2 X2 Y0 I1 F60\n",
        3,
        "J word missing in absolute center arc",
    );
    // 3-D program whose Z is never positioned.
    // The path is 2-D when Z is unknown where its feed motion begins: a Z word later is refused.
    fails(
        "G0 X0 Y0\nG1 X1 F60\nG1 Z-1\n",
        3,
        "Z position was unknown where the feed motion began",
    );
    fails(
        "G0 X0 Y0\nG1 Z-1 F60\n",
        2,
        "Z position was unknown where the feed motion began",
    );
}

#[test]
fn never_panics_on_garbage() {
    let samples = [
        "G",
        "G1.",
        "X.",
        "G5.2",
        "G5.3",
        "F",
        "G1 X1e5",
        "G0 X0 Y0\nG5.2 L3\nG5.3",
        "(((",
        ")",
        "G2 R0 X1",
        "G0 X0 Y0\nG2 X1 R0 F1",
        "G0 X0 Y0\nG3 X1e308 Y-1e308 R1e-308 F1",
        "\u{0}\u{1}",
        "G0 X0 Y0\nG1 X1 F1e400",
        "N",
        "N1",
        "M",
        "M2.5",
        "T-1",
        "G0 X0 Y0\nG5.2 P-1",
        "G0 X0 Y0 F1\nG5.2 X1 Y1 P1 L100000000000",
    ];
    for s in samples {
        let _ = gcode::parse("g.ngc", s);
    }
    // Every prefix of a valid program.
    let prog = std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("examples/trident.ngc")).unwrap();
    for cut in 0..prog.len() {
        if prog.is_char_boundary(cut) {
            let _ = gcode::parse("g.ngc", &prog[..cut]);
        }
    }
}

/// Coordinates beyond any machine (a mutated file's 1e13 mm) are refused with the line that
/// has them, before any planning: they would plan for minutes, and at the servo period the
/// finite differences of such positions lose the precision the limit check needs.
#[test]
fn coordinates_beyond_any_machine_are_refused_up_front() {
    let dir = std::env::temp_dir().join(format!("nurbs-gcode-sizes-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("far.ngc");
    std::fs::write(&path, "G21 G90\nG0 X0 Y0\nF600\nG1 X10 Y0\nG1 X10000000000000 Y5\nM2\n").unwrap();
    let e = read_toolpath(&path).expect_err("refused");
    assert!(e.to_string().contains("beyond 1000000 mm"), "{e}");
    // The G1 lines from line 4 on are one polyline element: it names where it starts.
    assert!(
        e.to_string().contains(":4: the path element that starts here"),
        "names the element: {e}"
    );
    std::fs::write(&path, "G21 G90\nG0 X0 Y0\nF600\nG1 X10 Y0\nG1 X999999 Y5\nM2\n").unwrap();
    assert!(read_toolpath(&path).is_ok(), "a long but possible line is read");
    std::fs::remove_dir_all(&dir).ok();
}

/// The tool axis of rotary angles `a` (tilt about X, degrees) and `c`, and the angles back on
/// the negative-tilt branch.
fn tool_axis(tilt: nurbs_motion::kinematics::Tilt, a: f64, c: f64) -> [f64; 3] {
    nurbs_motion::kinematics::TrtGeometry {
        tilt,
        ..Default::default()
    }
    .tool_axis(a, c)
}

/// `G1 X Y Z A C` (XYZAC, table-tilting): a 5-axis polyline whose vertices are the tool tip and
/// the point `TOP_LENGTH` up the tool axis of the programmed angles; the angles come back from
/// the tool axis on their branch; a move turning more than 0.5° is cut into equal pieces along
/// which tip and angles are linear (as LinuxCNC interpolates them); its ends are the poses.
#[test]
fn five_axis_g1_has_the_tool_axis_of_its_angles() {
    use nurbs_motion::kinematics::{TableTilting, Tilt, TrtGeometry};
    let t = ok("G21 G90 G94\nG0 X0 Y0 Z5 A-30 C10\nG1 X10 Y0 Z5 A-30 C10 F600\nG1 X20 Y5 Z4 A-32 C20\nM2\n");
    assert_eq!(t.elements.len(), 1);
    let c = &t.elements[0].curve;
    assert_eq!((c.dim(), c.tip_dim(), c.degree()), (6, 3, 1));
    // One piece, then 2° of A and 10° of C in 24 pieces of 0.5° together.
    assert_eq!(c.control_point_count(), 2 + 24);
    assert_eq!(t.elements[0].feed, Some(10.0));
    let machine = TableTilting {
        geometry: TrtGeometry::default(),
        negative_tilt: true,
    };
    for (k, (tip, a, cc)) in [
        ([0.0, 0.0, 5.0], -30.0, 10.0),
        ([10.0, 0.0, 5.0], -30.0, 10.0),
        ([20.0, 5.0, 4.0], -32.0, 20.0),
    ]
    .into_iter()
    .enumerate()
    {
        let p = c.control_point([0, 1, 25][k]);
        let axis = tool_axis(Tilt::X, a, cc);
        assert!(close(&p[..3], &tip, 0.0), "{p:?}");
        for i in 0..3 {
            assert!((p[3 + i] - tip[i] - gcode::TOP_LENGTH * axis[i]).abs() < 1e-12, "{p:?}");
        }
        let top_dir: Vec<f64> = (0..3).map(|i| p[3 + i] - p[i]).collect();
        let (ta, tc) = machine.angles([top_dir[0], top_dir[1], top_dir[2]], Some(cc));
        assert!((ta - a).abs() < 1e-9 && (tc - cc).abs() < 1e-9, "{ta} {tc}");
    }
    // Along the turning move: the top point at every vertex is that of linearly interpolated
    // angles, and between vertices the chord strays from it by at most 1e-4 mm.
    let (a0, b0) = (([10.0, 0.0, 5.0], -30.0, 10.0), ([20.0, 5.0, 4.0], -32.0, 20.0));
    let exact = |lambda: f64| -> [f64; 6] {
        let tip: Vec<f64> = (0..3).map(|i| a0.0[i] + (b0.0[i] - a0.0[i]) * lambda).collect();
        let axis = tool_axis(Tilt::X, a0.1 + (b0.1 - a0.1) * lambda, a0.2 + (b0.2 - a0.2) * lambda);
        core::array::from_fn(|i| {
            if i < 3 {
                tip[i]
            } else {
                tip[i - 3] + gcode::TOP_LENGTH * axis[i - 3]
            }
        })
    };
    let mut worst: f64 = 0.0;
    for k in 0..=4800 {
        let lambda = k as f64 / 4800.0;
        let e = exact(lambda);
        let u_start = c.knots()[2];
        let u = u_start + (c.u_max() - u_start) * lambda;
        let p = pt(c, u);
        for i in 0..6 {
            worst = worst.max((p[i] - e[i]).abs());
        }
    }
    assert!(
        worst <= 1e-4 && worst > 1e-6,
        "top chord off the interpolated pose by {worst}"
    );
    // XYZBC: B words tilt about Y.
    let t = ok("G0 X0 Y0 Z0 B20 C-100\nG1 X1 F60\n");
    let p = t.elements[0].curve.control_point(0).to_vec();
    let axis = tool_axis(Tilt::Y, 20.0, -100.0);
    assert!(
        (0..3).all(|i| (p[3 + i] - gcode::TOP_LENGTH * axis[i]).abs() < 1e-12),
        "{p:?}"
    );
}

/// `G93` inverse time: each `G1` takes 1/F minutes, so its tool-tip feed is its length times
/// F / 60 (per move, not modal: F on every `G1`); `G94` sets the feed to 0 again, as in
/// LinuxCNC; arcs and rotary words keep within what the path can hold.
#[test]
fn inverse_time_and_five_axis_errors() {
    let t = ok("G0 X0 Y0 Z0 A1 C0\nG93 G1 X3 Y4 F30\nG1 X3 Y10 F60\nM2\n");
    let feeds: Vec<f64> = t.elements.iter().map(|e| e.feed.unwrap()).collect();
    assert_eq!(feeds, vec![2.5, 6.0]);
    // Inverse time on a 3-axis path too.
    let t = ok("G0 X0 Y0\nG93 G1 X6 Y8 F120\n");
    assert_eq!(t.elements[0].feed, Some(20.0));
    fails(
        "G0 X0 Y0\nG93 G1 X6 Y8 F120\nG1 X7\n",
        3,
        "F word missing with inverse time G1 move",
    );
    fails("G0 X0 Y0\nF600\nG94\nG1 X1\n", 4, "zero feed rate");
    // An arc at constant angles carries its top curve; one that turns a rotary axis is refused.
    let t = ok("G0 X0 Y0 Z0 A10 C0\nG1 X1 F60\nG2 X3 Y0 I1 J0\n");
    assert_eq!(t.elements[1].curve.dim(), 6);
    fails(
        "G0 X0 Y0 Z0 A10 C0\nF60\nG2 X2 Y0 I1 J0 C5\n",
        3,
        "only G0 and G1 may turn a rotary axis",
    );
    fails(
        "G0 X0 Y0 Z0 A10 C0\nF60\nG5.2 X1 Y1 P1 C4\n",
        3,
        "only G0 and G1 may turn a rotary axis",
    );
    // One tilt axis; both rotary axes known where a 5-axis path begins; Z too.
    fails("G0 X0 Y0 Z0 A10 C0\nG0 B4\n", 2, "one tilt axis");
    fails("G0 X0 Y0 Z0 C0\nG1 X1 F60\n", 2, "C is positioned but A is not");
    fails("G0 X0 Y0 A0 C0\nG1 X1 F60\n", 2, "needs Z positioned");
    // A rotary move where the path began as 3-axis, and a pure reorientation.
    fails("G0 X0 Y0 Z0\nG1 X1 F60\nG1 X2 A5\n", 3, "a 3-axis path");
    fails("G0 X0 Y0 Z0 A5 C0\nG1 X1 F60\nG1 C30\n", 3, "pure reorientation");
    // The singularity: the tilt at 0, or changing sign, on a feed move.
    fails(
        "G0 X0 Y0 Z0 A0 C0\nG1 X1 F60\n",
        2,
        "A is 0 on this move, or changes sign (A0 to A0)",
    );
    fails("G0 X0 Y0 Z0 A5 C0\nG1 X1 F60\nG1 X2 A-5\n", 3, "(A5 to A-5)");
    fails("G0 X0 Y0 Z0 B0 C0\nF60\nG2 X2 Y0 I1 J0\n", 3, "B is 0");
}
