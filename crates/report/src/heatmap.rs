//! Heatmap pictures of error maps: diverging colours centred on 0 µm (or viridis for magnitudes), colour bar, axes in mm, probes, rejects and the measured hull.
//!
//! A map is drawn cell by cell (one cell per grid node, centred on it) with equal scales on both
//! axes; probe points as black dots in a white rim, rejected points as crossed circles, the
//! measured hull as a black outline on a white rim, nodes outside it lightened; a colour bar
//! with its quantity and unit on the right, and legend lines under the title saying what every
//! mark, line and colour means. Colour maps: [`crate::colormap`].

use crate::chart::{self, Frame, FONT};
use crate::colormap::{draw_colour_bar, nice_limit, ColourBar, ColourMap};
use errmap_core::error::Result;
use plotters::coord::types::RangedCoordf64;
use plotters::prelude::*;
use std::path::Path;

/// How values map to colours.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Scale {
    /// Signed errors: RdBu, blue (below nominal) – white (0 µm) – red (above nominal), limits ±max|E|.
    Diverging,
    /// Magnitudes such as a standard deviation: viridis from 0 (dark) to the largest (light).
    Sequential,
}

impl Scale {
    /// The colour map of the scale.
    pub fn colour_map(self) -> ColourMap {
        match self {
            Scale::Diverging => ColourMap::Diverging,
            Scale::Sequential => ColourMap::Viridis,
        }
    }
}

/// One picture of a map over a regular grid in the map plane.
#[derive(Debug, Clone)]
pub struct Heatmap<'a> {
    /// Title line, e.g. `web-plate p01 — PV 41.2 µm, RMS 12.0 µm` (see [`pv_rms_um`]).
    pub title: String,
    /// Name of the first plane axis (horizontal in the picture), e.g. "x".
    pub u_name: &'a str,
    /// Name of the second plane axis (vertical in the picture), e.g. "y".
    pub v_name: &'a str,
    /// What the colour shows, quantity and unit, e.g. "E (µm)"; written above the colour bar.
    pub value_label: &'a str,
    /// u of the first grid node, mm; node (i, j) sits at (u0 + i·step, v0 + j·step).
    pub u0_mm: f64,
    /// v of the first grid node, mm.
    pub v0_mm: f64,
    /// Node spacing along both plane axes, mm (a value ≤ 0 is drawn as 1 mm).
    pub step_mm: f64,
    /// Nodes along u.
    pub nu: usize,
    /// Nodes along v.
    pub nv: usize,
    /// Values at the nodes, index j·nu + i; `None` is drawn grey (no value there).
    pub values: &'a [Option<f64>],
    /// Probe points kept (u, v) mm.
    pub probes: &'a [(f64, f64)],
    /// Rejected probe points (u, v) mm.
    pub rejected: &'a [(f64, f64)],
    /// The measured hull (u, v) mm, in order around it; empty = not drawn.
    pub hull: &'a [[f64; 2]],
    /// How values map to colours: diverging for signed E, sequential for magnitudes.
    pub scale: Scale,
    /// Nodes outside the measured domain (index j·nu + i), drawn lightened; empty = none.
    pub extrapolated: &'a [bool],
}

pub use errmap_core::numeric::pv_rms_um;

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
    scale.colour_map().of(v, lo, hi)
}

/// Height of the header: the title and three legend lines.
const HEADER: u32 = 104;
const MARGIN: u32 = 12;
const Y_LABELS: u32 = 70;
const X_LABELS: u32 = 50;
const BAR: u32 = 130;

/// The picture's geometry: cell size, data extent (mm) and plotting-area size (px).
struct Layout {
    step: f64,
    u: (f64, f64),
    v: (f64, f64),
    plot_w: u32,
    plot_h: u32,
}

