//! The toolpath settings that hints name; the front end words them (the binary as its flags).

/// A setting of toolpath compensation that a hint can tell the user to give.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Setting {
    /// The program's units when it sets none (`mm` or `inch`).
    Units,
}

impl errmap_core::Setting for Setting {
    fn key(self) -> &'static str {
        match self {
            Setting::Units => "units",
        }
    }
}
