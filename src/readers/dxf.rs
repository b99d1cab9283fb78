//! DXF drawings to a [`Toolpath`] (read with the `dxf` crate).
//!
//! * **Entities**, in file order (the ENTITIES section; geometry inside blocks referenced by
//!   `INSERT` is not expanded and an `INSERT` is an error):
//!   - `SPLINE`: degree (1..=7), knots, weights (all 1 when absent) and control points, as one
//!     [`ElementKind::Nurbs`] element. The stored data define the curve in the standard way on
//!     `[knots[p], knots[n + 1]]`, whatever the closed/periodic flags say. An unclamped knot vector
//!     (as periodic splines are stored) is clamped exactly by knot insertion (Boehm's algorithm
//!     in homogeneous coordinates), so the geometry is unchanged. A spline given only by fit
//!     points, a knot count other than control points + degree + 1, non-monotone knots,
//!     non-finite values or weights ≤ 0 are errors naming the entity.
//!   - `LINE`: consecutive `LINE`s become one [`ElementKind::Polyline`] while each starts where
//!     the previous one ended (within 1e-9 mm); otherwise a new element starts.
//!   - `LWPOLYLINE`: straight runs become polylines; segments with a bulge become exact
//!     [`ElementKind::Arc`] elements (included angle `4·atan(bulge)`, counter-clockwise when
//!     positive); a closed polyline gets its closing segment.
//!   - `ARC` and `CIRCLE` (counter-clockwise, circle from angle 0) become exact arcs.
//!   - Annotation (`TEXT`, `MTEXT`, `DIMENSION`, `POINT`, `HATCH`, `LEADER`, …) is ignored; any
//!     other entity type is an error, so no geometry is silently dropped.
//!   - Entities whose extrusion direction is not +Z (object coordinate systems) are errors.
//! * **Dimension**: the toolpath is 3-D if any used coordinate has a non-zero Z (spline control
//!   points, line end points, polyline/arc elevation); otherwise all elements are 2-D (X Y).
//! * **Units**: `$INSUNITS` is honoured (inches, feet, cm, m, µm, …); unitless drawings are
//!   taken as mm.
//! * Elements are neither reordered nor joined across gaps (only LINE chaining above): whether
//!   the elements form one continuous path is left to the consumer.
//! * Polylines are parameterised by chord length (mm), arcs by arc length at the piece ends, and
//!   splines keep their own knots (after clamping).

use super::gcode::{arc_geometry, arc_nurbs, polyline_nurbs};
use super::ReadError;
use crate::geometry::{ElementKind, Nurbs, PathElement, Toolpath};
use dxf::entities::{Entity, EntityType, Spline};
use dxf::enums::Units;
use std::f64::consts::TAU;

/// Gap below which consecutive LINE entities are chained (mm).
const CHAIN_TOL_MM: f64 = 1e-9;

/// An element before the 2-D/3-D decision: points carry Z.
enum Raw {
    Poly {
        points: Vec<[f64; 3]>,
    },
    Arc {
        start: [f64; 2],
        end: [f64; 2],
        center: [f64; 2],
        ccw: bool,
        full: bool,
        z: f64,
    },
    Spline {
        degree: usize,
        knots: Vec<f64>,
        points: Vec<[f64; 3]>,
        weights: Vec<f64>,
    },
}

fn scale_of(file: &str, units: Units) -> Result<f64, ReadError> {
    Ok(match units {
        Units::Unitless | Units::Millimeters => 1.0,
        Units::Inches | Units::USSurveyInch => 25.4,
        Units::Feet => 304.8,
        Units::Centimeters => 10.0,
        Units::Meters => 1000.0,
        Units::Microns => 0.001,
        Units::Decimeters => 100.0,
        Units::Mils => 0.0254,
        Units::Microinches => 25.4e-6,
        other => {
            return Err(ReadError::new(
                file,
                format!("unsupported drawing units $INSUNITS = {other:?}"),
            ))
        }
    })
}

fn describe(e: &Entity, index: usize) -> String {
    let kind = match &e.specific {
        EntityType::Spline(_) => "SPLINE",
        EntityType::Line(_) => "LINE",
        EntityType::LwPolyline(_) => "LWPOLYLINE",
        EntityType::Arc(_) => "ARC",
        EntityType::Circle(_) => "CIRCLE",
        _ => "entity",
    };
    format!("{kind} #{} (handle {:X})", index + 1, e.common.handle.0)
}

