//! The composite geometric + thermal model of seed 004, one per direction, fitted to campaigns:
//! `E(x, T) = Er(x) + tanβ·(x − Px)`, `tanβ = Σ k_j·ΔT_j (per coolant state) + ρ·ΔT_env`.
//!
//! Sign conventions (errmap's, see docs/thermal.md):
//! - E is the positioning error, measured − target (µm), as in the run files.
//! - Er(x) is the cold pitch error: Legendre series in s = (2x − x_min − x_max)/(x_max − x_min).
//! - The thermal part is `tanβ·(x − Px)`: the error lines fan about the reference point Px; a
//!   screw that grows away from Px gives positive k. (Seed 004 writes `tanβ·(Px − P0)` with P0
//!   the current position; that is the same model with the sign of tanβ flipped.) tanβ is in
//!   µm/m, so `E_um = Er_um + tanβ_um_per_m·(x_mm − Px_mm)/1000`, and k_j, ρ are in µm/m/K.
//! - ΔT_j is the rise of sensor j above the ambient relative to the cold reference state:
//!   `ΔT_j = (T_j − T_amb) − (T_j − T_amb)_ref`; ΔT_env = T_amb − T_amb,ref. A uniform change
//!   of the room thus moves ΔT_env only (the ρ term), the machine's own heating moves ΔT_j.
//!   Without an ambient sensor ΔT_j = T_j − T_j,ref and there is no ρ term.
//! - The compensation value sent to the controller is −E (P' = P − E).
//!
//! The reference state is taken one of four ways ([`Reference`]), chosen by
//! leave-one-campaign-out cross-validation unless given: the room itself (rises above the
//! ambient, calibrated sensors reading alike at rest), one cold state shared by all campaigns
//! (the mean of their cold measurements), each campaign's own cold measurement (seed 000's
//! thermal difference), or the shared state plus an explicit per-campaign offset of tanβ (sum
//! zero over the campaigns), which absorbs whatever a campaign's cold state holds.
//!
//! All coefficients of one direction are fitted in one linear least-squares problem over every
//! reading of every campaign (the multiple linear regression of tanβ on the rises, with the
//! pitch polynomial fitted jointly), giving standard errors for each. The polynomial order is
//! chosen by leave-one-target-out cross-validation, capped, or given.
//!
//! Gains and reference rises are JSON maps keyed by sensor name, and the gain sensors are kept
//! in name order, so the same campaigns give the same JSON whichever route they were read by.

use super::campaign::{direction_name, Campaign, Direction, Measurement, DIRECTIONS};
use super::lsq::{legendre_into, legendre_sum, lstsq};
use super::sensors::{Role, Sensor};
use crate::Setting;
use errmap_core::error::{Error, Result};
use errmap_core::setting::words;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

/// File format tag of model.json.
pub const MODEL_FORMAT: &str = "errmap-thermal-model/2";

/// Where the rises ΔT are measured from.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Reference {
    /// The room itself: ΔT_j = T_j − T_amb (calibrated sensors read alike at rest); needs an
    /// ambient sensor.
    Room,
    /// One cold state for all campaigns: the mean of their first measurements.
    #[default]
    Shared,
    /// Each campaign's own first (cold) measurement (the rises; the room keeps the shared one).
    OwnStart,
    /// The shared cold state plus a fitted tanβ offset per campaign (sum zero).
    CampaignOffset,
}

impl Reference {
    /// Fewest fitted quantities first: a near tie in cross-validation keeps the earlier one.
    pub const ALL: [Reference; 4] = [
        Reference::Room,
        Reference::Shared,
        Reference::OwnStart,
        Reference::CampaignOffset,
    ];

    /// The reference's name in model.json and on the command line (`room`, `shared`, `own-start`,
    /// `campaign-offset`).
    pub fn name(self) -> &'static str {
        match self {
            Reference::Room => "room",
            Reference::Shared => "shared",
            Reference::OwnStart => "own-start",
            Reference::CampaignOffset => "campaign-offset",
        }
    }

    /// The reference a name (as [`Reference::name`] spells it) stands for; None for an unknown name.
    pub fn parse(text: &str) -> Option<Reference> {
        Reference::ALL.into_iter().find(|r| r.name() == text)
    }
}

/// Cross-validation score of one reference.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ReferenceScore {
    /// The reference scored.
    pub reference: Reference,
    /// Pooled leave-one-campaign-out RMS (µm) of the measurements after each cold one.
    pub loco_rms_um: Option<f64>,
    /// Why there is no score, if there is none.
    pub note: Option<String>,
}

/// How to fit.
#[derive(Debug, Clone, PartialEq)]
pub struct FitOptions {
    /// Sensors whose rises drive tanβ; `None` = every sensor with role nut or bearing.
    pub sensors: Option<Vec<String>>,
    /// Highest polynomial order cross-validation may choose.
    pub max_order: usize,
    /// A fixed order instead of cross-validation.
    pub order: Option<usize>,
    /// ρ given (µm/m/K); `None` = fitted when there is an ambient sensor.
    pub rho_um_per_m_k: Option<f64>,
    /// Px (mm); `None` = the campaigns' `reference_point_mm` (which must agree).
    pub reference_point_mm: Option<f64>,
    /// Leave-one-campaign-out cross-validation of the residual.
    pub leave_one_out: bool,
    /// The rises' reference; `None` = chosen by leave-one-campaign-out cross-validation.
    pub reference: Option<Reference>,
}

impl Default for FitOptions {
    fn default() -> Self {
        FitOptions {
            sensors: None,
            max_order: 8,
            order: None,
            rho_um_per_m_k: None,
            reference_point_mm: None,
            leave_one_out: true,
            reference: None,
        }
    }
}

/// Gains of one coolant state.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CoolantGains {
    /// The coolant state's label, as the campaigns give it (e.g. `on`, `off`).
    pub coolant: String,
    /// k_j in µm/m/K, keyed by sensor name.
    pub k_um_per_m_k: BTreeMap<String, f64>,
    /// Standard error of each k_j (µm/m/K), by sensor name; None when the fit has no degrees of
    /// freedom left.
    pub k_se_um_per_m_k: BTreeMap<String, Option<f64>>,
}

