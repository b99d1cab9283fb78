//! Toolpath file readers: JSON (the benchmark schema), LinuxCNC G-code and DXF.
//!
//! Every reader returns a [`Toolpath`] or a [`ReadError`] naming the file, the line and column
//! where the format has them, and what is wrong. Readers never panic on bad input.

pub mod dxf;
pub mod gcode;
pub mod json;

use crate::geometry::{PathElement, Toolpath};
use std::fmt;
use std::path::Path;

/// A toolpath file could not be read.
#[derive(Clone, Debug, PartialEq)]
pub struct ReadError {
    pub file: String,
    /// 1-based line, where the format has lines.
    pub line: Option<usize>,
    /// 1-based column, where known.
    pub column: Option<usize>,
    pub message: String,
}

impl ReadError {
    pub fn new(file: &str, message: impl Into<String>) -> Self {
        ReadError {
            file: file.to_string(),
            line: None,
            column: None,
            message: message.into(),
        }
    }
    pub fn at(file: &str, line: usize, column: Option<usize>, message: impl Into<String>) -> Self {
        ReadError {
            file: file.to_string(),
            line: Some(line),
            column,
            message: message.into(),
        }
    }
}

impl fmt::Display for ReadError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}", self.file)?;
        if let Some(line) = self.line {
            write!(f, ":{line}")?;
            if let Some(col) = self.column {
                write!(f, ":{col}")?;
            }
        }
        write!(f, ": {}", self.message)
    }
}

impl std::error::Error for ReadError {}

/// The file formats we read, chosen by extension.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Format {
    Json,
    Gcode,
    Dxf,
}

impl Format {
    pub fn from_path(path: &Path) -> Option<Format> {
        let ext = path.extension()?.to_str()?.to_ascii_lowercase();
        match ext.as_str() {
            "json" => Some(Format::Json),
            "ngc" | "nc" | "gcode" | "g" | "tap" | "cnc" => Some(Format::Gcode),
            "dxf" => Some(Format::Dxf),
            _ => None,
        }
    }
}

/// Largest coordinate a toolpath may have (mm): beyond any machine's travel, and where the
/// finite differences of positions at a servo period of 0.25 ms would lose the precision the
/// limit check needs (a third difference of positions near 1e9 mm rounds to some 1e4 mm/s^3).
pub const MAX_COORDINATE: f64 = 1e6;
/// Most control points of one path element: with its knots and weights, a curve of up to six
/// coordinates (tool tip and top) then fits the realtime channel's arena of 4,194,304 values
/// (checked by the planner crate's tests), so that any element read can stream to the machine.
pub const MAX_CONTROL_POINTS: usize = 500_000;

/// A toolpath's elements in path order, as a reader hands them out: G-code as it reads its
/// lines ([`gcode::GcodeStream`]), JSON and DXF once the whole file is read. An error ends it.
pub type ElementStream = Box<dyn Iterator<Item = Result<PathElement, ReadError>> + Send>;

/// Refuses an element that no machine or the planner's precision can take: coordinates beyond
/// [`MAX_COORDINATE`], more than [`MAX_CONTROL_POINTS`]; the error names the element's source
/// line, or its index `i` where the format has no lines.
pub fn check_element(name: &str, i: usize, e: &PathElement) -> Result<(), ReadError> {
    let at = |what: String| match e.source_line {
        Some(line) => ReadError::at(name, line, None, format!("the path element that starts here: {what}")),
        None => ReadError::new(name, format!("path element {i}: {what}")),
    };
    let c = &e.curve;
    let points = c.points().len() / c.dim().max(1);
    if points > MAX_CONTROL_POINTS {
        return Err(at(format!(
            "{points} control points: more than {MAX_CONTROL_POINTS} in one element"
        )));
    }
    if let Some(x) = c.points().iter().find(|x| x.abs() > MAX_COORDINATE) {
        return Err(at(format!(
            "coordinate {x} mm is beyond {MAX_COORDINATE} mm: no machine's travel, and the servo-period check would lose its precision"
        )));
    }
    Ok(())
}

/// [`check_element`] on every element of a whole toolpath.
pub fn check_sizes(name: &str, toolpath: &Toolpath) -> Result<(), ReadError> {
    toolpath
        .elements
        .iter()
        .enumerate()
        .try_for_each(|(i, e)| check_element(name, i, e))
}

/// Opens a toolpath as a stream of elements, choosing the reader by file extension; each
/// element is checked ([`check_element`]) as it comes.
pub fn open_toolpath(path: &Path) -> Result<ElementStream, ReadError> {
    let name = path.display().to_string();
    let format = Format::from_path(path)
        .ok_or_else(|| ReadError::new(&name, "unknown file type: expected .json, .ngc/.nc/.gcode/.tap or .dxf"))?;
    let elements: ElementStream = match format {
        Format::Gcode => {
            use std::io::BufRead;
            let file = std::fs::File::open(path).map_err(|e| ReadError::new(&name, e.to_string()))?;
            Box::new(gcode::GcodeStream::new(&name, std::io::BufReader::new(file).lines()))
        }
        Format::Json | Format::Dxf => {
            let toolpath = match format {
                Format::Json => {
                    let text = std::fs::read_to_string(path).map_err(|e| ReadError::new(&name, e.to_string()))?;
                    json::parse(&name, &text)?
                }
                _ => {
                    let bytes = std::fs::read(path).map_err(|e| ReadError::new(&name, e.to_string()))?;
                    dxf::parse(&name, &bytes)?
                }
            };
            // A G-code path decides its dimension once; a file read whole says it here.
            let tip = toolpath.tip_dim();
            if let Some(i) = toolpath.elements.iter().position(|e| e.curve.tip_dim() != tip) {
                return Err(ReadError::new(
                    &name,
                    format!(
                        "path element {i} is {}-D in a {tip}-D path",
                        toolpath.elements[i].curve.tip_dim()
                    ),
                ));
            }
            Box::new(toolpath.elements.into_iter().map(Ok))
        }
    };
    let mut index = 0;
    Ok(Box::new(elements.map(move |e| {
        let e = e?;
        check_element(&name, index, &e)?;
        index += 1;
        Ok(e)
    })))
}

/// Reads a whole toolpath ([`open_toolpath`], collected).
pub fn read_toolpath(path: &Path) -> Result<Toolpath, ReadError> {
    let elements = open_toolpath(path)?.collect::<Result<Vec<_>, _>>()?;
    Ok(Toolpath { elements })
}