fn finite(file: &str, what: &str, values: &[f64]) -> Result<(), ReadError> {
    if values.iter().all(|v| v.is_finite()) {
        Ok(())
    } else {
        Err(ReadError::new(file, format!("{what}: a coordinate is NaN or infinite")))
    }
}

fn check_normal(file: &str, what: &str, n: &dxf::Vector) -> Result<(), ReadError> {
    if n.x == 0.0 && n.y == 0.0 && n.z > 0.0 {
        Ok(())
    } else {
        Err(ReadError::new(
            file,
            format!(
                "{what}: extrusion direction ({}, {}, {}) is not +Z; only the XY plane is supported",
                n.x, n.y, n.z
            ),
        ))
    }
}

/// Parses a DXF file (ASCII or binary) into a toolpath.
pub fn parse(file: &str, bytes: &[u8]) -> Result<Toolpath, ReadError> {
    if bytes.iter().all(|b| b.is_ascii_whitespace()) {
        return Err(ReadError::new(file, "file is empty"));
    }
    // The dxf crate panics on some malformed values (a date variable of the header out of
    // range, for one), even in parts of the file this reader does not use.
    let drawing = crate::panics::catch(|| dxf::Drawing::load(&mut std::io::Cursor::new(bytes)))
        .map_err(|panic| ReadError::new(file, format!("invalid DXF: the DXF library failed on it ({panic})")))?
        .map_err(|e| ReadError::new(file, format!("invalid DXF: {e}")))?;
    let s = scale_of(file, drawing.header.default_drawing_units)?;
    let mut raws: Vec<(String, Raw)> = Vec::new();
    for (index, e) in drawing.entities().enumerate() {
        read_entity(file, e, index, s, &mut raws)?;
    }
    if raws.is_empty() {
        return Err(ReadError::new(
            file,
            "the drawing contains no SPLINE, LINE, LWPOLYLINE, ARC or CIRCLE entities",
        ));
    }
    Ok(Toolpath {
        elements: to_elements(file, raws)?,
    })
}

/// Appends the path pieces of entity `e` (number `index`, coordinates scaled by `s` to mm) to
/// `raws`; entities that carry no path (text, dimensions, images, ...) add nothing.
fn read_entity(file: &str, e: &Entity, index: usize, s: f64, raws: &mut Vec<(String, Raw)>) -> Result<(), ReadError> {
    let what = describe(e, index);
    match &e.specific {
        EntityType::Spline(sp) => raws.push((what.clone(), spline(file, &what, sp, s)?)),
        EntityType::Line(l) => line(file, what, l, s, raws)?,
        EntityType::LwPolyline(p) => lw_polyline(file, what, p, e.common.elevation * s, s, raws)?,
        EntityType::Arc(a) => raws.push((what.clone(), arc(file, &what, a, s)?)),
        EntityType::Circle(c) => raws.push((what.clone(), circle(file, &what, c, s)?)),
        EntityType::Text(_)
        | EntityType::MText(_)
        | EntityType::RotatedDimension(_)
        | EntityType::RadialDimension(_)
        | EntityType::DiameterDimension(_)
        | EntityType::AngularThreePointDimension(_)
        | EntityType::OrdinateDimension(_)
        | EntityType::ModelPoint(_)
        | EntityType::Leader(_)
        | EntityType::ArcAlignedText(_)
        | EntityType::RText(_)
        | EntityType::Tolerance(_)
        | EntityType::Attribute(_)
        | EntityType::AttributeDefinition(_)
        | EntityType::Light(_)
        | EntityType::OleFrame(_)
        | EntityType::Ole2Frame(_)
        | EntityType::DgnUnderlay(_)
        | EntityType::DwfUnderlay(_)
        | EntityType::PdfUnderlay(_)
        | EntityType::Image(_)
        | EntityType::Wipeout(_) => {}
        other => {
            let name = format!("{other:?}");
            let name = name.split(['(', ' ', '{']).next().unwrap_or("entity").to_string();
            return Err(ReadError::new(
                file,
                format!(
                    "entity #{} (handle {:X}) of type {name} is not supported (SPLINE, LINE, LWPOLYLINE, ARC, CIRCLE are)",
                    index + 1,
                    e.common.handle.0
                ),
            ));
        }
    }
    Ok(())
}

