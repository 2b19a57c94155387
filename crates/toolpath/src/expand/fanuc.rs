//! Fanuc / Haas custom macro B run into plain blocks: `M98`/`M97` subprograms, `G65` macro calls with arguments, `#` variables, `IF`/`GOTO`/`WHILE … DO … END`.

use super::eval::{self, Env, Expr, Rules, Var};
use super::{format_value, Flat, MAX_CALL_DEPTH, MAX_ITERATIONS};
use crate::dialect::{strip_comments, Dialect};
use crate::lexer::{self, Line, TokenKind, WordValue};
use errmap_core::error::{Error, Location, Result};
use std::collections::HashMap;
use std::path::Path;

/// G65 nesting the Fanuc manual allows ("four levels including simple calls (G65) and modal
/// calls (G66)"); local variable levels 0 to 4.
const MAX_MACRO_LEVELS: usize = 4;

/// One line, compiled once.
#[derive(Debug)]
enum Stmt {
    /// Copied as it is (comments, blank lines, `%`, the main program's O number, `DPRNT` …).
    Copy,
    /// A subprogram's O number: a program starts here.
    Header,
    /// A block of words (some values expressions).
    Words(Vec<Piece>),
    Assign(Var, Expr),
    IfGoto(Expr, Expr),
    IfThen(Expr, Var, Expr),
    Goto(Expr),
    /// `WHILE [cond] DOm` (a bare `DOm` loops for ever: cond 1).
    While(Expr, u32),
    End(u32),
}

#[derive(Debug)]
enum Piece {
    Text(std::ops::Range<usize>),
    Word {
        letter: u8,
        span: std::ops::Range<usize>,
        value: Val,
    },
}

#[derive(Debug)]
enum Val {
    /// A literal; `true` when written with a decimal point.
    Num(f64, bool),
    Expr(Expr),
}

/// A refusal found while compiling a line, raised only if the line runs: (word, message).
type Bad = (String, String);

struct Program {
    number: u64,
    /// Index of its O line and one past its last line.
    start: usize,
    end: usize,
}

struct Frame {
    return_pc: usize,
    /// The caller's program and call chain, restored at M99.
    range: (usize, usize),
    caller_chain: u32,
    /// The call chain of the lines run inside.
    chain: u32,
    /// First body line, for `L` repeats.
    body: usize,
    repeats_left: u64,
    /// A G65 call: its local variables are popped at M99.
    macro_call: bool,
}

struct Vars<'r> {
    locals: &'r [Option<f64>; 34],
    commons: &'r HashMap<u32, f64>,
}

/// What a system variable holds, for messages.
fn system_variable(n: u32) -> String {
    if (10_000..=10_999).contains(&n) {
        return format!("#{n} is a tool offset on a Fanuc (#10001–#13999) but a general-purpose variable on a Haas NGC (#10000–#10999 = #100–#999 there), and errmap reads both as one dialect; on a Haas write it as #{}", n - 10_000);
    }
    let what = match n {
        1000..=1999 => "interface signals",
        2000..=2999 => "tool offsets",
        3000..=3999 => "alarms, clock, messages and modes",
        4000..=4999 => "modal information",
        5000..=5999 => "positions, skip and probe positions, work offsets",
        6000.. => "parameters and work offsets",
        _ => {
            return format!("#{n} is not a common variable on every Fanuc (#100–#199 and #500–#999; the others need an option)")
        }
    };
    format!("#{n} is a system variable ({what}) whose value only the machine knows")
}

impl Env for Vars<'_> {
    fn get(&self, var: &Var, n: Option<u32>) -> std::result::Result<Option<f64>, String> {
        let Some(n) = n else {
            return Err(format!("`{var:?}`: named variables are not Fanuc macro B"));
        };
        match n {
            0 => Ok(None),
            1..=33 => Ok(self.locals[n as usize]),
            100..=199 | 500..=999 => Ok(self.commons.get(&n).copied()),
            _ => Err(system_variable(n)),
        }
    }
}

/// `[cond]` at the start of `s`: its inside and the rest.
fn bracketed(s: &str) -> Option<(&str, &str)> {
    let s = s.trim_start();
    if !s.starts_with('[') {
        return None;
    }
    let mut depth = 0;
    for (i, c) in s.char_indices() {
        match c {
            '[' => depth += 1,
            ']' => {
                depth -= 1;
                if depth == 0 {
                    return Some((&s[..=i], &s[i + 1..]));
                }
            }
            _ => {}
        }
    }
    None
}

