//! Chart of a rotary analysis: angular error vs commanded angle per direction over the whole turn, with the spread of the repeats and the sign convention stated.

use super::analysis::{Analysis, TableRow};
use super::input::Direction;
use crate::Setting;
use errmap_core::error::Result;
use errmap_core::setting::words;
use errmap_report::chart::{save_png, Frame, FONT};
use plotters::coord::types::RangedCoordf64;
use plotters::coord::Shift;
use plotters::prelude::*;
use std::path::Path;

/// Colours of the two directions.
pub const FORWARD: RGBColor = RGBColor(0, 0, 255);
pub const REVERSE: RGBColor = RGBColor(255, 0, 0);

/// Where the measured angles lie on the chart's x axis.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Span {
    x0_deg: f64,
    x1_deg: f64,
    /// The measured angles go round the turn: the first angle's rows repeat at first + 360°.
    wraps: bool,
}

/// The x extent: a turn from the first angle when the angles go round it (the gap from the last
/// angle back to the first, across 360°, is no wider than the widest step between measured
/// angles), else the measured range.
fn span(rows: &[TableRow]) -> Span {
    let mut angles: Vec<f64> = rows.iter().map(|r| r.angle_deg).collect();
    angles.sort_by(f64::total_cmp);
    angles.dedup();
    let (Some(&first), Some(&last)) = (angles.first(), angles.last()) else {
        return Span {
            x0_deg: 0.0,
            x1_deg: 360.0,
            wraps: false,
        };
    };
    let widest = angles.windows(2).map(|w| w[1] - w[0]).fold(0.0, f64::max);
    let closing = first + 360.0 - last;
    let wraps = angles.len() >= 2 && closing > 1e-9 && closing <= widest + 1e-9;
    if wraps {
        Span {
            x0_deg: first,
            x1_deg: first + 360.0,
            wraps,
        }
    } else if last > first {
        Span {
            x0_deg: first,
            x1_deg: last,
            wraps,
        }
    } else {
        Span {
            x0_deg: first - 1.0,
            x1_deg: first + 1.0,
            wraps,
        }
    }
}

/// Tick marks on whole-degree multiples (…, 30°, 45°, 90°), at most 13 over the span.
fn ticks(s: Span) -> Vec<f64> {
    let width = s.x1_deg - s.x0_deg;
    let step = [1.0, 2.0, 5.0, 10.0, 15.0, 30.0, 45.0, 90.0, 180.0]
        .into_iter()
        .find(|step| width / step <= 12.0)
        .unwrap_or(360.0);
    let first = (s.x0_deg / step).ceil() as i64;
    let last = (s.x1_deg / step).floor() as i64;
    (first..=last).map(|k| k as f64 * step).collect()
}

/// What a drawing step returns inside [`save_png`].
type Drawn = std::result::Result<(), Box<dyn std::error::Error + Send + Sync>>;
/// The header or the whole image.
type Area<'a> = DrawingArea<BitMapBackend<'a>, Shift>;
/// The plot: commanded angle (°) against error (arcsec).
type Plot<'a, 'b> =
    ChartContext<'a, BitMapBackend<'b>, Cartesian2d<RangedCoordf64, RangedCoordf64>>;

/// Draw the error against α, one line per direction through the mean over the repeats (dots)
/// with a bar from the smallest to the largest repeat, over the whole turn when the angles go
/// round it (the first angle repeated at +360°, hollow dot), and the sign convention under the
/// title. Written as PNG; returns where the plot lies.
pub fn save_error_chart(path: &Path, analysis: &Analysis) -> Result<Frame> {
    let rows = &analysis.table;
    let s = span(rows);
    let (y0, y1) = error_range(rows);
    let sign = analysis.sign;
    // A little room either side so the end points are not cut by the frame.
    let x_pad = (s.x1_deg - s.x0_deg) * 0.015;
    let (x0, x1) = (s.x0_deg - x_pad, s.x1_deg + x_pad);
    let mut frame = None;
    save_png(path, 1000, 600, |root| {
        let (header, body) = root.split_vertically(122);
        draw_title(&header, analysis)?;
        let mut chart = ChartBuilder::on(&body)
            .margin(15)
            .x_label_area_size(45)
            .y_label_area_size(70)
            .build_cartesian_2d(x0..x1, y0..y1)?;
        chart
            .configure_mesh()
            .x_desc("commanded angle α (°)")
            .y_desc(format!("error {} (arcsec)", sign.formula()))
            .x_labels(0)
            .disable_x_mesh()
            .label_style((FONT, 15))
            .axis_desc_style((FONT, 16))
            .draw()?;
        draw_angle_ticks(root, &mut chart, s, (y0, y1))?;
        for (dir, colour, name) in [
            (Direction::Forward, FORWARD, "+ direction"),
            (Direction::Reverse, REVERSE, "− direction"),
        ] {
            draw_direction(&header, &mut chart, rows, s, (dir, colour, name))?;
        }
        if s.wraps {
            draw_closing_note(&header, s)?;
        }
        frame = Some(Frame::new((x0, x1), (y0, y1), |x, y| {
            chart.backend_coord(&(x, y))
        }));
        Ok(())
    })?;
    frame.ok_or_else(|| errmap_core::Error::Internal(format!("{}: no plot drawn", path.display())))
}

