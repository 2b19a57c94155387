//! LinuxCNC's own interpreter (rs274, through shared/corpus/gcode/rs274-check.sh) as an executor for the corpus judge: its canonical output read into moves in mm.
// Each test binary that includes this module uses only part of it.
#![allow(dead_code)]

use super::path_judge::{sweep, ArcSeg, Seg};
use std::path::{Path, PathBuf};
use std::process::Command;

/// The folder with rs274-check.sh, beside the checkout.
pub fn gcode_dir() -> PathBuf {
    std::env::var_os("ERRMAP_GCODE_CORPUS")
        .map(PathBuf::from)
        .unwrap_or_else(|| Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/corpus/gcode"))
}

/// Whether a missing rs274 fails the test (`ERRMAP_REQUIRE_RS274=1`, set by .ci/run).
pub fn required() -> bool {
    std::env::var("ERRMAP_REQUIRE_RS274").is_ok_and(|v| v == "1")
}

/// Run rs274 on `program` (a copy in `work`, with user M codes M100–M199 blanked: they run
/// an outside script and never move the axes, and rs274 has no script for them here). `None`
/// when rs274 is not installed; `Err` with its message when it stops at an error.
pub fn run(work: &Path, name: &str, program: &[u8]) -> Option<Result<Vec<Seg>, String>> {
    let script = gcode_dir().join("rs274-check.sh");
    if !script.is_file() {
        return None;
    }
    let text = String::from_utf8_lossy(program);
    let blanked = blank_user_m_codes(&text);
    let prog = work.join(format!("{name}.ngc"));
    let canon = work.join(format!("{name}.canon"));
    std::fs::write(&prog, blanked).ok()?;
    let out = Command::new(&script).arg(&prog).arg(&canon).output().ok()?;
    match out.status.code() {
        Some(127) => None,
        Some(0) => Some(Ok(segs(
            &std::fs::read_to_string(&canon).unwrap_or_default(),
        ))),
        code => Some(Err(format!(
            "rs274 exit {code:?}: {}",
            String::from_utf8_lossy(&out.stderr).trim()
        ))),
    }
}

/// `M100` … `M199` words replaced by spaces of the same length (outside comments too, which is
/// harmless: the original and the output get the same treatment).
fn blank_user_m_codes(text: &str) -> String {
    let b = text.as_bytes();
    let mut out = b.to_vec();
    let mut i = 0;
    while i + 4 <= b.len() {
        let m = b[i].eq_ignore_ascii_case(&b'M');
        let before_ok = i == 0 || !b[i - 1].is_ascii_alphanumeric();
        if m && before_ok
            && b[i + 1] == b'1'
            && b[i + 2].is_ascii_digit()
            && b[i + 3].is_ascii_digit()
        {
            let after = b.get(i + 4).copied().unwrap_or(b' ');
            if !after.is_ascii_digit() {
                out[i..i + 4].copy_from_slice(b"    ");
            }
        }
        i += 1;
    }
    String::from_utf8(out).unwrap_or_else(|_| text.to_string())
}

/// The motions of a canonical output, mm.
pub fn segs(canon: &str) -> Vec<Seg> {
    let mut axes = (0, 1, 2);
    let mut scale = 1.0;
    let mut at = [0.0f64; 3];
    let mut out = Vec::new();
    for line in canon.lines() {
        let Some(open) = line.find('(') else { continue };
        let name = line[..open].split_whitespace().last().unwrap_or("");
        let args_text = line[open + 1..].trim_end_matches(')');
        let a: Vec<f64> = args_text
            .split(',')
            .map(|v| v.trim().parse::<f64>().unwrap_or(f64::NAN))
            .collect();
        match name {
            "USE_LENGTH_UNITS" => {
                scale = if args_text.contains("INCH") {
                    25.4
                } else {
                    1.0
                }
            }
            "SELECT_PLANE" => {
                axes = if args_text.contains("XZ") {
                    (2, 0, 1)
                } else if args_text.contains("YZ") {
                    (1, 2, 0)
                } else {
                    (0, 1, 2)
                }
            }
            "STRAIGHT_TRAVERSE" | "STRAIGHT_FEED" => {
                let end = [a[0] * scale, a[1] * scale, a[2] * scale];
                out.push(Seg {
                    cut: name == "STRAIGHT_FEED",
                    line: 0,
                    start: at,
                    end,
                    arc: None,
                });
                at = end;
            }
            "ARC_FEED" => {
                let mut end = [0.0; 3];
                end[axes.0] = a[0] * scale;
                end[axes.1] = a[1] * scale;
                end[axes.2] = a[5] * scale;
                let centre = (a[2] * scale, a[3] * scale);
                let rotation = a[4] as i32;
                let turns = rotation.unsigned_abs().saturating_sub(1);
                let s = sweep(axes, centre, &at, &end, rotation < 0, turns);
                out.push(Seg {
                    cut: true,
                    line: 0,
                    start: at,
                    end,
                    arc: Some(ArcSeg {
                        axes,
                        centre,
                        sweep_rad: s,
                    }),
                });
                at = end;
            }
            _ => {}
        }
    }
    out
}