fn parse(text: &str) -> std::result::Result<Expr, Bad> {
    eval::parse(text, Rules::Fanuc).map_err(|m| (text.trim().to_string(), m))
}

/// `#i = expr`.
fn assignment(text: &str) -> std::result::Result<(Var, Expr), Bad> {
    let (target, value) = text.split_once('=').ok_or_else(|| {
        (
            text.trim().to_string(),
            "an assignment without `=`".to_string(),
        )
    })?;
    let var = match parse(target)? {
        Expr::Var(v) => v,
        _ => {
            return Err((
                target.trim().to_string(),
                "only a #variable can be assigned".into(),
            ))
        }
    };
    Ok((var, parse(value)?))
}

/// A macro statement (`IF`, `GOTO`, `WHILE`, `DO`, `END`; output statements are copied).
fn keyword(name: &str, body: &str) -> std::result::Result<Stmt, Bad> {
    let body = strip_comments(body);
    let rest = body.get(name.len()..).unwrap_or("").trim();
    let bad = |m: &str| Err((name.to_string(), format!("`{}`: {m}", body.trim())));
    let upper = rest.to_ascii_uppercase();
    match name {
        "IF" => {
            let Some((cond, after)) = bracketed(rest) else {
                return bad("IF takes a condition in [ ]");
            };
            let cond = parse(cond)?;
            let after_up = after.trim_start().to_ascii_uppercase();
            let after = after.trim_start();
            if let Some(n) = after_up.strip_prefix("GOTO") {
                let n = &after[after.len() - n.len()..];
                Ok(Stmt::IfGoto(cond, parse(n)?))
            } else if let Some(s) = after_up.strip_prefix("THEN") {
                let (v, e) = assignment(&after[after.len() - s.len()..])?;
                Ok(Stmt::IfThen(cond, v, e))
            } else {
                bad("IF is followed by GOTO n or THEN #i = …")
            }
        }
        "GOTO" => Ok(Stmt::Goto(parse(rest)?)),
        "WHILE" => {
            let Some((cond, after)) = bracketed(rest) else {
                return bad("WHILE takes a condition in [ ]");
            };
            let after = after.trim_start().to_ascii_uppercase();
            match after.strip_prefix("DO").map(|m| m.trim().parse::<u32>()) {
                Some(Ok(m)) => Ok(Stmt::While(parse(cond)?, m)),
                _ => bad("WHILE [ … ] is followed by DOm"),
            }
        }
        "DO" => match upper.parse::<u32>() {
            Ok(m) => Ok(Stmt::While(Expr::Num(1.0), m)),
            Err(_) => bad("DO is followed by its number"),
        },
        "END" => match upper.parse::<u32>() {
            Ok(m) => Ok(Stmt::End(m)),
            Err(_) => bad("END is followed by its number"),
        },
        "POPEN" | "PCLOS" | "DPRNT" | "BPRNT" => Ok(Stmt::Copy),
        _ => bad("a macro statement errmap does not run"),
    }
}

/// Compile one line.
fn compile(text: &str, line: &Line) -> std::result::Result<Stmt, Bad> {
    let mut pieces = Vec::new();
    for (i, t) in line.tokens.iter().enumerate() {
        match &t.kind {
            TokenKind::Keyword { name } => {
                let others = line.tokens[..i]
                    .iter()
                    .any(|t| matches!(&t.kind, TokenKind::Word { letter, .. } if *letter != b'N'));
                if others {
                    return Err((
                        name.clone(),
                        format!("`{name}` after other words on a block"),
                    ));
                }
                return keyword(name, &text[t.span.clone()]);
            }
            TokenKind::Assignment { .. } => {
                let others = line
                    .tokens
                    .iter()
                    .any(|t| matches!(&t.kind, TokenKind::Word { letter, .. } if *letter != b'N'));
                let rest = strip_comments(&text[t.span.start..line.span.end]);
                if others {
                    return Err((
                        rest.trim().to_string(),
                        "an assignment on a block with other words, whose order errmap does not reproduce".into(),
                    ));
                }
                let (v, e) = assignment(&rest)?;
                return Ok(Stmt::Assign(v, e));
            }
            TokenKind::OWord { .. } => return Ok(Stmt::Header),
            TokenKind::Word { letter, value } => {
                let value = match value {
                    WordValue::Number(v) => Val::Num(*v, text[t.span.clone()].contains('.')),
                    WordValue::Expr(r) => Val::Expr(parse(&text[r.clone()])?),
                    _ => {
                        return Err((
                            text[t.span.clone()].to_string(),
                            "a value errmap does not read in the Fanuc dialect".into(),
                        ))
                    }
                };
                pieces.push(Piece::Word {
                    letter: *letter,
                    span: t.span.clone(),
                    value,
                });
            }
            _ => pieces.push(Piece::Text(t.span.clone())),
        }
    }
    Ok(if pieces.iter().all(|p| matches!(p, Piece::Text(_))) {
        Stmt::Copy
    } else {
        Stmt::Words(pieces)
    })
}

