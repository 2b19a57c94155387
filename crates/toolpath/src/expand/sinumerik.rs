//! Sinumerik control flow run into plain blocks: R parameters and `DEF` variables, labels and `GOTOF`/`GOTOB`/`GOTO`/`GOTOC`, `IF`/`ELSE`/`ENDIF`, `WHILE`, `FOR`, `REPEAT`/`UNTIL`, `LOOP`, program-section repetition (`REPEAT`/`REPEATB … P=n`) and values written `X=expr`.
//!
//! Rules from the SINUMERIK 840D sl programming manuals (Fundamentals; Job Planning): label names
//! have 2–32 characters, the first two letters or underscores, and end in `:`; `GOTOF` searches
//! toward the program end, `GOTOB` toward its start, `GOTO` forward then backward, `GOTOC` like
//! `GOTO` without an alarm when the target is missing. An R parameter keeps the value left on
//! the controller, so one read before the program sets it is refused; `DEF` variables start at 0.
//! Any name that is neither an instruction nor a variable of the program is a subprogram call:
//! of a `PROC` defined in this file after the main program's end (run, its call-by-value
//! parameters and `DEF` variables local to the call, R parameters shared), else of a program not
//! in this file (refused).

mod expr;

use super::{expand_words, format_value, Flat, MAX_CALL_DEPTH, MAX_ITERATIONS};
use errmap_core::error::{Error, Location, Result};
use expr::{Env, X};
use std::collections::HashMap;
use std::path::Path;

/// Predefined instructions copied to the flattened program for the rewriter to judge (it
/// follows some, refuses the others with its own reasons).
const INSTRUCTIONS: &[&str] = &[
    "TRANS",
    "ATRANS",
    "ROT",
    "AROT",
    "RPL",
    "SCALE",
    "ASCALE",
    "MIRROR",
    "AMIRROR",
    "SUPA",
    "TRAFOOF",
    "TRAORI",
    "TRANSMIT",
    "TRACYL",
    "TRAANG",
    "SOFT",
    "BRISK",
    "DRIVE",
    "FFWON",
    "FFWOF",
    "CFC",
    "CFTCP",
    "CFIN",
    "COMPCAD",
    "COMPCURV",
    "COMPON",
    "COMPOF",
    "STOPRE",
    "MSG",
    "WORKPIECE",
    "SPOS",
    "SPOSA",
    "SETMS",
    "FNORM",
    "MCALL",
    "FLIN",
    "FCUB",
    "CUT2D",
    "CUT2DF",
    "CUT3DC",
    "DIAMON",
    "DIAMOF",
    "DIAM90",
    "ORIWKS",
    "ORIMKS",
    "ORIAXES",
    "ORIVECT",
    "RTLION",
    "RTLIOF",
    "CP",
    "PTP",
    "PTPG0",
    "TOFRAME",
    "TOROT",
    "TOROTOF",
    "PAROT",
    "PAROTOF",
    "SBLOF",
    "SBLON",
    "DISPLOF",
    "DISPLON",
    "WAITM",
    "WAITS",
    "WAITE",
    "STOPFIFO",
    "STARTFIFO",
    "FIFOCTRL",
    "TCOABS",
    "TCOFR",
    "LEADON",
    "LEADOF",
    "COUPON",
    "COUPOF",
    "POLY",
    "BSPLINE",
    "ASPLINE",
    "CSPLINE",
    "CIP",
    "CT",
    "SPATH",
    "UPATH",
    "FTOCON",
    "FTOCOF",
    "DYNNORM",
    "DYNPOS",
    "DYNROUGH",
    "DYNSEMIFIN",
    "DYNFINISH",
    "SETINT",
    "ENABLE",
    "DISABLE",
    "CLRINT",
    "PRIO",
    "ID",
    "IDS",
    "WHEN",
    "WHENEVER",
    "DO",
    "EVERY",
    "CPRECON",
    "CPRECOF",
    "UPATH",
    "OFFN",
    "G642",
    "G641",
    "G645",
    "G644",
    "G643",
    "ACC",
    "VELOLIM",
    "JERKLIM",
    "TOWSTD",
    "TOWMCS",
    "TOWWCS",
    "TOWBCS",
    "TOWTCS",
    "TOWKCS",
    "CALCPOSI",
    "PRESETON",
    "SETPIECE",
    "TURN",
    "CHF",
    "CHR",
    "RND",
    "RNDM",
    "FRC",
    "FRCM",
    "ADIS",
    "ADISPOS",
    "CR",
    "AP",
    "RP",
    "AR",
    "POLF",
    "POLFMASK",
    "LIFTFAST",
    "SETAL",
    "M",
    "H",
    "T",
    "D",
    "S",
    "F",
    "G",
    "L",
];

/// Whether a name is a Siemens standard cycle (left to the rewriter, which refuses or follows it).
fn is_cycle(name: &str) -> bool {
    ["CYCLE", "POCKET", "SLOT", "HOLES", "LONGHOLE", "E_", "F_"]
        .iter()
        .any(|p| name.starts_with(p))
}

/// A jump: which way the label is searched and the target (label name or block number).
#[derive(Debug, Clone)]
struct Jump {
    /// `GOTOF` 'F', `GOTOB` 'B', `GOTO` 'A', `GOTOC` 'C'.
    dir: u8,
    word: String,
    target: Target,
}

#[derive(Debug, Clone, PartialEq)]
enum Target {
    Label(String),
    Number(u64),
}

/// One item of a block: text copied as it is, or a value written `NAME=expr`.
#[derive(Debug)]
enum Item {
    Text(std::ops::Range<usize>),
    /// `NAME=expr` (NAME an address): the span of the whole item, the name as written and its
    /// value; `wrap` is `AC`/`IC`/… when the value is `AC(expr)`.
    Value {
        span: std::ops::Range<usize>,
        name: String,
        wrap: Option<String>,
        value: X,
    },
    /// A cycle call whose arguments use variables: the span and each argument's span/value.
    Cycle {
        span: std::ops::Range<usize>,
        name: String,
        args: Vec<(std::ops::Range<usize>, Option<X>)>,
    },
}

/// A variable assignment: an R parameter (by number) or a name.
#[derive(Debug)]
enum Lhs {
    R(X),
    Name(String),
}

#[derive(Debug)]
enum Stmt {
    /// Copied as it is (comments, blank lines, `%`, `MSG`, blocks without variables).
    Copy,
    /// Nothing to write (a label or block number alone, `PROC` of a program body, `DEF`).
    Skip,
    Block(Vec<Item>),
    Assign(Vec<(String, Lhs, X)>),
    Def(Vec<(String, Kind, Option<X>)>),
    If(X),
    IfGoto(X, Jump),
    Goto(Jump),
    Else,
    EndIf,
    While(X),
    EndWhile,
    For(String, Lhs, X, X),
    EndFor,
    Repeat,
    Until(X),
    Loop,
    EndLoop,
    /// `REPEAT a [b] P=n` / `REPEATB a P=n`: first label, last label (None: up to this line),
    /// count, and whether it is `REPEATB` (one block).
    Section(String, Option<String>, X, bool),
    Ret,
    /// A call of a `PROC` of this file: its name and, when written `NAME(…)`, each argument's
    /// text and value (`None`: left out, 0 per the manual).
    Call(String, Option<Vec<(String, Option<X>)>>),
    /// The `PROC` line of a subprogram defined after the main program's end.
    ProcStart(String),
}

#[derive(Debug, Clone, Copy, PartialEq)]
enum Kind {
    Real,
    Int,
    Bool,
}

/// A refusal found while compiling a line, raised only if the line runs: (word, message, hint).
type Bad = (String, String, String);

fn bad(word: &str, message: String, hint: &str) -> Bad {
    (word.to_string(), message, hint.to_string())
}

/// A line split into its parts: block number, label, body (comment removed) and comment.
struct Parts<'a> {
    number: Option<u64>,
    label: Option<String>,
    /// Byte range of `N… LABEL:` at the start (dropped from the output).
    head: std::ops::Range<usize>,
    body_start: usize,
    body: &'a str,
}

/// End of the text before a `;` comment outside quotes.
fn comment_start(s: &str) -> usize {
    let mut quote = false;
    for (i, c) in s.char_indices() {
        match c {
            '"' => quote = !quote,
            ';' if !quote => return i,
            _ => {}
        }
    }
    s.len()
}

fn ident_end(s: &str, from: usize) -> usize {
    s[from..]
        .find(|c: char| !(c.is_ascii_alphanumeric() || c == '_' || c == '$'))
        .map_or(s.len(), |e| from + e)
}

