//! Heatmap pictures of error maps: diverging colour map centred on 0 µm, colour bar, axes in mm, probe points.
//!
//! A map is drawn cell by cell (one cell per grid node, centred on it) with equal scales on both
//! axes, probe points as black dots, rejected points as crossed circles, a colour bar with µm
//! ticks on the right, and a legend line under the title saying what the colours and marks mean.

use crate::error::Result;
use crate::report::chart::{self, FONT};
use plotters::prelude::*;
use std::path::Path;

/// How values map to colours.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Scale {
    /// Blue (below nominal) – white (0 µm) – red (above nominal), limits ±max|E|.
    Diverging,
    /// White (0) to dark purple (max), for magnitudes such as a standard deviation.
    Sequential,
}

/// One picture of a map over a regular grid in the map plane.
#[derive(Debug, Clone)]
pub struct Heatmap<'a> {
    /// Title line, e.g. `web-plate p01 — PV 41.2 µm, RMS 12.0 µm` (see [`pv_rms_um`]).
    pub title: String,
    /// Axis names of the plane, e.g. ("x", "y").
    pub u_name: &'a str,
    pub v_name: &'a str,
    /// What the colour shows, e.g. "E (µm)".
    pub value_label: &'a str,
    /// First node and step of the grid, mm; node (i, j) sits at (u0 + i·step, v0 + j·step).
    pub u0_mm: f64,
    pub v0_mm: f64,
    pub step_mm: f64,
    pub nu: usize,
    pub nv: usize,
    /// Values at the nodes, index j·nu + i; `None` is drawn grey (no value there).
    pub values: &'a [Option<f64>],
    /// Probe points kept (u, v) mm.
    pub probes: &'a [(f64, f64)],
    /// Rejected probe points (u, v) mm.
    pub rejected: &'a [(f64, f64)],
    pub scale: Scale,
    /// Nodes outside the measured domain (index j·nu + i), drawn lightened; empty = none.
    pub extrapolated: &'a [bool],
}

/// Peak-to-valley and RMS (about 0) of the values present, µm.
pub fn pv_rms_um(values: &[Option<f64>]) -> (f64, f64) {
    let present: Vec<f64> = values.iter().flatten().copied().collect();
    if present.is_empty() {
        return (0.0, 0.0);
    }
    let max = present.iter().cloned().fold(f64::NEG_INFINITY, f64::max);
    let min = present.iter().cloned().fold(f64::INFINITY, f64::min);
    let rms = (present.iter().map(|v| v * v).sum::<f64>() / present.len() as f64).sqrt();
    (max - min, rms)
}

/// A "nice" colour limit ≥ `v` (1, 2, 2.5, 5 × 10ⁿ), so colour-bar ticks fall on round numbers.
pub fn nice_limit(v: f64) -> f64 {
    if !(v.is_finite() && v > 0.0) {
        return 1.0;
    }
    let p = 10f64.powf(v.log10().floor());
    for m in [1.0, 2.0, 2.5, 5.0, 10.0] {
        if m * p >= v * (1.0 - 1e-12) {
            return m * p;
        }
    }
    10.0 * p
}

// ColorBrewer RdBu (11 classes), reversed so negative is blue and positive red.
const DIVERGING: [(u8, u8, u8); 11] = [
    (5, 48, 97),
    (33, 102, 172),
    (67, 147, 195),
    (146, 197, 222),
    (209, 229, 240),
    (247, 247, 247),
    (253, 219, 199),
    (244, 165, 130),
    (214, 96, 77),
    (178, 24, 43),
    (103, 0, 31),
];

// ColorBrewer Purples (9 classes), white to dark purple.
const SEQUENTIAL: [(u8, u8, u8); 9] = [
    (252, 251, 253),
    (239, 237, 245),
    (218, 218, 235),
    (188, 189, 220),
    (158, 154, 200),
    (128, 125, 186),
    (106, 81, 163),
    (84, 39, 143),
    (63, 0, 125),
];

