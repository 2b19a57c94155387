//! One compensated axis: its thermal model evaluated for the live state (the library's own
//! `ThermalModel` evaluation, so `errmap thermal compensate` gives the same values), and the
//! safety rules on what is written: bounds on |compensation| and on the slope, and a rate
//! limit on how fast the compensation may change anywhere on the axis's travel.
//!
//! The thermal part is carried as a line about the model's reference point Px, the way the
//! Sinumerik temperature compensation (K3) takes it: `offset_um + slope_um_per_m·(x − Px)/1000`.
//! errmap's model has no offset of its own (its lines fan about Px), so the offset is zero
//! except while ramping from a controller's present value. Compensation = −E (P' = P − E).

use errmap_core::direction::Direction;
use errmap_metrology::thermal::model::{ThermalModel, ThermalState};

/// The thermal compensation line: value at x = offset + slope·(x − Px)/1000 (µm).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Line {
    /// The compensation at Px (µm, compensation sign: −E); zero except while ramping from a
    /// controller's present value.
    pub offset_um: f64,
    /// The compensation's slope along the axis (µm per m of travel, compensation sign: −tanβ).
    pub slope_um_per_m: f64,
}

impl Line {
    /// The line's value at a position (µm).
    pub fn at(&self, x_mm: f64, px_mm: f64) -> f64 {
        self.offset_um + self.slope_um_per_m * (x_mm - px_mm) / 1000.0
    }
}

/// What the model asks of an axis this cycle.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Demand {
    /// The thermal compensation line (−tanβ about Px).
    pub line: Line,
    /// tanβ of the model (µm/m, errmap's error sign).
    pub tan_beta_um_per_m: f64,
    /// E(x, T), the modelled error at the position (µm; None without a position).
    pub error_um: Option<f64>,
    /// −Er(x) at the position, when the axis includes the geometric part (µm).
    pub geometric_comp_um: Option<f64>,
}

/// The limits of an axis.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Limits {
    /// Bound on |compensation| anywhere on the fitted travel (µm).
    pub limit_um: f64,
    /// Bound on |tanβ| of the written line (µm/m).
    pub slope_limit_um_per_m: f64,
    /// Fastest allowed change of the compensation at the worst point of the travel (µm/s).
    pub rate_limit_um_s: f64,
}

/// An axis: model, limits and the lever of its travel.
#[derive(Debug, Clone)]
pub struct AxisModel {
    /// The axis's name, as in the model and the config (`X`, ...).
    pub name: String,
    /// The axis's fitted thermal model (the file `errmap thermal fit` writes).
    pub model: ThermalModel,
    /// The axis's bounds and rate limit.
    pub limits: Limits,
    /// Whether a point target's value adds the geometric compensation −Er(x) (false: Er(x) is in the
    /// controller's pitch table).
    pub include_geometric: bool,
    /// Largest |x − Px| over the fitted travel (m): the rate limit and bounds act there.
    pub lever_m: f64,
}

/// Positions at which the bounds are checked when the geometric part is included.
const BOUND_SAMPLES: usize = 41;

impl AxisModel {
    /// An axis of a model: the lever is the larger distance from Px to either end of the model's
    /// fitted travel (`x_min_mm` … `x_max_mm`).
    pub fn new(name: String, model: ThermalModel, limits: Limits, include_geometric: bool) -> Self {
        let px = model.reference_point_mm;
        let lever_m = (model.x_min_mm - px).abs().max((model.x_max_mm - px).abs()) / 1000.0;
        AxisModel {
            name,
            model,
            limits,
            include_geometric,
            lever_m,
        }
    }

    /// The model's reference point Px (mm, machine coordinates), about which the line turns.
    pub fn px_mm(&self) -> f64 {
        self.model.reference_point_mm
    }

    /// The model's demand for a direction (None: the mean of both), position and state.
    pub fn demand(
        &self,
        direction: Option<Direction>,
        x_mm: Option<f64>,
        state: &ThermalState,
    ) -> Demand {
        let m = &self.model;
        let mean = |f: &dyn Fn(Direction) -> f64| match direction {
            Some(d) => f(d),
            None => 0.5 * (f(Direction::Forward) + f(Direction::Reverse)),
        };
        let tan_beta = mean(&|d| m.slope_um_per_m(d, state));
        let error_um = x_mm.map(|x| mean(&|d| m.error_um(d, x, state)));
        let geometric_comp_um = match (self.include_geometric, x_mm) {
            (true, Some(x)) => Some(-mean(&|d| m.geometric_um(d, x))),
            _ => None,
        };
        Demand {
            line: Line {
                offset_um: 0.0,
                slope_um_per_m: -tan_beta,
            },
            tan_beta_um_per_m: tan_beta,
            error_um,
            geometric_comp_um,
        }
    }