/// The model of one direction.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DirectionModel {
    /// The direction of travel this model is for.
    pub direction: Direction,
    /// The order of the Legendre series of Er(x) (0: a constant).
    pub order: usize,
    /// "cross-validation" or "given".
    pub order_chosen_by: String,
    /// Leave-one-target-out RMS (µm) for orders 0, 1, … (None: not tried or not computable).
    pub cv_rms_um_by_order: Vec<Option<f64>>,
    /// Er(x) = Σ c_n·P_n(s), µm.
    pub legendre_um: Vec<f64>,
    /// Standard error of each Legendre coefficient (µm), same order; None without degrees of freedom.
    pub legendre_se_um: Vec<Option<f64>>,
    /// The gains k_j of each coolant state, in the model's `coolant_states` order.
    pub gains: Vec<CoolantGains>,
    /// ρ, the gain of the room's change ΔT_env (µm/m/K): fitted, given, or 0 without an ambient
    /// sensor.
    pub rho_um_per_m_k: f64,
    /// Standard error of ρ (µm/m/K); None when ρ was given, not fitted, or the fit has no degrees
    /// of freedom left.
    pub rho_se_um_per_m_k: Option<f64>,
    /// Whether ρ was fitted (an ambient sensor and no given ρ), rather than given or 0.
    pub rho_fitted: bool,
    /// With reference "campaign-offset": each campaign's tanβ offset (µm/m, sum zero).
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub campaign_offsets_um_per_m: BTreeMap<String, f64>,
    /// RMS of measured − modelled E over every reading of this direction in the fit (µm).
    pub residual_rms_um: f64,
    /// Readings of this direction in the fit (every campaign, every measurement).
    pub points: usize,
}

/// Residuals of one campaign.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CampaignReport {
    /// The campaign's name.
    pub name: String,
    /// The campaign's coolant state label.
    pub coolant: String,
    /// Measurements in the campaign (each: the laser readings taken at one thermal state).
    pub measurements: usize,
    /// The campaign's readings in the fit, both directions.
    pub points: usize,
    /// RMS of measured − modelled error of the full fit (µm), both directions.
    pub residual_rms_um: f64,
    /// RMS when the model is fitted without this campaign (µm), both directions.
    pub loco_rms_um: Option<f64>,
    /// Why there is no leave-one-out figure, if there is none.
    pub loco_note: Option<String>,
}

/// The fitted composite model (model.json).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ThermalModel {
    /// File format tag, `errmap-thermal-model/2`; a model file of another format is refused.
    pub format: String,
    /// Axis name of the fitted campaigns (e.g. `X`).
    pub axis: String,
    /// Px: the point the thermal error lines fan about (mm).
    pub reference_point_mm: f64,
    /// Lower end of the travel covered by the fitting campaigns, mm (s = −1); Er(x) is held at
    /// these ends outside it.
    pub x_min_mm: f64,
    /// Upper end of the travel covered by the fitting campaigns, mm (s = +1).
    pub x_max_mm: f64,
    /// Sensors tanβ depends on, in gain order.
    pub gain_sensors: Vec<String>,
    /// The ambient sensor, if the model has one.
    pub ambient_sensor: Option<String>,
    /// Sensor definitions (unit, calibration) used to read machine logs.
    pub sensors: Vec<Sensor>,
    /// How the rises were referenced in the fit: `room`, `shared`, `own-start` or
    /// `campaign-offset`.
    #[serde(default)]
    pub reference: Reference,
    /// "cross-validation", "given" or a default.
    #[serde(default)]
    pub reference_chosen_by: String,
    /// Leave-one-campaign-out score of each reference tried.
    #[serde(default)]
    pub reference_cv: Vec<ReferenceScore>,
    /// (T_j − T_amb) (or T_j without ambient) in the cold reference state, °C, by sensor:
    /// the mean of the campaigns' cold measurements (zeros with the `room` reference).
    pub reference_rise_c: BTreeMap<String, f64>,
    /// Ambient temperature of the cold reference state, °C.
    pub reference_ambient_c: Option<f64>,
    /// Coolant state labels of the fitted campaigns; each direction has gains per state, in this
    /// order.
    pub coolant_states: Vec<String>,
    /// Forward then reverse.
    pub directions: Vec<DirectionModel>,
    /// Residuals of each fitted campaign, in the full fit and held out.
    pub campaigns: Vec<CampaignReport>,
    /// Pooled leave-one-campaign-out RMS (µm) over campaigns that have one.
    pub loco_rms_um: Option<f64>,
}

/// Temperatures of one thermal state, as the model needs them.
#[derive(Debug, Clone, PartialEq)]
pub struct ThermalState {
    /// Calibrated temperatures of the gain sensors (°C), model order.
    pub sensors_c: Vec<f64>,
    /// Calibrated ambient temperature (°C), if the model has an ambient sensor.
    pub ambient_c: Option<f64>,
    /// Index into `coolant_states`.
    pub coolant: usize,
}

/// One reading prepared for the regression.
#[derive(Debug, Clone)]
struct Obs {
    campaign: usize,
    measurement: usize,
    direction: Direction,
    x_mm: f64,
    y_um: f64,
    target_key: i64,
}

/// Rises of one measurement.
#[derive(Debug, Clone)]
struct Rises {
    /// T_j − T_amb (or T_j) per gain sensor, before subtracting the reference.
    above_c: Vec<f64>,
    ambient_c: Option<f64>,
    coolant: usize,
}

struct Prepared {
    gain_sensors: Vec<String>,
    ambient: Option<String>,
    coolant_states: Vec<String>,
    reference_point_mm: f64,
    x_min_mm: f64,
    x_max_mm: f64,
    /// rises[campaign][measurement]
    rises: Vec<Vec<Rises>>,
    obs: Vec<Obs>,
}

fn choose_sensors(campaigns: &[Campaign], options: &FitOptions) -> Result<Vec<String>> {
    let first = &campaigns[0];
    let names: Vec<String> = match &options.sensors {
        Some(list) => list.clone(),
        None => first
            .sensors
            .sensors
            .iter()
            .filter(|s| matches!(s.role, Role::Nut | Role::Bearing))
            .map(|s| s.name.clone())
            .collect(),
    };
    let mut names = names;
    names.sort();
    names.dedup();
    if names.is_empty() {
        return Err(Error::usage(
            "no sensors to fit the gains on",
            format!(
                "mark sensors as nut or bearing in the sensor table, or name them with {}",
                words(Setting::Sensors)
            ),
        ));
    }
    Ok(names)
}