/// Colour of `t` in [0, 1] along a piecewise-linear palette.
fn palette(colours: &[(u8, u8, u8)], t: f64) -> RGBColor {
    let t = if t.is_finite() {
        t.clamp(0.0, 1.0)
    } else {
        0.5
    };
    let x = t * (colours.len() - 1) as f64;
    let i = (x.floor() as usize).min(colours.len() - 2);
    let f = x - i as f64;
    let (a, b) = (colours[i], colours[i + 1]);
    let mix = |p: u8, q: u8| (p as f64 + (q as f64 - p as f64) * f).round() as u8;
    RGBColor(mix(a.0, b.0), mix(a.1, b.1), mix(a.2, b.2))
}

/// The colour limits (lo, hi) a map is drawn with: symmetric about 0 for [`Scale::Diverging`].
pub fn limits(values: &[Option<f64>], scale: Scale) -> (f64, f64) {
    let max_abs = values.iter().flatten().fold(0.0f64, |m, v| m.max(v.abs()));
    let lim = nice_limit(max_abs);
    match scale {
        Scale::Diverging => (-lim, lim),
        Scale::Sequential => (0.0, lim),
    }
}

fn colour_of(v: f64, lo: f64, hi: f64, scale: Scale) -> RGBColor {
    let t = (v - lo) / (hi - lo);
    match scale {
        Scale::Diverging => palette(&DIVERGING, t),
        Scale::Sequential => palette(&SEQUENTIAL, t),
    }
}

