//! DXF reader: spline round trip, exact clamping of unclamped splines, lines, polylines with
//! bulges, arcs, units and malformed input.

use dxf::entities::{Arc, Circle, Ellipse, Entity, EntityType, Line, LwPolyline, Spline};
use dxf::enums::{AcadVersion, Units};
use dxf::LwPolylineVertex;
use dxf::{Drawing, Point};
use nurbs_motion::geometry::*;
use nurbs_motion::readers::{dxf as dxf_reader, json, read_toolpath, ReadError};
use std::path::Path;

fn bytes_of(entities: Vec<EntityType>, units: Units) -> Vec<u8> {
    let mut d = Drawing::new();
    d.header.version = AcadVersion::R2013;
    d.header.default_drawing_units = units;
    for e in entities {
        d.add_entity(Entity::new(e));
    }
    let mut out = Vec::new();
    d.save(&mut out).unwrap();
    out
}

fn read(entities: Vec<EntityType>) -> Result<Toolpath, ReadError> {
    dxf_reader::parse("t.dxf", &bytes_of(entities, Units::Millimeters))
}

fn spline(degree: i32, knots: Vec<f64>, points: &[[f64; 3]], weights: Vec<f64>) -> EntityType {
    let mut s = Spline {
        degree_of_curve: degree,
        knot_values: knots,
        weight_values: weights,
        ..Default::default()
    };
    s.control_points = points.iter().map(|p| Point::new(p[0], p[1], p[2])).collect();
    s.set_is_rational(!s.weight_values.is_empty());
    EntityType::Spline(s)
}

fn fails(entities: Vec<EntityType>, needle: &str) {
    let e = read(entities).expect_err("expected an error");
    assert!(
        e.message.contains(needle),
        "{:?} does not contain {needle:?}",
        e.message
    );
}

fn pt(c: &Nurbs, u: f64) -> Vec<f64> {
    c.point(u)[..c.dim()].to_vec()
}

/// Independent reference: rational de Boor on possibly unclamped knots.
fn de_boor(p: usize, knots: &[f64], pts: &[[f64; 3]], w: &[f64], u: f64) -> [f64; 3] {
    let n = pts.len();
    let mut k = p;
    while k + 1 < n && knots[k + 1] <= u {
        k += 1;
    }
    let mut d: Vec<[f64; 4]> = (0..=p)
        .map(|j| {
            let i = j + k - p;
            [pts[i][0] * w[i], pts[i][1] * w[i], pts[i][2] * w[i], w[i]]
        })
        .collect();
    for r in 1..=p {
        for j in (r..=p).rev() {
            let i = j + k - p;
            let a = (u - knots[i]) / (knots[i + 1 + p - r] - knots[i]);
            let prev = d[j - 1];
            for (c, v) in d[j].iter_mut().enumerate() {
                *v = (1.0 - a) * prev[c] + a * *v;
            }
        }
    }
    [d[p][0] / d[p][3], d[p][1] / d[p][3], d[p][2] / d[p][3]]
}

#[test]
fn rational_spline_round_trips() {
    let knots = vec![0.0, 0.0, 0.0, 0.0, 0.3, 0.35, 0.35, 0.9, 1.7, 1.7, 1.7, 1.7];
    let pts = [
        [0.0, 0.0, 0.0],
        [1.0, 2.0, 0.5],
        [3.0, 2.5, 1.0],
        [4.0, 0.0, 0.0],
        [5.0, -1.0, 2.0],
        [6.5, 1.0, 0.0],
        [7.0, 3.0, 1.0],
        [9.0, 0.0, 0.0],
    ];
    let weights = vec![1.0, 0.5, 2.0, 1.0, 0.75, 3.0, 1.0, 1.0];
    let t = read(vec![spline(3, knots.clone(), &pts, weights.clone())]).unwrap();
    assert_eq!(t.elements.len(), 1);
    let e = &t.elements[0];
    assert_eq!(e.kind, ElementKind::Nurbs);
    assert_eq!(e.feed, None);
    let c = &e.curve;
    assert_eq!(c.degree(), 3);
    assert_eq!(c.knots(), &knots[..]);
    assert_eq!(c.weights(), &weights[..]);
    assert_eq!(c.points(), &pts.concat()[..]);
    assert_eq!(t.tip_dim(), 3);
    // Planar spline at z = 0 reads as 2-D.
    let flat: Vec<[f64; 3]> = pts.iter().map(|p| [p[0], p[1], 0.0]).collect();
    let t = read(vec![spline(3, knots, &flat, vec![])]).unwrap();
    assert_eq!(t.tip_dim(), 2);
    assert_eq!(t.elements[0].curve.weights(), &[1.0; 8]);
}

