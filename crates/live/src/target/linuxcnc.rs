//! The LinuxCNC external-offsets target: per axis L, the compensation at the axis's present
//! position as an external offset, through errmap's HAL component (`crate::hal`), whose pins
//! drive `axis.L.eoffset-counts`, `axis.L.eoffset-scale` and `axis.L.eoffset-enable`.
//!
//! LinuxCNC (motion's `plan_external_offsets`, docs "External Axis Offsets") adds the change of
//! `eoffset-counts` since the last servo period, times `eoffset-scale`, to the requested offset
//! `axis.L.eoffset-request` while `eoffset-enable` is set, the machine is on and every joint is
//! homed (changes otherwise are dropped), zeroes the request at machine-on, and moves the axis
//! to it at `[AXIS_L] OFFSET_AV_RATIO` of its velocity and acceleration. So errmap steers by
//! the request: each write reads it and changes the counts by round((wanted − request)/scale);
//! a request that is not what the last write asked for (a machine-off/on, eoffset-clear, or a
//! change dropped) is reported by [`Target::moved`], and the loop ramps from it as at a start.

use super::{Output, Present, Target};
use crate::config::{LiveConfig, TargetAxisConfig, TargetConfig};
use crate::hal::{HalLink, HalValue, PinSpec};
use crate::source::linuxcnc::DEFAULT_PYTHON;
use crate::LinkError;
use errmap_core::error::{Error, Result};
use std::collections::BTreeMap;
use std::time::Duration;

/// The shortest loop period with a LinuxCNC target (ms): a count change must reach motion (one
/// servo period, 1 ms in LinuxCNC's configurations) before the next cycle reads the request.
pub const MIN_PERIOD_MS: u64 = 10;

/// One axis's pins and what errmap last asked of it.
struct AxisPins {
    /// `axis.L.eoffset-request`, the requested offset (machine units).
    request_pin: String,
    /// errmap's pin driving `axis.L.eoffset-counts` (`L.counts`).
    counts_pin: String,
    /// Machine units per count.
    scale: f64,
    /// mm per machine unit (1, or 25.4 on an inch machine).
    mm_per_unit: f64,
    /// The counts errmap's pin holds now.
    counts: i32,
    /// The request errmap's last write leads to (machine units); None before the first.
    expected: Option<f64>,
    /// The request read this cycle by `moved`, used by the write that follows.
    request_now: Option<f64>,
}

/// A running LinuxCNC: errmap's HAL component linked to every configured axis's offset pins.
pub struct LinuxCncTarget {
    name: String,
    link: HalLink,
    axes: BTreeMap<String, AxisPins>,
}

/// The counts change that moves a request to `wanted` (both machine units), and the request
/// it leads to.
pub fn counts_step(wanted: f64, request: f64, scale: f64) -> (i32, f64) {
    let steps = ((wanted - request) / scale)
        .round()
        .clamp(i32::MIN as f64, i32::MAX as f64) as i32;
    (steps, request + f64::from(steps) * scale)
}

impl LinuxCncTarget {
    /// Start errmap's HAL component for `targets[index]`, link its pins to every axis's
    /// `axis.L.eoffset-*` pins, set the scale and enable the offsets (exit 2 for a bad key,
    /// exit 3 when LinuxCNC or its `hal` module cannot be reached or a pin is driven already).
    pub fn connect(
        config: &LiveConfig,
        index: usize,
        t: &TargetConfig,
    ) -> Result<LinuxCncTarget, LinkError> {
        let key = format!("targets.{index}");
        check_target(config, &key, t)?;
        let component = t
            .component
            .clone()
            .unwrap_or_else(|| format!("errmap-{}", t.name));
        let mut pins = Vec::new();
        let mut axes = BTreeMap::new();
        for (axis, a) in &t.axes {
            let (axis_pins, specs) =
                axis_pins(config, &format!("{key}.axes.{axis}"), axis, a, &component)?;
            pins.extend(specs);
            axes.insert(axis.clone(), axis_pins);
        }
        let what = format!("LinuxCNC target '{}'", t.name);
        let mut link = HalLink::start(
            &what,
            t.python.as_deref().unwrap_or(DEFAULT_PYTHON),
            &component,
            &pins,
            Duration::from_millis(1000),
        )?;
        take_over(&mut link, &what, &component, &mut axes)?;
        Ok(LinuxCncTarget {
            name: t.name.clone(),
            link,
            axes,
        })
    }

