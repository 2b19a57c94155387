//! The terminal text of each thermal command's result: tables and reports, each line ending
//! in a newline, for the caller to print.

use super::campaign::direction_name;
use super::commands::ModelsReport;
use super::compensate::CompensateSummary;
use super::difference::Difference;
use super::evaluate::EvaluationReport;
use super::model::ThermalModel;
use super::sensors::CalibrationFit;
use super::store::IngestSummary;
use std::fmt::Write;

/// A figure at 3 decimals, or `n/a`.
fn opt(v: Option<f64>) -> String {
    errmap_core::numeric::format::opt(v, 3, "n/a")
}

/// `thermal calibrate`: one row per sensor.
pub fn calibration_table(fits: &[CalibrationFit]) -> String {
    let mut t = String::from("sensor      offset_c     scale  residual_rms_c  samples\n");
    for f in fits {
        let _ = writeln!(
            t,
            "{:<10} {:>9.4} {:>9.5} {:>15.4} {:>8}{}",
            f.sensor,
            f.calibration.offset_c,
            f.calibration.scale,
            f.residual_rms_c,
            f.samples,
            if f.scale_fitted {
                ""
            } else {
                "  (offset only: too little range)"
            }
        );
    }
    t
}

/// `thermal difference`: the error line of each time and direction.
pub fn difference_table(d: &Difference) -> String {
    let mut t = String::new();
    let _ = writeln!(
        t,
        "campaign {} — thermal error lines Et = offset + slope·x (cold measurement at {} s)",
        d.campaign, d.cold_time_s
    );
    t.push_str("  time_s  dir  slope_um_per_m  offset_um  rms_um\n");
    for l in &d.lines {
        let _ = writeln!(
            t,
            "{:>8} {:>4} {:>15.3} {:>10.3} {:>7.3}",
            l.time_s,
            l.direction.symbol(),
            l.slope_um_per_m,
            l.offset_um,
            l.rms_um
        );
    }
    t
}

/// `thermal ingest`: what one campaign added.
pub fn ingest_line(s: &IngestSummary) -> String {
    format!(
        "{}: {} sensors, {} temperature samples, {} laser readings{}\n",
        s.campaign,
        s.sensors,
        s.temperature_samples,
        s.laser_readings,
        if s.replaced { " (replaced)" } else { "" }
    )
}

/// `thermal fit`: the model's settings, each direction's terms and each campaign's residuals.
pub fn model_report(m: &ThermalModel) -> String {
    let mut t = model_header(m);
    for d in &m.directions {
        let _ = writeln!(
            t,
            "{}: Er(x) order {} ({}), residual RMS {:.3} µm over {} readings",
            direction_name(d.direction),
            d.order,
            d.order_chosen_by,
            d.residual_rms_um,
            d.points
        );
        let coeffs: Vec<String> = d
            .legendre_um
            .iter()
            .zip(&d.legendre_se_um)
            .map(|(c, se)| format!("{c:.3}±{}", opt(*se)))
            .collect();
        let _ = writeln!(t, "  Er Legendre coefficients (µm): {}", coeffs.join("  "));
        for gset in &d.gains {
            let ks: Vec<String> = gset
                .k_um_per_m_k
                .iter()
                .map(|(s, k)| {
                    let se = gset.k_se_um_per_m_k.get(s).copied().flatten();
                    format!("k_{s} = {k:.3}±{} µm/m/K", opt(se))
                })
                .collect();
            let _ = writeln!(t, "  coolant {}: {}", gset.coolant, ks.join(", "));
        }
        if m.ambient_sensor.is_some() {
            let _ = writeln!(
                t,
                "  ρ = {:.3}{} µm/m/K ({})",
                d.rho_um_per_m_k,
                d.rho_se_um_per_m_k
                    .map(|s| format!("±{s:.3}"))
                    .unwrap_or_default(),
                if d.rho_fitted { "fitted" } else { "given" }
            );
        }
    }
    t + &model_campaigns(m)
}

/// The model's axis, sensors and reference choice.
fn model_header(m: &ThermalModel) -> String {
    let mut t = String::new();
    let _ = writeln!(
        t,
        "axis {}: Px = {} mm, travel {} … {} mm, sensors {}{}",
        m.axis,
        m.reference_point_mm,
        m.x_min_mm,
        m.x_max_mm,
        m.gain_sensors.join(", "),
        m.ambient_sensor
            .as_ref()
            .map(|a| format!(", ambient {a}"))
            .unwrap_or_default()
    );
    let scores: Vec<String> = m
        .reference_cv
        .iter()
        .map(|r| format!("{} {}", r.reference.name(), opt(r.loco_rms_um)))
        .collect();
    let _ = writeln!(
        t,
        "rises from: {} ({}); held-out RMS µm by reference: {}",
        m.reference.name(),
        m.reference_chosen_by,
        scores.join(", ")
    );
    t
}

/// The residuals of each campaign the model was fitted to, and the held-out RMS.
fn model_campaigns(m: &ThermalModel) -> String {
    let mut t =
        String::from("campaign                     coolant  times  residual_rms_um  loco_rms_um\n");
    for c in &m.campaigns {
        let _ = writeln!(
            t,
            "{:<28} {:<8} {:>5} {:>16.3} {:>12}{}",
            c.name,
            c.coolant,
            c.measurements,
            c.residual_rms_um,
            opt(c.loco_rms_um),
            c.loco_note
                .as_ref()
                .map(|n| format!("  ({n})"))
                .unwrap_or_default()
        );
    }
    if let Some(l) = m.loco_rms_um {
        let _ = writeln!(t, "leave-one-campaign-out RMS: {l:.3} µm");
    }
    t
}

/// `thermal models`: the stored campaigns and one row per model version.
pub fn models_table(r: &ModelsReport) -> String {
    let mut t = format!("campaigns: {}\n", r.campaigns.join(", "));
    t.push_str("name        version  created_unix  loco_rms_um  campaigns\n");
    for m in &r.models {
        let _ = writeln!(
            t,
            "{:<11} {:>7} {:>13} {:>12}  {}",
            m.name,
            m.version,
            m.created_unix,
            opt(m.loco_rms_um),
            m.campaigns.join(",")
        );
    }
    t
}

/// `thermal compensate`: rows, largest compensation and rows outside the model's travel.
pub fn compensate_line(s: &CompensateSummary, model: &ThermalModel) -> String {
    format!(
        "{} rows, max |compensation| {:.3} µm, {} rows outside the fitted travel {} … {} mm\n",
        s.rows, s.max_abs_compensation_um, s.outside_travel, model.x_min_mm, model.x_max_mm
    )
}

/// `thermal evaluate`: E, A and B before → after compensation for each measurement.
pub fn evaluate_table(report: &EvaluationReport) -> String {
    let mut t = format!(
        "standard {}: figures before → after compensation (µm)\n",
        report.standard
    );
    t.push_str("campaign                      time_s   E before → after   A before → after   B before → after\n");
    for r in &report.times {
        let _ = writeln!(
            t,
            "{:<28} {:>7} {:>8} → {:<7} {:>8} → {:<7} {:>7} → {:<7}",
            r.campaign,
            r.time_s,
            opt(r.before.E),
            opt(r.after.E),
            opt(r.before.A),
            opt(r.after.A),
            opt(r.before.B),
            opt(r.after.B)
        );
    }
    t
}
