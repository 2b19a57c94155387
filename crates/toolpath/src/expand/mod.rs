//! `--expand`: run a program's subprograms, loops and parameters as its controller would, into a straight-line program of the same dialect with plain numbers, each output line mapped to its source line and call chain.
//!
//! The flattened program is compensated by the ordinary rewrite; a refusal there is mapped back
//! to the original file:line (and the calls that led to it). Anything whose value is known only
//! on the machine (system variables, positions, offsets, probing, operator input, another file)
//! is refused naming it. Work is bounded: the flattened text by `--max-output-mb`, loops by
//! [`MAX_ITERATIONS`]. See docs/toolpath.md, "Subprograms, loops and parameters (--expand)".

pub(crate) mod eval;
mod fanuc;
mod klartext;
mod linuxcnc;
mod sinumerik;

use super::dialect::Dialect;
use crate::setting::Setting;
use errmap_core::error::{Error, Location, Result};
use errmap_core::setting::words;
use std::path::Path;

/// Most backward jumps (loop turns, repeats, jumps back) one program may make; more is taken
/// for an endless loop and refused naming the loop's line. A million is far more than a real
/// program's loops turn (a 1 m pocket at 0.01 mm steps is 100 000), and refusing an endless
/// loop stays well under a second.
pub(crate) const MAX_ITERATIONS: u64 = 1_000_000;

/// The smaller budget of a trial run made without `--expand`, only to decide whether a
/// refusal's hint may offer the flag: loop turns and flattened bytes. Past it the trial stops
/// (the flag is offered; the full run decides).
const TRIAL_ITERATIONS: u64 = 100_000;
const TRIAL_BYTES: u64 = 8_000_000;

/// The message of the error that stops a trial run at its budget (never shown).
const TRIAL_STOP: &str = "expand trial budget reached";

/// Deepest nesting of calls followed (controllers allow fewer: Fanuc 4 macro levels).
pub(crate) const MAX_CALL_DEPTH: usize = 16;

/// The end of the Klartext rewriter's refusal of a Q word on a cut, replaced by why the run
/// does not know the value.
const Q_UNKNOWN: &str = "errmap does not compute Q parameters";

/// The hint given where the ordinary rewrite refuses control flow that the expanding run
/// ([`Setting::Expand`]) can run.
pub(crate) fn hint() -> String {
    format!(
        "pass {} to run the program's subprograms, loops and parameters as the controller would and compensate the flattened program (job key [toolpaths] expand), or move the zone away",
        expand_words()
    )
}

/// The words for the expanding run ([`Setting::Expand`]) in messages that say what it runs.
pub(crate) fn expand_words() -> String {
    words(Setting::Expand)
}

/// A straight-line program and, for each of its lines, where it came from.
#[derive(Debug, Default)]
pub(crate) struct Flat {
    pub text: String,
    /// A trial run (smaller budget, see [`TRIAL_ITERATIONS`]).
    trial: bool,
    /// Per output line: the source line (1-based) and its call chain (index into `chains`).
    origin: Vec<(u64, u32)>,
    /// Call chains: (parent chain, line of the call, what was called). Chain 0 is the top level.
    chains: Vec<(u32, u64, String)>,
    /// A refusal that stopped the run (Klartext): reported when the blocks before it compensate.
    pub pending: Option<Error>,
    /// Klartext: the output line of each output block number, and each source line's block
    /// number, so `block N` in a message names the original block.
    blocks: Vec<u64>,
    source_blocks: Vec<Option<u64>>,
    /// Klartext: why a Q word left in an output line (by line) has no value errmap knows.
    why: std::collections::HashMap<u64, String>,
}

impl Flat {
    fn new(capacity: usize, trial: bool) -> Flat {
        Flat {
            trial,
            text: String::with_capacity(capacity),
            origin: Vec::new(),
            chains: vec![(0, 0, String::new())],
            ..Flat::default()
        }
    }

    /// A new call chain: `called` run from `line` under `parent`.
    fn chain(&mut self, parent: u32, line: u64, called: String) -> u32 {
        self.chains.push((parent, line, called));
        (self.chains.len() - 1) as u32
    }

