//! Sinumerik writer: the leadscrew/measuring-system error compensation (LEC, `%_N_AX_EEC_INI`) zero at the reference point, and the direction-dependent part as two interpolatory (CEC, `%_N_NC_CEC_INI`) tables.

use super::{check_name, fixed, min_spacing, AxisKind, ControllerTable, TableOptions};
use crate::Setting;
use errmap_core::error::{Error, Result};
use errmap_core::setting::words;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// Interpolation points per table unless told otherwise: the 808D's LEC table holds 200
/// (N = 0 ... 199) and the 828D's sag-compensation tables 200. On an 840D sl the limit is the
/// machine data MD38000 $MA_MM_ENC_COMP_MAX_POINTS (LEC) and MD18342 $MN_MM_CEC_MAX_POINTS (CEC).
pub const SINUMERIK_DEFAULT_MAX_POINTS: usize = 200;

/// Path of the second Sinumerik file (direction-dependent CEC tables) beside `path`.
pub fn sinumerik_cec_path(path: &Path) -> PathBuf {
    let stem = path
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default();
    let name = match path.extension() {
        Some(ext) => format!("{stem}_cec.{}", ext.to_string_lossy()),
        None => format!("{stem}_cec"),
    };
    path.with_file_name(name)
}

fn default_axis(t: &ControllerTable) -> String {
    match t.kind {
        AxisKind::Linear => "AX1".to_string(),
        AxisKind::Rotary => format!("{}1", t.axis),
    }
}

/// Values in mm or deg with 6 (linear) or 7 (rotary) decimals.
fn value(t: &ControllerTable, e: f64) -> String {
    match t.kind {
        AxisKind::Linear => fixed(t.kind.to_position_unit(e), 6),
        AxisKind::Rotary => fixed(t.kind.to_position_unit(e), 7),
    }
}

/// (LEC file, CEC file).
pub(super) fn write(t: &ControllerTable, opts: &TableOptions) -> Result<(String, String)> {
    let axis = opts.axis.clone().unwrap_or_else(|| default_axis(t));
    check_name(&axis, "Sinumerik machine axis name", "AX1 or X1")?;
    let n = t.len();
    if n > opts.sinumerik_max_points {
        return Err(Error::usage(
            format!(
                "{n} interpolation points, but the Sinumerik table holds {} (MD38000 / MD18342)",
                opts.sinumerik_max_points
            ),
            format!(
                "choose a spacing of at least {} {}, or give {} as configured in MD38000 and MD18342",
                min_spacing(t.end() - t.start, opts.sinumerik_max_points),
                t.kind.position_unit(),
                words(Setting::SinumerikMaxPoints)
            ),
        ));
    }
    let r = t.reference_index()?;
    let modulo = u8::from(t.kind == AxisKind::Rotary);
    let u = t.kind.position_unit();
    let step = fixed(t.step, 6);
    let (min, max) = (fixed(t.start, 6), fixed(t.end(), 6));
    let mean = t.mean();
    let mut lec = String::from("%_N_AX_EEC_INI\nCHANDATA(1)\n");
    let _ = writeln!(
        lec,
        "; errmap LEC, axis {axis}: mean of both directions minus its value at the reference point {} {u}, in {u} (a positive value moves the axis negative)",
        fixed(t.reference, 4)
    );
    for note in &t.notes {
        let _ = writeln!(lec, "; {note}");
    }
    for (i, m) in mean.iter().enumerate() {
        let _ = writeln!(lec, "$AA_ENC_COMP[0,{i},{axis}]={}", value(t, m - mean[r]));
    }
    let _ = writeln!(lec, "$AA_ENC_COMP_STEP[0,{axis}]={step}");
    let _ = writeln!(lec, "$AA_ENC_COMP_MIN[0,{axis}]={min}");
    let _ = writeln!(lec, "$AA_ENC_COMP_MAX[0,{axis}]={max}");
    let _ = writeln!(lec, "$AA_ENC_COMP_IS_MODULO[0,{axis}]={modulo}");
    lec.push_str("M17\n");

    let mut cec = String::from("%_N_NC_CEC_INI\nCHANDATA(1)\n");
    let _ = writeln!(
        cec,
        "; errmap direction-dependent part, axis {axis}: -(e - mean) in {u}, added to the setpoint"
    );
    for (k, (dir, ys)) in [(1, &t.forward), (-1, &t.reverse)].into_iter().enumerate() {
        let tab = opts.cec_table + k as u32;
        for (i, (v, m)) in ys.iter().zip(&mean).enumerate() {
            let _ = writeln!(cec, "$AN_CEC[{tab},{i}]={}", value(t, -(v - m)));
        }
        let _ = writeln!(cec, "$AN_CEC_INPUT_AXIS[{tab}]=({axis})");
        let _ = writeln!(cec, "$AN_CEC_OUTPUT_AXIS[{tab}]=({axis})");
        let _ = writeln!(cec, "$AN_CEC_STEP[{tab}]={step}");
        let _ = writeln!(cec, "$AN_CEC_MIN[{tab}]={min}");
        let _ = writeln!(cec, "$AN_CEC_MAX[{tab}]={max}");
        let _ = writeln!(cec, "$AN_CEC_DIRECTION[{tab}]={dir}");
        let _ = writeln!(cec, "$AN_CEC_MULT_BY_TABLE[{tab}]=0");
        let _ = writeln!(cec, "$AN_CEC_IS_MODULO[{tab}]={modulo}");
    }
    cec.push_str("M17\n");
    Ok((lec, cec))
}
