//! Error maps: one fitted part (grid + model), family aggregation, and the map file formats.
//!
//! - [`FittedModel`] is `model.json`: the network, its normalisation, the domain and the normal —
//!   enough to evaluate the map anywhere without retraining ([`load_error_field`]).
//! - [`ErrorMap`] is the network evaluated on the output grid: `map.csv` (`x_mm,y_mm,e_um,u_um`
//!   for normal z; the plane's two axes otherwise; `u_um` is [`uncertainty`]'s u(E)).
//! - [`family_stats`] gives the family mean and standard-deviation maps.

pub mod grid_file;
pub mod uncertainty;

pub use crate::error::MapError;
use crate::interp::Grid;
use crate::nn::{Mlp, Normalisation};
use crate::Setting;
use errmap_core::error::{Error, Location, Result};
use errmap_core::geom::{Axis, Domain, ErrorField};
use errmap_core::setting::words;
use serde::{Deserialize, Serialize};
use std::path::Path;

/// Format tag written into every `model.json`.
pub const MODEL_FORMAT: &str = "errmap-map-model/1";

/// A part's measured domain: its probes' hull (plane axes, mm) and surface extent along the
/// normal, when recorded.
pub type PartDomain<'a> = (Option<&'a Vec<[f64; 2]>>, Option<[f64; 2]>);

/// A fitted map: `E(u, v) = unscale(net(scale(u, v)))` µm over `domain` (the file `model.json`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FittedModel {
    /// Format tag, [`MODEL_FORMAT`]; reading refuses a file with another.
    pub format: String,
    /// Part (or `family`) the map belongs to.
    pub name: String,
    /// Error direction; the map spans [`Axis::plane_axes`] of it.
    pub normal: Axis,
    /// Where the map is defined (plane axes, mm); outside it [`ErrorField::error_mm`] is `None`.
    pub domain: Domain,
    /// Scaling between `(u, v)` in mm, E in µm and the network's inputs and output.
    pub normalisation: Normalisation,
    /// The trained network; the delivered map unless `kriging` is present.
    pub network: Mlp,
    /// When present, the delivered map is this kriging of the probe points (it fitted the
    /// held-out points better than the network), and [`FittedModel::e_um`] evaluates it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub kriging: Option<crate::interp::kriging::Kriging>,
    /// When present, the delivered map is this local kriging of the probe points (a part of
    /// more points than the exact kriging takes, where it fitted the held-out points better
    /// than the network), and [`FittedModel::e_um`] evaluates it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub local_kriging: Option<crate::interp::local::LocalKrigingModel>,
    /// The measured domain: convex hull of the probed points (plane axes, mm), counter-clockwise.
    /// Absent in maps written by older versions (toolpath compensation then needs `--extrapolate`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub hull_mm: Option<Vec<[f64; 2]>>,
    /// Nominal extent `[min, max]` of the probed surface along the normal, mm.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub surface_mm: Option<[f64; 2]>,
    /// What the delivered map removes at the held-out probe points. Absent in maps written
    /// before errmap recorded it, and in maps without held-out points (the family map).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub benefit: Option<Benefit>,
    /// u(E) on the map grid ([`uncertainty::Uncertainty`]). Absent in maps written before
    /// errmap recorded it (`--max-uncertainty-um` then refuses the map).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub uncertainty: Option<uncertainty::Uncertainty>,
}

/// Below this share of E removed at the held-out points, `errmap compensate` refuses a map
/// unless `--allow-weak-map` (the scatter it would "correct" is noise).
pub const MIN_BENEFIT_SHARE: f64 = 0.10;

/// A map's benefit, judged at points its hold-out fit never saw.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Benefit {
    /// RMS of E (about zero) at the held-out probe points, µm.
    pub holdout_e_rms_um: f64,
    /// RMS of what remains after compensation there (E − hold-out map), µm.
    pub holdout_residual_rms_um: f64,
    /// 1 − residual RMS / E RMS: the share of E the map removes.
    pub share: f64,
}

/// RMS of values (about zero), µm; `None` for none.
pub fn rms_um(values: &[f64]) -> Option<f64> {
    if values.is_empty() {
        return None;
    }
    Some((values.iter().map(|v| v * v).sum::<f64>() / values.len() as f64).sqrt())
}

