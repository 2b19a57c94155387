//! Fanuc pitch-error compensation writer: parameters 3620-3627 and incremental compensation points on a `%` tape, checked against the value ranges of the chosen control series.

use super::{fixed, min_spacing, AxisKind, ControllerTable, TableOptions};
use crate::Setting;
use errmap_core::error::{Error, Result};
use errmap_core::setting::words;
use std::fmt::Write as _;

/// Control series whose parameter ranges are checked.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
pub enum FanucSeries {
    /// Series 0i-F (parameter manual B-64610EN).
    Fs0iF,
    /// Series 30i/31i/32i-B (parameter manual B-64490EN).
    Fs30iB,
}

/// The valid data ranges errmap checks for a series.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FanucLimits {
    /// Highest compensation point number (3620-3622, 3626).
    pub max_point_number: i64,
    /// Smallest compensation value of one point, in detection units times the magnification.
    pub value_min: i64,
    /// Largest compensation value of one point, in the same units.
    pub value_max: i64,
    /// Parameter 3623.
    pub magnification_max: u32,
    /// Parameter 3624 (detection units).
    pub interval_max: i64,
    /// Parameter 3627 (detection units).
    pub reference_value_max: i64,
}

impl FanucSeries {
    /// The series' name on the command line and in messages (`0i-F`, `30i-B`).
    pub fn name(self) -> &'static str {
        match self {
            FanucSeries::Fs0iF => "0i-F",
            FanucSeries::Fs30iB => "30i-B",
        }
    }
    /// The data ranges of the series' parameter manual: point numbers 0 … 1023 (0i-F) or 0 … 1535
    /// (30i-B), values −128 … 127 per point, magnification up to 100.
    pub fn limits(self) -> FanucLimits {
        let max_point_number = match self {
            FanucSeries::Fs0iF => 1023,
            FanucSeries::Fs30iB => 1535,
        };
        FanucLimits {
            max_point_number,
            value_min: -128,
            value_max: 127,
            magnification_max: 100,
            interval_max: 99_999_999,
            reference_value_max: 32_767,
        }
    }
}

/// Forward points 0 ... n-1, reverse points n ... 2n-1; `reference_index` within a block.
struct Layout {
    axis: u32,
    /// Size of one compensation step in the axis unit's thousandths (µm or 0.001 deg).
    step_units: f64,
    reference_index: usize,
    interval_counts: i64,
}

fn usage(message: String, hint: impl Into<String>) -> Error {
    Error::usage(message, hint)
}

fn layout(t: &ControllerTable, opts: &TableOptions) -> Result<Layout> {
    let lim = opts.fanuc_series.limits();
    let series = opts.fanuc_series.name();
    let axis = axis_number(opts.axis.as_deref())?;
    let unit = opts.fanuc_unit_um;
    if !(unit.is_finite() && unit > 0.0) {
        return Err(usage(
            format!("Fanuc detection unit {unit} is not positive"),
            format!(
                "use {} 1 for IS-B (0.001 mm or 0.001 deg), 0.1 for IS-C",
                words(Setting::FanucUnitUm)
            ),
        ));
    }
    let mag = opts.fanuc_magnification;
    if mag < 1 || mag > lim.magnification_max {
        return Err(usage(
            format!(
                "magnification {mag} (parameter 3623) is outside 1 ... {} of series {series}",
                lim.magnification_max
            ),
            format!(
                "give {} between 1 and 100",
                words(Setting::FanucMagnification)
            ),
        ));
    }
    check_point_count(t, opts.fanuc_series)?;
    let interval_counts = interval_counts(t, unit, opts.fanuc_series)?;
    let reference_index = t.reference_index()?;
    if t.kind == AxisKind::Rotary && reference_index != 0 {
        return Err(Error::Internal(
            "rotary Fanuc table not starting at its reference".into(),
        ));
    }
    Ok(Layout {
        axis,
        step_units: unit * mag as f64,
        reference_index,
        interval_counts,
    })
}

/// The controlled-axis number of `--axis` (default 1).
fn axis_number(axis: Option<&str>) -> Result<u32> {
    match axis {
        None => Ok(1),
        Some(a) => a.parse().ok().filter(|&n| n >= 1).ok_or_else(|| {
            usage(
                format!("Fanuc axis '{a}' is not an axis number"),
                format!(
                    "give the controlled-axis number, e.g. {} 1 for X",
                    words(Setting::Axis)
                ),
            )
        }),
    }
}

/// Both directions' blocks of points must fit the series' point numbers.
fn check_point_count(t: &ControllerTable, fanuc_series: FanucSeries) -> Result<()> {
    let lim = fanuc_series.limits();
    let series = fanuc_series.name();
    let highest = 2 * t.len() as i64 - 1;
    if highest > lim.max_point_number {
        return Err(usage(
            format!(
                "{} compensation points (numbers 0 ... {highest}) exceed series {series}'s 0 ... {}",
                2 * t.len(),
                lim.max_point_number
            ),
            format!(
                "choose a spacing of at least {} {} (each direction needs its own block of points)",
                min_spacing(t.end() - t.start, ((lim.max_point_number + 1) / 2) as usize),
                t.kind.position_unit()
            ),
        ));
    }
    Ok(())
}