/// Draw the heatmap and write it to `path` as PNG (atomically).
pub fn save_heatmap(path: &Path, map: &Heatmap<'_>) -> Result<()> {
    let step = if map.step_mm > 0.0 { map.step_mm } else { 1.0 };
    let half = step / 2.0;
    let u_lo = map.u0_mm - half;
    let v_lo = map.v0_mm - half;
    let u_hi = map.u0_mm + step * map.nu.saturating_sub(1) as f64 + half;
    let v_hi = map.v0_mm + step * map.nv.saturating_sub(1) as f64 + half;
    // Equal scales: the plotting area's pixel aspect equals the domain's.
    const MARGIN: u32 = 12;
    const Y_LABELS: u32 = 70;
    const X_LABELS: u32 = 50;
    const HEADER: u32 = 64;
    const BAR: u32 = 130;
    let aspect = ((v_hi - v_lo) / (u_hi - u_lo)).clamp(0.05, 20.0);
    let (mut plot_w, mut plot_h) = (800.0, 800.0 * aspect);
    if plot_h > 700.0 {
        plot_h = 700.0;
        plot_w = plot_h / aspect;
    }
    let plot_w = plot_w.round().max(120.0) as u32;
    let plot_h = plot_h.round().max(120.0) as u32;
    let main_w = plot_w + Y_LABELS + 2 * MARGIN;
    let width = main_w + BAR;
    let height = HEADER + plot_h + X_LABELS + 2 * MARGIN;
    let (lo, hi) = limits(map.values, map.scale);
    let values = map.values;
    let (nu, nv) = (map.nu, map.nv);
    chart::save_png(path, width, height, |root| {
        let (header, body) = root.split_vertically(HEADER);
        header.draw(&Text::new(
            map.title.clone(),
            (MARGIN as i32, 6),
            (FONT, 22).into_font().color(&BLACK),
        ))?;
        // Legend line: what the marks and colours mean.
        let small = (FONT, 15).into_font().color(&BLACK);
        let y = 44;
        let mut x = MARGIN as i32 + 6;
        // Marks appear in the legend only when the picture has them.
        if !map.probes.is_empty() {
            header.draw(&Circle::new((x, y), 3, BLACK.filled()))?;
            let probe_text = format!("probe point ({})", map.probes.len());
            header.draw(&Text::new(
                probe_text.clone(),
                (x + 10, y - 9),
                small.clone(),
            ))?;
            x += 24 + 8 * probe_text.chars().count() as i32;
        }
        if !map.rejected.is_empty() || !map.probes.is_empty() {
            draw_rejected_mark(&header, (x, y))?;
            let rej_text = format!("rejected gross error ({})", map.rejected.len());
            header.draw(&Text::new(rej_text.clone(), (x + 12, y - 9), small.clone()))?;
            x += 28 + 8 * rej_text.chars().count() as i32;
        }
        let sense = match map.scale {
            Scale::Diverging => "red: above nominal (E > 0), blue: below",
            Scale::Sequential => "darker: larger",
        };
        header.draw(&Text::new(sense, (x, y - 9), small.clone()))?;

        let (main, _bar) = body.split_horizontally(main_w);
        let mut chart = ChartBuilder::on(&main)
            .margin(MARGIN)
            .x_label_area_size(X_LABELS)
            .y_label_area_size(Y_LABELS)
            .build_cartesian_2d(u_lo..u_hi, v_lo..v_hi)?;
        chart
            .configure_mesh()
            .disable_mesh()
            .x_desc(format!("{} (mm)", map.u_name))
            .y_desc(format!("{} (mm)", map.v_name))
            .label_style((FONT, 14))
            .axis_desc_style((FONT, 16))
            .draw()?;
        let grey = RGBColor(200, 200, 200);
        chart.draw_series(
            (0..nv)
                .flat_map(|j| (0..nu).map(move |i| (i, j)))
                .map(|(i, j)| {
                    let u = map.u0_mm + step * i as f64;
                    let v = map.v0_mm + step * j as f64;
                    let mut colour = match values.get(j * nu + i).copied().flatten() {
                        Some(e) => colour_of(e, lo, hi, map.scale),
                        None => grey,
                    };
                    if map.extrapolated.get(j * nu + i) == Some(&true) {
                        // Extrapolated: halfway to white, so the measured domain stands out.
                        let w = |c: u8| ((u16::from(c) + 255) / 2) as u8;
                        colour = RGBColor(w(colour.0), w(colour.1), w(colour.2));
                    }
                    Rectangle::new(
                        [(u - half, v - half), (u + half, v + half)],
                        colour.filled(),
                    )
                }),
        )?;
        chart.draw_series(
            map.probes
                .iter()
                .map(|&(u, v)| Circle::new((u, v), 3, BLACK.filled())),
        )?;
        for &(u, v) in map.rejected {
            let (px, py) = chart.backend_coord(&(u, v));
            draw_rejected_mark(root, (px, py))?;
        }

        // Colour bar beside the plot, same height, ticks and labels in the map's unit on its right.
        let (_, y_px) = chart.plotting_area().get_pixel_range();
        let (top, bottom) = (y_px.start, y_px.end);
        let x0 = main_w as i32 + 6;
        let x1 = x0 + 24;
        let span = (bottom - top).max(1);
        for k in 0..span {
            // Row k from the top shows the value at its centre.
            let value = hi - (hi - lo) * (k as f64 + 0.5) / span as f64;
            let c = colour_of(value, lo, hi, map.scale);
            root.draw(&Rectangle::new(
                [(x0, top + k), (x1, top + k + 1)],
                c.filled(),
            ))?;
        }
        root.draw(&Rectangle::new(
            [(x0, top), (x1, bottom)],
            BLACK.stroke_width(1),
        ))?;
        let tick = nice_limit((hi - lo) / 10.0);
        let decimals = if tick >= 1.0 {
            0
        } else if tick >= 0.1 {
            1
        } else {
            2
        };
        let first = (lo / tick).ceil() as i64;
        let last = (hi / tick).floor() as i64;
        let label_font = (FONT, 14).into_font().color(&BLACK);
        for n in first..=last {
            let value = n as f64 * tick;
            let y = bottom - ((value - lo) / (hi - lo) * span as f64).round() as i32;
            root.draw(&PathElement::new(
                vec![(x1, y), (x1 + 5, y)],
                BLACK.stroke_width(1),
            ))?;
            root.draw(&Text::new(
                format!("{value:.decimals$}"),
                (x1 + 8, y - 7),
                label_font.clone(),
            ))?;
        }
        root.draw(&Text::new(
            map.value_label.to_string(),
            (x0 - 4, top - 22),
            (FONT, 15).into_font().color(&BLACK),
        ))?;
        Ok(())
    })
}