/// share = 1 − residual RMS / E RMS; `None` when E's RMS is zero or a figure is not finite.
pub fn benefit_share(holdout_e_rms_um: f64, holdout_residual_rms_um: f64) -> Option<f64> {
    let share = 1.0 - holdout_residual_rms_um / holdout_e_rms_um;
    (holdout_e_rms_um > 0.0 && share.is_finite()).then_some(share)
}

impl Benefit {
    /// From E and the residual after compensation at the held-out points (µm each).
    pub fn of(holdout_e_um: &[f64], holdout_residual_um: &[f64]) -> Option<Benefit> {
        Benefit::from_rms(rms_um(holdout_e_um)?, rms_um(holdout_residual_um)?)
    }

    /// From the two RMS figures, µm; `None` when the share is undefined.
    pub fn from_rms(e: f64, r: f64) -> Option<Benefit> {
        Some(Benefit {
            holdout_e_rms_um: e,
            holdout_residual_rms_um: r,
            share: benefit_share(e, r)?,
        })
    }
}

impl FittedModel {
    /// A network map of part `name`, tagged [`MODEL_FORMAT`], with no kriging, hull, surface
    /// extent or benefit recorded yet.
    pub fn new(
        name: &str,
        normal: Axis,
        domain: Domain,
        normalisation: Normalisation,
        network: Mlp,
    ) -> Self {
        FittedModel {
            format: MODEL_FORMAT.into(),
            name: name.into(),
            normal,
            domain,
            normalisation,
            network,
            kriging: None,
            local_kriging: None,
            hull_mm: None,
            surface_mm: None,
            benefit: None,
            uncertainty: None,
        }
    }

    /// Record the map's u(E) on its grid.
    pub fn with_uncertainty(mut self, uncertainty: Option<uncertainty::Uncertainty>) -> Self {
        self.uncertainty = uncertainty;
        self
    }

    /// Record the map's benefit at the held-out points.
    pub fn with_benefit(mut self, benefit: Option<Benefit>) -> Self {
        self.benefit = benefit;
        self
    }

    /// Refuse a map that removes less than [`MIN_BENEFIT_SHARE`] of E at its held-out points
    /// (unless `allow_weak`; `how_to_allow` names the flag or job key that allows it in the
    /// hint). A map without the figures is used: the returned warning says so.
    pub fn check_benefit(
        &self,
        allow_weak: bool,
        how_to_allow: &str,
        path: &Path,
    ) -> Result<Option<String>, MapError> {
        let Some(b) = self.benefit else {
            return Ok(Some(format!(
                "benefit unknown: {} was written before errmap recorded it (or has no held-out points); it is used as before",
                path.display()
            )));
        };
        if allow_weak || b.share >= MIN_BENEFIT_SHARE {
            return Ok(None);
        }
        Err(MapError::Weak(Error::input(
            Location::file(path),
            format!(
                "the map removes {:.1} % of E at its held-out points (RMS of E {:.3} µm, after compensation {:.3} µm), below the {:.0} % a map must remove to be used",
                b.share * 100.0,
                b.holdout_e_rms_um,
                b.holdout_residual_rms_um,
                MIN_BENEFIT_SHARE * 100.0
            ),
            format!("the surface's scatter is mostly noise: compensating with it moves the tool for nothing; {how_to_allow} to use it anyway"),
        )))
    }

