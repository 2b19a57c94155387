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
    let t = code.trim_start();
    let lead = code.len() - t.len();
    let digits = t.bytes().take_while(u8::is_ascii_digit).count();
    let number = t[..digits].parse::<u64>().ok();
    let number_span = lead..lead + digits;
    let after = &code[lead + digits..];
    let body = after.trim_start();
    let body_at = code.len() - body.len();
    let mut block = Block {
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
    let head_len = body.find(|c: char| c.is_whitespace()).unwrap_or(body.len());
    block.head = body[..head_len].to_ascii_uppercase();
    let rest = &body[head_len..];
    block.rest = rest.trim().to_string();
    let rest_at = body_at + head_len;
    if matches!(
        block.head.as_str(),
        "L" | "C" | "CR" | "CT" | "CC" | "LP" | "CP" | "RND" | "CHF"
    ) {
        block.words = words(content, rest, rest_at)?;
    } else if block.head == "CYCL" {
        match words(content, rest, rest_at) {
            Ok(w) => block.words = w,
            Err(e) => block.bad = Some(e),
        }
    }
    Ok(block)
}

/// 1-based column of byte `at` in `content`.
fn col(content: &str, at: usize) -> usize {
    content.get(..at).map_or(at, |s| s.chars().count()) + 1
}

/// The words of a path block: address letters, then a signed number, a sign or a parameter.
fn words(content: &str, rest: &str, rest_at: usize) -> Result<Vec<Word>, LexError> {
    let mut out: Vec<Word> = Vec::new();
    let mut offset = 0;
    for tok in rest.split_whitespace() {
        let at = rest_at + offset + rest[offset..].find(tok).unwrap_or(0);
        offset = at - rest_at + tok.len();
        let column = col(content, at);
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
