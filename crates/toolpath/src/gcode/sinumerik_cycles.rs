//! Sinumerik standard drilling cycles `CYCLE81`–`CYCLE89` and `CYCLE840`, called directly or modally (`MCALL`), and the `CYCLE832` path tolerance: holes outside the zone are copied, holes whose bottom lies in it are refused or, with `--compensate-holes`, drilled with RFP and DP moved by −E at the hole.
//!
//! The parameters errmap reads (SINUMERIK 840D sl cycles, "Drilling, centering – CYCLE81" and
//! its siblings): RTP retraction plane (absolute), RFP reference plane (absolute), SDIS safety
//! distance (no sign, added to RFP), DP final drilling depth (absolute), DPR final drilling
//! depth relative to RFP (no sign). CYCLE83 also takes FDEP/FDPR, its first drilling depth,
//! absolute and relative to RFP. Everything else is relative to those or is technology.
//!
//! One modal call serves holes with different E, so a compensated hole under `MCALL` is drilled
//! by a modal call of its own: `MCALL CYCLE8x(…compensated…)` before its positioning block and
//! the program's own `MCALL CYCLE8x(…)` again after it. Both are plain modal calls, which the
//! control runs after the next block with path motion, so the positioning block drills exactly
//! the hole it drills in the original, and every later block runs under the original call.

use super::super::lexer::{Line, TokenKind};
use super::{Rewriter, AXES};
use crate::setting::Setting;
use errmap_core::error::Result;
use errmap_core::setting::words;

/// Parameter positions (0-based) common to CYCLE81–89 and CYCLE840.
const RTP: usize = 0;
const RFP: usize = 1;
const SDIS: usize = 2;
const DP: usize = 3;
const DPR: usize = 4;
/// CYCLE83: first drilling depth, absolute and relative to RFP.
const FDEP: usize = 5;
const FDPR: usize = 6;

/// One argument of a cycle call.
#[derive(Debug, Clone, PartialEq)]
enum Arg {
    /// Nothing between the commas (the cycle's default).
    Empty,
    /// A plain number.
    Num(f64),
    /// A variable, expression or string.
    Other,
}

impl Arg {
    /// Empty or zero: a relative depth or mode that is not in use.
    fn unset(&self) -> bool {
        matches!(self, Arg::Empty) || *self == Arg::Num(0.0)
    }
}

/// A standard cycle call, `CYCLE81(10, 0, 2, -5)`.
#[derive(Debug, Clone)]
pub(super) struct Call {
    /// `CYCLE81`, as errmap writes it.
    name: String,
    number: u32,
    /// Each argument's text (as written, trimmed) and what it is.
    args: Vec<(String, Arg)>,
    /// The call as written (`CYCLE81(10,0,2,-5)`), for writing the modal call again.
    text: String,
    /// The line of the `MCALL` (modal calls).
    line: u64,
}

/// The levels of one hole, program units, absolute.
struct Levels {
    rtp: f64,
    rfp: f64,
    sdis: f64,
    bottom: f64,
    /// Which absolute depths are in use and move with RFP (DP, and CYCLE83's FDEP).
    dp_moves: bool,
    fdep_moves: bool,
}

/// What a hole comes to.
enum Hole {
    Copy,
    /// Drilled with RFP and the absolute depths moved by −e.
    Write(f64),
}

/// The argument count of each cycle's classic parameter list (840D cycles manual); arguments
/// after it (the 840D sl GMODE/DMODE/AMODE forms and later additions) must be empty or 0.
fn classic_count(number: u32) -> Option<usize> {
    Some(match number {
        81 => 5,
        82 => 6,
        83 => 17,
        84 => 18,
        840 => 14,
        85 => 8,
        86 => 11,
        87 => 6,
        88 => 7,
        89 => 6,
        _ => return None,
    })
}

/// The position of the tool-axis parameter `_AXN` (0 or empty: the plane's tool axis).
fn axn_index(number: u32) -> Option<usize> {
    match number {
        83 | 84 => Some(12),
        840 => Some(11),
        _ => None,
    }
}