    /// The map with nodes whose u(E) exceeds `max_um` treated as outside its domain (left
    /// nominal by a compensation); refused when the map has no u(E), naming `path`.
    pub fn bounded_by_uncertainty(
        &self,
        max_um: f64,
        path: &Path,
    ) -> Result<uncertainty::Bounded<'_>, MapError> {
        uncertainty::validate_max_uncertainty(max_um, &words(Setting::MaxUncertainty))?;
        let u = self.uncertainty.as_ref().ok_or_else(|| {
            Error::input(
                Location::file(path),
                format!(
                    "the map records no u(E) (written before errmap computed it, or its probe points could not be kriged), so {} cannot be applied",
                    words(Setting::MaxUncertainty)
                ),
                format!(
                    "refit the map with this version of errmap, or leave out {} (job key max_uncertainty_um)",
                    words(Setting::MaxUncertainty)
                ),
            )
        })?;
        Ok(uncertainty::Bounded {
            field: self,
            uncertainty: u,
            max_um,
        })
    }

    /// The same model delivering `kriging` instead of the network.
    pub fn with_kriging(mut self, kriging: crate::interp::kriging::Kriging) -> Self {
        self.kriging = Some(kriging);
        self
    }

    /// The same model delivering the local kriging `kriging` instead of the network.
    pub fn with_local_kriging(mut self, kriging: &crate::interp::local::LocalKriging) -> Self {
        self.local_kriging = Some(crate::interp::local::LocalKrigingModel::of(kriging));
        self
    }

    /// Record the measured domain and surface of the probed points the map was fitted to.
    pub fn with_probes(mut self, points: &[crate::probe::ProbePoint]) -> Self {
        let n = self.normal.index();
        let plane: Vec<[f64; 2]> = points.iter().map(|p| [p.u_mm, p.v_mm]).collect();
        self.hull_mm = Some(errmap_core::geom::convex_hull(&plane));
        self.surface_mm = points
            .iter()
            .map(|p| p.nominal_mm[n])
            .fold(None, |acc: Option<[f64; 2]>, z| {
                Some(acc.map_or([z, z], |[lo, hi]| [lo.min(z), hi.max(z)]))
            });
        self
    }

    /// Record the union of the parts' measured domains and surfaces (for a family map); none
    /// if a part lacks one.
    pub fn with_parts(self, parts: &[&FittedModel]) -> Self {
        let domains: Vec<PartDomain> = parts
            .iter()
            .map(|m| (m.hull_mm.as_ref(), m.surface_mm))
            .collect();
        self.with_domains(&domains)
    }

    /// [`FittedModel::with_parts`] from each part's (hull, surface) alone.
    pub fn with_domains(mut self, parts: &[PartDomain]) -> Self {
        let hulls: Option<Vec<&Vec<[f64; 2]>>> = parts.iter().map(|p| p.0).collect();
        let surfaces: Option<Vec<[f64; 2]>> = parts.iter().map(|p| p.1).collect();
        if let (Some(h), Some(s), false) = (hulls, surfaces, parts.is_empty()) {
            let all: Vec<[f64; 2]> = h.into_iter().flatten().copied().collect();
            self.hull_mm = Some(errmap_core::geom::convex_hull(&all));
            self.surface_mm = s
                .into_iter()
                .reduce(|a, b| [a[0].min(b[0]), a[1].max(b[1])]);
        }
        self
    }

    /// E at (u, v) in µm, evaluated anywhere (outside the domain the network extrapolates,
    /// the kriging returns towards its mean).
    pub fn e_um(&self, u_mm: f64, v_mm: f64) -> f64 {
        if let Some(k) = &self.kriging {
            return k.predict(u_mm, v_mm);
        }
        if let Some(k) = &self.local_kriging {
            return k.predict(u_mm, v_mm);
        }
        let x = self.normalisation.scale_input(u_mm, v_mm);
        self.normalisation.unscale_output(self.network.forward(x))
    }

    /// Largest |E| of the map over its domain, µm, sampled on a 129 × 129 grid of the
    /// domain (corners and edges included): what a compensation with it can move a point by.
    pub fn max_abs_e_um(&self) -> f64 {
        const N: usize = 129;
        let d = &self.domain;
        let mut worst = 0.0_f64;
        for j in 0..N {
            let v = d.v_min_mm + d.height_mm() * j as f64 / (N - 1) as f64;
            for i in 0..N {
                let u = d.u_min_mm + d.width_mm() * i as f64 / (N - 1) as f64;
                let e = self.e_um(u, v).abs();
                // NaN is the worst value of all.
                worst = if e.is_nan() {
                    f64::INFINITY
                } else {
                    worst.max(e)
                };
            }
        }
        worst
    }

    /// Refuse a map that would move a point by more than `max_mm` (a unit slip in the data it
    /// was fitted to, or a network that went wild), naming the file it came from.
    pub fn check_plausible(&self, max_mm: f64, path: &Path) -> Result<(), MapError> {
        let worst_um = self.max_abs_e_um();
        if worst_um <= max_mm * 1000.0 {
            return Ok(());
        }
        Err(MapError::Implausible(Error::input(
            Location::file(path),
            format!(
                "the map reaches |E| = {worst_um:.1} µm over its domain, beyond the plausibility bound of {max_mm} mm",
            ),
            format!(
                "a compensation that large is almost always a unit slip in the probe data (µm or inches written as mm); refit the map from corrected data, or raise {} if the part really is this far off",
                words(Setting::MaxDeviation)
            ),
        )))
    }

    /// Read and check a `model.json`.
    pub fn read(path: &Path) -> Result<FittedModel, MapError> {
        let text = errmap_core::io::read_text(path)?;
        let model: FittedModel = serde_json::from_str(&text).map_err(|e| {
            Error::input(
                Location::cell(path, e.line() as u64, e.column().to_string()),
                format!("not an errmap model.json: {e}"),
                "pass the model.json written by `errmap batch` or `errmap map`",
            )
        })?;
        if model.format != MODEL_FORMAT {
            return Err(Error::input(
                Location::file(path),
                format!("model format '{}' is not '{MODEL_FORMAT}'", model.format),
                "refit the map with this version of errmap",
            )
            .into());
        }
        let sizes = &model.network.layer_sizes;
        let expected: usize = sizes.windows(2).map(|w| w[0] * w[1] + w[1]).sum();
        if sizes.first() != Some(&2)
            || sizes.last() != Some(&1)
            || sizes.contains(&0)
            || model.network.params.len() != expected
            || !model.network.params.iter().all(|p| p.is_finite())
        {
            return Err(Error::input(
                Location::file(path),
                format!(
                    "network layers {:?} do not match its {} parameters (or a parameter is not finite)",
                    sizes,
                    model.network.params.len()
                ),
                "the file is damaged: refit the map",
            ).into());
        }
        if let Some(Err(m)) = model.uncertainty.as_ref().map(|u| u.validate()) {
            return Err(Error::input(
                Location::file(path),
                m,
                "the file is damaged: refit the map",
            )
            .into());
        }
        if let Some(Err(m)) = model.local_kriging.as_ref().map(|k| k.validate()) {
            return Err(Error::input(
                Location::file(path),
                m,
                "the file is damaged: refit the map",
            )
            .into());
        }
        if let Some(Err(m)) = model.kriging.as_ref().map(|k| k.validate()) {
            return Err(Error::input(
                Location::file(path),
                m,
                "the file is damaged: refit the map",
            )
            .into());
        }
        let n = &model.normalisation;
        let d = &model.domain;
        let finite = [
            n.u_min_mm,
            n.u_max_mm,
            n.v_min_mm,
            n.v_max_mm,
            n.e_mean_um,
            n.e_std_um,
            d.u_min_mm,
            d.u_max_mm,
            d.v_min_mm,
            d.v_max_mm,
        ]
        .iter()
        .all(|v| v.is_finite());
        let extra_finite = model
            .hull_mm
            .iter()
            .flatten()
            .flatten()
            .chain(model.surface_mm.iter().flatten())
            .all(|v| v.is_finite());
        if !finite || !extra_finite || d.u_min_mm > d.u_max_mm || d.v_min_mm > d.v_max_mm {
            return Err(Error::input(
                Location::file(path),
                "the normalisation or domain holds a non-finite number or an empty range",
                "the file is damaged: refit the map",
            )
            .into());
        }
        Ok(model)
    }
}

