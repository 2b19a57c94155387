//! Charts of the thermal commands: the fan of thermal error lines (seed 000) and the positioning
//! figures before/after compensation over time.

use super::campaign::{direction_name, DIRECTIONS};
use super::difference::Difference;
use super::evaluate::EvaluationReport;
use crate::error::Result;
use crate::report::chart::{save_png, FONT};
use plotters::prelude::*;
use std::path::Path;

/// Picks one figure of a time, if the standard defines it there.
type Figure = fn(&super::evaluate::TimeFigures) -> Option<f64>;

/// Colour of time `t` on a blue (cold) → red (warm) scale over `[t0, t1]`.
fn time_colour(t: f64, t0: f64, t1: f64) -> RGBColor {
    let w = if t1 > t0 {
        ((t - t0) / (t1 - t0)).clamp(0.0, 1.0)
    } else {
        0.0
    };
    RGBColor((40.0 + 200.0 * w) as u8, 60, (230.0 - 200.0 * w) as u8)
}

fn span(values: impl Iterator<Item = f64>) -> (f64, f64) {
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for v in values {
        lo = lo.min(v);
        hi = hi.max(v);
    }
    if !lo.is_finite() {
        return (0.0, 1.0);
    }
    let pad = ((hi - lo) * 0.08).max(0.5);
    (lo - pad, hi + pad)
}

/// Et points and the fitted line of every time, one panel per direction.
pub fn fan_chart(path: &Path, d: &Difference) -> Result<()> {
    let (x0, x1) = span(d.rows.iter().map(|r| r.target_mm));
    let (y0, y1) = span(d.rows.iter().map(|r| r.et_um));
    let (t0, t1) = span(d.lines.iter().map(|l| l.time_s));
    save_png(path, 1200, 560, |root| {
        let panels = root.split_evenly((1, 2));
        for (area, dir) in panels.iter().zip(DIRECTIONS) {
            let mut chart = ChartBuilder::on(area)
                .caption(
                    format!(
                        "{} {}: Et = E − Es (blue cold → red warm)",
                        d.campaign,
                        direction_name(dir)
                    ),
                    (FONT, 16),
                )
                .margin(12)
                .x_label_area_size(40)
                .y_label_area_size(56)
                .build_cartesian_2d(x0..x1, y0..y1)?;
            chart
                .configure_mesh()
                .x_desc("target (mm)")
                .y_desc("thermal error Et (µm)")
                .label_style((FONT, 13))
                .axis_desc_style((FONT, 14))
                .draw()?;
            for line in d.lines.iter().filter(|l| l.direction == dir) {
                let colour = time_colour(line.time_s, t0, t1);
                let at = |x: f64| line.offset_um + line.slope_um_per_m * x / 1000.0;
                chart.draw_series(LineSeries::new(
                    [(x0, at(x0)), (x1, at(x1))],
                    colour.stroke_width(2),
                ))?;
                chart.draw_series(
                    d.rows
                        .iter()
                        .filter(|r| r.direction == dir && r.time_s == line.time_s)
                        .map(|r| Circle::new((r.target_mm, r.et_um), 3, colour.filled())),
                )?;
            }
        }
        Ok(())
    })
}

/// Systematic deviation E and accuracy A (when defined) before and after, over time.
pub fn evaluate_chart(path: &Path, report: &EvaluationReport) -> Result<()> {
    let hours = |t: f64| t / 3600.0;
    let (x0, x1) = span(report.times.iter().map(|t| hours(t.time_s)));
    let values = report.times.iter().flat_map(|t| {
        [t.before.E, t.after.E, t.before.A, t.after.A]
            .into_iter()
            .flatten()
    });
    let (_, y1) = span(values);
    let mut campaigns: Vec<&str> = report.times.iter().map(|t| t.campaign.as_str()).collect();
    campaigns.dedup();
    save_png(path, 1000, 600, |root| {
        let mut chart = ChartBuilder::on(root)
            .caption(
                format!(
                    "positioning figures before / after compensation ({})",
                    report.standard
                ),
                (FONT, 18),
            )
            .margin(14)
            .x_label_area_size(40)
            .y_label_area_size(56)
            .build_cartesian_2d(x0..x1, 0.0..y1)?;
        chart
            .configure_mesh()
            .x_desc("time (h)")
            .y_desc("µm")
            .label_style((FONT, 13))
            .axis_desc_style((FONT, 14))
            .draw()?;
        let series: [(&str, RGBColor, Figure); 4] = [
            ("E before", RED, |t| t.before.E),
            ("E after", BLUE, |t| t.after.E),
            ("A before", RGBColor(240, 150, 40), |t| t.before.A),
            ("A after", RGBColor(40, 160, 220), |t| t.after.A),
        ];
        for (label, colour, get) in series {
            let mut first = true;
            for c in &campaigns {
                let pts: Vec<(f64, f64)> = report
                    .times
                    .iter()
                    .filter(|t| t.campaign == *c)
                    .filter_map(|t| get(t).map(|v| (hours(t.time_s), v)))
                    .collect();
                if pts.is_empty() {
                    continue;
                }
                let drawn = chart.draw_series(LineSeries::new(pts, colour.stroke_width(2)))?;
                if first {
                    drawn.label(label).legend(move |(x, y)| {
                        PathElement::new([(x, y), (x + 18, y)], colour.stroke_width(2))
                    });
                    first = false;
                }
            }
        }
        chart
            .configure_series_labels()
            .position(SeriesLabelPosition::UpperLeft)
            .label_font((FONT, 14))
            .border_style(BLACK)
            .background_style(WHITE.mix(0.85))
            .draw()?;
        Ok(())
    })
}
