//! One compensation-table model for every controller (axis, directions, reference point, spacing, entries with units) and a writer per controller, used by linear and rotary axes alike.
//!
//! The model holds the axis error e = actual - nominal of each direction at equally spaced
//! positions, in µm (linear) or arcsec (rotary). Each writer converts to its controller's own
//! sign, unit and layout and checks the controller's documented limits; a table beyond a limit
//! is refused with the entry, its value, the limit and what to do (exit 2). The sources of the
//! limits are cited in docs/linear.md and docs/rotary.md.
//!
//! | format | linear | rotary |
//! |---|---|---|
//! | `linuxcnc` | `[JOINT_n]COMP_FILE`, type 0 or 1, at most 256 lines | type 0 over 0 ... 360 deg |
//! | `sinumerik` | LEC `%_N_AX_EEC_INI` zero at the reference point + CEC `%_N_NC_CEC_INI` per direction | the same, modulo |
//! | `fanuc` | parameters 3620-3624, 3626, 3627 and incremental points, range of the series | with 3625 (travel per turn) |
//! | `heidenhain` | `.COM` table + `.CMA` assignment, at most 256 entries | AXISPOS 0 ... 360 |
//! | `csv` | errmap's own: position, e forward, e reverse | angle, err = -e (arcsec) |

mod fanuc;
mod heidenhain;
mod linuxcnc;
mod sinumerik;

pub use crate::error::TableError;
pub use fanuc::{FanucLimits, FanucSeries};
pub use heidenhain::{heidenhain_cma_path, HEIDENHAIN_MAX_ENTRIES};
pub use linuxcnc::LINUXCNC_MAX_LINES;
pub use sinumerik::{sinumerik_cec_path, SINUMERIK_DEFAULT_MAX_POINTS};

use errmap_core::error::{Error, Result};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// Controller file format (the same names for linear and rotary tables).
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum TableFormat {
    /// LinuxCNC `[JOINT_n]COMP_FILE`.
    Linuxcnc,
    /// Sinumerik 840D/828D/808D LEC (`$AA_ENC_COMP`) and direction-dependent CEC (`$AN_CEC`).
    Sinumerik,
    /// Fanuc pitch-error compensation parameters and data (0i-F, 30i-B).
    Fanuc,
    /// Heidenhain TNC `.COM` compensation-value table and its `.CMA` assignment table.
    Heidenhain,
    /// errmap's own CSV.
    Csv,
}

impl TableFormat {
    /// The format's name on the command line and in JSON (`linuxcnc`, `sinumerik`, `fanuc`,
    /// `heidenhain`, `csv`).
    pub fn name(self) -> &'static str {
        match self {
            TableFormat::Linuxcnc => "linuxcnc",
            TableFormat::Sinumerik => "sinumerik",
            TableFormat::Fanuc => "fanuc",
            TableFormat::Heidenhain => "heidenhain",
            TableFormat::Csv => "csv",
        }
    }
}

/// Linear axes (mm, µm) or modulo rotary axes (deg, arcsec, a whole turn 0 ... 360).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum AxisKind {
    /// A linear axis: positions in mm, errors in µm.
    Linear,
    /// A modulo rotary axis: positions in degrees over one turn 0 … 360, errors in arcsec.
    Rotary,
}

impl AxisKind {
    /// Unit of positions in files (`mm`, `deg`).
    pub fn position_unit(self) -> &'static str {
        match self {
            AxisKind::Linear => "mm",
            AxisKind::Rotary => "deg",
        }
    }
    /// Unit of the model's errors (`um`, `arcsec`).
    pub fn error_unit(self) -> &'static str {
        match self {
            AxisKind::Linear => "um",
            AxisKind::Rotary => "arcsec",
        }
    }
    /// An error of the model (µm or arcsec) in the position unit (mm or deg).
    pub fn to_position_unit(self, e: f64) -> f64 {
        match self {
            AxisKind::Linear => e * 1e-3,
            AxisKind::Rotary => e / 3600.0,
        }
    }
}