/// A label per the manual: 2+ characters, the first two letters or underscores, then letters,
/// digits or underscores.
fn is_label_name(name: &str) -> bool {
    let b = name.as_bytes();
    b.len() >= 2
        && b.len() <= 32
        && b[..2].iter().all(|c| c.is_ascii_alphabetic() || *c == b'_')
        && b.iter().all(|c| c.is_ascii_alphanumeric() || *c == b'_')
}

fn split(line: &str) -> Parts<'_> {
    let code_end = comment_start(line);
    let code = &line[..code_end];
    let mut i = code.len() - code.trim_start().len();
    let mut number = None;
    let bytes = code.as_bytes();
    if i < bytes.len() && (bytes[i] == b'N' || bytes[i] == b'n') {
        let d = bytes[i + 1..]
            .iter()
            .take_while(|c| c.is_ascii_digit())
            .count();
        let after = bytes.get(i + 1 + d).copied();
        if d > 0 && after.is_none_or(|c| c == b' ' || c == b'\t') {
            number = code[i + 1..i + 1 + d].parse().ok();
            i += 1 + d;
            i += code[i..].len() - code[i..].trim_start().len();
        }
    }
    let mut label = None;
    let e = ident_end(code, i);
    if e > i && code[e..].starts_with(':') && is_label_name(&code[i..e]) {
        label = Some(code[i..e].to_ascii_uppercase());
        i = e + 1;
        i += code[i..].len() - code[i..].trim_start().len();
    }
    let start = code.len() - code.trim_start().len();
    Parts {
        number,
        label,
        head: start..i,
        body_start: i,
        body: code[i..].trim_end(),
    }
}

fn upper_word(s: &str) -> (String, &str) {
    let e = ident_end(s, 0);
    (s[..e].to_ascii_uppercase(), &s[e..])
}

fn expr_err(text: &str, m: String) -> Bad {
    bad(
        text.trim(),
        format!("`{}`: {m}", text.trim()),
        "write the expression as the SINUMERIK programming manual gives it, or move the zone away",
    )
}

fn parse_cond(text: &str) -> std::result::Result<X, Bad> {
    expr::parse(text).map_err(|m| expr_err(text, m))
}

/// `GOTOF LABEL`, `GOTOB N100` …: the jump, from the keyword on.
fn jump(kw: &str, rest: &str) -> std::result::Result<Jump, Bad> {
    let dir = match kw {
        "GOTOF" => b'F',
        "GOTOB" => b'B',
        "GOTO" => b'A',
        "GOTOC" => b'C',
        _ => return Err(bad(kw, format!("`{kw}` is not a jump"), "")),
    };
    let t = rest.trim();
    let (name, after) = upper_word(t);
    if name.is_empty() || !after.trim().is_empty() {
        return Err(bad(
            kw,
            format!("`{kw} {t}`: the target is not a label or block number written in the program (a target in a variable is not run)"),
            "jump to a label (NAME:) or a block number (N100)",
        ));
    }
    let number = name
        .strip_prefix('N')
        .filter(|d| !d.is_empty() && d.bytes().all(|c| c.is_ascii_digit()))
        .and_then(|d| d.parse::<u64>().ok());
    let target = match number {
        Some(n) => Target::Number(n),
        None => Target::Label(name),
    };
    Ok(Jump {
        dir,
        word: format!("{kw} {t}"),
        target,
    })
}

/// A `DEF` line: `DEF REAL A=1, B` … (arrays and types other than REAL/INT/BOOL refused).
fn def(rest: &str) -> std::result::Result<Stmt, Bad> {
    let rest = rest.trim();
    let (ty, names) = upper_word(rest);
    let kind = match ty.as_str() {
        "REAL" => Kind::Real,
        "INT" => Kind::Int,
        "BOOL" => Kind::Bool,
        _ => {
            return Err(bad(
                "DEF",
                format!("`DEF {rest}`: variables of type {ty} are not run by errmap's {expand} (REAL, INT and BOOL are)", expand = expand_words()),
                "use REAL, INT or BOOL variables, or move the zone away",
            ))
        }
    };
    let mut out = Vec::new();
    for part in split_commas(names) {
        let part = part.trim();
        let (name, value) = match part.split_once('=') {
            Some((n, v)) => (n.trim(), Some(v)),
            None => (part, None),
        };
        if let Some((array, dim)) = name.split_once('[') {
            // An array sized by a name the program does not define: the size (and so the
            // program) depends on the controller's data.
            let dim = dim.trim_end_matches(']');
            let size = dim.split(',').find(|d| {
                let d = d.trim();
                !d.is_empty() && d.parse::<f64>().is_err()
            });
            let why = match size {
                Some(d) => format!(": its size {} is not defined in this program (a global user variable, machine data or macro of the controller, read at run time)", d.trim()),
                None => String::new(),
            };
            return Err(bad(
                size.map_or(array, |d| d.trim()),
                format!(
                    "`DEF {rest}`: arrays are not run by errmap's {expand}{why}",
                    expand = expand_words()
                ),
                "use single variables, or move the zone away",
            ));
        }
        if name.is_empty() || ident_end(name, 0) != name.len() || name.starts_with('$') {
            return Err(bad(
                "DEF",
                format!("`DEF {rest}`: `{name}` is not a variable name"),
                "fix the definition",
            ));
        }
        let value = value.map(parse_cond).transpose()?;
        out.push((name.to_ascii_uppercase(), kind, value));
    }
    Ok(Stmt::Def(out))
}

/// Split at commas outside parentheses, brackets and quotes.
fn split_commas(s: &str) -> Vec<&str> {
    let (mut depth, mut quote, mut from) = (0i32, false, 0);
    let mut out = Vec::new();
    for (i, c) in s.char_indices() {
        match c {
            '"' => quote = !quote,
            '(' | '[' if !quote => depth += 1,
            ')' | ']' if !quote => depth -= 1,
            ',' if !quote && depth == 0 => {
                out.push(&s[from..i]);
                from = i + 1;
            }
            _ => {}
        }
    }
    out.push(&s[from..]);
    out
}

/// A variable on the left of `=`: `R1`, `R[expr]`, a name.
fn lhs(name: &str, index: Option<&str>) -> std::result::Result<Option<Lhs>, Bad> {
    let upper = name.to_ascii_uppercase();
    if let Some(d) = upper.strip_prefix('R') {
        if !d.is_empty() && d.bytes().all(|c| c.is_ascii_digit()) && index.is_none() {
            let n: f64 = d.parse().map_err(|_| bad(name, "R".into(), ""))?;
            return Ok(Some(Lhs::R(X::Num(n))));
        }
        if d.is_empty() {
            if let Some(i) = index {
                return Ok(Some(Lhs::R(parse_cond(i)?)));
            }
        }
    }
    Ok(None)
}

/// The program's compiled lines and their structure.
struct Program<'a> {
    source: &'a Path,
    /// Per line: content and 1-based number.
    lines: Vec<(&'a str, u64)>,
    parts: Vec<Parts<'a>>,
    stmts: Vec<std::result::Result<Stmt, Bad>>,
    /// Partners: IF→ELSE/ENDIF, ELSE→ENDIF, loop start ↔ loop end.
    partner: HashMap<usize, usize>,
    else_of: HashMap<usize, usize>,
    /// Innermost control structure (its first line) each line is in, and each structure's parent.
    inside: Vec<Option<usize>>,
    parent: HashMap<usize, Option<usize>>,
    labels: HashMap<String, Vec<usize>>,
    numbers: HashMap<u64, Vec<usize>>,
    /// DEF variables declared anywhere (a name is a variable, not a call, from its DEF on).
    declared: HashMap<String, Kind>,
    /// The PROCs defined after the main program's end, by name.
    procs: HashMap<String, Proc>,
}

