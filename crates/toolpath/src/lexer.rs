//! G-code lexer that keeps the byte span of every token, so unchanged lines can be copied byte for byte.
//!
//! RS274/NGC (LinuxCNC dialect): words are a letter and a value, case-insensitive; spaces and
//! tabs may sit between the letter and its value; values are numbers, `#` parameter references
//! or `[expressions]`. Comments are `( … )` and `;` to the end of the line. `%` delimits the
//! program. `O` words are flow control (sub, call, while, if, repeat …). `#name = value` assigns
//! a parameter. Polar words `@` (radius) and `^` (angle) are lexed like letters.
//! Nothing is evaluated here: see `expr` for the small evaluator used to classify moves.
//!
//! Dialect deltas: Fanuc macro B statements (`WHILE`, `IF`, `GOTO`, `END`) and Sinumerik
//! instructions (`TRANS`, `DEF`, …) are [`TokenKind::Keyword`] running to the end of the block;
//! Sinumerik writes `X=10`, `X=AC(10)`, `X=IC(1)`, `CR=5` (lexed as an `R` word), `R1=5` (an
//! assignment) and only `;` comments; Heidenhain ISO blocks end in `*` and `%` lines are headers.
//! Every byte is looked at a bounded number of times: lexing is linear in the line length.

use super::dialect::Dialect;
use std::ops::Range;

/// What a token is. The tokens of a line tile its content exactly.
#[derive(Debug, Clone, PartialEq)]
pub enum TokenKind {
    /// A word: upper-cased letter (or `@`/`^`) and its value.
    Word {
        /// The address: an upper-case ASCII letter, or `@`/`^` for polar words.
        letter: u8,
        /// The word's value as written.
        value: WordValue,
    },
    /// `( … )` comment (also `(msg, …)`, `(debug, …)`).
    Comment,
    /// `;` comment to the end of the line.
    LineComment,
    /// `%` program delimiter.
    Percent,
    /// `#n = value` or `#<name> = value`: `target` is the normalised parameter name.
    Assignment {
        /// The parameter assigned, normalised ([`param_name`]): `1`, `<level>`.
        target: String,
        /// Byte range of the right-hand side in the program text (not evaluated here).
        value_span: Range<usize>,
    },
    /// An O-word line: `keyword` is `sub`, `endsub`, `call`, `while`, … (lower case).
    OWord {
        /// The O-word's number or `<name>`, normalised ([`param_name`]): `100`, `<probe>`.
        name: String,
        /// The flow-control keyword after it, lower case; empty when there is none.
        keyword: String,
    },
    /// Spaces and tabs.
    Space,
    /// A dialect statement or instruction (`WHILE`, `GOTO`, `TRANS`, `DEF`, a Heidenhain `%`
    /// header …): `name` upper-cased; the token runs to the end of the block.
    Keyword {
        /// The statement's name, upper case (`WHILE`, `TRANS`).
        name: String,
    },
    /// Anything else (a letter without a value, a stray character).
    Other,
}

/// The value of a word.
#[derive(Debug, Clone, PartialEq)]
pub enum WordValue {
    /// A literal number.
    Number(f64),
    /// A `#` parameter reference, `[expression]` or function: its text span (not evaluated here).
    Expr(Range<usize>),
    /// Sinumerik `X=AC(…)`: an absolute value whatever G90/G91 say.
    Abs(f64),
    /// Sinumerik `X=IC(…)`: an incremental value whatever G90/G91 say.
    Inc(f64),
}

/// One token of a line: its kind and where it lies in the program text.
#[derive(Debug, Clone, PartialEq)]
pub struct Token {
    /// What the token is.
    pub kind: TokenKind,
    /// Byte range of the token in the whole program text (not the line).
    pub span: Range<usize>,
}

/// One line of the program: `span` is its content, `end` the byte after its terminator
/// (`\n` or `\r\n`, or nothing on a last line without one).
#[derive(Debug, Clone)]
pub struct Line {
    /// 1-based line number as an editor shows it.
    pub number: u64,
    /// Byte range of the line's content in the program text, without its terminator.
    pub span: Range<usize>,
    /// Byte offset just after the line's terminator: where the next line starts.
    pub end: usize,
    /// The line's tokens in order; they tile `span` exactly.
    pub tokens: Vec<Token>,
}

