//! NURBS geometry core against independent references: the `curvo` crate, an exact rational
//! circle, finite differences, and the independently computed stats of the benchmark curves.

use nalgebra::Point3;
use nurbs_motion::geometry::{analyze, ArcLengthTable, Nurbs};
use nurbs_motion::readers::read_toolpath;
use std::path::Path;

fn example(name: &str) -> Nurbs {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("examples").join(name);
    read_toolpath(&path).unwrap().elements.remove(0).curve
}

fn stats_of(name: &str) -> serde_json::Value {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("examples").join(name);
    let v: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap();
    v["stats"]["control_points"].clone()
}

const CURVES: [&str; 5] = [
    "butterfly.json",
    "trident.json",
    "fan.json",
    "open_pocket.json",
    "fan_5axis.json",
];

#[test]
fn arc_lengths_match_independent_stats_to_1e_6_mm() {
    for name in CURVES {
        let curve = example(name);
        let expected = stats_of(name)["arc_length_mm"].as_f64().unwrap();
        let got = ArcLengthTable::new(&curve).total();
        assert!((got - expected).abs() < 1e-6, "{name}: {got} vs {expected}");
        // The paper's adaptive Simpson agrees as well.
        let simpson = nurbs_motion::geometry::simpson_length(&curve, curve.u_min(), curve.u_max(), 1e-10);
        assert!(
            (simpson - expected).abs() < 1e-6,
            "{name}: Simpson {simpson} vs {expected}"
        );
    }
}

/// The control polygon bounds the arc length of a non-rational curve from above (what the hold
/// stops rely on to skip integrating an element's length): on the benchmark curves, a straight
/// line (where the two are equal) and a single short corner spline; none for a rational curve.
#[test]
fn control_polygon_bounds_the_arc_length() {
    let line = Nurbs::new(1, vec![0.0, 0.0, 1.0, 1.0], &[vec![3.0, 4.0], vec![3.012, 4.016]], None).unwrap();
    let corner = Nurbs::new(
        3,
        vec![0.0, 0.0, 0.0, 0.0, 1.0, 1.0, 1.0, 1.0],
        &[
            vec![0.0, 0.0],
            vec![0.004, 0.0],
            vec![0.008, 0.0003],
            vec![0.0119, 0.001],
        ],
        None,
    )
    .unwrap();
    let mut curves: Vec<Nurbs> = CURVES.iter().map(|name| example(name)).collect();
    curves.extend([line.clone(), corner]);
    for (k, curve) in curves.iter().enumerate() {
        let length = ArcLengthTable::new(curve).total();
        let Some(bound) = curve.polygon_length() else {
            assert!(curve.weights().iter().any(|&w| w != curve.weights()[0]), "curve {k}");
            continue;
        };
        // As the hold stops use it: above the polygon by more than the table's rounding.
        assert!(bound * (1.0 + 1e-9) + 1e-12 >= length, "curve {k}: {bound} < {length}");
        assert!(bound <= 10.0 * length, "curve {k}: {bound} vs {length}");
    }
    assert!((line.polygon_length().unwrap() - 0.02).abs() < 1e-15);
    let h = std::f64::consts::FRAC_1_SQRT_2;
    let quarter = Nurbs::new(
        2,
        vec![0.0, 0.0, 0.0, 1.0, 1.0, 1.0],
        &[vec![1.0, 0.0], vec![1.0, 1.0], vec![0.0, 1.0]],
        Some(vec![1.0, h, 1.0]),
    )
    .unwrap();
    assert_eq!(quarter.polygon_length(), None);
}