fn prepare(campaigns: &[Campaign], options: &FitOptions) -> Result<Prepared> {
    if campaigns.is_empty() {
        return Err(Error::usage(
            "no campaigns to fit",
            "give at least one campaign",
        ));
    }
    let gain_sensors = choose_sensors(campaigns, options)?;
    let ambient = campaigns[0]
        .sensors
        .with_role(Role::Ambient)
        .map(|s| s.name.clone());
    let reference_point_mm = common_reference_point(campaigns, options)?;
    let coolant_states = coolant_states(campaigns);
    let mut rises = Vec::new();
    let mut obs = Vec::new();
    for (ci, c) in campaigns.iter().enumerate() {
        if c.sensors.with_role(Role::Ambient).map(|s| &s.name) != ambient.as_ref() {
            return Err(Error::usage(
                format!(
                    "campaign '{}' has a different ambient sensor from '{}'",
                    c.name, campaigns[0].name
                ),
                "use one sensor table for all campaigns of a model",
            ));
        }
        let coolant = coolant_states
            .iter()
            .position(|s| s == &c.coolant)
            .unwrap_or(0);
        let inputs = (gain_sensors.as_slice(), ambient.as_deref(), coolant);
        rises.push(campaign_observations(ci, c, inputs, &mut obs)?);
    }
    let x_min_mm = obs.iter().map(|o| o.x_mm).fold(f64::INFINITY, f64::min);
    let x_max_mm = obs.iter().map(|o| o.x_mm).fold(f64::NEG_INFINITY, f64::max);
    if x_max_mm - x_min_mm <= 0.0 {
        return Err(Error::usage(
            "all readings are at one target position",
            "measure the axis at several target positions",
        ));
    }
    Ok(Prepared {
        gain_sensors,
        ambient,
        coolant_states,
        reference_point_mm,
        x_min_mm,
        x_max_mm,
        rises,
        obs,
    })
}

/// Px: the option, else the one reference point every campaign shares.
fn common_reference_point(campaigns: &[Campaign], options: &FitOptions) -> Result<f64> {
    if let Some(p) = options.reference_point_mm {
        return Ok(p);
    }
    let p = campaigns[0].reference_point_mm;
    if let Some(c) = campaigns.iter().find(|c| c.reference_point_mm != p) {
        return Err(Error::usage(
            format!(
                "campaigns '{}' and '{}' have different reference points ({} and {} mm)",
                campaigns[0].name, c.name, p, c.reference_point_mm
            ),
            format!(
                "give one reference point with {}",
                words(Setting::ReferenceMm)
            ),
        ));
    }
    Ok(p)
}

/// The campaigns' coolant states, sorted, each once.
fn coolant_states(campaigns: &[Campaign]) -> Vec<String> {
    let mut states: Vec<String> = Vec::new();
    for c in campaigns {
        if !states.contains(&c.coolant) {
            states.push(c.coolant.clone());
        }
    }
    states.sort();
    states
}

/// The rises of each measurement of campaign `ci`, whose readings are appended to `obs`.
/// `inputs`: the gain sensors, the ambient sensor and the campaign's coolant index.
fn campaign_observations(
    ci: usize,
    c: &Campaign,
    (gain_sensors, ambient, coolant): (&[String], Option<&str>, usize),
    obs: &mut Vec<Obs>,
) -> Result<Vec<Rises>> {
    let mut per_m = Vec::new();
    for (mi, m) in c.measurements.iter().enumerate() {
        per_m.push(measurement_rises(c, m, gain_sensors, ambient, coolant)?);
        for p in &m.points {
            obs.push(Obs {
                campaign: ci,
                measurement: mi,
                direction: p.direction,
                x_mm: p.target_mm,
                y_um: p.deviation_um,
                target_key: (p.target_mm * 1e6).round() as i64,
            });
        }
    }
    Ok(per_m)
}

fn measurement_rises(
    c: &Campaign,
    m: &Measurement,
    gain_sensors: &[String],
    ambient: Option<&str>,
    coolant: usize,
) -> Result<Rises> {
    let get = |name: &str| {
        m.temperatures_c.get(name).copied().ok_or_else(|| {
            Error::usage(
                format!(
                    "campaign '{}' has no temperatures for sensor '{name}'",
                    c.name
                ),
                format!(
                    "log every sensor of the model in every campaign, or choose others with {}",
                    words(Setting::Sensors)
                ),
            )
        })
    };
    let ambient_c = match ambient {
        Some(a) => Some(get(a)?),
        None => None,
    };
    let mut above_c = Vec::with_capacity(gain_sensors.len());
    for s in gain_sensors {
        above_c.push(get(s)? - ambient_c.unwrap_or(0.0));
    }
    Ok(Rises {
        above_c,
        ambient_c,
        coolant,
    })
}

/// A cold state: rises above the ambient per gain sensor, and the ambient.
type Cold = (Vec<f64>, Option<f64>);

/// The mean cold state (first measurement) of the included campaigns.
fn shared_cold(prep: &Prepared, include: &[bool]) -> Cold {
    let n = prep.gain_sensors.len();
    let mut rise = vec![0.0; n];
    let mut amb = 0.0;
    let mut count = 0.0;
    for (ci, per_m) in prep.rises.iter().enumerate() {
        if !include[ci] {
            continue;
        }
        if let Some(cold) = per_m.first() {
            for (r, above) in rise.iter_mut().zip(&cold.above_c) {
                *r += above;
            }
            amb += cold.ambient_c.unwrap_or(0.0);
            count += 1.0;
        }
    }
    if count > 0.0 {
        for r in &mut rise {
            *r /= count;
        }
        amb /= count;
    }
    (rise, prep.ambient.as_ref().map(|_| amb))
}

/// The cold state each campaign's rises are measured from (the shared one over `include`).
fn campaign_refs(prep: &Prepared, include: &[bool], reference: Reference) -> Vec<Cold> {
    let shared = shared_cold(prep, include);
    prep.rises
        .iter()
        .map(|per_m| match (reference, per_m.first()) {
            (Reference::OwnStart, Some(cold)) => (cold.above_c.clone(), shared.1),
            (Reference::Room, _) => (vec![0.0; shared.0.len()], shared.1),
            _ => shared.clone(),
        })
        .collect()
}