impl Line {
    /// The line terminator (`"\n"`, `"\r\n"` or `""`).
    pub fn terminator<'a>(&self, text: &'a str) -> &'a str {
        text.get(self.span.end..self.end).unwrap_or("")
    }
}

/// Split a LinuxCNC program into lines and tokens. Never fails: what it cannot read becomes `Other`.
pub fn lex(text: &str) -> Vec<Line> {
    lex_dialect(text, Dialect::Linuxcnc)
}

/// [`lex`] with the lexing rules of `dialect`.
pub fn lex_dialect(text: &str, dialect: Dialect) -> Vec<Line> {
    let mut lines = Vec::new();
    let _ = for_each_line(text, dialect, |line| {
        lines.push(line.clone());
        Ok::<(), std::convert::Infallible>(())
    });
    lines
}

/// Lex `text` line by line into one reused [`Line`] and hand each to `f`, stopping at its
/// first error: memory stays that of one line, however long the program.
pub fn for_each_line<E>(
    text: &str,
    dialect: Dialect,
    mut f: impl FnMut(&Line) -> Result<(), E>,
) -> Result<(), E> {
    let bytes = text.as_bytes();
    let mut line = Line {
        number: 0,
        span: 0..0,
        end: 0,
        tokens: Vec::new(),
    };
    let mut start = 0usize;
    while start < bytes.len() {
        let nl = bytes[start..]
            .iter()
            .position(|&b| b == b'\n')
            .map(|p| start + p);
        let (content_end, end) = match nl {
            Some(p) => {
                let ce = if p > start && bytes[p - 1] == b'\r' {
                    p - 1
                } else {
                    p
                };
                (ce, p + 1)
            }
            None => (bytes.len(), bytes.len()),
        };
        line.number += 1;
        line.span = start..content_end;
        line.end = end;
        line.tokens.clear();
        lex_line_into(bytes, start, content_end, dialect, &mut line.tokens);
        f(&line)?;
        start = end;
    }
    Ok(())
}

fn is_space(b: u8) -> bool {
    b == b' ' || b == b'\t'
}

/// Fanuc custom macro B statements.
const FANUC_KEYWORDS: [&str; 10] = [
    "WHILE", "IF", "GOTO", "DO", "END", "THEN", "POPEN", "PCLOS", "DPRNT", "BPRNT",
];

fn letter_run(b: &[u8], i: usize, end: usize) -> usize {
    let mut j = i;
    while j < end && b[j].is_ascii_alphabetic() {
        j += 1;
    }
    j
}

/// A keyword token from `i` to the end of the block (before a `;` comment).
fn keyword(b: &[u8], i: usize, name_end: usize, end: usize) -> (TokenKind, usize) {
    let mut m = name_end;
    while m < end && b[m] != b';' {
        m += 1;
    }
    while m > name_end && is_space(b[m - 1]) {
        m -= 1;
    }
    let name = String::from_utf8_lossy(&b[i..name_end]).to_ascii_uppercase();
    (TokenKind::Keyword { name }, m)
}

fn lex_line_into(b: &[u8], start: usize, end: usize, dialect: Dialect, tokens: &mut Vec<Token>) {
    let mut i = start;
    while i < end {
        let c = b[i];
        let run = if c.is_ascii_alphabetic() {
            letter_run(b, i, end)
        } else {
            i
        };
        let (kind, next) = if is_space(c) {
            let mut j = i;
            while j < end && is_space(b[j]) {
                j += 1;
            }
            (TokenKind::Space, j)
        } else if dialect == Dialect::Fanuc
            && run - i >= 2
            && FANUC_KEYWORDS
                .iter()
                .any(|k| k.as_bytes().eq_ignore_ascii_case(&b[i..run]))
        {
            keyword(b, i, run, end)
        } else if dialect == Dialect::Sinumerik && c != b';' && !is_space(c) {
            lex_siemens(b, i, run, end)
        } else if dialect == Dialect::Heidenhain && c == b'*' {
            (TokenKind::LineComment, end)
        } else if dialect == Dialect::Heidenhain && c == b'%' {
            keyword(b, i, i + 1, end)
        } else if c == b'(' {
            let j = b[i..end]
                .iter()
                .position(|&x| x == b')')
                .map(|p| i + p + 1)
                .unwrap_or(end);
            (TokenKind::Comment, j)
        } else if c == b';' {
            (TokenKind::LineComment, end)
        } else if c == b'%' {
            (TokenKind::Percent, i + 1)
        } else if c == b'#' {
            lex_assignment(b, i, end, dialect)
        } else if c == b'o' || c == b'O' {
            lex_oword(b, i, end)
        } else if c.is_ascii_alphabetic() || c == b'@' || c == b'^' {
            match lex_word(b, i, end) {
                // A run of letters that is no word: one token, so it is not rescanned.
                (TokenKind::Other, _) if run > i + 1 => (TokenKind::Other, run),
                t => t,
            }
        } else {
            // Keep multi-byte UTF-8 characters whole so every span is a valid `str` range.
            let mut j = i + 1;
            while j < end && (0x80..0xC0).contains(&b[j]) {
                j += 1;
            }
            (TokenKind::Other, j)
        };
        tokens.push(Token {
            kind,
            span: i..next,
        });
        i = next;
    }
}

