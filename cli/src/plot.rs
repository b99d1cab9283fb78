//! `plan --plot`: the layout of Erwinski et al.'s Fig. 5 as a PNG. Three panels over the curve
//! parameter: (a) the planned feedrate with the feedrate limit function's components dashed and
//! the critical points marked; (b) axial accelerations and (c) axial jerks with their limits.
//!
//! Panels (b) and (c) are the finite differences of the sampled positions that `verify` checks
//! (`planner::axial`), so the plot shows exactly what is measured against the limits. Text is
//! drawn with a font compiled into the binary (assets/fonts), so no font library or font file
//! is needed at build or run time.

use nurbs_motion::geometry::Toolpath;
use nurbs_motion::planner::axial::MAX_AXES;
use nurbs_motion::planner::flf::{flf, CriticalPoint, FlfValue};
use nurbs_motion::planner::Limits;
use plotters::coord::Shift;
use plotters::element::DashedPathElement;
use plotters::prelude::*;
use std::fmt;
use std::path::Path;

/// Image size (pixels).
pub const WIDTH: u32 = 1600;
pub const HEIGHT: u32 = 1800;

const FONT_BYTES: &[u8] = include_bytes!("../../assets/fonts/DejaVuSans-subset.ttf");
const FONT: &str = "sans-serif";

/// FLF samples over the whole path (at least `MIN_FLF_PER_ELEMENT` per element).
const FLF_SAMPLES: usize = 4000;
const MIN_FLF_PER_ELEMENT: usize = 200;

/// One setpoint as plotted: where on the path, the planned feed and the axis positions.
#[derive(Clone, Copy, Debug)]
pub struct PlotSample {
    pub curve: usize,
    pub u: f64,
    /// Feed (mm/s).
    pub feed: f64,
    /// Axis positions in the order of [`Profile::axes`].
    pub q: [f64; MAX_AXES],
}

/// Everything the figure shows.
pub struct Profile<'a> {
    pub toolpath: &'a Toolpath,
    /// Limits as planned, one value per plotted axis.
    pub limits: &'a Limits,
    /// Axis names, in the order of `PlotSample::q` and of the limits.
    pub axes: &'a [&'a str],
    /// Axes from this index on are rotary (degrees): their units are deg/s^2 and deg/s^3.
    pub rotary_from: usize,
    pub samples: &'a [PlotSample],
    /// Draw the FLF components (the limits apply to the tool-tip coordinates).
    pub flf: bool,
    /// Critical points as (curve, point); empty when the planner has none.
    pub critical_points: &'a [(usize, CriticalPoint)],
    pub title: String,
}

/// A figure that could not be drawn or written.
#[derive(Debug)]
pub struct PlotError(pub String);

impl fmt::Display for PlotError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.0)
    }
}
impl std::error::Error for PlotError {}

fn draw_err<E: fmt::Debug>(e: E) -> PlotError {
    PlotError(format!("drawing the plot failed: {e:?}"))
}

/// The global plot parameter of (curve, u): u itself on a single-element path, otherwise the
/// element index plus u normalised to [0, 1] over that element.
struct Parameter {
    spans: Vec<(f64, f64)>,
}

impl Parameter {
    fn new(toolpath: &Toolpath) -> Self {
        Parameter {
            spans: toolpath
                .elements
                .iter()
                .map(|e| {
                    let v = e.curve.view();
                    (v.u_min(), v.u_max())
                })
                .collect(),
        }
    }
    fn single(&self) -> bool {
        self.spans.len() == 1
    }
    fn at(&self, curve: usize, u: f64) -> f64 {
        if self.single() {
            return u;
        }
        let (a, b) = self.spans[curve.min(self.spans.len() - 1)];
        let t = if b > a { (u - a) / (b - a) } else { 0.0 };
        curve as f64 + t.clamp(0.0, 1.0)
    }
    fn range(&self) -> (f64, f64) {
        if self.single() {
            self.spans[0]
        } else {
            (0.0, self.spans.len() as f64)
        }
    }
    fn label(&self) -> &'static str {
        if self.single() {
            "curve parameter u"
        } else {
            "path parameter: element index + u normalised over the element"
        }
    }
}

