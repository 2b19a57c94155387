//! The Klartext rewriter: a compensated cut written as `L` blocks to P' = P − E (points on the original line or arc, split at the zone and domain edges), and the return along the normal before a block that starts from the original position.

use super::super::gcode::{dist, emit_curve, lerp, Breaks};
use super::block::{Block, Word};
use super::interp::{known, PathMove};
use super::{Kt, OutLine};
use crate::setting::Setting;
use errmap_core::error::Result;
use errmap_core::setting::words;

const AXES: [&str; 3] = ["X", "Y", "Z"];

/// A cut's known start and end (program units) and how many pieces it needs.
pub(super) type BoundedCut = ([f64; 3], [f64; 3], usize);

/// The fewest bytes a written piece takes: `L X0.0000 Y0.0000 Z0.0000` and a newline (every
/// piece writes the three axes with at least four decimals).
const MIN_PIECE_BYTES: u64 = 26;

/// M functions that act at the end of their block: they go with the last piece.
const M_END: [f64; 7] = [0.0, 1.0, 2.0, 5.0, 6.0, 9.0, 30.0];

impl Kt<'_> {
    /// A cut's start, end and piece count when both ends are known (`None`: copy it unchanged), refused when it
    /// would need a million pieces or more: lines cut every `max_segment`, arcs also at
    /// `chord_tol` (infinite under radius compensation, where only length and quarter turns
    /// cut them). The refusal's hint says to raise `raise`.
    pub(super) fn bounded_ends(
        &self,
        n: u64,
        b: &Block,
        mv: &PathMove,
        chord_tol: f64,
        raise: &[Setting],
    ) -> Result<Option<BoundedCut>> {
        let (Some(s), Some(e)) = (known(mv.start), known(mv.end)) else {
            return Ok(None);
        };
        let step = self.m.step();
        let (length, pieces) = match &mv.arc {
            None => (dist(&s, &e), 1),
            Some(a) => (
                a.sweep.abs() * a.r_start.max(a.r_end),
                a.chords(chord_tol, step),
            ),
        };
        if !length.is_finite() || length / step > 1e6 || pieces >= 1_000_000 {
            return Err(self.err(
                n,
                b.head_col,
                &b.head,
                format!("this move ({length:.6e} program units) would need more than a million segments"),
                &format!(
                    "check the coordinates and units, or raise {}",
                    raise.iter().map(|s| words(*s)).collect::<Vec<_>>().join(" / ")
                ),
            ));
        }
        Ok(Some((s, e, pieces)))
    }

    /// Compensate a cut whose start is known and which nothing forbids: its points every
    /// `max_segment` (arcs within the chord tolerance) and at the zone and domain edges.
    pub(super) fn compensate_path(
        &mut self,
        n: u64,
        content: &str,
        term: &str,
        b: &Block,
        mv: &PathMove,
    ) -> Result<()> {
        let Some((s, e, chords)) = self.bounded_ends(
            n,
            b,
            mv,
            self.m.chord_tol(),
            &[Setting::MaxSegment, Setting::ChordTol],
        )?
        else {
            return self.unchanged(n, content, term, b, false);
        };
        let step = self.m.step();
        let mut emitted = Vec::new();
        {
            let curve = |t: f64| match &mv.arc {
                None => lerp(&s, &e, t),
                Some(a) => a.point(t),
            };
            let error_at = |p: &[f64; 3]| self.m.error_at(p);
            // Each piece is an `L X… Y… Z…` block of at least MIN_PIECE_BYTES: stop as soon as
            // the pieces outnumber what the output limit has room for.
            let limit = errmap_core::io::safety::max_output_bytes();
            let room = limit.saturating_sub(self.out_bytes as u64) / MIN_PIECE_BYTES;
            let complete = emit_curve(
                Breaks::Fractions(chords),
                &curve,
                step,
                self.m.zone_now(),
                self.m.normal,
                &error_at,
                usize::try_from(room).unwrap_or(usize::MAX),
                &mut emitted,
            );
            if !complete {
                return Err(self.err(
                    n,
                    b.head_col,
                    &b.head,
                    format!(
                        "this move is cut into more pieces than the output limit of {} MB has room for (at least {MIN_PIECE_BYTES} bytes each)",
                        limit / 1_000_000
                    ),
                    &format!(
                        "check the move's length, raise {} / {}, or raise {}",
                        words(Setting::MaxSegment),
                        words(Setting::ChordTol),
                        words(errmap_core::core_setting::Setting::MaxOutputMb)
                    ),
                ));
            }
        }
        self.m.kept_nominal.count(&mut self.report);
        if !emitted.iter().any(|(_, e)| e.is_some()) {
            let absolute = b.head == "L" && b.word(AXES[self.m.normal]).is_some();
            return self.unchanged(n, content, term, b, absolute);
        }
        self.write_pieces(content, term, b, &emitted);
        Ok(())
    }

    /// The pieces as `L X… Y… Z…` blocks (absolute): the first keeps the block's feed, radius
    /// and start M words and its comment; the last takes the M words that act at block end.
    fn write_pieces(
        &mut self,
        content: &str,
        term: &str,
        b: &Block,
        emitted: &[([f64; 3], Option<f64>)],
    ) {
        let targets = self.targets(emitted);
        let bodies = self.bodies(b, &targets);
        let span = b.number_span.clone();
        let pieces = bodies.len();
        for (i, body) in bodies.into_iter().enumerate() {
            let after = if i == 0 {
                format!("{body}{}", b.comment)
            } else {
                body
            };
            let t = match (i + 1 == pieces, term.is_empty()) {
                (false, true) => "\n",
                _ => term,
            };
            let (before, number) = if i == 0 {
                (
                    content[..span.start].to_string(),
                    content[span.clone()].to_string(),
                )
            } else {
                (String::new(), String::new())
            };
            self.push(OutLine {
                before,
                number: Some(number),
                after,
                term: t.to_string(),
            });
        }
        self.report.moves_changed += 1;
        if targets.len() > 1 {
            self.report.moves_split += 1;
        }
        self.report.segments_emitted += targets.len() as u64;
        self.m.offset = emitted.last().and_then(|(_, e)| *e).map_or(0.0, |e| -e);
    }

    /// The targets P' = P − E of the emitted points, leaving out those that round onto the
    /// position before them (no zero-length moves); counts the compensated points.
    fn targets(&mut self, emitted: &[([f64; 3], Option<f64>)]) -> Vec<[f64; 3]> {
        let mut out_pos = self.m.pos.map(|c| c.unwrap_or(0.0));
        out_pos[self.m.normal] += self.m.offset;
        let d = self.decimals;
        let written = |v: f64| {
            let p = 10f64.powi(d as i32);
            (v * p).round() / p
        };
        let mut targets: Vec<[f64; 3]> = Vec::new();
        let mut last = out_pos.map(written);
        for (p, e) in emitted {
            let mut q = *p;
            if let Some(e) = e {
                q[self.m.normal] -= e;
                let e_mm = e.abs() * self.m.scale_mm();
                self.report.max_abs_error_mm = self.report.max_abs_error_mm.max(e_mm);
                self.report.points_compensated += 1;
            }
            let w = q.map(written);
            if w != last {
                targets.push(q);
                last = w;
            }
        }
        targets
    }

    /// The text of each piece after its block number; none when every target rounds onto the
    /// current position and the block has no other words.
    fn bodies(&self, b: &Block, targets: &[[f64; 3]]) -> Vec<String> {
        let end_m = |w: &Word| w.addr == "M" && w.num().is_some_and(|m| M_END.contains(&m));
        let replaced = |w: &Word| {
            let coordinate = matches!(
                w.addr.as_str(),
                "X" | "Y" | "Z" | "IX" | "IY" | "IZ" | "DR" | "PA" | "IPA" | "PR" | "IPR"
            );
            let radius = b.head == "CR" && w.addr == "R";
            coordinate || radius || end_m(w)
        };
        let keep = |w: &&Word| !replaced(w);
        let first_words: Vec<&str> = b
            .words
            .iter()
            .filter(keep)
            .map(|w| w.text.as_str())
            .collect();
        let end_words: Vec<&str> = b
            .words
            .iter()
            .filter(|w| end_m(w))
            .map(|w| w.text.as_str())
            .collect();
        let count = targets.len().max(1);
        let mut bodies: Vec<String> = Vec::with_capacity(count);
        for i in 0..count {
            let mut body = String::from(" L");
            if let Some(q) = targets.get(i) {
                for (k, a) in AXES.iter().enumerate() {
                    body.push(' ');
                    body.push_str(a);
                    body.push_str(&self.coord(q[k]));
                }
            }
            let words = (if i == 0 { &first_words[..] } else { &[] })
                .iter()
                .chain(if i + 1 == count { &end_words[..] } else { &[] });
            for w in words {
                body.push(' ');
                body.push_str(w);
            }
            bodies.push(body);
        }
        if targets.is_empty() && bodies[0] == " L" {
            bodies.clear();
        }
        bodies
    }

    /// `L Z…` (`FMAX` before a rapid) back to the original normal coordinate after a cut that ended compensated.
    pub(super) fn return_step(&mut self, term: &str, rapid: bool) {
        let Some(orig) = self.m.pos[self.m.normal] else {
            return;
        };
        let fmax = if rapid { " FMAX" } else { "" };
        let body = format!(" L {}{}{fmax}", AXES[self.m.normal], self.coord(orig));
        self.push_block(body, term);
        self.m.offset = 0.0;
        self.report.returns_inserted += 1;
    }
}