    /// Append one line from source line `line`; refused past `--max-output-mb`.
    fn push(&mut self, source: &Path, line: u64, chain: u32, text: &str) -> Result<()> {
        self.text.push_str(text);
        self.text.push('\n');
        self.origin.push((line, chain));
        let limit = errmap_core::io::safety::max_output_bytes();
        if self.trial && self.text.len() as u64 > TRIAL_BYTES.min(limit) {
            return Err(Error::Internal(TRIAL_STOP.into()));
        }
        if self.text.len() as u64 > limit {
            return Err(Error::input(
                Location::line(source, line),
                format!(
                    "the program, run with its loops and subprograms, would exceed the output limit of {} MB by this line{}",
                    limit / 1_000_000,
                    self.calls(chain)
                ),
                format!("check the loop counts, or raise {}", words(errmap_core::core_setting::Setting::MaxOutputMb)),
            ));
        }
        Ok(())
    }

    /// Past the loop budget: `Some(stop)` for a trial (stop quietly), `None` for a full run
    /// (the caller refuses naming the loop).
    fn over_budget(&self, iterations: u64) -> Option<Error> {
        (self.trial && iterations > TRIAL_ITERATIONS).then(|| Error::Internal(TRIAL_STOP.into()))
    }

    /// `" (in O1000 called on line 12, in …)"`: the calls that led to a chain, innermost first.
    fn calls(&self, mut chain: u32) -> String {
        let mut parts = Vec::new();
        while chain != 0 && parts.len() < 8 {
            let Some((parent, line, called)) = self.chains.get(chain as usize) else {
                break;
            };
            parts.push(format!("{called} called on line {line}"));
            chain = *parent;
        }
        if parts.is_empty() {
            String::new()
        } else {
            format!(" (in {})", parts.join(", in "))
        }
    }

    /// A refusal of the flattened program, moved to the original line, column and call chain.
    fn map_error(&self, original: &str, e: Error) -> Error {
        let Error::Input {
            location,
            message,
            hint,
        } = e
        else {
            return e;
        };
        let Some(out_line) = location.line else {
            return Error::Input {
                location,
                message,
                hint,
            };
        };
        let Some(&(line, chain)) = self.origin.get(out_line.saturating_sub(1) as usize) else {
            return Error::Input {
                location,
                message,
                hint,
            };
        };
        // "7 (X10.)": find the word on the original line; the flattened one may hold a value
        // where the original has an expression, so fall back to its letter.
        let column = location.column.map(|c| {
            let word = c
                .split_once('(')
                .map(|(_, w)| w.trim_end_matches(')').to_string())
                .unwrap_or_default();
            let src = original
                .lines()
                .nth(line.saturating_sub(1) as usize)
                .unwrap_or("");
            let upper = src.to_ascii_uppercase();
            let at = (!word.is_empty())
                .then(|| upper.find(&word.to_ascii_uppercase()))
                .flatten()
                .or_else(|| {
                    let letter = word.chars().next()?.to_ascii_uppercase();
                    letter
                        .is_ascii_alphabetic()
                        .then(|| upper.find(letter))
                        .flatten()
                });
            match at {
                Some(a) => {
                    let end = src[a..]
                        .find(|ch: char| ch.is_whitespace() || ch == '(' || ch == ';')
                        .map_or(src.len(), |e| a + e);
                    format!("{} ({})", src[..a].chars().count() + 1, &src[a..end])
                }
                None => format!("1 ({word})"),
            }
        });
        let message = self.original_lines(&self.original_blocks(&message));
        // A Q word the run left in place: say why its value is unknown (in original terms).
        let message = match self.why.get(&out_line) {
            Some(why) if message.contains(Q_UNKNOWN) => message.replace(Q_UNKNOWN, why),
            _ => message,
        };
        Error::Input {
            location: Location {
                file: location.file,
                line: Some(line),
                column,
            },
            message: format!("{message}{}", self.calls(chain)),
            hint,
        }
    }

