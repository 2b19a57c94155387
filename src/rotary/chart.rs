//! Chart of a rotary analysis: angular error vs commanded angle per direction, with the spread of the repeats.

use super::analysis::Analysis;
use super::input::Direction;
use crate::error::Result;
use crate::report::chart::{save_png, FONT};
use plotters::prelude::*;
use std::path::Path;

/// Draw err = α − β against α, one line per direction (mean over the repeats) with a bar
/// from the smallest to the largest repeat at each angle, and write it as PNG.
pub fn save_error_chart(path: &Path, analysis: &Analysis) -> Result<()> {
    let rows = &analysis.table;
    let (mut x0, mut x1) = (f64::INFINITY, f64::NEG_INFINITY);
    let (mut y0, mut y1) = (f64::INFINITY, f64::NEG_INFINITY);
    for r in rows {
        x0 = x0.min(r.angle_deg);
        x1 = x1.max(r.angle_deg);
        y0 = y0.min(r.min_arcsec);
        y1 = y1.max(r.max_arcsec);
    }
    if x1 <= x0 {
        x0 -= 1.0;
        x1 += 1.0;
    }
    let pad = ((y1 - y0) * 0.1).max(0.5);
    let (y0, y1) = (y0 - pad, y1 + pad);
    let title = format!("{} axis: angular error err = α − β", analysis.axis);
    save_png(path, 1000, 600, |root| {
        let mut chart = ChartBuilder::on(root)
            .caption(title, (FONT, 22))
            .margin(15)
            .x_label_area_size(45)
            .y_label_area_size(70)
            .build_cartesian_2d(x0..x1, y0..y1)?;
        chart
            .configure_mesh()
            .x_desc("commanded angle α (°)")
            .y_desc("error (arcsec)")
            .label_style((FONT, 15))
            .axis_desc_style((FONT, 16))
            .draw()?;
        for (dir, colour, name) in [
            (Direction::Forward, BLUE, "+ direction (min…max of repeats)"),
            (Direction::Reverse, RED, "− direction (min…max of repeats)"),
        ] {
            let pts: Vec<_> = rows.iter().filter(|r| r.direction == dir).collect();
            if pts.is_empty() {
                continue;
            }
            chart
                .draw_series(LineSeries::new(
                    pts.iter().map(|r| (r.angle_deg, r.error_arcsec)),
                    colour.stroke_width(2),
                ))?
                .label(name)
                .legend(move |(x, y)| {
                    PathElement::new(vec![(x, y), (x + 20, y)], colour.stroke_width(2))
                });
            chart.draw_series(pts.iter().map(|r| {
                ErrorBar::new_vertical(
                    r.angle_deg,
                    r.min_arcsec,
                    r.error_arcsec,
                    r.max_arcsec,
                    colour.filled(),
                    8,
                )
            }))?;
        }
        chart
            .configure_series_labels()
            .label_font((FONT, 15))
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK)
            .draw()?;
        Ok(())
    })
}