    fn pins(&mut self, axis: &str) -> Result<&mut AxisPins> {
        let name = self.name.clone();
        self.axes.get_mut(axis).ok_or_else(|| {
            Error::usage(
                format!("target '{name}' has no axis {axis}"),
                format!("add [targets.axes.{axis}]"),
            )
        })
    }

    fn failed(&self, action: &'static str, e: String) -> Error {
        Error::io(action, &self.link.what, std::io::Error::other(e))
    }

    /// `axis.L.eoffset-request` now (machine units).
    fn request(&mut self, axis: &str) -> Result<f64> {
        let pin = self.pins(axis)?.request_pin.clone();
        let v = self
            .link
            .get(std::slice::from_ref(&pin))
            .map_err(|e| self.failed("read from", e))?;
        Ok(v[0].as_f64())
    }
}

/// The loop period a linuxcnc target needs, and no key of another target kind.
fn check_target(config: &LiveConfig, key: &str, t: &TargetConfig) -> Result<()> {
    if config.cycle.period_ms < MIN_PERIOD_MS {
        return Err(config.key_error(
                "loop.period_ms",
                format!(
                    "a linuxcnc target needs a loop period of at least {MIN_PERIOD_MS} ms, so that motion has taken a write before the next cycle reads it back"
                ),
                format!("period_ms = {MIN_PERIOD_MS} or more"),
            ));
    }
    for (k, present) in [
        ("endpoint", t.endpoint.is_some()),
        ("address", t.address.is_some()),
        ("unit_id", t.unit_id.is_some()),
        ("security_policy", t.security_policy.is_some()),
        ("user", t.user.is_some()),
        ("password", t.password.is_some()),
    ] {
        if present {
            return Err(config.key_error(
                &format!("{key}.{k}"),
                format!("a linuxcnc target has no key '{k}'"),
                "its keys: name, kind, python, component, axes",
            ));
        }
    }
    Ok(())
}

/// An axis's pins (`L.counts`, `L.scale`, `L.enable`, linked to `axis.L.eoffset-*`) from its
/// `[targets.axes.*]` table at `key`: letter, resolution and unit checked.
fn axis_pins(
    config: &LiveConfig,
    key: &str,
    axis: &str,
    a: &TargetAxisConfig,
    component: &str,
) -> Result<(AxisPins, [PinSpec; 3])> {
    for (field, present) in [
        ("sd43900", a.sd43900.is_some()),
        ("sd43910", a.sd43910.is_some()),
        ("sd43920", a.sd43920.is_some()),
        ("node", a.node.is_some()),
        ("register", a.register.is_some()),
        ("type", a.data_type.is_some()),
        ("word_order", a.word_order.is_some()),
        ("scale", a.scale.is_some()),
    ] {
        if present {
            return Err(config.key_error(
                &format!("{key}.{field}"),
                format!("a linuxcnc axis has no key '{field}'"),
                "its keys: letter, resolution_um, unit",
            ));
        }
    }
    let letter = a.letter.clone().unwrap_or_else(|| axis.to_lowercase());
    if !(letter.len() == 1 && "xyzabcuvw".contains(letter.as_str())) {
        return Err(config.key_error(
            &format!("{key}.letter"),
            format!("'{letter}' is not a LinuxCNC axis letter"),
            "one of x y z a b c u v w (letter = \"z\")",
        ));
    }
    let resolution_um = a.resolution_um.unwrap_or(0.1);
    if !(resolution_um.is_finite() && resolution_um > 0.0 && resolution_um <= 1000.0) {
        return Err(config.key_error(
            &format!("{key}.resolution_um"),
            format!("{resolution_um} is not a resolution"),
            "µm per count, e.g. 0.1",
        ));
    }
    let mm_per_unit = match a.unit.as_deref() {
        None | Some("mm") => 1.0,
        Some("inch") => 25.4,
        Some(other) => {
            return Err(config.key_error(
                &format!("{key}.unit"),
                format!("'{other}' is not a LinuxCNC linear unit"),
                "mm or inch, as [TRAJ] LINEAR_UNITS",
            ))
        }
    };
    let specs = [
        ("counts", "s32", "eoffset-counts"),
        ("scale", "float", "eoffset-scale"),
        ("enable", "bit", "eoffset-enable"),
    ]
    .map(|(pin, hal_type, motion)| PinSpec {
        name: format!("{letter}.{pin}"),
        hal_type,
        net: Some(format!("axis.{letter}.{motion}")),
        signal: format!("{component}-{letter}-{pin}"),
    });
    Ok((
        AxisPins {
            request_pin: format!("axis.{letter}.eoffset-request"),
            counts_pin: format!("{letter}.counts"),
            scale: resolution_um / 1000.0 / mm_per_unit,
            mm_per_unit,
            counts: 0,
            expected: None,
            request_now: None,
        },
        specs,
    ))
}

