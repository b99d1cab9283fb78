//! Where a program's coordinates sit on the machine: LinuxCNC's work offsets, as its canonical
//! layer applies them to every programmed point (`rotate_and_offset_pos` in `emccanon.cc`):
//! the G92 offset added, the XY rotation of the coordinate system (`G10 L2 R`) about the
//! machine's Z, then the G54-G59.3 offset and the tool length offset added. A NURBS curve is
//! affine-invariant in its control points, so placing the control points places the curve
//! exactly (arcs stay arcs, weights are unchanged).

use super::{Nurbs, PathElement};

/// Program coordinates to machine coordinates: `machine = Rz(rotation) * (p + before) + after`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Placement {
    /// Added before the rotation (LinuxCNC's G92 offset), mm.
    pub before: [f64; 3],
    /// Rotation about Z, degrees counter-clockwise (the coordinate system's `R`).
    pub rotation_deg: f64,
    /// Added after the rotation (the G54-G59.3 offset plus the tool length offset), mm.
    pub after: [f64; 3],
}

impl Placement {
    /// Program coordinates are machine coordinates.
    pub const IDENTITY: Placement = Placement {
        before: [0.0; 3],
        rotation_deg: 0.0,
        after: [0.0; 3],
    };

    pub fn is_identity(&self) -> bool {
        *self == Self::IDENTITY
    }

    /// A point of 2 (X Y) or 3 (X Y Z) coordinates, in place; the formula and the order of its
    /// floating-point operations are LinuxCNC's (`rotate` in `emccanon.cc`).
    pub fn apply(&self, p: &mut [f64]) {
        for (x, b) in p.iter_mut().zip(self.before) {
            *x += b;
        }
        if self.rotation_deg != 0.0 {
            let t = self.rotation_deg * std::f64::consts::PI / 180.0;
            let (x, y) = (p[0], p[1]);
            p[0] = x * t.cos() - y * t.sin();
            p[1] = x * t.sin() + y * t.cos();
        }
        for (x, a) in p.iter_mut().zip(self.after) {
            *x += a;
        }
    }

    /// `curve` placed: every control point of the tool tip (and of the top curve of a 5-axis
    /// path) moved by [`Placement::apply`].
    pub fn curve(&self, curve: &Nurbs) -> Nurbs {
        let tip = curve.tip_dim();
        let mut points = curve.points().to_vec();
        for point in points.chunks_mut(curve.dim()) {
            for part in point.chunks_mut(tip) {
                self.apply(part);
            }
        }
        Nurbs::from_flat(
            curve.degree(),
            curve.dim(),
            tip,
            curve.knots().to_vec(),
            points,
            curve.weights().to_vec(),
        )
        .expect("moved control points of a valid curve stay valid")
    }

    /// `element` placed ([`Placement::curve`]); kind, feed and source line unchanged.
    pub fn element(&self, element: PathElement) -> PathElement {
        PathElement {
            curve: self.curve(&element.curve),
            ..element
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::ElementKind;

    #[test]
    fn offsets_and_rotation_apply_in_linuxcncs_order() {
        // G92 offset (1, 0, 0), R 90 degrees, G54 (10, 20, 30): program (1, 0, 5) is
        // (2, 0, 5) before the rotation, (0, 2, 5) after it, (10, 22, 35) on the machine.
        let placement = Placement {
            before: [1.0, 0.0, 0.0],
            rotation_deg: 90.0,
            after: [10.0, 20.0, 30.0],
        };
        let mut p = [1.0, 0.0, 5.0];
        placement.apply(&mut p);
        assert!(
            (p[0] - 10.0).abs() < 1e-12 && (p[1] - 22.0).abs() < 1e-12 && p[2] == 35.0,
            "{p:?}"
        );
        // A 2-D point takes X and Y only.
        let mut q = [1.0, 0.0];
        placement.apply(&mut q);
        assert!((q[0] - 10.0).abs() < 1e-12 && (q[1] - 22.0).abs() < 1e-12, "{q:?}");
    }

    #[test]
    fn a_placed_arc_is_the_placed_circle() {
        // A quarter circle of radius 2 about the origin (rational quadratic), rotated 30 degrees
        // and moved: every point stays at distance 2 from the moved centre.
        let w = std::f64::consts::FRAC_1_SQRT_2;
        let arc = Nurbs::new(
            2,
            vec![0.0, 0.0, 0.0, 1.0, 1.0, 1.0],
            &[vec![2.0, 0.0, 1.0], vec![2.0, 2.0, 1.0], vec![0.0, 2.0, 1.0]],
            Some(vec![1.0, w, 1.0]),
        )
        .unwrap();
        let placement = Placement {
            before: [0.0; 3],
            rotation_deg: 30.0,
            after: [5.0, -3.0, 0.5],
        };
        let element = placement.element(PathElement {
            kind: ElementKind::Arc,
            curve: arc,
            feed: Some(10.0),
            source_line: Some(7),
        });
        assert_eq!(
            (element.kind, element.feed, element.source_line),
            (ElementKind::Arc, Some(10.0), Some(7))
        );
        for k in 0..=20 {
            let p = element.curve.point(k as f64 / 20.0);
            let r = ((p[0] - 5.0).powi(2) + (p[1] + 3.0).powi(2)).sqrt();
            assert!((r - 2.0).abs() < 1e-12 && (p[2] - 1.5).abs() < 1e-12, "{p:?}");
        }
        let start = element.curve.point(0.0);
        let t = 30f64.to_radians();
        assert!((start[0] - (5.0 + 2.0 * t.cos())).abs() < 1e-12 && (start[1] - (-3.0 + 2.0 * t.sin())).abs() < 1e-12);
    }
}
