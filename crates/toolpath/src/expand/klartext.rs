//! Heidenhain Klartext control flow run into plain blocks: labels `LBL n` / `LBL "name"` … `LBL 0`, subprogram calls `CALL LBL n`, program-section repeats `CALL LBL n REP m`, `FN 0–12` and formula Q parameters, `FN 9–12` conditional jumps, `END PGM`, `M2`/`M30`.
//!
//! The flattened program keeps every block that acts on the machine, in the order the TNC runs
//! them, renumbered from 0; a Q parameter in a word becomes a plain number where its value is in
//! the program. Blocks that only compute Q parameters (`FN 0–8`, `Q5 = …`, `FN 18 SYSREAD`) are
//! kept as written: the machine computes the same values in the same order, so a Q word whose
//! value errmap cannot know (read from the machine, read before it is set, set by a called
//! program or a probe) stays a Q word, which the ordinary rewriter refuses on a cut that may lie
//! in the zone, with the reason recorded here. Labels, calls and jumps are dropped.
//!
//! What cannot be run from the file (a jump on such a value, `FN 14 ERROR`, `FN 17`, `FN 19`,
//! `FN 20`, table access, control flow behind a block skip `/`) stops the run there: the blocks
//! before it are still compensated, so a refusal of an earlier cut is reported first, as the
//! plain rewriter would, and otherwise the run's own refusal.

use super::{Flat, MAX_ITERATIONS};
use crate::dialect::Dialect;
use errmap_core::error::{Error, Location, Result};
use std::collections::{HashMap, HashSet};
use std::path::Path;

/// Deepest nesting of subprogram calls: TNC 370 User's Manual §6.4 "Nesting" ("Maximum nesting
/// depth for subprograms: 8"; newer TNCs allow more, the smallest limit is kept).
const MAX_SUB_DEPTH: usize = 8;

/// The hint of refusals of values known only on the machine.
const RUNTIME_HINT: &str = "set the Q parameter in the program from numbers, or move the zone away from the moves that depend on it";

/// A block: its lines (`first..=last`, continued with `~`), number, block skip, where its
/// function starts on the first line, and its code (before comments, without `~`, upper case).
struct Blk {
    first: usize,
    last: usize,
    number: Option<u64>,
    skip: bool,
    body_at: usize,
    code: String,
}

/// A value: known, or unknown and why.
#[derive(Clone, Debug)]
enum Val {
    Known(f64),
    Unknown(String),
}

struct Frame {
    return_pc: usize,
    caller_chain: u32,
    label: String,
}

/// An active program-section repeat: passes left, the chain the passes after the first run
/// under, and the chain before it.
struct Repeat {
    left: u64,
    chain: u32,
    outer: u32,
}

/// Where the run goes after a block.
enum Next {
    At(usize),
    End,
}

struct Run<'a> {
    source: &'a Path,
    lines: Vec<&'a str>,
    blocks: Vec<Blk>,
    labels: HashMap<String, usize>,
    duplicate: HashSet<String>,
    known: HashMap<String, f64>,
    unknown: HashMap<String, String>,
    /// Why a global Q parameter not set since is unknown: a called program or a probe may set it.
    forgotten: Option<String>,
    frames: Vec<Frame>,
    repeats: HashMap<(usize, usize), Repeat>,
    flat: Flat,
    iterations: u64,
    chain: u32,
    numbered: bool,
    next_number: u64,
    /// The machining cycle defined last (`CYCL DEF 200`, line) and its Q parameters; the first
    /// of them changed since, with the line.
    cycle: Option<(String, u64, HashSet<String>)>,
    cycle_changed: Option<(String, u64)>,
    modal_call: bool,
    /// The output limit was reached: the run's error is final.
    fatal: bool,
}

/// The program run into straight-line Klartext, or `None` when it has nothing to run or is not
/// a Klartext program.
pub(super) fn flatten(text: &str, source: &Path, trial: bool) -> Result<Option<Flat>> {
    if !crate::klartext::applies(text, source, Some(Dialect::Heidenhain)) {
        return Ok(None);
    }
    let lines: Vec<&str> = text
        .split_inclusive('\n')
        .map(|l| l.trim_end_matches(['\n', '\r']))
        .collect();
    let blocks = read_blocks(&lines);
    let flow = blocks.iter().any(|b| {
        let c = b.code.as_str();
        c.starts_with("LBL")
            || c.starts_with("CALL LBL")
            || c.starts_with("FN")
            || assignment(c).is_some()
            || (!c.starts_with("CYCL")
                && !c.starts_with("TCH")
                && !c.starts_with('*')
                && has_q_ref(c))
    });
    if !flow {
        return Ok(None);
    }
    let mut labels = HashMap::new();
    let mut duplicate = HashSet::new();
    for (i, b) in blocks.iter().enumerate() {
        if let Some(rest) = b.code.strip_prefix("LBL") {
            let name = label_name(&lines[b.first][b.body_at..], rest).0;
            if labels.insert(name.clone(), i).is_some() {
                duplicate.insert(name);
            }
        }
    }
    let mut flat = Flat::new(text.len() * 2, trial);
    flat.source_blocks = lines.iter().map(|l| block_number(l)).collect();
    let mut run = Run {
        source,
        numbered: blocks.iter().any(|b| b.number.is_some()),
        lines,
        blocks,
        labels,
        duplicate,
        known: HashMap::new(),
        unknown: HashMap::new(),
        forgotten: None,
        frames: Vec::new(),
        repeats: HashMap::new(),
        flat,
        iterations: 0,
        chain: 0,
        next_number: 0,
        cycle: None,
        cycle_changed: None,
        modal_call: false,
        fatal: false,
    };
    match run.run() {
        Ok(()) => {}
        // A budget stop or the output limit ends the run; a refusal of what the run cannot
        // follow waits for the compensation of the blocks before it.
        Err(e) if super::is_trial_stop(&e) => return Err(e),
        Err(e) if run.fatal => return Err(e),
        Err(e) => run.flat.pending = Some(e),
    }
    Ok(Some(run.flat))
}