/// A plain Sinumerik number (digits, one point, a sign; no exponent, no name).
fn plain_number(s: &str) -> Arg {
    if s.is_empty() {
        return Arg::Empty;
    }
    let digits = s.strip_prefix(['+', '-']).unwrap_or(s);
    let plain = !digits.is_empty()
        && digits.chars().all(|c| c.is_ascii_digit() || c == '.')
        && digits.chars().filter(|&c| c == '.').count() <= 1
        && digits.chars().any(|c| c.is_ascii_digit());
    match s.parse::<f64>() {
        Ok(v) if plain && v.is_finite() => Arg::Num(v),
        _ => Arg::Other,
    }
}

/// `NAME(args)` (nothing after the closing bracket): the name upper-cased and the arguments;
/// `None` when the text is not a call of that form.
fn parse_call(text: &str, line: u64) -> Option<Call> {
    let text = text.trim();
    let open = text.find('(')?;
    let name = text[..open].trim().to_ascii_uppercase();
    let inner = text[open + 1..].strip_suffix(')')?;
    if inner.contains(['(', ')', '"', '\'']) {
        return None;
    }
    let number = name.strip_prefix("CYCLE")?.parse::<u32>().ok()?;
    let args = inner
        .split(',')
        .map(|a| (a.trim().to_string(), plain_number(a.trim())))
        .collect();
    Some(Call {
        name,
        number,
        args,
        text: text.to_string(),
        line,
    })
}

impl Call {
    fn arg(&self, i: usize) -> &Arg {
        self.args.get(i).map_or(&Arg::Empty, |a| &a.1)
    }

    fn num(&self, i: usize) -> Option<f64> {
        match self.arg(i) {
            Arg::Num(v) => Some(*v),
            _ => None,
        }
    }

    /// Whether errmap drills this cycle (CYCLE81–89, CYCLE840).
    fn drills(&self) -> bool {
        classic_count(self.number).is_some()
    }

    /// The hole's levels, or why errmap cannot know them exactly.
    fn levels(&self) -> std::result::Result<Levels, String> {
        let Some(count) = classic_count(self.number) else {
            return Err(format!(
                "errmap follows the drilling cycles CYCLE81–CYCLE89 and CYCLE840, not {}",
                self.name
            ));
        };
        if let Some((t, _)) = self.args.iter().find(|a| a.1 == Arg::Other) {
            return Err(format!(
                "its parameter `{t}` is not a plain number (run the program with {} to write variables as numbers)",
                words(Setting::Expand)
            ));
        }
        if let Some((i, (t, _))) = self
            .args
            .iter()
            .enumerate()
            .skip(count)
            .find(|(_, a)| !a.1.unset())
        {
            return Err(format!(
                "its parameter {} (`{t}`) selects a mode (840D sl GMODE/DMODE/AMODE or later) that errmap does not follow",
                i + 1
            ));
        }
        if let Some(i) = axn_index(self.number).filter(|&i| !self.arg(i).unset()) {
            return Err(format!(
                "its tool axis parameter _AXN (parameter {}) names an axis; errmap follows the plane's own tool axis only",
                i + 1
            ));
        }
        let (Some(rtp), Some(rfp)) = (self.num(RTP), self.num(RFP)) else {
            return Err("its retraction plane RTP or reference plane RFP is not given".into());
        };
        let sdis = self.num(SDIS).unwrap_or(0.0);
        let (bottom, dp_moves) = absolute_or_relative(self, DP, DPR, rfp, "DP", "DPR")?
            .ok_or_else(|| "neither DP nor DPR gives its final drilling depth".to_string())?;
        let fdep_moves = if self.number == 83 {
            absolute_or_relative(self, FDEP, FDPR, rfp, "FDEP", "FDPR")?.is_some_and(|(_, m)| m)
        } else {
            false
        };
        if !(rtp > rfp && rfp > bottom && sdis >= 0.0) {
            return Err(format!(
                "RTP {rtp}, RFP {rfp}, SDIS {sdis} and the final depth {bottom} are not a hole drilled down the tool axis (RTP above RFP above the bottom)"
            ));
        }
        Ok(Levels {
            rtp,
            rfp,
            sdis,
            bottom,
            dp_moves,
            fdep_moves,
        })
    }
}

