//! Stage 4, write a part: a delivered part's files in its folder ([`crate::PART_OUTPUTS`]: map, model, points, heatmaps, summary, and `reduce.json` for the reduce), its marks and hold-out figures, and its summary row ([`PartSummary`]).

use super::draw::{draw_shaded, draw_uncertainty};
use super::nodes::Interpolated;
use crate::part_record::Marks;
use crate::plan::Settings;
use crate::summary::PartSummary;
use crate::timing::Stopping;
use errmap_core::error::{Diagnostic, Result};
use errmap_core::geom::Axis;
use errmap_maps::map::uncertainty;
use errmap_maps::map::{Benefit, ErrorMap, FittedModel};
use errmap_maps::probe;
use errmap_report::heatmap::Scale;
use std::path::Path;

/// Write every file of one part and return its summary.
pub(crate) fn write_part(
    p: &Interpolated,
    map: &ErrorMap,
    model: &FittedModel,
    holdout: Holdouts,
    stopping: Option<Stopping>,
    s: &Settings,
    axes: (Axis, Axis),
) -> Result<PartSummary> {
    let dir = &p.prep.input.out_dir;
    let name = &p.prep.input.name;
    check_map_plausible(map, s.max_deviation_mm, &p.prep.input.probe_file)?;
    let u_um = model.uncertainty.as_ref().map(|u| u.u_um.as_slice());
    map.write_csv_with_u(&dir.join("map.csv"), "e_um", u_um)?;
    errmap_core::io::write_json(&dir.join("model.json"), model)?;
    probe::write_points_csv(&dir.join("clean.csv"), s.normal, &p.prep.clean)?;
    probe::write_rejected_csv(&dir.join("rejected.csv"), &p.prep.rejected)?;
    let marks = part_marks(p);
    if s.reduce_inputs {
        crate::part_record::PartReduce {
            part: name.clone(),
            holdout_fit: p.holdout_nodes.is_some(),
            train_nodes: p.full_nodes.clone(),
            map_e_um: map.values.clone(),
            map_u_um: u_um.map(<[f64]>::to_vec),
            hull_mm: model.hull_mm.clone(),
            surface_mm: model.surface_mm,
            marks: marks.clone(),
        }
        .write(dir)?;
    }
    let acc = Accuracy::of(map, model);
    // `errmap map` names the family after the part: say it once.
    let label = if s.family == *name {
        name.clone()
    } else {
        format!("{} {name}", s.family)
    };
    let title = format!(
        "{label} — PV {:.1} µm, RMS {:.1} µm (measured area)",
        acc.pv_um, acc.rms_um
    );
    draw_shaded(
        &dir.join("map.png"),
        &title,
        map,
        &marks,
        model.hull_mm.as_deref().unwrap_or(&[]),
        Scale::Diverging,
        axes,
        "E (µm)",
        &acc.extrapolated,
    )?;
    let u_figures = u_um.and_then(|u| uncertainty::median_max_um(u, &acc.extrapolated));
    draw_uncertainty(
        &dir.join("uncertainty.png"),
        &label,
        map,
        u_um,
        u_figures,
        &marks,
        model.hull_mm.as_deref().unwrap_or(&[]),
        axes,
        &acc.extrapolated,
    )?;
    let mut summary = part_summary(p, holdout, model.benefit, stopping, &acc);
    summary.u_median_um = u_figures.map(|f| f.0);
    summary.u_max_um = u_figures.map(|f| f.1);
    summary.u_factor = model.uncertainty.as_ref().and_then(|u| u.factor);
    summary.noise_um = model.uncertainty.as_ref().and_then(|u| u.noise_um);
    errmap_core::io::write_json(&dir.join("summary.json"), &summary)?;
    Ok(summary)
}

/// A fitted map whose value anywhere exceeds the plausibility bound is not delivered: the
/// network extrapolated wildly or the probe data hide a unit slip.
pub(crate) fn check_map_plausible(
    map: &ErrorMap,
    max_deviation_mm: f64,
    probe_file: &Path,
) -> Result<()> {
    let worst_um = map.values.iter().fold(0.0_f64, |m, v| m.max(v.abs()));
    if worst_um.is_finite() && worst_um <= max_deviation_mm * 1000.0 {
        return Ok(());
    }
    Err(Diagnostic::input(
        errmap_core::Location::file(probe_file),
        format!(
            "the fitted map reaches |E| = {worst_um:.1} µm, beyond the plausibility bound of {max_deviation_mm} mm",
        ),
        format!("check the probe file's units and nominal; if the part really is this far off, raise max_deviation_mm ({})", errmap_core::setting::words(errmap_maps::Setting::MaxDeviation)),
    ))
}

