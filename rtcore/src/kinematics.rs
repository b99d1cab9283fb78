//! Kinematics of table-rotary-tilting 5-axis machines with LinuxCNC 2.9's geometry
//! (`xyzac-trt-kins`, `xyzbc-trt-kins`): the planner's, here in `no_std` so that the realtime
//! module can turn the same world pose into the same joints once it drives 5 joints.
//!
//! The tool stays along the machine's Z; the table tilts about X (A, XYZAC) or Y (B, XYZBC) and
//! rotates about its own normal (C). A world pose is LinuxCNC's: the controlled point in the
//! workpiece frame (mm) and the two rotary angles (degrees), which are also the rotary joints.
//! The geometry is the kinematics module's pins: the C axis passes through `rot_point`
//! (`x/y/z-rot-point`), the tilt axis through `rot_point + offset`, where `offset` is
//! (`x-offset`, `y-offset`, `z-offset` + `tool-offset`) without its component along the tilt
//! axis (which LinuxCNC ignores, as it moves nothing). With `q = R_z(C) (p - rot_point)`:
//!
//! `joints_xyz = R_tilt(T) (q - offset) + rot_point + offset`,
//!
//! `R_tilt` being `R_x` or `R_y` (right-handed: a positive angle turns the table
//! counter-clockwise seen from the positive axis). With all offsets zero both axes meet at
//! `rot_point`.
//!
//! The rotary angles of a tool axis t (workpiece frame, from the tip towards the holder) turn it
//! onto the machine's +Z: `R_tilt(T) R_z(C) t = (0, 0, 1)`. With rho = |t_xy|, `T = atan2(rho,
//! t_z)` and `C = atan2(t_x, t_y)` for a tilt about X, `C = atan2(t_y, -t_x)` about Y; or the
//! second branch `-T`, `C + 180°`. The functions are the same as LinuxCNC's `trtfuncs.c`
//! (checked against the loaded module by `tests/hal/test_machine_kins.sh`), written in this
//! vector form.

use core::f64::consts::PI;

/// The axis the table tilts about.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Tilt {
    /// About X: the A axis (XYZAC, `xyzac-trt-kins`).
    #[default]
    X,
    /// About Y: the B axis (XYZBC, `xyzbc-trt-kins`).
    Y,
}

/// The geometry of a table-rotary-tilting machine: LinuxCNC's kinematics pins.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct TrtGeometry {
    pub tilt: Tilt,
    /// A point on the C axis, where it meets the tilt axis when the offsets are zero
    /// (`x-rot-point`, `y-rot-point`, `z-rot-point`; mm, workpiece frame at zero angles).
    pub rot_point: [f64; 3],
    /// `x-offset`, `y-offset`, `z-offset` (mm): the tilt axis passes through
    /// `rot_point + offset` (XYZAC uses y and z, XYZBC x and z).
    pub offset: [f64; 3],
    /// `tool-offset` (mm), which LinuxCNC adds to `z-offset` (wired to `motion.tooloffset.z`).
    pub tool_offset: f64,
}

const TO_RAD: f64 = PI / 180.0;

/// `R_z(c) p` (radians).
fn rotate_c(c: f64, p: [f64; 3]) -> [f64; 3] {
    let (sc, cc) = (libm::sin(c), libm::cos(c));
    [cc * p[0] - sc * p[1], sc * p[0] + cc * p[1], p[2]]
}

/// `R_tilt(t) p` (radians).
fn rotate_tilt(tilt: Tilt, t: f64, p: [f64; 3]) -> [f64; 3] {
    let (st, ct) = (libm::sin(t), libm::cos(t));
    match tilt {
        Tilt::X => [p[0], ct * p[1] - st * p[2], st * p[1] + ct * p[2]],
        Tilt::Y => [ct * p[0] + st * p[2], p[1], -st * p[0] + ct * p[2]],
    }
}

impl TrtGeometry {
    /// The tilt axis's offset from `rot_point`, tool length included, without its component
    /// along the tilt axis.
    fn tilt_offset(&self) -> [f64; 3] {
        let dz = self.offset[2] + self.tool_offset;
        match self.tilt {
            Tilt::X => [0.0, self.offset[1], dz],
            Tilt::Y => [self.offset[0], 0.0, dz],
        }
    }

    /// Inverse kinematics: joints (x, y, z mm; tilt, c degrees) of world pose `world` (x, y, z
    /// mm; tilt, c degrees).
    pub fn joints(&self, world: [f64; 5]) -> [f64; 5] {
        let (r, d) = (self.rot_point, self.tilt_offset());
        let q = rotate_c(world[4] * TO_RAD, [world[0] - r[0], world[1] - r[1], world[2] - r[2]]);
        let m = rotate_tilt(self.tilt, world[3] * TO_RAD, [q[0] - d[0], q[1] - d[1], q[2] - d[2]]);
        [
            m[0] + r[0] + d[0],
            m[1] + r[1] + d[1],
            m[2] + r[2] + d[2],
            world[3],
            world[4],
        ]
    }

    /// Forward kinematics: the world pose of `joints`; the inverse of [`TrtGeometry::joints`].
    pub fn world(&self, joints: [f64; 5]) -> [f64; 5] {
        let (r, d) = (self.rot_point, self.tilt_offset());
        let m = [
            joints[0] - r[0] - d[0],
            joints[1] - r[1] - d[1],
            joints[2] - r[2] - d[2],
        ];
        let q = rotate_tilt(self.tilt, -joints[3] * TO_RAD, m);
        let p = rotate_c(-joints[4] * TO_RAD, [q[0] + d[0], q[1] + d[1], q[2] + d[2]]);
        [p[0] + r[0], p[1] + r[1], p[2] + r[2], joints[3], joints[4]]
    }

