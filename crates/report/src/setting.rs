//! The report settings that hints name; the front end words them (the binary as its flags).

/// A setting of report writing that a hint can tell the user to give.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Setting {
    /// Print the HTML report to PDF beside it.
    Pdf,
}

impl errmap_core::Setting for Setting {
    fn key(self) -> &'static str {
        match self {
            Setting::Pdf => "pdf",
        }
    }
}
