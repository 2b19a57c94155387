//! Plausibility of one temperature reading: an open or shorted RTD (a module's over- or
//! underrange value, or a Pt100 resistance outside IEC 60751's range), a reading outside the
//! sensor's range, and a change since the last accepted reading faster than the sensor's
//! rate of change allows.

use super::config::SensorConfig;

/// What is wrong with a reading (the message names the sensor's values).
#[derive(Debug, Clone, PartialEq)]
pub struct Implausible {
    /// `open`, `shorted`, `range`, `rate`.
    pub kind: &'static str,
    /// What is wrong, naming the sensor and the reading (the alarm's and the cycle note's text).
    pub message: String,
}

/// A raw Pt100 reading outside the convertible range: an open RTD reads high, a short low.
pub fn unconvertible(name: &str, raw: f64) -> Implausible {
    let open = raw
        > errmap_metrology::thermal::pt100::resistance_ohm(
            errmap_metrology::thermal::pt100::T_MAX_C,
        );
    Implausible {
        kind: if open { "open" } else { "shorted" },
        message: format!(
            "{name} {} RTD (reading {raw:.2} Ω outside the Pt100 range)",
            if open { "open" } else { "shorted" }
        ),
    }
}

/// Check a calibrated reading `value_c` at loop time `t_s` against the last accepted one.
pub fn check(
    name: &str,
    cfg: &SensorConfig,
    value_c: f64,
    t_s: f64,
    last_accepted: Option<(f64, f64)>,
) -> Result<(), Implausible> {
    if !value_c.is_finite() {
        return Err(Implausible {
            kind: "range",
            message: format!("{name} reading is not a number"),
        });
    }
    if value_c > cfg.open_above_c {
        return Err(Implausible {
            kind: "open",
            message: format!(
                "{name} open RTD (reading {value_c:.1} °C above {:.1} °C)",
                cfg.open_above_c
            ),
        });
    }
    if value_c < cfg.short_below_c {
        return Err(Implausible {
            kind: "shorted",
            message: format!(
                "{name} shorted RTD (reading {value_c:.1} °C below {:.1} °C)",
                cfg.short_below_c
            ),
        });
    }
    if value_c < cfg.min_c || value_c > cfg.max_c {
        return Err(Implausible {
            kind: "range",
            message: format!(
                "{name} reading {value_c:.2} °C outside {:.1} … {:.1} °C",
                cfg.min_c, cfg.max_c
            ),
        });
    }
    if let Some((t0, v0)) = last_accepted {
        let dt = (t_s - t0).max(0.0);
        let allowed = cfg.max_step_c + cfg.max_rate_c_per_s * dt;
        let change = (value_c - v0).abs();
        if change > allowed {
            return Err(Implausible {
                kind: "rate",
                message: format!(
                    "{name} changed {change:.2} °C in {dt:.2} s (at most {allowed:.2} °C: {} °C + {} °C/s)",
                    cfg.max_step_c, cfg.max_rate_c_per_s
                ),
            });
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::FilterChoice;

    fn cfg() -> SensorConfig {
        SensorConfig {
            channel: "a.b".into(),
            min_c: 0.0,
            max_c: 60.0,
            max_rate_c_per_s: 0.1,
            max_step_c: 0.5,
            open_above_c: 200.0,
            short_below_c: -50.0,
            filter: FilterChoice::None,
        }
    }

    #[test]
    fn each_rule_acts() {
        let c = cfg();
        assert!(check("T1", &c, 21.0, 0.0, None).is_ok());
        let e = check("T3", &c, 850.0, 0.0, None).unwrap_err();
        assert_eq!(e.kind, "open");
        assert_eq!(e.message, "T3 open RTD (reading 850.0 °C above 200.0 °C)");
        assert_eq!(
            check("T", &c, -200.0, 0.0, None).unwrap_err().kind,
            "shorted"
        );
        assert_eq!(check("T", &c, 61.0, 0.0, None).unwrap_err().kind, "range");
        // 10 s after 21 °C: at most 0.5 + 0.1·10 = 1.5 °C.
        assert!(check("T", &c, 22.49, 10.0, Some((0.0, 21.0))).is_ok());
        assert_eq!(
            check("T", &c, 22.51, 10.0, Some((0.0, 21.0)))
                .unwrap_err()
                .kind,
            "rate"
        );
        assert_eq!(unconvertible("T", 1e6).kind, "open");
        assert_eq!(unconvertible("T", 0.0).kind, "shorted");
    }
}
