//! LinuxCNC G-code (RS274/NGC as interpreted by LinuxCNC 2.9) to a [`Toolpath`].
//!
//! The reader follows LinuxCNC's interpreter source (`src/emc/rs274ngc/` in LinuxCNC/linuxcnc)
//! where it and the documentation disagree. What it reads:
//!
//! * **Lines and words.** Letters are case-insensitive; spaces and tabs outside comments are
//!   ignored (`close_and_downcase` in `interp_read.cc`); `( … )` comments (a `(` inside a comment
//!   is an error, as is an unclosed one) and `;` comments to the end of the line; an `N` number is
//!   only allowed first on a line; a program may be wrapped in `%` lines (then the second `%` ends
//!   it, and a missing one is an error, like LinuxCNC's "File ended with no percent sign"). `M2`
//!   and `M30` end the program; the rest of the file is ignored. Words execute in LinuxCNC's
//!   order of execution: `F` before `G20`/`G21`, those before `G90`/`G91`, motion last.
//! * **Units.** The program starts in `G21` (mm) and `G90`, `G91.1`, `G17`, `G94` (LinuxCNC's
//!   defaults with `LINEAR_UNITS = mm`). `G20` reads lengths in inches (×25.4). `F` is in
//!   program units per minute and is stored in mm/s; as in `convert_length_units`, a feed keeps its
//!   physical value when the units change afterwards.
//! * **Start point.** The tool's position before the first move is unknown (LinuxCNC uses the
//!   machine's actual position). An axis becomes known when a move programs it in `G90`; a move
//!   that needs an unknown coordinate (an incremental move of an unknown axis, or a feed move
//!   starting from an unknown point) is an error that asks for a `G0` positioning move first.
//! * **`G0` rapids** are not part of the planned motion: rapids before the first feed move only
//!   position the tool, rapids after the last feed move (retracts) are dropped, and a rapid that
//!   moves the tool *between* two feed moves is an error, because a [`Toolpath`] is one continuous
//!   feed motion.
//! * **`G1`**: consecutive `G1` moves at the same feed become one [`ElementKind::Polyline`]
//!   element (of at most 1,024 points), parameterised by cumulative chord length (mm).
//!   Zero-length moves are skipped.
//! * **`G2`/`G3`** in the XY plane with `I J` (incremental, or absolute after `G90.1`) or `R`
//!   (negative `R` for more than a half turn) and optional `P` turns become one exact
//!   [`ElementKind::Arc`] element: a rational quadratic NURBS split into equal pieces of at most
//!   90°, middle weights `cos(Δ/2)`, double interior knots, knot values the arc length (mm) at
//!   the piece ends. LinuxCNC's checks (`interp_arc.cc`) are reproduced: zero radius, radius to
//!   end differing from radius to start by more than `CENTER_ARC_RADIUS_TOLERANCE` (0.0283 mm /
//!   0.00283 in) or 0.1 %, `R` too small to reach the end point, start = end with `R`. LinuxCNC
//!   runs an arc whose two radii differ (within tolerance) as a spiral; a spiral is not a rational
//!   curve, so the reader moves the centre onto the perpendicular bisector of the chord (the
//!   exact circle through both programmed end points nearest the programmed centre) and rejects
//!   the arc if that moves the centre by more than the same tolerance. A full circle (start =
//!   end with `I J`) is 360°; `P n` adds n − 1 full turns. A `Z` word that changes Z on an arc
//!   (a helix) is an error: a helix has no exact rational representation.
//! * **`G5.2`/`G5.3` NURBS blocks** as `Interp::convert_nurbs` (`interp_convert.cc`): the current
//!   position is the first control point, with weight 1, or `P` if the opening `G5.2` line has
//!   `P` but no `X Y`; every control-point line needs both `X` and `Y` and a positive `P`; `L`
//!   (the order, degree + 1, default 3) takes effect on any line of the block when `L > 3`, as
//!   in LinuxCNC (a smaller `L` is ignored); `G5.3` needs at least `L` control points. The knot
//!   vector is LinuxCNC's `knot_vector_creator(n, k)` (`nurbs_additional_functions.cc`):
//!   `k` zeros, then `1, 2, …, n − k + 1`, then `k` times `n − k + 2` — clamped, uniform, integer.
//!   In `G91` every control point is relative to the block's start point, because LinuxCNC's
//!   `find_ends` adds the current position, which `convert_nurbs` only updates at `G5.3`. The
//!   feed is the one in effect at `G5.3`. Stricter than LinuxCNC (which would silently produce a
//!   different or degenerate path): a missing or non-positive `P` on the opening `G5.2` line
//!   with `X Y` (LinuxCNC stores weight −1 or 0), `Z` or other axis words inside a block
//!   (LinuxCNC ignores them), axis words on the `G5.3` line (ignored by LinuxCNC), any other G- or
//!   M-code inside a block (LinuxCNC would discard the open block), and end of file inside a
//!   block are errors.
//! * **Dimension**, decided where the feed motion begins (so that a program streams: elements
//!   go out before the rest of the file is read). The toolpath is 3-D (X Y Z) if the Z position
//!   is known at the start of the first feed move that moves (positioned by `G0` or `G1`
//!   before it); every element then carries Z (arcs and NURBS at the Z where they start).
//!   Otherwise it is 2-D (X Y), and a later feed move with a `Z` word is an error.
//! * **5-axis programs** for table-tilting machines (LinuxCNC's `xyzac-trt-kins` /
//!   `xyzbc-trt-kins`, whose world coordinates are the tool tip in the workpiece frame and the
//!   rotary angles): `A` (tilt about X) or `B` (about Y) and `C` words, in degrees whatever the
//!   length units, absolute or incremental like X Y Z; one tilt letter per program. The path is
//!   5-axis if the tilt and C are both known where the feed motion begins (Z must be known then
//!   too); every element then carries a top curve, the point [`TOP_LENGTH`] up the tool axis of
//!   the angles (`nurbs_rtcore::kinematics::TrtGeometry::tool_axis`). A `G1` interpolates tip
//!   and angles linearly, as LinuxCNC does: a move that turns by more than 0.5° (the two angles
//!   together) becomes equal polyline pieces whose top chords stay within 1e-4 mm of that
//!   interpolation. `G2`/`G3` and `G5.2` keep the angles (their top curve is the tip curve moved
//!   up the axis); a rotary word on them is an error, as is a move that only turns the tool
//!   about a standing tip (the feed is planned along the tip's path), one that turns an axis on
//!   a path that began 3-axis, a feed move where the tilt is 0 or changes sign (the singularity:
//!   the tool along the table's normal does not decide C), and `A` and `B` in one program. Which inverse-kinematics branch
//!   and C winding the machine takes is the planner's (`--machine`, `--negative-tilt`): the
//!   program's angles are recovered from the tool axis.
//! * **`G93` inverse time**: each `G1` needs its own `F` and takes 1/F minutes, so its feed
//!   (mm/s) is its tool-tip length times F / 60; `G2`/`G3`/`G5.2` in `G93` are errors. As in
//!   LinuxCNC (`convert_feed_mode`), `G94` sets the feed to 0 until the next `F`.
//! * **Streaming.** [`GcodeStream`] reads one line at a time and hands out each element once
//!   no later line can change it; a run of `G1` moves is cut into polyline elements of at most
//!   1,024 points. [`parse`] collects it. An error ends the stream after the elements before
//!   its line.
//! * **Accepted modal codes that do not change the tool-tip path:** `G17`, `G40`, `G43 H…`,
//!   `G49`, `G54`–`G59.3` (only before the first move: a change afterwards would move the path),
//!   `G61`, `G61.1`, `G64` (with `P`/`Q`), `G80`, `G90`/`G91`, `G90.1`/`G91.1`, `G96`,
//!   `G97`, `G98`, `G99`, `M0`, `M1`, `M3`–`M9`, `S`, `T`. Everything that would change the path
//!   or timing in a way we do not model — cutter compensation `G41`/`G42`, `G5`/`G5.1`, other
//!   planes, `G95`, `G4`, `G10`, `G28`, `G30`, `G52`, `G53`, `G92…`, canned cycles, probing,
//!   threading, axes U V W, parameters `#`, expressions `[…]`, O-words and block delete —
//!   is an error naming the line and column. An unknown G- or M-code is an error.

use super::ReadError;
use crate::geometry::{ElementKind, Nurbs, PathElement, Toolpath};
use nurbs_rtcore::kinematics::{Tilt, TrtGeometry};
use std::collections::VecDeque;
use std::f64::consts::{FRAC_PI_2, SQRT_2, TAU};
use std::sync::Arc;