/// The blocks of the program: a line with code that ends in `~` continues on the next.
fn read_blocks(lines: &[&str]) -> Vec<Blk> {
    let mut out = Vec::new();
    let mut i = 0;
    while i < lines.len() {
        let (skip, number, body_at) = lead(lines[i]);
        let mut last = i;
        let own_code = !code_of(&lines[i][body_at..]).trim().is_empty();
        while own_code && last + 1 < lines.len() && lines[last].trim_end().ends_with('~') {
            last += 1;
        }
        let mut code = code_of(&lines[i][body_at..]).to_string();
        for l in &lines[i + 1..=last] {
            code.push(' ');
            code.push_str(code_of(l));
        }
        out.push(Blk {
            first: i,
            last,
            number,
            skip,
            body_at,
            code: code.trim().to_ascii_uppercase(),
        });
        i = last + 1;
    }
    out
}

/// A line's block skip, block number and the byte where its function starts.
fn lead(line: &str) -> (bool, Option<u64>, usize) {
    let b = line.as_bytes();
    let mut at = 0;
    let mut skip = false;
    let ws = |at: &mut usize| {
        while *at < b.len() && b[*at].is_ascii_whitespace() {
            *at += 1;
        }
    };
    ws(&mut at);
    if b.get(at) == Some(&b'/') {
        skip = true;
        at += 1;
        ws(&mut at);
    }
    let start = at;
    while at < b.len() && b[at].is_ascii_digit() {
        at += 1;
    }
    let number = line[start..at].parse().ok();
    ws(&mut at);
    if b.get(at) == Some(&b'/') {
        skip = true;
        at += 1;
        ws(&mut at);
    }
    (skip, number, at)
}

fn block_number(line: &str) -> Option<u64> {
    lead(line).1
}

/// The code of a line: before its comment, without a trailing `~`.
fn code_of(s: &str) -> &str {
    let code = s.split(';').next().unwrap_or("");
    code.trim_end().trim_end_matches('~').trim_end()
}

/// `1` of `LBL 1` / `LBL1` / `LBL 01`, `"name"` of `LBL "name"`, and the text after it.
fn label_name<'t>(original: &str, upper_rest: &'t str) -> (String, &'t str) {
    let rest = upper_rest.trim_start();
    if let Some(inside) = rest.strip_prefix('"') {
        // The name as written (case kept), from the original text.
        let name = original
            .find('"')
            .and_then(|a| {
                let e = original[a + 1..].find('"')?;
                Some(original[a..a + e + 2].to_string())
            })
            .unwrap_or_default();
        let after = inside.find('"').map_or("", |e| &inside[e + 1..]);
        return (name, after);
    }
    let end = rest.find(|c: char| c.is_whitespace()).unwrap_or(rest.len());
    let token = &rest[..end];
    let name = match token.parse::<u64>() {
        Ok(n) => n.to_string(),
        Err(_) => token.to_string(),
    };
    (name, &rest[end..])
}

/// `Q5 = …`, `QL2 = …`, `QR1 = …`: the parameter and the formula.
fn assignment(code: &str) -> Option<(String, &str)> {
    let (name, len) = q_name(code, 0)?;
    let rest = code[len..].trim_start();
    let formula = rest.strip_prefix('=')?;
    Some((name, formula))
}

/// A Q parameter name at byte `at` (`Q5`, `QL2`, `QR1`, `QS3`): the name and its end.
fn q_name(code: &str, at: usize) -> Option<(String, usize)> {
    let b = code.as_bytes();
    if !matches!(b.get(at), Some(b'Q' | b'q')) {
        return None;
    }
    let mut end = at + 1;
    if matches!(b.get(end), Some(b'L' | b'R' | b'S' | b'l' | b'r' | b's')) {
        end += 1;
    }
    let digits = b[end.min(b.len())..]
        .iter()
        .take_while(|c| c.is_ascii_digit())
        .count();
    if digits == 0 {
        return None;
    }
    let name = code[at..end + digits].to_ascii_uppercase();
    // No leading zeros in the key: `Q05` is `Q5`.
    let (kind, n) = name.split_at(end - at);
    let n = n.trim_start_matches('0');
    Some((
        format!("{kind}{}", if n.is_empty() { "0" } else { n }),
        end + digits,
    ))
}

/// Whether the code reads a Q parameter in a word (`X+Q1`, `F Q5`).
fn has_q_ref(code: &str) -> bool {
    let b = code.as_bytes();
    (0..b.len()).any(|i| {
        q_name(code, i).is_some()
            && (i == 0 || matches!(b[i - 1], b'+' | b'-' | b'=' | b'(' | b' ' | b'F'))
    })
}

