//! Stage 4, evaluate: each trained part's delivered map on the map grid (the network's, or the kriging baseline's where it held out better), its hold-out figures, benefit and u(E) ([`Delivered`]); the part's files are written by [`super::part_files`].

use super::nodes::Interpolated;
use super::part_files::{better_fit, part_marks, write_part, Holdouts};
use super::read::failed_part;
use super::train::TrainingSets;
use crate::part_record::Marks;
use crate::plan::Settings;
use crate::summary::PartSummary;
use crate::timing::PartTiming;
use errmap_core::geom::{Axis, Domain};
use errmap_maps::interp::{self, Grid};
use errmap_maps::map::uncertainty::{self, Uncertainty};
use errmap_maps::map::{Benefit, ErrorMap, FittedModel};
use errmap_maps::nn::{Mlp, Normalisation};
use errmap_maps::probe;
use rayon::prelude::*;
use std::path::PathBuf;

/// What the steps after training share: the settings, the domain and map grid, the training
/// sets and their networks.
pub(crate) struct Fit<'a> {
    pub(crate) settings: &'a Settings,
    pub(crate) domain: Domain,
    pub(crate) grid: Grid,
    pub(crate) sets: &'a TrainingSets,
    pub(crate) nets: &'a [Mlp],
}

impl Fit<'_> {
    /// The fitted model of training slot `slot`.
    pub(crate) fn model(&self, name: &str, slot: usize) -> FittedModel {
        FittedModel::new(
            name,
            self.settings.normal,
            self.domain,
            self.sets.norms[slot].clone(),
            self.nets[slot].clone(),
        )
    }

    /// The delivered networks of the chunk's parts, in part order.
    pub(crate) fn delivered_nets(&self) -> Vec<Mlp> {
        self.sets
            .slots
            .iter()
            .map(|&(_, d)| self.nets[d].clone())
            .collect()
    }
}

/// The map grid's nodes in network inputs (the domain's scaling).
pub(crate) fn grid_inputs(domain: &Domain, grid: &Grid) -> Vec<[f32; 2]> {
    let scale = Normalisation::new(domain, &[]);
    let mut inputs = Vec::with_capacity(grid.len());
    for j in 0..grid.nv {
        for i in 0..grid.nu {
            let (u, v) = grid.node(i, j);
            inputs.push(scale.scale_input(u, v));
        }
    }
    inputs
}

/// A delivered part: its name, folder, map, model and marks.
pub(crate) struct PartMap {
    pub(crate) name: String,
    pub(crate) dir: Option<PathBuf>,
    pub(crate) map: ErrorMap,
    pub(crate) model: FittedModel,
    pub(crate) marks: Marks,
}

impl PartMap {
    /// The map's u(E) per node, when it has one.
    pub(crate) fn u_um(&self) -> Option<&[f64]> {
        self.model.uncertainty.as_ref().map(|u| u.u_um.as_slice())
    }
}

/// A chunk's outcome: every part's summary and the delivered maps, in batch order.
pub(crate) struct Delivered {
    pub(crate) summaries: Vec<PartSummary>,
    pub(crate) maps: Vec<PartMap>,
}

/// Every part's outputs of a chunk (rayon), each counted on `bar` as it is written.
pub(crate) fn write_parts(
    fit: &Fit,
    interpolated: &[Interpolated],
    outputs: &[Vec<f32>],
    timings: &[Option<PartTiming>],
    bar: &dyn errmap_core::progress::Progress,
) -> Delivered {
    let results: Vec<(PartSummary, Option<Fitted>)> = interpolated
        .par_iter()
        .zip(fit.sets.slots.par_iter())
        .zip(outputs.par_iter())
        .zip(timings.par_iter())
        .map(|(((p, &slots), out), timing)| {
            let r = deliver_part(fit, p, slots, out, timing.as_ref());
            bar.inc(1);
            r
        })
        .collect();
    let mut delivered = Delivered {
        summaries: Vec::new(),
        maps: Vec::new(),
    };
    for (summary, fitted) in results {
        if let Some((map, model, marks)) = fitted {
            delivered.maps.push(PartMap {
                name: summary.part.clone(),
                dir: summary.output_dir.clone(),
                map,
                model,
                marks,
            });
        }
        delivered.summaries.push(summary);
    }
    delivered
}

/// A part's delivered map, its model and its marks.
pub(crate) type Fitted = (ErrorMap, FittedModel, Marks);