const MM_PER_INCH: f64 = 25.4;
/// `CENTER_ARC_RADIUS_TOLERANCE_MM` (interp_internal.hh), in mm.
const SPIRAL_ABS_TOL_MM: f64 = 2.0 * 0.01 * SQRT_2;
/// `CENTER_ARC_RADIUS_TOLERANCE_INCH`, in inches.
const SPIRAL_ABS_TOL_INCH: f64 = 2.0 * 0.001 * SQRT_2;
/// `SPIRAL_RELATIVE_TOLERANCE`.
const SPIRAL_REL_TOL: f64 = 0.001;
/// `RADIUS_TOLERANCE_INCH`; `RADIUS_TOLERANCE_MM` is this times 25.4.
const RADIUS_TOL_INCH: f64 = 0.00005;
/// Most full turns accepted on one G2/G3 (keeps the arc's control polygon bounded).
const MAX_TURNS: u32 = 10_000;
/// Highest NURBS order (degree + 1) the geometry core supports.
const MAX_ORDER: usize = nurbs_rtcore::MAX_DEGREE + 1;

/// One word of a line: letter, value and 1-based column in the original text.
#[derive(Clone, Copy, Debug)]
struct Word {
    letter: char,
    value: f64,
    col: usize,
}

/// A pose whose coordinates may be unknown: X, Y, Z (mm), then the tilt (A or B) and C
/// (degrees) of a 5-axis program.
type Pos = [Option<f64>; 5];

/// Axis names of [`Pos`]'s entries (the tilt's as "A" for messages before one is known).
const POS_NAMES: [&str; 5] = ["X", "Y", "Z", "A", "C"];

/// A 5-axis program's top point: this far up the tool axis from the tip (mm).
pub const TOP_LENGTH: f64 = 10.0;

/// Largest rotary change (degrees, the tilt's and C's together) of one polyline piece of a
/// 5-axis `G1`: a move that turns more is cut into equal pieces, the tip and the angles interpolated linearly as LinuxCNC
/// does; the top point's chord then strays from that interpolation by at most
/// `TOP_LENGTH (1 - cos(Δ/2))`, 1e-4 mm at 0.5°.
const MAX_ROTARY_STEP: f64 = 0.5;

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Motion {
    Rapid,
    Line,
    ArcCw,
    ArcCcw,
    Nurbs,
}

/// A move after interpretation, in mm.
#[derive(Clone, Debug)]
enum Move {
    Rapid {
        line: usize,
        col: usize,
        from: Pos,
        to: Pos,
    },
    Line {
        line: usize,
        from: Pos,
        to: Pos,
        /// mm/s; in inverse time (`G93`) the line's F (1/min) instead.
        feed: f64,
        inverse_time: bool,
        z_word: bool,
    },
    Arc {
        line: usize,
        /// The pose where it starts (its Z and, constant along it, the rotary angles).
        from: Pos,
        arc: ArcGeom,
        feed: f64,
        z_word: bool,
    },
    Nurbs {
        line: usize,
        order: usize,
        points: Vec<[f64; 2]>,
        weights: Vec<f64>,
        /// The pose where the block starts (its Z, the rotary angles).
        from: Pos,
        feed: f64,
    },
}

/// A circular arc in the XY plane: exact end points, centre and signed sweep (radians, > 0 CCW).
#[derive(Clone, Copy, Debug)]
pub(crate) struct ArcGeom {
    pub start: [f64; 2],
    pub end: [f64; 2],
    pub center: [f64; 2],
    pub sweep: f64,
}

/// An open `G5.2` block.
struct NurbsBlock {
    line: usize,
    order: usize,
    start: [f64; 2],
    /// The pose where it opens.
    from: Pos,
    points: Vec<[f64; 2]>,
    weights: Vec<f64>,
}

struct Interp {
    file: Arc<str>,
    /// mm per program unit.
    scale: f64,
    absolute: bool,
    ij_absolute: bool,
    /// Modal motion; `None` after G80 / G5.3 / at start (LinuxCNC: G80 or -1).
    motion: Option<Motion>,
    /// Feed in mm/s (0 until an F word).
    feed: f64,
    /// `G93`: the F word of each feed move is its inverse time (1/min), not modal.
    inverse_time: bool,
    /// The tilt axis's letter (`A` or `B`) once a program uses one.
    tilt_letter: Option<char>,
    pos: Pos,
    coord_system: i32,
    nurbs: Option<NurbsBlock>,
    moves: Vec<Move>,
}

fn err(file: &str, line: usize, col: usize, msg: impl Into<String>) -> ReadError {
    ReadError::at(file, line, Some(col), msg)
}

fn fmt_code(letter: char, code10: i32) -> String {
    if code10 % 10 == 0 {
        format!("{letter}{}", code10 / 10)
    } else {
        format!("{letter}{}.{}", code10 / 10, code10 % 10)
    }
}

/// Splits one line into words (LinuxCNC `close_and_downcase` + `read_items`).
fn tokenize(file: &str, lineno: usize, text: &str) -> Result<Vec<Word>, ReadError> {
    // Normalised characters with their original columns.
    let mut chars: Vec<(char, usize)> = Vec::new();
    let mut in_comment: Option<usize> = None;
    for (i, c) in text.chars().enumerate() {
        let col = i + 1;
        if let Some(_start) = in_comment {
            if c == ')' {
                in_comment = None;
            } else if c == '(' {
                return Err(err(file, lineno, col, "nested comment found: '(' inside a '(' comment"));
            }
            continue;
        }
        match c {
            '(' => in_comment = Some(col),
            ';' => break,
            ' ' | '\t' | '\r' => {}
            _ => chars.push((c.to_ascii_lowercase(), col)),
        }
    }
    if let Some(start) = in_comment {
        return Err(err(file, lineno, start, "unclosed comment: '(' without ')'"));
    }
    let mut words = Vec::new();
    let mut i = 0;
    while i < chars.len() {
        let (c, col) = chars[i];
        match c {
            '/' if i == 0 => {
                return Err(err(
                    file,
                    lineno,
                    col,
                    "block delete '/' is not supported (whether the line runs depends on the operator's switch)",
                ))
            }
            '#' => return Err(err(file, lineno, col, "parameters ('#') are not supported")),
            '[' => return Err(err(file, lineno, col, "expressions ('[...]') are not supported")),
            'o' => {
                return Err(err(
                    file,
                    lineno,
                    col,
                    "O-words (subroutines, loops, conditionals) are not supported",
                ))
            }
            'a'..='z' => {}
            _ => return Err(err(file, lineno, col, format!("bad character '{c}' used"))),
        }
        i += 1;
        // Number: [+-] digits [. digits], at least one digit.
        let start = i;
        let mut s = String::new();
        if i < chars.len() && (chars[i].0 == '+' || chars[i].0 == '-') {
            s.push(chars[i].0);
            i += 1;
        }
        let mut digits = 0;
        let mut dot = false;
        while i < chars.len() {
            let d = chars[i].0;
            if d.is_ascii_digit() {
                digits += 1;
            } else if d == '.' && !dot {
                dot = true;
            } else {
                break;
            }
            s.push(d);
            i += 1;
        }
        if i < chars.len() && (chars[i].0 == '#' || chars[i].0 == '[') && digits == 0 {
            let what = if chars[i].0 == '#' {
                "parameters ('#')"
            } else {
                "expressions ('[...]')"
            };
            return Err(err(file, lineno, chars[i].1, format!("{what} are not supported")));
        }
        if digits == 0 {
            let at = chars.get(start).map_or(col + 1, |p| p.1);
            return Err(err(
                file,
                lineno,
                at,
                format!(
                    "bad number format: '{}' must be followed by a number",
                    c.to_ascii_uppercase()
                ),
            ));
        }
        let value: f64 = s.parse().map_err(|_| {
            err(
                file,
                lineno,
                col,
                format!("bad number format after '{}'", c.to_ascii_uppercase()),
            )
        })?;
        if c == 'n' {
            if !words.is_empty() {
                return Err(err(
                    file,
                    lineno,
                    col,
                    "an N line number is only allowed at the start of a line",
                ));
            }
            continue;
        }
        words.push(Word {
            letter: c.to_ascii_uppercase(),
            value,
            col,
        });
    }
    Ok(words)
}

/// The words of one line sorted by kind.
#[derive(Default)]
struct Block {
    g: Vec<(i32, usize)>,
    m: Vec<(i32, usize)>,
    /// Other words by letter index.
    words: [Option<(f64, usize)>; 26],
}

impl Block {
    fn get(&self, letter: char) -> Option<(f64, usize)> {
        self.words[(letter as u8 - b'A') as usize]
    }
    fn has(&self, letter: char) -> bool {
        self.get(letter).is_some()
    }
    fn has_g(&self, code: i32) -> bool {
        self.g.iter().any(|g| g.0 == code)
    }
    fn col_g(&self, code: i32) -> usize {
        self.g.iter().find(|g| g.0 == code).map_or(1, |g| g.1)
    }
}

