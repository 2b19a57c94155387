//! The stages of a family's pipeline, each with its own input and output type: read and clean ([`read`]: `PartInput` → `Prepared`) → training-grid values ([`nodes`]: → `Interpolated`) → train ([`train`]: → `Networks`) → evaluate and write each part ([`evaluate`], [`part_files`]: → `PartSummary` and the part's map) → family reduce ([`family`]: running sums → the family folder) → summary ([`summary`]: → `BatchSummary`) → report ([`report`]: summary and manifest → `report.html`).
//!
//! A run (`crate::run`) drives them chunk by chunk; the reduce of shards and of a resumed run
//! (`crate::reduce`) uses the family, toolpath and report stages on the parts' records. Neither
//! calls into the other.

pub(crate) mod draw;
pub(crate) mod evaluate;
pub(crate) mod family;
pub(crate) mod nodes;
pub(crate) mod part_files;
pub(crate) mod read;
pub(crate) mod report;
pub(crate) mod summary;
pub(crate) mod toolpaths;
pub(crate) mod train;
