//! LinuxCNC `[JOINT_n]COMP_FILE` writer: `nominal forward reverse` triplets, ascending, nothing else in the file.

use super::{fixed, min_spacing, AxisKind, ControllerTable, TableOptions};
use crate::Setting;
use errmap_core::error::{Error, Result};
use errmap_core::setting::words;
use std::fmt::Write as _;

/// LinuxCNC reads at most 256 triplets per joint (INI configuration, `[JOINT_n]COMP_FILE`).
pub const LINUXCNC_MAX_LINES: usize = 256;

/// Type 0: the actual positions x + e of each direction; type 1: the trims -e. Machine units
/// (mm or deg). No comment lines: LinuxCNC stops reading at the first line that is not a triplet.
pub(super) fn write(t: &ControllerTable, opts: &TableOptions) -> Result<String> {
    if t.len() > LINUXCNC_MAX_LINES {
        return Err(Error::usage(
            format!(
                "{} points, but LinuxCNC reads at most {LINUXCNC_MAX_LINES} per joint",
                t.len()
            ),
            format!(
                "choose a spacing of at least {} {} (or split the travel)",
                min_spacing(t.end() - t.start, LINUXCNC_MAX_LINES),
                t.kind.position_unit()
            ),
        ));
    }
    let digits = match t.kind {
        AxisKind::Linear => 6,
        AxisKind::Rotary => 7,
    };
    let mut out = String::new();
    for i in 0..t.len() {
        let x = t.position(i);
        let (ef, er) = (
            t.kind.to_position_unit(t.forward[i]),
            t.kind.to_position_unit(t.reverse[i]),
        );
        let (a, b) = match opts.linuxcnc_type {
            0 => (x + ef, x + er),
            1 => (-ef, -er),
            other => {
                return Err(Error::usage(
                    format!("LinuxCNC COMP_FILE_TYPE {other} does not exist"),
                    format!(
                        "use {} 0 (positions) or 1 (trims)",
                        words(Setting::LinuxcncType)
                    ),
                ))
            }
        };
        let _ = writeln!(
            out,
            "{} {} {}",
            fixed(x, 6),
            fixed(a, digits),
            fixed(b, digits)
        );
    }
    Ok(out)
}