/// Modal groups of the G-codes we know (from `_gees` in `interp_array.cc`), `None` if unknown.
fn g_group(code: i32) -> Option<u8> {
    Some(match code {
        0 | 10 | 20 | 30 | 50 | 51 | 52 | 53 | 330 | 331 | 382..=385 | 730 | 740 | 760 | 800..=890 => 1,
        170 | 171 | 180 | 181 | 190 | 191 => 2,
        900 | 910 => 3,
        901 | 911 => 4,
        930 | 940 | 950 => 5,
        200 | 210 => 6,
        400 | 410 | 411 | 420 | 421 => 7,
        430 | 431 | 432 | 490 => 8,
        980 | 990 => 10,
        540 | 550 | 560 | 570 | 580 | 590 | 591 | 592 | 593 => 12,
        610 | 611 | 640 => 13,
        960 | 970 => 14,
        70 | 80 => 15,
        40 | 100 | 280 | 281 | 300 | 301 | 520 | 530 | 920..=923 => 0,
        _ => return None,
    })
}

fn unsupported_g(code: i32) -> Option<&'static str> {
    Some(match code {
        50 | 51 => "cubic/quadratic splines G5/G5.1 are not supported (use G5.2/G5.3)",
        330 | 331 | 760 => "spindle-synchronised motion and threading are not supported",
        382..=385 => "probing moves are not supported",
        730 | 740 | 810..=890 => "canned cycles are not supported",
        171 | 180 | 181 | 190 | 191 => "only the XY plane (G17) is supported",
        950 => "feed per revolution G95 is not supported (use G94)",
        410 | 411 | 420 | 421 => "cutter radius compensation (G41/G42) changes the path and is not supported",
        431 | 432 => "dynamic/added tool length offsets (G43.1/G43.2) are not supported",
        70 | 80 => "lathe diameter/radius mode (G7/G8) is not supported",
        40 => "dwell G4 is not supported (the toolpath is one continuous feed motion)",
        100 => "G10 (setting offsets and tables) is not supported",
        280 | 281 | 300 | 301 => "reference moves G28/G30 are not supported",
        520 | 920..=923 => "coordinate offsets G52/G92 change the path and are not supported",
        530 => "moves in machine coordinates G53 are not supported",
        _ => return None,
    })
}

impl Interp {
    fn parse_block(&self, lineno: usize, words: &[Word]) -> Result<Block, ReadError> {
        let file_name = Arc::clone(&self.file);
        let file: &str = &file_name;
        let mut b = Block::default();
        let mut groups: Vec<(u8, i32)> = Vec::new();
        for w in words {
            match w.letter {
                'G' => {
                    let code = (w.value * 10.0).round();
                    if (w.value * 10.0 - code).abs() > 1e-4 || !(0.0..10000.0).contains(&code) {
                        return Err(err(file, lineno, w.col, format!("unknown G-code G{}", w.value)));
                    }
                    let code = code as i32;
                    let group = g_group(code)
                        .ok_or_else(|| err(file, lineno, w.col, format!("unknown G-code {}", fmt_code('G', code))))?;
                    if let Some(&(_, other)) = groups.iter().find(|(g, _)| *g == group && group != 0) {
                        return Err(err(
                            file,
                            lineno,
                            w.col,
                            format!(
                                "{} and {} are in the same modal group and cannot be on one line",
                                fmt_code('G', other),
                                fmt_code('G', code)
                            ),
                        ));
                    }
                    groups.push((group, code));
                    b.g.push((code, w.col));
                }
                'M' => {
                    let code = w.value.round();
                    if (w.value - code).abs() > 1e-4 || code < 0.0 {
                        return Err(err(file, lineno, w.col, format!("unknown M-code M{}", w.value)));
                    }
                    let code = code as i32;
                    match code {
                        0..=9 | 30 => {}
                        _ => {
                            return Err(err(
                                file,
                                lineno,
                                w.col,
                                format!("M{code} is not supported (accepted: M0-M9, M2, M30)"),
                            ))
                        }
                    }
                    b.m.push((code * 10, w.col));
                }
                'U' | 'V' | 'W' => {
                    return Err(err(
                        file,
                        lineno,
                        w.col,
                        format!(
                        "axis {} is not supported: toolpaths are X Y Z, with A or B and C on table-tilting machines",
                        w.letter
                    ),
                    ))
                }
                'E' => return Err(err(file, lineno, w.col, "E word is not supported")),
                letter => {
                    let slot = &mut b.words[(letter as u8 - b'A') as usize];
                    if slot.is_some() {
                        return Err(err(file, lineno, w.col, format!("multiple {letter} words on one line")));
                    }
                    *slot = Some((w.value, w.col));
                }
            }
        }
        // M-codes: one per LinuxCNC modal group (4: stop, 6: tool change, 7: spindle, 8: coolant).
        for (i, &(a, _)) in b.m.iter().enumerate() {
            let group = |m: i32| match m / 10 {
                0 | 1 | 2 | 30 => 4,
                6 => 6,
                3..=5 => 7,
                _ => 8,
            };
            if let Some(&(bm, bcol)) = b.m[i + 1..].iter().find(|(m, _)| group(*m) == group(a)) {
                return Err(err(
                    file,
                    lineno,
                    bcol,
                    format!(
                        "M{} and M{} are in the same modal group and cannot be on one line",
                        a / 10,
                        bm / 10
                    ),
                ));
            }
        }
        if let Some((_, col)) = b.words.iter().flatten().find(|w| !w.0.is_finite()) {
            return Err(err(file, lineno, *col, "number out of range"));
        }
        Ok(b)
    }

    fn need(&self, lineno: usize, col: usize, axis: usize) -> Result<f64, ReadError> {
        self.pos[axis].ok_or_else(|| {
            err(
                &self.file,
                lineno,
                col,
                format!(
                    "the current {} position is unknown here: position the tool with G0 (in G90) first",
                    self.axis_name(axis)
                ),
            )
        })
    }

    /// The name of [`Pos`] entry `axis`.
    fn axis_name(&self, axis: usize) -> String {
        match (axis, self.tilt_letter) {
            (3, Some(letter)) => letter.to_string(),
            _ => POS_NAMES[axis].to_string(),
        }
    }

    /// The rotary words of a line: its tilt letter (`A` or `B`) must be the program's (the first
    /// one it uses), as a table-tilting machine has one.
    fn rotary_axes(&mut self, lineno: usize, b: &Block) -> Result<(), ReadError> {
        for letter in ['A', 'B'] {
            if let Some((_, col)) = b.get(letter) {
                match self.tilt_letter {
                    Some(t) if t != letter => {
                        return Err(err(
                            &self.file,
                            lineno,
                            col,
                            format!("{letter} word in a program that tilts about {t}: a table-tilting machine has one tilt axis (XYZAC or XYZBC)"),
                        ))
                    }
                    _ => self.tilt_letter = Some(letter),
                }
            }
        }
        Ok(())
    }

    /// The line's first rotary word, if any.
    fn rotary_word(b: &Block) -> Option<(char, usize)> {
        ['A', 'B', 'C'].into_iter().find_map(|l| b.get(l).map(|w| (l, w.1)))
    }

    /// Arcs and NURBS blocks turn no rotary axis and run in units per minute (`G94`).
    fn refuse_rotary_or_inverse_time(&self, lineno: usize, col: usize, b: &Block, name: &str) -> Result<(), ReadError> {
        if let Some((letter, c)) = Self::rotary_word(b) {
            return Err(err(
                &self.file,
                lineno,
                c,
                format!("{letter} word on {name}: only G0 and G1 may turn a rotary axis"),
            ));
        }
        if self.inverse_time {
            return Err(err(
                &self.file,
                lineno,
                col,
                format!("{name} in inverse time (G93) is not supported: only G1 (use G94)"),
            ));
        }
        Ok(())
    }

    /// End point of a move (`find_ends`), in mm and degrees; unknown stays unknown for axes not
    /// programmed.
    fn find_end(&self, lineno: usize, b: &Block) -> Result<Pos, ReadError> {
        let mut end = self.pos;
        let tilt = self.tilt_letter.unwrap_or('A');
        for (axis, letter) in ['X', 'Y', 'Z', tilt, 'C'].into_iter().enumerate() {
            if let Some((v, col)) = b.get(letter) {
                // Rotary axes are in degrees whatever the length units.
                let v = if axis < 3 { v * self.scale } else { v };
                end[axis] = Some(if self.absolute {
                    v
                } else {
                    self.need(lineno, col, axis)? + v
                });
            }
        }
        Ok(end)
    }