/// A map's accuracy figures over the measured domain, the extrapolated rest reported apart.
pub(crate) struct Accuracy {
    /// Nodes outside the measured hull.
    pub(crate) extrapolated: Vec<bool>,
    pub(crate) pv_um: f64,
    pub(crate) rms_um: f64,
    /// (PV, RMS) of the extrapolated nodes, µm; `None` when there are none.
    pub(crate) outside_um: Option<(f64, f64)>,
}

impl Accuracy {
    pub(crate) fn of(map: &ErrorMap, model: &FittedModel) -> Accuracy {
        let extrapolated = map.extrapolated_nodes(model.hull_mm.as_deref());
        let (pv_um, rms_um) = map
            .pv_rms_where_um(&extrapolated, false)
            .unwrap_or((0.0, 0.0));
        let outside_um = map.pv_rms_where_um(&extrapolated, true);
        Accuracy {
            extrapolated,
            pv_um,
            rms_um,
            outside_um,
        }
    }
}

/// The summary of a delivered part.
pub(crate) fn part_summary(
    p: &Interpolated,
    holdout: Holdouts,
    benefit: Option<Benefit>,
    stopping: Option<Stopping>,
    acc: &Accuracy,
) -> PartSummary {
    let extrapolated = &acc.extrapolated;
    PartSummary {
        part: p.prep.input.name.clone(),
        probe_file: p.prep.input.probe_file.clone(),
        ok: true,
        points: p.prep.points,
        repeats_averaged: p.prep.repeats_averaged,
        preamble_lines: p.prep.preamble_lines,
        skipped_features: p.prep.skipped_features,
        rejected: p.prep.rejected.len(),
        sigma_um: Some(p.prep.sigma_um),
        holdout_points: p.prep.holdout.len(),
        holdout_rmse_um: holdout.network_rmse_um,
        kriging_holdout_rmse_um: p.kriging_holdout_rmse_um,
        better_fit: better_fit(p, holdout.network_rmse_um).map(str::to_string),
        delivered_holdout_rmse_um: holdout.delivered_rmse_um,
        holdout_e_rms_um: benefit.map(|b| b.holdout_e_rms_um),
        benefit_share: benefit.map(|b| b.share),
        rms_um: Some(acc.rms_um),
        pv_um: Some(acc.pv_um),
        extrapolated_fraction: Some(
            extrapolated.iter().filter(|&&x| x).count() as f64 / extrapolated.len().max(1) as f64,
        ),
        rms_extrapolated_um: acc.outside_um.map(|o| o.1),
        pv_extrapolated_um: acc.outside_um.map(|o| o.0),
        stopping,
        u_median_um: None,
        u_max_um: None,
        u_factor: None,
        noise_um: None,
        output_dir: Some(p.prep.input.out_dir.clone()),
        error: None,
    }
}

/// The part's hold-out figures: the network's, and the delivered map's (nested).
#[derive(Debug, Clone, Copy)]
pub(crate) struct Holdouts {
    pub(crate) network_rmse_um: Option<f64>,
    pub(crate) delivered_rmse_um: Option<f64>,
}

/// `kriging` when its hold-out RMSE is below the network's (a tie keeps the network).
pub(crate) fn better_fit(
    p: &Interpolated,
    network_holdout_rmse_um: Option<f64>,
) -> Option<&'static str> {
    match (network_holdout_rmse_um, p.kriging_holdout_rmse_um) {
        (Some(n), Some(k)) => Some(if k < n { "kriging" } else { "network" }),
        _ => None,
    }
}

/// A part's kept and rejected probe points in the map plane.
pub(crate) fn part_marks(p: &Interpolated) -> Marks {
    Marks {
        probes: p.prep.clean.iter().map(|q| (q.u_mm, q.v_mm)).collect(),
        rejected: p
            .prep
            .rejected
            .iter()
            .map(|r| (r.point.u_mm, r.point.v_mm))
            .collect(),
        totals: None,
    }
}
