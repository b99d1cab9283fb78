use super::LimitArgs;
use crate::planner::verify::{verify, Row};
use crate::planner::PathCurves;
use crate::readers::read_toolpath;
use std::path::Path;

/// Reads a setpoint CSV written by `plan` (columns t,u,x,y[,z] then optional extras; an
/// `element` column selects the path element, 0 otherwise).
pub fn read_rows(path: &Path, tip: usize) -> Result<Vec<Row>, String> {
    let text = std::fs::read_to_string(path).map_err(|e| format!("{}: {e}", path.display()))?;
    let mut lines = text.lines();
    let header: Vec<&str> = lines
        .next()
        .ok_or_else(|| format!("{}: empty file", path.display()))?
        .split(',')
        .collect();
    let col = |name: &str| header.iter().position(|h| h.trim() == name);
    let (Some(ct), Some(cu)) = (col("t"), col("u")) else {
        return Err(format!("{}: header must start with t,u,x,y", path.display()));
    };
    let axes: Vec<usize> = ["x", "y", "z"][..tip]
        .iter()
        .map(|n| col(n).ok_or_else(|| format!("{}: no column {n}", path.display())))
        .collect::<Result<_, _>>()?;
    let ce = col("element");
    let mut rows = Vec::new();
    for (i, line) in lines.enumerate() {
        if line.trim().is_empty() {
            continue;
        }
        let f: Vec<&str> = line.split(',').collect();
        let num = |c: usize| -> Result<f64, String> {
            f.get(c)
                .and_then(|v| v.trim().parse::<f64>().ok())
                .filter(|v| v.is_finite())
                .ok_or_else(|| format!("{}:{}: column {} is not a number", path.display(), i + 2, c + 1))
        };
        rows.push(Row {
            t: num(ct)?,
            u: num(cu)?,
            curve: match ce {
                Some(c) => num(c)? as usize,
                None => 0,
            },
            q: axes.iter().map(|&c| num(c)).collect::<Result<_, _>>()?,
        });
    }
    Ok(rows)
}

pub fn run(setpoints: &Path, toolpath: &Path, limits: &LimitArgs) -> Result<bool, Box<dyn std::error::Error>> {
    let toolpath = read_toolpath(toolpath)?;
    let limits = limits.limits(toolpath.tip_dim())?;
    let rows = read_rows(setpoints, toolpath.tip_dim())?;
    let curves = PathCurves::new(&toolpath);
    let report = verify(&curves, &limits, &rows);
    let tip = toolpath.tip_dim();
    println!(
        "{} setpoints ({:.6} s): max |v| {:?}, |a| {:?}, |jerk| {:?}; max feed {:.6}; chord error {:.3e} mm; off-curve {:.3e} mm",
        report.rows,
        report.rows.saturating_sub(1) as f64 * limits.period,
        &report.peaks.vel[..tip],
        &report.peaks.acc[..tip],
        &report.peaks.jerk[..tip],
        report.max_feed,
        report.max_chord_error,
        report.max_distance_to_curve,
    );
    for v in &report.violations {
        println!("VIOLATION: {v}");
    }
    if report.violations.is_empty() {
        println!("OK: no violation");
    }
    Ok(report.violations.is_empty())
}