/// The rejected-point mark: a black cross inside a white-rimmed circle, visible on any colour.
fn draw_rejected_mark<DB: DrawingBackend>(
    area: &DrawingArea<DB, plotters::coord::Shift>,
    (x, y): (i32, i32),
) -> std::result::Result<(), Box<dyn std::error::Error + Send + Sync>>
where
    DB::ErrorType: 'static,
{
    area.draw(&Circle::new((x, y), 8, WHITE.stroke_width(4)))?;
    area.draw(&Circle::new((x, y), 8, BLACK.stroke_width(2)))?;
    area.draw(&PathElement::new(
        vec![(x - 5, y - 5), (x + 5, y + 5)],
        BLACK.stroke_width(2),
    ))?;
    area.draw(&PathElement::new(
        vec![(x - 5, y + 5), (x + 5, y - 5)],
        BLACK.stroke_width(2),
    ))?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn limits_are_symmetric_and_nice() {
        assert_eq!(nice_limit(37.0), 50.0);
        assert_eq!(nice_limit(2.1), 2.5);
        assert_eq!(nice_limit(0.9), 1.0);
        let v = [Some(-3.0), None, Some(17.0)];
        assert_eq!(limits(&v, Scale::Diverging), (-20.0, 20.0));
        assert_eq!(limits(&v, Scale::Sequential), (0.0, 20.0));
        let (pv, rms) = pv_rms_um(&v);
        assert!((pv - 20.0).abs() < 1e-12);
        assert!((rms - ((9.0 + 289.0) / 2.0f64).sqrt()).abs() < 1e-12);
    }

    #[test]
    fn zero_is_white_and_signs_are_red_and_blue() {
        let white = colour_of(0.0, -10.0, 10.0, Scale::Diverging);
        assert_eq!((white.0, white.1, white.2), (247, 247, 247));
        let hot = colour_of(10.0, -10.0, 10.0, Scale::Diverging);
        let cold = colour_of(-10.0, -10.0, 10.0, Scale::Diverging);
        assert!(hot.0 > hot.2 && cold.2 > cold.0);
    }

    #[test]
    fn draws_cells_in_their_colours_with_equal_axes() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("m.png");
        // 3 × 2 grid over 20 × 10 mm: left column −3 µm, right column +3 µm (limits ±5).
        let values: Vec<Option<f64>> = (0..6)
            .map(|k| {
                Some(if k % 3 == 0 {
                    -3.0
                } else if k % 3 == 2 {
                    3.0
                } else {
                    0.0
                })
            })
            .collect();
        let map = Heatmap {
            title: "test".into(),
            u_name: "x",
            v_name: "y",
            value_label: "E (µm)",
            u0_mm: 0.0,
            v0_mm: 0.0,
            step_mm: 10.0,
            nu: 3,
            nv: 2,
            values: &values,
            probes: &[(0.0, 0.0)],
            rejected: &[(20.0, 10.0)],
            scale: Scale::Diverging,
            extrapolated: &[],
        };
        save_heatmap(&path, &map).unwrap();
        if let Ok(keep) = std::env::var("ERRMAP_KEEP_PNG") {
            std::fs::copy(&path, keep).unwrap();
        }
        let img = image::open(&path).unwrap().to_rgb8();
        // The 30 × 20 mm extent gives a 3:2 plotting area: 800 × 533 px.
        assert_eq!(img.width(), 800 + 70 + 24 + 130);
        assert_eq!(img.height(), 64 + 533 + 50 + 24);
        let reddish = img
            .pixels()
            .filter(|p| p.0[0] > 150 && p.0[2] < 120)
            .count();
        let bluish = img
            .pixels()
            .filter(|p| p.0[2] > 150 && p.0[0] < 120)
            .count();
        // A third of the plot is each colour (the colour bar adds a little of both).
        assert!(reddish > 100_000 && bluish > 100_000, "{reddish} {bluish}");
    }
}