/// Compile one line's body.
fn compile(
    p: &Parts<'_>,
    declared: &HashMap<String, Kind>,
    procs: &HashMap<String, Proc>,
) -> std::result::Result<Stmt, Bad> {
    let body = p.body;
    if body.is_empty() {
        return Ok(if p.number.is_some() || p.label.is_some() {
            Stmt::Skip
        } else {
            Stmt::Copy
        });
    }
    if let Some(after) = body.strip_prefix('/') {
        let (kw, _) = upper_word(after.trim_start());
        if FLOW.contains(&kw.as_str()) || body.contains('=') {
            return Err(bad(
                "/",
                format!("`{body}`: block delete on a statement errmap runs, whose effect depends on the operator's switch"),
                "remove the `/`, or move the zone away",
            ));
        }
        return Ok(Stmt::Copy);
    }
    let (kw, rest) = upper_word(body);
    let rest_t = rest.trim();
    match kw.as_str() {
        "IF" => {
            let (cond, end) = expr::parse_prefix(rest).map_err(|m| expr_err(rest, m))?;
            let after = rest[end..].trim();
            if after.is_empty() {
                return Ok(Stmt::If(cond));
            }
            let (g, grest) = upper_word(after);
            if g.starts_with("GOTO") {
                return Ok(Stmt::IfGoto(cond, jump(&g, grest)?));
            }
            Err(expr_err(
                rest,
                format!("cannot read `{after}` after the condition"),
            ))
        }
        "ELSE" if rest_t.is_empty() => Ok(Stmt::Else),
        "ENDIF" if rest_t.is_empty() => Ok(Stmt::EndIf),
        "WHILE" => Ok(Stmt::While(parse_cond(rest)?)),
        "ENDWHILE" if rest_t.is_empty() => Ok(Stmt::EndWhile),
        "FOR" => {
            let Some((var, range)) = rest.split_once('=') else {
                return Err(bad(
                    "FOR",
                    format!("`{body}`: FOR variable = start TO end"),
                    "write FOR as the manual gives it",
                ));
            };
            let upper = range.to_ascii_uppercase();
            let Some(to) = upper.find(" TO ") else {
                return Err(bad(
                    "FOR",
                    format!("`{body}`: FOR variable = start TO end"),
                    "write FOR as the manual gives it",
                ));
            };
            let name = var.trim();
            let (n, idx) = match name.split_once('[') {
                Some((n, i)) => (n, Some(i.trim_end_matches(']'))),
                None => (name, None),
            };
            let target = match lhs(n, idx)? {
                Some(l) => l,
                None if declared.contains_key(&n.to_ascii_uppercase()) => Lhs::Name(n.to_ascii_uppercase()),
                None => return Err(bad(n, format!("`{body}`: the loop counter `{n}` is not an R parameter or a DEF variable of this program"), "define the counter with DEF INT, or move the zone away")),
            };
            Ok(Stmt::For(
                name.to_string(),
                target,
                parse_cond(&range[..to])?,
                parse_cond(&range[to + 4..])?,
            ))
        }
        "ENDFOR" if rest_t.is_empty() => Ok(Stmt::EndFor),
        "REPEAT" if rest_t.is_empty() => Ok(Stmt::Repeat),
        "UNTIL" => Ok(Stmt::Until(parse_cond(rest)?)),
        "LOOP" if rest_t.is_empty() => Ok(Stmt::Loop),
        "ENDLOOP" if rest_t.is_empty() => Ok(Stmt::EndLoop),
        "REPEAT" | "REPEATB" => {
            let upper = rest_t.to_ascii_uppercase();
            let (labels, count) = match upper.find("P=").or_else(|| upper.find("P =")) {
                Some(at) => (
                    &rest_t[..at],
                    Some(rest_t[at..].split_once('=').map_or("", |x| x.1)),
                ),
                None => (rest_t, None),
            };
            let names: Vec<String> = labels
                .split_whitespace()
                .map(|s| s.to_ascii_uppercase())
                .collect();
            let ok = match kw.as_str() {
                "REPEATB" => names.len() == 1,
                _ => (1..=2).contains(&names.len()),
            } && names.iter().all(|n| is_label_name(n));
            if !ok {
                return Err(bad(
                    &kw,
                    format!(
                        "`{body}`: {kw} takes a label{} and P=count",
                        if kw == "REPEAT" { " (or two)" } else { "" }
                    ),
                    "write the repetition as the manual gives it",
                ));
            }
            let count = count.map(parse_cond).transpose()?.unwrap_or(X::Num(1.0));
            let end = names.get(1).cloned();
            Ok(Stmt::Section(names[0].clone(), end, count, kw == "REPEATB"))
        }
        "GOTO" | "GOTOF" | "GOTOB" | "GOTOC" => Ok(Stmt::Goto(jump(&kw, rest)?)),
        "DEF" => def(rest),
        "PROC" => {
            if rest.contains('(') {
                let (name, _) = upper_word(rest_t);
                return Err(bad("PROC", format!("`{body}` is a subprogram whose parameters only its caller gives: it runs from a main program errmap cannot see, which is not in this file"), &format!("compensate the main program that calls {name}, with {name} written out in it, or move the zone away")));
            }
            Ok(Stmt::Skip)
        }
        "RET" if rest_t.is_empty() => Ok(Stmt::Ret),
        "CASE" | "ENDPROC" | "EXTERN" | "GOTOS" | "ENDLABEL" | "SETDEF" | "SAVE" => Err(bad(
            &kw,
            format!("`{body}`: errmap's {expand} does not run {kw}", expand = expand_words()),
            "write the program with IF/GOTO or loops, or move the zone away",
        )),
        // A modal call of a standard cycle (`MCALL CYCLE81(…)`) or its end (bare `MCALL`) is
        // the rewriter's to follow or refuse; a modal call of any other program is a call.
        "MCALL" if rest_t.is_empty() || is_cycle(&upper_word(rest_t).0) => {
            items(p, declared, procs)
        }
        // `CALL "NAME"` of a PROC of this file without parameters (CALL gives none).
        "CALL" if quoted_proc(rest_t, procs).is_some() => {
            let name = quoted_proc(rest_t, procs).unwrap_or_default();
            Ok(Stmt::Call(name, None))
        }
        "CALL" | "PCALL" | "EXTCALL" | "MCALL" if quoted_proc(rest_t, procs).is_some() || procs.contains_key(&upper_word(rest_t).0) => Err(bad(
            &kw,
            format!("`{body}`: errmap's {expand} does not run {kw} of a subprogram (it runs a call of a PROC of this file written `NAME(…)` or `CALL \"NAME\"` on a block of its own)", expand = expand_words()),
            "call the subprogram by its name on a block of its own, or move the zone away",
        )),
        "CALL" | "PCALL" | "EXTCALL" | "MCALL" => Err(bad(
            &kw,
            format!(
                "`{body}` calls a program which is not in this file, whose moves errmap cannot see"
            ),
            "compensate a program with the called program written out in it, or move the zone away",
        )),
        _ if procs.contains_key(&kw) => call(&kw, rest, body),
        _ => items(p, declared, procs),
    }
}

/// `"NAME"` (quoted, as `CALL` writes it) when NAME is a PROC of this file.
fn quoted_proc(rest: &str, procs: &HashMap<String, Proc>) -> Option<String> {
    let name = rest
        .strip_prefix('"')?
        .strip_suffix('"')?
        .to_ascii_uppercase();
    procs.contains_key(&name).then_some(name)
}

/// A call of a PROC of this file, alone on its block: `NAME` or `NAME(a, , c)`.
fn call(name: &str, rest: &str, body: &str) -> std::result::Result<Stmt, Bad> {
    let rest = rest.trim();
    if rest.is_empty() {
        return Ok(Stmt::Call(name.to_string(), None));
    }
    let alone = || {
        bad(
            name,
            format!("`{body}` calls the subprogram {name} of this file with other words on its block (a repetition `P`, or words errmap does not place before or after the call)"),
            "write the call alone on its block, or move the zone away",
        )
    };
    let Some(inner_and_after) = rest.strip_prefix('(') else {
        return Err(alone());
    };
    let (mut depth, mut quote, mut close) = (1i32, false, None);
    for (i, c) in inner_and_after.char_indices() {
        match c {
            '"' => quote = !quote,
            '(' if !quote => depth += 1,
            ')' if !quote => {
                depth -= 1;
                if depth == 0 {
                    close = Some(i);
                    break;
                }
            }
            _ => {}
        }
    }
    let Some(close) = close else {
        return Err(expr_err(rest, "`)` missing".into()));
    };
    if !inner_and_after[close + 1..].trim().is_empty() {
        return Err(alone());
    }
    let inner = &inner_and_after[..close];
    let mut args = Vec::new();
    if !inner.trim().is_empty() {
        for a in split_commas(inner) {
            let t = a.trim();
            let value = if t.is_empty() {
                None
            } else {
                Some(parse_cond(t)?)
            };
            args.push((t.to_string(), value));
        }
    }
    Ok(Stmt::Call(name.to_string(), Some(args)))
}

/// A subprogram defined in this file after the main program's end: `PROC NAME(REAL A, …)` up
/// to the next PROC or the end of the file.
struct Proc {
    /// Index of its PROC line, and of the line after its last.
    line: usize,
    end: usize,
    /// Its call-by-value parameters, or why a call of it is refused.
    params: std::result::Result<Vec<(String, Kind)>, Bad>,
}

