//! Stage 2, training-grid values: a cleaned part ([`Prepared`]) interpolated (or binned) onto the training grid, with and without its held-out points, and its kriging baseline's hold-out misses ([`Interpolated`]).

use super::read::{failed_part, Prepared};
use crate::plan::{PartInput, Settings};
use crate::summary::PartSummary;
use errmap_core::error::{Diagnostic, Result};
use errmap_core::geom::Domain;
use errmap_maps::interp::{self, Grid, Method, Surface};
use errmap_maps::probe::{self, ProbePoint};
use rayon::prelude::*;

/// A part with its training sets (values at training-grid nodes, `None` outside the hull).
pub(crate) struct Interpolated {
    pub(crate) prep: Prepared,
    pub(crate) full_nodes: Vec<Option<f64>>,
    pub(crate) holdout_nodes: Option<Vec<Option<f64>>>,
    /// Hold-out RMSE of the kriging baseline (fitted on the same kept points), µm.
    pub(crate) kriging_holdout_rmse_um: Option<f64>,
    /// The kriging baseline's misses at the held-out points, µm (empty without a hold-out).
    pub(crate) kriging_misses_um: Vec<f64>,
}

/// The training grid (the networks' training points) and the map grid (the outputs).
pub(crate) struct Grids {
    pub(crate) train: Grid,
    pub(crate) map: Grid,
}

impl Grids {
    pub(crate) fn new(domain: &Domain, s: &Settings) -> Result<Grids> {
        Ok(Grids {
            train: Grid::covering(domain, s.spacing_mm)?,
            map: Grid::covering(domain, s.grid_step_mm)?,
        })
    }
}

/// The map domain, checked to span an area.
pub(crate) fn checked_domain(domain: Option<Domain>) -> Result<Domain> {
    match domain {
        Some(d) if d.width_mm() > 0.0 && d.height_mm() > 0.0 => Ok(d),
        _ => Err(Diagnostic::usage(
            "the probe points span no area (zero width or height)",
            "give a map domain",
        )),
    }
}

/// A chunk's training-grid values (rayon); the parts that fail are summarised.
pub(crate) fn interpolate_all(
    parts: Vec<Prepared>,
    s: &Settings,
    train_grid: &Grid,
) -> (Vec<Interpolated>, Vec<PartSummary>) {
    let results: Vec<_> = parts
        .into_par_iter()
        .map(|p| interpolate(p, s, train_grid))
        .collect();
    let mut interpolated = Vec::new();
    let mut failed = Vec::new();
    for r in results {
        match r {
            Ok(p) => interpolated.push(p),
            Err(b) => failed.push(failed_part(&b.0, &b.1)),
        }
    }
    (interpolated, failed)
}

pub(crate) fn interpolate(
    prep: Prepared,
    s: &Settings,
    train_grid: &Grid,
) -> std::result::Result<Interpolated, Box<(PartInput, Diagnostic)>> {
    let full = match full_nodes(&prep, s, train_grid) {
        Ok(nodes) => nodes,
        Err(e) => return Err(Box::new((prep.input, e))),
    };
    let kriging_misses_um = kriging_holdout_misses(&prep).unwrap_or_default();
    let kriging_holdout_rmse_um = errmap_maps::map::rms_um(&kriging_misses_um);
    let holdout_nodes = if prep.holdout.is_empty() {
        None
    } else {
        match training_nodes(&probe::uve(&kept_points(&prep)), s, train_grid) {
            Ok(nodes) => Some(nodes),
            Err(e) => return Err(Box::new((prep.input, e))),
        }
    };
    if full.iter().flatten().count() < 3 {
        let e = Diagnostic::input(
            errmap_core::Location::file(&prep.input.probe_file),
            format!(
                "the probes' convex hull holds fewer than 3 nodes of the {} mm training grid",
                s.spacing_mm
            ),
            "use a smaller [interp] spacing_mm or probe a larger area",
        );
        return Err(Box::new((prep.input, e)));
    }
    Ok(Interpolated {
        prep,
        full_nodes: full,
        holdout_nodes,
        kriging_holdout_rmse_um,
        kriging_misses_um,
    })
}

/// The part's training-grid values from all its clean points (`None` outside their hull).
pub(crate) fn full_nodes(
    prep: &Prepared,
    s: &Settings,
    train_grid: &Grid,
) -> Result<Vec<Option<f64>>> {
    training_nodes(&probe::uve(&prep.clean), s, train_grid)
}

/// Training-grid values from points: binned where they are dense, interpolated with the
/// job's method otherwise ([`interp::bin`]).
pub(crate) fn training_nodes(
    uve: &[[f64; 3]],
    s: &Settings,
    train_grid: &Grid,
) -> Result<Vec<Option<f64>>> {
    if interp::bin::choose(uve, train_grid) == interp::bin::TrainingSource::Binned {
        return Ok(interp::bin::binned_nodes(uve, train_grid));
    }
    let surface = Surface::new(uve)?;
    if s.method == Method::Kriging {
        surface.kriging()?;
    }
    Ok(interp::resample(&surface, s.method, train_grid))
}

/// A family member's training-grid values: those of a part that interpolates (see
/// [`interpolate`]), without its kriging baseline; `None` for a part that does not.
pub(crate) fn member_nodes(
    prep: &Prepared,
    s: &Settings,
    train_grid: &Grid,
) -> Option<Vec<Option<f64>>> {
    let full = full_nodes(prep, s, train_grid).ok()?;
    if full.iter().flatten().count() < 3 {
        return None;
    }
    if !prep.holdout.is_empty() && Surface::new(&probe::uve(&kept_points(prep))).is_err() {
        return None;
    }
    Some(full)
}

/// The clean points the hold-out fits see: all but the held-out ones.
pub(crate) fn kept_points(prep: &Prepared) -> Vec<ProbePoint> {
    prep.clean
        .iter()
        .enumerate()
        .filter(|(i, _)| prep.holdout.binary_search(i).is_err())
        .map(|(_, p)| p.clone())
        .collect()
}

/// The kriging baseline a metrologist would compare the map with (exact up to
/// [`interp::baseline::EXACT_MAX_SITES`] points, local above): fitted on the points the
/// hold-out network saw, its misses at the held-out points (µm); `None` without a hold-out or
/// when the points cannot be kriged.
pub(crate) fn kriging_holdout_misses(prep: &Prepared) -> Option<Vec<f64>> {
    if prep.holdout.is_empty() {
        return None;
    }
    let k = interp::baseline::Baseline::fit(&probe::uve(&kept_points(prep))).ok()?;
    let at: Vec<[f64; 2]> = prep
        .holdout
        .iter()
        .map(|&i| [prep.clean[i].u_mm, prep.clean[i].v_mm])
        .collect();
    prep.holdout
        .iter()
        .zip(k.predict_many(&at))
        .map(|(&i, e)| Some(prep.clean[i].e_um - e?))
        .collect()
}