impl ErrorField for FittedModel {
    fn normal(&self) -> Axis {
        self.normal
    }
    fn error_mm(&self, u_mm: f64, v_mm: f64) -> Option<f64> {
        // A hair of tolerance so points on the domain's edge (rounded in a program) count as inside.
        let tol = 1e-9 * (1.0 + self.domain.width_mm().abs() + self.domain.height_mm().abs());
        let inside = u_mm >= self.domain.u_min_mm - tol
            && u_mm <= self.domain.u_max_mm + tol
            && v_mm >= self.domain.v_min_mm - tol
            && v_mm <= self.domain.v_max_mm + tol;
        inside.then(|| self.e_um(u_mm, v_mm) / 1000.0)
    }
    fn measured(&self, u_mm: f64, v_mm: f64, margin_mm: f64) -> Option<bool> {
        let hull = self.hull_mm.as_ref()?;
        let tol = 1e-9 * (1.0 + self.domain.width_mm().abs() + self.domain.height_mm().abs());
        Some(errmap_core::geom::hull_distance_mm(hull, [u_mm, v_mm]) <= margin_mm + tol)
    }
    fn surface_mm(&self) -> Option<(f64, f64)> {
        self.surface_mm.map(|[lo, hi]| (lo, hi))
    }
}

/// Load a fitted map (`model.json`) as an error field for toolpath compensation.
pub fn load_error_field(model_json: &Path) -> Result<Box<dyn ErrorField>, MapError> {
    Ok(Box::new(FittedModel::read(model_json)?))
}

