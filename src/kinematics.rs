//! Inverse and forward kinematics of table-tilting 5-axis machines (VPOp paper section 3.3):
//! the tool is fixed along the machine Z axis; the table tilts about X (A axis, XYZAC: Mikron
//! UCP 710 type, LinuxCNC's `xyzac-trt-kins`) or about Y (B axis, XYZBC, `xyzbc-trt-kins`) and
//! rotates about its own normal (C axis).
//!
//! Machine position of a workpiece point p: `m = R_tilt(T) R_z(C) (p - pivot) + pivot`, where
//! `pivot` is the point (workpiece frame) where the tilt and C axes meet and `R_tilt` is `R_x`
//! or `R_y` (right-handed, positive angles turn the table counter-clockwise seen from the
//! positive axis). The tool axis t (workpiece frame, pointing from the tip to the holder) must
//! map to +Z: `R_tilt(T) R_z(C) t = (0, 0, 1)`. With rho = |t_xy| that gives `T = atan2(rho,
//! t_z)` and `C = atan2(t_x, t_y)` for a tilt about X, `C = atan2(t_y, -t_x)` about Y; or the
//! second branch `-T`, `C + 180°`. Joint order x, y, z, tilt, c; rotary axes in degrees
//! (LinuxCNC's convention).

/// The axis the table tilts about.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Tilt {
    /// About X: the A axis (XYZAC).
    #[default]
    X,
    /// About Y: the B axis (XYZBC).
    Y,
}

/// Machine geometry.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct TableTilting {
    pub tilt: Tilt,
    /// Intersection of the tilt and C axes in the workpiece frame (mm).
    pub pivot: [f64; 3],
    /// Which of the two angle branches to use: `false` for a tilt angle >= 0, `true` for <= 0.
    pub negative_tilt: bool,
}

/// `R_tilt(t) R_z(c) p`.
fn rot(tilt: Tilt, t: f64, c: f64, p: [f64; 3]) -> [f64; 3] {
    let (sc, cc) = c.sin_cos();
    let (st, ct) = t.sin_cos();
    let (x1, y1, z1) = (cc * p[0] - sc * p[1], sc * p[0] + cc * p[1], p[2]);
    match tilt {
        Tilt::X => [x1, ct * y1 - st * z1, st * y1 + ct * z1],
        Tilt::Y => [ct * x1 + st * z1, y1, -st * x1 + ct * z1],
    }
}

/// `R_z(-c) R_tilt(-t) m`.
fn rot_inv(tilt: Tilt, t: f64, c: f64, m: [f64; 3]) -> [f64; 3] {
    let (sc, cc) = c.sin_cos();
    let (st, ct) = t.sin_cos();
    let (x1, y1, z1) = match tilt {
        Tilt::X => (m[0], ct * m[1] + st * m[2], -st * m[1] + ct * m[2]),
        Tilt::Y => (ct * m[0] - st * m[2], m[1], st * m[0] + ct * m[2]),
    };
    [cc * x1 + sc * y1, -sc * x1 + cc * y1, z1]
}

impl TableTilting {
    /// Names of the joints in order (the CSV columns and the limits' order).
    pub fn joint_names(&self) -> [&'static str; 5] {
        match self.tilt {
            Tilt::X => ["x", "y", "z", "a", "c"],
            Tilt::Y => ["x", "y", "z", "b", "c"],
        }
    }

    /// Rotary angles (tilt, c; radians) for tool axis `axis` (need not be unit), on the
    /// configured branch, with C taken as the value `c_ref + 2 k pi` closest to `c_ref`
    /// (continuity).
    pub fn angles(&self, axis: [f64; 3], c_ref: Option<f64>) -> (f64, f64) {
        let n = (axis[0] * axis[0] + axis[1] * axis[1] + axis[2] * axis[2]).sqrt();
        let t = [axis[0] / n, axis[1] / n, axis[2] / n];
        let rho = (t[0] * t[0] + t[1] * t[1]).sqrt();
        let mut c = match self.tilt {
            Tilt::X => t[0].atan2(t[1]),
            Tilt::Y => t[1].atan2(-t[0]),
        };
        let mut tilt = rho.atan2(t[2]);
        if self.negative_tilt {
            tilt = -tilt;
            c += std::f64::consts::PI;
        }
        if let Some(r) = c_ref {
            let tau = std::f64::consts::TAU;
            c += ((r - c) / tau).round() * tau;
        }
        (tilt, c)
    }

