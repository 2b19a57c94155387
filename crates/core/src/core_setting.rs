//! The settings of this crate that its hints name; the front end words them (the binary as
//! its flags). A setting several crates' hints name lives in the lowest crate that has it.

/// A setting of the ground floor (output safety) that a hint can tell the user to give.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Setting {
    /// The largest file one output may grow to, MB.
    MaxOutputMb,
}

impl crate::Setting for Setting {
    fn key(self) -> &'static str {
        match self {
            Setting::MaxOutputMb => "max_output_mb",
        }
    }
}