#[test]
fn trident_fixture_matches_json() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let d = read_toolpath(&root.join("examples/trident.dxf")).unwrap();
    let j = json::parse(
        "trident.json",
        &std::fs::read_to_string(root.join("examples/trident.json")).unwrap(),
    )
    .unwrap();
    assert_eq!(d.elements.len(), 1);
    assert_eq!(d.elements[0].curve, j.elements[0].curve);
}

/// Writes examples/trident.dxf from examples/trident.json (run with `--ignored` to regenerate).
#[test]
#[ignore]
fn write_trident_fixture() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let j = json::parse(
        "trident.json",
        &std::fs::read_to_string(root.join("examples/trident.json")).unwrap(),
    )
    .unwrap();
    let c = &j.elements[0].curve;
    let pts: Vec<[f64; 3]> = (0..c.control_point_count())
        .map(|i| [c.control_point(i)[0], c.control_point(i)[1], 0.0])
        .collect();
    let bytes = bytes_of(vec![spline(3, c.knots().to_vec(), &pts, vec![])], Units::Millimeters);
    std::fs::write(root.join("examples/trident.dxf"), bytes).unwrap();
}

#[test]
fn unclamped_periodic_spline_is_clamped_exactly() {
    // A closed periodic cubic stored the standard way: uniform unclamped knots, first three
    // control points repeated at the end.
    let base = [
        [0.0, 0.0, 0.0],
        [4.0, -1.0, 0.0],
        [6.0, 3.0, 0.0],
        [2.0, 6.0, 0.0],
        [-2.0, 3.0, 0.0],
    ];
    let mut pts = base.to_vec();
    pts.extend_from_slice(&base[..3]);
    let w = vec![1.0, 2.0, 0.5, 1.0, 1.5, 1.0, 2.0, 0.5];
    let knots: Vec<f64> = (0..pts.len() + 4).map(|i| i as f64 * 0.5).collect();
    let mut s = match spline(3, knots.clone(), &pts, w.clone()) {
        EntityType::Spline(s) => s,
        _ => unreachable!(),
    };
    s.set_is_periodic(true);
    s.set_is_closed(true);
    let t = read(vec![EntityType::Spline(s)]).unwrap();
    let c = &t.elements[0].curve;
    assert_eq!(c.u_min(), knots[3]);
    assert_eq!(c.u_max(), knots[pts.len()]);
    for i in 0..=1000 {
        let u = c.u_min() + (c.u_max() - c.u_min()) * i as f64 / 1000.0;
        let r = de_boor(3, &knots, &pts, &w, u);
        assert!(
            (pt(c, u)[0] - r[0]).abs() < 1e-12 && (pt(c, u)[1] - r[1]).abs() < 1e-12,
            "at {u}"
        );
    }
    // Closed: ends meet.
    let (a, b) = (pt(c, c.u_min()), pt(c, c.u_max()));
    assert!((a[0] - b[0]).abs() < 1e-12 && (a[1] - b[1]).abs() < 1e-12);
}

