//! Vendor-style positioning chart: mean deviation per direction (markers at the targets) with the ±k·s band at each target, reversal marked, the pitch fit as a curve on a dense grid, before/after a table, and the axis figures beside it.

use super::eval::Evaluation;
use super::pitch::PitchFit;
use errmap_core::error::Result;
use errmap_report::chart::{save_png, Frame, FONT};
use plotters::coord::types::RangedCoordf64;
use plotters::coord::Shift;
use plotters::prelude::*;
use std::path::Path;

/// What the chart shows.
pub struct ChartInput<'a> {
    /// Title drawn above the plot.
    pub title: String,
    /// Unit of the deviations, e.g. "µm".
    pub unit: &'a str,
    /// The evaluation drawn: mean deviation and ±k·s band of each direction at each target.
    pub before: &'a Evaluation,
    /// Figures after applying a compensation table.
    pub after: Option<&'a Evaluation>,
    /// The pitch-error fit drawn as a curve; `None`: no curve.
    pub fit: Option<&'a PitchFit>,
}

fn fmt_opt(v: Option<f64>) -> String {
    errmap_core::numeric::format::opt(v, 2, "n/a")
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

/// Width of the chart's plotting area, pixels (about: the left panel less its label areas).
const PLOT_PX: f64 = 800.0;

/// The pitch fit evaluated on a grid fine enough for both the screen and the screw: at least
/// 2 points per pixel of the plot and 64 per lead, so the periodic term is drawn as the curve it
/// is between the targets, never as chords through them (capped at 200 000 points).
pub fn fit_curve(fit: &PitchFit, x_min: f64, x_max: f64, plot_px: f64) -> Vec<(f64, f64)> {
    let span = (x_max - x_min).max(0.0);
    let per_lead = if fit.lead_mm > 0.0 {
        64.0 * span / fit.lead_mm
    } else {
        0.0
    };
    let steps = (2.0 * plot_px).max(per_lead).clamp(1.0, 200_000.0).ceil() as usize;
    (0..=steps)
        .map(|i| {
            let x = x_min + span * i as f64 / steps as f64;
            (x, fit.eval(x))
        })
        .collect()
}

/// The plot area: target position (mm) × deviation.
type Plot<'a, 'b> =
    ChartContext<'a, BitMapBackend<'b>, Cartesian2d<RangedCoordf64, RangedCoordf64>>;

/// What a drawing stage returns (plotters' errors, turned into ours by `save_png`).
type Drawn = std::result::Result<(), Box<dyn std::error::Error + Send + Sync>>;

/// Draw the chart to `path` (PNG, 1280 × 720); returns where the plot lies.
pub fn save_chart(path: &Path, input: &ChartInput<'_>) -> Result<Frame> {
    let ev = input.before;
    let (y0, y1) = deviation_range(ev, input.after);
    let xs: Vec<f64> = ev.targets.iter().map(|t| t.target).collect();
    let x_min = xs.first().copied().unwrap_or(0.0);
    let x_max = xs.last().copied().unwrap_or(1.0).max(x_min + 1e-9);
    let x_pad = (x_max - x_min) * 0.03;
    let unit = input.unit;
    let mut frame = None;
    save_png(path, 1280, 720, |root| {
        let (left, right) = root.split_horizontally(900);
        let mut chart = ChartBuilder::on(&left)
            .caption(&input.title, (FONT, 22))
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
        draw_bands(&mut chart, ev)?;
        draw_means(&mut chart, ev)?;
        draw_widest_reversal(&mut chart, ev)?;
        if let Some(fit) = input.fit {
            draw_fit(&mut chart, fit, (x_min, x_max), unit)?;
        }
        if let Some(after) = input.after {
            draw_after(&mut chart, after)?;
        }
        chart
            .configure_series_labels()
            .label_font((FONT, 13))
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK)
            .position(SeriesLabelPosition::UpperLeft)
            .draw()?;
        frame = Some(Frame::new(
            (x_min - x_pad, x_max + x_pad),
            (y0, y1),
            |x, y| chart.backend_coord(&(x, y)),
        ));
        draw_side_table(&right, input)
    })?;
    frame.ok_or_else(|| errmap_core::Error::Internal(format!("{}: no plot drawn", path.display())))
}

