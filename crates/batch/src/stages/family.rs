//! Stage 5, family reduce: the family's running sums ([`FamilyMaps`], [`FamilyNodes`]) made its network, its mean, spread and u(E) maps and its folder ([`FamilySummary`], the family's [`FittedModel`]) — the same for a run, a resumed run and the merge of shards.

use super::draw::{draw_shaded, draw_uncertainty};
use super::evaluate::round4;
use super::part_files::check_map_plausible;
use super::train::training_set;
use crate::family_sums::{FamilyMaps, FamilyNodes};
use crate::plan::Settings;
use crate::summary::FamilySummary;
use crate::train_step::train_family;
use errmap_core::error::Result;
use errmap_core::geom::Domain;
use errmap_maps::interp::Grid;
use errmap_maps::map::uncertainty::{self, Uncertainty};
use errmap_maps::map::{ErrorMap, FittedModel};
use errmap_maps::nn::{Mlp, Normalisation, Trainer};
use errmap_report::heatmap::Scale;
use std::path::Path;

/// The family network fitted to the members' node-wise mean, with its normalisation; `None`
/// without members or with fewer than 3 nodes every member has.
pub(crate) fn family_network(
    trainer: &dyn Trainer,
    nodes: &FamilyNodes,
    train_grid: &Grid,
    domain: &Domain,
    s: &Settings,
) -> Result<Option<(Mlp, Normalisation)>> {
    let Some(mean) = nodes.mean() else {
        return Ok(None);
    };
    let (set, norm) = training_set(train_grid, &mean, domain);
    Ok(Some((train_family(trainer, &set, &s.model)?, norm)))
}

/// What the family stage is given once every part is mapped: the family folder, the map
/// domain, the family network and the parts' running sums.
pub(crate) struct FamilyInput<'a> {
    /// The family folder (a staging folder while the run or the merge writes it).
    pub(crate) dir: &'a Path,
    /// The map domain of every part.
    pub(crate) domain: Domain,
    /// The family network with its normalisation.
    pub(crate) network: (Mlp, Normalisation),
    /// The delivered parts' running sums, in batch order.
    pub(crate) maps: &'a FamilyMaps,
    /// The file a family mean beyond the plausibility bound is an error of (the job, or the
    /// family folder without one); `None`: not checked (the reduce, which takes maps that were
    /// checked one by one).
    pub(crate) check_against: Option<&'a Path>,
}

/// The family folder from the parts' sums: the mean from the running sums, the spread from
/// the delivered maps taken `again` (batch order), the family network's model; `None` without
/// a delivered map.
pub(crate) fn write_family_folder(
    input: FamilyInput,
    again: impl Iterator<Item = Result<Vec<f64>>>,
    s: &Settings,
) -> Result<Option<(FamilySummary, FittedModel)>> {
    let Some(mean) = input.maps.mean() else {
        return Ok(None);
    };
    let std = input.maps.std_map(&mean, again)?;
    if let Some(file) = input.check_against {
        check_map_plausible(&mean, s.max_deviation_mm, file)?;
    }
    let (net, norm) = input.network;
    let model = FittedModel::new("family", s.normal, input.domain, norm, net);
    write_family(input.dir, &mean, &std, model, input.maps, s).map(Some)
}

/// The family folder: mean and std maps (CSV, heatmaps with every part's probe and rejected
/// points and the family's measured hull), the family map's u(E) (`uncertainty.png`, when
/// every part has one) and the family network's `model.json`, which is returned with the
/// parts' measured domain and that u.
fn write_family(
    dir: &Path,
    mean: &ErrorMap,
    std: &ErrorMap,
    model: FittedModel,
    maps: &FamilyMaps,
    s: &Settings,
) -> Result<(FamilySummary, FittedModel)> {
    let model = family_model(model, maps, std);
    mean.write_csv(&dir.join("mean.csv"), "e_um")?;
    std.write_csv(&dir.join("std.csv"), "std_um")?;
    let extrapolated = mean.extrapolated_nodes(model.hull_mm.as_deref());
    let (pv, rms) = mean
        .pv_rms_where_um(&extrapolated, false)
        .unwrap_or_else(|| mean.pv_rms_um());
    let std_max = std.values.iter().cloned().fold(0.0, f64::max);
    let pictures = FamilyPictures {
        dir,
        marks: &maps.marks().to_marks(),
        hull: model.hull_mm.as_deref().unwrap_or(&[]),
        extrapolated: &extrapolated,
        s,
    };
    pictures.mean(mean, maps.count(), pv, rms)?;
    pictures.spread(std, std_max)?;
    let u_um = model.uncertainty.as_ref().map(|u| u.u_um.as_slice());
    let u_figures = u_um.and_then(|u| uncertainty::median_max_um(u, &extrapolated));
    pictures.uncertainty(mean, u_um, u_figures)?;
    errmap_core::io::write_json(&dir.join("model.json"), &model)?;
    let summary = FamilySummary {
        parts: maps.count(),
        output_dir: dir.to_path_buf(),
        mean_rms_um: rms,
        mean_pv_um: pv,
        std_max_um: std_max,
        u_median_um: u_figures.map(|f| f.0),
        u_max_um: u_figures.map(|f| f.1),
    };
    Ok((summary, model))
}

