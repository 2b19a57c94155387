//! The web-plate generator's settings as `errmap synth web-plate` takes them in words: plate
//! size `XxY`, origin `X,Y`, probe grid `NXxNY`, and the layout and noise checks.

use super::web_plate::Layout;
use crate::Setting;
use errmap_core::error::{Error, Result};
use errmap_core::setting::words;

fn parse_two(text: &str, sep: char) -> std::result::Result<(f64, f64), String> {
    let (a, b) = text
        .split_once(sep)
        .ok_or_else(|| format!("expected two numbers separated by '{sep}'"))?;
    let a: f64 = a
        .trim()
        .parse()
        .map_err(|_| format!("'{a}' is not a number"))?;
    let b: f64 = b
        .trim()
        .parse()
        .map_err(|_| format!("'{b}' is not a number"))?;
    if !a.is_finite() || !b.is_finite() {
        return Err("numbers must be finite".into());
    }
    Ok((a, b))
}

/// A plate size `XxY` in mm.
pub fn parse_size(text: &str) -> std::result::Result<(f64, f64), String> {
    parse_two(text, 'x')
}

/// A corner `X,Y` in mm.
pub fn parse_origin(text: &str) -> std::result::Result<(f64, f64), String> {
    parse_two(text, ',')
}

/// A probe grid `NXxNY` (points along X and Y).
pub fn parse_grid(text: &str) -> std::result::Result<(usize, usize), String> {
    let (a, b) = text.split_once('x').ok_or("expected NXxNY, e.g. 12x12")?;
    let a = a
        .trim()
        .parse()
        .map_err(|_| format!("'{a}' is not a count"))?;
    let b = b
        .trim()
        .parse()
        .map_err(|_| format!("'{b}' is not a count"))?;
    Ok((a, b))
}

/// The layout from `--grid` / `--irregular` (scattered points win; default a 12 × 12 grid).
pub fn layout(grid: Option<(usize, usize)>, irregular: Option<usize>) -> Layout {
    match (grid, irregular) {
        (_, Some(n)) => Layout::Irregular { n },
        (Some((nx, ny)), None) => Layout::Grid { nx, ny },
        (None, None) => Layout::Grid { nx: 12, ny: 12 },
    }
}

/// The probe noise (1σ, µm) must be a finite number ≥ 0.
pub fn check_noise_um(noise_um: f64) -> Result<(), crate::SynthError> {
    if noise_um.is_finite() && noise_um >= 0.0 {
        return Ok(());
    }
    Err(Error::usage(
        format!("{} must be ≥ 0", words(Setting::NoiseUm)),
        format!("e.g. {} 1", words(Setting::NoiseUm)),
    )
    .into())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sizes_origins_and_grids_parse_or_say_why_not() {
        assert_eq!(parse_size("600x300"), Ok((600.0, 300.0)));
        assert_eq!(parse_origin("-10, 5"), Ok((-10.0, 5.0)));
        assert_eq!(
            parse_size("600,300"),
            Err("expected two numbers separated by 'x'".to_string())
        );
        assert_eq!(parse_origin("a,1"), Err("'a' is not a number".to_string()));
        assert_eq!(
            parse_size("infx1"),
            Err("numbers must be finite".to_string())
        );
        assert_eq!(parse_grid("12x8"), Ok((12, 8)));
        assert_eq!(parse_grid("12x-1"), Err("'-1' is not a count".to_string()));
        assert_eq!(
            parse_grid("12"),
            Err("expected NXxNY, e.g. 12x12".to_string())
        );
    }

    #[test]
    fn scattered_points_win_over_a_grid_and_noise_is_not_negative() {
        assert_eq!(layout(Some((3, 4)), Some(50)), Layout::Irregular { n: 50 });
        assert_eq!(layout(Some((3, 4)), None), Layout::Grid { nx: 3, ny: 4 });
        assert_eq!(layout(None, None), Layout::Grid { nx: 12, ny: 12 });
        assert!(check_noise_um(0.0).is_ok());
        let err = check_noise_um(-1.0).unwrap_err();
        assert!(matches!(err, crate::SynthError::Options(_)), "{err}");
        assert!(err.to_string().contains("`noise_um` must be ≥ 0"), "{err}");
        assert!(check_noise_um(f64::NAN).is_err());
    }
}