/// Design of one direction's regression.
struct Design {
    order: usize,
    /// Coolant states that get gain columns (those present in the training set).
    states: Vec<usize>,
    /// Campaigns with a tanβ offset (sum zero: one column fewer than campaigns).
    offsets: Vec<usize>,
    fit_rho: bool,
    rho_given: f64,
}

impl Design {
    fn width(&self, n_sensors: usize) -> usize {
        self.order
            + 1
            + self.states.len() * n_sensors
            + self.offsets.len().saturating_sub(1)
            + usize::from(self.fit_rho)
    }
}

struct Context<'a> {
    prep: &'a Prepared,
    /// Cold state of each campaign.
    refs: Vec<Cold>,
}

impl Context<'_> {
    fn s(&self, x_mm: f64) -> f64 {
        (2.0 * x_mm - self.prep.x_min_mm - self.prep.x_max_mm)
            / (self.prep.x_max_mm - self.prep.x_min_mm)
    }
    fn lever_m(&self, o: &Obs) -> f64 {
        (o.x_mm - self.prep.reference_point_mm) / 1000.0
    }
    /// Append the row of `o` to `rows` and return the response (ρ given: moved to the left).
    fn row(&self, o: &Obs, d: &Design, rows: &mut Vec<f64>, poly: &mut [f64]) -> f64 {
        let r = &self.prep.rises[o.campaign][o.measurement];
        let (ref_rise, ref_amb) = &self.refs[o.campaign];
        let lever_m = self.lever_m(o);
        legendre_into(self.s(o.x_mm), d.order, poly);
        rows.extend_from_slice(&poly[..=d.order]);
        for &st in &d.states {
            for (j, above) in r.above_c.iter().enumerate() {
                let value = if r.coolant == st {
                    (above - ref_rise[j]) * lever_m
                } else {
                    0.0
                };
                rows.push(value);
            }
        }
        // Sum-zero coding: the first offset campaign carries minus the sum of the others;
        // a campaign outside the list (held out) has the mean offset, 0.
        let pos = d.offsets.iter().position(|&c| c == o.campaign);
        for k in 1..d.offsets.len() {
            rows.push(match pos {
                Some(0) => -lever_m,
                Some(p) if p == k => lever_m,
                _ => 0.0,
            });
        }
        let d_env = match (r.ambient_c, ref_amb) {
            (Some(a), Some(r0)) => a - r0,
            _ => 0.0,
        };
        if d.fit_rho {
            rows.push(d_env * lever_m);
            o.y_um
        } else {
            o.y_um - d.rho_given * d_env * lever_m
        }
    }

    fn fit(&self, obs: &[&Obs], d: &Design, what: &str) -> Result<super::lsq::LstsqFit> {
        let p = d.width(self.prep.gain_sensors.len());
        let mut rows = Vec::with_capacity(obs.len() * p);
        let mut y = Vec::with_capacity(obs.len());
        let mut poly = vec![0.0; d.order + 1];
        for o in obs {
            y.push(self.row(o, d, &mut rows, &mut poly));
        }
        lstsq(&rows, p, &y, what)
    }

    /// Prediction of `o` by coefficients `beta` of design `d` (its coolant state must be in `d.states`).
    fn predict(&self, o: &Obs, d: &Design, beta: &[f64]) -> f64 {
        let p = d.width(self.prep.gain_sensors.len());
        let mut rows = Vec::with_capacity(p);
        let mut poly = vec![0.0; d.order + 1];
        let y = self.row(o, d, &mut rows, &mut poly);
        let fitted: f64 = rows.iter().zip(beta).map(|(a, b)| a * b).sum();
        // `row` returned y − (given ρ part); the prediction of y adds it back.
        fitted + (o.y_um - y)
    }
}

/// Shared settings of the fits of one model.
struct Setup<'a> {
    prep: &'a Prepared,
    options: &'a FitOptions,
    names: Vec<String>,
    fit_rho: bool,
    rho_given: f64,
}

/// Leave-one-campaign-out result of one campaign.
struct Loco {
    sq: f64,
    n: usize,
    note: Option<String>,
}

/// One reference's fit: both directions, in-sample residuals and held-out scores per campaign.
struct Trial {
    reference: Reference,
    directions: Vec<DirectionModel>,
    residual_sq: ResidualSums,
    loco: Vec<Loco>,
}

impl Trial {
    fn pooled_loco_um(&self) -> Option<f64> {
        let (sq, n) = self
            .loco
            .iter()
            .fold((0.0, 0usize), |(s, n), l| (s + l.sq, n + l.n));
        (n > 0).then(|| (sq / n as f64).sqrt())
    }
}

/// Fit the composite model to campaigns.
pub fn fit(campaigns: &[Campaign], options: &FitOptions) -> Result<ThermalModel> {
    let prep = prepare(campaigns, options)?;
    let setup = Setup {
        prep: &prep,
        options,
        names: campaigns.iter().map(|c| c.name.clone()).collect(),
        fit_rho: prep.ambient.is_some() && options.rho_um_per_m_k.is_none(),
        rho_given: if prep.ambient.is_some() {
            options.rho_um_per_m_k.unwrap_or(0.0)
        } else {
            0.0
        },
    };
    if options.reference == Some(Reference::Room) && prep.ambient.is_none() {
        return Err(Error::usage(
            "rises from the room need an ambient sensor",
            format!(
                "give a sensor the role ambient in the sensor table, or choose another {}",
                words(Setting::Reference)
            ),
        ));
    }
    let candidates: Vec<Reference> = match options.reference {
        Some(r) => vec![r],
        None if options.leave_one_out && campaigns.len() > 1 => Reference::ALL
            .into_iter()
            .filter(|r| *r != Reference::Room || prep.ambient.is_some())
            .collect(),
        None => vec![Reference::Shared],
    };
    let mut trials = Vec::new();
    let mut scores = Vec::new();
    let mut first_err = None;
    for reference in candidates.iter().copied() {
        match try_reference(&setup, campaigns, reference) {
            Ok(t) => {
                let loco = t.pooled_loco_um();
                scores.push(ReferenceScore {
                    reference,
                    loco_rms_um: loco,
                    note: loco
                        .is_none()
                        .then(|| "no held-out campaign to score".into()),
                });
                trials.push(t);
            }
            Err(e) => {
                scores.push(ReferenceScore {
                    reference,
                    loco_rms_um: None,
                    note: Some(e.to_string()),
                });
                first_err.get_or_insert(e);
            }
        }
    }
    // The first (fewest fitted quantities) within 1 % of the lowest held-out RMS; without any
    // score, the first reference that fits.
    let lowest = trials
        .iter()
        .filter_map(Trial::pooled_loco_um)
        .fold(f64::INFINITY, f64::min);
    let best = trials
        .iter()
        .position(|t| t.pooled_loco_um().is_some_and(|v| v <= lowest * 1.01))
        .unwrap_or(0);
    if trials.is_empty() {
        return Err(first_err.unwrap_or_else(|| Error::Internal("no reference tried".into())));
    }
    let chosen_by = if options.reference.is_some() {
        "given"
    } else if candidates.len() > 1 && trials[best].pooled_loco_um().is_some() {
        "cross-validation"
    } else {
        "default (no held-out campaign to choose by)"
    };
    let trial = trials.swap_remove(best);
    Ok(assemble(&setup, campaigns, trial, chosen_by, scores))
}

