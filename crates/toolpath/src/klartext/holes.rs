//! Drilling cycles 200–209 (and the old cycle 1 PECKING) of Klartext at a cycle call (`CYCL CALL`, `M99`, after `M89`): a hole whose bottom (surface Q203 + depth Q201) lies in the zone is refused, or with `--compensate-holes` drilled from a surface moved by −E: the cycle is defined again before the call with Q203 − E (the depth Q201 and the clearances are relative to Q203), and the original definition is restored before a later call outside the zone.

use super::block::Block;
use super::{Kt, OutLine};
use crate::setting::Setting;
use errmap_core::error::Result;
use errmap_core::setting::words;

const AXES: [&str; 3] = ["X", "Y", "Z"];

/// A drilling cycle definition (`CYCL DEF 203 … Q201=-33 … Q203=+0 …`) as written.
#[derive(Debug, Clone)]
pub(super) struct HoleCycle {
    pub number: i64,
    pub line: u64,
    /// Q201 (depth, relative to Q203) and Q203 (surface coordinate): a number, or the text of
    /// the value when it is not one (`Q203=+Q5`), or `None` when the block has none.
    pub depth: Option<Result<f64, String>>,
    pub surface: Option<Result<f64, String>>,
    /// The definition's lines: content and terminator.
    pub lines: Vec<(String, String)>,
    /// Cycle 1 PECKING: `1.1 DIST` (set-up clearance) and `1.2 DEPTH`, both relative to the
    /// position at the call.
    pub dist: Option<Result<f64, String>>,
}

/// The number after `DIST`/`SET UP`/`DEPTH` in a cycle 1 block (`1.1 DIST25.000`,
/// `1.2 DEPTH-10`), or the text that is not one.
fn cycle1_value(rest: &str, keys: &[&str]) -> Option<Result<f64, String>> {
    let up = rest.to_ascii_uppercase();
    let key = keys
        .iter()
        .find_map(|k| up.find(k).map(|at| at + k.len()))?;
    let text = up[key..]
        .split_whitespace()
        .next()
        .unwrap_or("")
        .to_string();
    Some(
        text.parse::<f64>()
            .ok()
            .filter(|v| v.is_finite())
            .ok_or(text),
    )
}

/// `Q203=+0` in a block's text: the number, or the text that is not one.
pub(super) fn q_value(rest: &str, q: &str) -> Option<Result<f64, String>> {
    let key = format!("{q}=");
    rest.split_whitespace().find_map(|t| {
        let v = t
            .to_ascii_uppercase()
            .strip_prefix(&key)
            .map(str::to_string)?;
        Some(
            v.parse::<f64>()
                .ok()
                .filter(|x| x.is_finite())
                .ok_or_else(|| t.to_string()),
        )
    })
}