/// Signed axial velocity, acceleration and jerk per sample by the finite differences of
/// `planner::axial::FiniteDifferences` (same formulas, same order of operations): at rest before
/// the first sample, and three more samples at rest after the last.
pub fn axial_differences(samples: &[[f64; MAX_AXES]], axes: usize, dt: f64) -> Vec<[[f64; MAX_AXES]; 3]> {
    let mut out = Vec::with_capacity(samples.len() + 3);
    let Some(first) = samples.first() else {
        return out;
    };
    let mut history = [*first; 3];
    let last = *samples.last().unwrap();
    for p in samples.iter().chain([last; 3].iter()) {
        let [q3, q2, q1] = history;
        let mut d = [[0.0; MAX_AXES]; 3];
        for i in 0..axes {
            let v0 = (p[i] - q1[i]) / dt;
            let v1 = (q1[i] - q2[i]) / dt;
            let v2 = (q2[i] - q3[i]) / dt;
            let a0 = (v0 - v1) / dt;
            let a1 = (v1 - v2) / dt;
            let j0 = (a0 - a1) / dt;
            d[0][i] = v0;
            d[1][i] = a0;
            d[2][i] = j0;
        }
        out.push(d);
        history = [q2, q1, *p];
    }
    out
}

/// FLF components sampled along the path: (parameter, components), in parameter order.
fn flf_curve(profile: &Profile, param: &Parameter) -> Vec<(f64, FlfValue)> {
    let tp = profile.toolpath;
    let tip = tp.tip_dim();
    let n = tp.elements.len().max(1);
    let per = (FLF_SAMPLES / n).max(MIN_FLF_PER_ELEMENT);
    let mut out = Vec::new();
    for (c, element) in tp.elements.iter().enumerate() {
        // The planner lowers the feed cap to the element's programmed feed.
        let mut lim = profile.limits.clone();
        if let Some(f) = element.feed {
            lim.feed = lim.feed.min(f);
        }
        let view = element.curve.view();
        let (a, b) = (view.u_min(), view.u_max());
        let mut us: Vec<f64> = (0..=per).map(|k| a + (b - a) * k as f64 / per as f64).collect();
        // Critical points are narrow minima: sample them exactly.
        us.extend(
            profile
                .critical_points
                .iter()
                .filter(|(pc, _)| *pc == c)
                .map(|(_, p)| p.u),
        );
        us.sort_by(f64::total_cmp);
        out.extend(us.into_iter().map(|u| (param.at(c, u), flf(&view, tip, &lim, u))));
    }
    out
}

/// Splits a polyline into the runs that lie at or below `top`, cut exactly where it crosses
/// `top` (FLF components are unbounded on straight stretches).
fn clip_below(points: &[(f64, f64)], top: f64) -> Vec<Vec<(f64, f64)>> {
    let mut runs = Vec::new();
    let mut run: Vec<(f64, f64)> = Vec::new();
    let mut prev: Option<(f64, f64)> = None;
    for &(x, y) in points {
        let inside = y <= top;
        if let Some((px, py)) = prev {
            let was_inside = py <= top;
            if inside != was_inside {
                let cx = if y.is_finite() && py.is_finite() && y != py {
                    px + (x - px) * (top - py) / (y - py)
                } else if inside {
                    x
                } else {
                    px
                };
                run.push((cx, top));
                if !inside {
                    runs.push(std::mem::take(&mut run));
                }
            }
        }
        if inside {
            run.push((x, y));
        }
        prev = Some((x, y));
    }
    if run.len() > 1 {
        runs.push(run);
    }
    runs.retain(|r| r.len() > 1);
    runs
}

/// Columns a sampled curve is thinned to (about one per pixel of the plot width).
const COLUMNS: usize = 1500;