/// A map on a regular grid of the plane: one value per node (index `j·nu + i`).
#[derive(Debug, Clone, PartialEq)]
pub struct ErrorMap {
    /// The nodes, on the plane axes of `normal`.
    pub grid: Grid,
    /// Axis the values are errors along.
    pub normal: Axis,
    /// One value per node, µm, index `j·nu + i`: E (measured − nominal), or for the family's
    /// standard-deviation map the node-wise spread of E.
    pub values: Vec<f64>,
}

impl ErrorMap {
    /// Peak-to-valley and RMS (about 0) of the values, µm.
    pub fn pv_rms_um(&self) -> (f64, f64) {
        let opts: Vec<Option<f64>> = self.values.iter().map(|&v| Some(v)).collect();
        errmap_core::numeric::pv_rms_um(&opts)
    }

    /// Which nodes lie outside the measured domain `hull_mm` (where the map extrapolates);
    /// all `false` when the hull is unknown.
    pub fn extrapolated_nodes(&self, hull_mm: Option<&[[f64; 2]]>) -> Vec<bool> {
        let Some(hull) = hull_mm else {
            return vec![false; self.values.len()];
        };
        let tol = 1e-9 * (1.0 + self.grid.step_mm);
        (0..self.grid.nv)
            .flat_map(|j| (0..self.grid.nu).map(move |i| (i, j)))
            .map(|(i, j)| {
                let (u, v) = self.grid.node(i, j);
                errmap_core::geom::hull_distance_mm(hull, [u, v]) > tol
            })
            .collect()
    }

    /// PV and RMS of the nodes whose `extrapolated` flag equals `which`, µm; `None` if none.
    pub fn pv_rms_where_um(&self, extrapolated: &[bool], which: bool) -> Option<(f64, f64)> {
        let opts: Vec<Option<f64>> = self
            .values
            .iter()
            .zip(extrapolated)
            .map(|(&v, &x)| (x == which).then_some(v))
            .collect();
        opts.iter()
            .any(|v| v.is_some())
            .then(|| errmap_core::numeric::pv_rms_um(&opts))
    }

    /// Write as CSV `<u>_mm,<v>_mm,<value_column>` (e.g. `x_mm,y_mm,e_um`), atomically.
    pub fn write_csv(&self, path: &Path, value_column: &str) -> Result<()> {
        self.write_csv_with_u(path, value_column, None)
    }

    /// Write as CSV `<u>_mm,<v>_mm,<value_column>[,u_um]`, atomically: with `u_um` (one value
    /// per node), u(E) is the fourth column (`map.csv`).
    pub fn write_csv_with_u(
        &self,
        path: &Path,
        value_column: &str,
        u_um: Option<&[f64]>,
    ) -> Result<()> {
        let (ua, va) = self.normal.plane_axes();
        errmap_core::io::write_atomic(path, |w| {
            let extra = if u_um.is_some() { ",u_um" } else { "" };
            writeln!(w, "{}_mm,{}_mm,{value_column}{extra}", ua.name(), va.name())?;
            for j in 0..self.grid.nv {
                for i in 0..self.grid.nu {
                    let k = j * self.grid.nu + i;
                    let (u, v) = self.grid.node(i, j);
                    let e = self.values.get(k).copied().unwrap_or(f64::NAN);
                    write!(w, "{},{},{:.4}", round_mm(u), round_mm(v), e)?;
                    if let Some(us) = u_um {
                        write!(w, ",{:.4}", us.get(k).copied().unwrap_or(f64::NAN))?;
                    }
                    writeln!(w)?;
                }
            }
            Ok(())
        })
    }
}