fn skip_spaces(b: &[u8], mut i: usize, end: usize) -> usize {
    while i < end && is_space(b[i]) {
        i += 1;
    }
    i
}

/// A number: optional sign, digits and one decimal point; spaces between digits are allowed
/// (LinuxCNC ignores them). Returns the end and the value.
fn lex_number(b: &[u8], i: usize, end: usize) -> Option<(usize, f64)> {
    // Fast path: sign, digits and a point with no spaces inside.
    let s = skip_spaces(b, i, end);
    let mut j = s;
    if j < end && (b[j] == b'+' || b[j] == b'-') {
        j += 1;
    }
    let (mut digits, mut dot) = (0, false);
    // The digits as an integer and how many of them follow the point, while that is exact.
    let (mut mantissa, mut fraction_digits) = (0u64, 0usize);
    while j < end && (b[j].is_ascii_digit() || (b[j] == b'.' && !dot)) {
        if b[j] == b'.' {
            dot = true;
        } else {
            digits += 1;
            mantissa = mantissa
                .wrapping_mul(10)
                .wrapping_add(u64::from(b[j] - b'0'));
            fraction_digits += usize::from(dot);
        }
        j += 1;
    }
    // Spaces after the number end it unless more digits follow them.
    let k = skip_spaces(b, j, end);
    let more = k > j && k < end && (b[k].is_ascii_digit() || (b[k] == b'.' && !dot));
    if digits > 0 && !more {
        let negative = b[s] == b'-';
        if let Some(v) = exact_decimal(mantissa, digits, fraction_digits, negative) {
            return Some((j, v));
        }
        let v: f64 = std::str::from_utf8(&b[s..j]).ok()?.parse().ok()?;
        return Some((j, v));
    }
    lex_number_spaced(b, i, end)
}

/// `±mantissa × 10^-fraction_digits` when both factors are exact in an f64, so that one
/// division rounds correctly and gives the same value as `str::parse` (Clinger's fast path).
fn exact_decimal(
    mantissa: u64,
    digits: usize,
    fraction_digits: usize,
    negative: bool,
) -> Option<f64> {
    const POW10: [f64; 16] = [
        1e0, 1e1, 1e2, 1e3, 1e4, 1e5, 1e6, 1e7, 1e8, 1e9, 1e10, 1e11, 1e12, 1e13, 1e14, 1e15,
    ];
    // 15 digits keep the mantissa below 2^53 (and the wrapping arithmetic above from wrapping).
    if digits > 15 {
        return None;
    }
    let magnitude = mantissa as f64 / *POW10.get(fraction_digits)?;
    Some(if negative { -magnitude } else { magnitude })
}

