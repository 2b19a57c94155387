//! Polar chart of a circular test: magnified deviation on a ring for both directions, the minimum-zone band of G, and the figures with the largest contributors named.

use super::figures::Centred;
use super::input::Direction;
use super::Evaluation;
use crate::error::Result;
use crate::report::chart::{save_png, FONT};
use plotters::prelude::*;
use std::f64::consts::TAU;
use std::path::Path;

/// Ring radius of the nominal circle in chart units; deviations of ±span µm reach ±DEV_UNITS.
const DEV_UNITS: f64 = 0.35;

/// The smallest 1-2-5 number ≥ `v` (at least 0.1).
fn nice_span(v: f64) -> f64 {
    let v = v.max(0.1);
    let p = 10f64.powf(v.log10().floor());
    [1.0, 2.0, 5.0, 10.0]
        .iter()
        .map(|m| m * p)
        .find(|&s| s >= v * (1.0 - 1e-12))
        .unwrap_or(10.0 * p)
}

fn fmt_opt(v: Option<f64>) -> String {
    v.map_or_else(|| "–".to_string(), |v| format!("{v:.2}"))
}

/// Draw the polar chart and write it as PNG.
pub fn save_polar_chart(path: &Path, eval: &Evaluation, c: &Centred) -> Result<()> {
    let f = &eval.figures;
    let max_abs = c.dev_um.iter().fold(0.0_f64, |m, v| m.max(v.abs()));
    let zone = &f.zone;
    let span = nice_span(max_abs.max(zone.outer_um.abs()).max(zone.inner_um.abs()));
    let to_xy = |angle: f64, dev_um: f64| {
        let rho = 1.0 + DEV_UNITS * dev_um / span;
        (rho * angle.cos(), rho * angle.sin())
    };
    let [first, second] = eval.axes;
    let mut text = vec![
        format!("R = {} mm, plane {first}{second}", f.radius_mm),
        format!("scale: ring ±{span} µm"),
        String::new(),
        format!("G ccw  {} µm", fmt_opt(f.g_um.ccw)),
        format!("G cw   {} µm", fmt_opt(f.g_um.cw)),
        format!("G bi   {} µm", fmt_opt(f.g_um.bidirectional)),
        format!("H      {} µm", fmt_opt(f.h_um)),
        format!(
            "F      {} / {} µm",
            fmt_opt(
                f.f_max_um
                    .bidirectional
                    .or(f.f_max_um.ccw)
                    .or(f.f_max_um.cw)
            ),
            fmt_opt(
                f.f_min_um
                    .bidirectional
                    .or(f.f_min_um.ccw)
                    .or(f.f_min_um.cw)
            )
        ),
        format!(
            "centre {:+.2}, {:+.2} µm",
            f.centre_offset_um[0], f.centre_offset_um[1]
        ),
        format!("residual RMS {:.2} µm", eval.residual_rms_um),
        String::new(),
        "largest contributors:".to_string(),
    ];
    let terms = eval.terms.list();
    for key in eval.model.largest.iter().take(4) {
        if let Some((_, t)) = terms.iter().find(|(k, _)| k == key) {
            text.push(format!(
                " {} {:.3}: {:.0} % of G",
                key,
                t.value.unwrap_or(0.0),
                100.0 * t.share_of_g.unwrap_or(0.0)
            ));
        }
    }
    if eval.model.largest.is_empty() {
        text.push(" none above 5 % of G".to_string());
    }
    let band: Vec<(f64, f64)> = {
        let [a, b] = zone.centre_from_lsc_um;
        let curve = |level: f64, rev: bool| {
            let mut pts: Vec<(f64, f64)> = (0..=360)
                .map(|k| {
                    let t = TAU * k as f64 / 360.0;
                    to_xy(t, a * t.cos() + b * t.sin() + level)
                })
                .collect();
            if rev {
                pts.reverse();
            }
            pts
        };
        let mut v = curve(zone.outer_um, false);
        v.extend(curve(zone.inner_um, true));
        v
    };
    save_png(path, 1250, 900, |root| {
        let (left, right) = root.split_horizontally(900);
        let mut chart = ChartBuilder::on(&left)
            .caption("Circular test (ISO 230-4)", (FONT, 22))
            .margin(20)
            .build_cartesian_2d(-1.5..1.5, -1.5..1.5)?;
        chart
            .draw_series(std::iter::once(Polygon::new(band.clone(), GREEN.mix(0.18))))?
            .label(format!(
                "minimum zone G = {:.2} µm",
                zone.outer_um - zone.inner_um
            ))
            .legend(|(x, y)| {
                Rectangle::new([(x, y - 5), (x + 20, y + 5)], GREEN.mix(0.3).filled())
            });
        // Grid: rings at −span, −span/2, 0, +span/2, +span and spokes every 30°.
        for k in -2..=2 {
            let dev = span * k as f64 / 2.0;
            let style = if k == 0 {
                BLACK.stroke_width(2)
            } else {
                BLACK.mix(0.25).stroke_width(1)
            };
            chart.draw_series(std::iter::once(PathElement::new(
                (0..=360)
                    .map(|i| to_xy(TAU * i as f64 / 360.0, dev))
                    .collect::<Vec<_>>(),
                style,
            )))?;
        }
        for k in 0..12 {
            let t = TAU * k as f64 / 12.0;
            chart.draw_series(std::iter::once(PathElement::new(
                vec![to_xy(t, -span * 1.2), to_xy(t, span * 1.2)],
                BLACK.mix(0.2),
            )))?;
        }
        for (label, pos) in [
            (format!("+{first}"), (1.42, -0.03)),
            (format!("+{second}"), (-0.04, 1.45)),
            (
                format!("+{span} µm"),
                (to_xy(0.3, span).0, to_xy(0.3, span).1),
            ),
        ] {
            chart.draw_series(std::iter::once(Text::new(label, pos, (FONT, 16))))?;
        }
        for (d, colour) in [(Direction::Ccw, BLUE), (Direction::Cw, RED)] {
            let mut pts: Vec<(f64, f64)> = c
                .of(d)
                .iter()
                .map(|&i| (c.angle_rad[i], c.dev_um[i]))
                .collect();
            if pts.is_empty() {
                continue;
            }
            pts.sort_by(|a, b| a.0.total_cmp(&b.0));
            pts.push(pts[0]);
            chart
                .draw_series(LineSeries::new(
                    pts.iter().map(|&(a, v)| to_xy(a, v)),
                    // Width 1: plotters joins wide polylines with miters that spike on noise.
                    colour.stroke_width(1),
                ))?
                .label(d.name())
                .legend(move |(x, y)| {
                    PathElement::new(vec![(x, y), (x + 20, y)], colour.stroke_width(2))
                });
        }
        chart
            .configure_series_labels()
            .position(SeriesLabelPosition::LowerLeft)
            .label_font((FONT, 15))
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK)
            .draw()?;
        for (i, line) in text.iter().enumerate() {
            right.draw(&Text::new(
                line.clone(),
                (10, 60 + 26 * i as i32),
                (FONT, 16).into_font().color(&BLACK),
            ))?;
        }
        Ok(())
    })
}
