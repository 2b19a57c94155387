//! Charts of the thermal commands: the fan of thermal error lines (seed 000), coloured by time with a colour bar, and the positioning figures before/after compensation over time.

use super::campaign::{direction_name, Direction, DIRECTIONS};
use super::difference::Difference;
use super::evaluate::EvaluationReport;
use errmap_core::error::Result;
use errmap_report::chart::{save_png, FONT};
use errmap_report::colormap::{draw_colour_bar, ColourBar, ColourMap};
use plotters::prelude::*;
use std::path::Path;

/// Picks one figure of a time, if the standard defines it there.
type Figure = fn(&super::evaluate::TimeFigures) -> Option<f64>;

/// The time scale of the fan's colours: minutes, or hours past three hours.
fn time_unit(span_s: f64) -> (&'static str, f64) {
    if span_s > 3.0 * 3600.0 {
        ("h", 3600.0)
    } else {
        ("min", 60.0)
    }
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

/// A drawing failure inside [`save_png`].
type DrawResult = std::result::Result<(), Box<dyn std::error::Error + Send + Sync>>;

/// A drawing area of a chart being saved.
type Area<'a> = DrawingArea<BitMapBackend<'a>, plotters::coord::Shift>;

/// Et points and the fitted line of every time, one panel per direction, coloured (viridis) by
/// the time since the cold measurement, with a colour bar saying so.
pub fn fan_chart(path: &Path, d: &Difference) -> Result<()> {
    let x_mm = span(d.rows.iter().map(|r| r.target_mm));
    let et_um = span(d.rows.iter().map(|r| r.et_um));
    let last_s = d
        .lines
        .iter()
        .map(|l| l.time_s - d.cold_time_s)
        .fold(0.0, f64::max);
    let (unit, per) = time_unit(last_s);
    let t_max = if last_s > 0.0 { last_s / per } else { 1.0 };
    let colour =
        move |time_s: f64| ColourMap::Viridis.of((time_s - d.cold_time_s) / per, 0.0, t_max);
    let bar_label = format!("time ({unit})");
    save_png(path, 1300, 560, |root| {
        let (plots, bar) = root.split_horizontally(1160);
        let panels = plots.split_evenly((1, 2));
        for (area, dir) in panels.iter().zip(DIRECTIONS) {
            fan_panel(area, d, dir, (x_mm, et_um), &colour)?;
        }
        fan_legend(&bar, t_max, &bar_label)
    })
}

/// One direction's panel of the fan: each time's line over the travel and its Et points.
fn fan_panel(
    area: &Area,
    d: &Difference,
    dir: Direction,
    ((x0, x1), (y0, y1)): ((f64, f64), (f64, f64)),
    colour: &dyn Fn(f64) -> RGBColor,
) -> DrawResult {
    let mut chart = ChartBuilder::on(area)
        .caption(
            format!(
                "{} {}: Et = E − Es, one line per measurement",
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
        let c = colour(line.time_s);
        let at = |x: f64| line.offset_um + line.slope_um_per_m * x / 1000.0;
        chart.draw_series(LineSeries::new(
            [(x0, at(x0)), (x1, at(x1))],
            c.stroke_width(2),
        ))?;
        chart.draw_series(
            d.rows
                .iter()
                .filter(|r| r.direction == dir && r.time_s == line.time_s)
                .map(|r| Circle::new((r.target_mm, r.et_um), 3, c.filled())),
        )?;
    }
    Ok(())
}

/// The fan's key: what dots, lines and colours mean, and the colour bar of time.
fn fan_legend(bar: &Area, t_max: f64, bar_label: &str) -> DrawResult {
    let small = (FONT, 13).into_font().color(&BLACK);
    for (k, line) in [
        "dots: measured Et",
        "lines: fitted Et",
        "",
        "colour: time since",
        "the cold (first)",
        "measurement",
    ]
    .into_iter()
    .enumerate()
    {
        bar.draw(&Text::new(line, (4, 14 + 17 * k as i32), small.clone()))?;
    }
    draw_colour_bar(
        bar,
        &ColourBar {
            map: ColourMap::Viridis,
            lo: 0.0,
            hi: t_max,
            label: bar_label,
            x_px: 20,
            top_px: 150,
            bottom_px: 500,
        },
    )
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
