//! Heidenhain TNC writer: the `.COM` compensation-value table (NR, AXISPOS, axis column, BACKLASH) and the `.CMA` table that assigns it to the axis, within the TNC's limits on entries and spacing.

use super::{check_name, fixed, min_spacing, AxisKind, ControllerTable, TableOptions};
use errmap_core::error::{Error, Result};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// A `.COM` table with more entries is refused by the TNC ("compensation value table (.COM) has
/// more than 256 entries", TNC 407/415/425 technical manual, PLC module 9095).
pub const HEIDENHAIN_MAX_ENTRIES: usize = 256;

/// AXISPOS is written with 4 decimals (0.1 µm or 0.0001 deg).
const POSITION_DECIMALS: i32 = 4;

/// The `.CMA` assignment table beside a `.COM` file: same stem, extension `CMA` (case kept).
pub fn heidenhain_cma_path(path: &Path) -> PathBuf {
    let upper = path
        .extension()
        .map(|e| e.to_string_lossy().chars().any(|c| c.is_ascii_uppercase()))
        .unwrap_or(false);
    path.with_extension(if upper { "CMA" } else { "cma" })
}

fn check_limits(t: &ControllerTable) -> Result<()> {
    let u = t.kind.position_unit();
    if t.len() > HEIDENHAIN_MAX_ENTRIES {
        return Err(Error::usage(
            format!(
                "{} entries, but a TNC compensation-value table (.COM) holds at most {HEIDENHAIN_MAX_ENTRIES}",
                t.len()
            ),
            format!(
                "choose a spacing of at least {} {u}",
                min_spacing(t.end() - t.start, HEIDENHAIN_MAX_ENTRIES)
            ),
        ));
    }
    let scale = 10f64.powi(POSITION_DECIMALS);
    let q = t.step * scale;
    if (q - q.round()).abs() > 1e-6 {
        return Err(Error::usage(
            format!(
                "spacing {} {u} is not a multiple of 0.0001 {u}: the AXISPOS column would not be equally spaced",
                t.step
            ),
            format!("choose a spacing with at most {POSITION_DECIMALS} decimals"),
        ));
    }
    if t.kind == AxisKind::Rotary && (t.start < -1e-9 || t.end() > 360.0 + 1e-9) {
        return Err(Error::Internal(
            "rotary Heidenhain table outside 0 ... 360 deg".into(),
        ));
    }
    Ok(())
}

fn signed(v: f64) -> String {
    format!("{}{}", if v < 0.0 { "" } else { "+" }, v)
}

/// A model error as the value the TNC reads: mm (6 decimals) or deg (7 decimals).
fn value(t: &ControllerTable, e: f64) -> String {
    let decimals = match t.kind {
        AxisKind::Linear => 6,
        AxisKind::Rotary => 7,
    };
    let v: f64 = fixed(t.kind.to_position_unit(e), decimals)
        .parse()
        .unwrap_or(0.0);
    signed(v)
}

pub(super) fn write(
    t: &ControllerTable,
    opts: &TableOptions,
    path: &Path,
) -> Result<Vec<(PathBuf, String)>> {
    check_limits(t)?;
    let axis = opts.axis.clone().unwrap_or_else(|| match t.kind {
        AxisKind::Linear => "X".to_string(),
        AxisKind::Rotary => t.axis.clone(),
    });
    check_name(&axis, "Heidenhain axis column", "X or C")?;
    let com_name = path
        .file_name()
        .map(|s| s.to_string_lossy().to_uppercase())
        .unwrap_or_else(|| format!("{axis}.COM"));
    check_name(&com_name.replace('.', "_"), "TNC file name", "X.COM")?;
    let scale = 10f64.powi(POSITION_DECIMALS);
    let mut com = String::new();
    let _ = writeln!(com, "BEGIN {com_name} MM");
    let _ = writeln!(
        com,
        "{:<6}{:<16}{:<16}{:<16}",
        "NR", "AXISPOS", axis, "BACKLASH"
    );
    for i in 0..t.len() {
        let _ = writeln!(
            com,
            "{:<6}{:<16}{:<16}{:<16}",
            i,
            signed((t.position(i) * scale).round() / scale),
            value(t, t.forward[i]),
            value(t, t.reverse[i])
        );
    }
    com.push_str("[END]\n");
    let cma_path = heidenhain_cma_path(path);
    let cma_name = cma_path
        .file_name()
        .map(|s| s.to_string_lossy().to_uppercase())
        .unwrap_or_else(|| "CONFIG.CMA".into());
    let mut cma = String::new();
    let _ = writeln!(cma, "BEGIN {cma_name}");
    let _ = writeln!(cma, "{:<6}{:<24}ACTIVE", "NR", axis);
    let _ = writeln!(cma, "{:<6}{:<24}*", 0, com_name);
    cma.push_str("[END]\n");
    Ok(vec![(path.to_path_buf(), com), (cma_path, cma)])
}