/// Fit both directions with one reference and score it campaign by campaign.
fn try_reference(setup: &Setup, campaigns: &[Campaign], reference: Reference) -> Result<Trial> {
    let prep = setup.prep;
    let all = vec![true; campaigns.len()];
    let ctx = Context {
        prep,
        refs: campaign_refs(prep, &all, reference),
    };
    let offsets: Vec<usize> = if reference == Reference::CampaignOffset {
        (0..campaigns.len()).collect()
    } else {
        Vec::new()
    };
    let (directions, residual_sq) = fit_directions(setup, &ctx, &offsets)?;
    let loco = campaigns
        .iter()
        .enumerate()
        .map(|(ci, c)| loco_of(setup, campaigns, ci, c, reference, &directions))
        .collect();
    Ok(Trial {
        reference,
        directions,
        residual_sq,
        loco,
    })
}

fn loco_of(
    setup: &Setup,
    campaigns: &[Campaign],
    ci: usize,
    c: &Campaign,
    reference: Reference,
    directions: &[DirectionModel],
) -> Loco {
    let none = |note: String| Loco {
        sq: 0.0,
        n: 0,
        note: Some(note),
    };
    let others_same_state = campaigns
        .iter()
        .enumerate()
        .any(|(k, o)| k != ci && o.coolant == c.coolant);
    if !setup.options.leave_one_out {
        return none("not computed".into());
    }
    if campaigns.len() < 2 {
        return none("one campaign only".into());
    }
    if !others_same_state {
        return none(format!("no other campaign with coolant '{}'", c.coolant));
    }
    if c.measurements.len() < 2 {
        return none("only a cold measurement".into());
    }
    let coolant = setup
        .prep
        .coolant_states
        .iter()
        .position(|s| s == &c.coolant)
        .unwrap_or(0);
    match leave_one_out(setup, ci, coolant, directions, reference) {
        Ok((sq, n)) => Loco { sq, n, note: None },
        Err(e) => none(e.to_string()),
    }
}

/// (Σ residual², count) per campaign.
type ResidualSums = Vec<(f64, usize)>;

/// Fit both directions (orders by cross-validation unless given).
fn fit_directions(
    setup: &Setup,
    ctx: &Context,
    offsets: &[usize],
) -> Result<(Vec<DirectionModel>, ResidualSums)> {
    let prep = setup.prep;
    let all_states: Vec<usize> = (0..prep.coolant_states.len()).collect();
    let n_sensors = prep.gain_sensors.len();
    let mut directions = Vec::new();
    let mut residual_sq = vec![(0.0, 0usize); prep.rises.len()];
    for dir in DIRECTIONS {
        let obs: Vec<&Obs> = prep.obs.iter().filter(|o| o.direction == dir).collect();
        if obs.is_empty() {
            return Err(Error::usage(
                format!("no {} readings in the campaigns", direction_name(dir)),
                "measure both directions (bidirectional runs)",
            ));
        }
        let design = |order| Design {
            order,
            states: all_states.clone(),
            offsets: offsets.to_vec(),
            fit_rho: setup.fit_rho,
            rho_given: setup.rho_given,
        };
        let (order, chosen_by, cv) = choose_order(setup.options, ctx, dir, &obs, &design)?;
        let d = design(order);
        let what = format!("the {} model", direction_name(dir));
        let f = ctx.fit(&obs, &d, &what)?;
        let se_at = |i: usize| f.se.as_ref().map(|se| se[i]);
        let mut gains = Vec::new();
        for (si, &st) in d.states.iter().enumerate() {
            let base = order + 1 + si * n_sensors;
            let names = prep.gain_sensors.iter().cloned();
            gains.push(CoolantGains {
                coolant: prep.coolant_states[st].clone(),
                k_um_per_m_k: names.clone().zip(f.beta[base..].iter().copied()).collect(),
                k_se_um_per_m_k: names.zip((base..base + n_sensors).map(se_at)).collect(),
            });
        }
        let mut campaign_offsets_um_per_m = BTreeMap::new();
        if offsets.len() > 1 {
            let base = order + 1 + d.states.len() * n_sensors;
            let b = &f.beta[base..base + offsets.len() - 1];
            campaign_offsets_um_per_m
                .insert(setup.names[offsets[0]].clone(), -b.iter().sum::<f64>());
            for (k, v) in b.iter().enumerate() {
                campaign_offsets_um_per_m.insert(setup.names[offsets[k + 1]].clone(), *v);
            }
        }
        let (rho, rho_se) = if setup.fit_rho {
            let i = d.width(n_sensors) - 1;
            (f.beta[i], se_at(i))
        } else {
            (setup.rho_given, None)
        };
        for o in &obs {
            let r = o.y_um - ctx.predict(o, &d, &f.beta);
            residual_sq[o.campaign].0 += r * r;
            residual_sq[o.campaign].1 += 1;
        }
        directions.push(DirectionModel {
            direction: dir,
            order,
            order_chosen_by: chosen_by,
            cv_rms_um_by_order: cv,
            legendre_um: f.beta[..=order].to_vec(),
            legendre_se_um: (0..=order).map(se_at).collect(),
            gains,
            rho_um_per_m_k: rho,
            rho_se_um_per_m_k: rho_se,
            rho_fitted: setup.fit_rho,
            campaign_offsets_um_per_m,
            residual_rms_um: (f.rss / f.n as f64).sqrt(),
            points: f.n,
        });
    }
    Ok((directions, residual_sq))
}

