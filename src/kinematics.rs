//! Inverse and forward kinematics of an XYZAC table-tilting 5-axis machine (Mikron UCP 710
//! type, VPOp paper section 3.3): the tool is fixed along the machine Z axis; the table tilts
//! about X (A axis) and rotates about its own normal (C axis).
//!
//! Machine position of a workpiece point p: `m = R_x(A) R_z(C) (p - pivot) + pivot`, where
//! `pivot` is the point (workpiece frame) where the A and C axes meet. The tool axis t
//! (workpiece frame, pointing from the tip to the holder) must map to +Z:
//! `R_x(A) R_z(C) t = (0, 0, 1)`, which gives `C = atan2(t_x, t_y)`, `A = atan2(rho, t_z)`
//! (rho = |t_xy|), or the second branch `C + 180°`, `-A`. Joint order x, y, z, a, c; rotary
//! axes in degrees (LinuxCNC's convention).

/// Machine geometry.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Xyzac {
    /// Intersection of the A and C axes in the workpiece frame (mm).
    pub pivot: [f64; 3],
    /// Which of the two angle branches to use: `false` for A >= 0, `true` for A <= 0.
    pub negative_a: bool,
}

impl Default for Xyzac {
    fn default() -> Self {
        Xyzac {
            pivot: [0.0; 3],
            negative_a: false,
        }
    }
}

fn rot(a: f64, c: f64, p: [f64; 3]) -> [f64; 3] {
    let (sc, cc) = c.sin_cos();
    let (sa, ca) = a.sin_cos();
    // R_z(C)
    let x1 = cc * p[0] - sc * p[1];
    let y1 = sc * p[0] + cc * p[1];
    let z1 = p[2];
    // R_x(A)
    [x1, ca * y1 - sa * z1, sa * y1 + ca * z1]
}

fn rot_inv(a: f64, c: f64, m: [f64; 3]) -> [f64; 3] {
    let (sc, cc) = c.sin_cos();
    let (sa, ca) = a.sin_cos();
    // R_x(-A)
    let y1 = ca * m[1] + sa * m[2];
    let z1 = -sa * m[1] + ca * m[2];
    // R_z(-C)
    [cc * m[0] + sc * y1, -sc * m[0] + cc * y1, z1]
}

impl Xyzac {
    /// Rotary angles (radians) for tool axis `axis` (need not be unit), on the configured
    /// branch, with C taken as the value `c_ref + 2 k pi` closest to `c_ref` (continuity).
    pub fn angles(&self, axis: [f64; 3], c_ref: Option<f64>) -> (f64, f64) {
        let n = (axis[0] * axis[0] + axis[1] * axis[1] + axis[2] * axis[2]).sqrt();
        let t = [axis[0] / n, axis[1] / n, axis[2] / n];
        let rho = (t[0] * t[0] + t[1] * t[1]).sqrt();
        let mut c = t[0].atan2(t[1]);
        let mut a = rho.atan2(t[2]);
        if self.negative_a {
            a = -a;
            c += std::f64::consts::PI;
        }
        if let Some(r) = c_ref {
            let tau = std::f64::consts::TAU;
            c += ((r - c) / tau).round() * tau;
        }
        (a, c)
    }

    /// Joint positions x, y, z (mm), a, c (degrees) for a tool tip and tool axis.
    pub fn inverse(&self, tip: [f64; 3], axis: [f64; 3], c_ref_deg: Option<f64>) -> [f64; 5] {
        let (a, c) = self.angles(axis, c_ref_deg.map(f64::to_radians));
        let rel = [tip[0] - self.pivot[0], tip[1] - self.pivot[1], tip[2] - self.pivot[2]];
        let m = rot(a, c, rel);
        [
            m[0] + self.pivot[0],
            m[1] + self.pivot[1],
            m[2] + self.pivot[2],
            a.to_degrees(),
            c.to_degrees(),
        ]
    }

    /// Tool tip and unit tool axis in the workpiece frame from joint positions.
    pub fn forward(&self, joints: &[f64]) -> ([f64; 3], [f64; 3]) {
        let (a, c) = (joints[3].to_radians(), joints[4].to_radians());
        let m = [
            joints[0] - self.pivot[0],
            joints[1] - self.pivot[1],
            joints[2] - self.pivot[2],
        ];
        let p = rot_inv(a, c, m);
        let tip = [p[0] + self.pivot[0], p[1] + self.pivot[1], p[2] + self.pivot[2]];
        (tip, rot_inv(a, c, [0.0, 0.0, 1.0]))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_trip_both_branches() {
        for negative_a in [false, true] {
            let k = Xyzac {
                pivot: [3.0, -2.0, 10.0],
                negative_a,
            };
            for (tip, axis) in [
                ([1.0, 2.0, 3.0], [0.3, -0.2, 1.0]),
                ([-5.0, 7.0, 0.5], [-0.9, 0.1, 0.4]),
                ([0.0, 0.0, 0.0], [0.01, 0.02, 1.0]),
            ] {
                let j = k.inverse(tip, axis, Some(400.0));
                let (t, a) = k.forward(&j);
                let n = (axis[0] * axis[0] + axis[1] * axis[1] + axis[2] * axis[2]).sqrt();
                for i in 0..3 {
                    assert!((t[i] - tip[i]).abs() < 1e-12, "{t:?} {tip:?}");
                    assert!((a[i] - axis[i] / n).abs() < 1e-12, "{a:?} {axis:?}");
                }
                assert!((j[4] - 400.0).abs() <= 180.0 + 1e-9);
                assert_eq!(j[3] >= 0.0, !negative_a);
            }
        }
    }
}
