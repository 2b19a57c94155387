//! Shared numerics: linear least squares with its conditioning, and the number formatting of written files.

pub mod format;
pub mod lsq;