#[test]
fn lines_chain_only_when_connected() {
    let line = |a: [f64; 2], b: [f64; 2]| {
        EntityType::Line(Line::new(Point::new(a[0], a[1], 0.0), Point::new(b[0], b[1], 0.0)))
    };
    let t = read(vec![
        line([0., 0.], [1., 0.]),
        line([1., 0.], [1., 1.]),
        line([1., 1.], [0., 1.]),
        line([5., 5.], [6., 5.]),
    ])
    .unwrap();
    assert_eq!(t.elements.len(), 2);
    assert_eq!(t.elements[0].kind, ElementKind::Polyline);
    assert_eq!(t.elements[0].curve.points(), &[0., 0., 1., 0., 1., 1., 0., 1.]);
    assert_eq!(t.elements[0].curve.knots(), &[0., 0., 1., 2., 3., 3.]);
    assert_eq!(t.elements[1].curve.points(), &[5., 5., 6., 5.]);
}

#[test]
fn lwpolyline_with_bulge_gives_exact_arcs() {
    let v = |x: f64, y: f64, bulge: f64| LwPolylineVertex {
        x,
        y,
        bulge,
        ..Default::default()
    };
    // Closed: (0,0)->(10,0) straight, (10,0)->(10,10) CCW semicircle (bulge 1, centre (10,5)),
    // (10,10)->(0,10)->(0,0) straight (closing segment).
    let mut p = LwPolyline {
        vertices: vec![
            v(0.0, 0.0, 0.0),
            v(10.0, 0.0, 1.0),
            v(10.0, 10.0, 0.0),
            v(0.0, 10.0, 0.0),
        ],
        ..Default::default()
    };
    p.set_is_closed(true);
    let t = read(vec![EntityType::LwPolyline(p)]).unwrap();
    let kinds: Vec<_> = t.elements.iter().map(|e| e.kind).collect();
    assert_eq!(
        kinds,
        vec![ElementKind::Polyline, ElementKind::Arc, ElementKind::Polyline]
    );
    let arc = &t.elements[1].curve;
    for i in 0..=500 {
        let u = arc.u_max() * i as f64 / 500.0;
        let q = pt(arc, u);
        assert!(((q[0] - 10.0).hypot(q[1] - 5.0) - 5.0).abs() < 1e-12);
        assert!(q[0] >= 10.0 - 1e-12, "CCW from (10,0) to (10,10) bulges to +X");
    }
    assert_eq!(pt(arc, arc.u_max()), vec![10.0, 10.0]);
    assert_eq!(t.elements[2].curve.points(), &[10., 10., 0., 10., 0., 0.]);
}

#[test]
fn arc_circle_and_units() {
    let mut a = Arc::new(Point::new(1.0, 1.0, 0.0), 2.0, 0.0, 90.0);
    a.normal = dxf::Vector::z_axis();
    let c = Circle::new(Point::new(0.0, 0.0, 0.0), 1.0);
    let bytes = bytes_of(vec![EntityType::Arc(a), EntityType::Circle(c)], Units::Inches);
    let t = dxf_reader::parse("u.dxf", &bytes).unwrap();
    let arc = &t.elements[0].curve;
    assert!((analyze(arc).arc_length_mm - std::f64::consts::PI * 25.4).abs() < 1e-9);
    let s = pt(arc, 0.0);
    assert!((s[0] - 3.0 * 25.4).abs() < 1e-12 && (s[1] - 25.4).abs() < 1e-12);
    let circle = &t.elements[1].curve;
    assert!((analyze(circle).arc_length_mm - 2.0 * std::f64::consts::PI * 25.4).abs() < 1e-9);
}