/// The polynomial order of one direction: given, or by leave-one-target-out cross-validation.
fn choose_order(
    options: &FitOptions,
    ctx: &Context,
    dir: Direction,
    obs: &[&Obs],
    design: &dyn Fn(usize) -> Design,
) -> Result<(usize, String, Vec<Option<f64>>)> {
    let mut targets: Vec<i64> = obs.iter().map(|o| o.target_key).collect();
    targets.sort_unstable();
    targets.dedup();
    if let Some(o) = options.order {
        if o + 1 > targets.len() {
            return Err(Error::usage(
                format!(
                    "order {o} needs {} target positions, the {} readings have {}",
                    o + 1,
                    direction_name(dir),
                    targets.len()
                ),
                format!("give a lower {}", words(Setting::Order)),
            ));
        }
        return Ok((o, "given".to_string(), Vec::new()));
    }
    let cap = options.max_order.min(targets.len().saturating_sub(2));
    let cv: Vec<Option<f64>> = (0..=cap)
        .map(|order| cross_validate_targets(ctx, obs, &targets, &design(order)).ok())
        .collect();
    let best = cv.iter().flatten().cloned().fold(f64::INFINITY, f64::min);
    if !best.is_finite() {
        return Err(Error::numeric(
            format!(
                "no polynomial order could be cross-validated for {}",
                direction_name(dir)
            ),
            format!(
                "measure more target positions or give {}",
                words(Setting::Order)
            ),
        ));
    }
    // The lowest order within 2 % of the best: extra terms must earn their place.
    let order = cv
        .iter()
        .position(|v| v.is_some_and(|v| v <= best * 1.02))
        .unwrap_or(0);
    Ok((order, "cross-validation".to_string(), cv))
}

/// The model of the chosen trial.
fn assemble(
    setup: &Setup,
    campaigns: &[Campaign],
    trial: Trial,
    chosen_by: &str,
    scores: Vec<ReferenceScore>,
) -> ThermalModel {
    let prep = setup.prep;
    let mut reports = Vec::new();
    for (ci, c) in campaigns.iter().enumerate() {
        let l = &trial.loco[ci];
        let (sq, n) = trial.residual_sq[ci];
        reports.push(CampaignReport {
            name: c.name.clone(),
            coolant: c.coolant.clone(),
            measurements: c.measurements.len(),
            points: n,
            residual_rms_um: (sq / n.max(1) as f64).sqrt(),
            loco_rms_um: (l.n > 0).then(|| (l.sq / l.n as f64).sqrt()),
            loco_note: l.note.clone(),
        });
    }
    let mut sensors: Vec<Sensor> = Vec::new();
    for name in prep.gain_sensors.iter().chain(prep.ambient.iter()) {
        if let Some(s) = campaigns[0].sensors.get(name) {
            sensors.push(s.clone());
        }
    }
    let (mut ref_rise, ref_amb) = shared_cold(prep, &vec![true; campaigns.len()]);
    if trial.reference == Reference::Room {
        ref_rise.iter_mut().for_each(|r| *r = 0.0);
    }
    ThermalModel {
        format: MODEL_FORMAT.to_string(),
        axis: campaigns[0].axis.clone(),
        reference_point_mm: prep.reference_point_mm,
        x_min_mm: prep.x_min_mm,
        x_max_mm: prep.x_max_mm,
        gain_sensors: prep.gain_sensors.clone(),
        ambient_sensor: prep.ambient.clone(),
        sensors,
        reference: trial.reference,
        reference_chosen_by: chosen_by.to_string(),
        reference_cv: scores,
        reference_rise_c: prep.gain_sensors.iter().cloned().zip(ref_rise).collect(),
        reference_ambient_c: ref_amb,
        coolant_states: prep.coolant_states.clone(),
        loco_rms_um: trial.pooled_loco_um(),
        directions: trial.directions,
        campaigns: reports,
    }
}

/// Leave-one-target-out RMS of a design: every target position is predicted by a fit
/// without any reading at that position.
fn cross_validate_targets(ctx: &Context, obs: &[&Obs], targets: &[i64], d: &Design) -> Result<f64> {
    let (mut sq, mut n) = (0.0, 0usize);
    for &t in targets {
        let train: Vec<&Obs> = obs.iter().copied().filter(|o| o.target_key != t).collect();
        let f = ctx.fit(&train, d, "cross-validation")?;
        for o in obs.iter().filter(|o| o.target_key == t) {
            let r = o.y_um - ctx.predict(o, d, &f.beta);
            sq += r * r;
            n += 1;
        }
    }
    Ok((sq / n.max(1) as f64).sqrt())
}