/// The y extent: the smallest to the largest repeat, padded by a tenth (at least 0.5″).
fn error_range(rows: &[TableRow]) -> (f64, f64) {
    let (mut y0, mut y1) = (f64::INFINITY, f64::NEG_INFINITY);
    for r in rows {
        y0 = y0.min(r.min_arcsec);
        y1 = y1.max(r.max_arcsec);
    }
    if !(y0.is_finite() && y1.is_finite()) {
        (y0, y1) = (-1.0, 1.0);
    }
    let pad = ((y1 - y0) * 0.1).max(0.5);
    (y0 - pad, y1 + pad)
}

/// The title and, under it, the sign convention and what a positive error means.
fn draw_title(header: &Area<'_>, analysis: &Analysis) -> Drawn {
    let sign = analysis.sign;
    let title = format!("{} axis: angular error = {}", analysis.axis, sign.formula());
    let note = [
        format!(
            "sign: {}",
            match sign {
                super::Sign::Errmap => format!(
                    "errmap, error = commanded − measured ({} errmap)",
                    words(Setting::Sign)
                ),
                super::Sign::Calibrator => format!(
                    "calibrator, error = measured − commanded as ISO 230-2's x ({} calibrator)",
                    words(Setting::Sign)
                ),
            }
        ),
        sign.positive(analysis.axis),
    ];
    header.draw(&Text::new(
        title,
        (14, 8),
        (FONT, 22).into_font().color(&BLACK),
    ))?;
    for (k, line) in note.iter().enumerate() {
        header.draw(&Text::new(
            line.clone(),
            (14, 38 + 19 * k as i32),
            (FONT, 15).into_font().color(&BLACK),
        ))?;
    }
    Ok(())
}

/// Angle ticks on whole multiples of 30°, 45° … with grid lines (plotters' own ticks fall on
/// decimal steps, 50°, 100° …), labelled under the plot on `root`.
fn draw_angle_ticks(root: &Area<'_>, chart: &mut Plot<'_, '_>, s: Span, y: (f64, f64)) -> Drawn {
    let (y0, y1) = y;
    let font = (FONT, 15).into_font().color(&BLACK);
    for a in ticks(s) {
        chart.draw_series(std::iter::once(PathElement::new(
            vec![(a, y0), (a, y1)],
            BLACK.mix(0.12).stroke_width(1),
        )))?;
        let (x, y) = chart.backend_coord(&(a, y0));
        root.draw(&PathElement::new(
            vec![(x, y), (x, y + 5)],
            BLACK.stroke_width(1),
        ))?;
        let label = format!("{a}°");
        root.draw(&Text::new(
            label.clone(),
            (x - 4 * label.chars().count() as i32, y + 8),
            font.clone(),
        ))?;
    }
    Ok(())
}

/// One direction: the line through the means (closing the turn when the angles go round it),
/// its legend in the header, the bars of the repeats, the dots, and the hollow repeated dot.
fn draw_direction(
    header: &Area<'_>,
    chart: &mut Plot<'_, '_>,
    rows: &[TableRow],
    s: Span,
    (dir, colour, name): (Direction, RGBColor, &str),
) -> Drawn {
    let mut pts: Vec<TableRow> = rows
        .iter()
        .filter(|r| r.direction == dir)
        .cloned()
        .collect();
    if pts.is_empty() {
        return Ok(());
    }
    pts.sort_by(|a, b| a.angle_deg.total_cmp(&b.angle_deg));
    let repeated = pts
        .first()
        .filter(|r| s.wraps && r.angle_deg == s.x0_deg)
        .map(|r| TableRow {
            angle_deg: r.angle_deg + 360.0,
            ..r.clone()
        });
    let line: Vec<(f64, f64)> = pts
        .iter()
        .chain(repeated.as_ref())
        .map(|r| (r.angle_deg, r.error_arcsec))
        .collect();
    chart.draw_series(LineSeries::new(line, colour.stroke_width(2)))?;
    draw_legend(header, dir, colour, name)?;
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
    chart.draw_series(
        pts.iter()
            .map(|r| Circle::new((r.angle_deg, r.error_arcsec), 4, colour.filled())),
    )?;
    if let Some(r) = &repeated {
        chart.draw_series(std::iter::once(Circle::new(
            (r.angle_deg, r.error_arcsec),
            5,
            colour.stroke_width(2),
        )))?;
    }
    Ok(())
}

/// A direction's legend in the header (inside the plot it would hide points): + left, − right.
fn draw_legend(header: &Area<'_>, dir: Direction, colour: RGBColor, name: &str) -> Drawn {
    let lx = if dir == Direction::Forward { 14 } else { 510 };
    header.draw(&PathElement::new(
        vec![(lx, 94), (lx + 24, 94)],
        colour.stroke_width(2),
    ))?;
    header.draw(&Circle::new((lx + 12, 94), 4, colour.filled()))?;
    header.draw(&Text::new(
        format!("{name}: mean of the repeats (dot), bar from smallest to largest"),
        (lx + 32, 86),
        (FONT, 14).into_font().color(&BLACK),
    ))?;
    Ok(())
}