#[test]
fn malformed_dxf_errors() {
    let e = dxf_reader::parse("e.dxf", b"").unwrap_err();
    assert!(e.message.contains("empty"), "{e}");
    let e = dxf_reader::parse("g.dxf", b"0\nSECTION\n2\nENTITIES\n0\nLINE\n10\nnot-a-number\n").unwrap_err();
    assert!(e.message.contains("invalid DXF"), "{e}");
    let e = read(vec![]).unwrap_err();
    assert!(e.message.contains("no SPLINE"), "{e}");
    let p4 = [[0.0, 0.0, 0.0], [1.0, 1.0, 0.0], [2.0, 0.0, 0.0], [3.0, 1.0, 0.0]];
    let k = vec![0.0, 0.0, 0.0, 0.0, 1.0, 1.0, 1.0, 1.0];
    fails(
        vec![spline(3, vec![0.0, 0.0, 0.0, 0.0, 1.0, 1.0, 1.0], &p4, vec![])],
        "7 knots for 4 control points",
    );
    fails(
        vec![spline(3, vec![0.0, 0.0, 0.0, 1.0, 0.5, 1.0, 1.0, 1.0], &p4, vec![])],
        "not non-decreasing",
    );
    fails(
        vec![spline(3, k.clone(), &p4, vec![1.0, 0.0, 1.0, 1.0])],
        "weight 1 is 0",
    );
    fails(
        vec![spline(3, k.clone(), &p4, vec![1.0, -2.0, 1.0, 1.0])],
        "weights must be finite and > 0",
    );
    fails(
        vec![spline(3, k.clone(), &p4, vec![1.0, 1.0])],
        "2 weights for 4 control points",
    );
    fails(
        vec![spline(0, vec![0.0, 1.0, 2.0, 3.0], &p4, vec![])],
        "degree 0 is outside",
    );
    fails(
        vec![spline(8, (0..13).map(f64::from).collect(), &p4, vec![])],
        "degree 8 is outside",
    );
    fails(
        vec![spline(3, vec![0.0, 0.0, 0.0, 0.0, 1.0, 1.0, 1.0], &p4[..3], vec![])],
        "3 control points for degree 3",
    );
    fails(vec![spline(3, vec![1.0; 8], &p4, vec![])], "domain is empty");
    fails(
        vec![spline(
            3,
            vec![0.0, 0.0, 0.0, 0.0, f64::NAN, 1.0, 1.0, 1.0],
            &p4,
            vec![],
        )],
        "not finite",
    );
    fails(
        vec![spline(
            3,
            k.clone(),
            &[
                [0.0, 0.0, 0.0],
                [f64::INFINITY, 1.0, 0.0],
                [2.0, 0.0, 0.0],
                [3.0, 1.0, 0.0],
            ],
            vec![],
        )],
        "NaN or infinite",
    );
    let mut fit = Spline {
        degree_of_curve: 3,
        ..Default::default()
    };
    fit.fit_points = vec![Point::new(0.0, 0.0, 0.0), Point::new(1.0, 1.0, 0.0)];
    fails(vec![EntityType::Spline(fit)], "fit points only");
    fails(
        vec![EntityType::Ellipse(Ellipse::default())],
        "Ellipse is not supported",
    );
    let mut l = Line::new(Point::new(0.0, 0.0, 0.0), Point::new(1.0, 0.0, 0.0));
    l.extrusion_direction = dxf::Vector::new(0.0, 0.0, -1.0);
    fails(vec![EntityType::Line(l)], "not +Z");
}

#[test]
fn never_panics_on_garbage() {
    let good = bytes_of(
        vec![spline(
            2,
            vec![0.0, 0.0, 0.0, 1.0, 1.0, 1.0],
            &[[0.0, 0.0, 0.0], [1.0, 1.0, 0.0], [2.0, 0.0, 0.0]],
            vec![],
        )],
        Units::Millimeters,
    );
    for cut in (0..good.len()).step_by(97) {
        let _ = dxf_reader::parse("g.dxf", &good[..cut]);
    }
    let _ = dxf_reader::parse("g.dxf", &[0xff, 0x00, 0x13, 0x37]);
}

/// A header value the dxf library panics on (a date variable out of chrono's range, as odd CAD
/// exporters write) is a clear read error, not a crash: found by mutating the bundled trident.
#[test]
fn a_header_the_dxf_library_panics_on_is_a_read_error() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("examples/trident.dxf");
    let text = std::fs::read_to_string(path).unwrap();
    let bad = text.replacen(
        "$TDUPDATE\r\n 40\r\n2461367.190451388713",
        "$TDUPDATE\r\n 40\r\n2190451388713",
        1,
    );
    assert!(bad != text, "the mutation applies");
    let e = dxf_reader::parse("trident-bad-date.dxf", bad.as_bytes()).unwrap_err();
    assert!(e.to_string().contains("invalid DXF"), "{e}");
}