/// The deviation axis: every mean ± k·s of both evaluations, with a margin.
fn deviation_range(ev: &Evaluation, after: Option<&Evaluation>) -> (f64, f64) {
    let k = ev.k;
    let mut lo = f64::INFINITY;
    let mut hi = f64::NEG_INFINITY;
    let mut grow = |v: f64| {
        lo = lo.min(v);
        hi = hi.max(v);
    };
    for e in std::iter::once(ev).chain(after) {
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
    (lo - pad, hi + pad)
}

/// Colours of the forward (↑) and reverse (↓) means.
const BLUE_UP: RGBColor = RGBColor(31, 90, 200);
const RED_DOWN: RGBColor = RGBColor(200, 40, 40);

/// (target, mean) of one direction's measured targets.
fn mean_series(e: &Evaluation, up: bool) -> Vec<(f64, f64)> {
    e.targets
        .iter()
        .filter_map(|t| {
            let x = if up { t.mean_up } else { t.mean_down };
            x.map(|x| (t.target, x))
        })
        .collect()
}

/// Bands ±k·s at each target (error bars), both directions.
fn draw_bands(chart: &mut Plot<'_, '_>, ev: &Evaluation) -> Drawn {
    let k = ev.k;
    for t in &ev.targets {
        for (mean, s, colour) in [
            (t.mean_up, t.s_up, BLUE_UP),
            (t.mean_down, t.s_down, RED_DOWN),
        ] {
            if let Some((x, s)) = mean.zip(s) {
                chart.draw_series(std::iter::once(ErrorBar::new_vertical(
                    t.target,
                    x - k * s,
                    x,
                    x + k * s,
                    colour.stroke_width(1),
                    8,
                )))?;
            }
        }
    }
    Ok(())
}

/// Measured means as dots, joined by thin straight lines (vendor style); only the measured
/// directions are drawn (a unidirectional test has one line).
fn draw_means<'a, 'b: 'a>(chart: &mut Plot<'a, 'b>, ev: &Evaluation) -> Drawn {
    let band = format!("±{}s", ev.k);
    for (up, colour, name) in [
        (true, BLUE_UP, "mean ↑ (forward)"),
        (false, RED_DOWN, "mean ↓ (reverse)"),
    ] {
        let pts = mean_series(ev, up);
        if pts.is_empty() {
            continue;
        }
        chart.draw_series(LineSeries::new(pts.clone(), colour.stroke_width(1)))?;
        chart
            .draw_series(
                pts.iter()
                    .map(|&(x, e)| Circle::new((x, e), 4, colour.filled())),
            )?
            .label(format!("{name} at each target (dot), bar {band}"))
            .legend(move |(x, y)| {
                EmptyElement::at((x + 10, y))
                    + PathElement::new(vec![(-10, 0), (10, 0)], colour.stroke_width(1))
                    + Circle::new((0, 0), 4, colour.filled())
            });
    }
    Ok(())
}

/// Reversal: mark the target with the largest |B_i| (none in a unidirectional test).
fn draw_widest_reversal(chart: &mut Plot<'_, '_>, ev: &Evaluation) -> Drawn {
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
    Ok(())
}

/// The pitch fit as a curve over `x_range_mm`, and its trend a + k·x dashed.
fn draw_fit(
    chart: &mut Plot<'_, '_>,
    fit: &PitchFit,
    (x_min, x_max): (f64, f64),
    unit: &str,
) -> Drawn {
    chart
        .draw_series(LineSeries::new(
            fit_curve(fit, x_min, x_max, PLOT_PX),
            FIT.stroke_width(1),
        ))?
        .label(format!(
            "pitch fit a + k·x + d·sin(2πx/P + φ): k = {:.2} {unit}/m, d = {:.2} {unit}, P = {} mm",
            fit.k_um_per_m, fit.d_um, fit.lead_mm
        ))
        .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], FIT.stroke_width(1)));
    let trend = |x: f64| fit.a_um + fit.k_um_per_m * x * 1e-3;
    chart
        .draw_series(DashedLineSeries::new(
            [(x_min, trend(x_min)), (x_max, trend(x_max))],
            6,
            4,
            FIT.stroke_width(2),
        ))?
        .label("pitch fit without its periodic term: a + k·x")
        .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 8, y)], FIT.stroke_width(2)));
    Ok(())
}

/// The means after applying a compensation table, in light colours.
fn draw_after(chart: &mut Plot<'_, '_>, after: &Evaluation) -> Drawn {
    for (up, colour, label) in [
        (true, RGBColor(120, 160, 240), "after table ↑"),
        (false, RGBColor(240, 140, 140), "after table ↓"),
    ] {
        chart
            .draw_series(LineSeries::new(
                mean_series(after, up),
                colour.stroke_width(2),
            ))?
            .label(label)
            .legend(move |(x, y)| {
                PathElement::new(vec![(x, y), (x + 20, y)], colour.stroke_width(2))
            });
    }
    Ok(())
}