    fn line(&mut self, lineno: usize, words: &[Word]) -> Result<bool, ReadError> {
        let b = self.parse_block(lineno, words)?;
        let in_nurbs = self.nurbs.is_some();
        self.check_inside_nurbs(lineno, &b)?;
        let file_name = Arc::clone(&self.file);
        let file: &str = &file_name;
        for &(code, col) in &b.g {
            if let Some(why) = unsupported_g(code) {
                return Err(err(file, lineno, col, format!("{}: {why}", fmt_code('G', code))));
            }
        }

        self.rotary_axes(lineno, &b)?;
        // Order of execution (LinuxCNC manual, "Order of Execution"; execute_block).
        self.modal_settings(lineno, &b)?;
        // Motion (enhance_block).
        let (motion, axis_word) = self.motion_of(lineno, &b)?;
        let mcode = motion.map(|m| m.0);
        check_word_users(file, lineno, &b, mcode)?;
        match motion {
            None => {}
            Some((800, _)) => self.motion = None,
            Some((code @ (0 | 10), col)) => self.straight_move(lineno, code, col, axis_word, &b)?,
            Some((code @ (20 | 30), col)) => {
                self.motion = Some(if code == 20 { Motion::ArcCw } else { Motion::ArcCcw });
                self.arc(lineno, col, code == 20, &b)?;
            }
            Some((52, col)) => self.nurbs_point(lineno, col, &b)?,
            Some((53, _)) => self.end_nurbs_block(lineno, axis_word, &b)?,
            Some((other, col)) => {
                return Err(err(
                    file,
                    lineno,
                    col,
                    format!("{} is not supported", fmt_code('G', other)),
                ))
            }
        }
        if mcode != Some(52) && mcode != Some(53) && in_nurbs {
            // A line inside the block without control point: only F, comments and N are allowed.
            for letter in ['P', 'L'] {
                if let Some((_, col)) = b.get(letter) {
                    return Err(err(
                        file,
                        lineno,
                        col,
                        format!("{letter} word without X Y control point"),
                    ));
                }
            }
        }
        // Stop codes run last.
        Ok(b.m.iter().any(|m| m.0 == 20 || m.0 == 300))
    }

    /// Inside a G5.2 block only control points, F, comments and N may come.
    fn check_inside_nurbs(&self, lineno: usize, b: &Block) -> Result<(), ReadError> {
        let file: &str = &self.file;
        if let Some(open) = &self.nurbs {
            let opened = open.line;
            if let Some(&(code, col)) = b.g.iter().find(|g| g.0 != 52 && g.0 != 53) {
                let what = if unsupported_g(code).is_some() || g_group(code).is_some() {
                    format!("{} is not allowed inside a G5.2 NURBS block", fmt_code('G', code))
                } else {
                    format!("unknown G-code {} inside a G5.2 NURBS block", fmt_code('G', code))
                };
                return Err(err(
                    file,
                    lineno,
                    col,
                    format!("{what} (opened at line {opened}; close it with G5.3)"),
                ));
            }
            if let Some(&(code, col)) = b.m.first() {
                return Err(err(
                    file,
                    lineno,
                    col,
                    format!(
                        "M{} is not allowed inside a G5.2 NURBS block (opened at line {opened})",
                        code / 10
                    ),
                ));
            }
            for letter in ['Z', 'I', 'J', 'K', 'R', 'Q', 'H', 'S', 'T'] {
                if let Some((_, col)) = b.get(letter) {
                    let why = if letter == 'Z' {
                        " (LinuxCNC NURBS are XY only and ignore Z)"
                    } else {
                        ""
                    };
                    return Err(err(
                        file,
                        lineno,
                        col,
                        format!(
                            "{letter} word is not allowed inside a G5.2 NURBS block (opened at line {opened}){why}"
                        ),
                    ));
                }
            }
        }

        Ok(())
    }

    /// The words that set modes, in LinuxCNC's order: F (in the units active before this
    /// line's G20/G21), S, T, G20/G21, the coordinate system, G90/G91, G90.1/G91.1.
    fn modal_settings(&mut self, lineno: usize, b: &Block) -> Result<(), ReadError> {
        let file_name = Arc::clone(&self.file);
        let file: &str = &file_name;
        // The feed mode before F (`convert_feed_mode`): G94 also sets the feed to 0.
        if b.has_g(930) {
            self.inverse_time = true;
        }
        if b.has_g(940) {
            self.inverse_time = false;
            self.feed = 0.0;
        }
        if let Some((f, col)) = b.get('F') {
            if f < 0.0 {
                return Err(err(file, lineno, col, "negative F word found"));
            }
            if !self.inverse_time {
                self.feed = f * self.scale / 60.0;
            }
        }
        if let Some((s, col)) = b.get('S') {
            if s < 0.0 {
                return Err(err(file, lineno, col, "negative S word found"));
            }
        }
        if let Some((t, col)) = b.get('T') {
            if t < 0.0 || t.fract() != 0.0 {
                return Err(err(file, lineno, col, "T word must be a non-negative integer"));
            }
        }
        if b.has_g(200) {
            self.scale = MM_PER_INCH;
        }
        if b.has_g(210) {
            self.scale = 1.0;
        }
        if let Some(&(code, col)) = b.g.iter().find(|g| g_group(g.0) == Some(12)) {
            if code != self.coord_system && self.pos.iter().any(|p| p.is_some()) {
                return Err(err(
                    file,
                    lineno,
                    col,
                    format!(
                        "changing the coordinate system ({}) after the first move shifts the path; not supported",
                        fmt_code('G', code)
                    ),
                ));
            }
            self.coord_system = code;
        }
        if b.has_g(900) {
            self.absolute = true;
        }
        if b.has_g(910) {
            self.absolute = false;
        }
        if b.has_g(901) {
            self.ij_absolute = true;
        }
        if b.has_g(911) {
            self.ij_absolute = false;
        }

        Ok(())
    }

    /// The line's motion code and its column (programmed, or the modal one if an axis word
    /// comes alone), and its first axis word.
    #[allow(clippy::type_complexity)]
    fn motion_of(&self, lineno: usize, b: &Block) -> Result<(Option<(i32, usize)>, Option<(char, usize)>), ReadError> {
        let file: &str = &self.file;
        let motion_code = b.g.iter().find(|g| g_group(g.0) == Some(1)).copied();
        let axis_word = ['X', 'Y', 'Z', 'A', 'B', 'C']
            .iter()
            .find_map(|&l| b.get(l).map(|w| (l, w.1)));
        let motion: Option<(i32, usize)> = match motion_code {
            Some(m) => Some(m),
            None => match axis_word {
                Some((_, col)) => match self.motion {
                    None => {
                        return Err(err(
                            file,
                            lineno,
                            col,
                            "cannot use axis values without a G-code that uses them (no motion mode is active)",
                        ))
                    }
                    Some(m) => Some((
                        match m {
                            Motion::Rapid => 0,
                            Motion::Line => 10,
                            Motion::ArcCw => 20,
                            Motion::ArcCcw => 30,
                            Motion::Nurbs => 52,
                        },
                        col,
                    )),
                },
                None => None,
            },
        };
        Ok((motion, axis_word))
    }

    /// G0 or G1 to the line's end point.
    fn straight_move(
        &mut self,
        lineno: usize,
        code: i32,
        code_col: usize,
        axis_word: Option<(char, usize)>,
        b: &Block,
    ) -> Result<(), ReadError> {
        let file_name = Arc::clone(&self.file);
        let file: &str = &file_name;
        let m = if code == 0 { Motion::Rapid } else { Motion::Line };
        self.motion = Some(m);
        let to = self.find_end(lineno, b)?;
        if m == Motion::Line {
            let feed = if self.inverse_time {
                let f = b
                    .get('F')
                    .map(|f| f.0)
                    .ok_or_else(|| err(file, lineno, code_col, "F word missing with inverse time G1 move"))?;
                if f == 0.0 {
                    return Err(err(file, lineno, code_col, "cannot do G1 with zero feed rate"));
                }
                f
            } else {
                self.feed
            };
            if feed == 0.0 {
                return Err(err(file, lineno, code_col, "cannot do G1 with zero feed rate"));
            }
            if to != self.pos {
                // A feed move needs a known XY start point.
                let col = axis_word.map_or(code_col, |a| a.1);
                self.need(lineno, col, 0)?;
                self.need(lineno, col, 1)?;
            }
            self.moves.push(Move::Line {
                line: lineno,
                from: self.pos,
                to,
                feed,
                inverse_time: self.inverse_time,
                z_word: b.has('Z'),
            });
        } else {
            let col = axis_word.map_or(code_col, |a| a.1);
            self.moves.push(Move::Rapid {
                line: lineno,
                col,
                from: self.pos,
                to,
            });
        }
        self.pos = to;
        Ok(())
    }

    /// G5.3: the end of a G5.2 block, which becomes one NURBS move.
    fn end_nurbs_block(&mut self, lineno: usize, axis_word: Option<(char, usize)>, b: &Block) -> Result<(), ReadError> {
        let file_name = Arc::clone(&self.file);
        let file: &str = &file_name;
        let col = b.col_g(53);
        let Some(block) = self.nurbs.take() else {
            return Err(err(file, lineno, col, "cannot use G5.3 without G5.2 first"));
        };
        if let Some((l, c)) = axis_word {
            return Err(err(
                file,
                lineno,
                c,
                format!("{l} word on the G5.3 line: LinuxCNC ignores it; put the last control point on its own line"),
            ));
        }
        for letter in ['P', 'L'] {
            if let Some((_, c)) = b.get(letter) {
                return Err(err(file, lineno, c, format!("{letter} word with no G5.2 to use it")));
            }
        }
        let n = block.points.len();
        if n < block.order {
            return Err(err(
                file,
                lineno,
                col,
                format!(
                    "you must specify a number of control points at least equal to the order L = {} (the block opened at line {} has {n})",
                    block.order, block.line
                ),
            ));
        }
        let last = block.points[n - 1];
        self.pos[0] = Some(last[0]);
        self.pos[1] = Some(last[1]);
        self.moves.push(Move::Nurbs {
            line: block.line,
            order: block.order,
            points: block.points,
            weights: block.weights,
            from: block.from,
            feed: self.feed,
        });
        self.motion = None;
        Ok(())
    }

