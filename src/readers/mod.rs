//! Toolpath file readers: JSON (the benchmark schema), LinuxCNC G-code and DXF.
//!
//! Every reader returns a [`Toolpath`] or a [`ReadError`] naming the file, the line and column
//! where the format has them, and what is wrong. Readers never panic on bad input.

pub mod dxf;
pub mod gcode;
pub mod json;

use crate::geometry::Toolpath;
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
/// Most control points of one path element: more than the channel's arena carries.
pub const MAX_CONTROL_POINTS: usize = 1_000_000;
/// Most path elements of one toolpath (it is held in memory whole: some 300 bytes each).
pub const MAX_ELEMENTS: usize = 20_000_000;

/// Refuses a toolpath that no machine or the planner's precision can take: coordinates beyond
/// [`MAX_COORDINATE`], an element of more than [`MAX_CONTROL_POINTS`], more than
/// [`MAX_ELEMENTS`] elements. Each with the element (and source line) it found first.
pub fn check_sizes(name: &str, toolpath: &Toolpath) -> Result<(), ReadError> {
    if toolpath.elements.len() > MAX_ELEMENTS {
        return Err(ReadError::new(
            name,
            format!(
                "{} path elements: more than {MAX_ELEMENTS} in one toolpath",
                toolpath.elements.len()
            ),
        ));
    }
    for (i, e) in toolpath.elements.iter().enumerate() {
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
    }
    Ok(())
}

/// Reads a toolpath, choosing the reader by file extension, and checks its sizes
/// ([`check_sizes`]).
pub fn read_toolpath(path: &Path) -> Result<Toolpath, ReadError> {
    let name = path.display().to_string();
    let toolpath = read_as_format(&name, path)?;
    check_sizes(&name, &toolpath)?;
    Ok(toolpath)
}

fn read_as_format(name: &str, path: &Path) -> Result<Toolpath, ReadError> {
    let name = name.to_owned();
    let format = Format::from_path(path)
        .ok_or_else(|| ReadError::new(&name, "unknown file type: expected .json, .ngc/.nc/.gcode/.tap or .dxf"))?;
    match format {
        Format::Json => {
            let text = std::fs::read_to_string(path).map_err(|e| ReadError::new(&name, e.to_string()))?;
            json::parse(&name, &text)
        }
        Format::Gcode => {
            let text = std::fs::read_to_string(path).map_err(|e| ReadError::new(&name, e.to_string()))?;
            gcode::parse(&name, &text)
        }
        Format::Dxf => {
            let bytes = std::fs::read(path).map_err(|e| ReadError::new(&name, e.to_string()))?;
            dxf::parse(&name, &bytes)
        }
    }
}
