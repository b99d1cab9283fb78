//! 5-axis tool paths on table-tilting machines (VPOp paper section 3.3): the joints of a tool
//! tip and tool axis on the geometry of LinuxCNC's `xyzac-trt-kins` / `xyzbc-trt-kins`, on one
//! of the two inverse-kinematics branches. The functions are `nurbs_rtcore::kinematics` (`no_std`,
//! for the realtime module to share). Joint order x, y, z, tilt, c; rotary axes in degrees (LinuxCNC's
//! convention).

pub use nurbs_rtcore::kinematics::{Tilt, TrtGeometry};

/// A table-tilting machine and the inverse-kinematics branch a tool path is planned on.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct TableTilting {
    pub geometry: TrtGeometry,
    /// Which of the two angle branches to use: `false` for a tilt angle >= 0, `true` for <= 0.
    pub negative_tilt: bool,
}

impl TableTilting {
    /// Names of the joints in order (the CSV columns and the limits' order).
    pub fn joint_names(&self) -> [&'static str; 5] {
        match self.geometry.tilt {
            Tilt::X => ["x", "y", "z", "a", "c"],
            Tilt::Y => ["x", "y", "z", "b", "c"],
        }
    }

    /// Rotary angles (tilt, c; degrees) for tool axis `axis` (need not be unit), on the
    /// configured branch, with C taken as the value `c + 360° k` closest to `c_ref` (continuity).
    pub fn angles(&self, axis: [f64; 3], c_ref: Option<f64>) -> (f64, f64) {
        self.geometry.angles(axis, self.negative_tilt, c_ref)
    }

    /// Joint positions x, y, z (mm), tilt, c (degrees) for a tool tip and tool axis.
    pub fn inverse(&self, tip: [f64; 3], axis: [f64; 3], c_ref: Option<f64>) -> [f64; 5] {
        let (t, c) = self.angles(axis, c_ref);
        self.geometry.joints([tip[0], tip[1], tip[2], t, c])
    }

    /// Tool tip and unit tool axis in the workpiece frame from joint positions.
    pub fn forward(&self, joints: &[f64]) -> ([f64; 3], [f64; 3]) {
        let w = self
            .geometry
            .world([joints[0], joints[1], joints[2], joints[3], joints[4]]);
        ([w[0], w[1], w[2]], self.geometry.tool_axis(joints[3], joints[4]))
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
                    geometry: TrtGeometry {
                        tilt,
                        rot_point: [3.0, -2.0, 10.0],
                        offset: [1.0, 20.0, -10.0],
                        tool_offset: 42.0,
                    },
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
            geometry: TrtGeometry {
                tilt: Tilt::Y,
                ..TrtGeometry::default()
            },
            ..TableTilting::default()
        }
        .inverse([0.0; 3], axis, None);
        assert!(
            (bc[3] - 45.0).abs() < 1e-12 && (bc[4].abs() - 90.0).abs() < 1e-12,
            "{bc:?}"
        );
        // Along x: XYZBC needs no C turn.
        let bx = TableTilting {
            geometry: TrtGeometry {
                tilt: Tilt::Y,
                ..TrtGeometry::default()
            },
            ..TableTilting::default()
        }
        .inverse([0.0; 3], [1.0, 0.0, 1.0], None);
        assert!((bx[3] - 45.0).abs() < 1e-12 && (bx[4].abs() % 180.0) < 1e-12, "{bx:?}");
    }
}
