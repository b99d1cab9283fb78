//! placeholder
use super::ReadError;
use crate::geometry::Toolpath;
pub fn parse(file: &str, _bytes: &[u8]) -> Result<Toolpath, ReadError> { Err(ReadError::new(file, "DXF reader not built yet")) }