/// A LINE: joined to the previous LINE's polyline when it starts where that one ends.
fn line(
    file: &str,
    what: String,
    l: &dxf::entities::Line,
    s: f64,
    raws: &mut Vec<(String, Raw)>,
) -> Result<(), ReadError> {
    check_normal(file, &what, &l.extrusion_direction)?;
    let a = [l.p1.x * s, l.p1.y * s, l.p1.z * s];
    let b = [l.p2.x * s, l.p2.y * s, l.p2.z * s];
    finite(file, &what, &[a[0], a[1], a[2], b[0], b[1], b[2]])?;
    if a == b {
        return Ok(());
    }
    if let Some((_, Raw::Poly { points })) = raws.last_mut().filter(|(w, _)| w.starts_with("LINE")) {
        let last = *points.last().expect("polylines have points");
        if dist(&last, &a) <= CHAIN_TOL_MM {
            points.push(b);
            return Ok(());
        }
    }
    raws.push((what, Raw::Poly { points: vec![a, b] }));
    Ok(())
}

/// An LWPOLYLINE at height `z`: its straight runs as polylines, its bulged vertices as arcs.
fn lw_polyline(
    file: &str,
    what: String,
    p: &dxf::entities::LwPolyline,
    z: f64,
    s: f64,
    raws: &mut Vec<(String, Raw)>,
) -> Result<(), ReadError> {
    check_normal(file, &what, &p.extrusion_direction)?;
    let mut verts: Vec<([f64; 2], f64)> = p.vertices.iter().map(|v| ([v.x * s, v.y * s], v.bulge)).collect();
    for (v, b) in &verts {
        finite(file, &what, &[v[0], v[1], *b, z])?;
    }
    if p.is_closed() && verts.len() > 1 {
        let first = verts[0];
        verts.push((first.0, 0.0));
    }
    if verts.len() < 2 {
        return Err(ReadError::new(file, format!("{what}: fewer than two vertices")));
    }
    let mut run: Vec<[f64; 3]> = Vec::new();
    for w in verts.windows(2) {
        let ((a, bulge), (b, _)) = (w[0], w[1]);
        if a == b {
            continue;
        }
        if bulge == 0.0 {
            if run.is_empty() {
                run.push([a[0], a[1], z]);
            }
            run.push([b[0], b[1], z]);
            continue;
        }
        if run.len() > 1 {
            raws.push((
                what.clone(),
                Raw::Poly {
                    points: std::mem::take(&mut run),
                },
            ));
        }
        run.clear();
        raws.push((what.clone(), bulge_arc(a, b, bulge, z)));
    }
    if run.len() > 1 {
        raws.push((what, Raw::Poly { points: run }));
    }
    Ok(())
}

/// The arc from `a` to `b` of a polyline vertex with `bulge` (tan of a quarter of its sweep).
fn bulge_arc(a: [f64; 2], b: [f64; 2], bulge: f64, z: f64) -> Raw {
    let theta = 4.0 * bulge.atan();
    let c = ((b[0] - a[0]).powi(2) + (b[1] - a[1]).powi(2)).sqrt();
    let n = [-(b[1] - a[1]) / c, (b[0] - a[0]) / c];
    let d = (c / 2.0) / (theta / 2.0).tan();
    let center = [(a[0] + b[0]) / 2.0 + n[0] * d, (a[1] + b[1]) / 2.0 + n[1] * d];
    Raw::Arc {
        start: a,
        end: b,
        center,
        ccw: bulge > 0.0,
        full: false,
        z,
    }
}

/// An ARC entity (counter-clockwise from its start angle to its end angle, in degrees).
fn arc(file: &str, what: &str, a: &dxf::entities::Arc, s: f64) -> Result<Raw, ReadError> {
    check_normal(file, what, &a.normal)?;
    let (c, r) = ([a.center.x * s, a.center.y * s], a.radius * s);
    finite(file, what, &[c[0], c[1], r, a.start_angle, a.end_angle, a.center.z])?;
    if r <= 0.0 {
        return Err(ReadError::new(file, format!("{what}: radius {r} must be > 0")));
    }
    let (t0, t1) = (a.start_angle.to_radians(), a.end_angle.to_radians());
    let full = (t1 - t0).rem_euclid(TAU) == 0.0;
    let p = |t: f64| [c[0] + r * t.cos(), c[1] + r * t.sin()];
    Ok(Raw::Arc {
        start: p(t0),
        end: p(t1),
        center: c,
        ccw: true,
        full,
        z: a.center.z * s,
    })
}

