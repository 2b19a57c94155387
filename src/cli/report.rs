//! CLI of `errmap report`: the self-contained `report.html` of a batch run or of an analysis's outputs, and its PDF.

use super::exit::Result;
use super::Globals;
use errmap::batch::manifest::{sha256_bytes, RunManifest};
use errmap::batch::{folder_report::render_path, run_page::REPORT_FILE};
use errmap::report::pdf::print_pdf;
use errmap::Diagnostic;
use std::path::{Path, PathBuf};

#[derive(Debug, clap::Args)]
pub struct ReportArgs {
    /// A batch's output folder, or the folder (or result .json) where `linear analyze --chart`,
    /// `thermal difference`, `thermal evaluate`, `rotary analyze --chart` or `circular -o` wrote.
    pub source: PathBuf,
    /// The HTML file to write; default: report.html in the folder (NAME.html beside a result file).
    #[arg(short = 'o', long = "output", value_name = "FILE")]
    pub output: Option<PathBuf>,
    /// Also print the report to this PDF through a headless Chromium.
    #[arg(long, value_name = "FILE")]
    pub pdf: Option<PathBuf>,
}

pub fn run(args: ReportArgs, _globals: Globals) -> Result<i32> {
    let html = render_path(&args.source)?;
    let output = match &args.output {
        Some(o) => o.clone(),
        None if args.source.is_dir() => {
            check_listed_report(&args.source, &html)?;
            args.source.join(REPORT_FILE)
        }
        None => args.source.with_extension("html"),
    };
    errmap::io::write_atomic_bytes(&output, html.as_bytes())?;
    info!("wrote {}", output.display());
    if let Some(pdf) = &args.pdf {
        print_pdf(&output, pdf)?;
        info!("wrote {}", pdf.display());
    }
    Ok(0)
}

/// A run's `report.html` is listed in its `run.json`: replacing it with other bytes would leave
/// the manifest vouching for a file that is gone, so that needs `-o`.
fn check_listed_report(dir: &Path, html: &str) -> errmap::Result<()> {
    let Some(m) = RunManifest::read(dir)? else {
        return Ok(());
    };
    match m.files.get(REPORT_FILE) {
        Some(h) if *h != sha256_bytes(html.as_bytes()) => Err(Diagnostic::usage(
            format!(
                "{} is part of the run (listed in run.json) and this errmap renders it differently",
                dir.join(REPORT_FILE).display()
            ),
            "write the new report elsewhere with -o FILE",
        )),
        _ => Ok(()),
    }
}
