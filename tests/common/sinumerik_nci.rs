//! The Sinumerik executor of the corpus judge: the `nc-gcode-interpreter` package from PyPI (a Sinumerik-flavoured interpreter, installed by .ci/run into a venv), read into moves in mm.
//!
//! It reports each block's motion mode and absolute X/Y/Z (it evaluates R parameters, IC()/AC(),
//! loops), but not arc centres, and version 0.1.9 does not accumulate G91 moves; so the judge
//! declines (the file fails as unverified) a program with arcs or G91 rather than trust it.
//! Version 0.1.9 reads R parameters only as `R[1]` (the judge writes `R1` so for it), and does
//! not parse labels, `GOTO…`, `REPEAT`, `LOOP` or functions (`SIN(…)`, `TRUNC(…)`): a program it
//! cannot parse is read by [`reference`], a tracer written here from the SINUMERIK 840D sl
//! programming manuals (Fundamentals; Job Planning), sharing no code with errmap.
// Each test binary that includes this module uses only part of it.
#![allow(dead_code)]

use super::path_judge::Seg;
use std::path::{Path, PathBuf};
use std::process::Command;

/// The venv with nc-gcode-interpreter: `ERRMAP_NCI_VENV`, default `.ci/venv` in the checkout.
pub fn venv() -> PathBuf {
    std::env::var_os("ERRMAP_NCI_VENV")
        .map(PathBuf::from)
        .unwrap_or_else(|| Path::new(env!("CARGO_MANIFEST_DIR")).join(".ci/venv"))
}

/// Whether a missing interpreter fails the test (`ERRMAP_REQUIRE_NCI=1`, set by .ci/run).
pub fn required() -> bool {
    std::env::var("ERRMAP_REQUIRE_NCI").is_ok_and(|v| v == "1")
}

const SCRIPT: &str = r#"
import sys, math
from nc_gcode_interpreter import nc_to_dataframe
text = open(sys.argv[1], encoding="utf-8", errors="replace").read()
df, _ = nc_to_dataframe(text, iteration_limit=200000)
cols = set(df.columns)
for row in df.iter_rows(named=True):
    m = row.get("gg01_motion") or "-"
    units = row.get("gg13_wp_measure") or "-"
    xyz = [row.get(a) if a in cols else None for a in "XYZ"]
    print(m, units, *["nan" if v is None else repr(float(v)) for v in xyz])
"#;

/// Whether the interpreter is installed.
pub fn available() -> bool {
    python().is_file()
}

fn python() -> PathBuf {
    venv().join("bin/python")
}

/// The moves of the program in `path`, mm; `Err` when the interpreter stops or the program
/// holds what this judge does not read (arcs, G91).
pub fn trace(path: &Path, text: &str) -> Result<Vec<Seg>, String> {
    for (n, line) in text.lines().enumerate() {
        let code = line.split(';').next().unwrap_or("").to_ascii_uppercase();
        let has = |w: &str| {
            code.split(|c: char| !c.is_ascii_alphanumeric())
                .any(|t| t == w)
        };
        for w in ["G2", "G3", "G02", "G03", "CIP", "CT", "G91", "TURN"] {
            if has(w) {
                return Err(format!(
                    "line {}: `{w}`: nc-gcode-interpreter reports no arc centres and no G91 sums",
                    n + 1
                ));
            }
        }
    }
    let bracketed = path.with_extension("nci.mpf");
    std::fs::write(&bracketed, r_brackets(text)).map_err(|e| format!("cannot write: {e}"))?;
    let out = Command::new(python())
        .arg("-c")
        .arg(SCRIPT)
        .arg(&bracketed)
        .output()
        .map_err(|e| format!("cannot run nc-gcode-interpreter: {e}"))?;
    if !out.status.success() {
        let err = String::from_utf8_lossy(&out.stderr);
        // What the interpreter cannot parse (labels, jumps, functions) the reference tracer reads.
        if err.contains("ParseError") || err.contains("Unexpected rule") {
            return reference::trace(text);
        }
        return Err(format!(
            "nc-gcode-interpreter: {}",
            err.lines().last().unwrap_or("failed")
        ));
    }
    let mut at = [f64::NAN; 3];
    let mut segs = Vec::new();
    for (row, line) in String::from_utf8_lossy(&out.stdout).lines().enumerate() {
        let f: Vec<&str> = line.split_whitespace().collect();
        if f.len() != 5 {
            continue;
        }
        let scale = if f[1] == "G70" || f[1] == "G700" {
            25.4
        } else {
            1.0
        };
        let end = [2, 3, 4].map(|k| f[k].parse::<f64>().unwrap_or(f64::NAN) * scale);
        let moved = (0..3).any(|k| {
            !(end[k].is_nan() && at[k].is_nan()) && (end[k] - at[k]).abs() > 1e-12
                || end[k].is_nan() != at[k].is_nan()
        });
        if moved {
            let cut = matches!(f[0], "G1" | "G01");
            if !cut && f[0] != "G0" && f[0] != "G00" {
                return Err(format!("row {}: motion {} is not read here", row + 1, f[0]));
            }
            if cut && at.iter().chain(&end).any(|v| v.is_nan()) {
                return Err(format!("row {}: a cut from an unknown position", row + 1));
            }
            segs.push(Seg {
                cut,
                line: row as u64 + 1,
                start: at,
                end,
                arc: None,
            });
            at = end;
        }
    }
    Ok(segs)
}

