//! placeholder
use super::ReadError;
use crate::geometry::Toolpath;
pub fn parse(file: &str, _text: &str) -> Result<Toolpath, ReadError> { Err(ReadError::new(file, "G-code reader not built yet")) }