/// The parameters of `PROC NAME(…) …` (`rest` after the name): REAL, INT and BOOL by value;
/// `VAR` (call by reference), arrays and other types refused; after `)` only DISPLOF/DISPLON/
/// SBLOF (SAVE restores the caller's modal G functions at the return, which errmap does not
/// follow).
fn proc_params(name: &str, rest: &str) -> std::result::Result<Vec<(String, Kind)>, Bad> {
    let head = format!("PROC {name}{rest}");
    let head = head.trim();
    let rest = rest.trim();
    let (inner, after) = match rest.strip_prefix('(') {
        Some(r) => match r.find(')') {
            Some(c) => (&r[..c], &r[c + 1..]),
            None => return Err(bad("PROC", format!("`{head}`: `)` missing"), "")),
        },
        None => ("", rest),
    };
    for w in after.split(|c: char| c.is_whitespace() || c == ',') {
        let w = w.to_ascii_uppercase();
        if !w.is_empty() && !["DISPLOF", "DISPLON", "SBLOF"].contains(&w.as_str()) {
            return Err(bad(
                &w,
                format!(
                    "`{head}`: errmap's {expand} does not run a PROC with {w}",
                    expand = expand_words()
                ),
                "remove it from the PROC line, or move the zone away",
            ));
        }
    }
    let mut out = Vec::new();
    if inner.trim().is_empty() {
        return Ok(out);
    }
    for part in split_commas(inner) {
        let words: Vec<String> = part
            .split_whitespace()
            .map(|w| w.to_ascii_uppercase())
            .collect();
        if words.first().map(String::as_str) == Some("VAR") {
            return Err(bad(
                "VAR",
                format!("`{head}`: `{}` is a call-by-reference parameter (VAR), which errmap's {expand} does not run", part.trim(), expand = expand_words()),
                "pass the value by value (without VAR) and return results in R parameters, or move the zone away",
            ));
        }
        let kind = match words.first().map(String::as_str) {
            Some("REAL") => Kind::Real,
            Some("INT") => Kind::Int,
            Some("BOOL") => Kind::Bool,
            _ => {
                return Err(bad(
                    "PROC",
                    format!("`{head}`: the parameter `{}` is not of type REAL, INT or BOOL, which errmap's {expand} runs", part.trim(), expand = expand_words()),
                    "use REAL, INT or BOOL parameters, or move the zone away",
                ))
            }
        };
        let pname = words.get(1).cloned().unwrap_or_default();
        if words.len() != 2
            || pname.starts_with('$')
            || ident_end(&pname, 0) != pname.len()
            || !pname.starts_with(|c: char| c.is_ascii_alphabetic() || c == '_')
        {
            return Err(bad(
                "PROC",
                format!(
                    "`{head}`: `{}` is not a parameter errmap's {expand} runs (arrays are not)",
                    part.trim(),
                    expand = expand_words()
                ),
                "use single REAL, INT or BOOL parameters, or move the zone away",
            ));
        }
        out.push((pname, kind));
    }
    Ok(out)
}

/// The control-flow statements (never copied).
const FLOW: &[&str] = &[
    "IF", "ELSE", "ENDIF", "WHILE", "ENDWHILE", "FOR", "ENDFOR", "REPEAT", "REPEATB", "UNTIL",
    "LOOP", "ENDLOOP", "GOTO", "GOTOF", "GOTOB", "GOTOC", "DEF", "PROC", "RET", "CASE",
];

/// A block of words, values and instructions; assignments to variables alone on their block.
fn items(
    p: &Parts<'_>,
    declared: &HashMap<String, Kind>,
    procs: &HashMap<String, Proc>,
) -> std::result::Result<Stmt, Bad> {
    let body = p.body;
    let base = p.body_start;
    let b = body.as_bytes();
    let mut i = 0;
    let mut out: Vec<Item> = Vec::new();
    let mut assigns: Vec<(String, Lhs, X)> = Vec::new();
    let mut others = false;
    let mut any_value = false;
    while i < b.len() {
        if b[i] == b' ' || b[i] == b'\t' {
            i += 1;
            continue;
        }
        let start = i;
        let c = b[i];
        if !(c.is_ascii_alphabetic() || c == b'_' || c == b'$') {
            // A stray character: the rest is copied for the rewriter to judge.
            out.push(Item::Text(base + start..base + b.len()));
            others = true;
            break;
        }
        let e = ident_end(body, i);
        let name = &body[i..e];
        let upper = name.to_ascii_uppercase();
        let mut j = e;
        let mut index = None;
        if b.get(j) == Some(&b'[') {
            let (inner_end, close) = body[j..]
                .find(']')
                .map_or((b.len(), b.len()), |k| (j + k, j + k + 1));
            index = Some(&body[j + 1..inner_end]);
            j = close;
        }
        let k = j + (body[j..].len() - body[j..].trim_start().len());
        let is_assign = b.get(k) == Some(&b'=') && b.get(k + 1) != Some(&b'=');
        if is_assign {
            let vs = k + 1;
            let (value, vend) =
                expr::parse_prefix(&body[vs..]).map_err(|m| expr_err(&body[start..], m))?;
            let end = vs + vend;
            let end = end - (body[vs..end].len() - body[vs..end].trim_end().len());
            let item_text = body[start..end].trim().to_string();
            if upper.starts_with('$') {
                return Err(bad(name, format!("`{item_text}` sets the system variable {upper}, whose effect errmap does not follow (its value is read at run time)"), "remove the assignment from the program errmap compensates, or move the zone away"));
            }
            if let Some(l) = lhs(name, index)? {
                assigns.push((item_text, l, value));
            } else if declared.contains_key(&upper) {
                if index.is_some() {
                    return Err(bad(
                        name,
                        format!(
                            "`{item_text}`: arrays are not run by errmap's {expand}",
                            expand = expand_words()
                        ),
                        "use single variables, or move the zone away",
                    ));
                }
                assigns.push((item_text, Lhs::Name(upper), value));
            } else {
                others = true;
                if index.is_some() {
                    return Err(bad(name, format!("`{item_text}`: an address with an index, whose value errmap does not run"), "write the address without an index, or move the zone away"));
                }
                let plain = matches!(value, X::Num(_) | X::Str(_))
                    || matches!(&value, X::Neg(a) if matches!(**a, X::Num(_)));
                let (wrap, value) = match value {
                    X::Call(f, mut args)
                        if [
                            "AC", "IC", "ACP", "ACN", "DC", "CAC", "CIC", "CACP", "CACN", "CDC",
                        ]
                        .contains(&f.as_str())
                            && args.len() == 1 =>
                    {
                        let inner = args.pop().unwrap_or(X::Num(0.0));
                        let plain_inner = matches!(inner, X::Num(_))
                            || matches!(&inner, X::Neg(a) if matches!(**a, X::Num(_)));
                        if plain_inner {
                            out.push(Item::Text(base + start..base + end));
                            i = end;
                            continue;
                        }
                        (Some(f), inner)
                    }
                    v => (None, v),
                };
                if plain {
                    out.push(Item::Text(base + start..base + end));
                } else {
                    any_value = true;
                    out.push(Item::Value {
                        span: base + start..base + end,
                        name: name.to_string(),
                        wrap,
                        value,
                    });
                }
            }
            i = end;
            continue;
        }
        others = true;
        if b.get(j) == Some(&b'(') {
            // `NAME(…)`: an instruction, a cycle, or a subprogram call with parameters.
            let mut depth = 0i32;
            let mut quote = false;
            let mut close = b.len();
            let mut inner_end = b.len();
            for (q, &ch) in b.iter().enumerate().skip(j) {
                match ch {
                    b'"' => quote = !quote,
                    b'(' if !quote => depth += 1,
                    b')' if !quote => {
                        depth -= 1;
                        if depth == 0 {
                            close = q + 1;
                            inner_end = q;
                            break;
                        }
                    }
                    _ => {}
                }
            }
            let whole = &body[start..close];
            if is_cycle(&upper) {
                let inner = &body[j + 1..inner_end];
                let mut args = Vec::new();
                let mut at = j + 1;
                let mut uses = false;
                for a in split_commas(inner) {
                    let t = a.trim();
                    let parsed = if t.is_empty() || t.starts_with('"') || t.parse::<f64>().is_ok() {
                        None
                    } else {
                        uses = true;
                        Some(expr::parse(t).map_err(|m| expr_err(t, m))?)
                    };
                    args.push((base + at..base + at + a.len(), parsed));
                    at += a.len() + 1;
                }
                if uses {
                    any_value = true;
                    out.push(Item::Cycle {
                        span: base + start..base + close,
                        name: name.to_string(),
                        args,
                    });
                } else {
                    out.push(Item::Text(base + start..base + close));
                }
            } else if INSTRUCTIONS.contains(&upper.as_str()) {
                out.push(Item::Text(base + start..base + close));
            } else if procs.contains_key(&upper) {
                return Err(call_among_words(&upper, body));
            } else {
                return Err(call_refusal(name, whole));
            }
            i = close;
            continue;
        }
        // A word: one letter and a number (`G1`, `X10.5`, `X-5`, `M30`); words may follow
        // without a space (`T1D1M6`, `G0G90X53.8`).
        if matches!(b.get(start + 1), Some(b'0'..=b'9' | b'.' | b'-' | b'+')) {
            let mut end = start + 1;
            if matches!(b[end], b'-' | b'+') {
                end += 1;
            }
            while end < b.len() && (b[end].is_ascii_digit() || b[end] == b'.') {
                end += 1;
            }
            if upper.starts_with('L') {
                return Err(call_refusal(&body[start..end], &body[start..end]));
            }
            out.push(Item::Text(base + start..base + end));
            i = end;
            continue;
        }
        if upper.starts_with('$')
            || declared.contains_key(&upper)
            || INSTRUCTIONS.contains(&upper.as_str())
            || is_cycle(&upper)
        {
            // An instruction (its arguments follow as items), or something the rewriter judges.
            out.push(Item::Text(base + start..base + j));
            i = j;
            continue;
        }
        if procs.contains_key(&upper) {
            return Err(call_among_words(&upper, body));
        }
        return Err(call_refusal(name, name));
    }
    if !assigns.is_empty() {
        if others {
            return Err(bad(&assigns[0].0, format!("`{body}`: a variable assignment on a block with other words, whose order errmap does not reproduce"), "write the assignment on a block of its own"));
        }
        return Ok(Stmt::Assign(assigns));
    }
    Ok(if any_value || p.label.is_some() {
        Stmt::Block(out)
    } else {
        Stmt::Copy
    })
}