impl ErrorMap {
    /// Read a map file written by [`ErrorMap::write_csv`] (`<u>_mm,<v>_mm,<value>`, u fastest)
    /// and recover its grid; rows that do not form a regular grid are an error naming the line.
    pub fn read_csv(path: &Path, normal: Axis) -> Result<ErrorMap, MapError> {
        Ok(ErrorMap::read_csv_with_u(path, normal)?.0)
    }

    /// [`ErrorMap::read_csv`] and the `u_um` column when the file has one (`map.csv` since
    /// errmap wrote u(E); older three-column files give `None`). The value is the column after
    /// the coordinates (`e_um`, `std_um`, …) that is not `u_um`.
    pub fn read_csv_with_u(
        path: &Path,
        normal: Axis,
    ) -> Result<(ErrorMap, Option<Vec<f64>>), MapError> {
        let table = errmap_core::io::CsvTable::read(path)?;
        let (ua, va) = normal.plane_axes();
        let cu = table.require(&format!("{}_mm", ua.name()))?;
        let cv = table.require(&format!("{}_mm", va.name()))?;
        let cu_um = table.headers.iter().position(|h| h == "u_um");
        let ce = (0..table.headers.len())
            .rev()
            .find(|&c| c != cu && c != cv && Some(c) != cu_um)
            .ok_or_else(|| {
                Error::input(
                    Location::line(path, 1),
                    "no value column after the coordinates",
                    "write <u>_mm,<v>_mm,e_um",
                )
            })?;
        let mut rows = Vec::with_capacity(table.rows.len());
        let mut u_values = Vec::new();
        for row in &table.rows {
            rows.push((
                table.f64(row, cu)?,
                table.f64(row, cv)?,
                table.f64(row, ce)?,
                row.line,
            ));
            if let Some(c) = cu_um {
                u_values.push(table.f64(row, c)?);
            }
        }
        let first = rows.first().ok_or_else(|| {
            Error::input(
                Location::file(path),
                "the map has no rows",
                "map the part again",
            )
        })?;
        let (u0, v0) = (first.0, first.1);
        let nu = rows.iter().take_while(|r| r.1 == v0).count();
        let step = if nu > 1 {
            rows[1].0 - u0
        } else if rows.len() > 1 {
            rows[1].1 - v0
        } else {
            1.0
        };
        let nv = rows.len() / nu.max(1);
        let grid = Grid {
            u0_mm: u0,
            v0_mm: v0,
            step_mm: step,
            nu,
            nv,
        };
        let tol = 1e-5 * (1.0 + step.abs());
        let step_ok = step.is_finite() && step > 0.0;
        for (k, r) in rows.iter().enumerate() {
            let (u, v) = grid.node(k % nu, k / nu);
            if nu * nv != rows.len() || !step_ok || (r.0 - u).abs() > tol || (r.1 - v).abs() > tol {
                return Err(Error::input(
                    Location::line(path, r.3),
                    format!(
                        "({}, {}) is not node {k} of a regular grid ({u}, {v})",
                        r.0, r.1
                    ),
                    "pass map files written by errmap",
                )
                .into());
            }
        }
        let map = ErrorMap {
            grid,
            normal,
            values: rows.iter().map(|r| r.2).collect(),
        };
        Ok((map, cu_um.map(|_| u_values)))
    }
}

/// Coordinates to 1 nm, so 0.1 + 0.2 prints as 0.3.
fn round_mm(x: f64) -> f64 {
    let r = (x * 1e6).round() / 1e6;
    if r == 0.0 {
        0.0
    } else {
        r
    }
}

