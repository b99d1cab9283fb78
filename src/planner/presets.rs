//! The named limit sets of the papers and the benchmarks, in one place: the command line takes
//! them by name (`--limits NAME`), the tests, benches and scripts use them, and the table in
//! `docs/planners.md` is rendered from them (`make man`, checked by the tests).

use super::Limits;

/// A named set of limits (mm, s). One value of a per-axis list applies to every axis; no
/// velocity list means the feed on every axis.
#[derive(Clone, Copy, Debug)]
pub struct Preset {
    pub name: &'static str,
    /// Where it comes from.
    pub source: &'static str,
    pub feed: f64,
    pub velocity: &'static [f64],
    pub acceleration: &'static [f64],
    pub jerk: &'static [f64],
    pub chord_tolerance: f64,
    pub period: f64,
}

impl Preset {
    /// The limits, not yet spread over a path's axes ([`Limits::for_axes`]).
    pub fn limits(&self) -> Limits {
        Limits {
            feed: self.feed,
            velocity: if self.velocity.is_empty() {
                vec![self.feed]
            } else {
                self.velocity.to_vec()
            },
            acceleration: self.acceleration.to_vec(),
            jerk: self.jerk.to_vec(),
            chord_tolerance: self.chord_tolerance,
            period: self.period,
            hold_reserve: 0.0,
        }
    }

    /// The limits on `axes` axes. Panics if the preset does not fit them (a test's mistake).
    pub fn on(&self, axes: usize) -> Limits {
        self.limits()
            .for_axes(axes)
            .unwrap_or_else(|e| panic!("preset {} on {axes} axes: {e}", self.name))
    }
}

/// Every preset.
pub const PRESETS: &[Preset] = &[
    Preset {
        name: "lab1",
        source: "Erwinski et al. 2022, lab set 1 (their laboratory machine)",
        feed: 2500.0,
        velocity: &[],
        acceleration: &[1e4],
        jerk: &[6e4],
        chord_tolerance: 0.001,
        period: 0.00025,
    },
    Preset {
        name: "lab2",
        source: "Erwinski et al. 2022, lab set 2",
        feed: 2500.0,
        velocity: &[],
        acceleration: &[1.5e4],
        jerk: &[2e5],
        chord_tolerance: 0.001,
        period: 0.00025,
    },
    Preset {
        name: "table3-f40",
        source: "Erwinski et al. 2022, Table III",
        feed: 40.0,
        velocity: &[],
        acceleration: &[500.0],
        jerk: &[2e4],
        chord_tolerance: 0.001,
        period: 0.00025,
    },
    Preset {
        name: "table3-f250",
        source: "Erwinski et al. 2022, Table III",
        feed: 250.0,
        velocity: &[],
        acceleration: &[2000.0],
        jerk: &[2e4],
        chord_tolerance: 0.001,
        period: 0.00025,
    },
    Preset {
        name: "table3-f300",
        source: "Erwinski et al. 2022, Table III",
        feed: 300.0,
        velocity: &[],
        acceleration: &[2500.0],
        jerk: &[5e4],
        chord_tolerance: 0.001,
        period: 0.00025,
    },
    Preset {
        name: "vpop-trident",
        source: "Beudaert et al. 2012 (VPOp), the trident's limits (X, Y)",
        feed: 166.667,
        velocity: &[500.0, 500.0],
        acceleration: &[2500.0, 3000.0],
        jerk: &[5000.0, 5000.0],
        chord_tolerance: 0.02,
        period: 0.006,
    },
    Preset {
        name: "vpop-tip",
        source: "Beudaert et al. 2012 (VPOp), Table 1's X, Y, Z on a tool-tip path at the trident's feed",
        feed: 166.667,
        velocity: &[500.0],
        acceleration: &[2500.0, 3000.0, 2100.0],
        jerk: &[5000.0, 5000.0, 50000.0],
        chord_tolerance: 0.02,
        period: 0.006,
    },
    Preset {
        name: "vpop-table1",
        source: "Beudaert et al. 2012 (VPOp), Table 1: joints x, y, z (mm), a, c (degrees) of the XYZAC machine",
        feed: 83.333,
        velocity: &[500.0, 500.0, 500.0, 90.0, 120.0],
        acceleration: &[2500.0, 3000.0, 2100.0, 298.8, 298.8],
        jerk: &[5000.0, 5000.0, 50000.0, 1800.0, 36000.0],
        chord_tolerance: 0.02,
        period: 0.006,
    },
    Preset {
        name: "vpop-table1-tip",
        source: "Beudaert et al. 2012 (VPOp), Table 1's X, Y, Z on a tool-tip path",
        feed: 83.333,
        velocity: &[500.0],
        acceleration: &[2500.0, 3000.0, 2100.0],
        jerk: &[5000.0, 5000.0, 50000.0],
        chord_tolerance: 0.02,
        period: 0.006,
    },
];

/// The preset called `name`.
pub fn preset(name: &str) -> Option<&'static Preset> {
    PRESETS.iter().find(|p| p.name == name)
}

/// The preset called `name`; panics if there is none (for tests and benches).
pub fn named(name: &str) -> &'static Preset {
    preset(name).unwrap_or_else(|| panic!("no limit preset {name}"))
}

/// The presets as a markdown table (`nurbs-plan presets`, and `docs/planners.md`).
pub fn markdown_table() -> String {
    let list = |v: &[f64]| v.iter().map(|x| format!("{x}")).collect::<Vec<_>>().join(", ");
    let mut out = String::from(
        "| name | F (mm/s) | axis velocity (mm/s) | A (mm/s²) | J (mm/s³) | ε (mm) | T (ms) | source |\n\
         |---|---|---|---|---|---|---|---|\n",
    );
    for p in PRESETS {
        out += &format!(
            "| `{}` | {} | {} | {} | {} | {} | {} | {} |\n",
            p.name,
            p.feed,
            if p.velocity.is_empty() {
                "F".to_owned()
            } else {
                list(p.velocity)
            },
            list(p.acceleration),
            list(p.jerk),
            p.chord_tolerance,
            p.period * 1e3,
            p.source
        );
    }
    out
}