    /// One line of a G5.2 block (`Interp::convert_nurbs`).
    fn nurbs_point(&mut self, lineno: usize, col: usize, b: &Block) -> Result<(), ReadError> {
        self.refuse_rotary_or_inverse_time(lineno, col, b, "G5.2")?;
        let file_name = Arc::clone(&self.file);
        let file: &str = &file_name;
        let (x, y) = (b.get('X'), b.get('Y'));
        if x.is_some() != y.is_some() {
            let c = x.or(y).map_or(col, |w| w.1);
            return Err(err(
                file,
                lineno,
                c,
                "you must specify both X and Y coordinates for control points",
            ));
        }
        let has_xy = x.is_some();
        let first = self.nurbs.is_none();
        if !has_xy && b.has('P') && !first {
            return Err(err(
                file,
                lineno,
                b.get('P').unwrap().1,
                "can specify P without X and Y only for the first control point",
            ));
        }
        if self.feed == 0.0 {
            return Err(err(file, lineno, col, "cannot make a NURBS with 0 feedrate"));
        }
        if first {
            let x0 = self.need(lineno, col, 0)?;
            let y0 = self.need(lineno, col, 1)?;
            let w0 = match (has_xy, b.get('P')) {
                (false, Some((p, pc))) => {
                    if p <= 0.0 {
                        return Err(err(
                            file,
                            lineno,
                            pc,
                            "must specify positive weight P for every control point",
                        ));
                    }
                    p
                }
                _ => 1.0,
            };
            self.nurbs = Some(NurbsBlock {
                line: lineno,
                order: 3,
                start: [x0, y0],
                from: self.pos,
                points: vec![[x0, y0]],
                weights: vec![w0],
            });
            self.motion = Some(Motion::Nurbs);
        }
        let (scale, absolute) = (self.scale, self.absolute);
        let block = self.nurbs.as_mut().expect("opened above");
        if let Some((l, lc)) = b.get('L') {
            if l.fract() != 0.0 || l < 0.0 {
                return Err(err(file, lineno, lc, "L word must be a non-negative integer"));
            }
            // LinuxCNC: `if (block->l_number != -1 && block->l_number > 3) nurbs_order = L`.
            if l > 3.0 {
                if l > MAX_ORDER as f64 {
                    return Err(err(
                        file,
                        lineno,
                        lc,
                        format!(
                            "NURBS order L = {l} is above the supported maximum {MAX_ORDER} (degree {})",
                            MAX_ORDER - 1
                        ),
                    ));
                }
                block.order = l as usize;
            }
        }
        if let (Some((xv, _)), Some((yv, _))) = (x, y) {
            let p = match b.get('P') {
                Some((p, _)) if p > 0.0 => p,
                Some((_, pc)) => {
                    return Err(err(
                        file,
                        lineno,
                        pc,
                        "must specify positive weight P for every control point",
                    ))
                }
                None => {
                    return Err(err(
                        file,
                        lineno,
                        col,
                        "must specify positive weight P for every control point",
                    ))
                }
            };
            let (xv, yv) = (xv * scale, yv * scale);
            let pt = if absolute {
                [xv, yv]
            } else {
                [block.start[0] + xv, block.start[1] + yv]
            };
            block.points.push(pt);
            block.weights.push(p);
        }
        Ok(())
    }

    /// G2/G3 in the XY plane (`convert_arc`, `arc_data_ijk`, `arc_data_r`).
    fn arc(&mut self, lineno: usize, col: usize, cw: bool, b: &Block) -> Result<(), ReadError> {
        let file_name = Arc::clone(&self.file);
        let file: &str = &file_name;
        let name = if cw { "G2" } else { "G3" };
        let ijk = b.has('I') || b.has('J');
        let r = b.get('R');
        if r.is_none() && !ijk {
            return Err(err(file, lineno, col, "R, I, J, and K words all missing for arc"));
        }
        if let (Some((_, rc)), true) = (r, ijk) {
            return Err(err(file, lineno, rc, "mixed radius-ijk format for arc"));
        }
        if r.is_some() && !b.has('X') && !b.has('Y') {
            return Err(err(file, lineno, col, "X and Y words missing for arc in XY plane"));
        }
        self.refuse_rotary_or_inverse_time(lineno, col, b, name)?;
        if self.feed == 0.0 {
            return Err(err(file, lineno, col, "cannot make arc with zero feed rate"));
        }
        let turns = arc_turns(file, lineno, b, name)?;
        let end = self.find_end(lineno, b)?;
        let sx = self.need(lineno, col, 0)?;
        let sy = self.need(lineno, col, 1)?;
        let (ex, ey) = (end[0].unwrap_or(sx), end[1].unwrap_or(sy));
        if let Some((_, zc)) = b.get('Z') {
            let z0 = self.need(lineno, zc, 2)?;
            if end[2] != Some(z0) {
                return Err(err(
                    file,
                    lineno,
                    zc,
                    "helical arc (Z changes on G2/G3) cannot be represented exactly as a NURBS; not supported",
                ));
            }
        }
        let (spiral_abs, radius_tol) = if self.scale == 1.0 {
            (SPIRAL_ABS_TOL_MM, RADIUS_TOL_INCH * MM_PER_INCH)
        } else {
            (SPIRAL_ABS_TOL_INCH * MM_PER_INCH, RADIUS_TOL_INCH * MM_PER_INCH)
        };
        let center = if let Some((rv, _)) = r {
            let at = |message: &str| err(file, lineno, col, message);
            radius_center(rv * self.scale, cw, [sx, sy], [ex, ey], radius_tol).map_err(at)?
        } else {
            let i = b.get('I').map(|w| w.0 * self.scale);
            let j = b.get('J').map(|w| w.0 * self.scale);
            if self.ij_absolute {
                for (v, l) in [(i, 'I'), (j, 'J')] {
                    if v.is_none() {
                        return Err(err(
                            file,
                            lineno,
                            col,
                            format!("{l} word missing in absolute center arc"),
                        ));
                    }
                }
                [i.unwrap(), j.unwrap()]
            } else {
                [sx + i.unwrap_or(0.0), sy + j.unwrap_or(0.0)]
            }
        };
        let abs_err = check_radii(file, lineno, col, [sx, sy], [ex, ey], center, (spiral_abs, radius_tol))?;
        let geom = arc_geometry([sx, sy], [ex, ey], center, !cw, turns).map_err(|shift| {
            err(
                file,
                lineno,
                col,
                format!(
                    "the arc's radii differ by {abs_err:.3e} mm; the exact circle through both end points would move the centre by {shift:.3e} mm (LinuxCNC would run a spiral); not supported"
                ),
            )
        })?;
        if let Some(shift) = geom.1 {
            if shift > spiral_abs {
                return Err(err(
                    file,
                    lineno,
                    col,
                    format!(
                        "the arc's radii differ by {abs_err:.3e} mm; the exact circle through both end points would move the centre by {shift:.3e} mm (LinuxCNC would run a spiral); not supported"
                    ),
                ));
            }
        }
        self.moves.push(Move::Arc {
            line: lineno,
            from: self.pos,
            arc: geom.0,
            feed: self.feed,
            z_word: b.has('Z'),
        });
        self.pos[0] = Some(ex);
        self.pos[1] = Some(ey);
        Ok(())
    }
}

/// The exact circular arc from `start` to `end` about (nearly) `center`, counter-clockwise if
/// `ccw`, with `turns - 1` extra full turns. When the two radii differ, the centre is projected
/// onto the chord's perpendicular bisector; the second value is how far it moved. A full circle
/// is made when `start == end`.
pub(crate) fn arc_geometry(
    start: [f64; 2],
    end: [f64; 2],
    center: [f64; 2],
    ccw: bool,
    turns: u32,
) -> Result<(ArcGeom, Option<f64>), f64> {
    let mut c = center;
    let mut shift = None;
    let chord = [end[0] - start[0], end[1] - start[1]];
    let len = chord[0].hypot(chord[1]);
    if len > 0.0 {
        let m = [(start[0] + end[0]) / 2.0, (start[1] + end[1]) / 2.0];
        let u = [chord[0] / len, chord[1] / len];
        let along = (c[0] - m[0]) * u[0] + (c[1] - m[1]) * u[1];
        if along != 0.0 {
            c = [c[0] - along * u[0], c[1] - along * u[1]];
            shift = Some(along.abs());
        }
    }
    let a0 = (start[1] - c[1]).atan2(start[0] - c[0]);
    let a1 = (end[1] - c[1]).atan2(end[0] - c[0]);
    let mut base = if ccw { a1 - a0 } else { a0 - a1 };
    base = base.rem_euclid(TAU);
    if base < 1e-12 || len == 0.0 {
        base = TAU;
    }
    let sweep = base + TAU * (turns.max(1) - 1) as f64;
    Ok((
        ArcGeom {
            start,
            end,
            center: c,
            sweep: if ccw { sweep } else { -sweep },
        },
        shift,
    ))
}

