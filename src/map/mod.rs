//! Error maps: one fitted part (grid + model), family aggregation, and the map file formats.

use crate::error::Result;
use crate::geom::ErrorField;
use std::path::Path;

/// Load a fitted map (`model.json`) as an error field for toolpath compensation.
pub fn load_error_field(model_json: &Path) -> Result<Box<dyn ErrorField>> {
    Err(crate::Error::Internal(format!(
        "loading {} is not built yet",
        model_json.display()
    )))
}