#[test]
fn max_curvature_and_bbox_match_independent_stats() {
    for name in CURVES {
        let curve = example(name);
        let s = stats_of(name);
        let got = analyze(&curve);
        let k = s["max_curvature_per_mm"].as_f64().unwrap();
        assert!(
            (got.max_curvature_per_mm - k).abs() <= 1e-3 * k.max(1e-9),
            "{name}: {} vs {k}",
            got.max_curvature_per_mm
        );
        for (a, (lo, hi)) in got.bbox_min.iter().zip(&got.bbox_max).enumerate() {
            let (elo, ehi) = (s["bbox_min"][a].as_f64().unwrap(), s["bbox_max"][a].as_f64().unwrap());
            // Independent stats come from sampling, so our refined extremes may only be wider.
            assert!(
                *lo <= elo + 1e-9 && *lo > elo - 1e-4,
                "{name} axis {a} min {lo} vs {elo}"
            );
            assert!(
                *hi >= ehi - 1e-9 && *hi < ehi + 1e-4,
                "{name} axis {a} max {hi} vs {ehi}"
            );
        }
    }
}

/// Quarter circles as rational quadratics: every point lies on the circle, the speed integrates
/// to the exact length, curvature is 1/r.
#[test]
fn exact_rational_circle() {
    let r = 7.5;
    let h = std::f64::consts::FRAC_1_SQRT_2;
    let pts = vec![
        vec![r, 0.0],
        vec![r, r],
        vec![0.0, r],
        vec![-r, r],
        vec![-r, 0.0],
        vec![-r, -r],
        vec![0.0, -r],
        vec![r, -r],
        vec![r, 0.0],
    ];
    let weights = vec![1.0, h, 1.0, h, 1.0, h, 1.0, h, 1.0];
    let knots = vec![0.0, 0.0, 0.0, 0.25, 0.25, 0.5, 0.5, 0.75, 0.75, 1.0, 1.0, 1.0];
    let c = Nurbs::new(2, knots, &pts, Some(weights)).unwrap();
    for i in 0..=1000 {
        let u = i as f64 / 1000.0;
        let p = c.point(u);
        assert!((p[0].hypot(p[1]) - r).abs() < 1e-12, "u={u}");
        assert!((c.curvature(u) - 1.0 / r).abs() < 1e-12, "u={u}");
    }
    let len = ArcLengthTable::new(&c).total();
    assert!((len - 2.0 * std::f64::consts::PI * r).abs() < 1e-11, "{len}");
}

/// Derivatives 1..3 agree with central differences of the next lower derivative.
#[test]
fn derivatives_match_finite_differences() {
    for name in CURVES {
        let curve = example(name);
        let view = curve.view();
        let h = 1e-6 * (curve.u_max() - curve.u_min());
        for i in 1..200 {
            let u = curve.u_min() + (curve.u_max() - curve.u_min()) * (i as f64 + 0.37) / 200.0;
            let d = view.derivatives(u, 3);
            let (dp, dm) = (view.derivatives(u + h, 3), view.derivatives(u - h, 3));
            for k in 1..=3.min(curve.degree()) {
                for a in 0..curve.dim() {
                    let fd = (dp[k - 1][a] - dm[k - 1][a]) / (2.0 * h);
                    let scale = 1.0 + d[k][a].abs() + dp[k][a].abs();
                    // Skip samples straddling a knot where the k-th derivative may jump.
                    if (dp[k][a] - dm[k][a]).abs() > 1e-3 * scale {
                        continue;
                    }
                    assert!(
                        (fd - d[k][a]).abs() < 1e-5 * scale,
                        "{name} u={u} k={k} axis={a}: {fd} vs {}",
                        d[k][a]
                    );
                }
            }
        }
    }
}