    /// Joint positions x, y, z (mm), tilt, c (degrees) for a tool tip and tool axis.
    pub fn inverse(&self, tip: [f64; 3], axis: [f64; 3], c_ref_deg: Option<f64>) -> [f64; 5] {
        let (t, c) = self.angles(axis, c_ref_deg.map(f64::to_radians));
        let rel = [tip[0] - self.pivot[0], tip[1] - self.pivot[1], tip[2] - self.pivot[2]];
        let m = rot(self.tilt, t, c, rel);
        [
            m[0] + self.pivot[0],
            m[1] + self.pivot[1],
            m[2] + self.pivot[2],
            t.to_degrees(),
            c.to_degrees(),
        ]
    }

    /// Tool tip and unit tool axis in the workpiece frame from joint positions.
    pub fn forward(&self, joints: &[f64]) -> ([f64; 3], [f64; 3]) {
        let (t, c) = (joints[3].to_radians(), joints[4].to_radians());
        let m = [
            joints[0] - self.pivot[0],
            joints[1] - self.pivot[1],
            joints[2] - self.pivot[2],
        ];
        let p = rot_inv(self.tilt, t, c, m);
        let tip = [p[0] + self.pivot[0], p[1] + self.pivot[1], p[2] + self.pivot[2]];
        (tip, rot_inv(self.tilt, t, c, [0.0, 0.0, 1.0]))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Forward of inverse is the identity on both machines and both branches; the tilt angle
    /// has the branch's sign; C is continuous with the reference.
    #[test]
    fn round_trip_both_machines_and_branches() {
        for tilt in [Tilt::X, Tilt::Y] {
            for negative_tilt in [false, true] {
                let k = TableTilting {
                    tilt,
                    pivot: [3.0, -2.0, 10.0],
                    negative_tilt,
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
                        assert!((t[i] - tip[i]).abs() < 1e-12, "{tilt:?} {t:?} {tip:?}");
                        assert!((a[i] - axis[i] / n).abs() < 1e-12, "{tilt:?} {a:?} {axis:?}");
                    }
                    assert!((j[4] - 400.0).abs() <= 180.0 + 1e-9);
                    assert_eq!(j[3] >= 0.0, !negative_tilt);
                }
            }
        }
    }

    /// The tilt turns the table about its own axis: a tool axis tilted towards +y needs an A
    /// turn on XYZAC with C = 0, and the same axis on XYZBC a B turn with C = ±90°.
    #[test]
    fn the_tilt_axis_is_the_named_one() {
        let axis = [0.0, 0.5f64.sqrt(), 0.5f64.sqrt()];
        let ac = TableTilting::default().inverse([0.0; 3], axis, None);
        assert!((ac[3] - 45.0).abs() < 1e-12 && ac[4].abs() < 1e-12, "{ac:?}");
        let bc = TableTilting {
            tilt: Tilt::Y,
            ..TableTilting::default()
        }
        .inverse([0.0; 3], axis, None);
        assert!(
            (bc[3] - 45.0).abs() < 1e-12 && (bc[4].abs() - 90.0).abs() < 1e-12,
            "{bc:?}"
        );
        // Along x: XYZBC needs no C turn.
        let bx = TableTilting {
            tilt: Tilt::Y,
            ..TableTilting::default()
        }
        .inverse([0.0; 3], [1.0, 0.0, 1.0], None);
        assert!((bx[3] - 45.0).abs() < 1e-12 && (bx[4].abs() % 180.0) < 1e-12, "{bx:?}");
    }
}
