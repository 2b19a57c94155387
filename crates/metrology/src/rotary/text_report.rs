//! The text report of `rotary analyze`: the reference, the sphere fits, the axis, the mean error per angle and direction, and the ISO 230-2 figures.

use super::analysis::{Analysis, Sign};
use super::table::fixed;
use crate::Setting;
use errmap_core::setting::words;
use std::fmt::Write as _;

/// The whole report, section by section, each ending in a newline.
pub fn text_report(a: &Analysis) -> String {
    let mut s = String::new();
    reference_line(&mut s, a);
    sphere_line(&mut s, a);
    axis_line(&mut s, a);
    error_table(&mut s, a);
    iso_line(&mut s, a);
    s
}

/// `v` with `digits` decimals, or `-` when there is none.
fn opt(v: Option<f64>, digits: usize) -> String {
    v.map_or_else(|| "-".to_string(), |v| fixed(v, digits))
}

/// The axis, the number of observations and the reference vector.
fn reference_line(s: &mut String, a: &Analysis) {
    let r = &a.reference;
    let _ = writeln!(
        s,
        "{} axis: {} observations, reference {}° ({}, {} repeat(s)), lever {:.3} mm",
        a.axis,
        a.observations.len(),
        r.angle_deg,
        r.direction,
        r.n,
        r.lever_mm
    );
}

/// The summary of the sphere fits (touch-point files only).
fn sphere_line(s: &mut String, a: &Analysis) {
    if let Some(sp) = &a.spheres {
        let _ = writeln!(
            s,
            "sphere fits: {}, form ≤ {:.2} µm rms ({:.2} µm p-v), mean radius {:.4} mm{}",
            sp.fits,
            sp.max_form_rms_mm * 1e3,
            sp.max_form_pv_mm * 1e3,
            sp.mean_radius_mm,
            sp.max_abs_radius_deviation_mm
                .map(|d| format!(", |radius − nominal| ≤ {:.2} µm", d * 1e3))
                .unwrap_or_default()
        );
    }
}

/// The axis direction used: nominal, or fitted with its tilt and location.
fn axis_line(s: &mut String, a: &Analysis) {
    let ax = &a.axis_fit;
    let d = ax.direction;
    match (ax.tilt_arcsec, &ax.tilt_toward_arcsec, ax.location_mm) {
        (Some(tilt), Some(toward), Some(loc)) => {
            let parts: Vec<String> = toward
                .iter()
                .map(|(k, v)| format!("toward {k} {v:+.2}″"))
                .collect();
            let _ = writeln!(
                s,
                "axis (fitted): direction ({:.8}, {:.8}, {:.8}), tilt {:.2}″ ({}), location ({:.4}, {:.4}, {:.4}) mm",
                d[0],
                d[1],
                d[2],
                tilt,
                parts.join(", "),
                loc[0],
                loc[1],
                loc[2]
            );
        }
        _ => {
            let _ = writeln!(
                s,
                "axis (nominal): direction ({}, {}, {})",
                d[0], d[1], d[2]
            );
        }
    }
}

/// The sign convention and the mean error per angle and direction.
fn error_table(s: &mut String, a: &Analysis) {
    match a.sign {
        Sign::Errmap => {
            let _ = writeln!(s, "\nerr = α − β (arcsec), mean over repeats");
        }
        Sign::Calibrator => {
            let _ = writeln!(
                s,
                "\nerror = β − α = measured − commanded (arcsec, {} calibrator: ISO 230-2's x), mean over repeats\n{}",
                words(Setting::Sign),
                a.sign.positive(a.axis)
            );
        }
    }
    let _ = writeln!(
        s,
        "{:>10}  dir  {:>12}  {:>8}  {:>3}",
        "angle_deg", "error_arcsec", "s_arcsec", "n"
    );
    for row in &a.table {
        let _ = writeln!(
            s,
            "{:>10}  {:>3}  {:>12}  {:>8}  {:>3}",
            row.angle_deg,
            row.direction.symbol(),
            fixed(row.error_arcsec, 2),
            opt(row.s_arcsec, 2),
            row.n
        );
    }
}

/// The ISO 230-2 figures, or why there are none.
fn iso_line(s: &mut String, a: &Analysis) {
    match &a.iso230_2 {
        Some(e) => {
            let f = &e.axis;
            let _ = writeln!(
                s,
                "\nISO 230-2:2014 (arcsec, x = actual − target = {}): A {}  A↑ {}  A↓ {}  R {}  R↑ {}  R↓ {}  E {}  M {}  B {}  B̄ {}",
                match a.sign {
                    Sign::Errmap => "−err",
                    Sign::Calibrator => "the error above",
                },
                opt(f.A, 2),
                opt(f.A_up, 2),
                opt(f.A_down, 2),
                opt(f.R, 2),
                opt(f.R_up, 2),
                opt(f.R_down, 2),
                opt(f.E, 2),
                opt(f.M, 2),
                opt(f.B, 2),
                f.B_mean
                    .map_or_else(|| "-".to_string(), |v| format!("{v:+.2}"))
            );
        }
        None => {
            if let Some(note) = &a.iso230_2_note {
                let _ = writeln!(s, "\nISO 230-2: not evaluated ({note})");
            }
        }
    }
}