/// An exact rational quadratic NURBS for an arc in the XY plane, at height `z` if given.
pub(crate) fn arc_nurbs(arc: &ArcGeom, z: Option<f64>) -> Result<Nurbs, nurbs_rtcore::GeometryError> {
    let c = arc.center;
    let r = (arc.start[0] - c[0]).hypot(arc.start[1] - c[1]);
    let a0 = (arc.start[1] - c[1]).atan2(arc.start[0] - c[0]);
    let pieces = ((arc.sweep.abs() / FRAC_PI_2) - 1e-9).ceil().max(1.0) as usize;
    let d = arc.sweep / pieces as f64;
    let w = (d / 2.0).cos();
    let seg_len = r * d.abs();
    let mut points: Vec<Vec<f64>> = Vec::with_capacity(2 * pieces + 1);
    let mut weights = Vec::with_capacity(2 * pieces + 1);
    let mut knots = vec![0.0; 3];
    let with_z = |x: f64, y: f64| match z {
        Some(z) => vec![x, y, z],
        None => vec![x, y],
    };
    points.push(with_z(arc.start[0], arc.start[1]));
    weights.push(1.0);
    for i in 0..pieces {
        let am = a0 + d * (i as f64 + 0.5);
        let rm = r / w;
        points.push(with_z(c[0] + rm * am.cos(), c[1] + rm * am.sin()));
        weights.push(w);
        if i + 1 == pieces {
            points.push(with_z(arc.end[0], arc.end[1]));
        } else {
            let ae = a0 + d * (i + 1) as f64;
            points.push(with_z(c[0] + r * ae.cos(), c[1] + r * ae.sin()));
        }
        weights.push(1.0);
        let k = seg_len * (i + 1) as f64;
        if i + 1 == pieces {
            knots.extend_from_slice(&[k, k, k]);
        } else {
            knots.extend_from_slice(&[k, k]);
        }
    }
    Nurbs::new(2, knots, &points, Some(weights))
}

/// A degree-1 NURBS through `points`, parameterised by cumulative chord length of the tool tip
/// (mm): 2-D or 3-D points, or 5-axis points of six coordinates (tip, then top point).
/// Consecutive duplicate points must have been removed.
pub(crate) fn polyline_nurbs(points: &[Vec<f64>]) -> Result<Nurbs, nurbs_rtcore::GeometryError> {
    let dim = points.first().map_or(0, Vec::len);
    let tip_dim = if dim == 6 { 3 } else { dim };
    let mut knots = vec![0.0, 0.0];
    let mut s = 0.0;
    for w in points.windows(2) {
        s += w[0][..tip_dim]
            .iter()
            .zip(&w[1][..tip_dim])
            .map(|(a, b)| (a - b) * (a - b))
            .sum::<f64>()
            .sqrt();
        knots.push(s);
    }
    knots.push(s);
    if tip_dim == dim {
        return Nurbs::new(1, knots, points, None);
    }
    let flat: Vec<f64> = points.iter().flatten().copied().collect();
    Nurbs::from_flat(1, dim, tip_dim, knots, flat, vec![1.0; points.len()])
}

/// LinuxCNC's `knot_vector_creator(n, k)` for `n + 1` control points and order `k`.
pub fn linuxcnc_knot_vector(control_points: usize, order: usize) -> Vec<f64> {
    let n = control_points - 1;
    (0..=n + order)
        .map(|i| {
            if i < order {
                0.0
            } else if i <= n {
                (i - order + 1) as f64
            } else {
                (n + 2 - order) as f64
            }
        })
        .collect()
}

/// Most points of one polyline element: a longer run of G1 moves is cut into elements of this
/// many points (joined end to start), so that a program streams in bounded memory however
/// long its G1 runs are. Corner rounding joins them again.
const POLYLINE_POINTS: usize = 1024;

/// Parses a whole LinuxCNC G-code program into a toolpath (collects [`GcodeStream`]; see the
/// module documentation for the exact semantics and every decision).
pub fn parse(file: &str, text: &str) -> Result<Toolpath, ReadError> {
    let elements = GcodeStream::new(file, text.lines().map(|l| Ok(l.to_owned()))).collect::<Result<Vec<_>, _>>()?;
    Ok(Toolpath { elements })
}

/// A G-code program read one line at a time, as a stream of path elements: each element is
/// handed out as soon as the lines after it cannot change it, so a program of any length is
/// read in constant memory and planning can begin at its first line. An error ends the
/// stream (after the elements before it).
pub struct GcodeStream<L> {
    lines: L,
    lineno: usize,
    /// `Some(open)` once the first non-blank line is seen: whether the program is wrapped in `%`.
    percent: Option<bool>,
    /// No more lines are read (`M2`/`M30`, the closing `%`, or the end of the file).
    ended: bool,
    failed: bool,
    interp: Interp,
    builder: Builder,
    out: VecDeque<PathElement>,
}

impl<L: Iterator<Item = std::io::Result<String>>> GcodeStream<L> {
    /// The program whose lines `lines` gives; `file` names it in errors.
    pub fn new(file: &str, lines: L) -> Self {
        let file: Arc<str> = Arc::from(file);
        GcodeStream {
            lines,
            lineno: 0,
            percent: None,
            ended: false,
            failed: false,
            interp: Interp {
                file: Arc::clone(&file),
                scale: 1.0,
                absolute: true,
                ij_absolute: false,
                motion: None,
                feed: 0.0,
                inverse_time: false,
                tilt_letter: None,
                pos: [None; 5],
                coord_system: 540,
                nurbs: None,
                moves: Vec::new(),
            },
            builder: Builder {
                file,
                three_d: None,
                five_axis: None,
                poly: None,
                pending_rapid: None,
                any: false,
            },
            out: VecDeque::new(),
        }
    }

    /// Reads and interprets the next line (or ends the program).
    fn step(&mut self) -> Result<(), ReadError> {
        let file = Arc::clone(&self.interp.file);
        let Some(raw) = self.lines.next() else {
            return self.end_of_file();
        };
        let raw = raw.map_err(|e| ReadError::new(&file, e.to_string()))?;
        self.lineno += 1;
        let lineno = self.lineno;
        let trimmed = raw.trim();
        if trimmed.starts_with('%') {
            match self.percent {
                None => {
                    self.percent = Some(true);
                    return Ok(());
                }
                Some(true) => {
                    self.percent = Some(false);
                    return self.end_of_program();
                }
                Some(false) => {}
            }
        }
        if self.percent.is_none() && !trimmed.is_empty() {
            self.percent = Some(false);
        }
        let words = tokenize(&file, lineno, &raw)?;
        let stop = self.interp.line(lineno, &words)?;
        for m in self.interp.moves.drain(..) {
            self.builder.push(m, self.interp.tilt_letter, &mut self.out)?;
        }
        if stop {
            if let Some(block) = &self.interp.nurbs {
                return Err(ReadError::at(
                    &file,
                    lineno,
                    None,
                    format!("program ends inside the G5.2 NURBS block opened at line {}", block.line),
                ));
            }
            return self.end_of_program();
        }
        Ok(())
    }

    fn end_of_file(&mut self) -> Result<(), ReadError> {
        let file = Arc::clone(&self.interp.file);
        match self.percent {
            None => return Err(ReadError::new(&file, "file is empty")),
            Some(true) => {
                return Err(ReadError::at(
                    &file,
                    self.lineno,
                    None,
                    "file ended with no closing percent sign",
                ))
            }
            Some(false) => {}
        }
        if let Some(block) = &self.interp.nurbs {
            return Err(ReadError::at(
                &file,
                self.lineno,
                None,
                format!(
                    "file ends inside the G5.2 NURBS block opened at line {} (missing G5.3)",
                    block.line
                ),
            ));
        }
        self.end_of_program()
    }

    fn end_of_program(&mut self) -> Result<(), ReadError> {
        self.ended = true;
        self.builder.finish(&mut self.out)
    }
}

impl<L: Iterator<Item = std::io::Result<String>>> Iterator for GcodeStream<L> {
    type Item = Result<PathElement, ReadError>;

    fn next(&mut self) -> Option<Self::Item> {
        loop {
            if let Some(e) = self.out.pop_front() {
                return Some(Ok(e));
            }
            if self.ended || self.failed {
                return None;
            }
            if let Err(e) = self.step() {
                self.failed = true;
                return Some(Err(e));
            }
        }
    }
}