impl Kt<'_> {
    /// Remember a cycle 200–209 definition; another `CYCL DEF` of a machining cycle replaces it.
    pub(super) fn define_cycle(&mut self, n: u64, major: i64, b: &Block) {
        self.machining_cycle = Some((major, n));
        if major == 1 {
            // Cycle 1 PECKING is defined over blocks `1.0` … `1.5`: the later ones fill it in.
            let minor = super::cycle_id(b).map(|v| ((v - v.trunc()) * 10.0).round() as i64);
            match (minor, self.hole_cycle.as_mut().filter(|c| c.number == 1)) {
                (Some(1), Some(c)) => c.dist = cycle1_value(&b.rest, &["DIST", "SET UP", "SETUP"]),
                (Some(2), Some(c)) => c.depth = cycle1_value(&b.rest, &["DEPTH"]),
                (Some(3..=5), Some(_)) => {}
                _ => {
                    self.hole_cycle = Some(HoleCycle {
                        number: 1,
                        line: n,
                        depth: None,
                        surface: None,
                        lines: Vec::new(),
                        dist: None,
                    })
                }
            }
            self.hole_surface_out = None;
            return;
        }
        self.hole_cycle = (200..=209).contains(&major).then(|| HoleCycle {
            number: major,
            line: n,
            depth: q_value(&b.rest, "Q201"),
            surface: q_value(&b.rest, "Q203"),
            lines: self.block_lines.clone(),
            dist: None,
        });
        self.hole_surface_out = None;
    }

    /// A call of cycle 1 PECKING at the current position (TNC 426/430 User's Manual, "PECKING
    /// (Cycle 1)"): from the starting position the tool drills DIST + |DEPTH| in DEPTH's
    /// direction and returns to the starting position, so the whole hole moves with the start.
    /// A hole whose bottom lies in the zone is refused, or with `--compensate-holes` started
    /// from Z − E: the positioning block's Z (written when it has none), or an `L Z… FMAX`
    /// before a call of its own. `Some(true)`: handled, the tool back at the (original) start.
    fn pecking_call(
        &mut self,
        n: u64,
        col: usize,
        word: &str,
        cycle: &HoleCycle,
        (x, y): (f64, f64),
    ) -> Result<Option<bool>> {
        let k = self.m.normal;
        let hole = format!("cycle 1 PECKING ({})", self.at(cycle.line));
        let (dist, depth) = match (&cycle.dist, &cycle.depth) {
            (Some(Ok(a)), Some(Ok(d))) if *d != 0.0 => (*a, *d),
            (a, d) => {
                let mut p = self.m.pos;
                p[k] = None;
                if !self.may_touch(&[p]) {
                    return Ok(Some(false));
                }
                let what = [("1.1 DIST", a), ("1.2 DEPTH", d)]
                    .iter()
                    .find_map(|(q, v)| match v {
                        Some(Ok(_)) => None,
                        Some(Err(t)) => Some(format!("its {q} is `{t}`, not a number")),
                        None => Some(format!("it has no {q}")),
                    })
                    .unwrap_or_else(|| "its DEPTH is 0".into());
                return Err(self.err(n, col, word, format!("`{word}` calls {hole}, which may drill in the compensation zone, and {what}: errmap cannot tell the hole's bottom"), "define cycle 1 with numbers for DIST and DEPTH, or move the zone away"));
            }
        };
        let Some(start) = self.m.pos[k] else {
            let mut p = self.m.pos;
            p[k] = None;
            if !self.may_touch(&[p]) {
                return Ok(Some(false));
            }
            return Err(self.err(n, col, word, format!("`{word}` calls {hole} from an unknown {} position (cycle 1 drills relative to where the tool stands), and the hole may lie in the compensation zone", AXES[k]), "position the tool with an absolute Z before the call"));
        };
        let bottom = start + depth.signum() * (dist.abs() + depth.abs());
        let (u, v) = self.m.plane_uv;
        let mut p = [0.0; 3];
        p[u] = x;
        p[v] = y;
        p[k] = bottom;
        let e = self.m.error_at(&p);
        self.m.kept_nominal.count(&mut self.report);
        // The hole passes from the start down to the bottom: one that passes through the zone
        // with its bottom outside it is not compensated and refused (its walls would be).
        let (lo, hi) = (start.min(bottom), start.max(bottom));
        let through = self
            .m
            .zone_now()
            .is_some_and(|(zl, zh)| zl <= hi && zh >= lo && !(zl..=zh).contains(&bottom));
        let Some(e) = e else {
            if through && self.m.compensable(x, y) {
                return Err(self.err(n, col, word, format!("`{word}` drills a hole of {hole} through the compensation zone, with its bottom {}{} outside it", AXES[k], self.coord(bottom)), "move the zone away, or split the hole"));
            }
            return Ok(Some(true));
        };
        if !self.m.settings.compensate_holes {
            return Err(self.err(
                n,
                col,
                word,
                format!(
                    "`{word}` drills a hole of {hole} whose bottom {}{} lies in the compensation zone, at {}{} {}{}",
                    AXES[k],
                    self.coord(bottom),
                    AXES[u],
                    self.coord(x),
                    AXES[v],
                    self.coord(y)
                ),
                &format!("pass {} to start the cycle (which drills relative to its starting position) from Z − E at each such hole, or move the zone away", words(Setting::CompensateHoles)),
            ));
        }
        let z = format!("{}{}", AXES[k], self.coord(start - e));
        let last = self
            .out
            .len()
            .checked_sub(1)
            .filter(|&i| i >= self.block_out_start);
        // The block's own positioning, when it is an `L` (M99 on it): its Z word set.
        let block = super::block::read(self.block_lines.first().map_or("", |l| l.0.as_str())).ok();
        let positioning = block
            .as_ref()
            .filter(|b| b.head == "L" && self.block_lines.len() == 1)
            .and(last);
        match (positioning, block) {
            (Some(i), Some(b)) => {
                let after = &self.out[i].after;
                let axis = AXES[k];
                let new = match b.word(axis).or_else(|| b.word(&format!("I{axis}"))) {
                    Some(w) => {
                        // The word's text in the block after the number: replaced.
                        let Some(at) = after.find(w.text.as_str()) else {
                            return Err(self.err(
                                n,
                                w.col,
                                &w.text,
                                "errmap cannot rewrite this block's Z".into(),
                                "write the Z word plainly (Z+25)",
                            ));
                        };
                        format!("{}{z}{}", &after[..at], &after[at + w.text.len()..])
                    }
                    None => {
                        // After the block's last coordinate (X/Y), else after `L`.
                        let head = after.find(&b.head).map_or(0, |h| h + b.head.len());
                        let at = b
                            .words
                            .iter()
                            .filter(|w| {
                                matches!(w.addr.as_str(), "X" | "Y" | "Z" | "IX" | "IY" | "IZ")
                            })
                            .filter_map(|w| after.find(w.text.as_str()).map(|i| i + w.text.len()))
                            .max()
                            .unwrap_or(head);
                        format!("{} {z}{}", &after[..at], &after[at..])
                    }
                };
                let grown = new.len() - after.len().min(new.len());
                self.out[i].after = new;
                self.out_bytes += grown;
            }
            _ => {
                let at = self.block_out_start.min(self.out.len());
                let line = OutLine {
                    before: String::new(),
                    number: Some(String::new()),
                    after: format!(" L {z} FMAX"),
                    term: "
"
                    .into(),
                };
                self.out_bytes += line.after.len() + 3;
                self.out.insert(at, line);
                self.block_out_start += 1;
            }
        }
        // The cycle ends back at its starting position: Z − E, the original's at Z.
        self.m.pos[k] = Some(start);
        self.m.offset = -e;
        let e_mm = e.abs() * self.m.scale_mm();
        self.report.max_abs_error_mm = self.report.max_abs_error_mm.max(e_mm);
        self.report.points_compensated += 1;
        self.report.moves_changed += 1;
        self.cut_seen = true;
        Ok(Some(true))
    }

    /// A call of a drilling cycle at the current position, when its hole can be judged:
    /// `Some(())` when handled (outside the zone, or compensated), `None` to fall back to the
    /// general rule for cycle calls.
    /// `Some(true)` when the tool is back at a known position after the cycle (cycle 1).
    pub(super) fn hole_call(&mut self, n: u64, col: usize, word: &str) -> Result<Option<bool>> {
        let Some(cycle) = self.hole_cycle.clone() else {
            return Ok(None);
        };
        // `CYCL CALL PAT` / `CYCL CALL POS X… Y… Z…` drill elsewhere than the current position.
        let upper = word.to_ascii_uppercase();
        if upper.contains("PAT") || upper.contains("POS") {
            return Ok(None);
        }
        let (u, v) = self.m.plane_uv;
        // Holes along the map's normal only, in plain work coordinates, outside label bodies
        // (a label runs with whatever definition its caller left in force).
        if self.tool_axis != self.m.normal
            || !self.frames.is_empty()
            || self.label.is_some()
            || cycle.number == 204
        {
            return Ok(None);
        }
        let (Some(x), Some(y)) = (self.m.pos[u], self.m.pos[v]) else {
            return Ok(None);
        };
        if cycle.number == 1 {
            if upper.contains("M89") {
                return Ok(None);
            }
            return self.pecking_call(n, col, word, &cycle, (x, y));
        }
        let hole = format!("cycle {} ({})", cycle.number, self.at(cycle.line));
        let (surface, depth) = match (&cycle.surface, &cycle.depth) {
            (Some(Ok(s)), Some(Ok(d))) => (*s, *d),
            (s, d) => {
                let what = [("Q203", s), ("Q201", d)]
                    .iter()
                    .find_map(|(q, v)| match v {
                        Some(Ok(_)) => None,
                        Some(Err(t)) => Some(format!("{q} is `{t}`, not a number")),
                        None => Some(format!("it has no {q}")),
                    })
                    .unwrap_or_default();
                let mut p = self.m.pos;
                p[self.m.normal] = None;
                if !self.may_touch(&[p]) {
                    return Ok(Some(false));
                }
                return Err(self.err(n, col, word, format!("`{word}` calls {hole}, which may drill in the compensation zone, and {what}: errmap cannot tell the hole's bottom"), "give Q201 and Q203 as numbers, or move the zone away"));
            }
        };
        let bottom = surface + depth;
        let mut p = [0.0; 3];
        p[u] = x;
        p[v] = y;
        p[self.m.normal] = bottom;
        let e = self.m.error_at(&p);
        self.m.kept_nominal.count(&mut self.report);
        let Some(e) = e else {
            // Outside the zone or the measured domain: the original definition drills it.
            if self.hole_surface_out.is_some() {
                self.define_again(None);
            }
            return Ok(Some(false));
        };
        if !self.m.settings.compensate_holes {
            return Err(self.err(
                n,
                col,
                word,
                format!(
                    "`{word}` drills a hole of {hole} whose bottom {}{} lies in the compensation zone, at {}{} {}{}",
                    ["X", "Y", "Z"][self.m.normal],
                    self.coord(bottom),
                    ["X", "Y", "Z"][u],
                    self.coord(x),
                    ["X", "Y", "Z"][v],
                    self.coord(y)
                ),
                &format!("pass {} to move the cycle's surface coordinate Q203 by −E at each such hole (its depth Q201 is relative to Q203), or move the zone away", words(Setting::CompensateHoles)),
            ));
        }
        let new_surface = surface - e;
        if self.hole_surface_out != Some(new_surface) {
            self.define_again(Some(new_surface));
        }
        let e_mm = e.abs() * self.m.scale_mm();
        self.report.max_abs_error_mm = self.report.max_abs_error_mm.max(e_mm);
        self.report.points_compensated += 1;
        self.report.moves_changed += 1;
        self.cut_seen = true;
        Ok(Some(false))
    }

    /// Write the drilling cycle's definition again before the current block, with Q203 set to
    /// `surface` (`None`: as the program wrote it).
    fn define_again(&mut self, surface: Option<f64>) {
        let Some(cycle) = self.hole_cycle.clone() else {
            return;
        };
        let mut lines: Vec<OutLine> = Vec::with_capacity(cycle.lines.len());
        for (i, (content, term)) in cycle.lines.iter().enumerate() {
            let mut text = content.clone();
            if let Some(s) = surface {
                text = replace_q(&text, "Q203", &self.coord(s));
            }
            let term = if term.is_empty() { "\n" } else { term }.to_string();
            if i == 0 {
                // The definition's first line gets a number of its own (renumbered).
                let code = text.trim_start();
                let digits = code.bytes().take_while(u8::is_ascii_digit).count();
                let body = code[digits..].trim_start();
                lines.push(OutLine {
                    before: String::new(),
                    number: Some(String::new()),
                    after: format!(" {body}"),
                    term,
                });
            } else {
                lines.push(OutLine {
                    before: String::new(),
                    number: None,
                    after: text,
                    term,
                });
            }
        }
        let bytes: usize = lines
            .iter()
            .map(|l| l.before.len() + l.after.len() + l.term.len() + 2)
            .sum();
        self.out_bytes += bytes;
        let at = self.block_out_start.min(self.out.len());
        self.out.splice(at..at, lines);
        self.block_out_start += cycle.lines.len();
        self.hole_surface_out = surface;
    }
}

/// `Q203=+0 ;SURFACE` with the value after `Q203=` replaced.
fn replace_q(text: &str, q: &str, value: &str) -> String {
    let upper = text.to_ascii_uppercase();
    let key = format!("{q}=");
    let Some(at) = upper.find(&key) else {
        return text.to_string();
    };
    let start = at + key.len();
    let len = text[start..]
        .find(|c: char| c.is_whitespace() || c == ';' || c == '~')
        .unwrap_or(text.len() - start);
    format!("{}{value}{}", &text[..start], &text[start + len..])
}