impl Layout {
    fn of(map: &Heatmap<'_>) -> Layout {
        let step = if map.step_mm > 0.0 { map.step_mm } else { 1.0 };
        let half = step / 2.0;
        let u = (
            map.u0_mm - half,
            map.u0_mm + step * map.nu.saturating_sub(1) as f64 + half,
        );
        let v = (
            map.v0_mm - half,
            map.v0_mm + step * map.nv.saturating_sub(1) as f64 + half,
        );
        // Equal scales: the plotting area's pixel aspect equals the domain's.
        let aspect = ((v.1 - v.0) / (u.1 - u.0)).clamp(0.05, 20.0);
        let (mut plot_w, mut plot_h) = (800.0, 800.0 * aspect);
        if plot_h > 700.0 {
            plot_h = 700.0;
            plot_w = plot_h / aspect;
        }
        Layout {
            step,
            u,
            v,
            plot_w: plot_w.round().max(120.0) as u32,
            plot_h: plot_h.round().max(120.0) as u32,
        }
    }
}

/// Where [`save_heatmap`] puts the plot of `map` in its PNG (from the grid alone, without drawing).
pub fn frame(map: &Heatmap<'_>) -> Frame {
    let l = Layout::of(map);
    let left = (MARGIN + Y_LABELS) as i32;
    let top = (HEADER + MARGIN) as i32;
    // Plotters maps the range's ends onto the first and the last pixel of the area.
    Frame::new(l.u, l.v, |u, v| {
        let x = if u == l.u.0 {
            left
        } else {
            left + l.plot_w as i32 - 1
        };
        let y = if v == l.v.0 {
            top + l.plot_h as i32 - 1
        } else {
            top
        };
        (x, y)
    })
}

/// Draw the heatmap and write it to `path` as PNG (atomically); returns where the plot lies.
pub fn save_heatmap(path: &Path, map: &Heatmap<'_>) -> Result<Frame> {
    save_heatmap_counted(path, map, (map.probes.len(), map.rejected.len()))
}

/// [`save_heatmap`] with the legend's counts of kept and rejected points given apart: a family
/// map draws each distinct position once but counts every part's points.
pub fn save_heatmap_counted(
    path: &Path,
    map: &Heatmap<'_>,
    counts: (usize, usize),
) -> Result<Frame> {
    let layout = Layout::of(map);
    let main_w = layout.plot_w + Y_LABELS + 2 * MARGIN;
    let width = main_w + BAR;
    let height = HEADER + layout.plot_h + X_LABELS + 2 * MARGIN;
    let (lo, hi) = limits(map.values, map.scale);
    let mut frame = None;
    chart::save_png(path, width, height, |root| {
        let (header, body) = root.split_vertically(HEADER);
        header.draw(&Text::new(
            map.title.clone(),
            (MARGIN as i32, 6),
            (FONT, 22).into_font().color(&BLACK),
        ))?;
        draw_legend(&header, map, counts, lo, hi)?;

        let (main, _bar) = body.split_horizontally(main_w);
        let mut chart = draw_axes(&main, map, &layout)?;
        draw_cells(&mut chart, map, layout.step, lo, hi)?;
        draw_hull(&mut chart, map.hull)?;
        for &(u, v) in map.probes {
            draw_probe_mark(root, chart.backend_coord(&(u, v)))?;
        }
        for &(u, v) in map.rejected {
            draw_rejected_mark(root, chart.backend_coord(&(u, v)))?;
        }
        frame = Some(Frame::new(layout.u, layout.v, |u, v| {
            chart.backend_coord(&(u, v))
        }));

        // Colour bar beside the plot, same height, ticks in the map's unit, its label above.
        let (_, y_px) = chart.plotting_area().get_pixel_range();
        draw_colour_bar(
            root,
            &ColourBar {
                map: map.scale.colour_map(),
                lo,
                hi,
                label: map.value_label,
                x_px: main_w as i32 + 6,
                top_px: y_px.start,
                bottom_px: y_px.end,
            },
        )?;
        Ok(())
    })?;
    frame.ok_or_else(|| errmap_core::Error::Internal(format!("{}: no plot drawn", path.display())))
}

/// The plot of a heatmap: plane coordinates in mm on a bitmap.
type MapChart<'a, 'b> =
    ChartContext<'a, BitMapBackend<'b>, Cartesian2d<RangedCoordf64, RangedCoordf64>>;

/// What a drawing step returns.
type Drawn<T> = std::result::Result<T, Box<dyn std::error::Error + Send + Sync>>;