/// A compensation table as every controller writer takes it.
#[derive(Debug, Clone, PartialEq)]
pub struct ControllerTable {
    /// Linear or rotary: fixes the units of positions and errors.
    pub kind: AxisKind,
    /// Axis letter (X, C), for comments and the Heidenhain column.
    pub axis: String,
    /// Position of entry 0 (mm or deg); rotary tables start at 0.
    pub start: f64,
    /// Spacing of the entries (mm or deg).
    pub step: f64,
    /// e = actual - nominal, forward (+) approach, per entry (µm or arcsec).
    pub forward: Vec<f64>,
    /// e, reverse (-) approach (equal to `forward` for a unidirectional measurement).
    pub reverse: Vec<f64>,
    /// Whether both directions were measured.
    pub bidirectional: bool,
    /// Reference position (mm or deg): a table entry. Sinumerik's LEC and Fanuc's table are
    /// zero there.
    pub reference: f64,
    /// How the entries were obtained, written into the files that take comments (ASCII).
    pub notes: Vec<String>,
}

impl ControllerTable {
    /// Number of entries (positions) of the table.
    pub fn len(&self) -> usize {
        self.forward.len()
    }
    /// Whether the table has no entries.
    pub fn is_empty(&self) -> bool {
        self.forward.is_empty()
    }
    /// Position of entry `i`.
    pub fn position(&self, i: usize) -> f64 {
        self.start + i as f64 * self.step
    }
    /// Position of the last entry (mm or deg); `start` for an empty table.
    pub fn end(&self) -> f64 {
        self.position(self.len().saturating_sub(1))
    }
    /// Index of the reference position, or an error naming the table's points.
    pub fn reference_index(&self) -> Result<usize> {
        let u = self.kind.position_unit();
        (0..self.len())
            .find(|&i| (self.position(i) - self.reference).abs() < 1e-6)
            .ok_or_else(|| {
                Error::usage(
                    format!(
                        "reference position {} {u} is not a table point ({} ... {} {u} every {} {u})",
                        self.reference,
                        self.start,
                        self.end(),
                        self.step
                    ),
                    "give a reference position equal to the first point plus a multiple of the spacing",
                )
            })
    }
    /// Mean of both directions per entry.
    pub fn mean(&self) -> Vec<f64> {
        self.forward
            .iter()
            .zip(&self.reverse)
            .map(|(f, r)| 0.5 * (f + r))
            .collect()
    }
}

/// Options of the controller writers.
#[derive(Debug, Clone, PartialEq)]
pub struct TableOptions {
    /// LinuxCNC COMP_FILE_TYPE: 0 positions, 1 trims.
    pub linuxcnc_type: u8,
    /// Axis name: Sinumerik machine axis (AX1, C1), Heidenhain column (X, C), Fanuc axis number (1).
    pub axis: Option<String>,
    /// Fanuc detection unit in thousandths of the axis unit: µm (linear) or 0.001 deg (rotary);
    /// 1 = IS-B, 0.1 = IS-C.
    pub fanuc_unit_um: f64,
    /// Fanuc control series, whose parameter ranges are checked.
    pub fanuc_series: FanucSeries,
    /// Fanuc pitch-error compensation magnification (parameter 3623).
    pub fanuc_magnification: u32,
    /// Reference position (mm); defaults to the first position (linear) or 0 deg (rotary).
    pub reference_mm: Option<f64>,
    /// First Sinumerik CEC table index for the direction-dependent part (uses t and t + 1).
    pub cec_table: u32,
    /// Interpolation points per Sinumerik table (MD38000 for LEC, MD18342 for CEC).
    pub sinumerik_max_points: usize,
}

impl Default for TableOptions {
    fn default() -> Self {
        TableOptions {
            linuxcnc_type: 0,
            axis: None,
            fanuc_unit_um: 1.0,
            fanuc_series: FanucSeries::Fs0iF,
            fanuc_magnification: 1,
            reference_mm: None,
            cec_table: 0,
            sinumerik_max_points: SINUMERIK_DEFAULT_MAX_POINTS,
        }
    }
}