/// [`lex_number`] with spaces between the digits.
fn lex_number_spaced(b: &[u8], i: usize, end: usize) -> Option<(usize, f64)> {
    let mut j = skip_spaces(b, i, end);
    let mut text = String::new();
    if j < end && (b[j] == b'+' || b[j] == b'-') {
        if b[j] == b'-' {
            text.push('-');
        }
        j = skip_spaces(b, j + 1, end);
    }
    let mut digits = 0;
    let mut dot = false;
    let mut last = j;
    while j < end {
        let c = b[j];
        if c.is_ascii_digit() {
            text.push(c as char);
            digits += 1;
            j += 1;
            last = j;
        } else if c == b'.' && !dot {
            text.push('.');
            dot = true;
            j += 1;
            last = j;
        } else if is_space(c) {
            // Continue only if more digits follow the spaces.
            let k = skip_spaces(b, j, end);
            if k < end && (b[k].is_ascii_digit() || (b[k] == b'.' && !dot)) {
                j = k;
            } else {
                break;
            }
        } else {
            break;
        }
    }
    if digits == 0 {
        return None;
    }
    if text.ends_with('.') {
        text.push('0');
    }
    if text.starts_with('.') || text.starts_with("-.") {
        text = text.replacen('.', "0.", 1);
    }
    text.parse::<f64>().ok().map(|v| (last, v))
}

/// End of a `[ … ]` group starting at `i` (which holds `[`), balanced.
fn bracket_end(b: &[u8], i: usize, end: usize) -> usize {
    let mut depth = 0i32;
    let mut j = i;
    while j < end {
        match b[j] {
            b'[' => depth += 1,
            b']' => {
                depth -= 1;
                if depth == 0 {
                    return j + 1;
                }
            }
            _ => {}
        }
        j += 1;
    }
    end
}

/// A parameter reference starting at `#`: `#12`, `#<name>`, `#[expr]`, `##1`.
fn param_end(b: &[u8], i: usize, end: usize) -> usize {
    let mut j = skip_spaces(b, i + 1, end);
    if j >= end {
        return j;
    }
    match b[j] {
        b'<' => b[j..end]
            .iter()
            .position(|&x| x == b'>')
            .map(|p| j + p + 1)
            .unwrap_or(end),
        b'[' => bracket_end(b, j, end),
        b'#' => param_end(b, j, end),
        _ => {
            while j < end && b[j].is_ascii_digit() {
                j += 1;
            }
            j
        }
    }
}

/// A value that is not a plain number: `#…`, `[…]`, or a function such as `SQRT[…]`, with a sign.
fn expr_value_end(b: &[u8], i: usize, end: usize) -> Option<usize> {
    let mut j = skip_spaces(b, i, end);
    if j < end && (b[j] == b'+' || b[j] == b'-') {
        j = skip_spaces(b, j + 1, end);
    }
    if j >= end {
        return None;
    }
    match b[j] {
        b'#' => Some(param_end(b, j, end)),
        b'[' => Some(bracket_end(b, j, end)),
        c if c.is_ascii_alphabetic() => {
            let mut k = j;
            while k < end && b[k].is_ascii_alphabetic() {
                k += 1;
            }
            let k2 = skip_spaces(b, k, end);
            if k - j >= 2 && k2 < end && b[k2] == b'[' {
                Some(bracket_end(b, k2, end))
            } else {
                None
            }
        }
        _ => None,
    }
}

fn lex_word(b: &[u8], i: usize, end: usize) -> (TokenKind, usize) {
    let letter = b[i].to_ascii_uppercase();
    if let Some((j, v)) = lex_number(b, i + 1, end) {
        return (
            TokenKind::Word {
                letter,
                value: WordValue::Number(v),
            },
            j,
        );
    }
    if let Some(j) = expr_value_end(b, i + 1, end) {
        let vs = skip_spaces(b, i + 1, end);
        return (
            TokenKind::Word {
                letter,
                value: WordValue::Expr(vs..j),
            },
            j,
        );
    }
    (TokenKind::Other, i + 1)
}

/// Normalised parameter name: `#<Name >` → `<name>`, `#12` → `12`.
pub fn param_name(text: &str) -> String {
    let t: String = text
        .trim_start_matches('#')
        .chars()
        .filter(|c| !c.is_whitespace())
        .collect();
    t.to_ascii_lowercase()
}

