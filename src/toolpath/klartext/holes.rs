//! Drilling cycles 200–209 of Klartext at a cycle call (`CYCL CALL`, `M99`, after `M89`): a hole whose bottom (surface Q203 + depth Q201) lies in the zone is refused, or with `--compensate-holes` drilled from a surface moved by −E: the cycle is defined again before the call with Q203 − E (the depth Q201 and the clearances are relative to Q203), and the original definition is restored before a later call outside the zone.

use super::block::Block;
use super::{Kt, OutLine};
use crate::error::Result;

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
        self.hole_cycle = (200..=209).contains(&major).then(|| HoleCycle {
            number: major,
            line: n,
            depth: q_value(&b.rest, "Q201"),
            surface: q_value(&b.rest, "Q203"),
            lines: self.block_lines.clone(),
        });
        self.hole_surface_out = None;
    }

    /// A call of a drilling cycle at the current position, when its hole can be judged:
    /// `Some(())` when handled (outside the zone, or compensated), `None` to fall back to the
    /// general rule for cycle calls.
    pub(super) fn hole_call(&mut self, n: u64, col: usize, word: &str) -> Result<Option<()>> {
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
                    return Ok(Some(()));
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
        if self.m.extrapolated.replace(false) {
            self.report.moves_outside_domain += 1;
        }
        let Some(e) = e else {
            // Outside the zone or the measured domain: the original definition drills it.
            if self.hole_surface_out.is_some() {
                self.define_again(None);
            }
            return Ok(Some(()));
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
                "pass --compensate-holes to move the cycle's surface coordinate Q203 by −E at each such hole (its depth Q201 is relative to Q203), or move the zone away",
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
        Ok(Some(()))
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