/// Node-wise mean and (population) standard deviation of maps on the same grid, µm.
pub fn family_stats(maps: &[&ErrorMap]) -> Option<(ErrorMap, ErrorMap)> {
    let first = maps.first()?;
    let n = maps.len() as f64;
    let len = first.values.len();
    if maps
        .iter()
        .any(|m| m.values.len() != len || m.grid != first.grid)
    {
        return None;
    }
    let mut mean = vec![0.0; len];
    let mut std = vec![0.0; len];
    for k in 0..len {
        let mu = maps.iter().map(|m| m.values[k]).sum::<f64>() / n;
        let var = maps.iter().map(|m| (m.values[k] - mu).powi(2)).sum::<f64>() / n;
        mean[k] = mu;
        std[k] = var.sqrt();
    }
    Some((
        ErrorMap {
            grid: first.grid,
            normal: first.normal,
            values: mean,
        },
        ErrorMap {
            grid: first.grid,
            normal: first.normal,
            values: std,
        },
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn accuracy_figures_split_at_the_measured_hull() {
        // Nodes at u = 0, 1, 2 (v = 0) with E = 1, −1, 5 µm; the hull covers u ∈ [0, 1]:
        // measured PV 2, RMS 1; extrapolated (u = 2 alone) PV 0, RMS 5.
        let map = ErrorMap {
            grid: Grid {
                u0_mm: 0.0,
                v0_mm: 0.0,
                step_mm: 1.0,
                nu: 3,
                nv: 1,
            },
            normal: Axis::Z,
            values: vec![1.0, -1.0, 5.0],
        };
        let hull = [[0.0, -1.0], [1.0, -1.0], [1.0, 1.0], [0.0, 1.0]];
        let x = map.extrapolated_nodes(Some(&hull));
        assert_eq!(x, vec![false, false, true]);
        assert_eq!(map.pv_rms_where_um(&x, false), Some((2.0, 1.0)));
        assert_eq!(map.pv_rms_where_um(&x, true), Some((0.0, 5.0)));
        assert_eq!(map.extrapolated_nodes(None), vec![false; 3]);
    }
    use crate::nn::Activation;

    fn tiny_model() -> FittedModel {
        // 2 → 1 → 1 tanh net: y = 2·tanh(0.5·x0 + 0) + 0.25.
        let net = Mlp {
            layer_sizes: vec![2, 1, 1],
            activation: Activation::Tanh,
            params: vec![0.5, 0.0, 0.0, 2.0, 0.25],
        };
        let domain = Domain {
            u_min_mm: 0.0,
            v_min_mm: 0.0,
            u_max_mm: 100.0,
            v_max_mm: 50.0,
        };
        let norm = Normalisation {
            u_min_mm: 0.0,
            u_max_mm: 100.0,
            v_min_mm: 0.0,
            v_max_mm: 50.0,
            e_mean_um: 10.0,
            e_std_um: 4.0,
        };
        FittedModel::new("p", Axis::Z, domain, norm, net)
    }

    #[test]
    fn model_evaluates_by_hand_and_round_trips_through_json() {
        let m = tiny_model();
        // u = 100 → x0 = 1: y = 2·tanh(0.5) + 0.25; E = 10 + 4·y µm.
        let y = 2.0 * 0.5f64.tanh() + 0.25;
        let expect_um = 10.0 + 4.0 * y;
        assert!((m.e_um(100.0, 20.0) - expect_um).abs() < 1e-5);
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("model.json");
        errmap_core::io::write_json(&path, &m).unwrap();
        let field = load_error_field(&path).unwrap();
        assert_eq!(field.normal(), Axis::Z);
        let e_mm = field.error_mm(100.0, 20.0).unwrap();
        assert!((e_mm - expect_um / 1000.0).abs() < 1e-8);
        assert!(field.error_mm(100.1, 20.0).is_none());
    }

    #[test]
    fn damaged_model_is_refused_with_the_reason() {
        let mut m = tiny_model();
        m.network.params.pop();
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("model.json");
        errmap_core::io::write_json(&path, &m).unwrap();
        let err = load_error_field(&path).err().unwrap().to_string();
        assert!(err.contains("do not match its 4 parameters"), "{err}");
        std::fs::write(&path, "{\"format\": 3}").unwrap();
        let err = load_error_field(&path).err().unwrap().to_string();
        assert!(err.contains("not an errmap model.json"), "{err}");
    }

    #[test]
    fn family_mean_and_std_by_hand() {
        let grid = Grid {
            u0_mm: 0.0,
            v0_mm: 0.0,
            step_mm: 1.0,
            nu: 2,
            nv: 1,
        };
        let a = ErrorMap {
            grid,
            normal: Axis::Z,
            values: vec![1.0, 4.0],
        };
        let b = ErrorMap {
            grid,
            normal: Axis::Z,
            values: vec![3.0, 4.0],
        };
        let (mean, std) = family_stats(&[&a, &b]).unwrap();
        assert_eq!(mean.values, vec![2.0, 4.0]);
        assert_eq!(std.values, vec![1.0, 0.0]);
        // A map file reads back onto the same grid.
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("mean.csv");
        mean.write_csv(&path, "e_um").unwrap();
        assert_eq!(ErrorMap::read_csv(&path, Axis::Z).unwrap(), mean);
        std::fs::write(&path, "x_mm,y_mm,e_um\n0,0,1\n1,0,2\n3,0,2\n").unwrap();
        let err = ErrorMap::read_csv(&path, Axis::Z).unwrap_err().to_string();
        assert!(
            err.contains("mean.csv:4") && err.contains("regular grid"),
            "{err}"
        );
    }

    #[test]
    fn map_files_with_and_without_the_u_column_read_alike() {
        let grid = Grid {
            u0_mm: 0.0,
            v0_mm: 0.0,
            step_mm: 2.5,
            nu: 2,
            nv: 2,
        };
        let map = ErrorMap {
            grid,
            normal: Axis::Z,
            values: vec![1.0, -2.0, 3.5, 0.25],
        };
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("map.csv");
        map.write_csv_with_u(&path, "e_um", Some(&[0.5, 0.75, 1.0, 1.25]))
            .unwrap();
        let text = std::fs::read_to_string(&path).unwrap();
        assert!(
            text.starts_with("x_mm,y_mm,e_um,u_um\n0,0,1.0000,0.5000\n2.5,0,-2.0000,0.7500\n"),
            "{text}"
        );
        let (back, u) = ErrorMap::read_csv_with_u(&path, Axis::Z).unwrap();
        assert_eq!(back, map);
        assert_eq!(u, Some(vec![0.5, 0.75, 1.0, 1.25]));
        // A three-column file of an older errmap: the same map, no u.
        std::fs::write(
            &path,
            "x_mm,y_mm,e_um\n0,0,1\n2.5,0,-2\n0,2.5,3.5\n2.5,2.5,0.25\n",
        )
        .unwrap();
        let (old, u) = ErrorMap::read_csv_with_u(&path, Axis::Z).unwrap();
        assert_eq!((old, u), (map.clone(), None));
        assert_eq!(ErrorMap::read_csv(&path, Axis::Z).unwrap(), map);
    }

    #[test]
    fn benefit_share_by_hand() {
        // E at 4 held-out points: 3, −3, 4, −4 µm → RMS √((9+9+16+16)/4) = √12.5.
        // Residuals after compensation 1, −1, 1, −1 µm → RMS 1. share = 1 − 1/√12.5 ≈ 0.71716.
        let b = Benefit::of(&[3.0, -3.0, 4.0, -4.0], &[1.0, -1.0, 1.0, -1.0]).unwrap();
        assert!((b.holdout_e_rms_um - 12.5_f64.sqrt()).abs() < 1e-12);
        assert_eq!(b.holdout_residual_rms_um, 1.0);
        assert!(
            (b.share - 0.717_157_287_525_381).abs() < 1e-12,
            "{}",
            b.share
        );
        // A map as wrong as the scatter itself removes nothing; a worse one removes less.
        assert_eq!(benefit_share(2.0, 2.0), Some(0.0));
        assert_eq!(benefit_share(2.0, 3.0), Some(-0.5));
        // No held-out points, or E identically zero: undefined, not invented.
        assert_eq!(Benefit::of(&[], &[]), None);
        assert_eq!(benefit_share(0.0, 0.0), None);
        assert_eq!(benefit_share(0.0, 1.0), None);
    }

    #[test]
    fn weak_maps_are_refused_unless_allowed() {
        let path = Path::new("p01/model.json");
        let mut m = tiny_model();
        let warning = m
            .check_benefit(false, "pass --allow-weak-map", path)
            .unwrap();
        assert!(warning.unwrap().starts_with("benefit unknown"));
        m.benefit = Benefit::from_rms(2.0, 1.9);
        let err = m
            .check_benefit(false, "pass --allow-weak-map", path)
            .unwrap_err();
        let text = err.to_string();
        assert!(
            text.contains("5.0 %") && text.contains("2.000 µm") && text.contains("1.900 µm"),
            "{text}"
        );
        assert!(text.contains("--allow-weak-map"), "{text}");
        assert_eq!(
            m.check_benefit(true, "pass --allow-weak-map", path)
                .unwrap(),
            None
        );
        m.benefit = Benefit::from_rms(2.0, 1.5);
        assert_eq!(m.check_benefit(false, "", path).unwrap(), None);
    }
}