/// A CIRCLE: a full counter-clockwise arc from its rightmost point.
fn circle(file: &str, what: &str, a: &dxf::entities::Circle, s: f64) -> Result<Raw, ReadError> {
    check_normal(file, what, &a.normal)?;
    let (c, r) = ([a.center.x * s, a.center.y * s], a.radius * s);
    finite(file, what, &[c[0], c[1], r, a.center.z])?;
    if r <= 0.0 {
        return Err(ReadError::new(file, format!("{what}: radius {r} must be > 0")));
    }
    let p = [c[0] + r, c[1]];
    Ok(Raw::Arc {
        start: p,
        end: p,
        center: c,
        ccw: true,
        full: true,
        z: a.center.z * s,
    })
}

/// The path elements of the pieces read, in order; 2-D unless a piece leaves Z = 0.
fn to_elements(file: &str, raws: Vec<(String, Raw)>) -> Result<Vec<PathElement>, ReadError> {
    let three_d = raws.iter().any(|(_, r)| match r {
        Raw::Poly { points } | Raw::Spline { points, .. } => points.iter().any(|p| p[2] != 0.0),
        Raw::Arc { z, .. } => *z != 0.0,
    });
    let coords = |p: &[f64; 3]| {
        if three_d {
            p.to_vec()
        } else {
            vec![p[0], p[1]]
        }
    };
    let mut elements = Vec::new();
    for (what, raw) in raws {
        let bad = |e: nurbs_rtcore::GeometryError| ReadError::new(file, format!("{what}: invalid curve: {e}"));
        let (kind, curve) = match raw {
            Raw::Poly { points } => {
                let pts: Vec<Vec<f64>> = points.iter().map(coords).collect();
                (ElementKind::Polyline, polyline_nurbs(&pts).map_err(bad)?)
            }
            Raw::Arc {
                start,
                end,
                center,
                ccw,
                full,
                z,
            } => {
                let (mut geom, _) = arc_geometry(start, end, center, ccw, 1)
                    .map_err(|_| ReadError::new(file, format!("{what}: degenerate arc")))?;
                if full {
                    geom.end = geom.start;
                    geom.sweep = if ccw { TAU } else { -TAU };
                }
                (ElementKind::Arc, arc_nurbs(&geom, three_d.then_some(z)).map_err(bad)?)
            }
            Raw::Spline {
                degree,
                knots,
                points,
                weights,
            } => {
                let pts: Vec<Vec<f64>> = points.iter().map(coords).collect();
                (
                    ElementKind::Nurbs,
                    Nurbs::new(degree, knots, &pts, Some(weights)).map_err(bad)?,
                )
            }
        };
        elements.push(PathElement {
            kind,
            curve,
            feed: None,
            source_line: None,
        });
    }
    Ok(elements)
}

fn dist(a: &[f64; 3], b: &[f64; 3]) -> f64 {
    ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
}