/// `#i = value`. A Fanuc macro B right side is an expression without brackets (`#1=#1+1`)
/// running to the end of the block (before a comment).
fn lex_assignment(b: &[u8], i: usize, end: usize, dialect: Dialect) -> (TokenKind, usize) {
    let pe = param_end(b, i, end);
    let eq = skip_spaces(b, pe, end);
    if eq < end && b[eq] == b'=' {
        let vs = skip_spaces(b, eq + 1, end);
        let ve = if dialect == Dialect::Fanuc {
            let mut m = vs;
            while m < end && b[m] != b'(' && b[m] != b';' {
                m += 1;
            }
            while m > vs && is_space(b[m - 1]) {
                m -= 1;
            }
            m
        } else {
            lex_number(b, vs, end)
                .map(|(j, _)| j)
                .or_else(|| expr_value_end(b, vs, end))
                .unwrap_or(vs)
        };
        let target = param_name(&String::from_utf8_lossy(&b[i..pe]));
        return (
            TokenKind::Assignment {
                target,
                value_span: vs..ve,
            },
            ve.max(eq + 1),
        );
    }
    (TokenKind::Other, pe.max(i + 1))
}

/// `o100 sub`, `O<name> call [1] [2]`, `o101 while [#8 GT #4]` …: the token runs to the end of
/// the line, stopping before a trailing comment outside brackets.
fn lex_oword(b: &[u8], i: usize, end: usize) -> (TokenKind, usize) {
    let mut j = skip_spaces(b, i + 1, end);
    let name_start = j;
    if j < end && b[j] == b'<' {
        j = b[j..end]
            .iter()
            .position(|&x| x == b'>')
            .map(|p| j + p + 1)
            .unwrap_or(end);
    } else if j < end && b[j] == b'#' {
        j = param_end(b, j, end);
    } else {
        while j < end && b[j].is_ascii_digit() {
            j += 1;
        }
    }
    if j == name_start {
        // A lone `o` is not an O-word.
        return (TokenKind::Other, i + 1);
    }
    let name = param_name(&String::from_utf8_lossy(&b[name_start..j]));
    let ks = skip_spaces(b, j, end);
    let mut k = ks;
    while k < end && b[k].is_ascii_alphabetic() {
        k += 1;
    }
    let keyword = String::from_utf8_lossy(&b[ks..k]).to_ascii_lowercase();
    // The rest (arguments, conditions) up to a comment outside brackets.
    let mut depth = 0i32;
    let mut m = k;
    while m < end {
        match b[m] {
            b'[' => depth += 1,
            b']' => depth -= 1,
            b'(' | b';' if depth <= 0 => break,
            _ => {}
        }
        m += 1;
    }
    // Keep trailing spaces out of the token.
    while m > k && is_space(b[m - 1]) {
        m -= 1;
    }
    (TokenKind::OWord { name, keyword }, m.max(k))
}

/// Map a Sinumerik address to the letter errmap's rewrite knows: `CR` → `R` (radius), `AP` →
/// `^` and `RP` → `@` (polar, refused in the zone); single letters are themselves.
fn siemens_address(name: &[u8]) -> Option<u8> {
    match name.len() {
        1 if name[0] != b'R' => Some(name[0].to_ascii_uppercase()),
        2 => match [name[0].to_ascii_uppercase(), name[1].to_ascii_uppercase()] {
            [b'C', b'R'] => Some(b'R'),
            [b'A', b'P'] => Some(b'^'),
            [b'R', b'P'] => Some(b'@'),
            _ => None,
        },
        _ => None,
    }
}

/// One Sinumerik token starting at a non-space `i` (`run` is the end of its letter run).
/// Sinumerik instructions that take no argument and may share their block with motion words.
const SIEMENS_BARE: [&str; 15] = [
    "SOFT", "BRISK", "FFWON", "FFWOF", "CFC", "CFTCP", "CFIN", "COMPCAD", "COMPCURV", "COMPON",
    "COMPOF", "FNORM", "STOPRE", "TRAFOOF", "SUPA",
];

