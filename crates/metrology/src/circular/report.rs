//! What `errmap circular` does as one library call: check the request, read the run, evaluate and diagnose it, draw the polar chart with its result file; and the text report of an evaluation.

use super::chart::save_polar_chart;
use super::input::{read_run, Plane, ReadOptions};
use super::{analyze, Evaluation};
use crate::Setting;
use errmap_core::error::{Error, Result};
use errmap_core::setting::words;
use std::fmt::Write as _;
use std::path::Path;

/// A circular test to evaluate.
#[derive(Debug, Clone, Copy)]
pub struct TestRequest<'a> {
    /// The run file (radial or two-axis CSV).
    pub run: &'a Path,
    /// Programmed radius of the circle.
    pub radius_mm: f64,
    /// The plane of the circle; it only names the axes in the output.
    pub plane: Plane,
    /// Programmed feed; needed for the servo mismatch in ms.
    pub feed_mm_per_min: Option<f64>,
    /// Nominal centre in a two-axis file's coordinates.
    pub centre_mm: [f64; 2],
    /// Write the polar chart here, and the result beside it.
    pub chart: Option<&'a Path>,
}

/// Check the request, evaluate the run, and write the chart and its result if asked.
pub fn run_test(req: &TestRequest<'_>) -> Result<Evaluation, crate::error::CircularError> {
    check_request(req)?;
    let opts = ReadOptions {
        radius_mm: req.radius_mm,
        centre_mm: req.centre_mm,
    };
    let run = read_run(req.run, &opts)?;
    let (eval, centred, _) = analyze(&run, req.plane, req.feed_mm_per_min)?;
    if let Some(png) = req.chart {
        save_polar_chart(png, &eval, &centred)?;
        // The result beside the chart, for `errmap report`.
        errmap_report::result::write_result(
            &errmap_report::result::beside(png),
            &errmap_report::result::ResultSpec {
                kind: "circular",
                title: format!("Circular test {}", req.run.display()),
                inputs: &[req.run],
                charts: &[png],
                table: None,
            },
            &eval,
        )?;
    }
    Ok(eval)
}

/// A feed must be a positive speed; the chart must not replace the run file.
fn check_request(req: &TestRequest<'_>) -> Result<()> {
    if let Some(feed) = req.feed_mm_per_min {
        if !(feed.is_finite() && feed > 0.0) {
            return Err(Error::usage(
                format!("feed {feed} mm/min is not a positive speed"),
                format!(
                    "give the programmed feed, e.g. {} 1000",
                    words(Setting::Feed)
                ),
            ));
        }
    }
    if let Some(png) = req.chart {
        let same = png == req.run
            || matches!((png.canonicalize(), req.run.canonicalize()), (Ok(a), Ok(b)) if a == b);
        if same {
            return Err(Error::usage(
                format!("the chart {} would overwrite the run file", png.display()),
                "give the chart another name with -o, e.g. -o circle.png",
            ));
        }
    }
    Ok(())
}

/// A centre given as `FIRST,SECOND` (mm), e.g. `250,-120`.
pub fn parse_centre_mm(s: &str) -> std::result::Result<[f64; 2], String> {
    let v: Vec<f64> = s
        .split(',')
        .map(|p| p.trim().parse::<f64>())
        .collect::<std::result::Result<_, _>>()
        .map_err(|_| format!("'{s}' is not two numbers such as 250,-120"))?;
    match v.as_slice() {
        [a, b] if a.is_finite() && b.is_finite() => Ok([*a, *b]),
        _ => Err(format!("'{s}' is not two numbers such as 250,-120")),
    }
}

fn num(v: Option<f64>, digits: usize) -> String {
    errmap_core::numeric::format::opt(v, digits, "-")
}

/// The text report of `errmap circular`: the ISO 230-4 figures, then the diagnosis.
pub fn human_report(e: &Evaluation) -> String {
    let mut s = figures_text(e);
    s.push_str(&diagnosis_text(e));
    s
}

/// The run, G, F, H and the set-up offset.
fn figures_text(e: &Evaluation) -> String {
    let f = &e.figures;
    let [first, second] = e.axes;
    let mut s = String::new();
    let overrun = match f.readings.overrun {
        0 => String::new(),
        n => format!(", {n} of them readings past one turn"),
    };
    let _ = writeln!(
        s,
        "circular test, R {} mm, plane {first}{second}: {} ccw, {} cw readings ({} overshoot rows ignored{overrun})",
        f.radius_mm, f.readings.ccw, f.readings.cw, f.readings.overshoot
    );
    let _ = writeln!(s, "\nISO 230-4 (µm)        ccw       cw    both");
    for (name, v) in [
        ("G circular deviation", &f.g_um),
        ("F max", &f.f_max_um),
        ("F min", &f.f_min_um),
    ] {
        let _ = writeln!(
            s,
            "{name:<20} {:>7} {:>8} {:>7}",
            num(v.ccw, 2),
            num(v.cw, 2),
            num(v.bidirectional, 2)
        );
    }
    let _ = writeln!(s, "H circular hysteresis {:>22}", num(f.h_um, 2));
    let _ = writeln!(
        s,
        "centre offset (set-up, removed): {first} {:+.2} µm, {second} {:+.2} µm; mean radius {:+.2} µm",
        f.centre_offset_um[0], f.centre_offset_um[1], f.mean_radius_deviation_um
    );
    s
}

/// The diagnosis terms, the residual and the largest contributors.
fn diagnosis_text(e: &Evaluation) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        "\ndiagnosis (least squares)        value    stderr   share of G"
    );
    for (key, t) in e.terms.list() {
        let mut extra = String::new();
        if let Some(p) = t.period_mm {
            let _ = write!(extra, "  period {p:.3} mm");
        }
        if let Some(d) = t.decay_mm {
            let _ = write!(extra, "  decay {d:.3} mm");
        }
        if let Some(n) = &t.note {
            let _ = write!(extra, "  ({n})");
        }
        let _ = writeln!(
            s,
            "{key:<28} {:>9} {:>9} {:>8}{extra}",
            num(t.value, 3),
            num(t.stderr, 3),
            t.share_of_g
                .map_or_else(|| "-".to_string(), |v| format!("{:.0} %", 100.0 * v)),
        );
    }
    let _ = writeln!(s, "residual RMS {:.3} µm", e.residual_rms_um);
    if !e.model.largest.is_empty() {
        let _ = writeln!(s, "largest contributors: {}", e.model.largest.join(", "));
    }
    s
}