fn spline(file: &str, what: &str, sp: &Spline, s: f64) -> Result<Raw, ReadError> {
    let fail = |msg: String| ReadError::new(file, format!("{what}: {msg}"));
    check_normal(file, what, &sp.normal).or_else(|e| {
        // Splines are 3-D curves in WCS; the normal only matters for planar splines. Accept any
        // normal for non-planar ones.
        if sp.is_planar() {
            Err(e)
        } else {
            Ok(())
        }
    })?;
    let n = sp.control_points.len();
    if n == 0 {
        return Err(fail(if sp.fit_points.is_empty() {
            "no control points".into()
        } else {
            "defined by fit points only; only control-point splines are supported".into()
        }));
    }
    let degree = usize::try_from(sp.degree_of_curve).unwrap_or(0);
    if !(1..=nurbs_rtcore::MAX_DEGREE).contains(&degree) {
        return Err(fail(format!(
            "degree {} is outside 1..={}",
            sp.degree_of_curve,
            nurbs_rtcore::MAX_DEGREE
        )));
    }
    if n < degree + 1 {
        return Err(fail(format!(
            "{n} control points for degree {degree}; at least {} are needed",
            degree + 1
        )));
    }
    let knots = sp.knot_values.clone();
    if knots.len() != n + degree + 1 {
        let periodic = if sp.is_periodic() || sp.is_closed() {
            " (closed/periodic spline stored in an unsupported way)"
        } else {
            ""
        };
        return Err(fail(format!(
            "{} knots for {n} control points of degree {degree}; expected {}{periodic}",
            knots.len(),
            n + degree + 1
        )));
    }
    if let Some(i) = knots.iter().position(|k| !k.is_finite()) {
        return Err(fail(format!("knot {i} is not finite")));
    }
    if let Some(i) = (1..knots.len()).find(|&i| knots[i] < knots[i - 1]) {
        return Err(fail(format!(
            "knots are not non-decreasing at index {i} ({} < {})",
            knots[i],
            knots[i - 1]
        )));
    }
    if knots[degree] >= knots[n] {
        return Err(fail("the knot vector's parameter domain is empty".into()));
    }
    let weights = if sp.weight_values.is_empty() {
        vec![1.0; n]
    } else if sp.weight_values.len() == n {
        sp.weight_values.clone()
    } else {
        return Err(fail(format!(
            "{} weights for {n} control points",
            sp.weight_values.len()
        )));
    };
    if let Some((i, w)) = weights.iter().enumerate().find(|(_, w)| !(w.is_finite() && **w > 0.0)) {
        return Err(fail(format!("weight {i} is {w}; weights must be finite and > 0")));
    }
    let points: Vec<[f64; 3]> = sp.control_points.iter().map(|p| [p.x * s, p.y * s, p.z * s]).collect();
    if points.iter().flatten().any(|v| !v.is_finite()) {
        return Err(fail("a control point coordinate is NaN or infinite".into()));
    }
    let clamped = knots[..=degree].iter().all(|&k| k == knots[0]) && knots[n..].iter().all(|&k| k == knots[n]);
    if clamped {
        return Ok(Raw::Spline {
            degree,
            knots,
            points,
            weights,
        });
    }
    // Clamp both ends exactly (no-op for clamped splines).
    let mut hw: Vec<[f64; 4]> = points
        .iter()
        .zip(&weights)
        .map(|(p, w)| [p[0] * w, p[1] * w, p[2] * w, *w])
        .collect();
    let mut knots = knots;
    clamp_start(degree, &mut knots, &mut hw);
    // Reverse (negating the knots, which is exact), clamp the start, reverse back.
    let mut rk: Vec<f64> = knots.iter().rev().map(|k| -k).collect();
    hw.reverse();
    clamp_start(degree, &mut rk, &mut hw);
    hw.reverse();
    let knots: Vec<f64> = rk.iter().rev().map(|k| -k).collect();
    let points = hw.iter().map(|h| [h[0] / h[3], h[1] / h[3], h[2] / h[3]]).collect();
    let weights = hw.iter().map(|h| h[3]).collect();
    Ok(Raw::Spline {
        degree,
        knots,
        points,
        weights,
    })
}

/// Makes the first `degree + 1` knots equal to `knots[degree]` by inserting that knot (Boehm,
/// Piegl & Tiller A5.1 with r = 1) and dropping the control points that no longer act.
fn clamp_start(p: usize, knots: &mut Vec<f64>, hw: &mut Vec<[f64; 4]>) {
    let a = knots[p];
    if knots[..=p].iter().all(|&k| k == a) {
        return;
    }
    loop {
        let mult = knots.iter().filter(|&&k| k == a).count();
        if mult >= p {
            break;
        }
        // Span k with knots[k] <= a < knots[k + 1].
        let k = (0..knots.len() - 1)
            .rfind(|&i| knots[i] <= a && a < knots[i + 1])
            .expect("a is inside the domain");
        let mut q = Vec::with_capacity(hw.len() + 1);
        for i in 0..=hw.len() {
            if i + p <= k {
                q.push(hw[i]);
            } else if i > k {
                q.push(hw[i - 1]);
            } else {
                let alpha = (a - knots[i]) / (knots[i + p] - knots[i]);
                let mut h = [0.0; 4];
                for (c, hc) in h.iter_mut().enumerate() {
                    *hc = alpha * hw[i][c] + (1.0 - alpha) * hw[i - 1][c];
                }
                q.push(h);
            }
        }
        knots.insert(k + 1, a);
        *hw = q;
    }
    let first = knots.iter().position(|&k| k == a).expect("inserted");
    // C(a) = Q[first - 1]; earlier control points and knots no longer act on [a, ...).
    let drop = first.saturating_sub(1);
    hw.drain(..drop);
    knots.drain(..first);
    knots.insert(0, a);
}