/// Whether the program has anything to run.
fn has_flow(stmts: &[std::result::Result<Stmt, Bad>]) -> bool {
    stmts.iter().any(|s| match s {
        Err(_) => true,
        Ok(Stmt::Words(pieces)) => pieces.iter().any(|p| match p {
            Piece::Word {
                value: Val::Expr(..),
                ..
            } => true,
            Piece::Word {
                letter: b'M',
                value: Val::Num(v, _),
                ..
            } => [97.0, 98.0].contains(v),
            Piece::Word {
                letter: b'G',
                value: Val::Num(v, _),
                ..
            } => [65.0, 66.0].contains(v),
            _ => false,
        }),
        Ok(Stmt::Copy | Stmt::Header) => false,
        Ok(_) => true,
    })
}

struct Run<'a> {
    text: &'a str,
    source: &'a Path,
    lines: Vec<Line>,
    stmts: Vec<std::result::Result<Stmt, Bad>>,
    programs: Vec<Program>,
    /// Line indices by their leading sequence number.
    labels: HashMap<u64, Vec<usize>>,
    /// WHILE ↔ END partners by line index.
    partner: HashMap<usize, usize>,
    locals: Vec<[Option<f64>; 34]>,
    commons: HashMap<u32, f64>,
    frames: Vec<Frame>,
    flat: Flat,
    iterations: u64,
}

pub(super) fn flatten(text: &str, source: &Path, trial: bool) -> Result<Option<Flat>> {
    let lines = lexer::lex_dialect(text, Dialect::Fanuc);
    let stmts: Vec<_> = lines.iter().map(|l| compile(text, l)).collect();
    if !has_flow(&stmts) {
        return Ok(None);
    }
    let mut programs: Vec<Program> = Vec::new();
    for (i, s) in stmts.iter().enumerate() {
        if let Ok(Stmt::Header) = s {
            let number = lines[i]
                .tokens
                .iter()
                .find_map(|t| match &t.kind {
                    TokenKind::OWord { name, .. } => name.parse::<u64>().ok(),
                    _ => None,
                })
                .unwrap_or(u64::MAX);
            if let Some(p) = programs.last_mut() {
                p.end = i;
            }
            programs.push(Program {
                number,
                start: i,
                end: lines.len(),
            });
        }
    }
    let mut labels: HashMap<u64, Vec<usize>> = HashMap::new();
    for (i, l) in lines.iter().enumerate() {
        let first = l.tokens.iter().find(|t| t.kind != TokenKind::Space);
        if let Some(TokenKind::Word {
            letter: b'N',
            value: WordValue::Number(n),
        }) = first.map(|t| &t.kind)
        {
            labels.entry(*n as u64).or_default().push(i);
        }
    }
    let mut run = Run {
        text,
        source,
        lines,
        stmts,
        programs,
        labels,
        partner: HashMap::new(),
        locals: vec![[None; 34]],
        commons: HashMap::new(),
        frames: Vec::new(),
        flat: Flat::new(text.len() * 2, trial),
        iterations: 0,
    };
    run.pair_loops()?;
    let main = run.main_range()?;
    run.run(main)?;
    // The closing `%` of the file, after the main program's end.
    let last = text
        .lines()
        .enumerate()
        .filter(|(_, l)| !l.trim().is_empty())
        .last();
    if let Some((i, l)) = last {
        if l.trim() == "%" && !run.flat.text.ends_with("%\n") {
            run.flat.push(source, i as u64 + 1, 0, "%")?;
        }
    }
    Ok(Some(run.flat))
}

