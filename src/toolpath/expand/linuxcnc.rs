//! LinuxCNC O-word control flow run into plain blocks (not yet: programs are left to the ordinary rewrite).

use super::Flat;
use crate::error::Result;
use std::path::Path;

pub(super) fn flatten(_text: &str, _source: &Path) -> Result<Option<Flat>> {
    Ok(None)
}