/// A depth given absolute (`abs`) or relative to RFP (`rel`, no sign): the depth, and whether
/// the absolute value is the one in use (so it moves with RFP). A relative depth other than 0
/// wins; an absolute one given beside it must agree, since which of the two the control takes
/// is not confirmed in a manual errmap's authors had (docs/toolpath.md).
fn absolute_or_relative(
    call: &Call,
    abs: usize,
    rel: usize,
    rfp: f64,
    abs_name: &str,
    rel_name: &str,
) -> std::result::Result<Option<(f64, bool)>, String> {
    match (call.arg(abs), call.arg(rel)) {
        (a, Arg::Num(r)) if *r != 0.0 => {
            if *r < 0.0 {
                return Err(format!(
                    "{rel_name} {r} has a sign (the manual gives it without)"
                ));
            }
            let depth = rfp - r;
            match a {
                Arg::Num(d) if *d != 0.0 && (d - depth).abs() > 1e-9 => Err(format!(
                    "{abs_name} {d} and {rel_name} {r} (RFP − {rel_name} = {depth}) give different depths"
                )),
                Arg::Num(d) if *d != 0.0 => Ok(Some((depth, true))),
                _ => Ok(Some((depth, false))),
            }
        }
        (Arg::Num(d), _) => Ok(Some((*d, true))),
        _ => Ok(None),
    }
}

impl<'a> Rewriter<'a> {
    /// A Sinumerik `CYCLE…(…)` or `MCALL …` statement: `Ok(false)` when it is none errmap reads
    /// here (the caller refuses or copies it as before); `Ok(true)` when it was written.
    pub(super) fn siemens_cycle(&mut self, line: &Line, name: &str, body: &str) -> Result<bool> {
        // Words before the call on the same block (other than N) move or set modes first.
        let other_words = line.tokens.iter().any(|t| match &t.kind {
            TokenKind::Word { letter, .. } => *letter != b'N',
            _ => false,
        });
        if name == "MCALL" {
            let rest = body.trim()[5.min(body.trim().len())..].trim();
            if rest.is_empty() {
                // The modal call ends. No return step can be due: a hole leaves the tool at RTP
                // and errmap refuses to rewrite a block under a modal call.
                self.mcall = None;
                self.copy_line(line);
                return Ok(true);
            }
            let Some(call) = parse_call(rest, line.number).filter(Call::drills) else {
                return Ok(false);
            };
            if other_words {
                return Err(self.err(
                    line,
                    name,
                    format!("`{}`: MCALL with other words on its block", body.trim()),
                    "write MCALL in a block of its own",
                ));
            }
            self.return_if_needed(line, &[], true)?;
            self.mcall = Some(call);
            self.copy_line(line);
            return Ok(true);
        }
        let Some(call) = parse_call(body, line.number) else {
            return Ok(false);
        };
        if call.number == 832 && !other_words {
            // The path tolerance of CYCLE832: copied, noted in the report when larger than E.
            self.path_tolerance(&call, line.number);
            self.copy_line(line);
            return Ok(true);
        }
        if call.number == 800 {
            return Err(self.err(
                line,
                "CYCLE800",
                format!("`{}`: CYCLE800 swivels the working plane or aligns the tool (5-axis swivel cycle), which errmap does not follow", body.trim()),
                "errmap compensates 3-axis cuts in an untilted working plane: post the cuts in the zone without CYCLE800, or move the zone away",
            ));
        }
        if !call.drills() {
            return Ok(false);
        }
        if other_words {
            // errmap does not split the block's own move from the hole drilled after it.
            let at = [None; 3];
            self.judge_hole(line, &call, at)?;
            self.return_if_needed(line, &[], true)?;
            self.copy_line(line);
            self.m.forget_position(line.number);
            return Ok(true);
        }
        self.return_if_needed(line, &[], true)?;
        let at = self.m.pos;
        let start = self.out.len();
        self.copy_line(line);
        self.drill(line, &call, at, start, false)?;
        Ok(true)
    }

