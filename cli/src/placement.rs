//! Where the program sits on the machine (`--work-offset`, `--g92-offset`, `--rotation-xy`):
//! the offsets LinuxCNC applies to a program's coordinates, for toolpaths written in program
//! coordinates (the runs `nurbs-filter` cuts from a CAM program; `M101` passes the offsets
//! active when the run starts). Without them a toolpath is in machine coordinates.

use nurbs_motion::geometry::Placement;

#[derive(clap::Args, Clone, Debug, Default)]
pub struct PlacementArgs {
    /// The toolpath is in program coordinates: add this offset (mm; X,Y,Z) after the rotation:
    /// the active G54-G59.3 offset plus the tool length offset, as LinuxCNC adds them.
    #[arg(long, value_delimiter = ',', value_name = "X,Y,Z")]
    pub work_offset: Option<Vec<f64>>,
    /// LinuxCNC's G92 offset (mm; X,Y,Z), added to program coordinates before the rotation.
    #[arg(long, value_delimiter = ',', value_name = "X,Y,Z")]
    pub g92_offset: Option<Vec<f64>>,
    /// Rotation of the coordinate system about Z (degrees, counter-clockwise; `G10 L2 R`).
    #[arg(long, value_name = "DEG")]
    pub rotation_xy: Option<f64>,
}

impl PlacementArgs {
    /// The placement the flags give (identity without them), checked.
    pub fn placement(&self) -> Result<Placement, String> {
        let xyz = |flag: &str, v: &Option<Vec<f64>>| -> Result<[f64; 3], String> {
            match v.as_deref() {
                None => Ok([0.0; 3]),
                Some(&[x, y, z]) if [x, y, z].iter().all(|c| c.is_finite()) => Ok([x, y, z]),
                Some(other) => Err(format!("--{flag} {other:?}: three finite numbers X,Y,Z (mm)")),
            }
        };
        let rotation_deg = self.rotation_xy.unwrap_or(0.0);
        if !rotation_deg.is_finite() {
            return Err(format!("--rotation-xy {rotation_deg}: a finite angle in degrees"));
        }
        Ok(Placement {
            before: xyz("g92-offset", &self.g92_offset)?,
            rotation_deg,
            after: xyz("work-offset", &self.work_offset)?,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn flags_make_the_placement_and_bad_ones_are_refused() {
        assert!(PlacementArgs::default().placement().unwrap().is_identity());
        let args = PlacementArgs {
            work_offset: Some(vec![1.0, 2.0, 3.0]),
            g92_offset: None,
            rotation_xy: Some(15.0),
        };
        let p = args.placement().unwrap();
        assert_eq!((p.after, p.before, p.rotation_deg), ([1.0, 2.0, 3.0], [0.0; 3], 15.0));
        let two = PlacementArgs {
            work_offset: Some(vec![1.0, 2.0]),
            ..Default::default()
        };
        assert!(two.placement().unwrap_err().contains("--work-offset"));
        let nan = PlacementArgs {
            rotation_xy: Some(f64::NAN),
            ..Default::default()
        };
        assert!(nan.placement().is_err());
    }
}