/// A number as a TNC word writes it: up to 6 decimals, no trailing zeros.
fn plain(v: f64) -> String {
    let mut s = format!("{v:.6}");
    while s.ends_with('0') {
        s.pop();
    }
    if s.ends_with('.') {
        s.pop();
    }
    if s == "-0" {
        s = "0".into();
    }
    s
}

fn signed(v: f64) -> String {
    let s = plain(v);
    if s.starts_with('-') {
        s
    } else {
        format!("+{s}")
    }
}

impl Run<'_> {
    /// Whether a Q parameter is one the TNC presets itself (Q100–Q199: tool data, spindle and
    /// coolant state, PLANE angles Q120–Q122, probing results …).
    fn preset(name: &str) -> bool {
        name.strip_prefix('Q')
            .and_then(|n| n.parse::<u32>().ok())
            .is_some_and(|n| (100..=199).contains(&n))
    }

    fn get(&self, name: &str) -> Val {
        if name.starts_with("QS") {
            return Val::Unknown(format!("{name} is a string parameter"));
        }
        if Self::preset(name) {
            return Val::Unknown(format!("{name} is preset by the TNC itself (Q100–Q199: tool data, spindle and coolant state, PLANE angles, probing results), a runtime value errmap cannot know"));
        }
        if let Some(v) = self.known.get(name) {
            return Val::Known(*v);
        }
        if let Some(why) = self.unknown.get(name) {
            return Val::Unknown(why.clone());
        }
        match &self.forgotten {
            Some(why) if !name.starts_with("QL") => Val::Unknown(format!("{name} {why}")),
            _ => Val::Unknown(format!("{name} is read before the program sets it: its value is left from before the program (a runtime value errmap cannot know)")),
        }
    }

    fn set(&mut self, name: &str, v: Val, line: u64) {
        match v {
            Val::Known(x) => {
                self.known.insert(name.to_string(), x);
                self.unknown.remove(name);
            }
            Val::Unknown(why) => {
                self.known.remove(name);
                self.unknown.insert(name.to_string(), why);
            }
        }
        if let Some((_, _, params)) = &self.cycle {
            if params.contains(name) && self.cycle_changed.is_none() {
                self.cycle_changed = Some((name.to_string(), line));
            }
        }
    }

    /// Every global Q parameter unknown from here on (a called program or a probe may set it);
    /// QL parameters are local to the program and keep their values.
    fn forget(&mut self, why: String) {
        self.known.retain(|k, _| k.starts_with("QL"));
        self.unknown.retain(|k, _| k.starts_with("QL"));
        self.forgotten = Some(why);
    }

    fn line_of(&self, bi: usize) -> u64 {
        self.blocks[bi].first as u64 + 1
    }

    /// `block 12, line 13` (or `line 13`).
    fn at(&self, bi: usize) -> String {
        match self.blocks[bi].number {
            Some(n) => format!("block {n}, line {}", self.line_of(bi)),
            None => format!("line {}", self.line_of(bi)),
        }
    }

    /// A refusal at block `bi`, at the column of `word` on its first line.
    fn err(&self, bi: usize, word: &str, message: String, hint: &str) -> Error {
        let content = self.lines[self.blocks[bi].first];
        let at = content
            .to_ascii_uppercase()
            .find(&word.to_ascii_uppercase())
            .unwrap_or(self.blocks[bi].body_at.min(content.len()));
        let prefix = match self.blocks[bi].number {
            Some(n) => format!("block {n}: "),
            None => String::new(),
        };
        Error::input(
            Location::cell(
                self.source,
                self.line_of(bi),
                format!("{} ({word})", content[..at].chars().count() + 1),
            ),
            format!("{prefix}{message}{}", self.flat.calls(self.chain)),
            hint,
        )
    }

    fn run(&mut self) -> Result<()> {
        let mut pc = 0;
        while pc < self.blocks.len() {
            match self.block(pc)? {
                Next::At(next) => pc = next,
                Next::End => break,
            }
        }
        // The program ends with its END PGM block, wherever the run stopped.
        if let Some(end) = self
            .blocks
            .iter()
            .position(|b| b.code.starts_with("END PGM") || b.code == "END")
        {
            if pc != end {
                self.emit(end)?;
            }
        }
        Ok(())
    }

    /// A jump back (a repeat pass, a jump to an earlier label, a call); refused past
    /// [`MAX_ITERATIONS`].
    fn turn(&mut self, from: usize, label: usize) -> Result<()> {
        self.iterations += 1;
        if let Some(stop) = self.flat.over_budget(self.iterations) {
            return Err(stop);
        }
        if self.iterations > MAX_ITERATIONS {
            let word = self.blocks[label].code.clone();
            return Err(self.err(
                label,
                &word,
                format!(
                    "the jump from {} back to this label runs more than {MAX_ITERATIONS} times (an endless loop?)",
                    self.at(from)
                ),
                "check the loop's condition and counter",
            ));
        }
        Ok(())
    }

    /// The label block of `name`, for a call or jump at `bi`.
    fn label(&self, bi: usize, name: &str, word: &str) -> Result<usize> {
        let Some(&target) = self.labels.get(name) else {
            return Err(self.err(
                bi,
                word,
                format!("`{word}`: the program has no label LBL {name} (the TNC refuses the call)"),
                "add the label, or call one the program has",
            ));
        };
        if self.duplicate.contains(name) {
            return Err(self.err(
                bi,
                word,
                format!("`{word}`: the program has more than one label LBL {name}"),
                "give each label its own number or name",
            ));
        }
        if self.blocks[target].skip {
            return Err(self.err(
                bi,
                word,
                format!("`{word}` goes to the label LBL {name} ({}), which has a block skip `/`: where the TNC continues depends on the block-skip switch", self.at(target)),
                "remove the `/` from the label",
            ));
        }
        Ok(target)
    }

    /// Control flow behind a block skip: refused.
    fn skipped(&self, bi: usize, what: &str) -> Error {
        let word = self.blocks[bi].code.clone();
        self.err(
            bi,
            "/",
            format!("block skip `/` on `{word}`: {what} depends on the block-skip switch, set at run time"),
            "remove the `/` from the block, or run the program without it",
        )
    }

    fn block(&mut self, bi: usize) -> Result<Next> {
        let code = self.blocks[bi].code.clone();
        let skip = self.blocks[bi].skip;
        let line = self.line_of(bi);
        if let Some(rest) = code.strip_prefix("LBL") {
            let name = label_name("", rest).0;
            if name == "0" && !self.frames.is_empty() {
                if skip {
                    return Err(self.skipped(bi, "whether the subprogram returns here"));
                }
                return Ok(Next::At(self.ret()));
            }
            // A label reached in sequence marks a place; LBL 0 outside a subprogram does
            // nothing (a program-section repeat's body may hold one).
            return Ok(Next::At(bi + 1));
        }
        if let Some(rest) = code.strip_prefix("CALL") {
            let rest = rest.trim_start();
            if let Some(after) = rest.strip_prefix("LBL") {
                if skip {
                    return Err(self.skipped(bi, "whether the label is called"));
                }
                return self.call(bi, after);
            }
            if rest.starts_with("PGM") || rest.starts_with("SELECTED") {
                self.emit(bi)?;
                let first = self.lines[self.blocks[bi].first];
                let what = first[self.blocks[bi].body_at..]
                    .split(';')
                    .next()
                    .unwrap_or("")
                    .trim()
                    .to_string();
                self.forget(format!(
                    "may be set by `{what}` ({}), another program, not in this file",
                    self.at(bi)
                ));
                return Ok(Next::At(bi + 1));
            }
        }
        if let Some(rest) = code.strip_prefix("FN") {
            return self.function(bi, rest);
        }
        if let Some((name, formula)) = assignment(&code) {
            if !name.starts_with("QS") {
                let v = if skip {
                    Val::Unknown(format!("{name} is set by a block with block skip `/` ({}), whose running depends on the switch set at run time", self.at(bi)))
                } else {
                    self.eval(bi, formula, &name)?
                };
                self.set(&name, v, line);
            }
            self.emit(bi)?;
            return Ok(Next::At(bi + 1));
        }
        if code.starts_with("END PGM") || code == "END" {
            if skip {
                return Err(self.skipped(bi, "whether the program ends here"));
            }
            self.emit(bi)?;
            return Ok(Next::End);
        }
        if code.starts_with("CYCL DEF") {
            self.cycle_definition(bi, &code);
        }
        if code.starts_with("TCH PROBE") {
            self.emit(bi)?;
            self.forget(format!(
                "may be set by the touch probe cycle at {} from what it measures at run time",
                self.at(bi)
            ));
            return Ok(Next::At(bi + 1));
        }
        let m = m_words(&code);
        let ends = m.iter().any(|&m| m == 2 || m == 30);
        let calls = code.starts_with("CYCL CALL")
            || m.iter().any(|&m| m == 99 || m == 89)
            || (self.modal_call && code.starts_with("L "));
        self.modal_call |= m.contains(&89);
        if calls {
            if let (Some((q, at)), Some((cycle, def, _))) = (&self.cycle_changed, &self.cycle) {
                let word = code.split_whitespace().next().unwrap_or("").to_string();
                return Err(self.err(bi, &word, format!("cycle call of `{cycle}` (line {def}) after `{q}`, one of its parameters, was set again on line {at}: which value the cycle runs with is not in the manuals errmap's authors had"), "set the cycle's parameters in its CYCL DEF block only"));
            }
        }
        if ends && skip {
            return Err(self.skipped(bi, "whether the program ends here"));
        }
        self.emit(bi)?;
        if ends {
            return Ok(Next::End);
        }
        Ok(Next::At(bi + 1))
    }

    /// `CYCL DEF n …`: a machining cycle's parameters (`Q200=+2`) are the Q parameters of the
    /// same numbers, unknown after it (whether the TNC keeps them is not confirmed).
    fn cycle_definition(&mut self, bi: usize, code: &str) {
        let number = code["CYCL DEF".len()..]
            .split_whitespace()
            .next()
            .unwrap_or("")
            .to_string();
        let major = number.split('.').next().unwrap_or("");
        let transform = matches!(major, "7" | "8" | "9" | "10" | "11" | "19" | "26" | "32");
        let mut params = HashSet::new();
        let b = code.as_bytes();
        for i in 0..b.len() {
            if i > 0 && !b[i - 1].is_ascii_whitespace() {
                continue;
            }
            if let Some((name, end)) = q_name(code, i) {
                if code[end..].trim_start().starts_with('=') {
                    params.insert(name);
                }
            }
        }
        let line = self.line_of(bi);
        for p in &params {
            let why = format!("{p} was last written by the cycle definition `CYCL DEF {number}` ({}): whether a CYCL DEF sets the Q parameter of the same number is not confirmed in the TNC manual", self.at(bi));
            self.known.remove(p);
            self.unknown.insert(p.clone(), why);
        }
        if !transform {
            self.cycle = Some((format!("CYCL DEF {number}"), line, params));
            self.cycle_changed = None;
        }
    }

    /// `LBL 0` in a subprogram: back to the block after its call.
    fn ret(&mut self) -> usize {
        let Some(f) = self.frames.pop() else {
            return 0;
        };
        let depth = self.frames.len();
        self.repeats.retain(|(d, _), _| *d <= depth);
        self.chain = f.caller_chain;
        f.return_pc
    }

    /// `CALL LBL n`: a subprogram call; `CALL LBL n REP m`: repeat the section from the label
    /// (before the call) to the call m more times.
    fn call(&mut self, bi: usize, after: &str) -> Result<Next> {
        let first = self.lines[self.blocks[bi].first];
        let original = &first[self.blocks[bi].body_at..];
        let (name, rest) = label_name(original, after);
        let word = format!("CALL LBL {name}");
        if name == "0" {
            return Err(self.err(
                bi,
                "CALL",
                "`CALL LBL 0`: LBL 0 ends a subprogram and cannot be called".into(),
                "call a label with a number other than 0 or a name",
            ));
        }
        let rest = rest.trim();
        let target = self.label(bi, &name, &word)?;
        let line = self.line_of(bi);
        if let Some(rep) = rest.strip_prefix("REP") {
            let digits: String = rep
                .trim_start()
                .chars()
                .take_while(char::is_ascii_digit)
                .collect();
            let Ok(m) = digits.parse::<u64>() else {
                return Err(self.err(
                    bi,
                    "REP",
                    format!("`{word} {rest}`: REP without a number of repetitions errmap can read"),
                    "write the repetitions as a number, e.g. CALL LBL 1 REP 2",
                ));
            };
            if target > bi {
                return Err(self.err(
                    bi,
                    "REP",
                    format!("`{word} REP {m}` with the label after the call: the TNC manual describes REP for a program section between a label and the call after it"),
                    "put the label before the call, or call the subprogram without REP",
                ));
            }
            let key = (self.frames.len(), bi);
            if !self.repeats.contains_key(&key) {
                let chain =
                    self.flat
                        .chain(self.chain, line, format!("LBL {name} repeated (REP {m})"));
                self.repeats.insert(
                    key,
                    Repeat {
                        left: m,
                        chain,
                        outer: self.chain,
                    },
                );
            }
            let (left, chain, outer) = match self.repeats.get_mut(&key) {
                Some(r) if r.left > 0 => {
                    r.left -= 1;
                    (true, r.chain, r.outer)
                }
                Some(r) => (false, r.chain, r.outer),
                None => (false, self.chain, self.chain),
            };
            if left {
                self.turn(bi, target)?;
                self.chain = chain;
                return Ok(Next::At(target + 1));
            }
            self.repeats.remove(&key);
            self.chain = outer;
            return Ok(Next::At(bi + 1));
        }
        if !rest.is_empty() {
            return Err(self.err(
                bi,
                "CALL",
                format!("`{word} {rest}`: a label call errmap does not read"),
                "write CALL LBL n or CALL LBL n REP m",
            ));
        }
        if self.frames.iter().any(|f| f.label == name) {
            return Err(self.err(
                bi,
                "CALL",
                format!(
                    "`{word}` inside the subprogram LBL {name}: a subprogram cannot call itself"
                ),
                "end the subprogram with LBL 0 before calling it",
            ));
        }
        if self.frames.len() >= MAX_SUB_DEPTH {
            return Err(self.err(
                bi,
                "CALL",
                format!(
                    "subprogram calls nested deeper than {MAX_SUB_DEPTH} levels (the TNC's limit)"
                ),
                "nest fewer subprogram calls",
            ));
        }
        self.turn(bi, target)?;
        let inner = self.flat.chain(self.chain, line, format!("LBL {name}"));
        self.frames.push(Frame {
            return_pc: bi + 1,
            caller_chain: self.chain,
            label: name,
        });
        self.chain = inner;
        Ok(Next::At(target + 1))
    }

    /// `FN n: …`.
    fn function(&mut self, bi: usize, rest: &str) -> Result<Next> {
        let rest = rest.trim_start();
        let digits: String = rest.chars().take_while(char::is_ascii_digit).collect();
        let body = rest[digits.len()..]
            .trim_start()
            .strip_prefix(':')
            .unwrap_or(&rest[digits.len()..])
            .trim();
        let skip = self.blocks[bi].skip;
        let line = self.line_of(bi);
        let word = format!("FN {digits}");
        let Ok(n) = digits.parse::<u32>() else {
            return Err(self.err(
                bi,
                "FN",
                "an FN block without its function number".into(),
                "write FN n: …",
            ));
        };
        match n {
            0..=8 => {
                let Some((name, formula)) = assignment(body) else {
                    return Err(self.err(
                        bi,
                        "FN",
                        format!("`{word}: {body}` is not an assignment `Qn = …` errmap reads"),
                        "write e.g. FN 1: Q1 = +Q2 + +5",
                    ));
                };
                let v = if skip {
                    Val::Unknown(format!("{name} is set by a block with block skip `/` ({}), whose running depends on the switch set at run time", self.at(bi)))
                } else {
                    self.eval(bi, formula, &name)?
                };
                self.set(&name, v, line);
                self.emit(bi)?;
                Ok(Next::At(bi + 1))
            }
            9..=12 => {
                if skip {
                    return Err(self.skipped(bi, "whether the jump is made"));
                }
                self.jump(bi, &word, body)
            }
            15 | 16 => {
                // PRINT / F-PRINT: text out, no motion; the machine prints its own values.
                self.emit(bi)?;
                Ok(Next::At(bi + 1))
            }
            18 => {
                let target = body
                    .find('Q')
                    .and_then(|at| q_name(body, at))
                    .map(|(q, _)| q);
                if let Some(q) = target {
                    let why = format!(
                        "{q} is set by `FN 18: SYSREAD` ({}), a value read from the machine at run time",
                        self.at(bi)
                    );
                    self.set(&q, Val::Unknown(why), line);
                }
                self.emit(bi)?;
                Ok(Next::At(bi + 1))
            }
            _ => {
                let what = match n {
                    14 => "FN 14: ERROR stops the program with an error message",
                    17 => "FN 17: SYSWRITE writes machine data (datums, tool data) at run time",
                    19 => "FN 19: PLC hands values to the machine's PLC at run time",
                    20 => "FN 20: WAIT FOR waits for a condition of the machine at run time",
                    26 => "FN 26: TABOPEN opens a table whose contents are read or written at run time",
                    27 => "FN 27: TABWRITE writes a table at run time",
                    28 => "FN 28: TABREAD reads a table at run time",
                    _ => "",
                };
                let message = if what.is_empty() {
                    format!("`{word}` is a function errmap does not run (its effect is known at run time only)")
                } else {
                    format!("`{word}`: {what}; errmap cannot follow the program past it")
                };
                Err(self.err(
                    bi,
                    "FN",
                    message,
                    "move the function to a program of its own, or run the program without it",
                ))
            }
        }
    }

    /// `FN 9–12: IF a EQU|NE|GT|LT b GOTO LBL n`.
    fn jump(&mut self, bi: usize, word: &str, body: &str) -> Result<Next> {
        let bad = |s: &Self| {
            s.err(
                bi,
                "FN",
                format!("`{word}: {body}` is not a jump errmap reads"),
                "write e.g. FN 9: IF +Q1 EQU +Q2 GOTO LBL 3",
            )
        };
        let Some(cond) = body.strip_prefix("IF") else {
            return Err(bad(self));
        };
        let Some(goto) = cond.find("GOTO") else {
            return Err(bad(self));
        };
        let (cond, target) = (&cond[..goto], cond[goto + 4..].trim_start());
        let Some(label) = target.strip_prefix("LBL") else {
            return Err(bad(self));
        };
        let first = self.lines[self.blocks[bi].first];
        let (name, _) = label_name(&first[self.blocks[bi].body_at..], label);
        if name.starts_with('Q') {
            return Err(self.err(
                bi,
                "GOTO",
                format!("`{word}` jumps to a label given by the parameter {name}"),
                "jump to a label number or name",
            ));
        }
        let words: Vec<&str> = cond.split_whitespace().collect();
        let Some(op_at) = words
            .iter()
            .position(|w| matches!(*w, "EQU" | "NE" | "GT" | "LT"))
        else {
            return Err(bad(self));
        };
        let (a, b) = (words[..op_at].join(" "), words[op_at + 1..].join(" "));
        let a = self.eval(bi, &a, "the condition")?;
        let b = self.eval(bi, &b, "the condition")?;
        let (a, b) = match (a, b) {
            (Val::Known(a), Val::Known(b)) => (a, b),
            (Val::Unknown(why), _) | (_, Val::Unknown(why)) => {
                return Err(self.err(
                    bi,
                    "FN",
                    format!(
                        "the jump `{word}: {}` depends on a value errmap cannot know: {why}",
                        body.trim()
                    ),
                    RUNTIME_HINT,
                ))
            }
        };
        let taken = match words[op_at] {
            "EQU" => a == b,
            "NE" => a != b,
            "GT" => a > b,
            _ => a < b,
        };
        if !taken {
            return Ok(Next::At(bi + 1));
        }
        let target = self.label(bi, &name, &format!("GOTO LBL {name}"))?;
        if target <= bi {
            self.turn(bi, target)?;
        }
        Ok(Next::At(target + 1))
    }

    /// A formula's value; refused where the TNC would stop with an error (division by zero …).
    fn eval(&self, bi: usize, formula: &str, target: &str) -> Result<Val> {
        let mut p = Parser {
            s: formula.as_bytes(),
            at: 0,
            run: self,
        };
        let v = p.expr().and_then(|v| {
            p.space();
            if p.at < p.s.len() {
                Err(format!("`{}` after the formula", &formula[p.at..]))
            } else {
                Ok(v)
            }
        });
        v.map_err(|m| {
            self.err(
                bi,
                target,
                format!("the Q parameter formula for {target}: {m}; the TNC stops the program here with an error"),
                "fix the formula",
            )
        })
    }

    /// Write block `bi`: renumbered, its Q words replaced by their values where known.
    fn emit(&mut self, bi: usize) -> Result<()> {
        let keep = {
            let c = &self.blocks[bi].code;
            // `* - section` blocks are text.
            c.starts_with("FN") || c.starts_with('*') || assignment(c).is_some()
        };
        let (first, last, body_at, skip, numbered) = {
            let b = &self.blocks[bi];
            (b.first, b.last, b.body_at, b.skip, b.number.is_some())
        };
        let mut why: Option<String> = None;
        let chain = self.chain;
        for i in first..=last {
            let content = self.lines[i];
            let body = if i == first {
                &content[body_at..]
            } else {
                content
            };
            let (code, comment) = match body.find(';') {
                Some(c) => (&body[..c], &body[c..]),
                None => (body, ""),
            };
            let code = if keep {
                code.to_string()
            } else {
                self.substitute(code, &mut why)
            };
            let mut out = String::with_capacity(content.len() + 8);
            if i == first {
                if skip {
                    out.push_str("/ ");
                }
                if self.numbered && numbered {
                    out.push_str(&self.next_number.to_string());
                    out.push(' ');
                    self.next_number += 1;
                    self.flat.blocks.push(self.flat.origin.len() as u64 + 1);
                }
            }
            out.push_str(&code);
            out.push_str(comment);
            let at = self.flat.origin.len() as u64 + 1;
            if let Err(e) = self.flat.push(self.source, i as u64 + 1, chain, &out) {
                self.fatal = true;
                return Err(e);
            }
            if let (true, Some(w)) = (i == first, why.take()) {
                self.flat.why.insert(at, w);
            }
        }
        Ok(())
    }

    /// `X+Q1` → `X+12.5`, `F Q5` / `FQ5` → `F4500`, `Q321=+Q71` → `Q321=+92.5`; an unknown
    /// value keeps its Q word (its reason in `why`).
    fn substitute(&self, code: &str, why: &mut Option<String>) -> String {
        let b = code.as_bytes();
        let mut out = String::with_capacity(code.len() + 8);
        let mut i = 0;
        let mut quoted = false;
        while i < b.len() {
            let c = b[i];
            if c == b'"' {
                quoted = !quoted;
            }
            let prev = if i == 0 { b' ' } else { b[i - 1] };
            let prev_ok = matches!(prev, b'+' | b'-' | b'=' | b'(' | b' ' | b'\t')
                || (matches!(prev, b'F' | b'f') && (i < 2 || !b[i - 2].is_ascii_alphanumeric()));
            let parsed = if quoted || !prev_ok {
                None
            } else {
                q_name(code, i)
            };
            let Some((name, end)) = parsed
                .filter(|(n, e)| !n.starts_with("QS") && !code[*e..].trim_start().starts_with('='))
            else {
                let ch = code[i..].chars().next().unwrap_or(' ');
                out.push(ch);
                i += ch.len_utf8();
                continue;
            };
            match self.get(&name) {
                Val::Known(v) => {
                    let feed_spaced =
                        prev.is_ascii_whitespace() && out.trim_end().ends_with(['F', 'f']) && {
                            let t = out.trim_end();
                            t.len() < 2 || !t.as_bytes()[t.len() - 2].is_ascii_alphanumeric()
                        };
                    if matches!(prev, b'+' | b'-') {
                        out.pop();
                        let s = if prev == b'-' { -1.0 } else { 1.0 };
                        out.push_str(&signed(s * v));
                    } else if matches!(prev, b'F' | b'f') {
                        out.push_str(&plain(v));
                    } else if feed_spaced {
                        let t = out.trim_end().len();
                        out.truncate(t);
                        out.push_str(&plain(v));
                    } else {
                        out.push_str(&signed(v));
                    }
                }
                Val::Unknown(w) => {
                    why.get_or_insert(w);
                    out.push_str(&code[i..end]);
                }
            }
            i = end;
        }
        out
    }
}

