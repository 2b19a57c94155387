//! The Sinumerik executor of the corpus judge: the `nc-gcode-interpreter` package from PyPI (a Sinumerik-flavoured interpreter, installed by .ci/run into a venv), read into moves in mm.
//!
//! It reports each block's motion mode and absolute X/Y/Z (it evaluates R parameters, IC()/AC(),
//! loops), but not arc centres, and version 0.1.9 does not accumulate G91 moves; so the judge
//! declines (the file fails as unverified) a program with arcs or G91 rather than trust it.
// Each test binary that includes this module uses only part of it.
#![allow(dead_code)]

use super::path_judge::Seg;
use std::path::{Path, PathBuf};
use std::process::Command;

/// The venv with nc-gcode-interpreter: `ERRMAP_NCI_VENV`, default `.ci/venv` in the checkout.
pub fn venv() -> PathBuf {
    std::env::var_os("ERRMAP_NCI_VENV")
        .map(PathBuf::from)
        .unwrap_or_else(|| Path::new(env!("CARGO_MANIFEST_DIR")).join(".ci/venv"))
}

/// Whether a missing interpreter fails the test (`ERRMAP_REQUIRE_NCI=1`, set by .ci/run).
pub fn required() -> bool {
    std::env::var("ERRMAP_REQUIRE_NCI").is_ok_and(|v| v == "1")
}

const SCRIPT: &str = r#"
import sys, math
from nc_gcode_interpreter import nc_to_dataframe
text = open(sys.argv[1], encoding="utf-8", errors="replace").read()
df, _ = nc_to_dataframe(text, iteration_limit=200000)
cols = set(df.columns)
for row in df.iter_rows(named=True):
    m = row.get("gg01_motion") or "-"
    units = row.get("gg13_wp_measure") or "-"
    xyz = [row.get(a) if a in cols else None for a in "XYZ"]
    print(m, units, *["nan" if v is None else repr(float(v)) for v in xyz])
"#;

/// Whether the interpreter is installed.
pub fn available() -> bool {
    python().is_file()
}

fn python() -> PathBuf {
    venv().join("bin/python")
}

/// The moves of the program in `path`, mm; `Err` when the interpreter stops or the program
/// holds what this judge does not read (arcs, G91).
pub fn trace(path: &Path, text: &str) -> Result<Vec<Seg>, String> {
    for (n, line) in text.lines().enumerate() {
        let code = line.split(';').next().unwrap_or("").to_ascii_uppercase();
        let has = |w: &str| {
            code.split(|c: char| !c.is_ascii_alphanumeric())
                .any(|t| t == w)
        };
        for w in ["G2", "G3", "G02", "G03", "CIP", "CT", "G91", "TURN"] {
            if has(w) {
                return Err(format!(
                    "line {}: `{w}`: nc-gcode-interpreter reports no arc centres and no G91 sums",
                    n + 1
                ));
            }
        }
    }
    let out = Command::new(python())
        .arg("-c")
        .arg(SCRIPT)
        .arg(path)
        .output()
        .map_err(|e| format!("cannot run nc-gcode-interpreter: {e}"))?;
    if !out.status.success() {
        let err = String::from_utf8_lossy(&out.stderr);
        return Err(format!(
            "nc-gcode-interpreter: {}",
            err.lines().last().unwrap_or("failed")
        ));
    }
    let mut at = [f64::NAN; 3];
    let mut segs = Vec::new();
    for (row, line) in String::from_utf8_lossy(&out.stdout).lines().enumerate() {
        let f: Vec<&str> = line.split_whitespace().collect();
        if f.len() != 5 {
            continue;
        }
        let scale = if f[1] == "G70" || f[1] == "G700" {
            25.4
        } else {
            1.0
        };
        let end = [2, 3, 4].map(|k| f[k].parse::<f64>().unwrap_or(f64::NAN) * scale);
        let moved = (0..3).any(|k| {
            !(end[k].is_nan() && at[k].is_nan()) && (end[k] - at[k]).abs() > 1e-12
                || end[k].is_nan() != at[k].is_nan()
        });
        if moved {
            let cut = matches!(f[0], "G1" | "G01");
            if !cut && f[0] != "G0" && f[0] != "G00" {
                return Err(format!("row {}: motion {} is not read here", row + 1, f[0]));
            }
            if cut && at.iter().chain(&end).any(|v| v.is_nan()) {
                return Err(format!("row {}: a cut from an unknown position", row + 1));
            }
            segs.push(Seg {
                cut,
                line: row as u64 + 1,
                start: at,
                end,
                arc: None,
            });
            at = end;
        }
    }
    Ok(segs)
}
