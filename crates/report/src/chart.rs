//! Chart plumbing every picture uses: an embedded font (no system font needed) and atomic PNG output from a plotters drawing.

use errmap_core::error::{Error, Result};
use plotters::prelude::*;
use std::path::Path;
use std::sync::Once;

/// The font family name charts use; registered from the embedded DejaVu Sans.
pub const FONT: &str = "sans-serif";

static FONTS: Once = Once::new();

/// Register the embedded DejaVu Sans fonts with plotters (once per process).
pub fn ensure_fonts() {
    FONTS.call_once(|| {
        // The bytes are valid TrueType shipped by the `dejavu` crate; a failure here is a build defect.
        let _ = plotters::style::register_font(FONT, FontStyle::Normal, dejavu::sans::regular());
        let _ = plotters::style::register_font(FONT, FontStyle::Bold, dejavu::sans::bold());
        let _ = plotters::style::register_font(FONT, FontStyle::Italic, dejavu::sans::oblique());
        let _ = plotters::style::register_font(FONT, FontStyle::Oblique, dejavu::sans::oblique());
    });
}

/// Draw a `width_px` × `height_px` picture with `draw` and write it to `path` as PNG, atomically.
///
/// `draw` gets a white root drawing area; its errors become [`Error::Internal`] naming the file.
pub fn save_png(
    path: &Path,
    width_px: u32,
    height_px: u32,
    draw: impl FnOnce(
        &DrawingArea<BitMapBackend<'_>, plotters::coord::Shift>,
    ) -> std::result::Result<(), Box<dyn std::error::Error + Send + Sync>>,
) -> Result<()> {
    ensure_fonts();
    let mut rgb = vec![255u8; width_px as usize * height_px as usize * 3];
    {
        let root = BitMapBackend::with_buffer(&mut rgb, (width_px, height_px)).into_drawing_area();
        root.fill(&WHITE).map_err(|e| chart_error(path, &e))?;
        draw(&root).map_err(|e| chart_error(path, e.as_ref()))?;
        root.present().map_err(|e| chart_error(path, &e))?;
    }
    let png = encode_png(&rgb, width_px, height_px)
        .map_err(|e| Error::Internal(format!("PNG encoding of {}: {e}", path.display())))?;
    errmap_core::io::write_atomic_bytes(path, &png)
}

/// Encode an RGB8 buffer as PNG bytes.
pub fn encode_png(
    rgb: &[u8],
    width_px: u32,
    height_px: u32,
) -> std::result::Result<Vec<u8>, image::ImageError> {
    let mut out = std::io::Cursor::new(Vec::new());
    image::write_buffer_with_format(
        &mut out,
        rgb,
        width_px,
        height_px,
        image::ExtendedColorType::Rgb8,
        image::ImageFormat::Png,
    )?;
    Ok(out.into_inner())
}

/// Where a chart's plotting area lies in its PNG: data coordinates to pixels, so that a test or
/// a report can find what was drawn at a value.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Frame {
    /// Data range of the x axis (first, last), in the chart's x unit.
    pub x_range: (f64, f64),
    /// Data range of the y axis (first, last), in the chart's y unit.
    pub y_range: (f64, f64),
    /// Pixels of the corners (x_range.0, y_range.0) and (x_range.1, y_range.1).
    lo_px: (i32, i32),
    hi_px: (i32, i32),
}

impl Frame {
    /// The frame of a chart whose mapping is `to_px` (e.g. `|x, y| chart.backend_coord(&(x, y))`).
    pub fn new(
        x_range: (f64, f64),
        y_range: (f64, f64),
        to_px: impl Fn(f64, f64) -> (i32, i32),
    ) -> Frame {
        Frame {
            x_range,
            y_range,
            lo_px: to_px(x_range.0, y_range.0),
            hi_px: to_px(x_range.1, y_range.1),
        }
    }

    /// The pixel (column, row) plotters draws the data point (x, y) at: it rounds toward the
    /// range's start (floor on x, ceil on the upward y axis).
    pub fn pixel(&self, x: f64, y: f64) -> (i32, i32) {
        let snap = |v: f64, (p, q): (i32, i32)| {
            if q >= p {
                (v + 1e-3).floor() as i32
            } else {
                (v - 1e-3).ceil() as i32
            }
        };
        let (px, py) = self.to_px(x, y);
        (
            snap(px, (self.lo_px.0, self.hi_px.0)),
            snap(py, (self.lo_px.1, self.hi_px.1)),
        )
    }

    /// Pixel (column, row) of the data point (x, y), unrounded.
    pub fn to_px(&self, x: f64, y: f64) -> (f64, f64) {
        let f = |v: f64, (a, b): (f64, f64), (p, q): (i32, i32)| {
            f64::from(p) + (v - a) / (b - a) * f64::from(q - p)
        };
        (
            f(x, self.x_range, (self.lo_px.0, self.hi_px.0)),
            f(y, self.y_range, (self.lo_px.1, self.hi_px.1)),
        )
    }
}

fn chart_error(path: &Path, e: &dyn std::fmt::Display) -> Error {
    Error::Internal(format!("drawing {}: {e}", path.display()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn draws_text_with_the_embedded_font_into_a_png() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("t.png");
        save_png(&path, 200, 80, |root| {
            root.draw(&Text::new(
                "errmap 12 µm",
                (10, 30),
                (FONT, 24).into_font().color(&BLACK),
            ))?;
            Ok(())
        })
        .unwrap();
        let img = image::open(&path).unwrap().to_rgb8();
        assert_eq!(img.dimensions(), (200, 80));
        let dark = img.pixels().filter(|p| p.0[0] < 100).count();
        assert!(
            dark > 50,
            "text should have drawn dark pixels, found {dark}"
        );
    }
}
