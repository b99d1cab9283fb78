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