/// `R1` → `R[1]` outside comments and strings (nc-gcode-interpreter 0.1.9 reads only the latter).
pub fn r_brackets(text: &str) -> String {
    let mut out = String::with_capacity(text.len() + 64);
    for line in text.split_inclusive('\n') {
        let b = line.as_bytes();
        let mut i = 0;
        let mut quote = false;
        while i < b.len() {
            let c = b[i];
            if c == b';' && !quote {
                out.push_str(&line[i..]);
                break;
            }
            if c == b'"' {
                quote = !quote;
            }
            let word_start = i == 0 || !(b[i - 1].is_ascii_alphanumeric() || b[i - 1] == b'_');
            if !quote && (c == b'R' || c == b'r') && word_start {
                let d = b[i + 1..].iter().take_while(|x| x.is_ascii_digit()).count();
                let after = b.get(i + 1 + d).copied().unwrap_or(b' ');
                if d > 0 && !(after.is_ascii_alphanumeric() || after == b'_') {
                    out.push_str(&format!("R[{}]", &line[i + 1..i + 1 + d]));
                    i += 1 + d;
                    continue;
                }
            }
            let ch = line[i..].chars().next().unwrap_or(' ');
            out.push(ch);
            i += ch.len_utf8();
        }
    }
    out
}

/// A SINUMERIK tracer written from the programming manuals for what nc-gcode-interpreter 0.1.9
/// does not parse: R parameters, `DEF REAL/INT/BOOL`, labels (`NAME:`), `GOTOF`/`GOTOB`/`GOTO`/
/// `GOTOC` to labels or block numbers, `IF cond GOTOx`, `IF/ELSE/ENDIF`, `WHILE/ENDWHILE`,
/// `FOR/ENDFOR`, `REPEAT/UNTIL`, `LOOP/ENDLOOP`, `REPEAT label [label] P=n`, `REPEATB label P=n`,
/// arithmetic with the manual's operator priority and functions in degrees; G0/G1 in G90 with
/// X/Y/Z, G70/G71/G700/G710; subprograms `PROC NAME(REAL A, INT B, BOOL C)` written after the
/// main program's end and called `NAME(a, , c)` or `NAME` (Job Planning, "Subprogram technique":
/// parameters by value, one left out is 0; the subprogram's `DEF` variables are its own, R
/// parameters global; M17 or RET returns). Anything else that could move or shift the axes is
/// declined.
pub mod reference {
    use super::super::path_judge::Seg;
    use std::collections::HashMap;

    /// Statements executed before the tracer gives up (an endless loop).
    const STEPS: u64 = 20_000_000;

    struct Line {
        number: Option<u64>,
        label: Option<String>,
        /// Upper-cased code without the comment, block number and label.
        code: String,
    }