/// A name that is no instruction and no variable: the controller runs it as a subprogram.
fn call_refusal(name: &str, whole: &str) -> Bad {
    let upper = name.to_ascii_uppercase();
    let note = if upper == "PRINTLN" {
        " (PRINTLN is no SINUMERIK instruction: the programming manuals list none, so the controller looks for a subprogram of that name)"
    } else {
        ""
    };
    bad(
        name,
        format!("`{}` calls the subprogram {upper}{note}, which is not in this file: errmap cannot see its moves", whole.trim()),
        "compensate a program with the subprogram written out in it (or post the program without subprogram calls), or move the zone away",
    )
}

/// A call of a PROC of this file on a block with other words.
fn call_among_words(name: &str, body: &str) -> Bad {
    bad(
        name,
        format!("`{body}` calls the subprogram {name} of this file on a block with other words, whose order errmap does not reproduce"),
        "write the call alone on its block, or move the zone away",
    )
}

/// Whether the program has anything to run (else the plain rewrite's answer stands).
fn has_flow(stmts: &[std::result::Result<Stmt, Bad>]) -> bool {
    stmts
        .iter()
        .any(|s| !matches!(s, Ok(Stmt::Copy) | Ok(Stmt::Skip)))
}

/// Whether a block ends the program (M30, M2, M17: the end of a program run on its own).
fn ends(p: &Parts<'_>) -> bool {
    // Words outside quoted texts (`MSG("M30")` ends nothing).
    p.body
        .split('"')
        .step_by(2)
        .flat_map(|part| part.split(|c: char| !c.is_ascii_alphanumeric()))
        .any(|w| {
            ["M30", "M2", "M02", "M17"]
                .iter()
                .any(|m| w.eq_ignore_ascii_case(m))
        })
}

/// A program-section repetition in progress.
struct Section {
    start: usize,
    /// Last line of the section.
    end: usize,
    left: u64,
    ret: usize,
}

struct Run<'a> {
    prog: Program<'a>,
    r: HashMap<u32, f64>,
    vars: HashMap<String, (Kind, f64)>,
    for_end: HashMap<usize, f64>,
    sections: Vec<Section>,
    flat: Flat,
    iterations: u64,
    /// The call chain of the lines run now (0: the main program).
    chain: u32,
    /// The calls of PROCs in progress, innermost last.
    frames: Vec<Frame>,
    /// The lines of the program unit run now (the main program or a PROC's body): jumps and
    /// section labels are searched in it.
    range: (usize, usize),
}

/// A PROC call in progress: what its return restores.
struct Frame {
    name: String,
    /// The call's line.
    call: usize,
    vars: HashMap<String, (Kind, f64)>,
    sections: Vec<Section>,
    chain: u32,
    range: (usize, usize),
}

struct Vars<'r> {
    r: &'r HashMap<u32, f64>,
    vars: &'r HashMap<String, (Kind, f64)>,
    declared: &'r HashMap<String, Kind>,
}

impl Env for Vars<'_> {
    fn r(&self, n: u32) -> std::result::Result<f64, String> {
        self.r.get(&n).copied().ok_or_else(|| format!("R{n} is read before the program sets it: an R parameter keeps the value left on the controller, which errmap knows only at run time"))
    }

    fn name(&self, name: &str) -> std::result::Result<f64, String> {
        if let Some((_, v)) = self.vars.get(name) {
            return Ok(*v);
        }
        if self.declared.contains_key(name) {
            return Err(format!(
                "{name} is read before its DEF runs, so the controller raises an alarm"
            ));
        }
        Err(format!("{name} is not defined in this program: a global user variable (GUD), machine data or macro of the controller, whose value is read at run time"))
    }
}

pub(super) fn flatten(text: &str, source: &Path, trial: bool) -> Result<Option<Flat>> {
    let mut lines = Vec::new();
    for (i, l) in text.split('\n').enumerate() {
        lines.push((l.strip_suffix('\r').unwrap_or(l), i as u64 + 1));
    }
    if text.ends_with('\n') {
        lines.pop();
    }
    let parts: Vec<Parts> = lines.iter().map(|(l, _)| split(l)).collect();
    // DEF names first, so a name used before (or after) its DEF is read as a variable.
    let mut declared = HashMap::new();
    for p in &parts {
        if let ("DEF", rest) = (upper_word(p.body).0.as_str(), upper_word(p.body).1) {
            if let Ok(Stmt::Def(d)) = def(rest) {
                for (n, k, _) in d {
                    declared.insert(n, k);
                }
            }
        }
    }
    // PROCs after the main program's end (a line with M30/M2/M17 or RET before them): the
    // subprograms of this file, each up to the next PROC or the end of the file.
    let mut procs: HashMap<String, Proc> = HashMap::new();
    let mut starts = Vec::new();
    let mut ended = false;
    for (i, p) in parts.iter().enumerate() {
        let (kw, rest) = upper_word(p.body);
        if kw == "PROC" && ended {
            let (name, after) = upper_word(rest.trim_start());
            if !name.is_empty() {
                starts.push((i, name, after));
            }
        }
        ended = ended || ends(p) || (kw == "RET" && rest.trim().is_empty());
    }
    for (k, (i, name, after)) in starts.iter().enumerate() {
        let end = starts.get(k + 1).map_or(parts.len(), |s| s.0);
        let mut params = proc_params(name, after);
        if let Ok(list) = &params {
            for (n, kind) in list {
                declared.entry(n.clone()).or_insert(*kind);
            }
        }
        if let Some(first) = procs.get(name) {
            params = Err(bad(
                name,
                format!(
                    "the subprogram {name} is defined twice in this file (lines {} and {})",
                    lines[first.line].1, lines[*i].1
                ),
                "name each PROC once",
            ));
        }
        procs.insert(
            name.clone(),
            Proc {
                line: *i,
                end,
                params,
            },
        );
    }
    let main_end = starts.first().map_or(parts.len(), |s| s.0);
    let mut stmts: Vec<_> = parts
        .iter()
        .map(|p| compile(p, &declared, &procs))
        .collect();
    for (i, name, _) in &starts {
        stmts[*i] = Ok(Stmt::ProcStart(name.clone()));
    }
    if !has_flow(&stmts) {
        return Ok(None);
    }
    let mut labels: HashMap<String, Vec<usize>> = HashMap::new();
    let mut numbers: HashMap<u64, Vec<usize>> = HashMap::new();
    for (i, p) in parts.iter().enumerate() {
        if let Some(l) = &p.label {
            labels.entry(l.clone()).or_default().push(i);
        }
        if let Some(n) = p.number {
            numbers.entry(n).or_default().push(i);
        }
    }
    let n = lines.len();
    let mut prog = Program {
        source,
        lines,
        parts,
        stmts,
        partner: HashMap::new(),
        else_of: HashMap::new(),
        inside: vec![None; n],
        parent: HashMap::new(),
        labels,
        numbers,
        declared,
        procs,
    };
    prog.pair();
    let mut run = Run {
        prog,
        r: HashMap::new(),
        vars: HashMap::new(),
        for_end: HashMap::new(),
        sections: Vec::new(),
        flat: Flat::new(text.len() * 2, trial),
        iterations: 0,
        chain: 0,
        frames: Vec::new(),
        range: (0, main_end),
    };
    run.run()?;
    Ok(Some(run.flat))
}