/// Thins a curve whose x never decreases to the first, lowest, highest and last point of each
/// of `COLUMNS` columns over `[x0, x1]`: every peak stays, and thousands of sub-pixel segments
/// do not smear a wide line.
fn decimate(points: impl Iterator<Item = (f64, f64)>, x0: f64, x1: f64) -> Vec<(f64, f64)> {
    let width = (x1 - x0).max(f64::MIN_POSITIVE);
    let column = |x: f64| ((x - x0) / width * COLUMNS as f64).floor().clamp(0.0, COLUMNS as f64) as usize;
    let mut out = Vec::new();
    let mut group: Vec<(f64, f64)> = Vec::new();
    let flush = |group: &mut Vec<(f64, f64)>, out: &mut Vec<(f64, f64)>| {
        if group.is_empty() {
            return;
        }
        let lo = (0..group.len())
            .min_by(|a, b| group[*a].1.total_cmp(&group[*b].1))
            .unwrap();
        let hi = (0..group.len())
            .max_by(|a, b| group[*a].1.total_cmp(&group[*b].1))
            .unwrap();
        let mut keep = [0, lo, hi, group.len() - 1];
        keep.sort_unstable();
        let mut last = usize::MAX;
        for k in keep {
            if k != last {
                out.push(group[k]);
                last = k;
            }
        }
        group.clear();
    };
    let mut current = usize::MAX;
    for (x, y) in points {
        let c = column(x);
        if c != current {
            flush(&mut group, &mut out);
            current = c;
        }
        group.push((x, y));
    }
    flush(&mut group, &mut out);
    out
}

/// Tick label: integers for large values, a few decimals for small ones.
fn tick(v: &f64) -> String {
    let a = v.abs();
    if a == 0.0 {
        "0".into()
    } else if a >= 100.0 {
        format!("{v:.0}")
    } else if a >= 1.0 {
        let s = format!("{v:.2}");
        s.trim_end_matches('0').trim_end_matches('.').to_string()
    } else {
        let s = format!("{v:.4}");
        s.trim_end_matches('0').trim_end_matches('.').to_string()
    }
}

fn axis_color(i: usize) -> RGBColor {
    const COLORS: [RGBColor; 6] = [
        RGBColor(31, 119, 180),
        RGBColor(214, 39, 40),
        RGBColor(44, 160, 44),
        RGBColor(148, 103, 189),
        RGBColor(140, 86, 75),
        RGBColor(23, 190, 207),
    ];
    COLORS[i % COLORS.len()]
}

/// Reads one FLF component.
type Component = fn(&FlfValue) -> f64;

const FEED_COLOR: RGBColor = RGBColor(31, 119, 180);
const CAP_FEED: RGBColor = RGBColor(110, 110, 110);
const CAP_CHORD: RGBColor = RGBColor(255, 127, 14);
const CAP_ACCEL: RGBColor = RGBColor(44, 160, 44);
const CAP_JERK: RGBColor = RGBColor(148, 103, 189);
const CRITICAL: RGBColor = RGBColor(128, 0, 128);
const LIMIT: RGBColor = RGBColor(0, 0, 0);

/// Draws `profile` and writes it as a PNG to `path`.
pub fn write_png(path: &Path, profile: &Profile) -> Result<(), PlotError> {
    plotters::style::register_font(FONT, FontStyle::Normal, FONT_BYTES)
        .map_err(|_| PlotError("the embedded plot font is not a valid font file".into()))?;
    let (w, h) = (WIDTH as usize, HEIGHT as usize);
    let mut buf = vec![255u8; w * h * 3];
    {
        let root = BitMapBackend::with_buffer(&mut buf, (WIDTH, HEIGHT)).into_drawing_area();
        draw(&root, profile)?;
        root.present().map_err(draw_err)?;
    }
    let mut png_bytes = Vec::new();
    {
        let mut enc = png::Encoder::new(&mut png_bytes, WIDTH, HEIGHT);
        enc.set_color(png::ColorType::Rgb);
        enc.set_depth(png::BitDepth::Eight);
        enc.set_compression(png::Compression::Best);
        let mut writer = enc
            .write_header()
            .map_err(|e| PlotError(format!("encoding the PNG failed: {e}")))?;
        writer
            .write_image_data(&buf)
            .map_err(|e| PlotError(format!("encoding the PNG failed: {e}")))?;
    }
    std::fs::write(path, &png_bytes).map_err(|e| PlotError(format!("cannot write plot {}: {e}", path.display())))
}