/// Turns interpreted moves into path elements as they come.
struct Builder {
    file: Arc<str>,
    /// Whether the path is 3-D: decided by the first feed move that moves, by whether the Z
    /// position is known where it starts.
    three_d: Option<bool>,
    /// Whether the path is 5-axis, and its tilt: decided by the first feed move that moves, by
    /// whether the tilt and C are known where it starts.
    five_axis: Option<Option<Tilt>>,
    /// The polyline under construction: (first line, feed, points).
    poly: Option<(usize, f64, Vec<Vec<f64>>)>,
    /// A rapid that moved the tool after a feed move (an error if another feed move follows).
    pending_rapid: Option<(usize, usize)>,
    /// A feed move has been taken.
    any: bool,
}

impl Builder {
    fn geometry(&self, line: usize) -> impl Fn(nurbs_rtcore::GeometryError) -> ReadError + '_ {
        move |e| ReadError::at(&self.file, line, None, format!("invalid curve: {e}"))
    }

    /// The Z of a 3-D path's move, which is known there (the path's Z was known where the
    /// feed motion began, and stays known).
    fn z_of(&self, line: usize, z: Option<f64>) -> Result<f64, ReadError> {
        z.ok_or_else(|| {
            ReadError::at(
                &self.file,
                line,
                None,
                "the Z position is unknown at the start of this move, but the program moves in Z: position Z with G0 first",
            )
        })
    }

    /// Decides the dimension at the first feed move (where Z starts `z`), and refuses a Z word
    /// on a feed move of a 2-D path.
    fn dimension(&mut self, line: usize, z: Option<f64>, z_word: bool) -> Result<bool, ReadError> {
        let three_d = *self.three_d.get_or_insert(z.is_some());
        if !three_d && z_word {
            return Err(ReadError::at(
                &self.file,
                line,
                None,
                "this move programs Z, but the Z position was unknown where the feed motion began (a 2-D path): position Z with G0 before the first feed move",
            ));
        }
        Ok(three_d)
    }

    fn flush(&mut self, out: &mut VecDeque<PathElement>) -> Result<(), ReadError> {
        if let Some((line, feed, pts)) = self.poly.take() {
            let curve = polyline_nurbs(&pts).map_err(self.geometry(line))?;
            out.push_back(PathElement {
                kind: ElementKind::Polyline,
                curve,
                feed: Some(feed),
                source_line: Some(line),
            });
        }
        Ok(())
    }

    /// A feed move is taken: a rapid that moved the tool since the last one is an error.
    fn feed_move(&mut self) -> Result<(), ReadError> {
        if let Some((rl, rc)) = self.pending_rapid.take() {
            return Err(ReadError::at(
                &self.file,
                rl,
                Some(rc),
                "G0 rapid between feed moves is not supported: a toolpath is one continuous feed motion (split the program)",
            ));
        }
        self.any = true;
        Ok(())
    }

    /// An arc or NURBS block starting at pose `from` is taken: the polyline before it goes out;
    /// its Z, on a 3-D path, and its constant tilt and C, on a 5-axis one.
    #[allow(clippy::type_complexity)]
    fn begin_curve(
        &mut self,
        line: usize,
        from: &Pos,
        z_word: bool,
        tilt_letter: Option<char>,
        out: &mut VecDeque<PathElement>,
    ) -> Result<(Option<f64>, Option<(Tilt, [f64; 2])>), ReadError> {
        let three_d = self.dimension(line, from[2], z_word)?;
        let five_axis = self.five_axis(line, from, three_d, tilt_letter)?;
        self.feed_move()?;
        self.flush(out)?;
        let z = three_d.then(|| self.z_of(line, from[2])).transpose()?;
        if five_axis.is_some() {
            self.off_the_singularity(line, from[3], from[3], tilt_letter)?;
        }
        let angles = five_axis.map(|tilt| (tilt, [from[3].expect("5-axis"), from[4].expect("5-axis")]));
        Ok((z, angles))
    }

    /// `curve` (the tool tip) with, on a 5-axis path, its top curve: the same curve moved
    /// [`TOP_LENGTH`] up the tool axis of the constant angles.
    fn with_top(&self, line: usize, curve: Nurbs, angles: Option<(Tilt, [f64; 2])>) -> Result<Nurbs, ReadError> {
        let Some((tilt, [t, c])) = angles else {
            return Ok(curve);
        };
        let axis = TrtGeometry {
            tilt,
            ..TrtGeometry::default()
        }
        .tool_axis(t, c);
        let top: Vec<Vec<f64>> = (0..curve.control_point_count())
            .map(|i| {
                let p = curve.control_point(i);
                (0..3).map(|k| p[k] + TOP_LENGTH * axis[k]).collect()
            })
            .collect();
        let top = Nurbs::new(
            curve.degree(),
            curve.knots().to_vec(),
            &top,
            Some(curve.weights().to_vec()),
        )
        .map_err(self.geometry(line))?;
        curve.with_top_curve(&top).map_err(self.geometry(line))
    }

    /// Decides at the first feed move whether the path is 5-axis: the tilt and C known where it
    /// starts (then Z must be known too). `None`: a 3-axis path.
    fn five_axis(
        &mut self,
        line: usize,
        from: &Pos,
        three_d: bool,
        tilt_letter: Option<char>,
    ) -> Result<Option<Tilt>, ReadError> {
        if let Some(decided) = self.five_axis {
            return Ok(decided);
        }
        let tilt = match tilt_letter {
            Some('B') => Tilt::Y,
            _ => Tilt::X,
        };
        let letter = tilt_letter.unwrap_or('A');
        let decided = match (from[3].is_some(), from[4].is_some()) {
            (false, false) => None,
            (true, true) if three_d => Some(tilt),
            (true, true) => {
                return Err(ReadError::at(
                    &self.file,
                    line,
                    None,
                    "a 5-axis program (the tilt and C positioned) needs Z positioned before its first feed move too",
                ))
            }
            (known_tilt, _) => {
                let (known, unknown) = if known_tilt { (letter, 'C') } else { ('C', letter) };
                return Err(ReadError::at(
                    &self.file,
                    line,
                    None,
                    format!("{known} is positioned but {unknown} is not where the feed motion begins: position both rotary axes with G0 first"),
                ));
            }
        };
        self.five_axis = Some(decided);
        Ok(decided)
    }

    /// A 5-axis feed move from tilt `from` to `to` keeps off 0: there the tool stands along
    /// the table's normal and its axis does not decide C, which the planner recovers from it.
    fn off_the_singularity(
        &self,
        line: usize,
        from: Option<f64>,
        to: Option<f64>,
        tilt_letter: Option<char>,
    ) -> Result<(), ReadError> {
        let (a, b) = (from.unwrap_or(0.0), to.unwrap_or(0.0));
        if a * b > 0.0 {
            return Ok(());
        }
        let letter = tilt_letter.unwrap_or('A');
        Err(ReadError::at(
            &self.file,
            line,
            None,
            format!("{letter} is 0 on this move, or changes sign ({letter}{a} to {letter}{b}): the tool along the table's normal does not decide C (the singularity), not supported on a 5-axis path"),
        ))
    }

    fn push(&mut self, m: Move, tilt_letter: Option<char>, out: &mut VecDeque<PathElement>) -> Result<(), ReadError> {
        match m {
            Move::Rapid { line, col, from, to } => {
                if from != to && self.any && self.pending_rapid.is_none() {
                    self.pending_rapid = Some((line, col));
                }
            }
            Move::Line {
                line,
                from,
                to,
                feed,
                inverse_time,
                z_word,
            } => {
                let moves_xy = from[0] != to[0] || from[1] != to[1];
                let moves_z = from[2] != to[2];
                let turns = from[3] != to[3] || from[4] != to[4];
                if self.three_d.is_none() && !(moves_xy || moves_z || turns) {
                    return Ok(());
                }
                let three_d = self.dimension(line, from[2], z_word)?;
                let five_axis = self.five_axis(line, &from, three_d, tilt_letter)?;
                if turns && five_axis.is_none() {
                    return Err(ReadError::at(
                        &self.file,
                        line,
                        None,
                        "this move turns a rotary axis, but the tilt and C were not both known where the feed motion began (a 3-axis path): position them with G0 before the first feed move",
                    ));
                }
                if !(moves_xy || three_d && moves_z) {
                    if turns {
                        return Err(ReadError::at(
                            &self.file,
                            line,
                            None,
                            "this move turns the tool about a standing tip (a pure reorientation): not supported, the feed is planned along the tool tip's path",
                        ));
                    }
                    return Ok(());
                }
                self.feed_move()?;
                let points = match five_axis {
                    None => {
                        let point = |p: &Pos| -> Result<Vec<f64>, ReadError> {
                            let (x, y) = (p[0].expect("checked"), p[1].expect("checked"));
                            Ok(if three_d {
                                vec![x, y, self.z_of(line, p[2])?]
                            } else {
                                vec![x, y]
                            })
                        };
                        vec![point(&from)?, point(&to)?]
                    }
                    Some(tilt) => {
                        self.off_the_singularity(line, from[3], to[3], tilt_letter)?;
                        five_axis_points(tilt, &from, &to)
                    }
                };
                let feed = if inverse_time {
                    // The move takes 1/F minutes: its tip feed.
                    let (start, end) = (&points[0], &points[points.len() - 1]);
                    let tip = start.len().min(3);
                    let length = (0..tip).map(|i| (end[i] - start[i]).powi(2)).sum::<f64>().sqrt();
                    length * feed / 60.0
                } else {
                    feed
                };
                match &mut self.poly {
                    Some((_, f, pts))
                        if *f == feed
                            && pts.last() == points.first()
                            && pts.len() + points.len() <= POLYLINE_POINTS + 1 =>
                    {
                        pts.extend(points.into_iter().skip(1))
                    }
                    _ => {
                        self.flush(out)?;
                        self.poly = Some((line, feed, points));
                    }
                }
            }
            Move::Arc {
                line,
                from,
                arc,
                feed,
                z_word,
            } => {
                let (z, angles) = self.begin_curve(line, &from, z_word, tilt_letter, out)?;
                let curve = arc_nurbs(&arc, z).map_err(self.geometry(line))?;
                let curve = self.with_top(line, curve, angles)?;
                out.push_back(PathElement {
                    kind: ElementKind::Arc,
                    curve,
                    feed: Some(feed),
                    source_line: Some(line),
                });
            }
            Move::Nurbs {
                line,
                order,
                points,
                weights,
                from,
                feed,
            } => {
                let (z, angles) = self.begin_curve(line, &from, false, tilt_letter, out)?;
                let pts: Vec<Vec<f64>> = points
                    .iter()
                    .map(|p| match z {
                        Some(z) => vec![p[0], p[1], z],
                        None => vec![p[0], p[1]],
                    })
                    .collect();
                let knots = linuxcnc_knot_vector(pts.len(), order);
                let curve = Nurbs::new(order - 1, knots, &pts, Some(weights)).map_err(self.geometry(line))?;
                let curve = self.with_top(line, curve, angles)?;
                out.push_back(PathElement {
                    kind: ElementKind::Nurbs,
                    curve,
                    feed: Some(feed),
                    source_line: Some(line),
                });
            }
        }
        Ok(())
    }

    /// The program has ended: the last polyline goes out.
    fn finish(&mut self, out: &mut VecDeque<PathElement>) -> Result<(), ReadError> {
        self.flush(out)?;
        if !self.any {
            return Err(ReadError::new(
                &self.file,
                "the program contains no feed moves (G1, G2, G3 or G5.2/G5.3)",
            ));
        }
        Ok(())
    }
}