impl Run<'_> {
    fn err(&self, pc: usize, word: &str, message: String, hint: &str) -> Error {
        let content = &self.text[self.lines[pc].span.clone()];
        let at = content
            .to_ascii_uppercase()
            .find(&word.to_ascii_uppercase())
            .unwrap_or(0);
        let chain = self.frames.last().map_or(0, |f| f.chain);
        Error::input(
            Location::cell(
                self.source,
                self.lines[pc].number,
                format!("{} ({word})", content[..at].chars().count() + 1),
            ),
            format!("{message}{}", self.flat.calls(chain)),
            hint,
        )
    }

    /// Pair each `WHILE … DOm` with its `ENDm` within each program.
    fn pair_loops(&mut self) -> Result<()> {
        let mut open: Vec<(u32, usize)> = Vec::new();
        for i in 0..self.stmts.len() {
            match &self.stmts[i] {
                Ok(Stmt::Header) => open.clear(),
                Ok(Stmt::While(_, m)) => open.push((*m, i)),
                Ok(Stmt::End(m)) => match open.pop() {
                    Some((om, w)) if om == *m => {
                        self.partner.insert(w, i);
                        self.partner.insert(i, w);
                    }
                    _ => {
                        self.stmts[i] = Err((
                            format!("END{m}"),
                            format!("END{m} does not close the innermost open DO{m}"),
                        ))
                    }
                },
                _ => {}
            }
        }
        Ok(())
    }

    /// The main program: the file before the first O number and the program that ends in
    /// M30/M02; with none, the first program that does not end in M99.
    fn main_range(&self) -> Result<(usize, usize)> {
        let n = self.lines.len();
        if self.programs.is_empty() {
            return Ok((0, n));
        }
        let has_m = |p: &Program, m: f64| {
            self.stmts[p.start..p.end].iter().any(|s| {
                matches!(s, Ok(Stmt::Words(ps)) if ps.iter().any(|p| matches!(p, Piece::Word { letter: b'M', value: Val::Num(v, _), .. } if *v == m)))
            })
        };
        let main = self
            .programs
            .iter()
            .position(|p| has_m(p, 30.0) || has_m(p, 2.0))
            .or_else(|| self.programs.iter().position(|p| !has_m(p, 99.0)));
        match main {
            Some(0) => Ok((0, self.programs[0].end)),
            Some(i) => Ok((self.programs[i].start, self.programs[i].end)),
            None => Err(Error::input(
                Location::line(self.source, self.lines[self.programs[0].start].number),
                "every program in the file ends in M99: they are subprograms, run from a main program errmap cannot see",
                "compensate the main program, with its subprograms in the same file",
            )),
        }
    }

    fn vars(&self) -> Vars<'_> {
        Vars {
            locals: self.locals.last().unwrap_or(&[None; 34]),
            commons: &self.commons,
        }
    }

    fn value(&self, pc: usize, word: &str, e: &Expr) -> Result<f64> {
        eval::value(e, Rules::Fanuc, &self.vars()).map_err(|m| {
            self.err(
                pc,
                word,
                format!("`{word}`: {m}"),
                "set the variable in the program before this line, or move the zone away from the moves that depend on it",
            )
        })
    }

    fn condition(&self, pc: usize, word: &str, e: &Expr) -> Result<bool> {
        Ok(self.value(pc, word, e)? != 0.0)
    }

    fn assign(&mut self, pc: usize, word: &str, var: &Var, e: &Expr) -> Result<()> {
        // `#1 = #0` (or another vacant variable alone) makes #1 vacant; in arithmetic a vacant
        // value is refused (the controller reads it as 0, a sign of a program error).
        let v = match e {
            Expr::Var(_) => eval::eval(e, Rules::Fanuc, &self.vars()).map_err(|m| {
                self.err(pc, word, format!("`{word}`: {m}"), "set the variable in the program before this line, or move the zone away from the moves that depend on it")
            })?,
            _ => Some(self.value(pc, word, e)?),
        };
        let n = match var {
            Var::Number(n) => *n,
            Var::Indirect(i) => {
                let k = self.value(pc, word, i)?;
                if k.fract() != 0.0 || !(0.0..1e9).contains(&k) {
                    return Err(self.err(
                        pc,
                        word,
                        format!("`{word}`: #{k} is not a variable"),
                        "fix the variable number",
                    ));
                }
                k as u32
            }
            Var::Named(_) => {
                return Err(self.err(
                    pc,
                    word,
                    "named variables are not Fanuc macro B".into(),
                    "use #1–#33, #100–#199 or #500–#999",
                ))
            }
        };
        match n {
            1..=33 => {
                if let Some(l) = self.locals.last_mut() {
                    l[n as usize] = v;
                }
            }
            100..=199 | 500..=999 => {
                match v {
                    Some(v) => self.commons.insert(n, v),
                    None => self.commons.remove(&n),
                };
            }
            0 => {
                return Err(self.err(
                    pc,
                    word,
                    "#0 is always vacant and cannot be set".into(),
                    "assign another variable",
                ))
            }
            _ => return Err(self.err(
                pc,
                word,
                format!(
                    "`{word}` sets a variable errmap does not follow: {}",
                    system_variable(n)
                ),
                "remove the assignment from the program errmap compensates, or move the zone away",
            )),
        }
        Ok(())
    }

    /// A backward jump to `target` from `pc`; refused past [`MAX_ITERATIONS`].
    fn turn(&mut self, pc: usize, target: usize) -> Result<()> {
        self.iterations += 1;
        if let Some(stop) = self.flat.over_budget(self.iterations) {
            return Err(stop);
        }
        if self.iterations > MAX_ITERATIONS {
            let word = self.text[self.lines[target].span.clone()]
                .trim()
                .to_string();
            let word: String = word.chars().take(30).collect();
            return Err(self.err(
                target,
                &word,
                format!(
                    "the loop from line {} back to this line runs more than {MAX_ITERATIONS} times (an endless loop?)",
                    self.lines[pc].number
                ),
                "check the loop's condition and counter",
            ));
        }
        Ok(())
    }

    fn goto(&mut self, pc: usize, word: &str, n: f64, range: (usize, usize)) -> Result<usize> {
        let found: Vec<usize> = (n.fract() == 0.0 && n >= 0.0)
            .then(|| self.labels.get(&(n as u64)))
            .flatten()
            .map(|v| {
                v.iter()
                    .copied()
                    .filter(|&i| i >= range.0 && i < range.1)
                    .collect()
            })
            .unwrap_or_default();
        match found.as_slice() {
            [t] => {
                if *t <= pc {
                    self.turn(pc, *t)?;
                }
                Ok(*t)
            }
            [] => Err(self.err(pc, word, format!("`{word}`: no block N{n} in this program"), "add the sequence number, or fix the jump")),
            _ => Err(self.err(pc, word, format!("`{word}`: N{n} numbers several blocks of this program, so the target depends on the controller's search"), "number the target block uniquely")),
        }
    }

    fn run(&mut self, main: (usize, usize)) -> Result<()> {
        let stmts = std::mem::take(&mut self.stmts);
        let mut pc = main.0;
        let mut range = main;
        let mut chain = 0u32;
        loop {
            if pc >= range.1 {
                if self.frames.is_empty() {
                    return Ok(());
                }
                let start = range.0;
                let num = self.lines[start].number;
                return Err(self.err(
                    start,
                    "O",
                    format!("the subprogram starting on line {num} ends without M99"),
                    "end the subprogram with M99",
                ));
            }
            let line_no = self.lines[pc].number;
            let stmt = match &stmts[pc] {
                Ok(s) => s,
                Err((w, m)) => {
                    return Err(self.err(pc, w, m.clone(), "write the statement as the Fanuc macro B manual gives it, or move the zone away"));
                }
            };
            let text = self.text;
            let content = &text[self.lines[pc].span.clone()];
            match stmt {
                Stmt::Copy => {
                    if content.trim() != "%" || self.frames.is_empty() {
                        self.flat.push(self.source, line_no, chain, content)?;
                    }
                    pc += 1;
                }
                Stmt::Header => {
                    if self.frames.is_empty() {
                        self.flat.push(self.source, line_no, chain, content)?;
                    }
                    pc += 1;
                }
                Stmt::Assign(v, e) => {
                    self.assign(pc, content.trim(), v, e)?;
                    pc += 1;
                }
                Stmt::IfGoto(c, n) => {
                    let w = content.trim();
                    if self.condition(pc, w, c)? {
                        let n = self.value(pc, w, n)?;
                        pc = self.goto(pc, w, n, range)?;
                    } else {
                        pc += 1;
                    }
                }
                Stmt::IfThen(c, v, e) => {
                    let w = content.trim();
                    if self.condition(pc, w, c)? {
                        self.assign(pc, w, v, e)?;
                    }
                    pc += 1;
                }
                Stmt::Goto(n) => {
                    let w = content.trim();
                    let n = self.value(pc, w, n)?;
                    pc = self.goto(pc, w, n, range)?;
                }
                Stmt::While(c, _) => {
                    let w = content.trim();
                    let Some(&end) = self.partner.get(&pc) else {
                        return Err(self.err(
                            pc,
                            "WHILE",
                            "a DO without its END".into(),
                            "close the loop with ENDm",
                        ));
                    };
                    pc = if self.condition(pc, w, c)? {
                        pc + 1
                    } else {
                        end + 1
                    };
                }
                Stmt::End(m) => {
                    let Some(&w) = self.partner.get(&pc) else {
                        return Err(self.err(
                            pc,
                            &format!("END{m}"),
                            format!("END{m} without its DO{m}"),
                            "open the loop with WHILE [ … ] DOm",
                        ));
                    };
                    self.turn(pc, w)?;
                    pc = w;
                }
                Stmt::Words(pieces) => match self.words(pc, pieces, chain, range)? {
                    Next::Line => pc += 1,
                    Next::Stop => return Ok(()),
                    Next::Call(frame, to, to_range, to_chain) => {
                        self.frames.push(frame);
                        pc = to;
                        range = to_range;
                        chain = to_chain;
                    }
                    Next::Return => {
                        let Some(f) = self.frames.last_mut() else {
                            return Err(Error::Internal("M99 without a caller".into()));
                        };
                        if f.repeats_left > 0 {
                            f.repeats_left -= 1;
                            let body = f.body;
                            self.turn(pc, body)?;
                            pc = body;
                        } else {
                            let f = self
                                .frames
                                .pop()
                                .ok_or_else(|| Error::Internal("no frame".into()))?;
                            if f.macro_call {
                                self.locals.pop();
                            }
                            pc = f.return_pc;
                            range = f.range;
                            chain = f.caller_chain;
                        }
                    }
                },
            }
        }
    }
}

