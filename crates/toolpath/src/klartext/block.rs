//! One Klartext block read into its number, its function (`L`, `CC`, `CYCL DEF` …), its words with their columns, and its comment; malformed numbers and repeated words are errors.

use std::ops::Range;

/// The value of a word: `X+10` a number, `DR+` a sign, `X+Q1` a parameter, `RL` nothing.
#[derive(Debug, Clone, PartialEq)]
pub(super) enum Value {
    None,
    Num(f64),
    Sign(bool),
    Param,
}

/// A word of a block: its address (`X`, `IX`, `F`, `FMAX`, `DR`, `M` …) and value.
#[derive(Debug, Clone)]
pub(super) struct Word {
    pub addr: String,
    pub value: Value,
    /// Its text as written, and its 1-based column on the line.
    pub text: String,
    pub col: usize,
}

impl Word {
    pub fn num(&self) -> Option<f64> {
        match self.value {
            Value::Num(v) => Some(v),
            _ => None,
        }
    }
}

/// A block: `lead` (whitespace) + `number` + `body`, as in the text, read into words.
#[derive(Debug, Clone)]
pub(super) struct Block {
    /// Block skip `/` before the block: whether it runs depends on the operator's switch.
    pub skip: bool,
    pub number: Option<u64>,
    /// Byte range of the block number in the line's content.
    pub number_span: Range<usize>,
    /// The function, upper case: `L`, `CC`, `C`, `CR`, `CT`, `RND`, `CHF`, `LBL`, `CALL`, `CYCL`,
    /// `TOOL`, `BEGIN`, `END`, `;`, `*`, … (empty for an empty line).
    pub head: String,
    pub head_col: usize,
    /// The text after the function, before the comment.
    pub rest: String,
    /// The words after the function (for path blocks and cycle parameters).
    pub words: Vec<Word>,
    /// ` ; comment` with its leading space, if any.
    pub comment: String,
    /// A word errmap could not read (kept for cycles, whose parameters it reads only for the
    /// cycles it follows).
    pub bad: Option<LexError>,
}

impl Block {
    pub fn word(&self, addr: &str) -> Option<&Word> {
        self.words.iter().find(|w| w.addr == addr)
    }

    pub fn has(&self, addr: &str) -> bool {
        self.word(addr).is_some()
    }
}

/// A lexing error: column, the word, and what is wrong.
pub(super) type LexError = (usize, String, String);

/// Read a line's content (no terminator).
pub(super) fn read(content: &str) -> Result<Block, LexError> {
    let (code, comment) = match content.find(';') {
        Some(i) => {
            let start = content[..i].trim_end().len();
            (&content[..start], &content[start..])
        }
        None => (content, ""),
    };
    let mut t = code.trim_start();
    let skip = t.starts_with('/');
    if skip {
        t = t[1..].trim_start();
    }
    let lead = code.len() - t.len();
    let digits = t.bytes().take_while(u8::is_ascii_digit).count();
    let number = t[..digits].parse::<u64>().ok();
    let number_span = lead..lead + digits;
    let after = &code[lead + digits..];
    let mut body = after.trim_start();
    // `/ 24 L …` as the TNC shows it, or `24 / L …`.
    let skip = skip || body.starts_with('/');
    if body.starts_with('/') {
        body = body[1..].trim_start();
    }
    let body_at = code.len() - body.len();
    let mut block = Block {
        skip,
        number,
        number_span,
        head: String::new(),
        head_col: col(content, body_at),
        rest: String::new(),
        words: Vec::new(),
        comment: comment.to_string(),
        bad: None,
    };
    if body.is_empty() {
        if !comment.is_empty() {
            block.head = ";".into();
            block.head_col = col(
                content,
                code.len() + (comment.len() - comment.trim_start().len()),
            );
        }
        return Ok(block);
    }
    if let Some(r) = body.strip_prefix('*') {
        block.head = "*".into();
        block.rest = r.to_string();
        return Ok(block);
    }
    let mut head_len = body.find(|c: char| c.is_whitespace()).unwrap_or(body.len());
    block.head = body[..head_len].to_ascii_uppercase();
    // `FN18: SYSREAD …`, `FN0: Q3 = 1.995`: the function FN, its number in the rest.
    if block.head.len() > 2 && block.head.starts_with("FN") {
        block.head = "FN".into();
        head_len = 2;
    }
    let rest = &body[head_len..];
    block.rest = rest.trim().to_string();
    let rest_at = body_at + head_len;
    if matches!(
        block.head.as_str(),
        "L" | "C" | "CR" | "CT" | "CC" | "LP" | "CP" | "RND" | "CHF"
    ) {
        block.words = words(content, rest, rest_at)?;
    } else if is_m_head(&block.head) {
        // `M140 MB MAX`, `M5 M9`: the head is a word too.
        block.words = words(content, body, body_at)?;
    } else if block.head == "CYCL" {
        match words(content, rest, rest_at) {
            Ok(w) => block.words = w,
            Err(e) => block.bad = Some(e),
        }
    }
    Ok(block)
}

/// `M3`, `M140`: a block of miscellaneous functions.
pub(super) fn is_m_head(head: &str) -> bool {
    head.len() > 1 && head.starts_with('M') && head[1..].bytes().all(|b| b.is_ascii_digit())
}

/// 1-based column of byte `at` in `content`.
fn col(content: &str, at: usize) -> usize {
    content.get(..at).map_or(at, |s| s.chars().count()) + 1
}