impl Program<'_> {
    /// Pair each structure's start with its end (a mismatch becomes the line's refusal).
    fn pair(&mut self) {
        let mut open: Vec<(usize, &'static str)> = Vec::new();
        for i in 0..self.stmts.len() {
            self.inside[i] = open.last().map(|o| o.0);
            let close = match &self.stmts[i] {
                Ok(Stmt::If(_)) => Some(("IF", None)),
                Ok(Stmt::While(_)) => Some(("WHILE", None)),
                Ok(Stmt::For(..)) => Some(("FOR", None)),
                Ok(Stmt::Repeat) => Some(("REPEAT", None)),
                Ok(Stmt::Loop) => Some(("LOOP", None)),
                Ok(Stmt::Else) => Some(("", Some("IF"))),
                Ok(Stmt::EndIf) => Some(("", Some("IF"))),
                Ok(Stmt::EndWhile) => Some(("", Some("WHILE"))),
                Ok(Stmt::EndFor) => Some(("", Some("FOR"))),
                Ok(Stmt::Until(_)) => Some(("", Some("REPEAT"))),
                Ok(Stmt::EndLoop) => Some(("", Some("LOOP"))),
                _ => None,
            };
            match close {
                Some((start, None)) => {
                    self.parent.insert(i, open.last().map(|o| o.0));
                    open.push((i, start));
                }
                Some((_, Some(want))) => {
                    let is_else = matches!(self.stmts[i], Ok(Stmt::Else));
                    match open.last() {
                        Some(&(s, k)) if k == want => {
                            if is_else {
                                if let std::collections::hash_map::Entry::Vacant(e) =
                                    self.else_of.entry(s)
                                {
                                    e.insert(i);
                                } else {
                                    self.stmts[i] = Err(bad(
                                        "ELSE",
                                        "a second ELSE of one IF".into(),
                                        "close the IF with ENDIF",
                                    ));
                                }
                            } else {
                                open.pop();
                                self.partner.insert(s, i);
                                self.partner.insert(i, s);
                            }
                        }
                        _ => {
                            let word = self.parts[i]
                                .body
                                .split_whitespace()
                                .next()
                                .unwrap_or("")
                                .to_string();
                            self.stmts[i] = Err(bad(
                                &word,
                                format!("`{word}` does not close an open {want}"),
                                "pair each control structure's start and end",
                            ));
                        }
                    }
                }
                None => {}
            }
        }
        for (s, k) in open {
            self.stmts[s] = Err(bad(
                k,
                format!("{k} without its end"),
                "close the control structure",
            ));
        }
    }
}