/// Where control goes after a block of words.
enum Next {
    Line,
    Stop,
    Call(Frame, usize, (usize, usize), u32),
    Return,
}

/// Fanuc argument specification I: the local variable each G65 argument letter sets.
fn argument_variable(letter: u8) -> Option<usize> {
    Some(match letter {
        b'A' => 1,
        b'B' => 2,
        b'C' => 3,
        b'I' => 4,
        b'J' => 5,
        b'K' => 6,
        b'D' => 7,
        b'E' => 8,
        b'F' => 9,
        b'H' => 11,
        b'M' => 13,
        b'Q' => 17,
        b'R' => 18,
        b'S' => 19,
        b'T' => 20,
        b'U' => 21,
        b'V' => 22,
        b'W' => 23,
        b'X' => 24,
        b'Y' => 25,
        b'Z' => 26,
        _ => return None,
    })
}

/// A word's value after evaluation.
struct Word {
    letter: u8,
    value: f64,
    dot: bool,
    /// Index of its piece.
    piece: usize,
    /// The word as written.
    text: String,
}

impl Run<'_> {
    /// Evaluate a block's words, then run it: a call, a return, the end, or a block to write.
    fn words(
        &mut self,
        pc: usize,
        pieces: &[Piece],
        chain: u32,
        range: (usize, usize),
    ) -> Result<Next> {
        let mut words: Vec<Word> = Vec::new();
        for (i, p) in pieces.iter().enumerate() {
            let Piece::Word {
                letter,
                span,
                value,
            } = p
            else {
                continue;
            };
            let text = self.text[span.clone()].to_string();
            let (value, dot) = match value {
                Val::Num(v, dot) => (*v, *dot),
                Val::Expr(e) => match eval::eval(e, Rules::Fanuc, &self.vars()) {
                    Ok(Some(v)) => (v, true),
                    Ok(None) => {
                        return Err(self.err(
                            pc,
                            &text,
                            format!("`{text}`: the variable is vacant (never set), so the controller leaves the word out of the block"),
                            "set the variable before this line, or remove the word",
                        ))
                    }
                    Err(m) => {
                        return Err(self.err(
                            pc,
                            &text,
                            format!("`{text}`: {m}"),
                            "set the variable in the program before this line, or move the zone away from the moves that depend on it",
                        ))
                    }
                },
            };
            words.push(Word {
                letter: *letter,
                value,
                dot,
                piece: i,
                text,
            });
        }
        for w in &words {
            let from_expr = matches!(
                &pieces[w.piece],
                Piece::Word {
                    value: Val::Expr(..),
                    ..
                }
            );
            if w.letter == b'G' && from_expr {
                return Err(self.err(
                    pc,
                    &w.text,
                    format!("`{}`: a G code given by a variable", w.text),
                    "write the G code as a number",
                ));
            }
        }
        let code = |l: u8, c: f64| words.iter().any(|w| w.letter == l && w.value == c);
        let find = |l: u8| words.iter().find(|w| w.letter == l);
        if code(b'G', 66.0) {
            let w = find(b'G').map_or("G66".to_string(), |w| w.text.clone());
            return Err(self.err(pc, "G66", format!("`{w}`: a modal macro call (G66) runs the macro after every move, which errmap does not follow"), "call the macro with G65 at each position, or move the zone away"));
        }
        if code(b'G', 65.0) {
            return self.macro_call(pc, &words, chain, range);
        }
        if code(b'M', 98.0) || code(b'M', 97.0) {
            let local = code(b'M', 97.0);
            let keep: Vec<usize> = words
                .iter()
                .filter(|w| {
                    !matches!(w.letter, b'M' | b'P' | b'L')
                        || (w.letter == b'M' && !(w.value == 97.0 || w.value == 98.0))
                })
                .map(|w| w.piece)
                .collect();
            self.emit(pc, pieces, &words, &keep, chain)?;
            return self.call(pc, &words, local, chain, range);
        }
        if code(b'M', 99.0) {
            if self.frames.is_empty() {
                return Err(self.err(
                    pc,
                    "M99",
                    "M99 in the main program jumps back to its start, endlessly".into(),
                    "end the main program with M30",
                ));
            }
            if let Some(p) = find(b'P') {
                return Err(self.err(pc, &p.text.clone(), format!("`M99 {}` returns to a block number of the caller, which errmap does not follow", p.text), "return with a plain M99, or move the zone away"));
            }
            let keep: Vec<usize> = words
                .iter()
                .filter(|w| !(w.letter == b'M' && w.value == 99.0))
                .map(|w| w.piece)
                .collect();
            self.emit(pc, pieces, &words, &keep, chain)?;
            return Ok(Next::Return);
        }
        let all: Vec<usize> = words.iter().map(|w| w.piece).collect();
        self.emit(pc, pieces, &words, &all, chain)?;
        if code(b'M', 30.0) || code(b'M', 2.0) {
            return Ok(Next::Stop);
        }
        Ok(Next::Line)
    }

    /// Write the block with the words `keep` (by piece), values in plain numbers; a block
    /// left with no word but its sequence number is not written.
    fn emit(
        &mut self,
        pc: usize,
        pieces: &[Piece],
        words: &[Word],
        keep: &[usize],
        chain: u32,
    ) -> Result<()> {
        if !words
            .iter()
            .any(|w| keep.contains(&w.piece) && w.letter != b'N')
        {
            return Ok(());
        }
        let mut out = String::new();
        for (i, p) in pieces.iter().enumerate() {
            match p {
                Piece::Text(r) => out.push_str(&self.text[r.clone()]),
                Piece::Word { span, value, .. } => {
                    if !keep.contains(&i) {
                        continue;
                    }
                    match value {
                        Val::Num(..) => out.push_str(&self.text[span.clone()]),
                        Val::Expr(..) => {
                            let w = words
                                .iter()
                                .find(|w| w.piece == i)
                                .ok_or_else(|| Error::Internal("word".into()))?;
                            out.push_str(&self.text[span.start..span.start + 1]);
                            let v = if b"MSTHDNPLO".contains(&w.letter) {
                                w.value.round()
                            } else {
                                w.value
                            };
                            out.push_str(&format_value(w.letter, v));
                        }
                    }
                }
            }
        }
        let out = out.trim_end().to_string();
        self.flat
            .push(self.source, self.lines[pc].number, chain, &out)
    }

    /// `M98 P<n> L<k>` (or the old `M98 P<kkkk><nnnn>`), Haas `M97 P<label> L<k>`.
    fn call(
        &mut self,
        pc: usize,
        words: &[Word],
        local: bool,
        chain: u32,
        range: (usize, usize),
    ) -> Result<Next> {
        let name = match (local, words.iter().any(|w| w.letter == b'G')) {
            (true, _) => "M97",
            (false, true) => "G65",
            (false, false) => "M98",
        };
        let Some(p) = words.iter().find(|w| w.letter == b'P') else {
            return Err(self.err(
                pc,
                name,
                format!("{name} without P (the program to call)"),
                "give the subprogram number with P",
            ));
        };
        let l = words.iter().find(|w| w.letter == b'L');
        let mut times = match l {
            Some(l) if l.value.fract() == 0.0 && l.value >= 1.0 => l.value as u64,
            Some(l) => {
                return Err(self.err(
                    pc,
                    &l.text.clone(),
                    format!("`{}`: a repeat count must be a whole number ≥ 1", l.text),
                    "fix the repeat count",
                ))
            }
            None => 1,
        };
        let pv = p.value.round() as u64;
        let (start, sub_range, called) = if local {
            let found: Vec<usize> = self
                .labels
                .get(&pv)
                .map(|v| {
                    v.iter()
                        .copied()
                        .filter(|&i| i >= range.0 && i < range.1)
                        .collect()
                })
                .unwrap_or_default();
            match found.as_slice() {
                [t] => (*t, range, format!("N{pv}")),
                [] => {
                    return Err(self.err(
                        pc,
                        &p.text.clone(),
                        format!("`M97 {}`: no block N{pv} in this program", p.text),
                        "add the sequence number, or fix the call",
                    ))
                }
                _ => {
                    return Err(self.err(
                        pc,
                        &p.text.clone(),
                        format!("`M97 {}`: N{pv} numbers several blocks", p.text),
                        "number the target block uniquely",
                    ))
                }
            }
        } else {
            let by = |n: u64| self.programs.iter().find(|q| q.number == n);
            let old = (l.is_none() && pv >= 10_000).then_some((pv / 10_000, pv % 10_000));
            let target = match (by(pv), old.and_then(|(k, n)| by(n).map(|q| (k, q)))) {
                (Some(_), Some(_)) => {
                    return Err(self.err(pc, &p.text.clone(), format!("`{name} {}` is ambiguous: O{pv} called once, or O{} called {} times (the old P<count><number> form)", p.text, pv % 10_000, pv / 10_000), "write the repeat count with L"))
                }
                (Some(q), None) => q,
                (None, Some((k, q))) => {
                    times = k;
                    q
                }
                (None, None) => {
                    return Err(self.err(
                        pc,
                        &p.text.clone(),
                        format!("`{name} {}` calls subprogram O{pv}, which is not in this file: errmap runs subprograms of the same file only", p.text),
                        "copy the subprogram into this file after the main program (each starting with its O number, ending in M99), or move the zone away",
                    ))
                }
            };
            (
                target.start + 1,
                (target.start, target.end),
                format!("O{}", target.number),
            )
        };
        if self.frames.len() >= MAX_CALL_DEPTH {
            return Err(self.err(pc, name, format!("calls nested deeper than {MAX_CALL_DEPTH} levels (a subprogram calling itself?)"), "controllers allow fewer levels; check the calls"));
        }
        if times > 1 {
            self.turn(pc, pc)?;
        }
        let inner = self.flat.chain(chain, self.lines[pc].number, called);
        let frame = Frame {
            return_pc: pc + 1,
            range,
            caller_chain: chain,
            chain: inner,
            body: start,
            repeats_left: times - 1,
            macro_call: false,
        };
        Ok(Next::Call(frame, start, sub_range, inner))
    }

    /// `G65 P<n> L<k> A… B…`: a macro call with its arguments in new local variables.
    fn macro_call(
        &mut self,
        pc: usize,
        words: &[Word],
        chain: u32,
        range: (usize, usize),
    ) -> Result<Next> {
        let mut locals = [None; 34];
        let mut seen = Vec::new();
        for w in words {
            if matches!(w.letter, b'G' | b'P' | b'L' | b'N' | b'O') {
                continue;
            }
            let Some(v) = argument_variable(w.letter) else {
                return Err(self.err(
                    pc,
                    &w.text,
                    format!(
                        "`{}` is not a G65 argument (argument specification I)",
                        w.text
                    ),
                    "pass arguments with A–Z except G, L, N, O, P",
                ));
            };
            if seen.contains(&w.letter) {
                return Err(self.err(pc, &w.text, format!("`{}`: a repeated argument letter (argument specification II), which errmap does not follow", w.text), "give each argument letter once"));
            }
            seen.push(w.letter);
            if !w.dot && w.value != 0.0 {
                return Err(self.err(
                    pc,
                    &w.text,
                    format!("`{}`: an argument without a decimal point is read in the least input increment of its address, which depends on the machine (Fanuc manual, custom macro: argument specification)", w.text),
                    &format!("write it with a decimal point ({}.)", w.text),
                ));
            }
            locals[v] = Some(w.value);
        }
        if self.locals.len() > MAX_MACRO_LEVELS {
            return Err(self.err(
                pc,
                "G65",
                format!(
                    "macro calls nested deeper than the {MAX_MACRO_LEVELS} levels a Fanuc allows"
                ),
                "check the macro calls",
            ));
        }
        let plain: Vec<Word> = words
            .iter()
            .filter(|w| matches!(w.letter, b'P' | b'L' | b'G'))
            .map(|w| Word {
                letter: w.letter,
                value: w.value,
                dot: w.dot,
                piece: w.piece,
                text: w.text.clone(),
            })
            .collect();
        let next = self.call(pc, &plain, false, chain, range)?;
        let Next::Call(mut frame, to, to_range, inner) = next else {
            return Ok(next);
        };
        if frame.repeats_left > 0 {
            return Err(self.err(pc, "L", "G65 with a repeat count L, whose local variables on each repeat errmap does not follow".into(), "call the macro once per G65 block"));
        }
        frame.macro_call = true;
        self.locals.push(locals);
        Ok(Next::Call(frame, to, to_range, inner))
    }
}