/// The rendered file(s) of a table: `(path, text)` pairs (Sinumerik and Heidenhain write two).
/// Every text is ASCII: controllers read nothing else.
pub fn render(
    table: &ControllerTable,
    format: TableFormat,
    opts: &TableOptions,
    path: &Path,
) -> Result<Vec<(PathBuf, String)>> {
    if table.len() < 2 || table.reverse.len() != table.len() {
        return Err(Error::usage(
            "a compensation table needs at least two points",
            "use a smaller spacing or measure a longer travel",
        ));
    }
    if !(table.step.is_finite() && table.step > 0.0) {
        return Err(Error::Internal(format!("table step {}", table.step)));
    }
    let files = match format {
        TableFormat::Linuxcnc => vec![(path.to_path_buf(), linuxcnc::write(table, opts)?)],
        TableFormat::Sinumerik => {
            let (lec, cec) = sinumerik::write(table, opts)?;
            vec![(path.to_path_buf(), lec), (sinumerik_cec_path(path), cec)]
        }
        TableFormat::Fanuc => vec![(path.to_path_buf(), fanuc::write(table, opts)?)],
        TableFormat::Heidenhain => heidenhain::write(table, opts, path)?,
        TableFormat::Csv => vec![(path.to_path_buf(), csv(table))],
    };
    for (p, text) in &files {
        if let Some(at) = text.bytes().position(|b| !b.is_ascii()) {
            return Err(Error::Internal(format!(
                "non-ASCII byte at offset {at} of {}",
                p.display()
            )));
        }
    }
    Ok(files)
}

/// An axis name given by the user: ASCII letters, digits and `_` only (controllers' identifiers).
pub(crate) fn check_name(name: &str, what: &str, example: &str) -> Result<()> {
    if name.is_empty() || !name.chars().all(|c| c.is_ascii_alphanumeric() || c == '_') {
        return Err(Error::usage(
            format!("'{name}' is not a {what}"),
            format!("use ASCII letters and digits, e.g. {example}"),
        ));
    }
    Ok(())
}

/// The smallest spacing (4 decimals, rounded up) that puts `span` into at most `entries` entries.
pub(crate) fn min_spacing(span: f64, entries: usize) -> String {
    let s = span / (entries.max(2) - 1) as f64;
    fixed(((s * 1e4) - 1e-6).ceil() / 1e4, 4)
}

pub use errmap_core::numeric::format::fixed;

fn csv(t: &ControllerTable) -> String {
    let mut out = String::new();
    match t.kind {
        AxisKind::Linear => {
            out.push_str("# errmap compensation table: axis error e = actual - nominal per direction (um); a controller applies -e\n");
            for n in &t.notes {
                let _ = writeln!(out, "# {n}");
            }
            out.push_str("position_mm,forward_um,reverse_um\n");
            for i in 0..t.len() {
                let _ = writeln!(
                    out,
                    "{:.6},{:.4},{:.4}",
                    t.position(i),
                    t.forward[i],
                    t.reverse[i]
                );
            }
        }
        AxisKind::Rotary => {
            let _ = writeln!(
                out,
                "# errmap rotary table, axis {}: err = alpha - beta (commanded - measured), arcsec; add err to the command to correct",
                t.axis
            );
            for n in &t.notes {
                let _ = writeln!(out, "# {n}");
            }
            out.push_str("angle_deg,error_forward_arcsec,error_reverse_arcsec\n");
            for i in 0..t.len() {
                let _ = writeln!(
                    out,
                    "{},{},{}",
                    t.position(i),
                    fixed(-t.forward[i], 3),
                    fixed(-t.reverse[i], 3)
                );
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fixed_point_has_no_negative_zero() {
        assert_eq!(fixed(-0.0000001, 3), "0.000");
        assert_eq!(fixed(-0.0004, 3), "0.000");
        assert_eq!(fixed(-0.0006, 3), "-0.001");
        assert_eq!(fixed(12.5, 1), "12.5");
    }
}
