//! Toolpaths the tests and benchmarks generate (compiled into the tests, and into the
//! benchmarks by `#[path]`).

use nurbs_motion::geometry::{ElementKind, Nurbs, Toolpath};

/// A G1 program of `lines` 2 mm lines zigzagging along x (y = 5 sin(0.7 k)), its corners
/// rounded within 0.001 mm as `nurbs-planner` rounds them: 2 `lines` - 1 elements.
pub fn g1_zigzag(lines: usize) -> Toolpath {
    let vertices: Vec<Vec<f64>> = (0..=lines)
        .map(|k| vec![2.0 * k as f64, 5.0 * (0.7 * k as f64).sin()])
        .collect();
    let mut knots = vec![0.0, 0.0];
    knots.extend((1..lines).map(|k| k as f64));
    knots.extend([lines as f64; 2]);
    let polyline = Toolpath::single(ElementKind::Polyline, Nurbs::new(1, knots, &vertices, None).unwrap());
    nurbs_motion::planner::corner::round_toolpath(&polyline, 0.001)
        .unwrap()
        .toolpath
}

/// A straight line of `length` mm along X (one element; one segment of the Erwinski plan).
pub fn line(length: f64) -> Toolpath {
    let curve = Nurbs::new(1, vec![0.0, 0.0, 1.0, 1.0], &[vec![0.0, 0.0], vec![length, 0.0]], None).unwrap();
    Toolpath::single(ElementKind::Polyline, curve)
}

/// One cubic B-spline of `points` control points 0.1 mm apart along x, waving in y
/// (0.5 sin(0.05 k)): a single curve of some 4 `points` values.
pub fn long_spline(points: usize) -> Toolpath {
    let control: Vec<Vec<f64>> = (0..points)
        .map(|k| vec![0.1 * k as f64, 0.5 * (0.05 * k as f64).sin()])
        .collect();
    let mut knots = vec![0.0; 4];
    knots.extend((1..points - 3).map(|k| k as f64));
    knots.extend([(points - 3) as f64; 4]);
    Toolpath::single(ElementKind::Nurbs, Nurbs::new(3, knots, &control, None).unwrap())
}

/// A G1 polyline of five segments (up to 90 mm) with its corners rounded within 0.001 mm:
/// lines and corner splines, 9 elements.
pub fn rounded_polyline() -> Toolpath {
    let vertices = [[0.0, 0.0], [8.0, 0.0], [8.0, 6.0], [2.0, 9.0], [2.0, 3.0], [5.0, 3.0]];
    let points: Vec<Vec<f64>> = vertices.iter().map(|v| vec![10.0 * v[0], 10.0 * v[1]]).collect();
    let mut knots = vec![0.0, 0.0];
    knots.extend((1..vertices.len() - 1).map(|k| k as f64));
    knots.extend([(vertices.len() - 1) as f64; 2]);
    let polyline = Toolpath::single(ElementKind::Polyline, Nurbs::new(1, knots, &points, None).unwrap());
    nurbs_motion::planner::corner::round_toolpath(&polyline, 0.001)
        .unwrap()
        .toolpath
}

/// A dense G1 program as CAM writes one: `lines` lines of 0.02 mm along a circle of 5 mm
/// radius (a turn of 0.004 rad at each vertex), its corners rounded within 0.001 mm. No single
/// segment of its plan is long enough to stop in: the planner's stops are chains.
pub fn dense_arc(lines: usize) -> Toolpath {
    let (r, step) = (5.0, 0.02);
    let vertices: Vec<Vec<f64>> = (0..=lines)
        .map(|k| {
            let a = k as f64 * step / r;
            vec![r * a.sin(), r * (1.0 - a.cos())]
        })
        .collect();
    let mut knots = vec![0.0, 0.0];
    knots.extend((1..lines).map(|k| k as f64));
    knots.extend([lines as f64; 2]);
    let polyline = Toolpath::single(ElementKind::Polyline, Nurbs::new(1, knots, &vertices, None).unwrap());
    nurbs_motion::planner::corner::round_toolpath(&polyline, 0.001)
        .unwrap()
        .toolpath
}