/// One part's delivered map and model, written with its summary; a part that fails here is
/// summarised with its error.
pub(crate) fn deliver_part(
    fit: &Fit,
    p: &Interpolated,
    (h, d): (Option<usize>, usize),
    out: &[f32],
    timing: Option<&PartTiming>,
) -> (PartSummary, Option<Fitted>) {
    let s = fit.settings;
    let map = ErrorMap {
        grid: fit.grid,
        normal: s.normal,
        values: out
            .iter()
            .map(|&y| fit.sets.norms[d].unscale_output(y))
            .collect(),
    };
    let model = fit.model(&p.prep.input.name, d).with_probes(&p.prep.clean);
    let network_misses_um = h.map(|h| holdout_misses(p, &fit.model("holdout", h)));
    let holdout_rmse_um = network_misses_um
        .as_deref()
        .and_then(errmap_maps::map::rms_um);
    let (map, model) = match kriging_if_better(p, holdout_rmse_um) {
        Some(interp::baseline::Baseline::Exact(k)) => {
            (kriging_map(&k, fit.grid, s.normal), model.with_kriging(k))
        }
        Some(interp::baseline::Baseline::Local(k)) => {
            match local_kriging_map(&k, fit.grid, s.normal) {
                Some(m) => (m, model.with_local_kriging(&k)),
                None => (map, model),
            }
        }
        None => (map, model),
    };
    // The delivered map's hold-out figure, nested: each held-out point is predicted by the kind
    // chosen on the other held-out points, so the choice never sees the point it is judged on.
    let delivered_rmse_um = network_misses_um
        .as_deref()
        .and_then(|n| crate::nested::nested_holdout_rmse(n, &p.kriging_misses_um));
    let benefit = holdout_e_rms(p)
        .zip(delivered_rmse_um)
        .and_then(|(e, r)| Benefit::from_rms(e, r));
    let uncertainty = part_uncertainty(p, &map);
    let model = model.with_benefit(benefit).with_uncertainty(uncertainty);
    let stopping = timing.map(PartTiming::stopping);
    let axes = s.normal.plane_axes();
    let holdout = Holdouts {
        network_rmse_um: holdout_rmse_um,
        delivered_rmse_um,
    };
    match write_part(p, &map, &model, holdout, stopping, s, axes) {
        Ok(summary) => (summary, Some((map, model, part_marks(p)))),
        Err(e) => (failed_part(&p.prep.input, &e), None),
    }
}

/// RMS of E (about zero) at the part's held-out points, µm; `None` without any.
pub(crate) fn holdout_e_rms(p: &Interpolated) -> Option<f64> {
    let e: Vec<f64> = p
        .prep
        .holdout
        .iter()
        .map(|&i| p.prep.clean[i].e_um)
        .collect();
    errmap_maps::map::rms_um(&e)
}

/// A hold-out network's misses at the part's held-out points, µm.
pub(crate) fn holdout_misses(p: &Interpolated, holdout_model: &FittedModel) -> Vec<f64> {
    p.prep
        .holdout
        .iter()
        .map(|&i| {
            let q = &p.prep.clean[i];
            q.e_um - holdout_model.e_um(q.u_mm, q.v_mm)
        })
        .collect()
}

/// The kriging of every clean point, when it fits the held-out points better than the network
/// (fitted only then: it costs a likelihood search).
pub(crate) fn kriging_if_better(
    p: &Interpolated,
    network_holdout_rmse_um: Option<f64>,
) -> Option<interp::baseline::Baseline> {
    if better_fit(p, network_holdout_rmse_um) != Some("kriging") {
        return None;
    }
    interp::baseline::Baseline::fit(&probe::uve(&p.prep.clean)).ok()
}

/// A local kriging's values on the map grid; `None` if a node cannot be predicted.
pub(crate) fn local_kriging_map(
    k: &interp::local::LocalKriging,
    grid: Grid,
    normal: Axis,
) -> Option<ErrorMap> {
    let nodes: Vec<[f64; 2]> = (0..grid.nv)
        .flat_map(|j| (0..grid.nu).map(move |i| (i, j)))
        .map(|(i, j)| {
            let (u, v) = grid.node(i, j);
            [u, v]
        })
        .collect();
    let values: Option<Vec<f64>> = k
        .predict_many(&nodes)
        .into_iter()
        .map(|q| q.map(|q| q.e_um))
        .collect();
    Some(ErrorMap {
        grid,
        normal,
        values: values?,
    })
}

/// A kriging's values on the map grid.
pub(crate) fn kriging_map(k: &interp::kriging::Kriging, grid: Grid, normal: Axis) -> ErrorMap {
    let values = (0..grid.nv)
        .flat_map(|j| (0..grid.nu).map(move |i| (i, j)))
        .map(|(i, j)| {
            let (u, v) = grid.node(i, j);
            k.predict(u, v)
        })
        .collect();
    ErrorMap {
        grid,
        normal,
        values,
    }
}

/// The delivered map's u(E) on its grid (`errmap_maps::map::uncertainty`): c·max(σ_K, |E_map −
/// E_K|) at each node, σ_K and E_K the local kriging's of every clean point, c the factor its
/// cross-validation folds give; `None` when the points cannot be kriged (the map is delivered
/// without u).
pub(crate) fn part_uncertainty(p: &Interpolated, map: &ErrorMap) -> Option<Uncertainty> {
    let seed = crate::train_step::fnv1a(&p.prep.input.name) ^ 0x75_6e_63_65_72_74;
    let cal = uncertainty::calibrate(&probe::uve(&p.prep.clean), seed).ok()?;
    let noise_um = cal.kriging.parameters.noise_um();
    let factor = cal.factor;
    let g = map.grid;
    let nodes: Vec<[f64; 2]> = (0..g.nv)
        .flat_map(|j| (0..g.nu).map(move |i| (i, j)))
        .map(|(i, j)| {
            let (u, v) = g.node(i, j);
            [u, v]
        })
        .collect();
    let u_um: Option<Vec<f64>> = cal
        .kriging
        .predict_many(&nodes)
        .into_iter()
        .zip(&map.values)
        .map(|(q, e)| q.map(|q| round4(factor * q.sd_um.max((e - q.e_um).abs()))))
        .collect();
    Some(Uncertainty {
        method: "local-kriging-cv".into(),
        grid: g,
        u_um: u_um?,
        factor: Some(factor),
        noise_um: Some(noise_um),
    })
}

/// To 1e-4 (µm): what `map.csv` prints, so the file and `model.json` agree.
pub(crate) fn round4(x: f64) -> f64 {
    (x * 1e4).round() / 1e4
}