fn lex_siemens(b: &[u8], i: usize, run: usize, end: usize) -> (TokenKind, usize) {
    let c = b[i];
    if !c.is_ascii_alphabetic() {
        let mut j = i + 1;
        while j < end && (0x80..0xC0).contains(&b[j]) {
            j += 1;
        }
        return (TokenKind::Other, j);
    }
    let eq = skip_spaces(b, run, end);
    // `R1=…`: an R parameter assignment.
    if (c == b'R' || c == b'r') && run == i + 1 {
        let mut d = run;
        while d < end && b[d].is_ascii_digit() {
            d += 1;
        }
        let e = skip_spaces(b, d, end);
        if d > run && e < end && b[e] == b'=' {
            let vs = skip_spaces(b, e + 1, end);
            let ve = value_end(b, vs, end);
            let target = String::from_utf8_lossy(&b[i..d]).to_ascii_lowercase();
            return (
                TokenKind::Assignment {
                    target,
                    value_span: vs..ve,
                },
                ve.max(e + 1),
            );
        }
    }
    if eq < end && b[eq] == b'=' {
        let vs = skip_spaces(b, eq + 1, end);
        let ve = value_end(b, vs, end);
        let Some(letter) = siemens_address(&b[i..run]) else {
            return keyword(b, i, run, end);
        };
        let value = siemens_value(b, vs, ve);
        return (TokenKind::Word { letter, value }, ve.max(eq + 1));
    }
    if run - i >= 2 {
        // An instruction without arguments is its name alone: the words after it on the
        // block (`SUPA G0 Z0`, `SOFT G1 X10`) are lexed as words.
        if SIEMENS_BARE
            .iter()
            .any(|k| k.as_bytes().eq_ignore_ascii_case(&b[i..run]))
            && (run == end || !b[run].is_ascii_alphanumeric() && b[run] != b'(' && b[run] != b'_')
        {
            let name = String::from_utf8_lossy(&b[i..run]).to_ascii_uppercase();
            return (TokenKind::Keyword { name }, run);
        }
        return keyword(b, i, run, end);
    }
    if c == b'R' || c == b'r' {
        // A bare R is a parameter reference in Sinumerik, not a radius.
        return (TokenKind::Other, run);
    }
    lex_word(b, i, end)
}

/// End of a Sinumerik value: up to a space or `;` outside parentheses and quotes.
fn value_end(b: &[u8], i: usize, end: usize) -> usize {
    let (mut depth, mut quote, mut j) = (0i32, false, i);
    while j < end {
        match b[j] {
            b'"' => quote = !quote,
            b'(' | b'[' if !quote => depth += 1,
            b')' | b']' if !quote => depth -= 1,
            b' ' | b'\t' | b';' if depth <= 0 && !quote => break,
            _ => {}
        }
        j += 1;
    }
    j
}