/// The figures table beside the plot: before (and after), the counts, the fit.
fn draw_side_table(right: &DrawingArea<BitMapBackend<'_>, Shift>, input: &ChartInput<'_>) -> Drawn {
    let ev = input.before;
    let unit = input.unit;
    let font = (FONT, 15).into_font();
    let bold = (FONT, 17).into_font().style(FontStyle::Bold);
    right.draw(&Text::new(
        format!("{} ({unit})", ev.standard.name()),
        (10, 30),
        bold.clone(),
    ))?;
    let has_after = input.after.is_some();
    let header = if has_after { "before      after" } else { "" };
    right.draw(&Text::new(header.to_string(), (200, 60), font.clone()))?;
    let rows = figure_rows(ev, input.after);
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
}

/// Colour of the pitch fit.
pub const FIT: RGBColor = RGBColor(20, 140, 60);

#[cfg(test)]
mod tests {
    use super::*;
    use crate::linear::{evaluate, fit_pitch, Direction, Sample, Standard};

    /// e(x) = 2 µm + 10 µm/m · x + 8 µm · sin(2πx/50 + 0.3): a screw of lead 50 mm over 200 mm.
    fn planted(x_mm: f64) -> f64 {
        2.0 + 10.0 * x_mm * 1e-3 + 8.0 * (2.0 * std::f64::consts::PI * x_mm / 50.0 + 0.3).sin()
    }

    const TARGETS: [f64; 11] = [
        0.0, 17.0, 41.0, 58.0, 83.0, 100.0, 124.0, 141.0, 166.0, 183.0, 200.0,
    ];

    #[test]
    fn the_fit_is_a_curve_between_the_targets_not_chords() {
        let samples: Vec<Sample> = (0..5)
            .flat_map(|run| {
                [Direction::Forward, Direction::Reverse]
                    .into_iter()
                    .flat_map(move |direction| {
                        TARGETS.iter().map(move |&target| Sample {
                            run,
                            direction,
                            target,
                            deviation: planted(target),
                        })
                    })
            })
            .collect();
        let ev = evaluate(&samples, Standard::Iso230_2_2014).unwrap();
        let means: Vec<f64> = TARGETS.iter().map(|&x| planted(x)).collect();
        let fit = fit_pitch(&TARGETS, &means, 50.0).unwrap();
        // The noise-free fit is the planted curve (checked against the formula, not the fit).
        assert!((fit.d_um - 8.0).abs() < 1e-9 && (fit.k_um_per_m - 10.0).abs() < 1e-9);
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("x.png");
        let input = ChartInput {
            title: "synthetic".into(),
            unit: "µm",
            before: &ev,
            after: None,
            fit: Some(&fit),
        };
        let f = save_chart(&path, &input).unwrap();
        let img = image::open(&path).unwrap().to_rgb8();
        let fit_at = |x: f64, y: f64| -> bool {
            let (px, py) = f.pixel(x, y);
            (-2..=2).any(|d| img.get_pixel(px as u32, (py + d) as u32).0 == [FIT.0, FIT.1, FIT.2])
        };
        let mut checked = 0;
        for w in TARGETS.windows(2) {
            let x = (w[0] + w[1]) / 2.0;
            let (truth, chord) = (planted(x), (planted(w[0]) + planted(w[1])) / 2.0);
            let trend = 2.0 + 10.0 * x * 1e-3;
            let px = |y: f64| f.to_px(x, y).1;
            // Below the legend box, and the chord well apart from the curve and the dashed trend.
            if px(truth) < 140.0 || (px(truth) - px(chord)).abs() < 10.0 {
                continue;
            }
            if (px(chord) - px(trend)).abs() < 6.0 {
                continue;
            }
            assert!(
                fit_at(x, truth),
                "no fit curve at x = {x} mm, e = {truth:.2} µm"
            );
            assert!(!fit_at(x, chord), "fit drawn as a chord at x = {x} mm");
            checked += 1;
        }
        assert!(checked >= 3, "only {checked} midpoints checked");
    }

    #[test]
    fn the_fit_grid_resolves_the_screw_and_the_pixels() {
        // The sample axis: 1000 mm with a 10 mm lead is 100 periods over ~800 px.
        let fit = PitchFit {
            lead_mm: 10.0,
            a_um: 0.0,
            k_um_per_m: 0.0,
            d_um: 1.0,
            phi_rad: 0.0,
            residual_rms_um: 0.0,
            points: 21,
        };
        let pts = fit_curve(&fit, 0.0, 1000.0, PLOT_PX);
        let step = pts[1].0 - pts[0].0;
        assert!(step <= 10.0 / 64.0 + 1e-12, "step {step} mm");
        assert!(pts.len() as f64 >= 2.0 * PLOT_PX);
        // Every crest of the sine is reached to within 0.2 % of d.
        let top = pts.iter().map(|p| p.1).fold(f64::MIN, f64::max);
        assert!(top > 0.998, "{top}");
    }
}