    /// A message with each `block N` of the flattened Klartext program named by the original
    /// block it came from.
    fn original_blocks(&self, message: &str) -> String {
        if self.blocks.is_empty() {
            return message.to_string();
        }
        let mut out = String::with_capacity(message.len());
        let mut rest = message;
        while let Some(at) = rest.find("block ") {
            let (head, tail) = rest.split_at(at + 6);
            out.push_str(head);
            let digits = tail.bytes().take_while(u8::is_ascii_digit).count();
            let mapped = tail[..digits]
                .parse::<usize>()
                .ok()
                .and_then(|n| self.blocks.get(n))
                .and_then(|l| self.origin.get((*l as usize).checked_sub(1)?))
                .and_then(|(line, _)| *self.source_blocks.get((*line as usize).checked_sub(1)?)?);
            match mapped {
                Some(b) => out.push_str(&b.to_string()),
                None => out.push_str(&tail[..digits]),
            }
            rest = &tail[digits..];
        }
        out.push_str(rest);
        out
    }

    /// A message with each `line N` of the flattened program named by its source line.
    fn original_lines(&self, message: &str) -> String {
        let mut out = String::with_capacity(message.len());
        let mut rest = message;
        while let Some(at) = rest.find("line ") {
            let (head, tail) = rest.split_at(at + 5);
            out.push_str(head);
            let digits = tail.bytes().take_while(u8::is_ascii_digit).count();
            let mapped = tail[..digits]
                .parse::<usize>()
                .ok()
                .and_then(|n| self.origin.get(n.checked_sub(1)?));
            match mapped {
                Some((line, _)) => out.push_str(&line.to_string()),
                None => out.push_str(&tail[..digits]),
            }
            rest = &tail[digits..];
        }
        out.push_str(rest);
        out
    }
}

/// The program run into straight-line text, or `None` when it has nothing to run (no
/// subprogram, loop, jump or parameter) or its dialect is not one errmap runs. A `trial` run
/// (without `--expand`) stops at a smaller budget: see [`is_trial_stop`].
pub(crate) fn flatten(
    text: &str,
    source: &Path,
    dialect: Dialect,
    trial: bool,
) -> Result<Option<Flat>> {
    match dialect {
        Dialect::Fanuc => fanuc::flatten(text, source, trial),
        Dialect::Linuxcnc => linuxcnc::flatten(text, source, trial),
        Dialect::Sinumerik => sinumerik::flatten(text, source, trial),
        Dialect::Heidenhain => klartext::flatten(text, source, trial),
    }
}

/// Whether a trial run stopped at its budget (it found nothing to refuse before).
pub(crate) fn is_trial_stop(e: &Error) -> bool {
    matches!(e, Error::Internal(m) if m == TRIAL_STOP)
}

/// Compensate the flattened program with `compensate`; its refusals name the original lines.
pub(crate) fn compensate_flat<T>(
    text: &str,
    flat: &Flat,
    compensate: impl FnOnce(&str) -> Result<T, crate::CompensateError>,
) -> Result<T, crate::CompensateError> {
    compensate(&flat.text).map_err(|e| e.map_diagnostic(|d| flat.map_error(text, d)))
}

/// A plain-rewrite refusal with its hint replaced by [`hint`] (the program would compensate
/// with `--expand`).
pub(crate) fn with_hint(e: Error) -> Error {
    match e {
        Error::Input {
            location, message, ..
        } => Error::Input {
            location,
            message,
            hint: hint(),
        },
        e => e,
    }
}

/// How a number is written back in a word: axis-like values with a decimal point and up to 6
/// decimals (the controller rounds to its least input increment, as it would the original's
/// value); integral codes (G, M, N, T …) without one.
pub(crate) fn format_value(letter: u8, v: f64) -> String {
    let axis_like = b"XYZIJKRABCUVWQEF@^".contains(&letter.to_ascii_uppercase());
    let v = if v == 0.0 { 0.0 } else { v };
    if !axis_like && v.fract() == 0.0 && v.abs() < 1e15 {
        return format!("{}", v as i64);
    }
    let mut s = format!("{v:.6}");
    while s.ends_with('0') {
        s.pop();
    }
    if s == "-0." {
        s = "0.".into();
    }
    s
}