impl Run<'_> {
    fn err(&self, pc: usize, word: &str, message: String, hint: &str) -> Error {
        let (content, number) = self.prog.lines[pc];
        let at = content
            .to_ascii_uppercase()
            .find(&word.to_ascii_uppercase())
            .unwrap_or(0);
        Error::input(
            Location::cell(
                self.prog.source,
                number,
                format!("{} ({word})", content[..at].chars().count() + 1),
            ),
            format!("{message}{}", self.flat.calls(self.chain)),
            hint,
        )
    }

    fn env(&self) -> Vars<'_> {
        Vars {
            r: &self.r,
            vars: &self.vars,
            declared: &self.prog.declared,
        }
    }

    /// Evaluate `e` written as `text` on line `pc`; a refusal names the first variable in it.
    fn value(&self, pc: usize, text: &str, e: &X) -> Result<f64> {
        expr::value(e, &self.env()).map_err(|m| {
            let mut names = Vec::new();
            expr::names(e, &mut names);
            let word = names
                .into_iter()
                .find(|n| m.contains(n.as_str()))
                .unwrap_or_else(|| text.to_string());
            self.err(
                pc,
                &word,
                format!("`{}`: {m}", text.trim()),
                "set the variable in the program before this line, or move the zone away from the moves that depend on it",
            )
        })
    }

    fn set(&mut self, pc: usize, text: &str, target: &Lhs, v: f64) -> Result<()> {
        match target {
            Lhs::R(i) => {
                let n = self.value(pc, text, i)?;
                if n.fract() != 0.0 || !(0.0..1e6).contains(&n) {
                    return Err(self.err(
                        pc,
                        text,
                        format!("`{text}`: R[{n}] is not an R parameter"),
                        "fix the parameter number",
                    ));
                }
                self.r.insert(n as u32, v);
            }
            Lhs::Name(n) => {
                let Some(&(kind, _)) = self.vars.get(n) else {
                    return Err(self.err(pc, n, format!("`{text}`: {n} is set before its DEF runs, so the controller raises an alarm"), "define variables at the start of the program"));
                };
                // INT keeps the rounded value, BOOL whether it is not 0.
                let v = match kind {
                    Kind::Real => v,
                    Kind::Int => v.round(),
                    Kind::Bool => f64::from(u8::from(v != 0.0)),
                };
                self.vars.insert(n.clone(), (kind, v));
            }
        }
        Ok(())
    }

    /// A backward jump from `pc` to `target`; refused past [`MAX_ITERATIONS`].
    fn turn(&mut self, pc: usize, target: usize) -> Result<()> {
        self.iterations += 1;
        if let Some(stop) = self.flat.over_budget(self.iterations) {
            return Err(stop);
        }
        if self.iterations > MAX_ITERATIONS {
            let word: String = self.prog.parts[target]
                .body
                .trim()
                .chars()
                .take(30)
                .collect();
            let word = if word.is_empty() {
                self.prog.lines[target].0.trim().to_string()
            } else {
                word
            };
            return Err(self.err(
                target,
                &word,
                format!(
                    "the loop from line {} back to this line runs more than {MAX_ITERATIONS} times (an endless loop?)",
                    self.prog.lines[pc].1
                ),
                "check the loop's condition and counter",
            ));
        }
        Ok(())
    }

    /// The line a jump lands on, searched the way its keyword says.
    fn find(&self, pc: usize, j: &Jump) -> Result<Option<usize>> {
        let empty = Vec::new();
        let found = match &j.target {
            Target::Label(l) => self.prog.labels.get(l).unwrap_or(&empty),
            Target::Number(n) => self.prog.numbers.get(n).unwrap_or(&empty),
        };
        // Only the program unit run now (the main program or this PROC) is searched.
        let (lo, hi) = self.range;
        let found: Vec<usize> = found
            .iter()
            .copied()
            .filter(|t| (lo..hi).contains(t))
            .collect();
        if let (Target::Label(l), true) = (&j.target, found.len() > 1) {
            return Err(self.err(
                pc,
                &j.word,
                format!(
                    "`{}`: the label {l} marks several blocks, which the controller refuses",
                    j.word
                ),
                "name each label once",
            ));
        }
        let forward = found.iter().copied().find(|&t| t > pc);
        let backward = found.iter().copied().rev().find(|&t| t <= pc);
        let t = match j.dir {
            b'F' => forward,
            b'B' => backward,
            // A section's label: toward the program start first, then toward its end.
            b'S' => backward.or(forward),
            _ => forward.or(backward),
        };
        let Some(t) = t else {
            if j.dir == b'C' || j.dir == b'S' {
                return Ok(None);
            }
            let way = match j.dir {
                b'F' => " after this line",
                b'B' => " before this line",
                _ => "",
            };
            return Err(self.err(
                pc,
                &j.word,
                format!(
                    "`{}`: no such label or block number{way} in this program",
                    j.word
                ),
                "fix the jump's target",
            ));
        };
        // Into a control structure from outside it: the controller raises an alarm.
        let mut chain = Vec::new();
        let mut s = self.prog.inside[pc];
        while let Some(x) = s {
            chain.push(x);
            s = self.prog.parent.get(&x).copied().flatten();
        }
        if let Some(inner) = self.prog.inside[t] {
            if !chain.contains(&inner) {
                return Err(self.err(pc, &j.word, format!("`{}` jumps into a control structure (line {}), which the controller does not allow", j.word, self.prog.lines[inner].1), "jump to a label outside the loop or IF"));
            }
        }
        Ok(Some(t))
    }

    fn run(&mut self) -> Result<()> {
        let stmts = std::mem::take(&mut self.prog.stmts);
        let mut pc = 0usize;
        while pc < stmts.len() || !self.frames.is_empty() {
            if !self.frames.is_empty() && pc >= self.range.1 {
                // A PROC's last line run without M17/RET: it returns.
                match self.ret()? {
                    Some(n) => {
                        pc = n;
                        continue;
                    }
                    None => break,
                }
            }
            let (content, line_no) = self.prog.lines[pc];
            let stmt = match &stmts[pc] {
                Ok(s) => s,
                Err((w, m, h)) => {
                    let h = if h.is_empty() {
                        "write the statement as the SINUMERIK programming manual gives it, or move the zone away"
                    } else {
                        h
                    };
                    return Err(self.err(pc, w, m.clone(), h));
                }
            };
            let mut next = pc + 1;
            match stmt {
                Stmt::Copy => {
                    if ends(&self.prog.parts[pc]) {
                        if self.frames.is_empty() {
                            self.flat.push(self.prog.source, line_no, 0, content)?;
                            return Ok(());
                        }
                        self.end_of_call(pc, content)?;
                        match self.ret()? {
                            Some(n) => next = n,
                            None => return Ok(()),
                        }
                    } else {
                        self.flat
                            .push(self.prog.source, line_no, self.chain, content)?;
                    }
                }
                Stmt::Skip => {}
                Stmt::Block(items) => {
                    if self.block(pc, items)? {
                        match self.ret()? {
                            Some(n) => next = n,
                            None => return Ok(()),
                        }
                    }
                }
                Stmt::Assign(list) => {
                    for (t, target, e) in list {
                        let v = self.value(pc, t, e)?;
                        self.set(pc, t, target, v)?;
                    }
                }
                Stmt::Def(list) => {
                    for (n, k, e) in list {
                        let v = match e {
                            Some(e) => self.value(pc, n, e)?,
                            None => 0.0,
                        };
                        self.vars.insert(n.clone(), (*k, 0.0));
                        self.set(pc, n, &Lhs::Name(n.clone()), v)?;
                    }
                }
                Stmt::If(c) => {
                    if self.value(pc, content, c)? == 0.0 {
                        next = match self.prog.else_of.get(&pc) {
                            Some(&e) => e + 1,
                            None => self.partner(pc)? + 1,
                        };
                    }
                }
                Stmt::Else => {
                    let start = self.partner_of_else(pc)?;
                    next = self.partner(start)? + 1;
                }
                Stmt::EndIf | Stmt::Repeat | Stmt::Loop => {}
                Stmt::IfGoto(c, j) => {
                    if self.value(pc, content, c)? != 0.0 {
                        if let Some(t) = self.find(pc, j)? {
                            if t <= pc {
                                self.turn(pc, t)?;
                            }
                            next = t;
                        }
                    }
                }
                Stmt::Goto(j) => {
                    if let Some(t) = self.find(pc, j)? {
                        if t <= pc {
                            self.turn(pc, t)?;
                        }
                        next = t;
                    }
                }
                Stmt::While(c) => {
                    if self.value(pc, content, c)? == 0.0 {
                        next = self.partner(pc)? + 1;
                    }
                }
                Stmt::EndWhile => {
                    let w = self.partner(pc)?;
                    self.turn(pc, w)?;
                    next = w;
                }
                Stmt::For(t, target, a, b) => {
                    let start = self.value(pc, t, a)?;
                    let end = self.value(pc, content, b)?;
                    self.set(pc, t, target, start)?;
                    self.for_end.insert(pc, end);
                    if start > end {
                        next = self.partner(pc)? + 1;
                    }
                }
                Stmt::EndFor => {
                    let f = self.partner(pc)?;
                    let Ok(Stmt::For(t, target, ..)) = &stmts[f] else {
                        return Err(Error::Internal("ENDFOR without FOR".into()));
                    };
                    let now = match target {
                        Lhs::R(i) => self.value(f, t, &X::R(Box::new(i.clone())))?,
                        Lhs::Name(n) => self.value(f, t, &X::Name(n.clone()))?,
                    };
                    self.set(f, t, target, now + 1.0)?;
                    let end = self.for_end.get(&f).copied().unwrap_or(f64::NEG_INFINITY);
                    if now + 1.0 <= end {
                        self.turn(pc, f + 1)?;
                        next = f + 1;
                    }
                }
                Stmt::Until(c) => {
                    if self.value(pc, content, c)? == 0.0 {
                        let r = self.partner(pc)?;
                        self.turn(pc, r + 1)?;
                        next = r + 1;
                    }
                }
                Stmt::EndLoop => {
                    let l = self.partner(pc)?;
                    self.turn(pc, l + 1)?;
                    next = l + 1;
                }
                Stmt::Section(first, last, count, single) => {
                    next = self.section(pc, first, last.as_deref(), count, *single)?;
                }
                Stmt::Ret => match self.ret()? {
                    Some(n) => next = n,
                    None => return Ok(()),
                },
                Stmt::ProcStart(name) => {
                    if self.frames.is_empty() {
                        return Err(self.err(
                            pc,
                            "PROC",
                            format!("the main program runs on into the subprogram {name} defined on this line without ending"),
                            "end the main program with M30 before the PROC definitions",
                        ));
                    }
                    match self.ret()? {
                        Some(n) => next = n,
                        None => return Ok(()),
                    }
                }
                Stmt::Call(name, args) => {
                    next = self.call(pc, name, args.as_deref())?;
                }
            }
            // The end of a repeated section: again, or back after its REPEAT.
            if next == pc + 1 {
                next = self.after(pc)?;
            }
            pc = next;
        }
        Ok(())
    }

    /// The line to run after line `pc` ran to its end: the start of a repeated section again,
    /// back after its REPEAT, or the next line.
    fn after(&mut self, pc: usize) -> Result<usize> {
        let mut next = pc + 1;
        while let Some(s) = self.sections.last_mut() {
            if s.end != pc {
                break;
            }
            s.left -= 1;
            if s.left > 0 {
                let start = s.start;
                self.turn(pc, start)?;
                next = start;
                break;
            }
            next = s.ret;
            self.sections.pop();
        }
        Ok(next)
    }

    /// Run a call of a PROC of this file from line `pc`: its parameters bound (by value, each
    /// argument evaluated in the caller; one left out is 0, per the manual's "incomplete
    /// parameter transfer"), as the only local variables of the call; returns its first line.
    fn call(
        &mut self,
        pc: usize,
        name: &str,
        args: Option<&[(String, Option<X>)]>,
    ) -> Result<usize> {
        let content = self.prog.lines[pc].0.trim();
        let Some(proc) = self.prog.procs.get(name) else {
            return Err(Error::Internal(format!("no PROC {name}")));
        };
        let (line, end) = (proc.line, proc.end);
        let params = match &proc.params {
            Ok(p) => p.clone(),
            Err((_, m, h)) => {
                let def_line = self.prog.lines[line].1;
                let h = if h.is_empty() {
                    "write the PROC line as the SINUMERIK programming manual gives it, or move the zone away"
                } else {
                    h
                };
                return Err(self.err(
                    pc,
                    name,
                    format!("`{content}` calls {name} (PROC on line {def_line}): {m}"),
                    h,
                ));
            }
        };
        if self.frames.iter().any(|f| f.name == name) {
            return Err(self.err(
                pc,
                name,
                format!("`{content}` calls {name} while {name} runs (a recursive call), which errmap's {expand} does not run", expand = expand_words()),
                "write the repetition as a loop, or move the zone away",
            ));
        }
        if self.frames.len() >= MAX_CALL_DEPTH {
            return Err(self.err(
                pc,
                name,
                format!("`{content}`: subprogram calls nested deeper than {MAX_CALL_DEPTH} levels"),
                "check the calls",
            ));
        }
        let args = match args {
            Some(a) => a,
            None if params.is_empty() => &[][..],
            None => {
                return Err(self.err(
                    pc,
                    name,
                    format!("`{content}` calls {name} without its parameter list, which errmap's {expand} does not run", expand = expand_words()),
                    &format!("write the arguments, e.g. {name}(…), or move the zone away"),
                ))
            }
        };
        if args.len() > params.len() {
            return Err(self.err(
                pc,
                name,
                format!(
                    "`{content}` gives {} arguments to {name}, which takes {}, so the controller raises an alarm",
                    args.len(),
                    params.len()
                ),
                "fix the call's arguments",
            ));
        }
        let mut values = Vec::new();
        for (text, e) in args {
            values.push(match e {
                Some(e) => self.value(pc, text, e)?,
                None => 0.0,
            });
        }
        let mut vars = HashMap::new();
        for (k, (pname, kind)) in params.iter().enumerate() {
            let v = values.get(k).copied().unwrap_or(0.0);
            // INT keeps the rounded value, BOOL whether it is not 0 (as an assignment).
            let v = match kind {
                Kind::Real => v,
                Kind::Int => v.round(),
                Kind::Bool => f64::from(u8::from(v != 0.0)),
            };
            vars.insert(pname.clone(), (*kind, v));
        }
        let line_no = self.prog.lines[pc].1;
        let chain = self.flat.chain(self.chain, line_no, name.to_string());
        self.frames.push(Frame {
            name: name.to_string(),
            call: pc,
            vars: std::mem::replace(&mut self.vars, vars),
            sections: std::mem::take(&mut self.sections),
            chain: self.chain,
            range: self.range,
        });
        self.chain = chain;
        self.range = (line + 1, end);
        Ok(line + 1)
    }

    /// Return from the innermost PROC call: the line after the call (or the start of a section
    /// the call ends), `None` in the main program (its end).
    fn ret(&mut self) -> Result<Option<usize>> {
        let Some(f) = self.frames.pop() else {
            return Ok(None);
        };
        self.vars = f.vars;
        self.sections = f.sections;
        self.chain = f.chain;
        self.range = f.range;
        self.after(f.call).map(Some)
    }

    /// A line ending a PROC call: M17 returns (the line is written without it); M2/M30 in a
    /// subprogram is refused.
    fn end_of_call(&mut self, pc: usize, text: &str) -> Result<()> {
        let (code, comment) = text.split_at(comment_start(text));
        let mut kept = Vec::new();
        for w in code.split_whitespace() {
            let u = w.to_ascii_uppercase();
            if ["M30", "M2", "M02"].contains(&u.as_str()) {
                return Err(self.err(
                    pc,
                    w,
                    format!("`{}` ends the program inside a subprogram, which errmap's {expand} does not run (whether it returns or ends is not confirmed in the manual)", text.trim(), expand = expand_words()),
                    "end the subprogram with M17 or RET, or move the zone away",
                ));
            }
            if u != "M17" {
                kept.push(w);
            }
        }
        let only_number = kept.len() == 1
            && kept[0].len() > 1
            && kept[0].starts_with(['N', 'n'])
            && kept[0][1..].bytes().all(|c| c.is_ascii_digit());
        if kept.is_empty() || only_number {
            return Ok(());
        }
        let mut out = kept.join(" ");
        if !comment.is_empty() {
            out.push(' ');
            out.push_str(comment);
        }
        let line_no = self.prog.lines[pc].1;
        self.flat.push(self.prog.source, line_no, self.chain, &out)
    }

    fn partner(&self, pc: usize) -> Result<usize> {
        self.prog
            .partner
            .get(&pc)
            .copied()
            .ok_or_else(|| Error::Internal(format!("no partner of line {}", pc + 1)))
    }

    fn partner_of_else(&self, pc: usize) -> Result<usize> {
        self.prog
            .else_of
            .iter()
            .find(|(_, &e)| e == pc)
            .map(|(&s, _)| s)
            .ok_or_else(|| Error::Internal("ELSE without IF".into()))
    }

    /// `REPEAT a P=n` (from label a up to this line), `REPEAT a b P=n` (a to b), `REPEATB a
    /// P=n` (the block a): run the section n times, then go on after this line.
    fn section(
        &mut self,
        pc: usize,
        first: &str,
        last: Option<&str>,
        count: &X,
        single: bool,
    ) -> Result<usize> {
        let content = self.prog.lines[pc].0;
        let n = self.value(pc, content, count)?;
        if n.fract() != 0.0 || n < 0.0 {
            return Err(self.err(
                pc,
                "P",
                format!("`{}`: P must be a whole number ≥ 0", content.trim()),
                "fix the repetition count",
            ));
        }
        let jump = |name: &str, dir: u8| Jump {
            dir,
            word: name.to_string(),
            target: Target::Label(name.to_string()),
        };
        let start = if single || last.is_some() {
            self.find(pc, &jump(first, b'S'))?
        } else {
            self.find(pc, &jump(first, b'B'))?
        };
        let Some(start) = start else {
            return Err(self.err(
                pc,
                first,
                format!("`{}`: no label {first} in this program", content.trim()),
                "fix the label",
            ));
        };
        let end = match (single, last) {
            (true, _) => start,
            (false, None) => pc.saturating_sub(1),
            (false, Some(l)) => {
                let found = self
                    .prog
                    .labels
                    .get(l)
                    .and_then(|v| v.iter().copied().find(|&t| t >= start && t < self.range.1));
                match found {
                    Some(e) => e,
                    None => {
                        return Err(self.err(
                            pc,
                            l,
                            format!("`{}`: no label {l} after {first}", content.trim()),
                            "fix the labels",
                        ))
                    }
                }
            }
        };
        if n == 0.0 || end < start || (start..=end).contains(&pc) {
            if (start..=end).contains(&pc) && n > 0.0 {
                return Err(self.err(
                    pc,
                    first,
                    format!(
                        "`{}`: the section repeats this REPEAT line itself",
                        content.trim()
                    ),
                    "end the section before the REPEAT line",
                ));
            }
            return Ok(pc + 1);
        }
        if self.sections.len() >= 64 {
            return Err(self.err(
                pc,
                first,
                "section repetitions nested deeper than 64 levels".into(),
                "check the repetitions",
            ));
        }
        self.turn(pc, start)?;
        self.sections.push(Section {
            start,
            end,
            left: n as u64,
            ret: pc + 1,
        });
        Ok(start)
    }

    /// Write a block with its values evaluated; `true` at the program's end (M30, M2, M17).
    fn block(&mut self, pc: usize, items: &[Item]) -> Result<bool> {
        let (content, line_no) = self.prog.lines[pc];
        let parts = &self.prog.parts[pc];
        let mut out = String::new();
        // The block number is kept; a label is dropped (nothing jumps in the flat program).
        if let Some(n) = parts.number {
            let _ = n;
            let head = &content[parts.head.clone()];
            let num_end = head.find(|c: char| c.is_whitespace()).unwrap_or(head.len());
            out.push_str(&head[..num_end]);
        }
        let mut words = String::new();
        let mut last = parts.body_start;
        for it in items {
            match it {
                Item::Text(r) => {
                    words.push_str(&content[last..r.end]);
                    last = r.end;
                }
                Item::Value {
                    span,
                    name,
                    wrap,
                    value,
                } => {
                    words.push_str(&content[last..span.start]);
                    let text = &content[span.clone()];
                    let v = self.value(pc, text, value)?;
                    let letter = name.as_bytes().first().copied().unwrap_or(b'X');
                    let v = if b"MSTHDNPLGO".contains(&letter.to_ascii_uppercase())
                        && name.len() == 1
                    {
                        v.round()
                    } else {
                        v
                    };
                    let num = format_value(letter, v);
                    match wrap {
                        Some(w) => words.push_str(&format!("{name}={w}({num})")),
                        None => words.push_str(&format!("{name}={num}")),
                    }
                    last = span.end;
                }
                Item::Cycle { span, name, args } => {
                    words.push_str(&content[last..span.start]);
                    let mut parts_out = Vec::new();
                    for (r, e) in args {
                        match e {
                            Some(e) => {
                                let t = &content[r.clone()];
                                let v = self.value(pc, t, e)?;
                                parts_out.push(format_value(b'X', v));
                            }
                            None => parts_out.push(content[r.clone()].trim().to_string()),
                        }
                    }
                    words.push_str(&format!("{name}({})", parts_out.join(",")));
                    last = span.end;
                }
            }
        }
        words.push_str(&content[last..]);
        let words = words.trim();
        if !words.is_empty() || content[parts.body_start..].contains(';') {
            if !out.is_empty() && !words.is_empty() {
                out.push(' ');
            }
            out.push_str(words);
        }
        let end = ends(parts);
        if end && !self.frames.is_empty() {
            self.end_of_call(pc, &out)?;
            return Ok(true);
        }
        if out.trim().is_empty() || (parts.number.is_some() && words.is_empty()) {
            return Ok(end);
        }
        self.flat
            .push(self.prog.source, line_no, self.chain, &out)?;
        Ok(end)
    }
}
