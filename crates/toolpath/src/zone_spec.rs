//! The compensation settings as `errmap compensate` takes them, in words: the zone
//! (`MIN,MAX`, `all`, or the map's surface band) and the controller choices by name.

use super::{CompensationSettings, Dialect, FanucNumbers, PowerOnMotion, Units};
use crate::error::SettingsError;
use crate::setting::Setting;
use errmap_core::error::Error;
use errmap_core::setting::words;

type Result<T, E = SettingsError> = std::result::Result<T, E>;

/// Where moves are compensated, as given on the command line.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ZoneSpec {
    /// The map's probed surface ± the surface tolerance (no `--zone`).
    Surface,
    /// A band `MIN,MAX` along the map's normal, in program units.
    Band(f64, f64),
    /// Everywhere (`--zone all`).
    All,
}

impl ZoneSpec {
    /// Parse `--zone`: absent, `all` or `MIN,MAX`.
    pub fn parse(text: Option<&str>) -> Result<ZoneSpec> {
        match text {
            None => Ok(ZoneSpec::Surface),
            Some("all") => Ok(ZoneSpec::All),
            Some(t) => parse_zone(t).map(|(lo, hi)| ZoneSpec::Band(lo, hi)),
        }
    }
}

/// Parse `MIN,MAX`.
pub fn parse_zone(text: &str) -> Result<(f64, f64)> {
    let bad = || {
        SettingsError::Zone(Error::usage(
            format!("{} '{text}' is not MIN,MAX", words(Setting::Zone)),
            format!(
                "give two numbers in program units, e.g. {zone} -5,0 (or {zone} all)",
                zone = words(Setting::Zone)
            ),
        ))
    };
    let (a, b) = text.split_once(',').ok_or_else(bad)?;
    let lo: f64 = a.trim().parse().map_err(|_| bad())?;
    let hi: f64 = b.trim().parse().map_err(|_| bad())?;
    Ok((lo, hi))
}

/// Parse an enumerated flag value, or a usage error listing the choices.
fn choice<T>(
    setting: Setting,
    text: Option<&str>,
    parse: fn(&str) -> Option<T>,
    choices: &str,
) -> Result<Option<T>> {
    text.map(|t| {
        parse(t).ok_or_else(|| {
            SettingsError::Choice(Error::usage(
                format!("{} '{t}' is not one of {choices}", words(setting)),
                format!("use {} with one of {choices}", words(setting)),
            ))
        })
    })
    .transpose()
}

/// The compensation settings in words, as the command line gives them.
#[derive(Debug, Clone, Default)]
pub struct SettingsText<'a> {
    /// `--zone`: `MIN,MAX` along the map's normal in the units the program starts in, or `all`;
    /// `None` = the map's probed surface ± `surface_tol_mm`.
    pub zone: Option<&'a str>,
    /// `--surface-tol`: half-width of the default zone around the probed surface, mm.
    pub surface_tol_mm: f64,
    /// `--max-segment`: longest segment emitted in the zone, mm.
    pub max_segment_mm: f64,
    /// `--chord-tol`: largest distance between an arc and its chords, mm.
    pub chord_tol_mm: f64,
    /// `--dialect` (`linuxcnc`, `fanuc`, `sinumerik`, `heidenhain`); `None` = detect.
    pub dialect: Option<&'a str>,
    /// `--units` of a program that does not say (`mm`, `inch`); `None` = refuse such a program.
    pub units: Option<&'a str>,
    /// `--fanuc-numbers` (`calculator`, `is-a`, `is-b`, `is-c`); `None` = refuse decimal-less
    /// Fanuc coordinates.
    pub fanuc_numbers: Option<&'a str>,
    /// `--extrapolate`: also compensate outside the measured domain.
    pub extrapolate: bool,
    /// `--domain-margin`: margin around the probes' hull that still counts as measured, mm.
    pub domain_margin_mm: f64,
    /// `--power-on-motion` (`g0`, `g1`); `None` = refuse axis words before any motion word.
    pub power_on_motion: Option<&'a str>,
    /// `--expand`: run subprograms, loops and parameters and write the flattened program.
    pub expand: bool,
    /// `--compensate-holes`: move canned-cycle depths by −E at holes in the zone.
    pub compensate_holes: bool,
    /// `--same-part-per-offset`: apply the map in each work offset's coordinates.
    pub same_part_per_offset: bool,
}

impl SettingsText<'_> {
    /// The settings, parsed and checked.
    pub fn settings(&self) -> Result<CompensationSettings> {
        let zone = ZoneSpec::parse(self.zone)?;
        let settings = CompensationSettings {
            zone: match zone {
                ZoneSpec::Band(lo, hi) => Some((lo, hi)),
                ZoneSpec::Surface | ZoneSpec::All => None,
            },
            everywhere: zone == ZoneSpec::All,
            surface_tol_mm: self.surface_tol_mm,
            max_segment: self.max_segment_mm,
            chord_tol: self.chord_tol_mm,
            dialect: choice(
                Setting::Dialect,
                self.dialect,
                Dialect::parse,
                "linuxcnc, fanuc, sinumerik, heidenhain",
            )?,
            units: choice(Setting::Units, self.units, Units::parse, "mm, inch")?,
            fanuc_numbers: choice(
                Setting::FanucNumbers,
                self.fanuc_numbers,
                FanucNumbers::parse,
                "calculator, is-a, is-b, is-c",
            )?,
            extrapolate: self.extrapolate,
            domain_margin_mm: self.domain_margin_mm,
            power_on_motion: choice(
                Setting::PowerOnMotion,
                self.power_on_motion,
                PowerOnMotion::parse,
                "g0, g1",
            )?,
            expand: self.expand,
            compensate_holes: self.compensate_holes,
            same_part_per_offset: self.same_part_per_offset,
        };
        settings.validate()?;
        Ok(settings)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn zones_parse_as_surface_band_or_all() {
        assert_eq!(ZoneSpec::parse(None).unwrap(), ZoneSpec::Surface);
        assert_eq!(ZoneSpec::parse(Some("all")).unwrap(), ZoneSpec::All);
        assert_eq!(
            ZoneSpec::parse(Some(" -5, 0.5")).unwrap(),
            ZoneSpec::Band(-5.0, 0.5)
        );
        for bad in ["5", "a,1", "1,b", ""] {
            let err = ZoneSpec::parse(Some(bad)).unwrap_err();
            assert!(matches!(err, SettingsError::Zone(_)), "{bad}");
            assert!(
                err.to_string()
                    .contains(&format!("`zone` '{bad}' is not MIN,MAX")),
                "{err}"
            );
        }
    }

    #[test]
    fn an_unknown_choice_lists_the_valid_ones() {
        let text = SettingsText {
            dialect: Some("mazak"),
            max_segment_mm: 5.0,
            chord_tol_mm: 0.005,
            surface_tol_mm: 0.5,
            ..SettingsText::default()
        };
        let err = text.settings().unwrap_err();
        assert!(matches!(err, SettingsError::Choice(_)), "{err}");
        assert!(
            err.to_string()
                .contains("`dialect` 'mazak' is not one of linuxcnc, fanuc, sinumerik, heidenhain"),
            "{err}"
        );
        let ok = SettingsText {
            zone: Some("all"),
            units: Some("inch"),
            ..text
        };
        let ok = SettingsText {
            dialect: None,
            ..ok
        }
        .settings()
        .unwrap();
        assert!(ok.everywhere && ok.zone.is_none());
        assert_eq!(ok.units, Some(Units::Inch));
    }
}
