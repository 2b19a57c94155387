//! Polar chart of a circular test: magnified deviation on a ring for both directions, the minimum-zone band of G, and the figures with the largest contributors named.

use super::figures::{Centred, ZoneReport};
use super::input::Rotation;
use super::Evaluation;
use errmap_core::error::Result;
use errmap_report::chart::{save_png, FONT};
use plotters::coord::types::RangedCoordf64;
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
    errmap_core::numeric::format::opt(v, 2, "–")
}

/// Magnified polar position of a deviation: the nominal circle at radius 1, ±span µm at ±DEV_UNITS.
#[derive(Clone, Copy)]
struct Polar {
    span_um: f64,
}

impl Polar {
    fn xy(self, angle_rad: f64, dev_um: f64) -> (f64, f64) {
        let rho = 1.0 + DEV_UNITS * dev_um / self.span_um;
        (rho * angle_rad.cos(), rho * angle_rad.sin())
    }
}

/// The text beside the chart: figures and the largest contributors.
fn side_text(eval: &Evaluation, span_um: f64) -> Vec<String> {
    let f = &eval.figures;
    let [first, second] = eval.axes;
    let either = |v: &super::PerDirection| v.bidirectional.or(v.ccw).or(v.cw);
    let mut text = vec![
        format!("R = {} mm, plane {first}{second}", f.radius_mm),
        format!("scale: ring ±{span_um} µm"),
        String::new(),
        format!("G ccw  {} µm", fmt_opt(f.g_um.ccw)),
        format!("G cw   {} µm", fmt_opt(f.g_um.cw)),
        format!("G bi   {} µm", fmt_opt(f.g_um.bidirectional)),
        format!("H      {} µm", fmt_opt(f.h_um)),
        format!(
            "F      {} / {} µm",
            fmt_opt(either(&f.f_max_um)),
            fmt_opt(either(&f.f_min_um))
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
    text
}

/// The minimum-zone band as one closed polygon: its outer circle, then its inner one backwards
/// (both about the zone centre, drawn in the chart's LSC coordinates).
fn zone_band(zone: &ZoneReport, polar: Polar) -> Vec<(f64, f64)> {
    let [a, b] = zone.centre_from_lsc_um;
    let curve = |level: f64| {
        (0..=360).map(move |k| {
            let t = TAU * k as f64 / 360.0;
            polar.xy(t, a * t.cos() + b * t.sin() + level)
        })
    };
    let mut v: Vec<(f64, f64)> = curve(zone.outer_um).collect();
    let inner: Vec<(f64, f64)> = curve(zone.inner_um).collect();
    v.extend(inner.into_iter().rev());
    v
}

/// Grid lines: rings at −span, −span/2, 0 (the nominal circle, major), +span/2, +span, and
/// spokes every 30°.
fn grid_paths(polar: Polar) -> Vec<(Vec<(f64, f64)>, bool)> {
    let span = polar.span_um;
    let mut paths: Vec<(Vec<(f64, f64)>, bool)> = (-2..=2)
        .map(|k| {
            let dev = span * k as f64 / 2.0;
            let ring = (0..=360)
                .map(|i| polar.xy(TAU * i as f64 / 360.0, dev))
                .collect();
            (ring, k == 0)
        })
        .collect();
    for k in 0..12 {
        let t = TAU * k as f64 / 12.0;
        paths.push((
            vec![polar.xy(t, -span * 1.2), polar.xy(t, span * 1.2)],
            false,
        ));
    }
    paths
}

/// The polar plot area: chart units, the nominal circle at radius 1.
type Plot<'a, 'b> =
    ChartContext<'a, BitMapBackend<'b>, Cartesian2d<RangedCoordf64, RangedCoordf64>>;

/// What a drawing stage returns (plotters' errors, turned into ours by `save_png`).
type Drawn = std::result::Result<(), Box<dyn std::error::Error + Send + Sync>>;

/// Draw the polar chart and write it as PNG.
pub fn save_polar_chart(path: &Path, eval: &Evaluation, c: &Centred) -> Result<()> {
    let zone = &eval.figures.zone;
    let max_abs = c.dev_um.iter().fold(0.0_f64, |m, v| m.max(v.abs()));
    let span = nice_span(max_abs.max(zone.outer_um.abs()).max(zone.inner_um.abs()));
    let polar = Polar { span_um: span };
    let text = side_text(eval, span);
    save_png(path, 1250, 900, |root| {
        let (left, right) = root.split_horizontally(900);
        let mut chart = ChartBuilder::on(&left)
            .caption("Circular test (ISO 230-4)", (FONT, 22))
            .margin(20)
            .build_cartesian_2d(-1.5..1.5, -1.5..1.5)?;
        draw_zone_and_grid(&mut chart, zone, polar)?;
        draw_axis_labels(&mut chart, eval.axes, polar)?;
        draw_paths(&mut chart, c, polar)?;
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

/// The minimum-zone band (with its legend entry) under the rings and spokes of the grid.
fn draw_zone_and_grid(chart: &mut Plot<'_, '_>, zone: &ZoneReport, polar: Polar) -> Drawn {
    chart
        .draw_series(std::iter::once(Polygon::new(
            zone_band(zone, polar),
            GREEN.mix(0.18),
        )))?
        .label(format!(
            "minimum zone G = {:.2} µm",
            zone.outer_um - zone.inner_um
        ))
        .legend(|(x, y)| Rectangle::new([(x, y - 5), (x + 20, y + 5)], GREEN.mix(0.3).filled()));
    for (path, major) in grid_paths(polar) {
        let style = if major {
            BLACK.stroke_width(2)
        } else {
            BLACK.mix(0.25).stroke_width(1)
        };
        chart.draw_series(std::iter::once(PathElement::new(path, style)))?;
    }
    Ok(())
}

/// The axis directions and the scale of the outer ring.
fn draw_axis_labels(chart: &mut Plot<'_, '_>, axes: [&str; 2], polar: Polar) -> Drawn {
    let [first, second] = axes;
    let span = polar.span_um;
    for (label, pos) in [
        (format!("+{first}"), (1.42, -0.03)),
        (format!("+{second}"), (-0.04, 1.45)),
        (format!("+{span} µm"), polar.xy(0.3, span)),
    ] {
        chart.draw_series(std::iter::once(Text::new(label, pos, (FONT, 16))))?;
    }
    Ok(())
}

/// Each direction's path, closed, sorted by angle about the least-squares centre.
fn draw_paths(chart: &mut Plot<'_, '_>, c: &Centred, polar: Polar) -> Drawn {
    for (d, colour) in [(Rotation::Ccw, BLUE), (Rotation::Cw, RED)] {
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
                pts.iter().map(|&(a, v)| polar.xy(a, v)),
                // Width 1: plotters joins wide polylines with miters that spike on noise.
                colour.stroke_width(1),
            ))?
            .label(d.name())
            .legend(move |(x, y)| {
                PathElement::new(vec![(x, y), (x + 20, y)], colour.stroke_width(2))
            });
    }
    Ok(())
}