fn draw(root: &DrawingArea<BitMapBackend, Shift>, p: &Profile) -> Result<(), PlotError> {
    root.fill(&WHITE).map_err(draw_err)?;
    // The largest title font (24 px down to 12) that fits the width.
    let size = (12..=24)
        .rev()
        .find(|size| {
            root.estimate_text_size(&p.title, &TextStyle::from((FONT, *size as f64).into_font()))
                .is_ok_and(|(w, _)| w + 40 <= WIDTH)
        })
        .unwrap_or(12);
    let root = root
        .titled(&p.title, (FONT, size as f64).into_font())
        .map_err(draw_err)?;
    let panels = root.split_evenly((3, 1));
    let param = Parameter::new(p.toolpath);
    let xs: Vec<f64> = p.samples.iter().map(|s| param.at(s.curve, s.u)).collect();
    feed_panel(&panels[0], p, &param, &xs)?;
    // (b) and (c): axial accelerations and jerks with their limits.
    let axes = p.axes.len().min(MAX_AXES);
    let q: Vec<[f64; MAX_AXES]> = p.samples.iter().map(|s| s.q).collect();
    let diffs = axial_differences(&q, axes, p.limits.period);
    let panel = |order, caption, unit, limits| Axial {
        order,
        caption,
        unit,
        limits,
    };
    let accel = panel(1, "(b) axial accelerations", "acceleration", &p.limits.acceleration);
    let jerk = panel(2, "(c) axial jerks", "jerk", &p.limits.jerk);
    for axial in [accel, jerk] {
        axial_panel(&panels[axial.order], p, &param, &xs, &diffs, &axial)?;
    }
    Ok(())
}

/// Panel (a): the planned feedrate over the path parameter, with the feedrate limit function's
/// caps and the critical points.
fn feed_panel(
    panel: &DrawingArea<BitMapBackend, Shift>,
    p: &Profile,
    param: &Parameter,
    xs: &[f64],
) -> Result<(), PlotError> {
    let (x0, x1) = param.range();
    // (a) Feedrate and FLF.
    // Scaled to the planned feed (the caps run far above it on gentle stretches), with headroom
    // for the legend; the programmed feed line shows when it is within reach.
    let feed_max = p
        .samples
        .iter()
        .map(|s| s.feed)
        .chain(p.critical_points.iter().map(|(_, c)| c.flf))
        .fold(0.0, f64::max);
    let top = (feed_max * 1.8).min(p.limits.feed * 1.15);
    let top = if top > 0.0 { top } else { p.limits.feed };
    let caption = if !p.flf {
        "(a) feedrate (no feedrate limit function: the limits are joint limits)".to_string()
    } else if p.limits.feed > top {
        format!(
            "(a) feedrate and feedrate limit function (programmed feed {} mm/s is above the view)",
            tick(&p.limits.feed)
        )
    } else {
        "(a) feedrate and feedrate limit function".to_string()
    };
    let mut chart = ChartBuilder::on(panel)
        .caption(caption, (FONT, 24))
        .margin(12)
        .x_label_area_size(50)
        .y_label_area_size(90)
        .build_cartesian_2d(x0..x1, 0.0..top)
        .map_err(draw_err)?;
    mesh(&mut chart, param.label(), "feedrate [mm/s]")?;
    element_bounds(&mut chart, param, 0.0, top)?;
    if p.flf {
        let curve = flf_curve(p, param);
        let parts: [(&str, RGBColor, Component); 4] = [
            ("feed / axial velocity cap", CAP_FEED, |v| v.feed),
            ("chord error cap", CAP_CHORD, |v| v.chord),
            ("acceleration cap", CAP_ACCEL, |v| v.accel),
            ("jerk cap", CAP_JERK, |v| v.jerk),
        ];
        for (name, color, get) in parts {
            let pts: Vec<(f64, f64)> = curve.iter().map(|(x, v)| (*x, get(v))).collect();
            let style = color.stroke_width(2);
            let mut first = true;
            for run in clip_below(&pts, top) {
                let s = chart
                    .draw_series(DashedLineSeries::new(run, 10, 6, style))
                    .map_err(draw_err)?;
                if first {
                    s.label(name)
                        .legend(move |(x, y)| DashedPathElement::new(vec![(x, y), (x + 18, y)], 6, 4, style));
                    first = false;
                }
            }
        }
    }
    // A wide line drawn from sub-pixel segments comes out frayed: two 2-pixel lines half a
    // pixel above and below make a clean 3-pixel one.
    let feed = decimate(xs.iter().zip(p.samples).map(|(x, s)| (*x, s.feed)), x0, x1);
    let half_pixel = 0.5 * top / chart.plotting_area().dim_in_pixel().1.max(1) as f64;
    chart
        .draw_series(LineSeries::new(
            feed.iter().map(|(x, y)| (*x, y - half_pixel)),
            FEED_COLOR.stroke_width(2),
        ))
        .map_err(draw_err)?;
    chart
        .draw_series(LineSeries::new(
            feed.iter().map(|(x, y)| (*x, y + half_pixel)),
            FEED_COLOR.stroke_width(2),
        ))
        .map_err(draw_err)?
        .label("planned feedrate")
        .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 18, y)], FEED_COLOR.stroke_width(3)));
    if !p.critical_points.is_empty() {
        chart
            .draw_series(
                p.critical_points
                    .iter()
                    .map(|(c, cp)| Circle::new((param.at(*c, cp.u), cp.flf), 4, CRITICAL.filled())),
            )
            .map_err(draw_err)?
            .label("critical points (FLF minima)")
            .legend(|(x, y)| Circle::new((x + 9, y), 4, CRITICAL.filled()));
    }
    legend(&mut chart)?;

    Ok(())
}