    /// Rotary angles (tilt, c; degrees) that put tool axis `axis` (need not be unit) along the
    /// machine's Z: on the branch with tilt <= 0 if `negative_tilt`, else >= 0; C is the value
    /// `c + 360° k` nearest `c_ref` (continuity with the pose before), if given.
    pub fn angles(&self, axis: [f64; 3], negative_tilt: bool, c_ref: Option<f64>) -> (f64, f64) {
        let n = libm::sqrt(axis[0] * axis[0] + axis[1] * axis[1] + axis[2] * axis[2]);
        let t = [axis[0] / n, axis[1] / n, axis[2] / n];
        let rho = libm::sqrt(t[0] * t[0] + t[1] * t[1]);
        let mut c = match self.tilt {
            Tilt::X => libm::atan2(t[0], t[1]),
            Tilt::Y => libm::atan2(t[1], -t[0]),
        } / TO_RAD;
        let mut tilt = libm::atan2(rho, t[2]) / TO_RAD;
        if negative_tilt {
            tilt = -tilt;
            c += 180.0;
        }
        if let Some(r) = c_ref {
            c += libm::round((r - c) / 360.0) * 360.0;
        }
        (tilt, c)
    }

    /// The tool axis (unit, from the tip towards the holder) in the workpiece frame at rotary
    /// joints `tilt_deg`, `c_deg`: the machine's +Z turned back by the table.
    pub fn tool_axis(&self, tilt_deg: f64, c_deg: f64) -> [f64; 3] {
        rotate_c(
            -c_deg * TO_RAD,
            rotate_tilt(self.tilt, -tilt_deg * TO_RAD, [0.0, 0.0, 1.0]),
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn machines() -> impl Iterator<Item = TrtGeometry> {
        [Tilt::X, Tilt::Y].into_iter().flat_map(|tilt| {
            [
                TrtGeometry {
                    tilt,
                    ..TrtGeometry::default()
                },
                TrtGeometry {
                    tilt,
                    rot_point: [12.5, -30.0, 7.25],
                    offset: [4.0, 20.0, -10.0],
                    tool_offset: 55.5,
                },
            ]
        })
    }

    /// Forward of inverse is the identity, with and without offsets, on both machines.
    #[test]
    fn world_of_joints_of_world_is_the_identity() {
        for k in machines() {
            for w in [
                [1.0, 2.0, 3.0, 30.0, 45.0],
                [-50.0, 70.0, 0.5, -89.0, 400.0],
                [0.0, 0.0, 0.0, 0.0, 0.0],
            ] {
                let back = k.world(k.joints(w));
                for i in 0..5 {
                    assert!((back[i] - w[i]).abs() < 1e-12, "{k:?} {w:?} {back:?}");
                }
            }
        }
    }

    /// At zero angles the joints are the world position; the C axis turns about `rot_point`
    /// (a point on it stays where it is at any C, offsets or not).
    #[test]
    fn the_rotation_point_is_on_the_c_axis() {
        for k in machines() {
            let p = k.rot_point;
            let at_zero = k.joints([p[0] + 3.0, p[1] - 4.0, p[2] + 5.0, 0.0, 0.0]);
            assert!((at_zero[0] - p[0] - 3.0).abs() < 1e-12 && (at_zero[2] - p[2] - 5.0).abs() < 1e-12);
            let on_c = k.joints([p[0], p[1], p[2] + 9.0, 0.0, 123.0]);
            assert!(
                (on_c[0] - p[0]).abs() < 1e-12 && (on_c[1] - p[1]).abs() < 1e-12,
                "{k:?} {on_c:?}"
            );
        }
    }

    /// The tilt axis passes through `rot_point + offset` (tool length included): a point on it
    /// stays where it is at any tilt; a point off it moves.
    #[test]
    fn the_tilt_axis_passes_through_the_offset_point() {
        for k in machines() {
            let d = k.tilt_offset();
            let on_axis = [k.rot_point[0] + d[0], k.rot_point[1] + d[1], k.rot_point[2] + d[2]];
            let j = k.joints([on_axis[0], on_axis[1], on_axis[2], 35.0, 0.0]);
            for i in 0..3 {
                assert!((j[i] - on_axis[i]).abs() < 1e-12, "{k:?} {j:?} {on_axis:?}");
            }
            let off = k.joints([on_axis[0], on_axis[1], on_axis[2] + 10.0, 35.0, 0.0]);
            assert!((off[2] - on_axis[2] - 10.0).abs() > 1.0, "{k:?} {off:?}");
        }
    }

    /// The tool axis at the joints' angles maps to the machine's +Z.
    #[test]
    fn the_tool_axis_is_the_machine_z() {
        for k in machines() {
            let (t, c) = (27.0, -140.0);
            let axis = k.tool_axis(t, c);
            let m = rotate_tilt(k.tilt, t * TO_RAD, rotate_c(c * TO_RAD, axis));
            assert!(
                m[0].abs() < 1e-15 && m[1].abs() < 1e-15 && (m[2] - 1.0).abs() < 1e-15,
                "{m:?}"
            );
        }
    }
}