    fn parse_line(raw: &str) -> Line {
        let mut code = raw
            .split(';')
            .next()
            .unwrap_or("")
            .trim()
            .to_ascii_uppercase();
        let mut number = None;
        if let Some(rest) = code.strip_prefix('N') {
            let d: String = rest.chars().take_while(|c| c.is_ascii_digit()).collect();
            if !d.is_empty()
                && rest[d.len()..]
                    .chars()
                    .next()
                    .is_none_or(|c| c == ' ' || c == '\t')
            {
                number = d.parse().ok();
                code = rest[d.len()..].trim().to_string();
            }
        }
        let mut label = None;
        if let Some(colon) = code.find(':') {
            let name = &code[..colon];
            let ok = name.len() >= 2
                && name
                    .chars()
                    .take(2)
                    .all(|c| c.is_ascii_alphabetic() || c == '_')
                && name.chars().all(|c| c.is_ascii_alphanumeric() || c == '_');
            if ok {
                label = Some(name.to_string());
                code = code[colon + 1..].trim().to_string();
            }
        }
        Line {
            number,
            label,
            code,
        }
    }

    /// The expression evaluator: `(text, position)`, priority per the manual (comparisons
    /// lowest, then OR, XOR, AND, + -, * / DIV MOD, unary).
    struct Ev<'a> {
        s: &'a [u8],
        i: usize,
        r: &'a HashMap<i64, f64>,
        v: &'a HashMap<String, f64>,
    }

    impl Ev<'_> {
        fn ws(&mut self) {
            while self.i < self.s.len() && self.s[self.i] == b' ' {
                self.i += 1;
            }
        }
        fn eat(&mut self, t: &str) -> bool {
            self.ws();
            let ok = self.s[self.i..].starts_with(t.as_bytes());
            // A word operator must not run into a name.
            let word = t.as_bytes()[0].is_ascii_alphabetic();
            let next = self.s.get(self.i + t.len()).copied().unwrap_or(b' ');
            if ok && !(word && (next.is_ascii_alphanumeric() || next == b'_')) {
                self.i += t.len();
                true
            } else {
                false
            }
        }
        fn cmp(&mut self) -> Result<f64, String> {
            let a = self.or()?;
            for (op, f) in [
                ("==", (|a, b| a == b) as fn(f64, f64) -> bool),
                ("<>", |a, b| a != b),
                ("<=", |a, b| a <= b),
                (">=", |a, b| a >= b),
                ("<", |a, b| a < b),
                (">", |a, b| a > b),
            ] {
                if self.eat(op) {
                    let b = self.or()?;
                    return Ok(if f(a, b) { 1.0 } else { 0.0 });
                }
            }
            Ok(a)
        }
        fn or(&mut self) -> Result<f64, String> {
            let mut a = self.xor()?;
            while self.eat("OR") {
                let b = self.xor()?;
                a = f64::from(u8::from(a != 0.0 || b != 0.0));
            }
            Ok(a)
        }
        fn xor(&mut self) -> Result<f64, String> {
            let mut a = self.and()?;
            while self.eat("XOR") {
                let b = self.and()?;
                a = f64::from(u8::from((a != 0.0) != (b != 0.0)));
            }
            Ok(a)
        }
        fn and(&mut self) -> Result<f64, String> {
            let mut a = self.sum()?;
            while self.eat("AND") {
                let b = self.sum()?;
                a = f64::from(u8::from(a != 0.0 && b != 0.0));
            }
            Ok(a)
        }
        fn sum(&mut self) -> Result<f64, String> {
            let mut a = self.product()?;
            loop {
                if self.eat("+") {
                    a += self.product()?;
                } else if self.eat("-") {
                    a -= self.product()?;
                } else {
                    return Ok(a);
                }
            }
        }
        fn product(&mut self) -> Result<f64, String> {
            let mut a = self.unary()?;
            loop {
                if self.eat("*") {
                    a *= self.unary()?;
                } else if self.eat("/") {
                    a /= self.unary()?;
                } else if self.eat("DIV") {
                    a = (a / self.unary()?).trunc();
                } else if self.eat("MOD") {
                    a %= self.unary()?;
                } else {
                    return Ok(a);
                }
            }
        }
        fn unary(&mut self) -> Result<f64, String> {
            if self.eat("-") {
                return Ok(-self.unary()?);
            }
            if self.eat("+") {
                return self.unary();
            }
            if self.eat("NOT") {
                return Ok(f64::from(u8::from(self.unary()? == 0.0)));
            }
            self.primary()
        }
        fn primary(&mut self) -> Result<f64, String> {
            self.ws();
            if self.eat("(") {
                let v = self.cmp()?;
                if !self.eat(")") {
                    return Err("`)` missing".into());
                }
                return Ok(v);
            }
            let start = self.i;
            let c = *self.s.get(self.i).ok_or("value missing")?;
            if c.is_ascii_digit() || c == b'.' {
                while self.i < self.s.len()
                    && (self.s[self.i].is_ascii_digit() || self.s[self.i] == b'.')
                {
                    self.i += 1;
                }
                let t = std::str::from_utf8(&self.s[start..self.i]).unwrap_or("");
                let t = if t.ends_with('.') {
                    format!("{t}0")
                } else {
                    t.to_string()
                };
                return t.parse().map_err(|_| format!("number `{t}`"));
            }
            while self.i < self.s.len()
                && (self.s[self.i].is_ascii_alphanumeric() || self.s[self.i] == b'_')
            {
                self.i += 1;
            }
            let name = std::str::from_utf8(&self.s[start..self.i])
                .unwrap_or("")
                .to_string();
            if name.is_empty() {
                return Err(format!(
                    "cannot read at `{}`",
                    String::from_utf8_lossy(&self.s[start..])
                ));
            }
            if name == "R" && self.eat("[") {
                let n = self.cmp()?;
                if !self.eat("]") {
                    return Err("`]` missing".into());
                }
                return self
                    .r
                    .get(&(n as i64))
                    .copied()
                    .ok_or(format!("R{n} unset"));
            }
            if let Some(n) = name.strip_prefix('R').and_then(|d| d.parse::<i64>().ok()) {
                return self.r.get(&n).copied().ok_or(format!("R{n} unset"));
            }
            if self.eat("(") {
                let mut args = vec![self.cmp()?];
                while self.eat(",") {
                    args.push(self.cmp()?);
                }
                if !self.eat(")") {
                    return Err("`)` missing".into());
                }
                let x = args[0];
                let y = args.get(1).copied().unwrap_or(0.0);
                let rad = x.to_radians();
                return Ok(match name.as_str() {
                    "SIN" => rad.sin(),
                    "COS" => rad.cos(),
                    "TAN" => rad.tan(),
                    "ASIN" => x.asin().to_degrees(),
                    "ACOS" => x.acos().to_degrees(),
                    "ATAN2" => x.atan2(y).to_degrees(),
                    "SQRT" => x.sqrt(),
                    "ABS" => x.abs(),
                    "POT" => x * x,
                    "TRUNC" => x.trunc(),
                    "ROUND" => x.round(),
                    "ROUNDUP" => x.ceil(),
                    "MINVAL" => x.min(y),
                    "MAXVAL" => x.max(y),
                    _ => return Err(format!("function {name}")),
                });
            }
            match name.as_str() {
                "TRUE" => Ok(1.0),
                "FALSE" => Ok(0.0),
                _ => self
                    .v
                    .get(&name)
                    .copied()
                    .ok_or(format!("variable {name} unset")),
            }
        }
    }

    struct St {
        r: HashMap<i64, f64>,
        v: HashMap<String, f64>,
        ints: Vec<String>,
    }

    impl St {
        fn eval(&self, t: &str) -> Result<f64, String> {
            let mut e = Ev {
                s: t.as_bytes(),
                i: 0,
                r: &self.r,
                v: &self.v,
            };
            let v = e.cmp()?;
            e.ws();
            if e.i != t.len() {
                return Err(format!("cannot read `{t}`"));
            }
            Ok(v)
        }
        fn set(&mut self, name: &str, v: f64) -> Result<(), String> {
            let name = name.trim();
            if let Some(inner) = name.strip_prefix("R[").and_then(|x| x.strip_suffix(']')) {
                let n = self.eval(inner)?;
                self.r.insert(n as i64, v);
            } else if let Some(n) = name.strip_prefix('R').and_then(|d| d.parse::<i64>().ok()) {
                self.r.insert(n, v);
            } else if self.v.contains_key(name) {
                let v = if self.ints.iter().any(|i| i == name) {
                    v.round()
                } else {
                    v
                };
                self.v.insert(name.to_string(), v);
            } else {
                return Err(format!("`{name}` is not a variable"));
            }
            Ok(())
        }
    }

    /// `(start, end)` pairs of the control structures, both ways.
    fn structures(lines: &[Line]) -> Result<HashMap<usize, usize>, String> {
        let mut map = HashMap::new();
        let mut stack: Vec<(usize, &str)> = Vec::new();
        for (i, l) in lines.iter().enumerate() {
            let first = l.code.split_whitespace().next().unwrap_or("");
            let is_if_block = first == "IF" && !l.code.contains("GOTO");
            let opener = match first {
                "IF" if is_if_block => Some("IF"),
                "WHILE" => Some("WHILE"),
                "FOR" => Some("FOR"),
                "REPEAT" if l.code == "REPEAT" => Some("REPEAT"),
                "LOOP" => Some("LOOP"),
                _ => None,
            };
            let closer = match first {
                "ENDIF" => Some("IF"),
                "ENDWHILE" => Some("WHILE"),
                "ENDFOR" => Some("FOR"),
                "UNTIL" => Some("REPEAT"),
                "ENDLOOP" => Some("LOOP"),
                _ => None,
            };
            if let Some(o) = opener {
                stack.push((i, o));
            } else if first == "ELSE" {
                let &(s, _) = stack.last().ok_or("ELSE outside IF")?;
                map.insert(s + 1_000_000_000, i);
                map.insert(i, s);
            } else if let Some(c) = closer {
                let (s, o) = stack.pop().ok_or("unpaired end")?;
                if o != c {
                    return Err(format!("{o} closed by {first}"));
                }
                map.insert(s, i);
                map.insert(i, s);
            }
        }
        Ok(map)
    }

    /// A subprogram of the file: first line of its body, line after its last, parameters
    /// (name, whether INT).
    struct Sub {
        body: usize,
        end: usize,
        params: Vec<(String, bool)>,
    }

    /// The PROCs after the main program's end (a line holding M30, M2, M17 or RET).
    fn subs(lines: &[Line]) -> Result<HashMap<String, Sub>, String> {
        let ends = |code: &str| {
            code == "RET"
                || code
                    .split(|c: char| !c.is_ascii_alphanumeric())
                    .any(|w| ["M30", "M2", "M02", "M17"].contains(&w))
        };
        let mut starts = Vec::new();
        let mut ended = false;
        for (i, l) in lines.iter().enumerate() {
            if ended && l.code.starts_with("PROC ") {
                starts.push(i);
            }
            ended = ended || ends(&l.code);
        }
        let mut out = HashMap::new();
        for (k, &i) in starts.iter().enumerate() {
            let head = lines[i].code[5..].trim();
            let (name, list) = match head.split_once('(') {
                Some((n, r)) => (n.trim(), r.split(')').next().unwrap_or("")),
                None => (head, ""),
            };
            let mut params = Vec::new();
            for p in list.split(',').filter(|p| !p.trim().is_empty()) {
                let (ty, n) = p.trim().split_once(' ').ok_or("parameter type")?;
                if !["REAL", "INT", "BOOL"].contains(&ty) {
                    return Err(format!(
                        "parameter `{p}` is not read by the reference tracer"
                    ));
                }
                params.push((n.trim().to_string(), ty == "INT"));
            }
            let end = starts.get(k + 1).copied().unwrap_or(lines.len());
            out.insert(
                name.to_string(),
                Sub {
                    body: i + 1,
                    end,
                    params,
                },
            );
        }
        Ok(out)
    }

    /// Split at commas outside parentheses.
    fn args(s: &str) -> Vec<&str> {
        let (mut depth, mut from, mut out) = (0, 0, Vec::new());
        for (i, c) in s.char_indices() {
            match c {
                '(' | '[' => depth += 1,
                ')' | ']' => depth -= 1,
                ',' if depth == 0 => {
                    out.push(&s[from..i]);
                    from = i + 1;
                }
                _ => {}
            }
        }
        out.push(&s[from..]);
        out
    }

    /// A call in progress: where it returns to and what it hid of the caller.
    struct Frame {
        ret: usize,
        end: usize,
        v: HashMap<String, f64>,
        ints: Vec<String>,
        sections: Vec<(usize, usize, u64, usize)>,
    }

    pub fn trace(text: &str) -> Result<Vec<Seg>, String> {
        let lines: Vec<Line> = text.lines().map(parse_line).collect();
        let pairs = structures(&lines)?;
        let subs = subs(&lines)?;
        let mut calls: Vec<Frame> = Vec::new();
        let find = |target: &str, from: usize, dir: &str| -> Option<usize> {
            let hit = |l: &Line| match target.strip_prefix('N').and_then(|d| d.parse::<u64>().ok())
            {
                Some(n) => l.number == Some(n),
                None => l.label.as_deref() == Some(target),
            };
            let fwd = (from + 1..lines.len()).find(|&k| hit(&lines[k]));
            let back = (0..=from).rev().find(|&k| hit(&lines[k]));
            match dir {
                "GOTOF" => fwd,
                "GOTOB" => back,
                _ => fwd.or(back),
            }
        };
        let mut st = St {
            r: HashMap::new(),
            v: HashMap::new(),
            ints: Vec::new(),
        };
        let (mut pos, mut motion, mut inch) = ([f64::NAN; 3], 0u8, false);
        let mut segs = Vec::new();
        let mut for_limit: HashMap<usize, f64> = HashMap::new();
        // Section repetitions: (first line, last line, repeats left, line to go on at).
        let mut sections: Vec<(usize, usize, u64, usize)> = Vec::new();
        let mut pc = 0usize;
        let mut steps = 0u64;
        while pc < lines.len() || !calls.is_empty() {
            steps += 1;
            if steps > STEPS {
                return Err("too many steps (an endless loop?)".into());
            }
            // The end of a subprogram's lines, M17 or RET: back after the call.
            let returning = |calls: &mut Vec<Frame>,
                             st: &mut St,
                             sections: &mut Vec<(usize, usize, u64, usize)>|
             -> Option<usize> {
                let f = calls.pop()?;
                st.v = f.v;
                st.ints = f.ints;
                *sections = f.sections;
                Some(f.ret)
            };
            if calls.last().is_some_and(|f| pc >= f.end) {
                pc = returning(&mut calls, &mut st, &mut sections).unwrap_or(pc);
                continue;
            }
            let code = lines[pc].code.clone();
            let name_end = code
                .find(|c: char| !(c.is_ascii_alphanumeric() || c == '_'))
                .unwrap_or(code.len());
            if let Some(sub) = subs.get(&code[..name_end]) {
                let after = code[name_end..].trim();
                let given: Vec<&str> = match after.strip_prefix('(') {
                    Some(a) => args(a.strip_suffix(')').ok_or("call `)`")?)
                        .into_iter()
                        .filter(|_| !a.trim_end_matches(')').trim().is_empty())
                        .collect(),
                    None if after.is_empty() => Vec::new(),
                    None => return Err(format!("line {}: call with other words", pc + 1)),
                };
                if given.len() > sub.params.len() || calls.len() > 16 {
                    return Err(format!("line {}: bad call", pc + 1));
                }
                let mut v = HashMap::new();
                let mut ints = Vec::new();
                for (k, (n, int)) in sub.params.iter().enumerate() {
                    let a = given.get(k).map_or("", |a| a.trim());
                    let x = if a.is_empty() { 0.0 } else { st.eval(a)? };
                    v.insert(n.clone(), if *int { x.round() } else { x });
                    if *int {
                        ints.push(n.clone());
                    }
                }
                calls.push(Frame {
                    ret: pc + 1,
                    end: sub.end,
                    v: std::mem::replace(&mut st.v, v),
                    ints: std::mem::replace(&mut st.ints, ints),
                    sections: std::mem::take(&mut sections),
                });
                pc = sub.body;
                continue;
            }
            if code == "RET" {
                match returning(&mut calls, &mut st, &mut sections) {
                    Some(r) => {
                        pc = r;
                        continue;
                    }
                    None => break,
                }
            }
            let (first, rest) = code.split_once(' ').unwrap_or((code.as_str(), ""));
            let rest = rest.trim();
            let mut next = pc + 1;
            let mut end = false;
            let partner = |k: usize| {
                pairs
                    .get(&k)
                    .copied()
                    .ok_or(format!("line {}: unpaired", k + 1))
            };
            match first {
                "" | "STOPRE" | "ENDIF" | "REPEAT" if first != "REPEAT" || rest.is_empty() => {}
                "LOOP" => {}
                "PROC" if !rest.contains('(') => {}
                "DEF" => {
                    let (ty, names) = rest.split_once(' ').ok_or("DEF type")?;
                    for part in names.split(',') {
                        let (n, init) = part.split_once('=').unwrap_or((part, "0"));
                        let n = n.trim().to_string();
                        if ty == "INT" {
                            st.ints.push(n.clone());
                        }
                        st.v.insert(n.clone(), 0.0);
                        let v = st.eval(init.trim())?;
                        st.set(&n, v)?;
                    }
                }
                "IF" if code.contains("GOTO") => {
                    let at = code.find("GOTO").unwrap_or(code.len());
                    let cond = st.eval(code[2..at].trim())?;
                    let (dir, target) = code[at..].split_once(' ').ok_or("jump target")?;
                    if cond != 0.0 {
                        match find(target.trim(), pc, dir) {
                            Some(t) => next = t,
                            None if dir == "GOTOC" => {}
                            None => return Err(format!("line {}: no {target}", pc + 1)),
                        }
                    }
                }
                "IF" => {
                    if st.eval(rest)? == 0.0 {
                        next = match pairs.get(&(pc + 1_000_000_000)) {
                            Some(&e) => e + 1,
                            None => partner(pc)? + 1,
                        };
                    }
                }
                "ELSE" => next = partner(partner(pc)?)? + 1,
                "GOTOF" | "GOTOB" | "GOTO" | "GOTOC" => match find(rest, pc, first) {
                    Some(t) => next = t,
                    None if first == "GOTOC" => {}
                    None => return Err(format!("line {}: no {rest}", pc + 1)),
                },
                "WHILE" => {
                    if st.eval(rest)? == 0.0 {
                        next = partner(pc)? + 1;
                    }
                }
                "ENDWHILE" => next = partner(pc)?,
                "FOR" => {
                    let (var, range) = rest.split_once('=').ok_or("FOR =")?;
                    let (a, b) = range.split_once(" TO ").ok_or("FOR TO")?;
                    let a = st.eval(a.trim())?;
                    for_limit.insert(pc, st.eval(b.trim())?);
                    st.set(var, a)?;
                    if a > for_limit[&pc] {
                        next = partner(pc)? + 1;
                    }
                }
                "ENDFOR" => {
                    let f = partner(pc)?;
                    let var = lines[f].code[4..]
                        .split('=')
                        .next()
                        .unwrap_or("")
                        .trim()
                        .to_string();
                    let now = st.eval(&var)? + 1.0;
                    st.set(&var, now)?;
                    if now <= for_limit[&f] {
                        next = f + 1;
                    }
                }
                "UNTIL" => {
                    if st.eval(rest)? == 0.0 {
                        next = partner(pc)? + 1;
                    }
                }
                "ENDLOOP" => next = partner(pc)? + 1,
                "REPEAT" | "REPEATB" => {
                    let (labels, p) = rest.split_once("P=").unwrap_or((rest, "1"));
                    let n = st.eval(p.trim())? as u64;
                    let names: Vec<&str> = labels.split_whitespace().collect();
                    // The label is searched toward the program start first, then toward its end.
                    let a = find(names[0], pc, "GOTOB")
                        .or_else(|| find(names[0], pc, "GOTOF"))
                        .ok_or("section label")?;
                    let b = match (first, names.get(1)) {
                        ("REPEATB", _) => a,
                        (_, Some(l)) => (a..lines.len())
                            .find(|&k| lines[k].label.as_deref() == Some(*l))
                            .ok_or("end label")?,
                        _ => pc - 1,
                    };
                    if n > 0 {
                        sections.push((a, b, n, pc + 1));
                        next = a;
                    }
                }
                _ => {
                    // Assignments alone on their block, or a block of words.
                    let assignment = code.split_whitespace().all(|w| {
                        let lhs = w.split('=').next().unwrap_or("");
                        w.contains('=')
                            && (st.v.contains_key(lhs)
                                || lhs.starts_with("R[")
                                || lhs
                                    .strip_prefix('R')
                                    .is_some_and(|d| d.parse::<u32>().is_ok()))
                    });
                    if assignment && code.contains('=') && !code.contains("==") {
                        for w in code.split_whitespace() {
                            let (l, r) = w.split_once('=').ok_or("=")?;
                            let v = st.eval(r)?;
                            st.set(l, v)?;
                        }
                    } else {
                        let mut target = pos;
                        let mut moved = false;
                        let scale = |inch: bool| if inch { 25.4 } else { 1.0 };
                        let mut words: Vec<String> = Vec::new();
                        let clean = match code.find("MSG(") {
                            Some(m) => code[..m].to_string(),
                            None => code.clone(),
                        };
                        for w in clean.split_whitespace() {
                            words.push(w.to_string());
                        }
                        for w in &words {
                            match w.as_str() {
                                "G0" | "G00" => motion = 0,
                                "G1" | "G01" => motion = 1,
                                "G70" | "G700" => inch = true,
                                "G71" | "G710" => inch = false,
                                "G90" | "G17" | "G94" | "G54" | "G40" => {}
                                "M30" | "M2" | "M02" | "M17" => end = true,
                                _ => {
                                    let axis = match w.as_bytes()[0] {
                                        b'X' => Some(0),
                                        b'Y' => Some(1),
                                        b'Z' => Some(2),
                                        _ => None,
                                    };
                                    let letters =
                                        w.bytes().take_while(|c| c.is_ascii_alphabetic()).count();
                                    match axis {
                                        Some(k) if letters == 1 => {
                                            let t = w[1..].strip_prefix('=').unwrap_or(&w[1..]);
                                            let t = t
                                                .strip_prefix("AC(")
                                                .and_then(|x| x.strip_suffix(')'))
                                                .unwrap_or(t);
                                            target[k] = st.eval(t)? * scale(inch);
                                            moved = true;
                                        }
                                        _ if letters == 1
                                            && "FSTDMHG".contains(&w[..1])
                                            && !w.starts_with("G2")
                                            && !w.starts_with("G3")
                                            && !w.starts_with("G91") => {}
                                        _ => {
                                            return Err(format!(
                                            "line {}: `{w}` is not read by the reference tracer",
                                            pc + 1
                                        ))
                                        }
                                    }
                                }
                            }
                        }
                        if moved && (0..3).any(|k| target[k].to_bits() != pos[k].to_bits()) {
                            let cut = motion == 1;
                            if cut && target.iter().chain(&pos).any(|v| v.is_nan()) {
                                return Err(format!(
                                    "line {}: a cut from an unknown position",
                                    pc + 1
                                ));
                            }
                            segs.push(Seg {
                                cut,
                                line: pc as u64 + 1,
                                start: pos,
                                end: target,
                                arc: None,
                            });
                            pos = target;
                        }
                    }
                }
            }
            if end {
                match returning(&mut calls, &mut st, &mut sections) {
                    Some(r) => {
                        pc = r;
                        continue;
                    }
                    None => break,
                }
            }
            if next == pc + 1 {
                while let Some(s) = sections.last_mut() {
                    if s.1 != pc {
                        break;
                    }
                    s.2 -= 1;
                    if s.2 > 0 {
                        next = s.0;
                        break;
                    }
                    next = s.3;
                    sections.pop();
                }
            }
            pc = next;
        }
        Ok(segs)
    }
}
