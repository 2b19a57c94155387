//! The map settings that hints name; the front end words them (the binary as its flags).

/// A setting of probe reading, map fitting or training that a hint can tell the user to give.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Setting {
    /// Where networks train: `auto`, `cpu`, `cpu-reference` or `gpu`.
    Backend,
    /// The mapping of a probe file's columns to x, y, z (and normals, nominals, ids).
    Columns,
    /// The 1-based line of a probe file's header.
    HeaderLine,
    /// The nominal position of the surface along the map's normal, mm.
    NominalPlane,
    /// The map's normal axis, the direction of its error.
    Normal,
    /// The plausibility bound on a point's deviation from nominal, mm.
    MaxDeviation,
    /// The bound on a node's u(E) beyond which a map leaves it nominal, µm.
    MaxUncertainty,
    /// The bound on the memory one probe file may take, MB.
    MaxMemory,
    /// The training bench's number of parts (networks).
    BenchParts,
    /// The training bench's samples per network.
    BenchSamples,
}

impl errmap_core::Setting for Setting {
    fn key(self) -> &'static str {
        match self {
            Setting::Backend => "backend",
            Setting::Columns => "columns",
            Setting::HeaderLine => "header_line",
            Setting::NominalPlane => "nominal_plane_mm",
            Setting::Normal => "normal",
            Setting::MaxDeviation => "max_deviation_mm",
            Setting::MaxUncertainty => "max_uncertainty_um",
            Setting::MaxMemory => "max_memory_mb",
            Setting::BenchParts => "parts",
            Setting::BenchSamples => "samples",
        }
    }
}