/// What panel (b) or (c) shows: the axial finite differences of `order` (1 acceleration,
/// 2 jerk) and their limits.
struct Axial<'a> {
    order: usize,
    caption: &'a str,
    unit: &'a str,
    limits: &'a [f64],
}

/// Panel (b) or (c): the axial finite differences with their limits.
fn axial_panel(
    panel: &DrawingArea<BitMapBackend, Shift>,
    p: &Profile,
    param: &Parameter,
    xs: &[f64],
    diffs: &[[[f64; MAX_AXES]; 3]],
    what: &Axial,
) -> Result<(), PlotError> {
    let (d, caption, unit, lim) = (what.order, what.caption, what.unit, what.limits);
    let (x0, x1) = param.range();
    let axes = p.axes.len().min(MAX_AXES);
    // The three rest samples after the last setpoint sit at the end of the path.
    let x_of = |j: usize| xs.get(j).copied().or(xs.last().copied()).unwrap_or(x0);
    let peak = diffs
        .iter()
        .flat_map(|s| s[d][..axes].iter().map(|v| v.abs()))
        .fold(0.0, f64::max);
    let lim_max = lim[..axes].iter().copied().fold(0.0, f64::max);
    let y = lim_max.max(peak) * 1.3;
    let units = if d == 1 { "mm/s²" } else { "mm/s³" };
    let y_desc = if p.rotary_from < axes {
        format!("{unit} [{units}; rotary: deg/s{}]", if d == 1 { "²" } else { "³" })
    } else {
        format!("{unit} [{units}]")
    };
    let mut chart = ChartBuilder::on(panel)
        .caption(caption, (FONT, 24))
        .margin(12)
        .x_label_area_size(50)
        .y_label_area_size(90)
        .build_cartesian_2d(x0..x1, -y..y)
        .map_err(draw_err)?;
    mesh(&mut chart, param.label(), &y_desc)?;
    element_bounds(&mut chart, param, -y, y)?;
    for i in 0..axes {
        let color = axis_color(i);
        chart
            .draw_series(LineSeries::new(
                decimate(diffs.iter().enumerate().map(|(j, s)| (x_of(j), s[d][i])), x0, x1),
                color.stroke_width(if d == 1 { 2 } else { 1 }),
            ))
            .map_err(draw_err)?
            .label(p.axes[i].to_string())
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 18, y)], color.stroke_width(3)));
    }
    let same = lim[..axes].iter().all(|v| *v == lim[0]);
    let sym = if d == 1 { "A" } else { "J" };
    for i in 0..axes {
        if same && i > 0 {
            break;
        }
        let (color, name) = if same {
            (LIMIT, format!("±{sym} limit ({})", tick(&lim[0])))
        } else {
            (
                axis_color(i),
                format!("±{sym} limit, {} ({})", p.axes[i], tick(&lim[i])),
            )
        };
        let style = color.stroke_width(2);
        for (n, v) in [lim[i], -lim[i]].into_iter().enumerate() {
            let s = chart
                .draw_series(DashedLineSeries::new(vec![(x0, v), (x1, v)], 14, 6, style))
                .map_err(draw_err)?;
            if n == 0 {
                s.label(name.clone())
                    .legend(move |(x, y)| DashedPathElement::new(vec![(x, y), (x + 18, y)], 8, 4, style));
            }
        }
    }
    legend(&mut chart)?;
    Ok(())
}