/// The words of a path block: address letters, then a signed number, a sign or a parameter.
fn words(content: &str, rest: &str, rest_at: usize) -> Result<Vec<Word>, LexError> {
    let mut out: Vec<Word> = Vec::new();
    let mut offset = 0;
    let mut toks = rest.split_whitespace().peekable();
    while let Some(tok) = toks.next() {
        let at = rest_at + offset + rest[offset..].find(tok).unwrap_or(0);
        offset = at - rest_at + tok.len();
        let column = col(content, at);
        // Two-token words: `F AUTO` (the feed of the TOOL CALL), `F Q5` / `FQ5` (a feed from a
        // parameter), `MB MAX` / `MB +50` (M140's retract distance).
        let upper = tok.to_ascii_uppercase();
        let next = toks.peek().map(|t| t.to_ascii_uppercase());
        let merged = match (upper.as_str(), next.as_deref()) {
            ("F", Some("AUTO")) => Some(("FAUTO", Value::None)),
            ("F", Some(q)) if q.starts_with('Q') => Some(("F", Value::Param)),
            ("MB", Some("MAX")) => Some(("MB", Value::None)),
            ("MB", Some(v)) => value(v)
                .filter(|v| matches!(v, Value::Num(_)))
                .map(|v| ("MB", v)),
            (fq, _) if fq.starts_with("FQ") => {
                Some(("F", Value::Param)).filter(|_| value(&fq[1..]) == Some(Value::Param))
            }
            _ => None,
        };
        if let Some((addr, value)) = merged {
            let mut text = tok.to_string();
            if !upper.starts_with("FQ") {
                let second = toks.next().unwrap_or_default();
                let at2 = rest_at + offset + rest[offset..].find(second).unwrap_or(0);
                offset = at2 - rest_at + second.len();
                text = format!("{tok} {second}");
            }
            if out.iter().any(|w| w.addr == addr) {
                return Err((
                    column,
                    text,
                    format!("word `{addr}` given twice in one block"),
                ));
            }
            out.push(Word {
                addr: addr.to_string(),
                value,
                text,
                col: column,
            });
            continue;
        }
        let letters = tok
            .bytes()
            .take_while(|b| b.is_ascii_alphabetic() || *b == b'#')
            .count();
        let (addr, v) = tok.split_at(letters);
        let addr = addr.to_ascii_uppercase();
        let value = value(v).ok_or_else(|| {
            (
                column,
                tok.to_string(),
                format!("malformed number in `{tok}`"),
            )
        })?;
        // A number right after the cycle number (`7.1`, `11.1 SCL 0.75`) has no address.
        // Several M functions may stand in one block.
        let key = if addr.is_empty() || addr == "M" {
            String::new()
        } else {
            addr.clone()
        };
        if !key.is_empty() && out.iter().any(|w| w.addr == key) {
            return Err((
                column,
                tok.to_string(),
                format!("word `{key}` given twice in one block"),
            ));
        }
        out.push(Word {
            addr,
            value,
            text: tok.to_string(),
            col: column,
        });
    }
    Ok(out)
}

/// `+10`, `-5.5`, `10`, `.5`: a number; `+`/`-` alone: a sign; `+Q1`, `-QL3`: a parameter.
fn value(v: &str) -> Option<Value> {
    if v.is_empty() {
        return Some(Value::None);
    }
    let unsigned = v.trim_start_matches(['+', '-']);
    let signs = v.len() - unsigned.len();
    if signs > 1 {
        return None;
    }
    if unsigned.is_empty() {
        return Some(Value::Sign(!v.starts_with('-')));
    }
    if unsigned.starts_with(['Q', 'q']) {
        return Some(Value::Param);
    }
    let (int, frac) = match unsigned.split_once('.') {
        Some((i, f)) => (i, Some(f)),
        None => (unsigned, None),
    };
    let digits = |s: &str| s.bytes().all(|b| b.is_ascii_digit());
    let ok = digits(int)
        && frac.is_none_or(digits)
        && !(int.is_empty() && frac.is_none_or(str::is_empty));
    if !ok {
        return None;
    }
    v.parse::<f64>()
        .ok()
        .filter(|x| x.is_finite())
        .map(Value::Num)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_line_block_reads_into_words_with_columns() {
        let b = read("  7 L X+10.5 IY-5 R0 FMAX M3 ; approach").unwrap();
        assert_eq!(b.number, Some(7));
        assert_eq!(b.head, "L");
        let x = b.word("X").unwrap();
        assert_eq!((x.num(), x.col), (Some(10.5), 7));
        assert_eq!(b.word("IY").unwrap().num(), Some(-5.0));
        assert_eq!(b.word("FMAX").unwrap().value, Value::None);
        assert_eq!(b.comment, " ; approach");
        let c = read("9 C X+0 Y+25 DR-").unwrap();
        assert_eq!(c.word("DR").unwrap().value, Value::Sign(false));
        assert_eq!(
            read("3 L X+Q1").unwrap().word("X").unwrap().value,
            Value::Param
        );
    }

    #[test]
    fn malformed_numbers_and_repeated_words_are_errors() {
        let e = read("5 L X+1.2.3 Y+0").unwrap_err();
        assert_eq!((e.0, e.1.as_str()), (5, "X+1.2.3"));
        let e = read("5 L X+1 X+2").unwrap_err();
        assert_eq!(e.0, 9);
        assert!(read("5 L X+-1").is_err());
        assert!(read("5 L X+1,5").is_err());
    }
}
