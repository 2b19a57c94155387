//! Drilling canned cycles (G73, G81–G89; G98/G99; G80): where each hole leaves the tool, and with `--compensate-holes` a hole whose bottom lies in the zone gets its depth and R level moved by −E at its own position, written on every later hole block of the series.
//!
//! A cycle's Z (depth) and R (reference level) are modal within the cycle: a later block with
//! only X/Y drills another hole to the same levels (LinuxCNC: "sticky" while the motion mode is
//! the same cycle; Fanuc: kept until G80). Once one hole of a series is written with its own Z
//! and R, every later hole is too, so that none inherits another hole's compensated levels.

use super::super::dialect::{Dialect, GCode};
use super::super::lexer::{Line, TokenKind};
use super::{Rewriter, AXES, W};
use crate::setting::Setting;
use errmap_core::error::Result;

/// A series of canned cycles (from the first cycle block to G80 or another motion mode).
#[derive(Debug, Clone)]
pub(super) struct Cycle {
    code: GCode,
    /// The tool-axis coordinate before the series (G98's retract level), program units.
    initial: Option<f64>,
    /// Modal depth and R level (absolute, program units), when known.
    depth: Option<f64>,
    r: Option<f64>,
    /// A hole of the series was written with its own Z and R.
    rewritten: bool,
}

impl Cycle {
    /// A block errmap does not follow changed the cycle (block delete): its levels are unknown.
    pub(super) fn forget_levels(&mut self) {
        self.depth = None;
        self.r = None;
    }
}

/// What a hole block comes to.
enum Hole {
    /// Copied byte for byte.
    Copy,
    /// Written with these depth and R values (E at the hole applied, or not).
    Write { depth: f64, r: f64, e: Option<f64> },
}

impl<'a> Rewriter<'a> {
    /// Retract modes: G98 (initial level) and G99 (R level) in LinuxCNC and Fanuc.
    pub(super) fn retract_mode(&mut self, words: &[W]) {
        if !matches!(self.dialect, Dialect::Linuxcnc | Dialect::Fanuc) {
            return;
        }
        for (code, _) in words.iter().filter_map(|w| w.g) {
            match (code.number, code.decimal) {
                (98, 0) => self.retract_to_r = Some(false),
                (99, 0) => self.retract_to_r = Some(true),
                _ => {}
            }
        }
    }

    /// A block under a canned cycle: refused, copied or written, and the position after it.
    pub(super) fn canned(
        &mut self,
        line: &Line,
        words: &[W],
        start: [Option<f64>; 3],
        end: [Option<f64>; 3],
    ) -> Result<()> {
        let (a1, a2, ax) = self.plane.axes();
        let code = self.motion.map_or(GCode::whole(81), |m| m.code);
        let first = self.cycle.is_none();
        let mut cyc = self.cycle.take().unwrap_or(Cycle {
            code,
            initial: start[ax],
            depth: None,
            r: None,
            rewritten: false,
        });
        if cyc.code != code {
            // Another cycle: its levels are its own.
            cyc.code = code;
            cyc.depth = None;
            cyc.r = None;
        }
        let find = |l: u8| words.iter().find(|w| w.letter == l);
        let value = |w: Option<&W>, old: Option<f64>| match w {
            None => old,
            Some(w) if self.absolute && w.abs != Some(false) && !w.is_expr => w.value,
            Some(_) => None,
        };
        cyc.depth = value(find(AXES[ax]), cyc.depth);
        cyc.r = value(find(b'R'), cyc.r);
        // The hole: down from the R level to its depth at (x, y).
        let mut top = end;
        top[ax] = cyc.r;
        let mut bottom = end;
        bottom[ax] = cyc.depth;
        let mut over = end;
        over[ax] = start[ax];
        let touches = self.may_touch(&[start, over, top, bottom]);
        // K0 (Fanuc) or L0: the cycle's data is stored, no hole is drilled (and whether the
        // block positions X/Y differs between controls): copied, the position unknown.
        let stores_only = words
            .iter()
            .any(|w| matches!(w.letter, b'K' | b'L') && w.value == Some(0.0));
        if stores_only {
            if first {
                self.return_if_needed(line, words, false)?;
            }
            self.copy_line(line);
            self.out_motion = self.motion;
            self.m.forget_position(line.number);
            self.cycle = Some(cyc);
            return Ok(());
        }
        let hole = self.hole(line, words, &cyc, touches, bottom)?;
        if first {
            self.return_if_needed(line, words, false)?;
        }
        match hole {
            Hole::Copy => self.copy_line(line),
            Hole::Write { depth, r, e } => {
                self.write_hole(line, ax, depth, r);
                cyc.rewritten = true;
                self.report.moves_changed += 1;
                if let Some(e) = e {
                    self.report.points_compensated += 1;
                    let e_mm = e.abs() * self.m.scale_mm();
                    self.report.max_abs_error_mm = self.report.max_abs_error_mm.max(e_mm);
                }
            }
        }
        self.out_motion = self.motion;
        // Where the hole leaves the tool: G99 at R, G98 at the initial level (when above R).
        let level = match (self.retract_to_r, cyc.r, cyc.initial) {
            (Some(true), Some(r), _) => Some(r),
            (Some(false), Some(r), Some(i)) if i >= r => Some(i),
            _ => None,
        };
        let mut after = end;
        after[ax] = if self.absolute { level } else { None };
        if after[a1].is_none() || after[a2].is_none() || after[ax].is_none() {
            self.m.unknown_since = Some(line.number);
        }
        let e_here = match &hole {
            Hole::Write { e: Some(e), .. } if self.retract_to_r == Some(true) => *e,
            _ => 0.0,
        };
        self.m.offset = -e_here;
        self.m.pos = after;
        self.cycle = Some(cyc);
        Ok(())
    }

