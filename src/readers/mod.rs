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

/// Reads a toolpath, choosing the reader by file extension.
pub fn read_toolpath(path: &Path) -> Result<Toolpath, ReadError> {
    let name = path.display().to_string();
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
