//! Stand-in for contract C (`errmap::toolpath`) until the toolpath branch lands: same names and signatures.

use crate::error::{Error, Result};
use crate::geom::ErrorField;
use std::path::Path;

#[derive(Debug, Clone, PartialEq)]
pub struct CompensationSettings {
    pub zone: Option<(f64, f64)>,
    pub max_segment: f64,
    pub chord_tol: f64,
}

#[derive(Debug, Clone, Default, serde::Serialize)]
pub struct CompensationReport {
    pub moves_changed: u64,
    pub moves_split: u64,
    pub max_abs_error_mm: f64,
}

pub fn compensate_file(
    input: &Path,
    _output: &Path,
    _field: &dyn ErrorField,
    _settings: &CompensationSettings,
) -> Result<CompensationReport> {
    Err(Error::Internal(format!(
        "cannot compensate {}: toolpath compensation is not in this build",
        input.display()
    )))
}
