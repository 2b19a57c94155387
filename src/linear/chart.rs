//! Vendor-style positioning chart: mean deviation per direction with the ±k·s band at each target, reversal marked, pitch fit, before/after a table, and the axis figures beside it.

use super::eval::Evaluation;
use super::pitch::PitchFit;
use crate::error::Result;
use crate::report::chart::{save_png, FONT};
use plotters::prelude::*;
use std::path::Path;

/// What the chart shows.
pub struct ChartInput<'a> {
    pub title: String,
    /// Unit of the deviations, e.g. "µm".
    pub unit: &'a str,
    pub before: &'a Evaluation,
    /// Figures after applying a compensation table.
    pub after: Option<&'a Evaluation>,
    pub fit: Option<&'a PitchFit>,
}

fn fmt_opt(v: Option<f64>) -> String {
    v.map(|v| format!("{v:.2}")).unwrap_or_else(|| "n/a".into())
}

/// The figures of the side table: (label, before, after).
fn figure_rows(before: &Evaluation, after: Option<&Evaluation>) -> Vec<(String, String, String)> {
    let rows = |e: &Evaluation| -> Vec<(&'static str, String)> {
        let a = &e.axis;
        vec![
            ("A (accuracy)", fmt_opt(a.A)),
            ("A↑", fmt_opt(a.A_up)),
            ("A↓", fmt_opt(a.A_down)),
            ("R (repeatability)", fmt_opt(a.R)),
            ("R↑", fmt_opt(a.R_up)),
            ("R↓", fmt_opt(a.R_down)),
            ("E (systematic)", fmt_opt(a.E)),
            ("E↑", fmt_opt(a.E_up)),
            ("E↓", fmt_opt(a.E_down)),
            ("M (mean range)", fmt_opt(a.M)),
            ("B (reversal)", fmt_opt(a.B)),
            ("B mean (signed)", fmt_opt(a.B_mean)),
        ]
    };
    let b = rows(before);
    let a = after.map(rows);
    b.into_iter()
        .enumerate()
        .map(|(i, (label, v))| {
            let after_v = a
                .as_ref()
                .and_then(|r| r.get(i))
                .map(|r| r.1.clone())
                .unwrap_or_default();
            (label.to_string(), v, after_v)
        })
        .collect()
}

