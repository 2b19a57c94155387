//! `--pdf`: print a report through a headless Chromium (found as `$ERRMAP_CHROMIUM`, `chromium`, `chromium-browser`, `google-chrome` or `google-chrome-stable` on the PATH).

use crate::ReportError;
use crate::Setting;
use errmap_core::error::{Error, Result};
use errmap_core::setting::words;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

/// Names looked up on the PATH, in order.
pub const BROWSER_NAMES: [&str; 4] = [
    "chromium",
    "chromium-browser",
    "google-chrome",
    "google-chrome-stable",
];

/// Longest a print may take before the browser is stopped.
const PRINT_TIMEOUT: Duration = Duration::from_secs(120);

/// The browser to print with: `$ERRMAP_CHROMIUM` when set, else the first of
/// [`BROWSER_NAMES`] on the PATH.
pub fn find_chromium() -> Result<PathBuf, ReportError> {
    if let Some(p) = std::env::var_os("ERRMAP_CHROMIUM").filter(|p| !p.is_empty()) {
        let p = PathBuf::from(p);
        if p.is_file() {
            return Ok(p);
        }
        return Err(ReportError::NoBrowser(Error::usage(
            format!("ERRMAP_CHROMIUM={} is not a file", p.display()),
            "set ERRMAP_CHROMIUM to the Chromium or Chrome executable, or unset it to search the PATH",
        )));
    }
    let path = std::env::var_os("PATH").unwrap_or_default();
    for name in BROWSER_NAMES {
        for dir in std::env::split_paths(&path) {
            let candidate = dir.join(name);
            if candidate.is_file() {
                return Ok(candidate);
            }
        }
    }
    Err(ReportError::NoBrowser(Error::usage(
        format!(
            "{} needs a headless Chromium and none was found ({} on the PATH, or $ERRMAP_CHROMIUM)",
            words(Setting::Pdf),
            BROWSER_NAMES.join(", ")
        ),
        "install Chromium (Debian/Ubuntu: apt-get install chromium; Fedora: dnf install chromium) or set ERRMAP_CHROMIUM to a Chrome or Chromium executable; the HTML report does not need it",
    )))
}

/// A `file://` URL of an absolute path, bytes outside the unreserved set percent-encoded.
pub fn file_url(path: &Path) -> Result<String> {
    let abs = std::path::absolute(path).map_err(|e| Error::read(path, e))?;
    let mut url = String::from("file://");
    for b in abs.to_string_lossy().bytes() {
        if b.is_ascii_alphanumeric() || b"/-._~".contains(&b) {
            url.push(b as char);
        } else {
            url.push_str(&format!("%{b:02X}"));
        }
    }
    Ok(url)
}

/// Print the HTML file `html` to the PDF `pdf` (written atomically, never over an input).
pub fn print_pdf(html: &Path, pdf: &Path) -> Result<(), ReportError> {
    errmap_core::io::safety::check_output(pdf).map_err(|d| match d {
        Error::Internal(_) => ReportError::Internal(d),
        d => ReportError::Output(d),
    })?;
    let browser = find_chromium()?;
    let scratch = tempfile::tempdir().map_err(|e| Error::write(std::env::temp_dir(), e))?;
    let out = scratch.path().join("report.pdf");
    let mut child = std::process::Command::new(&browser)
        .arg("--headless")
        .arg("--no-sandbox")
        .arg("--disable-gpu")
        .arg("--no-first-run")
        .arg("--no-pdf-header-footer")
        .arg(format!(
            "--user-data-dir={}",
            scratch.path().join("profile").display()
        ))
        .arg(format!("--print-to-pdf={}", out.display()))
        .arg(file_url(html)?)
        .stdin(std::process::Stdio::null())
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .map_err(|e| ReportError::Print(Error::io("start", &browser, e)))?;
    let start = Instant::now();
    let status =
        loop {
            if let Some(s) = child
                .try_wait()
                .map_err(|e| ReportError::Print(Error::io("wait for", &browser, e)))?
            {
                break s;
            }
            if start.elapsed() > PRINT_TIMEOUT {
                let _ = child.kill();
                let _ = child.wait();
                return Err(Error::device(
                format!("{} did not print within {} s", browser.display(), PRINT_TIMEOUT.as_secs()),
                "print the HTML report from a browser, or check that Chromium starts headless here",
            ).into());
            }
            std::thread::sleep(Duration::from_millis(100));
        };
    let mut stderr = String::new();
    if let Some(mut e) = child.stderr.take() {
        use std::io::Read;
        let _ = e.read_to_string(&mut stderr);
    }
    let bytes = std::fs::read(&out).unwrap_or_default();
    if !status.success() || !bytes.starts_with(b"%PDF") {
        let tail: String = stderr.lines().rev().take(5).collect::<Vec<_>>().join(" | ");
        return Err(Error::device(
            format!("{} printed no PDF ({status}): {tail}", browser.display()),
            "print the HTML report from a browser, or check that Chromium starts headless here",
        )
        .into());
    }
    Ok(errmap_core::io::write_atomic_bytes(pdf, &bytes)?)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn file_urls_are_percent_encoded() {
        let u = file_url(Path::new("/tmp/a b/r#1é.html")).unwrap();
        assert_eq!(u, "file:///tmp/a%20b/r%231%C3%A9.html");
    }
}