/// Squared residuals of campaign `held` predicted by a fit without it (same orders), over its
/// measurements after the cold one. Own-start takes the held campaign's rises from its cold
/// measurement; campaign-offset estimates its offset from that measurement.
fn leave_one_out(
    setup: &Setup,
    held: usize,
    held_coolant: usize,
    directions: &[DirectionModel],
    reference: Reference,
) -> Result<(f64, usize)> {
    let prep = setup.prep;
    let include: Vec<bool> = (0..prep.rises.len()).map(|k| k != held).collect();
    let ctx = Context {
        prep,
        refs: campaign_refs(prep, &include, reference),
    };
    let mut states: Vec<usize> = prep
        .obs
        .iter()
        .filter(|o| o.campaign != held)
        .map(|o| prep.rises[o.campaign][o.measurement].coolant)
        .collect();
    states.sort_unstable();
    states.dedup();
    if !states.contains(&held_coolant) {
        return Err(Error::numeric("coolant state not in the training set", ""));
    }
    let offsets: Vec<usize> = match reference {
        Reference::CampaignOffset => (0..prep.rises.len()).filter(|&k| k != held).collect(),
        _ => Vec::new(),
    };
    let (mut sq, mut n) = (0.0, 0usize);
    for dm in directions {
        let d = Design {
            order: dm.order,
            states: states.clone(),
            offsets: offsets.clone(),
            fit_rho: setup.fit_rho,
            rho_given: setup.rho_given,
        };
        let train: Vec<&Obs> = prep
            .obs
            .iter()
            .filter(|o| o.campaign != held && o.direction == dm.direction)
            .collect();
        let f = ctx.fit(&train, &d, "leave-one-campaign-out")?;
        let held_obs: Vec<&Obs> = prep
            .obs
            .iter()
            .filter(|o| o.campaign == held && o.direction == dm.direction)
            .collect();
        let offset = if reference == Reference::CampaignOffset {
            let (mut num, mut den) = (0.0, 0.0);
            for o in held_obs.iter().filter(|o| o.measurement == 0) {
                let lever = ctx.lever_m(o);
                num += (o.y_um - ctx.predict(o, &d, &f.beta)) * lever;
                den += lever * lever;
            }
            if den > 0.0 {
                num / den
            } else {
                0.0
            }
        } else {
            0.0
        };
        for o in held_obs.iter().filter(|o| o.measurement > 0) {
            let r = o.y_um - ctx.predict(o, &d, &f.beta) - offset * ctx.lever_m(o);
            sq += r * r;
            n += 1;
        }
    }
    Ok((sq, n))
}

impl ThermalModel {
    /// Read and check a model.json.
    pub fn read(path: &std::path::Path) -> Result<ThermalModel> {
        let text = errmap_core::io::read_text(path)?;
        let model: ThermalModel = serde_json::from_str(&text).map_err(|e| {
            Error::input(
                errmap_core::error::Location::line(path, e.line() as u64),
                format!("not a thermal model: {e}"),
                "give a model.json written by `errmap thermal fit`",
            )
        })?;
        model.validate().map_err(|m| {
            Error::input(
                errmap_core::error::Location::file(path),
                m,
                "refit the model with `errmap thermal fit`",
            )
        })?;
        Ok(model)
    }

    /// Consistency of a model read from a file or the store (the message says what is wrong).
    pub fn validate(&self) -> std::result::Result<(), String> {
        if self.format != MODEL_FORMAT {
            return Err(format!("format '{}' is not {MODEL_FORMAT}", self.format));
        }
        if self.directions.len() != 2
            || self.directions[0].direction != Direction::Forward
            || self.directions[1].direction != Direction::Reverse
        {
            return Err("the model must hold a forward and a reverse direction".into());
        }
        if !self.x_min_mm.is_finite()
            || !self.x_max_mm.is_finite()
            || self.x_max_mm <= self.x_min_mm
        {
            return Err("x_max_mm must exceed x_min_mm (finite numbers)".into());
        }
        if self.coolant_states.is_empty() {
            return Err("the model names no coolant state".into());
        }
        for name in self.gain_sensors.iter().chain(self.ambient_sensor.iter()) {
            if !self.sensors.iter().any(|s| &s.name == name) {
                return Err(format!("sensor '{name}' has no definition in 'sensors'"));
            }
        }
        if self.ambient_sensor.is_some() != self.reference_ambient_c.is_some() {
            return Err("ambient_sensor and reference_ambient_c go together".into());
        }
        if !self
            .gain_sensors
            .iter()
            .all(|s| self.reference_rise_c.contains_key(s))
        {
            return Err("reference_rise_c needs a value for every gain sensor".into());
        }
        for d in &self.directions {
            if d.legendre_um.len() != d.order + 1 {
                return Err("legendre_um needs order + 1 coefficients".into());
            }
            if d.gains.len() != self.coolant_states.len() {
                return Err("each direction needs gains for every coolant state".into());
            }
            for (g, state) in d.gains.iter().zip(&self.coolant_states) {
                let all = self
                    .gain_sensors
                    .iter()
                    .all(|s| g.k_um_per_m_k.contains_key(s));
                if &g.coolant != state || !all {
                    return Err(format!(
                        "gains of coolant '{}' do not match the sensors",
                        g.coolant
                    ));
                }
            }
        }
        Ok(())
    }

    /// The model of direction `d`.
    pub fn direction(&self, d: Direction) -> &DirectionModel {
        &self.directions[match d {
            Direction::Forward => 0,
            Direction::Reverse => 1,
        }]
    }

    /// Index of a coolant state label in `coolant_states`; `None` when the model has no gains
    /// for it.
    pub fn coolant_index(&self, state: &str) -> Option<usize> {
        self.coolant_states.iter().position(|s| s == state)
    }

    /// s of a position; positions outside the fitted travel are held at its ends for Er(x).
    #[inline]
    pub fn scaled(&self, x_mm: f64) -> f64 {
        ((2.0 * x_mm - self.x_min_mm - self.x_max_mm) / (self.x_max_mm - self.x_min_mm))
            .clamp(-1.0, 1.0)
    }

    /// Er(x): the cold pitch error (µm).
    #[inline]
    pub fn geometric_um(&self, d: Direction, x_mm: f64) -> f64 {
        legendre_sum(&self.direction(d).legendre_um, self.scaled(x_mm))
    }

    /// tanβ (µm/m) of a thermal state, including the ambient term ρ·ΔT_env.
    pub fn slope_um_per_m(&self, d: Direction, state: &ThermalState) -> f64 {
        let dm = self.direction(d);
        let gains = &dm.gains[state.coolant.min(dm.gains.len() - 1)].k_um_per_m_k;
        let amb = state.ambient_c.unwrap_or(0.0);
        let mut slope = 0.0;
        for (name, t) in self.gain_sensors.iter().zip(&state.sensors_c) {
            let k = gains.get(name).copied().unwrap_or(0.0);
            let r0 = self.reference_rise_c.get(name).copied().unwrap_or(0.0);
            let above = if self.ambient_sensor.is_some() {
                t - amb
            } else {
                *t
            };
            slope += k * (above - r0);
        }
        if let (Some(a), Some(a0)) = (state.ambient_c, self.reference_ambient_c) {
            slope += dm.rho_um_per_m_k * (a - a0);
        }
        slope
    }