    /// The bounds: |slope| and |compensation| anywhere on the fitted travel (geometric part
    /// included when the axis carries it). The message says which and by how much.
    pub fn check_bounds(&self, line: &Line, direction: Option<Direction>) -> Result<(), String> {
        let l = &self.limits;
        if line.slope_um_per_m.abs() > l.slope_limit_um_per_m {
            return Err(format!(
                "{} slope {:.3} µm/m beyond ±{} µm/m",
                self.name, line.slope_um_per_m, l.slope_limit_um_per_m
            ));
        }
        let m = &self.model;
        let px = self.px_mm();
        let mut worst = (0.0f64, m.x_min_mm);
        for k in 0..BOUND_SAMPLES {
            let x = m.x_min_mm + (m.x_max_mm - m.x_min_mm) * k as f64 / (BOUND_SAMPLES - 1) as f64;
            let mut v = line.at(x, px);
            if self.include_geometric {
                v -= match direction {
                    Some(d) => m.geometric_um(d, x),
                    None => {
                        0.5 * (m.geometric_um(Direction::Forward, x)
                            + m.geometric_um(Direction::Reverse, x))
                    }
                };
            }
            if v.abs() > worst.0.abs() {
                worst = (v, x);
            }
            if !self.include_geometric && k == 0 {
                // A line's extremes are at the ends: check the other end only.
                let v = line.at(m.x_max_mm, px);
                if v.abs() > worst.0.abs() {
                    worst = (v, m.x_max_mm);
                }
                break;
            }
        }
        if worst.0.abs() > l.limit_um {
            return Err(format!(
                "{} compensation {:.3} µm at {:.1} mm beyond ±{} µm",
                self.name, worst.0, worst.1, l.limit_um
            ));
        }
        Ok(())
    }

    /// One cycle's move of the written line toward `goal`: the change of the compensation
    /// anywhere on the travel, |Δoffset| + |Δslope|·lever, stays within rate·dt (both parts
    /// scaled alike, so the line moves straight toward the goal).
    pub fn step_toward(&self, written: Line, goal: Line, dt_s: f64) -> Line {
        let d_off = goal.offset_um - written.offset_um;
        let d_slope = goal.slope_um_per_m - written.slope_um_per_m;
        let change_um = d_off.abs() + d_slope.abs() * self.lever_m;
        let allowed_um = self.limits.rate_limit_um_s * dt_s.max(0.0);
        // (A hair of slack: the last step of a ramp lands on the goal, not 1e-16 short of it.)
        if change_um <= allowed_um * (1.0 + 1e-9) {
            return goal;
        }
        let f = allowed_um / change_um;
        Line {
            offset_um: written.offset_um + f * d_off,
            slope_um_per_m: written.slope_um_per_m + f * d_slope,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn axis() -> AxisModel {
        let text = std::fs::read_to_string(concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../../data/thermal-live/model.json"
        ))
        .unwrap();
        let model: ThermalModel = serde_json::from_str(&text).unwrap();
        AxisModel::new(
            "X".into(),
            model,
            Limits {
                limit_um: 50.0,
                slope_limit_um_per_m: 100.0,
                rate_limit_um_s: 2.0,
            },
            false,
        )
    }

    #[test]
    fn rate_limit_bounds_the_change_at_the_travel_end() {
        let a = axis();
        // Travel 0 … 500 mm about Px = 0: the lever is 0.5 m.
        assert!((a.lever_m - 0.5).abs() < 1e-12);
        let goal = Line {
            offset_um: 0.0,
            slope_um_per_m: -40.0,
        };
        let mut w = Line::default();
        let mut steps = 0;
        while w != goal {
            let next = a.step_toward(w, goal, 0.1);
            // At x = 500 mm the change per 0.1 s is at most 2 µm/s·0.1 s.
            let change = (next.at(500.0, 0.0) - w.at(500.0, 0.0)).abs();
            assert!(change <= 0.2 + 1e-12, "{change}");
            w = next;
            steps += 1;
        }
        // 40 µm/m over 0.5 m is 20 µm: 100 steps of 0.2 µm.
        assert_eq!(steps, 100);
    }

    #[test]
    fn bounds_name_the_excess() {
        let a = axis();
        let ok = Line {
            offset_um: 0.0,
            slope_um_per_m: -99.0,
        };
        assert!(a.check_bounds(&ok, None).is_ok());
        let steep = Line {
            offset_um: 0.0,
            slope_um_per_m: 101.0,
        };
        assert!(a
            .check_bounds(&steep, None)
            .unwrap_err()
            .contains("slope 101.000"));
        let far = Line {
            offset_um: 30.0,
            slope_um_per_m: 90.0,
        };
        // 30 + 90·0.5 = 75 µm at 500 mm.
        let e = a.check_bounds(&far, None).unwrap_err();
        assert!(e.contains("75.000 µm at 500.0 mm"), "{e}");
    }
}