/// The M functions of a block's code (`M30`, `L … M99`).
fn m_words(code: &str) -> Vec<u32> {
    code.split_whitespace()
        .filter_map(|w| w.strip_prefix('M')?.parse().ok())
        .collect()
}

/// A TNC formula (`Q1 + 2 * SIN ( Q3 )`, `+Q2 DIV +Q3`, `SQRT Q4`), evaluated: `+ −`, `* /`
/// (`DIV`), `LEN` (root of the sum of squares), `^`, unary signs, parentheses, and the
/// functions SIN COS TAN ASIN ACOS ATAN (degrees) SQ SQRT LN LOG EXP ABS INT FRAC NEG SGN, PI.
struct Parser<'a> {
    s: &'a [u8],
    at: usize,
    run: &'a Run<'a>,
}

type Eval = std::result::Result<Val, String>;

impl Parser<'_> {
    fn space(&mut self) {
        while self.at < self.s.len() && self.s[self.at].is_ascii_whitespace() {
            self.at += 1;
        }
    }

    fn peek(&mut self) -> Option<u8> {
        self.space();
        self.s.get(self.at).copied()
    }

    fn keyword(&mut self, k: &str) -> bool {
        self.space();
        let end = self.at + k.len();
        let matches = self
            .s
            .get(self.at..end)
            .is_some_and(|w| w.eq_ignore_ascii_case(k.as_bytes()))
            && !self.s.get(end).is_some_and(u8::is_ascii_alphanumeric);
        if matches {
            self.at = end;
        }
        matches
    }

    fn expr(&mut self) -> Eval {
        let mut v = self.term()?;
        loop {
            match self.peek() {
                Some(c @ (b'+' | b'-')) => {
                    self.at += 1;
                    let r = self.term()?;
                    v = both(v, r, |a, b| Ok(if c == b'+' { a + b } else { a - b }))?;
                }
                _ => return Ok(v),
            }
        }
    }

    fn term(&mut self) -> Eval {
        let mut v = self.power()?;
        loop {
            let op = match self.peek() {
                Some(b'*') => {
                    self.at += 1;
                    '*'
                }
                Some(b'/') => {
                    self.at += 1;
                    '/'
                }
                _ if self.keyword("DIV") => '/',
                _ if self.keyword("LEN") => 'L',
                _ => return Ok(v),
            };
            let r = self.power()?;
            v = both(v, r, |a, b| match op {
                '*' => Ok(a * b),
                'L' => Ok(a.hypot(b)),
                _ if b == 0.0 => Err(format!("division by zero ({} / 0)", plain(a))),
                _ => Ok(a / b),
            })?;
        }
    }

    fn power(&mut self) -> Eval {
        let base = self.unary()?;
        if self.peek() == Some(b'^') {
            self.at += 1;
            let e = self.power()?;
            return both(base, e, |a, b| {
                let v = a.powf(b);
                if v.is_finite() {
                    Ok(v)
                } else {
                    Err(format!("{} ^ {} has no value", plain(a), plain(b)))
                }
            });
        }
        Ok(base)
    }

    fn unary(&mut self) -> Eval {
        match self.peek() {
            Some(b'+') => {
                self.at += 1;
                self.unary()
            }
            Some(b'-') => {
                self.at += 1;
                Ok(match self.unary()? {
                    Val::Known(v) => Val::Known(-v),
                    u => u,
                })
            }
            _ => self.primary(),
        }
    }

    fn primary(&mut self) -> Eval {
        match self.peek() {
            None => Err("a value is missing".into()),
            Some(b'(') => {
                self.at += 1;
                let v = self.expr()?;
                if self.peek() != Some(b')') {
                    return Err("a `(` without its `)`".into());
                }
                self.at += 1;
                Ok(v)
            }
            Some(c) if c.is_ascii_digit() || c == b'.' => {
                let start = self.at;
                while self
                    .s
                    .get(self.at)
                    .is_some_and(|c| c.is_ascii_digit() || *c == b'.')
                {
                    self.at += 1;
                }
                let t = std::str::from_utf8(&self.s[start..self.at]).unwrap_or("");
                t.parse::<f64>()
                    .map(Val::Known)
                    .map_err(|_| format!("`{t}` is not a number"))
            }
            Some(b'Q' | b'q')
                if std::str::from_utf8(self.s)
                    .ok()
                    .and_then(|s| q_name(s, self.at))
                    .is_some() =>
            {
                let s = std::str::from_utf8(self.s).unwrap_or("");
                let Some((name, end)) = q_name(s, self.at) else {
                    return Err("a Q parameter errmap cannot read".into());
                };
                self.at = end;
                Ok(self.run.get(&name))
            }
            Some(c) if c.is_ascii_alphabetic() => {
                let start = self.at;
                while self.s.get(self.at).is_some_and(u8::is_ascii_alphabetic) {
                    self.at += 1;
                }
                let f = String::from_utf8_lossy(&self.s[start..self.at]).to_ascii_uppercase();
                if f == "PI" {
                    return Ok(Val::Known(std::f64::consts::PI));
                }
                let arg = self.unary()?;
                let Val::Known(x) = arg else { return Ok(arg) };
                let rad = x.to_radians();
                let v = match f.as_str() {
                    "SIN" => rad.sin(),
                    "COS" => rad.cos(),
                    "TAN" if (x.rem_euclid(180.0) - 90.0).abs() < 1e-12 => {
                        return Err(format!("TAN of {}° has no value", plain(x)))
                    }
                    "TAN" => rad.tan(),
                    "ASIN" | "ACOS" if !(-1.0..=1.0).contains(&x) => {
                        return Err(format!("{f} of {} has no value", plain(x)))
                    }
                    "ASIN" => x.asin().to_degrees(),
                    "ACOS" => x.acos().to_degrees(),
                    "ATAN" => x.atan().to_degrees(),
                    "SQ" => x * x,
                    "SQRT" if x < 0.0 => {
                        return Err(format!(
                            "the square root of a negative number ({})",
                            plain(x)
                        ))
                    }
                    "SQRT" => x.sqrt(),
                    "LN" | "LOG" if x <= 0.0 => {
                        return Err(format!("{f} of {} has no value", plain(x)))
                    }
                    "LN" => x.ln(),
                    "LOG" => x.log10(),
                    "EXP" => x.exp(),
                    "ABS" => x.abs(),
                    "INT" => x.trunc(),
                    "FRAC" => x.fract(),
                    "NEG" => -x,
                    "SGN" => {
                        if x > 0.0 {
                            1.0
                        } else if x < 0.0 {
                            -1.0
                        } else {
                            0.0
                        }
                    }
                    _ => return Err(format!("`{f}` is not a function errmap computes")),
                };
                if v.is_finite() {
                    Ok(Val::Known(v))
                } else {
                    Err(format!("{f} of {} has no value", plain(x)))
                }
            }
            Some(c) => Err(format!("`{}` where a value belongs", c as char)),
        }
    }
}

/// A binary operation on two values: unknown when either is.
fn both(a: Val, b: Val, f: impl FnOnce(f64, f64) -> std::result::Result<f64, String>) -> Eval {
    match (a, b) {
        (Val::Known(a), Val::Known(b)) => f(a, b).map(Val::Known),
        (Val::Unknown(w), _) | (_, Val::Unknown(w)) => Ok(Val::Unknown(w)),
    }
}
