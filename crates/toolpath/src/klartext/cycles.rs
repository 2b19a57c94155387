//! Coordinate-transformation cycles of Klartext: 7 datum shift (followed), 8 mirror image, 10 rotation, 11 scaling, 26 axis-specific scaling and 19 working plane (cuts refused in the zone while active), and cycle calls.

use super::block::{Block, Value};
use super::{Frame, Kt};
use errmap_core::error::Result;

const AXES: [&str; 3] = ["X", "Y", "Z"];

impl Kt<'_> {
    /// `CYCL DEF n.m …` or `CYCL CALL …`.
    pub(super) fn cycle_block(
        &mut self,
        n: u64,
        content: &str,
        term: &str,
        b: &Block,
    ) -> Result<()> {
        let rest = b.rest.to_ascii_uppercase();
        if rest.starts_with("CALL") {
            self.unchanged(n, content, term, b, false)?;
            let (col, word) = (b.head_col, format!("CYCL {}", b.rest).trim().to_string());
            self.cycle_call(n, col, &word)?;
            if rest.contains("PAT") || rest.contains("POS") {
                self.m.lose_position(n, &[0, 1, 2]);
            }
            return Ok(());
        }
        let id = super::cycle_id(b);
        let (major, minor) = match id {
            Some(v) => (v.trunc() as i64, ((v - v.trunc()) * 10.0).round() as i64),
            None => (-1, 0),
        };
        let followed = matches!(major, 7 | 8 | 10 | 11 | 19 | 26 | 32);
        if let (true, Some((col, word, msg))) =
            (followed && minor != 0 && major != 32, b.bad.clone())
        {
            return Err(self.err(
                n,
                col,
                &word,
                msg,
                "write the cycle's words as the TNC does (e.g. CYCL DEF 7.1 X+10)",
            ));
        }
        // The cycle's own block (`7.0 DATUM SHIFT`) and machining-cycle definitions do nothing
        // until called.
        if !followed || minor == 0 {
            // A machining cycle's definition replaces the one a later call runs.
            if ![7, 8, 9, 10, 11, 19, 26, 32, 247].contains(&major) {
                self.define_cycle(n, major, b);
            }
            if major == 247 {
                return self.preset(n, content, term, b);
            }
            return self.unchanged(n, content, term, b, false);
        }
        self.unchanged(n, content, term, b, false)?;
        if major == 32 {
            self.path_tolerance(n, b);
            return Ok(());
        }
        match major {
            7 => self.datum_shift(n, b),
            _ => {
                self.transform(n, b, major);
                Ok(())
            }
        }
    }

    /// Cycle 247 DATUM SETTING activates preset Q339 of the preset table. The map is applied in
    /// the coordinates of the first preset the program selects (as the G-code dialects use the
    /// first work offset), provided no cut that may lie in the zone and no datum shift came
    /// before it; cuts under another preset are refused until the first is selected again.
    fn preset(&mut self, n: u64, content: &str, term: &str, b: &Block) -> Result<()> {
        let q = super::holes::q_value(&b.rest, "Q339");
        let number = match &q {
            Some(Ok(p)) => Some(*p),
            _ => None,
        };
        let first = match (number, self.first_preset) {
            // Whether a cycle 7 shift survives a preset change is not in the manuals errmap has.
            _ if self.m.shift != [0.0; 3] => Err("with a datum shift (cycle 7) in force"),
            // Identical parts, one per preset: the map applies in each preset's coordinates.
            (Some(_), _) if self.m.settings.same_part_per_offset => Ok(true),
            (Some(p), Some(first)) => Ok(p == first),
            (Some(p), None) if !self.cut_seen => {
                self.first_preset = Some(p);
                Ok(true)
            }
            (Some(_), None) => Err("after cuts under the preset in force before it"),
            (None, _) => Err("with a preset number errmap cannot read"),
        };
        self.frames.retain(|f| f.cycle != "247");
        if first != Ok(true) {
            let why = match (first, self.first_preset) {
                (Err(why), _) => why.to_string(),
                (_, Some(p)) => format!("another preset than the program's first (Q339={p})"),
                _ => String::new(),
            };
            let text = q
                .map(|v| v.map_or_else(|t| t, |p| format!("Q339={p}")))
                .unwrap_or_else(|| "no Q339".into());
            self.frames.push(Frame {
                cycle: "247".into(),
                line: n,
                what: format!("CYCL DEF 247 DATUM SETTING {text}, {why}"),
                normal: true,
            });
        }
        self.unchanged(n, content, term, b, false)?;
        self.m.lose_position(n, &[0, 1, 2]);
        Ok(())
    }

    /// Cycle 32 TOLERANCE: `32.1 T0.05` lets the control deviate from the programmed path by
    /// up to T (program units) while it smooths it; `32.1` alone resets the machine's default.
    fn path_tolerance(&mut self, n: u64, b: &Block) {
        let t = b.rest.split_whitespace().find_map(|w| {
            let v = w.strip_prefix('T').or_else(|| w.strip_prefix('t'))?;
            v.parse::<f64>().ok().filter(|t| t.is_finite() && *t >= 0.0)
        });
        if let Some(t) = t {
            let mm = t * self.m.scale_mm();
            if self.path_tolerance_mm.is_none_or(|(old, _)| mm > old) {
                self.path_tolerance_mm = Some((mm, n));
            }
        }
    }

    /// Cycle 7: `X+10` shifts the datum to X = 10 of the preset (absolute), `IX+10` by 10 from
    /// the current shift; `#5` takes a datum table line, which errmap cannot see.
    fn datum_shift(&mut self, n: u64, b: &Block) -> Result<()> {
        for w in b.words.iter().skip(2) {
            let axis = AXES
                .iter()
                .position(|a| w.addr.trim_start_matches('I') == *a);
            match (axis, w.num()) {
                (Some(i), Some(v)) => {
                    let new = if w.addr.starts_with('I') {
                        self.m.shift[i] + v
                    } else {
                        v
                    };
                    let delta = new - self.m.shift[i];
                    self.m.shift[i] = new;
                    self.m.pos[i] = self.m.pos[i].map(|p| p - delta);
                    self.centre[i] = self.centre[i].map(|p| p - delta);
                }
                _ => {
                    let param = w.value == Value::Param;
                    self.frames.push(Frame {
                        cycle: if param { "param" } else { "7" }.into(),
                        line: n,
                        what: format!("CYCL DEF 7 DATUM SHIFT {}", w.text),
                        normal: true,
                    });
                    self.m.lose_position(n, &[0, 1, 2]);
                }
            }
        }
        Ok(())
    }

    /// Cycles 8, 10, 11, 26 and 19: set (a frame) or reset (`8.1` with no axes, `ROT+0`,
    /// `SCL 1`, all factors 1, all angles 0).
    fn transform(&mut self, n: u64, b: &Block, major: i64) {
        let params = || b.words.iter().skip(2);
        let normal_letter = AXES[self.m.normal];
        let (name, active, normal) = match major {
            8 => {
                let axes: Vec<&str> = params()
                    .filter(|w| w.value == Value::None)
                    .map(|w| w.addr.as_str())
                    .collect();
                (
                    "MIRROR IMAGE",
                    !axes.is_empty(),
                    axes.contains(&normal_letter),
                )
            }
            10 => {
                let rot = params().find(|w| w.addr == "ROT").and_then(|w| w.num());
                (
                    "ROTATION",
                    rot != Some(0.0),
                    self.m.normal != self.tool_axis,
                )
            }
            11 => {
                let scl = params()
                    .find(|w| w.addr.is_empty() || w.addr == "SCL")
                    .and_then(|w| w.num());
                let scl =
                    scl.or_else(|| params().find(|w| w.addr.is_empty()).and_then(|w| w.num()));
                ("SCALING", scl != Some(1.0), true)
            }
            26 => {
                let factors: Vec<(&str, Option<f64>)> = params()
                    .filter(|w| AXES.contains(&w.addr.as_str()))
                    .map(|w| (w.addr.as_str(), w.num()))
                    .collect();
                let active = factors.iter().any(|(_, f)| *f != Some(1.0));
                let normal = factors
                    .iter()
                    .any(|(a, f)| *a == normal_letter && *f != Some(1.0));
                ("AXIS-SPECIFIC SCALING", active, normal)
            }
            _ => {
                let angles = params()
                    .filter(|w| w.addr.len() == 1)
                    .all(|w| w.num() == Some(0.0));
                ("WORKING PLANE", !angles, true)
            }
        };
        let cycle = major.to_string();
        self.frames.retain(|f| f.cycle != cycle);
        if active {
            self.frames.push(Frame {
                cycle,
                line: n,
                what: format!("CYCL DEF {major} {name}"),
                normal,
            });
        }
    }
}