/// The plot area with its axes (mm along the two plane axes), no mesh.
fn draw_axes<'a, 'b>(
    main: &'a DrawingArea<BitMapBackend<'b>, plotters::coord::Shift>,
    map: &Heatmap<'_>,
    layout: &Layout,
) -> Drawn<MapChart<'a, 'b>> {
    let mut chart = ChartBuilder::on(main)
        .margin(MARGIN)
        .x_label_area_size(X_LABELS)
        .y_label_area_size(Y_LABELS)
        .build_cartesian_2d(layout.u.0..layout.u.1, layout.v.0..layout.v.1)?;
    chart
        .configure_mesh()
        .disable_mesh()
        .x_desc(format!("{} (mm)", map.u_name))
        .y_desc(format!("{} (mm)", map.v_name))
        .label_style((FONT, 14))
        .axis_desc_style((FONT, 16))
        .draw()?;
    Ok(chart)
}

/// One cell per node, centred on it and `step` wide: its value's colour between `lo` and
/// `hi`, grey where there is none, lightened where it is extrapolated.
fn draw_cells(
    chart: &mut MapChart<'_, '_>,
    map: &Heatmap<'_>,
    step: f64,
    lo: f64,
    hi: f64,
) -> Drawn<()> {
    let half = step / 2.0;
    let (nu, nv) = (map.nu, map.nv);
    let grey = RGBColor(200, 200, 200);
    chart.draw_series(
        (0..nv)
            .flat_map(|j| (0..nu).map(move |i| (i, j)))
            .map(|(i, j)| {
                let u = map.u0_mm + step * i as f64;
                let v = map.v0_mm + step * j as f64;
                let mut colour = match map.values.get(j * nu + i).copied().flatten() {
                    Some(e) => colour_of(e, lo, hi, map.scale),
                    None => grey,
                };
                if map.extrapolated.get(j * nu + i) == Some(&true) {
                    colour = lighten(colour);
                }
                Rectangle::new(
                    [(u - half, v - half), (u + half, v + half)],
                    colour.filled(),
                )
            }),
    )?;
    Ok(())
}

/// The measured hull as a black outline on a white rim (nothing for fewer than 2 corners).
fn draw_hull(chart: &mut MapChart<'_, '_>, hull: &[[f64; 2]]) -> Drawn<()> {
    if hull.len() >= 2 {
        let mut ring: Vec<(f64, f64)> = hull.iter().map(|p| (p[0], p[1])).collect();
        ring.push(ring[0]);
        chart.draw_series(std::iter::once(PathElement::new(
            ring.clone(),
            WHITE.stroke_width(4),
        )))?;
        chart.draw_series(std::iter::once(PathElement::new(
            ring,
            BLACK.stroke_width(2),
        )))?;
    }
    Ok(())
}

/// Halfway to white: nodes outside the measured hull (extrapolated), so the measured domain stands out.
fn lighten(c: RGBColor) -> RGBColor {
    let w = |c: u8| ((u16::from(c) + 255) / 2) as u8;
    RGBColor(w(c.0), w(c.1), w(c.2))
}

/// The legend lines under the title: marks and lines (only those the picture has), then colours.
fn draw_legend<DB: DrawingBackend>(
    header: &DrawingArea<DB, plotters::coord::Shift>,
    map: &Heatmap<'_>,
    (kept, rejected): (usize, usize),
    lo: f64,
    hi: f64,
) -> std::result::Result<(), Box<dyn std::error::Error + Send + Sync>>
where
    DB::ErrorType: 'static,
{
    let small = (FONT, 15).into_font().color(&BLACK);
    let x0 = 12 + 6;
    let (y1, y2, y3) = (44, 66, 88);
    let mut x = x0;
    if !map.probes.is_empty() {
        draw_probe_mark(header, (x, y1))?;
        let text = format!("probe point kept ({kept})");
        header.draw(&Text::new(text.clone(), (x + 10, y1 - 9), small.clone()))?;
        x += 24 + 8 * text.chars().count() as i32;
    }
    if !map.rejected.is_empty() || !map.probes.is_empty() {
        draw_rejected_mark(header, (x, y1))?;
        let text = format!("rejected gross error ({rejected})");
        header.draw(&Text::new(text, (x + 16, y1 - 9), small.clone()))?;
    }
    let mut x = x0;
    if map.hull.len() >= 2 {
        header.draw(&PathElement::new(
            vec![(x - 6, y2), (x + 14, y2)],
            BLACK.stroke_width(2),
        ))?;
        let text = "measured hull (convex hull of the probe points)";
        header.draw(&Text::new(text, (x + 20, y2 - 9), small.clone()))?;
        x += 40 + 8 * text.chars().count() as i32;
    }
    if map.extrapolated.iter().any(|&e| e) {
        let sample = lighten(colour_of(hi, lo, hi, map.scale));
        header.draw(&Rectangle::new(
            [(x - 6, y2 - 7), (x + 14, y2 + 7)],
            sample.filled(),
        ))?;
        header.draw(&Text::new(
            "lighter: outside the hull (extrapolated)",
            (x + 20, y2 - 9),
            small.clone(),
        ))?;
    }
    let colours = match map.scale {
        Scale::Diverging => format!(
            "colour: {} — red above nominal (E > 0), white 0, blue below; limits ±{hi}",
            map.value_label
        ),
        Scale::Sequential => format!(
            "colour: {} — viridis, dark {lo} to light {hi}",
            map.value_label
        ),
    };
    header.draw(&Text::new(colours, (x0 - 6, y3 - 9), small))?;
    Ok(())
}