/// Draw the chart to `path` (PNG, 1280 × 720).
pub fn save_chart(path: &Path, input: &ChartInput<'_>) -> Result<()> {
    let ev = input.before;
    let k = ev.k;
    let xs: Vec<f64> = ev.targets.iter().map(|t| t.target).collect();
    let mut lo = f64::INFINITY;
    let mut hi = f64::NEG_INFINITY;
    let mut grow = |v: f64| {
        lo = lo.min(v);
        hi = hi.max(v);
    };
    for e in std::iter::once(ev).chain(input.after) {
        for t in &e.targets {
            // A direction not measured (unidirectional test) adds nothing.
            for (x, s) in [(t.mean_up, t.s_up), (t.mean_down, t.s_down)] {
                if let Some(x) = x {
                    grow(x + k * s.unwrap_or(0.0));
                    grow(x - k * s.unwrap_or(0.0));
                }
            }
        }
    }
    if !(lo.is_finite() && hi.is_finite()) {
        lo = -1.0;
        hi = 1.0;
    }
    let pad = ((hi - lo) * 0.12).max(0.5);
    let (y0, y1) = (lo - pad, hi + pad);
    let x_min = xs.first().copied().unwrap_or(0.0);
    let x_max = xs.last().copied().unwrap_or(1.0).max(x_min + 1e-9);
    let x_pad = (x_max - x_min) * 0.03;
    let unit = input.unit.to_string();
    let title = input.title.clone();
    let rows = figure_rows(ev, input.after);
    let standard = ev.standard.name().to_string();
    let band = format!("±{k}s");
    save_png(path, 1280, 720, move |root| {
        let (left, right) = root.split_horizontally(900);
        let mut chart = ChartBuilder::on(&left)
            .caption(&title, (FONT, 22))
            .margin(12)
            .x_label_area_size(45)
            .y_label_area_size(70)
            .build_cartesian_2d((x_min - x_pad)..(x_max + x_pad), y0..y1)?;
        chart
            .configure_mesh()
            .x_desc("target position (mm)")
            .y_desc(format!("deviation ({unit})"))
            .label_style((FONT, 14))
            .axis_desc_style((FONT, 16))
            .draw()?;
        let blue = RGBColor(31, 90, 200);
        let red = RGBColor(200, 40, 40);
        let series = |e: &Evaluation, up: bool| -> Vec<(f64, f64)> {
            e.targets
                .iter()
                .filter_map(|t| {
                    let x = if up { t.mean_up } else { t.mean_down };
                    x.map(|x| (t.target, x))
                })
                .collect()
        };
        // Bands ±k·s at each target (error bars), both directions.
        for t in &ev.targets {
            if let Some((x, s)) = t.mean_up.zip(t.s_up) {
                chart.draw_series(std::iter::once(ErrorBar::new_vertical(
                    t.target,
                    x - k * s,
                    x,
                    x + k * s,
                    blue.stroke_width(1),
                    8,
                )))?;
            }
            if let Some((x, s)) = t.mean_down.zip(t.s_down) {
                chart.draw_series(std::iter::once(ErrorBar::new_vertical(
                    t.target,
                    x - k * s,
                    x,
                    x + k * s,
                    red.stroke_width(1),
                    8,
                )))?;
            }
        }
        // Only the measured directions are drawn (a unidirectional test has one line).
        let up_pts = series(ev, true);
        if !up_pts.is_empty() {
            chart
                .draw_series(LineSeries::new(up_pts, blue.stroke_width(2)))?
                .label(format!("mean ↑ (forward), {band}"))
                .legend(move |(x, y)| {
                    PathElement::new(vec![(x, y), (x + 20, y)], blue.stroke_width(2))
                });
        }
        let down_pts = series(ev, false);
        if !down_pts.is_empty() {
            chart
                .draw_series(LineSeries::new(down_pts, red.stroke_width(2)))?
                .label(format!("mean ↓ (reverse), {band}"))
                .legend(move |(x, y)| {
                    PathElement::new(vec![(x, y), (x + 20, y)], red.stroke_width(2))
                });
        }
        // Reversal: mark the target with the largest |B_i| (none in a unidirectional test).
        let widest = ev
            .targets
            .iter()
            .filter_map(|t| Some((t, t.reversal?, t.mean_up?, t.mean_down?)))
            .max_by(|a, b| a.1.abs().total_cmp(&b.1.abs()));
        if let Some((t, b_i, x_up, x_down)) = widest {
            let grey = RGBColor(90, 90, 90);
            chart.draw_series(std::iter::once(PathElement::new(
                vec![(t.target, x_up), (t.target, x_down)],
                grey.stroke_width(3),
            )))?;
            chart.draw_series(std::iter::once(Text::new(
                format!(" B = {:.2}", b_i.abs()),
                (t.target, (x_up + x_down) / 2.0),
                (FONT, 14).into_font().color(&grey),
            )))?;
        }
        if let Some(fit) = input.fit {
            let green = RGBColor(20, 140, 60);
            let steps = 600;
            let pts: Vec<(f64, f64)> = (0..=steps)
                .map(|i| {
                    let x = x_min + (x_max - x_min) * i as f64 / steps as f64;
                    (x, fit.eval(x))
                })
                .collect();
            chart
                .draw_series(LineSeries::new(pts, green.stroke_width(1)))?
                .label(format!(
                    "pitch fit: k = {:.2} {unit}/m, d = {:.2} {unit}, P = {} mm",
                    fit.k_um_per_m, fit.d_um, fit.lead_mm
                ))
                .legend(move |(x, y)| {
                    PathElement::new(vec![(x, y), (x + 20, y)], green.stroke_width(1))
                });
        }
        if let Some(after) = input.after {
            let light_blue = RGBColor(120, 160, 240);
            let light_red = RGBColor(240, 140, 140);
            chart
                .draw_series(LineSeries::new(
                    series(after, true),
                    light_blue.stroke_width(2),
                ))?
                .label("after table ↑")
                .legend(move |(x, y)| {
                    PathElement::new(vec![(x, y), (x + 20, y)], light_blue.stroke_width(2))
                });
            chart
                .draw_series(LineSeries::new(
                    series(after, false),
                    light_red.stroke_width(2),
                ))?
                .label("after table ↓")
                .legend(move |(x, y)| {
                    PathElement::new(vec![(x, y), (x + 20, y)], light_red.stroke_width(2))
                });
        }
        chart
            .configure_series_labels()
            .label_font((FONT, 13))
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK)
            .position(SeriesLabelPosition::UpperLeft)
            .draw()?;

        // The figures table.
        let font = (FONT, 15).into_font();
        let bold = (FONT, 17).into_font().style(FontStyle::Bold);
        right.draw(&Text::new(
            format!("{standard} ({unit})"),
            (10, 30),
            bold.clone(),
        ))?;
        let has_after = input.after.is_some();
        let header = if has_after { "before      after" } else { "" };
        right.draw(&Text::new(header.to_string(), (200, 60), font.clone()))?;
        for (i, (label, before, after)) in rows.iter().enumerate() {
            let y = 90 + 28 * i as i32;
            right.draw(&Text::new(label.clone(), (10, y), font.clone()))?;
            right.draw(&Text::new(before.clone(), (200, y), font.clone()))?;
            if has_after {
                right.draw(&Text::new(after.clone(), (290, y), font.clone()))?;
            }
        }
        let mut y = 90 + 28 * rows.len() as i32 + 20;
        let n_note = format!(
            "targets: {}, runs ↑ {} ↓ {}",
            ev.targets.len(),
            ev.targets.first().map(|t| t.n_up).unwrap_or(0),
            ev.targets.first().map(|t| t.n_down).unwrap_or(0)
        );
        right.draw(&Text::new(n_note, (10, y), font.clone()))?;
        if let Some(fit) = input.fit {
            for line in [
                format!("fit a = {:.3} {unit}", fit.a_um),
                format!("fit k = {:.3} {unit}/m", fit.k_um_per_m),
                format!("fit d = {:.3} {unit}, φ = {:.3} rad", fit.d_um, fit.phi_rad),
                format!("fit residual RMS = {:.3} {unit}", fit.residual_rms_um),
            ] {
                y += 26;
                right.draw(&Text::new(line, (10, y), font.clone()))?;
            }
        }
        Ok(())
    })
}