/// Points and first derivatives against the curvo crate (independent implementation) on a
/// rational curve with non-uniform weights and knots.
#[test]
fn matches_curvo_on_rational_curve() {
    let butterfly = example("butterfly.json");
    // Give the butterfly non-uniform weights to exercise the rational path.
    let n = butterfly.control_point_count();
    let weights: Vec<f64> = (0..n).map(|i| 0.3 + 2.0 * ((i as f64 * 0.7).sin().abs())).collect();
    let rows: Vec<Vec<f64>> = (0..n).map(|i| butterfly.control_point(i).to_vec()).collect();
    let ours = Nurbs::new(3, butterfly.knots().to_vec(), &rows, Some(weights.clone())).unwrap();
    let homogeneous: Vec<Point3<f64>> = rows
        .iter()
        .zip(&weights)
        .map(|(p, w)| Point3::new(p[0] * w, p[1] * w, *w))
        .collect();
    let theirs = curvo::prelude::NurbsCurve2D::try_new(3, homogeneous, butterfly.knots().to_vec()).unwrap();
    for i in 0..=500 {
        let u = i as f64 / 500.0;
        let p = ours.point(u);
        let q = theirs.point_at(u);
        assert!(
            (p[0] - q.x).abs() < 1e-9 && (p[1] - q.y).abs() < 1e-9,
            "u={u}: {p:?} vs {q:?}"
        );
        let d = ours.view().derivatives(u, 2);
        let e = theirs.rational_derivatives(u, 2);
        for k in 1..=2 {
            let scale = 1.0 + e[k].norm();
            assert!(
                (d[k][0] - e[k][0]).abs() < 1e-8 * scale && (d[k][1] - e[k][1]).abs() < 1e-8 * scale,
                "u={u} k={k}"
            );
        }
    }
}

#[test]
fn inverse_arc_length_map_round_trips() {
    let curve = example("butterfly.json");
    let table = ArcLengthTable::new(&curve);
    for i in 0..=100 {
        let s = table.total() * i as f64 / 100.0;
        let u = table.parameter_at(&curve, s);
        assert!((table.length_to(&curve, u) - s).abs() < 1e-9, "s={s}");
    }
}

#[test]
fn malformed_curves_are_rejected_with_the_reason() {
    use nurbs_rtcore::GeometryError::*;
    let p = vec![vec![0.0, 0.0], vec![1.0, 0.0], vec![1.0, 1.0], vec![0.0, 1.0]];
    let k = vec![0.0, 0.0, 0.0, 0.0, 1.0, 1.0, 1.0, 1.0];
    assert!(Nurbs::new(3, k.clone(), &p, None).is_ok());
    assert_eq!(Nurbs::new(0, k.clone(), &p, None), Err(DegreeOutOfRange { degree: 0 }));
    assert_eq!(Nurbs::new(8, k.clone(), &p, None), Err(DegreeOutOfRange { degree: 8 }));
    assert_eq!(
        Nurbs::new(3, k[1..].to_vec(), &p, None),
        Err(KnotCountMismatch { expected: 8, found: 7 })
    );
    let mut dec = vec![0.0, 0.0, 0.0, 0.0, 0.6, 0.4, 1.0, 1.0, 1.0, 1.0];
    let p6: Vec<Vec<f64>> = (0..6).map(|i| vec![i as f64, (i * i) as f64]).collect();
    assert_eq!(Nurbs::new(3, dec.clone(), &p6, None), Err(KnotsDecreasing { index: 5 }));
    dec[5] = f64::NAN;
    assert_eq!(Nurbs::new(3, dec, &p6, None), Err(NonFiniteKnot { index: 5 }));
    assert_eq!(
        Nurbs::new(3, k.clone(), &p, Some(vec![1.0, 0.0, 1.0, 1.0])),
        Err(NonPositiveWeight { index: 1, value: 0.0 })
    );
    assert_eq!(
        Nurbs::new(3, k.clone(), &p[..3], None).unwrap_err(),
        TooFewControlPoints { count: 3, needed: 4 }
    );
    let mut nan = p.clone();
    nan[2][1] = f64::INFINITY;
    assert_eq!(
        Nurbs::new(3, k.clone(), &nan, None),
        Err(NonFiniteCoordinate { point: 2, axis: 1 })
    );
    let unclamped = vec![0.0, 0.1, 0.2, 0.3, 0.7, 0.8, 0.9, 1.0];
    assert_eq!(Nurbs::new(3, unclamped, &p, None), Err(NotClamped));
}