type Chart<'a, 'b> = ChartContext<
    'a,
    BitMapBackend<'b>,
    Cartesian2d<plotters::coord::types::RangedCoordf64, plotters::coord::types::RangedCoordf64>,
>;

fn mesh(chart: &mut Chart, x_desc: &str, y_desc: &str) -> Result<(), PlotError> {
    chart
        .configure_mesh()
        .x_desc(x_desc)
        .y_desc(y_desc)
        .x_labels(12)
        .y_labels(8)
        .x_label_formatter(&tick)
        .y_label_formatter(&tick)
        .label_style((FONT, 18))
        .axis_desc_style((FONT, 20))
        .light_line_style(RGBColor(235, 235, 235))
        .bold_line_style(RGBColor(205, 205, 205))
        .draw()
        .map_err(draw_err)
}

/// Thin vertical lines where one path element ends and the next begins.
fn element_bounds(chart: &mut Chart, param: &Parameter, y0: f64, y1: f64) -> Result<(), PlotError> {
    if param.single() {
        return Ok(());
    }
    let n = param.spans.len();
    chart
        .draw_series((1..n).map(|k| PathElement::new(vec![(k as f64, y0), (k as f64, y1)], RGBColor(190, 190, 190))))
        .map_err(draw_err)?;
    Ok(())
}

fn legend<'a, 'b: 'a>(chart: &mut Chart<'a, 'b>) -> Result<(), PlotError> {
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::UpperRight)
        .label_font((FONT, 18))
        .background_style(WHITE.mix(0.9))
        .border_style(RGBColor(120, 120, 120))
        .draw()
        .map_err(draw_err)
}

#[cfg(test)]
mod tests {
    use super::*;
    use nurbs_motion::planner::axial::FiniteDifferences;

    #[test]
    fn differences_match_the_verify_check() {
        let limits = Limits::uniform(2, 100.0, 1e3, 1e5, 1e-3, 1e-3);
        let q: Vec<[f64; MAX_AXES]> = (0..50)
            .map(|j| {
                let t = j as f64 * 1e-3;
                [t * t * t * 7.0, (t * 30.0).sin() * 0.01, 0.0, 0.0, 0.0, 0.0]
            })
            .collect();
        let d = axial_differences(&q, 2, 1e-3);
        assert_eq!(d.len(), q.len() + 3);
        let mut fd = FiniteDifferences::new(2, 1e-3);
        let last = *q.last().unwrap();
        for (j, p) in q.iter().chain([last; 3].iter()).enumerate() {
            fd.reset_peaks();
            fd.push(p, &limits);
            for i in 0..2 {
                assert_eq!(fd.peaks.vel[i], d[j][0][i].abs());
                assert_eq!(fd.peaks.acc[i], d[j][1][i].abs());
                assert_eq!(fd.peaks.jerk[i], d[j][2][i].abs());
            }
        }
    }

    #[test]
    fn decimation_keeps_the_peaks() {
        let n = 100_000;
        let pts: Vec<(f64, f64)> = (0..n)
            .map(|k| (k as f64 / n as f64, if k == 4321 { 9.0 } else { (k as f64).sin() }))
            .collect();
        let d = decimate(pts.iter().copied(), 0.0, 1.0);
        assert!(d.len() <= 4 * COLUMNS && d.len() > COLUMNS);
        assert!(d.contains(&pts[4321]) && d.contains(&pts[0]) && d.contains(&pts[n - 1]));
        assert!(d.windows(2).all(|w| w[0].0 <= w[1].0));
    }

    #[test]
    fn clipping_cuts_at_the_top() {
        let pts = [(0.0, 1.0), (1.0, 3.0), (2.0, f64::INFINITY), (3.0, 1.0), (4.0, 0.5)];
        let runs = clip_below(&pts, 2.0);
        assert_eq!(runs.len(), 2);
        assert_eq!(runs[0], vec![(0.0, 1.0), (0.5, 2.0)]);
        assert_eq!(runs[1], vec![(3.0, 2.0), (3.0, 1.0), (4.0, 0.5)]);
    }
}