/// `10.5`, `AC(10.5)`, `IC(-1)` or anything else (an expression).
fn siemens_value(b: &[u8], vs: usize, ve: usize) -> WordValue {
    let text = std::str::from_utf8(&b[vs..ve]).unwrap_or("");
    let num = |t: &str| t.trim().parse::<f64>().ok();
    let upper = text.to_ascii_uppercase();
    let inner = |p: &str| {
        upper
            .strip_prefix(p)
            .and_then(|r| r.strip_suffix(')'))
            .and_then(num)
    };
    if let Some(v) = num(text) {
        WordValue::Number(v)
    } else if let Some(v) = inner("AC(") {
        WordValue::Abs(v)
    } else if let Some(v) = inner("IC(") {
        WordValue::Inc(v)
    } else {
        WordValue::Expr(vs..ve)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn words(text: &str) -> Vec<(u8, WordValue)> {
        lex(text)
            .into_iter()
            .flat_map(|l| l.tokens)
            .filter_map(|t| match t.kind {
                TokenKind::Word { letter, value } => Some((letter, value)),
                _ => None,
            })
            .collect()
    }

    /// The fast path must give the bits Rust's correctly rounded `str::parse` gives, for short
    /// and long numbers, leading and trailing points, signs and zeros.
    #[test]
    fn numbers_equal_the_standard_parse_bit_for_bit() {
        let mut state = 0x2545_f491_4f6c_dd1du64;
        let mut next = |n: u64| {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            state % n
        };
        for _ in 0..20_000 {
            let mut t = String::new();
            match next(3) {
                0 => t.push('-'),
                1 => t.push('+'),
                _ => {}
            }
            let len = 1 + next(20) as usize;
            let dot_at = next(len as u64 + 2) as usize;
            for k in 0..len {
                if k == dot_at {
                    t.push('.');
                }
                t.push((b'0' + next(10) as u8) as char);
            }
            if dot_at == len {
                t.push('.');
            }
            let (end, v) = lex_number(t.as_bytes(), 0, t.len()).expect("a number");
            assert_eq!(end, t.len(), "{t}");
            let text = t.trim_start_matches('+');
            let expected: f64 = if text.trim_start_matches('-').starts_with('.') {
                text.replacen('.', "0.", 1).parse().unwrap()
            } else {
                text.parse().unwrap()
            };
            assert_eq!(v.to_bits(), expected.to_bits(), "{t}");
        }
    }

    #[test]
    fn words_are_case_insensitive_with_signs_and_spaces() {
        let w = words("n0080 g0 x +0.5 Y-.25 z 1.\tF 100");
        let letters: Vec<u8> = w.iter().map(|(l, _)| *l).collect();
        assert_eq!(letters, b"NGXYZF".to_vec());
        assert_eq!(w[0].1, WordValue::Number(80.0));
        assert_eq!(w[2].1, WordValue::Number(0.5));
        assert_eq!(w[3].1, WordValue::Number(-0.25));
        assert_eq!(w[4].1, WordValue::Number(1.0));
        assert_eq!(w[5].1, WordValue::Number(100.0));
    }

    #[test]
    fn packed_words_and_decimal_g_codes() {
        let w = words("N40G90G64P.1 G5.1");
        assert_eq!(w.len(), 5);
        assert_eq!(w[1], (b'G', WordValue::Number(90.0)));
        assert_eq!(w[3], (b'P', WordValue::Number(0.1)));
        assert_eq!(w[4], (b'G', WordValue::Number(5.1)));
    }

    #[test]
    fn expressions_parameters_and_polar_words() {
        let text = "G1 X[#<xscale>*53.] Y#2 @-.0025 ^4.5 Z SQRT[4]";
        let w = words(text);
        assert!(
            matches!(&w[1], (b'X', WordValue::Expr(r)) if &text[r.clone()] == "[#<xscale>*53.]")
        );
        assert!(matches!(&w[2], (b'Y', WordValue::Expr(r)) if &text[r.clone()] == "#2"));
        assert_eq!(w[3], (b'@', WordValue::Number(-0.0025)));
        assert_eq!(w[4], (b'^', WordValue::Number(4.5)));
        assert!(matches!(&w[5], (b'Z', WordValue::Expr(r)) if &text[r.clone()] == "SQRT[4]"));
    }

    #[test]
    fn comments_assignments_owords_percent() {
        let text = "%\r\n#<level> = #1 (save)\r\no100 repeat [800] ; loop\r\nG0 (a) X1\r\n";
        let lines = lex(text);
        assert_eq!(lines.len(), 4);
        assert_eq!(lines[0].tokens[0].kind, TokenKind::Percent);
        assert_eq!(lines[0].terminator(text), "\r\n");
        match &lines[1].tokens[0].kind {
            TokenKind::Assignment { target, value_span } => {
                assert_eq!(target, "<level>");
                assert_eq!(&text[value_span.clone()], "#1");
            }
            k => panic!("not an assignment: {k:?}"),
        }
        assert_eq!(
            lines[1].tokens.last().map(|t| &t.kind),
            Some(&TokenKind::Comment)
        );
        match &lines[2].tokens[0].kind {
            TokenKind::OWord { name, keyword } => {
                assert_eq!(name, "100");
                assert_eq!(keyword, "repeat");
            }
            k => panic!("not an O-word: {k:?}"),
        }
        assert_eq!(
            lines[2].tokens.last().map(|t| &t.kind),
            Some(&TokenKind::LineComment)
        );
        assert!(lines[3].tokens.iter().any(|t| t.kind == TokenKind::Comment));
    }

    #[test]
    fn tokens_tile_the_text() {
        let text = "N1 G1 X1 (c)\nbad ! line\r\n\nlast";
        let mut rebuilt = String::new();
        for l in lex(text) {
            let mut at = l.span.start;
            for t in &l.tokens {
                assert_eq!(t.span.start, at);
                at = t.span.end;
                rebuilt.push_str(&text[t.span.clone()]);
            }
            assert_eq!(at, l.span.end);
            rebuilt.push_str(l.terminator(text));
        }
        assert_eq!(rebuilt, text);
    }
}