    /// Under `MCALL`, a block with path motion drills the modal cycle at its end point: the
    /// block must be written as it stands (an inserted or split block would drill too), and a
    /// compensated hole gets a modal call of its own around it. `start`: where the block's
    /// output begins in `out`.
    pub(super) fn modal_hole(&mut self, line: &Line, start: usize) -> Result<()> {
        let Some(call) = self.mcall.clone() else {
            return Ok(());
        };
        let original = &self.text[line.span.start..line.end];
        if self.out.get(start..) != Some(original) {
            return Err(self.err(
                line,
                &call.name,
                format!("under `MCALL {}` (line {}) every block with path motion drills a hole (the canned cycle runs after it), and errmap would write this block as other blocks (a compensated cut or a return to the original path)", call.text, call.line),
                "end the modal call (MCALL) before the cuts in the compensation zone, or move the zone away",
            ));
        }
        let at = self.m.pos;
        self.drill(line, &call, at, start, true)
    }

    /// A block (with a group-0 code or a frame) under `MCALL` whose end point errmap does not
    /// know: refused when the hole may touch the zone.
    pub(super) fn modal_hole_unknown(&mut self, line: &Line) -> Result<()> {
        if let Some(call) = self.mcall.clone() {
            self.judge_hole(line, &call, [None; 3])?;
        }
        Ok(())
    }

    /// Drill `call` at `at` (the block's output already in `out` from `start`): copied, or
    /// written with the hole's own levels; the tool is left at RTP.
    fn drill(
        &mut self,
        line: &Line,
        call: &Call,
        at: [Option<f64>; 3],
        start: usize,
        modal: bool,
    ) -> Result<()> {
        let hole = self.judge_hole(line, call, at)?;
        let levels = call.levels().ok();
        if let (Hole::Write(e), Some(l)) = (&hole, &levels) {
            let written = self.call_text(call, l, *e);
            let eol = super::line_terminator(self.text, line);
            if modal {
                let before = format!("MCALL {written}{eol}");
                self.out.insert_str(start, &before);
                self.out.push_str(&format!("MCALL {}{eol}", call.text));
            } else {
                let orig = &self.text[line.span.start..line.end];
                let replaced = orig.replacen(&call.text, &written, 1);
                self.out.truncate(start);
                self.out.push_str(&replaced);
            }
            self.report.moves_changed += 1;
            self.report.points_compensated += 1;
            let e_mm = e.abs() * self.m.scale_mm();
            self.report.max_abs_error_mm = self.report.max_abs_error_mm.max(e_mm);
        }
        // The cycle ends at RTP above the hole.
        let n = self.m.normal;
        match (levels, at[self.m.plane_uv.0], at[self.m.plane_uv.1]) {
            (Some(l), Some(_), Some(_)) if self.plane.axes().2 == n => {
                self.m.pos = at;
                self.m.pos[n] = Some(l.rtp);
                self.m.offset = 0.0;
            }
            _ => self.m.forget_position(line.number),
        }
        Ok(())
    }