    /// E(x, T): the modelled positioning error (µm, measured − target).
    pub fn error_um(&self, d: Direction, x_mm: f64, state: &ThermalState) -> f64 {
        self.geometric_um(d, x_mm)
            + self.slope_um_per_m(d, state) * (x_mm - self.reference_point_mm) / 1000.0
    }

    /// The thermal state of a measurement of a campaign (its mean temperatures).
    pub fn state_of(&self, campaign: &Campaign, m: &Measurement) -> Result<ThermalState> {
        let coolant = self.coolant_index(&campaign.coolant).ok_or_else(|| {
            Error::usage(
                format!(
                    "campaign '{}' has coolant '{}', the model knows {}",
                    campaign.name,
                    campaign.coolant,
                    self.coolant_states.join(", ")
                ),
                "fit the model with a campaign in that coolant state",
            )
        })?;
        let get = |name: &str| {
            m.temperatures_c.get(name).copied().ok_or_else(|| {
                Error::usage(
                    format!("campaign '{}' has no sensor '{name}'", campaign.name),
                    "log every sensor the model uses",
                )
            })
        };
        let sensors_c = self
            .gain_sensors
            .iter()
            .map(|s| get(s))
            .collect::<Result<Vec<_>>>()?;
        let ambient_c = match &self.ambient_sensor {
            Some(a) => Some(get(a)?),
            None => None,
        };
        Ok(ThermalState {
            sensors_c,
            ambient_c,
            coolant,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::thermal::sample::{write_campaigns, SynthThermalOptions};
    use crate::thermal::sensors::{calibrate, SensorTable, TemperatureLog};

    /// Generate campaigns, calibrate the sensors on the calibration log, read the campaigns.
    pub(crate) fn synthetic(
        dir: &std::path::Path,
        options: &SynthThermalOptions,
    ) -> (crate::thermal::sample::ThermalTruth, Vec<Campaign>) {
        let truth = write_campaigns(dir, options).unwrap();
        let table_path = dir.join("sensors.csv");
        let mut table = SensorTable::read(&table_path).unwrap();
        let log = TemperatureLog::read(&dir.join("calibration.csv"), &table).unwrap();
        let fits = calibrate(&log, &table, 0.0, 1e9, 1.0).unwrap();
        table.apply_calibrations(&fits);
        table.write(&table_path).unwrap();
        let campaigns = truth
            .campaigns
            .iter()
            .map(|c| Campaign::read(&dir.join(&c.name)).unwrap())
            .collect();
        (truth, campaigns)
    }

    #[test]
    fn recovers_gains_and_predicts_held_out_campaigns() {
        let dir = tempfile::tempdir().unwrap();
        let (truth, campaigns) = synthetic(dir.path(), &SynthThermalOptions::default());
        let model = fit(&campaigns, &FitOptions::default()).unwrap();
        assert_eq!(model.gain_sensors, ["bearing", "nut"]);
        assert_eq!(model.coolant_states, ["off", "on"]);
        for (di, dm) in model.directions.iter().enumerate() {
            // The truth is a cubic: cross-validation must find order 3.
            assert_eq!(dm.order, 3, "{:?}", dm.cv_rms_um_by_order);
            for g in &dm.gains {
                let t = truth.gains(di, &g.coolant).unwrap();
                for (k, want) in [
                    (g.k_um_per_m_k["nut"], t.k_nut_um_per_m_k),
                    (g.k_um_per_m_k["bearing"], t.k_bearing_um_per_m_k),
                ] {
                    assert!(
                        (k / want - 1.0).abs() < 0.05,
                        "{} {}: k = {k}, truth {want}",
                        direction_name(dm.direction),
                        g.coolant
                    );
                }
            }
            assert!(
                (dm.rho_um_per_m_k / truth.rho_um_per_m_k - 1.0).abs() < 0.1,
                "ρ {}",
                dm.rho_um_per_m_k
            );
            // Er(x) shape: the Legendre coefficients above order 1 are independent of the
            // reference temperatures (those only shift the constant and linear terms).
            let want = &truth.directions[di].pitch_legendre_um;
            for (n, want_n) in want.iter().enumerate().skip(2) {
                assert!(
                    (dm.legendre_um[n] - want_n).abs() < 0.15,
                    "c{n} = {}",
                    dm.legendre_um[n]
                );
            }
        }
        // Held-out campaign residual within 1.5× the laser noise, for every campaign.
        for c in &model.campaigns {
            let loco = c.loco_rms_um.unwrap();
            assert!(loco < 1.5 * truth.laser_noise_um, "{}: {loco}", c.name);
            assert!(
                c.residual_rms_um < 1.2 * truth.laser_noise_um,
                "{}",
                c.residual_rms_um
            );
        }
    }

    #[test]
    fn predictions_follow_the_sign_convention() {
        let dir = tempfile::tempdir().unwrap();
        let options = SynthThermalOptions {
            campaigns: 2,
            repeats: 1,
            ..Default::default()
        };
        let (_, campaigns) = synthetic(dir.path(), &options);
        let model = fit(
            &campaigns[..1],
            &FitOptions {
                order: Some(3),
                ..Default::default()
            },
        )
        .unwrap();
        // Warm nut (3 K above its cold rise), room at the reference: E grows as
        // k_nut·3 K·(x − Px) — positive beyond Px for positive k.
        let d = Direction::Forward;
        let amb = model.reference_ambient_c.unwrap();
        let state = ThermalState {
            // Gain-sensor order is name order: bearing, nut.
            sensors_c: vec![
                amb + model.reference_rise_c["bearing"],
                amb + model.reference_rise_c["nut"] + 3.0,
            ],
            ambient_c: Some(amb),
            coolant: 0,
        };
        let k = model.direction(d).gains[0].k_um_per_m_k["nut"];
        let x = 400.0;
        let thermal = model.error_um(d, x, &state) - model.geometric_um(d, x);
        assert!((thermal - k * 3.0 * (x - model.reference_point_mm) / 1000.0).abs() < 1e-9);
        assert!(k > 0.0 && thermal > 0.0);
        // Only one coolant state: no leave-one-out for it, and the note says why.
        assert!(model.campaigns[0].loco_rms_um.is_none());
        assert!(model.campaigns[0]
            .loco_note
            .as_ref()
            .unwrap()
            .contains("one campaign"));
    }
}