/// The spacing in detection units of `unit` thousandths (parameter 3624): a whole number
/// within the series' limit.
fn interval_counts(t: &ControllerTable, unit: f64, fanuc_series: FanucSeries) -> Result<i64> {
    let lim = fanuc_series.limits();
    let series = fanuc_series.name();
    let spacing_counts = t.step * 1e3 / unit;
    let interval_counts = spacing_counts.round() as i64;
    if (spacing_counts - interval_counts as f64).abs() > 1e-6 || interval_counts <= 0 {
        return Err(usage(
            format!(
                "spacing {} {} is not a whole number of detection units of {unit}/1000",
                t.step,
                t.kind.position_unit()
            ),
            "choose a spacing that is a multiple of the detection unit",
        ));
    }
    if interval_counts > lim.interval_max {
        return Err(usage(
            format!(
                "interval {interval_counts} detection units (parameter 3624) exceeds series {series}'s {}",
                lim.interval_max
            ),
            "choose a smaller spacing",
        ));
    }
    Ok(interval_counts)
}

/// Absolute compensation per entry in steps, C = round(-e / step). The tape carries increments
/// C_k - C_(k-1) so that rounding never accumulates; point 0 of a block covers the section below
/// the table (0), or on a rotary axis repeats the last point (the turn closes).
fn increments(t: &ControllerTable, ys: &[f64], step_units: f64) -> (Vec<i64>, Vec<i64>) {
    let c: Vec<i64> = ys
        .iter()
        .map(|&e| (-(t.kind.to_position_unit(e) * 1e3) / step_units).round() as i64)
        .collect();
    let n = c.len();
    let mut inc: Vec<i64> = (0..n)
        .map(|k| if k == 0 { 0 } else { c[k] - c[k - 1] })
        .collect();
    if t.kind == AxisKind::Rotary {
        inc[0] = inc[n - 1];
    }
    (c, inc)
}

/// The first increment outside the series' range, as an error naming it.
fn check_range(
    t: &ControllerTable,
    opts: &TableOptions,
    blocks: &[(&str, usize, &Vec<i64>)],
) -> Result<()> {
    let lim = opts.fanuc_series.limits();
    let worst = blocks
        .iter()
        .flat_map(|b| b.2.iter())
        .map(|v| v.unsigned_abs())
        .max()
        .unwrap_or(0) as f64;
    for &(dir, base, inc) in blocks {
        for (k, &v) in inc.iter().enumerate() {
            if v < lim.value_min || v > lim.value_max {
                let mag = opts.fanuc_magnification;
                let needed = (worst * mag as f64 / lim.value_max as f64).ceil() as u32;
                let u = t.kind.position_unit();
                return Err(usage(
                    format!(
                        "Fanuc point N{} ({dir}, {} {u}): increment {v} (units of {} x magnification {mag}) is outside {} ... {} of series {}",
                        10000 + base + k,
                        fixed(t.position(k), 4),
                        opts.fanuc_unit_um,
                        lim.value_min,
                        lim.value_max,
                        opts.fanuc_series.name()
                    ),
                    if needed <= lim.magnification_max {
                        format!(
                            "use {} {needed} (parameter 3623: coarser steps) or a smaller {}",
                            words(Setting::FanucMagnification),
                            words(Setting::Spacing)
                        )
                    } else {
                        format!(
                            "the error changes too fast for this spacing: choose a smaller {}",
                            words(Setting::Spacing)
                        )
                    },
                ));
            }
        }
    }
    Ok(())
}

pub(super) fn write(t: &ControllerTable, opts: &TableOptions) -> Result<String> {
    let l = layout(t, opts)?;
    let n = t.len();
    let r = l.reference_index;
    let (up, inc_up) = increments(t, &t.forward, l.step_units);
    let (down, inc_down) = increments(t, &t.reverse, l.step_units);
    check_range(
        t,
        opts,
        &[("forward", 0, &inc_up), ("reverse", n, &inc_down)],
    )?;
    let at_ref = down[r] - up[r];
    let lim = opts.fanuc_series.limits();
    if at_ref.abs() > lim.reference_value_max {
        return Err(usage(
            format!(
                "reversal at the reference point {at_ref} steps (parameter 3627) exceeds +-{} of series {}",
                lim.reference_value_max,
                opts.fanuc_series.name()
            ),
            format!("use a larger {}", words(Setting::FanucMagnification)),
        ));
    }
    let a = l.axis;
    let mut out = String::from("%\n");
    let _ = writeln!(out, "N3620A{a}P{r}");
    let _ = writeln!(out, "N3621A{a}P0");
    let _ = writeln!(out, "N3622A{a}P{}", n - 1);
    let _ = writeln!(out, "N3623A{a}P{}", opts.fanuc_magnification);
    let _ = writeln!(out, "N3624A{a}P{}", l.interval_counts);
    if t.kind == AxisKind::Rotary {
        let per_turn = (360.0 * 1e3 / opts.fanuc_unit_um).round() as i64;
        let _ = writeln!(out, "N3625A{a}P{per_turn}");
    }
    let _ = writeln!(out, "N3626A{a}P{n}");
    let _ = writeln!(out, "N3627A{a}P{at_ref}");
    for (block, inc) in [(0, &inc_up), (n, &inc_down)] {
        for (k, v) in inc.iter().enumerate() {
            let _ = writeln!(out, "N{}P{v}", 10000 + block + k);
        }
    }
    out.push_str("%\n");
    Ok(out)
}