/// Take over each axis's offset where LinuxCNC has it: errmap's counts pins took the value
/// motion reads when they were linked, and the offsets move only by changes from there. The
/// scale is set before any change, then the offsets are enabled.
fn take_over(
    link: &mut HalLink,
    what: &str,
    component: &str,
    axes: &mut BTreeMap<String, AxisPins>,
) -> Result<()> {
    let reach = |e: String| Error::io("reach", what, std::io::Error::other(e));
    for a in axes.values_mut() {
        let full = format!("{component}.{}", a.counts_pin);
        a.counts = match link.get(&[full]).map_err(reach)?[..] {
            [HalValue::Integer(c)] => c as i32,
            _ => return Err(reach(format!("{} is not an s32", a.counts_pin))),
        };
        let letter = &a.counts_pin[..1];
        link.set(&[(format!("{letter}.scale"), format!("{:e}", a.scale))])
            .map_err(reach)?;
        link.set(&[(format!("{letter}.enable"), "1".into())])
            .map_err(reach)?;
    }
    Ok(())
}

impl Target for LinuxCncTarget {
    fn name(&self) -> &str {
        &self.name
    }
    fn kind(&self) -> &'static str {
        "linuxcnc"
    }
    fn is_point(&self) -> bool {
        true
    }
    fn present(&mut self, axis: &str) -> Result<Present> {
        let request = self.request(axis)?;
        let a = self.pins(axis)?;
        a.expected = Some(request);
        Ok(Present::Value(request * a.mm_per_unit * 1000.0))
    }
    fn moved(&mut self, axis: &str) -> Result<Option<Present>> {
        let request = self.request(axis)?;
        let a = self.pins(axis)?;
        a.request_now = Some(request);
        match a.expected {
            Some(e) if (request - e).abs() > 0.5 * a.scale => {
                a.expected = Some(request);
                Ok(Some(Present::Value(request * a.mm_per_unit * 1000.0)))
            }
            _ => Ok(None),
        }
    }
    fn write(&mut self, axis: &str, output: &Output) -> Result<()> {
        let value_um = output
            .value_um
            .ok_or_else(|| Error::usage("no position", "the axis needs a position channel"))?;
        let request = match self.pins(axis)?.request_now.take() {
            Some(r) => r,
            None => self.request(axis)?,
        };
        let a = self.pins(axis)?;
        let (steps, leads_to) = counts_step(value_um / 1000.0 / a.mm_per_unit, request, a.scale);
        if steps == 0 {
            a.expected = Some(leads_to);
            return Ok(());
        }
        let counts = a.counts.wrapping_add(steps);
        let pin = a.counts_pin.clone();
        self.link
            .set(&[(pin, counts.to_string())])
            .map_err(|e| self.failed("write to", e))?;
        let a = self.pins(axis)?;
        a.counts = counts;
        a.expected = Some(leads_to);
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn counts_step_rounds_to_the_nearest_count() {
        // 0.1 µm counts in mm: from a request of 0.0012 mm to 0.00347 mm is 22.7 → 23 counts,
        // which lead to 0.0035 mm.
        let (steps, to) = counts_step(0.00347, 0.0012, 0.0001);
        assert_eq!(steps, 23);
        assert!((to - 0.0035).abs() < 1e-15);
        // Downwards and by less than half a count.
        assert_eq!(counts_step(-0.00001, 0.0, 0.0001).0, 0);
        assert_eq!(counts_step(-0.00006, 0.0, 0.0001).0, -1);
        // An absurd request saturates instead of wrapping.
        assert_eq!(counts_step(1e12, 0.0, 0.0001).0, i32::MAX);
    }
}