/// The note on the hollow dot that closes the turn.
fn draw_closing_note(header: &Area<'_>, s: Span) -> Drawn {
    header.draw(&Circle::new((26, 110), 5, BLACK.stroke_width(2)))?;
    header.draw(&Text::new(
        format!(
            "hollow dot: the {}° point repeated at {}°, closing the turn",
            s.x0_deg, s.x1_deg
        ),
        (46, 102),
        (FONT, 14).into_font().color(&BLACK),
    ))?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rotary::input::parse_measurement;
    use crate::rotary::{analyze, AnalyzeOptions, Sign};
    use errmap_core::io::CsvTable;
    use std::fmt::Write;

    /// Planted err = α − β (arcsec) at the four measured angles of a C axis, + direction only.
    const PLANTED: [(f64, f64); 4] = [(0.0, 0.0), (90.0, 10.0), (180.0, -5.0), (270.0, 20.0)];

    fn analysis() -> Analysis {
        let mut s = String::from("axis,direction,repeat,angle_deg,sphere,x_mm,y_mm,z_mm\n");
        for (alpha, err) in PLANTED {
            let theta = (alpha - err / 3600.0).to_radians();
            for (k, r) in [(1, 50.0), (2, 250.0)] {
                let (x, y) = (r * theta.cos(), r * theta.sin());
                writeln!(s, "C,+,0,{alpha},{k},{x},{y},60").unwrap();
            }
        }
        let table = CsvTable::parse(Path::new("c.csv"), &s).unwrap();
        analyze(
            &parse_measurement(table).unwrap(),
            &AnalyzeOptions::default(),
        )
        .unwrap()
    }

    /// Pixels of the + direction's colour within ±6 px of the data point (angle, error).
    fn forward_pixels(img: &image::RgbImage, f: &Frame, angle_deg: f64, err: f64) -> usize {
        let (x, y) = f.to_px(angle_deg, err);
        let (x, y) = (x.round() as i64, y.round() as i64);
        (x - 6..=x + 6)
            .flat_map(|i| (y - 6..=y + 6).map(move |j| (i, j)))
            .filter(|&(i, j)| {
                i >= 0
                    && j >= 0
                    && img
                        .get_pixel_checked(i as u32, j as u32)
                        .is_some_and(|p| p.0 == [FORWARD.0, FORWARD.1, FORWARD.2])
            })
            .count()
    }

    #[test]
    fn the_turn_closes_at_360_degrees() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("c.png");
        let f = save_error_chart(&path, &analysis()).unwrap();
        if let Ok(keep) = std::env::var("ERRMAP_KEEP_PNG") {
            std::fs::copy(&path, keep).unwrap();
        }
        assert!(f.x_range.0 <= 0.0 && f.x_range.1 >= 360.0, "{f:?}");
        let img = image::open(&path).unwrap().to_rgb8();
        // The 0° point repeated at 360° with the line from 270° running into it.
        assert!(forward_pixels(&img, &f, 360.0, 0.0) > 20);
        assert!(
            forward_pixels(&img, &f, 315.0, 10.0) > 5,
            "the 270° → 360° line"
        );
        for (alpha, err) in PLANTED {
            assert!(forward_pixels(&img, &f, alpha, err) > 20, "{alpha}°");
        }
    }

    #[test]
    fn the_calibrator_sign_flips_the_points() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("c.png");
        let a = analysis().with_sign(Sign::Calibrator);
        assert_eq!(a.sign, Sign::Calibrator);
        let f = save_error_chart(&path, &a).unwrap();
        let img = image::open(&path).unwrap().to_rgb8();
        // err(270°) = +20″ is drawn at −20″ (measured − commanded) and not at +20″.
        assert!(forward_pixels(&img, &f, 270.0, -20.0) > 20);
        assert_eq!(forward_pixels(&img, &f, 270.0, 20.0), 0);
        // Flipping back restores the table exactly.
        let back = a.with_sign(Sign::Errmap);
        let orig = analysis();
        for (r, o) in back.table.iter().zip(&orig.table) {
            assert_eq!(
                (r.error_arcsec, r.min_arcsec, r.max_arcsec),
                (o.error_arcsec, o.min_arcsec, o.max_arcsec)
            );
        }
    }

    #[test]
    fn a_limited_range_does_not_wrap() {
        let rows: Vec<TableRow> = [-120.0, -90.0, -60.0, 0.0, 30.0]
            .into_iter()
            .map(|angle_deg| TableRow {
                angle_deg,
                direction: Direction::Forward,
                error_arcsec: 0.0,
                s_arcsec: None,
                n: 1,
                min_arcsec: 0.0,
                max_arcsec: 0.0,
            })
            .collect();
        let s = span(&rows);
        assert!(!s.wraps && s.x0_deg == -120.0 && s.x1_deg == 30.0, "{s:?}");
        assert_eq!(
            ticks(s),
            (-8..=2).map(|k| k as f64 * 15.0).collect::<Vec<_>>()
        );
    }
}