/// The family network's model with the parts' measured domain (hull and surface span) and
/// the family map's u(E).
fn family_model(mut model: FittedModel, maps: &FamilyMaps, std: &ErrorMap) -> FittedModel {
    if let Some((hull, surface)) = maps.domain() {
        model.hull_mm = Some(hull);
        model.surface_mm = Some(surface);
    }
    let u = maps
        .u_squared_sum()
        .and_then(|q| family_uncertainty(std, q, maps.count()));
    model.with_uncertainty(u)
}

/// The family's heatmaps: every part's marks, the family's hull, the extrapolated nodes.
struct FamilyPictures<'a> {
    dir: &'a Path,
    marks: &'a crate::part_record::Marks,
    hull: &'a [[f64; 2]],
    extrapolated: &'a [bool],
    s: &'a Settings,
}

impl FamilyPictures<'_> {
    /// `mean.png`: the mean map with its PV and RMS over the measured area.
    fn mean(&self, mean: &ErrorMap, parts: usize, pv: f64, rms: f64) -> Result<()> {
        let title = format!(
            "{} family mean of {parts} parts — PV {pv:.1} µm, RMS {rms:.1} µm (measured area)",
            self.s.family
        );
        draw_shaded(
            &self.dir.join("mean.png"),
            &title,
            mean,
            self.marks,
            self.hull,
            Scale::Diverging,
            self.s.normal.plane_axes(),
            "mean E (µm)",
            self.extrapolated,
        )
    }

    /// `std.png`: the part-to-part standard deviation.
    fn spread(&self, std: &ErrorMap, std_max: f64) -> Result<()> {
        let title = format!(
            "{} part-to-part standard deviation — max {std_max:.2} µm",
            self.s.family
        );
        draw_shaded(
            &self.dir.join("std.png"),
            &title,
            std,
            self.marks,
            self.hull,
            Scale::Sequential,
            self.s.normal.plane_axes(),
            "σ of E (µm)",
            self.extrapolated,
        )
    }

    /// `uncertainty.png`: the family map's u(E).
    fn uncertainty(
        &self,
        mean: &ErrorMap,
        u_um: Option<&[f64]>,
        u_figures: Option<(f64, f64)>,
    ) -> Result<()> {
        draw_uncertainty(
            &self.dir.join("uncertainty.png"),
            &format!("{} family", self.s.family),
            mean,
            u_um,
            u_figures,
            self.marks,
            self.hull,
            self.s.normal.plane_axes(),
            self.extrapolated,
        )
    }
}

/// The family map's u(E) per node: √(std² + Σ u_i² / N²) — how far the next part may stand
/// from the family mean, and how well the parts' maps know their own parts.
pub(crate) fn family_uncertainty(
    std: &ErrorMap,
    u_squared_sum: &[f64],
    n: usize,
) -> Option<Uncertainty> {
    if n == 0 || u_squared_sum.len() != std.values.len() {
        return None;
    }
    let u_um = std
        .values
        .iter()
        .zip(u_squared_sum)
        .map(|(s, q)| round4((s.powi(2) + q / (n * n) as f64).sqrt()))
        .collect();
    Some(Uncertainty {
        method: "family".into(),
        grid: std.grid,
        u_um,
        factor: None,
        noise_um: None,
    })
}