/// The polyline points of a 5-axis `G1` from `from` to `to` (known poses): the tool tip, then
/// the top point [`TOP_LENGTH`] up the tool axis of the move's angles, at the ends and where
/// the angles have turned by [`MAX_ROTARY_STEP`] more (tip and angles linear in between, as
/// LinuxCNC interpolates them). The ends are the poses' points exactly, so that consecutive
/// moves join.
fn five_axis_points(tilt: Tilt, from: &Pos, to: &Pos) -> Vec<Vec<f64>> {
    let value = |p: &Pos, i: usize| p[i].expect("a 5-axis pose is known");
    let (a, b): ([f64; 5], [f64; 5]) = (
        core::array::from_fn(|i| value(from, i)),
        core::array::from_fn(|i| value(to, i)),
    );
    // The tool axis turns by at most the sum of the two angles' turns.
    let turn = (b[3] - a[3]).abs() + (b[4] - a[4]).abs();
    let pieces = ((turn / MAX_ROTARY_STEP).ceil() as usize).max(1);
    let geometry = TrtGeometry {
        tilt,
        ..TrtGeometry::default()
    };
    (0..=pieces)
        .map(|k| {
            let pose: [f64; 5] = match k {
                0 => a,
                k if k == pieces => b,
                k => {
                    let t = k as f64 / pieces as f64;
                    core::array::from_fn(|i| a[i] + (b[i] - a[i]) * t)
                }
            };
            let axis = geometry.tool_axis(pose[3], pose[4]);
            let mut point = pose[..3].to_vec();
            point.extend((0..3).map(|i| pose[i] + TOP_LENGTH * axis[i]));
            point
        })
        .collect()
}

/// Words that need a code on the line to use them (LinuxCNC's check_other_codes).
fn check_word_users(file: &str, lineno: usize, b: &Block, mcode: Option<i32>) -> Result<(), ReadError> {
    let arc = matches!(mcode, Some(20) | Some(30));
    for (letter, ok, users) in [
        ('I', arc, "G2 or G3"),
        ('J', arc, "G2 or G3"),
        ('R', arc, "G2 or G3"),
        ('K', false, "an arc in the XY plane (K belongs to other planes)"),
        ('P', arc || mcode == Some(52) || b.has_g(640), "G2, G3, G5.2 or G64"),
        ('Q', b.has_g(640), "G64"),
        ('L', mcode == Some(52), "G5.2"),
        ('H', b.has_g(430), "G43"),
        ('D', false, "G41 or G42 (cutter compensation is not supported)"),
    ] {
        if let (Some((_, col)), false) = (b.get(letter), ok) {
            return Err(err(
                file,
                lineno,
                col,
                format!("{letter} word with no {users} to use it"),
            ));
        }
    }

    Ok(())
}

/// The number of turns of a G2/G3 (`name`): its P word, 1 without one.
fn arc_turns(file: &str, lineno: usize, b: &Block, name: &str) -> Result<u32, ReadError> {
    let Some((p, pc)) = b.get('P') else {
        return Ok(1);
    };
    if p.fract() != 0.0 || p < 1.0 {
        return Err(err(
            file,
            lineno,
            pc,
            format!("P word on {name} (number of turns) must be an integer >= 1"),
        ));
    }
    if p > MAX_TURNS as f64 {
        return Err(err(
            file,
            lineno,
            pc,
            format!("P{p} on {name}: more than {MAX_TURNS} turns is not supported"),
        ));
    }
    Ok(p as u32)
}

/// The centre of an R-format arc from `[sx, sy]` to `[ex, ey]` (LinuxCNC's arc_data_r): a
/// negative `radius` takes the long way round.
fn radius_center(
    radius: f64,
    cw: bool,
    [sx, sy]: [f64; 2],
    [ex, ey]: [f64; 2],
    radius_tol: f64,
) -> Result<[f64; 2], &'static str> {
    if ex == sx && ey == sy {
        return Err("current point same as end point of arc");
    }
    let abs_r = radius.abs();
    let (mx, my) = ((ex + sx) / 2.0, (ey + sy) / 2.0);
    let mut half = (mx - ex).hypot(my - ey);
    if half - abs_r > radius_tol {
        return Err("arc radius too small to reach end point");
    }
    if half / abs_r > 1.0 - 1e-12 {
        half = abs_r;
    }
    let theta = if (cw && radius > 0.0) || (!cw && radius < 0.0) {
        (ey - sy).atan2(ex - sx) - FRAC_PI_2
    } else {
        (ey - sy).atan2(ex - sx) + FRAC_PI_2
    };
    let offset = abs_r * (half / abs_r).asin().cos();
    Ok([mx + offset * theta.cos(), my + offset * theta.sin()])
}

/// The radii to the arc's start and end must be non-zero and agree (LinuxCNC's spiral
/// tolerances, `(absolute, radius)` in mm); their difference.
fn check_radii(
    file: &str,
    lineno: usize,
    col: usize,
    [sx, sy]: [f64; 2],
    [ex, ey]: [f64; 2],
    center: [f64; 2],
    (spiral_abs, radius_tol): (f64, f64),
) -> Result<f64, ReadError> {
    let r1 = (center[0] - sx).hypot(center[1] - sy);
    let r2 = (center[0] - ex).hypot(center[1] - ey);
    if r1 < radius_tol || r2 < radius_tol {
        return Err(err(
            file,
            lineno,
            col,
            format!(
                "zero-radius arc: start=({sx:.4},{sy:.4}) center=({:.4},{:.4}) end=({ex:.4},{ey:.4})",
                center[0], center[1]
            ),
        ));
    }
    let abs_err = (r1 - r2).abs();
    let rel_err = abs_err / r1.max(r2);
    if abs_err > spiral_abs || rel_err > SPIRAL_REL_TOL {
        return Err(err(
            file,
            lineno,
            col,
            format!(
                "radius to end of arc differs from radius to start: start=({sx:.4},{sy:.4}) center=({:.4},{:.4}) end=({ex:.4},{ey:.4}) r1={r1:.4} r2={r2:.4} (mm)",
                center[0], center[1]
            ),
        ));
    }
    Ok(abs_err)
}