    /// Decide a hole: copy it, write it with its own levels, or refuse it.
    fn hole(
        &self,
        line: &Line,
        words: &[W],
        cyc: &Cycle,
        touches: bool,
        bottom: [Option<f64>; 3],
    ) -> Result<Hole> {
        let name = cyc.code.to_string();
        let drills = matches!(cyc.code.number, 73 | 81..=89) && cyc.code.decimal == 0;
        let known = |p: [Option<f64>; 3]| Some([p[0]?, p[1]?, p[2]?]);
        let plain = self.absolute
            && drills
            && self.frames.is_empty()
            && self.flow.is_none()
            && self.blocks.is_empty()
            && self.m.units_known
            && !words.iter().any(|w| w.is_expr);
        let levels = match (known(bottom), cyc.r) {
            (Some(b), Some(r)) if plain => Some((b, r)),
            _ => None,
        };
        let Some((b, r)) = levels else {
            if !touches {
                return Ok(Hole::Copy);
            }
            let why = if !self.absolute {
                "under G91 (incremental) errmap does not follow a cycle's holes".to_string()
            } else if !drills {
                format!("errmap follows the drilling cycles G73 and G81–G89, not {name}")
            } else {
                "its position, depth or R level is not known to errmap (a frame, a loop, an expression, or no Z/R since the cycle began)".to_string()
            };
            return Err(self.err(
                line,
                &name,
                format!(
                    "canned cycle {name} in the compensation zone cannot be compensated: {why}"
                ),
                "expand the cycle into G0/G1 moves with your CAM post (or move the zone away)",
            ));
        };
        let (_, _, ax) = self.plane.axes();
        if ax != self.m.normal {
            if !touches {
                return Ok(Hole::Copy);
            }
            return Err(self.err(
                line,
                &name,
                format!("canned cycle {name} drills along {} but the map's normal axis is {}", AXES[ax] as char, AXES[self.m.normal] as char),
                "drill along the map's normal (G17 for a Z map), or expand the cycle into G0/G1 moves, or move the zone away",
            ));
        }
        let (n, (u, v)) = (self.m.normal, self.m.plane_uv);
        let depth = b[n];
        // A hole outside the measured domain or the zone keeps its levels (written out again
        // once the series has been rewritten).
        let keep = if cyc.rewritten {
            Hole::Write { depth, r, e: None }
        } else {
            Hole::Copy
        };
        if !self.m.compensable(b[u], b[v]) {
            return Ok(keep);
        }
        if let Some((lo, hi)) = self
            .m
            .zone_now()
            .filter(|(lo, hi)| depth < *lo || depth > *hi)
        {
            if r.min(depth) <= hi && r.max(depth) >= lo {
                return Err(self.err(
                    line,
                    &name,
                    format!("canned cycle {name}: the hole passes through the compensation zone but its bottom ({}{depth}) lies outside it, so errmap has no depth to move", AXES[n] as char),
                    "expand the cycle into G0/G1 moves, or set the zone to hold the hole bottoms, or move it away",
                ));
            }
            return Ok(keep);
        }
        if !self.m.settings.compensate_holes {
            return Err(self.err(
                line,
                &name,
                format!("canned cycle {name}: the hole at {}{} {}{} ends at {}{depth} in the compensation zone; errmap moves a hole's depth and R level by −E only when asked", AXES[u] as char, b[u], AXES[v] as char, b[v], AXES[n] as char),
                &format!("pass {} (job key [toolpaths] compensate_holes) to move each hole's Z and R by −E at its position, or expand the cycle into G0/G1 moves, or move the zone away", errmap_core::setting::words(Setting::CompensateHoles)),
            ));
        }
        Ok(match self.m.error_at(&b) {
            Some(e) => Hole::Write {
                depth: depth - e,
                r: r - e,
                e: Some(e),
            },
            None => keep,
        })
    }

    /// The hole block with its depth and R words set (replaced in place, or appended after its
    /// last word).
    fn write_hole(&mut self, line: &Line, ax: usize, depth: f64, r: f64) {
        let text = self.text;
        let mut z_text = String::from(AXES[ax] as char);
        self.push_coord(&mut z_text, depth);
        let mut r_text = String::from("R");
        self.push_coord(&mut r_text, r);
        let (mut z_done, mut r_done) = (false, false);
        let last_word = line
            .tokens
            .iter()
            .rposition(|t| matches!(t.kind, TokenKind::Word { .. }));
        let mut out = String::with_capacity(line.end - line.span.start + 24);
        for (i, t) in line.tokens.iter().enumerate() {
            match &t.kind {
                TokenKind::Word { letter, .. } if *letter == AXES[ax] && !z_done => {
                    out.push_str(&z_text);
                    z_done = true;
                }
                TokenKind::Word { letter: b'R', .. } if !r_done => {
                    out.push_str(&r_text);
                    r_done = true;
                }
                _ => out.push_str(text.get(t.span.clone()).unwrap_or("")),
            }
            if Some(i) == last_word {
                if !z_done {
                    out.push(' ');
                    out.push_str(&z_text);
                    z_done = true;
                }
                if !r_done {
                    out.push(' ');
                    out.push_str(&r_text);
                    r_done = true;
                }
            }
        }
        let end_of_tokens = line.tokens.last().map_or(line.span.start, |t| t.span.end);
        out.push_str(&text[end_of_tokens.max(line.span.start)..line.end]);
        self.out.push_str(&out);
    }
}