    /// Copy the hole, drill it compensated, or refuse it.
    fn judge_hole(&self, line: &Line, call: &Call, at: [Option<f64>; 3]) -> Result<Hole> {
        let name = call.name.clone();
        let (a1, a2, ax) = self.plane.axes();
        let levels = call.levels();
        // The tool's path: from where it stands over the hole, down to the bottom, up to RTP.
        let mut path = vec![at];
        match &levels {
            Ok(l) => {
                for z in [l.rfp + l.sdis, l.bottom, l.rtp] {
                    let mut p = at;
                    p[ax] = Some(z);
                    path.push(p);
                }
            }
            Err(_) => {
                let mut p = at;
                p[ax] = None;
                path.push(p);
            }
        }
        if !self.may_touch(&path) {
            return Ok(Hole::Copy);
        }
        let refuse = |why: String, hint: &str| {
            Err(self.err(
                line,
                &name,
                format!(
                    "canned cycle {name} in the compensation zone cannot be compensated: {why}"
                ),
                hint,
            ))
        };
        let expand = "expand the cycle into G0/G1 moves with your CAM post, or move the zone away";
        let l = match levels {
            Ok(l) => l,
            Err(why) => return refuse(why, expand),
        };
        if !self.absolute {
            return refuse(
                "under G91 (incremental) errmap does not follow a cycle's holes".into(),
                expand,
            );
        }
        if ax != self.m.normal {
            return refuse(
                format!(
                    "it drills along {} but the map's normal axis is {}",
                    AXES[ax] as char, AXES[self.m.normal] as char
                ),
                "drill along the map's normal (G17 for a Z map), or expand the cycle into G0/G1 moves, or move the zone away",
            );
        }
        let known = self.frames.is_empty()
            && self.flow.is_none()
            && self.blocks.is_empty()
            && self.m.units_known
            && at[a1].is_some()
            && at[a2].is_some();
        if !known {
            return refuse("the hole's position is not known to errmap (a frame, a jump, unknown units, or no X/Y since the position was lost)".into(), expand);
        }
        let mut b = [0.0; 3];
        b[a1] = at[a1].unwrap_or(0.0);
        b[a2] = at[a2].unwrap_or(0.0);
        b[ax] = l.bottom;
        let (u, v) = self.m.plane_uv;
        if !self.m.compensable(b[u], b[v]) {
            return Ok(Hole::Copy);
        }
        let zone = self.m.zone_now();
        if let Some((lo, hi)) = zone.filter(|(lo, hi)| l.bottom < *lo || l.bottom > *hi) {
            if l.rfp.min(l.bottom) <= hi && l.rfp.max(l.bottom) >= lo {
                return refuse(
                    format!("the hole passes through the compensation zone but its bottom ({}{}) lies outside it, so errmap has no depth to move", AXES[ax] as char, l.bottom),
                    "expand the cycle into G0/G1 moves, or set the zone to hold the hole bottoms, or move it away",
                );
            }
            return Ok(Hole::Copy);
        }
        if zone.is_some_and(|(lo, hi)| l.rtp >= lo && l.rtp <= hi) {
            return refuse(
                format!("its retraction plane RTP {} lies in the compensation zone, and errmap does not move the plane the tool retracts to", l.rtp),
                "set RTP above the zone, or move the zone away",
            );
        }
        if !self.m.settings.compensate_holes {
            return Err(self.err(
                line,
                &name,
                format!("canned cycle {name}: the hole at {}{} {}{} ends at {}{} in the compensation zone; errmap moves a hole's RFP and DP by −E only when asked", AXES[a1] as char, b[a1], AXES[a2] as char, b[a2], AXES[ax] as char, l.bottom),
                &format!("pass {} (job key [toolpaths] compensate_holes) to move each hole's RFP and DP by −E at its position, or expand the cycle into G0/G1 moves, or move the zone away", words(Setting::CompensateHoles)),
            ));
        }
        Ok(match self.m.error_at(&b) {
            Some(e) => Hole::Write(e),
            None => Hole::Copy,
        })
    }

    /// The call with RFP and the absolute depths in use moved by −e; other arguments as written.
    fn call_text(&self, call: &Call, l: &Levels, e: f64) -> String {
        let mut args: Vec<String> = call.args.iter().map(|a| a.0.clone()).collect();
        let mut set = |i: usize, v: f64| {
            let mut s = String::new();
            self.push_coord(&mut s, v);
            if let Some(a) = args.get_mut(i) {
                *a = s;
            }
        };
        set(RFP, l.rfp - e);
        if l.dp_moves {
            set(DP, l.bottom - e);
        }
        if l.fdep_moves {
            if let Some(f) = call.num(FDEP) {
                set(FDEP, f - e);
            }
        }
        format!("{}({})", call.name, args.join(", "))
    }

    /// `CYCLE832(tolerance, …)`: the largest tolerance of the program, for the report's note.
    fn path_tolerance(&mut self, call: &Call, line: u64) {
        if let Some(t) = call.num(0).filter(|t| *t > 0.0) {
            let mm = t * self.m.scale_mm();
            if self.path_tolerance_mm.is_none_or(|(old, _)| mm > old) {
                self.path_tolerance_mm = Some((mm, line));
            }
        }
    }

    /// The report's note when the program's CYCLE832 tolerance exceeds the largest |E| applied.
    pub(super) fn tolerance_note(&mut self) {
        let applied = self.report.max_abs_error_mm;
        if let Some((t, line)) = self.path_tolerance_mm {
            if applied > 0.0 && t > applied {
                self.report.notes.push(format!(
                    "CYCLE832 tolerance {t} mm (line {line}) is larger than the largest |E| applied ({applied:.4} mm): the control may smooth the path by up to the tolerance, which can swallow the compensation; set a tolerance smaller than |E| for the finishing cuts"
                ));
            }
        }
    }
}