/// The probe mark: a black dot in a white rim, visible on any colour.
fn draw_probe_mark<DB: DrawingBackend>(
    area: &DrawingArea<DB, plotters::coord::Shift>,
    (x, y): (i32, i32),
) -> std::result::Result<(), Box<dyn std::error::Error + Send + Sync>>
where
    DB::ErrorType: 'static,
{
    area.draw(&Circle::new((x, y), 5, WHITE.filled()))?;
    area.draw(&Circle::new((x, y), 3, BLACK.filled()))?;
    Ok(())
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
            hull: &[],
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
        assert_eq!(img.height(), HEADER + 533 + 50 + 24);
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

    /// A 4 × 3 map over 30 × 20 mm with two probes, one reject and a triangular hull.
    fn small_map<'a>(
        values: &'a [Option<f64>],
        scale: Scale,
        probes: &'a [(f64, f64)],
        hull: &'a [[f64; 2]],
    ) -> Heatmap<'a> {
        Heatmap {
            title: "test".into(),
            u_name: "x",
            v_name: "y",
            value_label: "σ of E (µm)",
            u0_mm: 0.0,
            v0_mm: 0.0,
            step_mm: 10.0,
            nu: 4,
            nv: 3,
            values,
            probes,
            rejected: &[(25.0, 15.0)],
            hull,
            scale,
            extrapolated: &[],
        }
    }

    fn rgb(img: &image::RgbImage, (x, y): (f64, f64)) -> [u8; 3] {
        img.get_pixel(x.round() as u32, y.round() as u32).0
    }

    #[test]
    fn probes_and_the_hull_are_drawn_where_they_are() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("std.png");
        // A uniform mid-scale σ: every cell the same viridis colour, so any black is a mark.
        let values = vec![Some(1.0); 12];
        let probes = [(7.0, 4.0), (18.0, 12.0)];
        let hull = [[0.0, 0.0], [30.0, 0.0], [0.0, 20.0]];
        let map = small_map(&values, Scale::Sequential, &probes, &hull);
        let drawn = save_heatmap(&path, &map).unwrap();
        let planned = frame(&map);
        for (u, v) in [(0.0, 0.0), (30.0, 20.0), (12.5, 7.5)] {
            let (a, b) = (drawn.to_px(u, v), planned.to_px(u, v));
            assert!(
                (a.0 - b.0).abs() <= 1.0 && (a.1 - b.1).abs() <= 1.0,
                "{a:?} {b:?}"
            );
        }
        let img = image::open(&path).unwrap().to_rgb8();
        let cell = rgb(&img, drawn.to_px(33.0, 23.0));
        assert!(cell.iter().any(|&c| c > 60), "cell colour {cell:?}");
        for &(u, v) in &probes {
            let (x, y) = drawn.to_px(u, v);
            assert!(
                rgb(&img, (x, y)).iter().all(|&c| c < 60),
                "probe at ({u}, {v})"
            );
            // The white rim around the dot.
            assert!(rgb(&img, (x + 4.0, y)).iter().all(|&c| c > 200));
        }
        // The hull's edge from (30, 0) to (0, 20) passes through (15, 10): black there, the
        // cell colour 12 px off it on both sides (its normal is (2, −3) in pixels).
        let (x, y) = drawn.to_px(15.0, 10.0);
        assert!(rgb(&img, (x, y)).iter().all(|&c| c < 60));
        let (dx, dy) = (12.0 * 2.0 / 13f64.sqrt(), 12.0 * 3.0 / 13f64.sqrt());
        assert_eq!(rgb(&img, (x + dx, y - dy)), cell);
        assert_eq!(rgb(&img, (x - dx, y + dy)), cell);
    }

    #[test]
    fn the_diverging_map_is_neutral_at_zero_and_symmetric() {
        let white = ColourMap::Diverging.at(0.5);
        assert!(white.0 == white.1 && white.1 == white.2 && white.0 > 240);
        // ±t from the middle: blue one side, red the other, of (nearly) equal lightness.
        for t in [0.1, 0.25, 0.4, 0.5] {
            let hot = ColourMap::Diverging.at(0.5 + t);
            let cold = ColourMap::Diverging.at(0.5 - t);
            assert!(hot.0 > hot.2 && cold.2 > cold.0, "{t}: {hot:?} {cold:?}");
            let (lh, lc) = (
                crate::colormap::luminance(hot),
                crate::colormap::luminance(cold),
            );
            assert!((lh - lc).abs() < 0.06, "{t}: Y {lh} vs {lc}");
        }
        // Limits are ±L about zero, whatever the sign of the larger error.
        assert_eq!(
            limits(&[Some(-7.0), Some(2.0)], Scale::Diverging),
            (-10.0, 10.0)
        );
        // In the picture, the colour bar's middle row is the neutral colour.
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("e.png");
        let values: Vec<Option<f64>> = (0..12).map(|k| Some(k as f64 - 3.0)).collect();
        let mut map = small_map(&values, Scale::Diverging, &[], &[]);
        map.value_label = "E (µm)";
        let f = save_heatmap(&path, &map).unwrap();
        let img = image::open(&path).unwrap().to_rgb8();
        let (_, top) = f.to_px(0.0, f.y_range.1);
        let (_, bottom) = f.to_px(0.0, f.y_range.0);
        let x_bar = (img.width() - BAR + 6 + 12) as f64;
        let mid = rgb(&img, (x_bar, (top + bottom) / 2.0));
        assert!(
            mid[0] == mid[1] && mid[1] == mid[2] && mid[0] > 240,
            "{mid:?}"
        );
        let (hi, lo) = (
            rgb(&img, (x_bar, top + 3.0)),
            rgb(&img, (x_bar, bottom - 3.0)),
        );
        assert!(hi[0] > hi[2] && lo[2] > lo[0], "{hi:?} {lo:?}");
    }

    #[test]
    fn the_magnitude_map_grows_lighter_monotonically() {
        let y: Vec<f64> = (0..=64)
            .map(|k| crate::colormap::luminance(ColourMap::Viridis.at(k as f64 / 64.0)))
            .collect();
        assert!(y.windows(2).all(|w| w[1] > w[0]), "{y:?}");
        // Published end points of viridis.
        assert_eq!(ColourMap::Viridis.at(0.0), RGBColor(68, 1, 84));
        assert_eq!(ColourMap::Viridis.at(1.0), RGBColor(253, 231, 37));
        // And in the picture: the colour bar darkens from top to bottom.
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("s.png");
        let values: Vec<Option<f64>> = (0..12).map(|k| Some(k as f64)).collect();
        let f = save_heatmap(&path, &small_map(&values, Scale::Sequential, &[], &[])).unwrap();
        let img = image::open(&path).unwrap().to_rgb8();
        let (_, top) = f.to_px(0.0, f.y_range.1);
        let (_, bottom) = f.to_px(0.0, f.y_range.0);
        let x_bar = (img.width() - BAR + 6 + 12) as f64;
        let bar: Vec<f64> = (0..=20)
            .map(|k| {
                let [r, g, b] = rgb(
                    &img,
                    (x_bar, top + 2.0 + (bottom - top - 4.0) * k as f64 / 20.0),
                );
                crate::colormap::luminance(RGBColor(r, g, b))
            })
            .collect();
        assert!(bar.windows(2).all(|w| w[1] < w[0]), "{bar:?}");
    }
}
