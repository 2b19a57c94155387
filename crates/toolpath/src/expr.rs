//! A small RS274/NGC expression evaluator used only to *classify* moves (inside or outside the zone).
//!
//! errmap never rewrites a line that needs evaluation; it only asks "could this move lie in the
//! zone?". Numbers, `#n` / `#<name>` parameters with known values, `+ - * / MOD **`, unary minus,
//! brackets and `SQRT ABS SIN COS TAN` (degrees, as in LinuxCNC) are understood; anything else
//! (comparisons, unknown parameters, indirect `##n`) gives `None` = unknown.

use std::collections::HashMap;

/// Known parameter values, by normalised name (`"12"`, `"<xscale>"`).
pub type Params = HashMap<String, f64>;

/// Evaluate a word value or assignment right-hand side.
pub fn eval(text: &str, params: &Params) -> Option<f64> {
    let toks = tokenize(text)?;
    let mut p = Parser {
        toks,
        at: 0,
        params,
        depth: 0,
    };
    let v = p.sum()?;
    if p.at == p.toks.len() && v.is_finite() {
        Some(v)
    } else {
        None
    }
}

#[derive(Debug, Clone, PartialEq)]
enum Tok {
    Num(f64),
    Param(String),
    Op(char),
    Pow,
    Mod,
    Open,
    Close,
    Func(String),
}

fn tokenize(text: &str) -> Option<Vec<Tok>> {
    let b = text.as_bytes();
    let mut out = Vec::new();
    let mut i = 0;
    while i < b.len() {
        let c = b[i];
        if c == b' ' || c == b'\t' {
            i += 1;
        } else if c.is_ascii_digit() || c == b'.' {
            let s = i;
            while i < b.len() && (b[i].is_ascii_digit() || b[i] == b'.') {
                i += 1;
            }
            let mut t = text.get(s..i)?.to_string();
            if t.starts_with('.') {
                t.insert(0, '0');
            }
            if t.ends_with('.') {
                t.push('0');
            }
            out.push(Tok::Num(t.parse().ok()?));
        } else if c == b'#' {
            let s = i + 1;
            if s < b.len() && b[s] == b'<' {
                let e = text.get(s..)?.find('>')? + s + 1;
                out.push(Tok::Param(super::lexer::param_name(text.get(s..e)?)));
                i = e;
            } else {
                let mut e = s;
                while e < b.len() && b[e].is_ascii_digit() {
                    e += 1;
                }
                if e == s {
                    return None; // indirect reference: unknown
                }
                out.push(Tok::Param(text.get(s..e)?.to_string()));
                i = e;
            }
        } else if c == b'*' && i + 1 < b.len() && b[i + 1] == b'*' {
            out.push(Tok::Pow);
            i += 2;
        } else if matches!(c, b'+' | b'-' | b'*' | b'/') {
            out.push(Tok::Op(c as char));
            i += 1;
        } else if c == b'[' {
            out.push(Tok::Open);
            i += 1;
        } else if c == b']' {
            out.push(Tok::Close);
            i += 1;
        } else if c.is_ascii_alphabetic() {
            let s = i;
            while i < b.len() && b[i].is_ascii_alphabetic() {
                i += 1;
            }
            let w = text.get(s..i)?.to_ascii_uppercase();
            if w == "MOD" {
                out.push(Tok::Mod);
            } else {
                out.push(Tok::Func(w));
            }
        } else {
            return None;
        }
    }
    Some(out)
}

/// Deepest nesting of brackets, unary signs and powers evaluated; deeper is "unknown", so a
/// hostile line cannot overflow the stack of the recursive descent.
const MAX_NESTING: usize = 100;

struct Parser<'a> {
    toks: Vec<Tok>,
    at: usize,
    params: &'a Params,
    /// Current nesting (every recursion passes through [`Parser::nested`]).
    depth: usize,
}

impl Parser<'_> {
    fn peek(&self) -> Option<&Tok> {
        self.toks.get(self.at)
    }
    fn sum(&mut self) -> Option<f64> {
        let mut v = self.product()?;
        while let Some(Tok::Op(op @ ('+' | '-'))) = self.peek().cloned() {
            self.at += 1;
            let r = self.product()?;
            v = if op == '+' { v + r } else { v - r };
        }
        Some(v)
    }
    fn product(&mut self) -> Option<f64> {
        let mut v = self.power()?;
        loop {
            match self.peek().cloned() {
                Some(Tok::Op('*')) => {
                    self.at += 1;
                    v *= self.power()?;
                }
                Some(Tok::Op('/')) => {
                    self.at += 1;
                    let d = self.power()?;
                    if d == 0.0 {
                        return None;
                    }
                    v /= d;
                }
                Some(Tok::Mod) => {
                    self.at += 1;
                    let d = self.power()?;
                    if d == 0.0 {
                        return None;
                    }
                    v = v.rem_euclid(d);
                }
                _ => return Some(v),
            }
        }
    }
    /// `a ** b ** c` is right-associative: the exponent recurses.
    fn power(&mut self) -> Option<f64> {
        let v = self.unary()?;
        if let Some(Tok::Pow) = self.peek() {
            self.at += 1;
            let e = self.nested(Self::power)?;
            return Some(v.powf(e));
        }
        Some(v)
    }
    fn unary(&mut self) -> Option<f64> {
        self.nested(Self::signed)
    }
    /// Run `f` one level deeper; `None` beyond [`MAX_NESTING`].
    fn nested(&mut self, f: fn(&mut Self) -> Option<f64>) -> Option<f64> {
        if self.depth >= MAX_NESTING {
            return None;
        }
        self.depth += 1;
        let v = f(self);
        self.depth -= 1;
        v
    }
    fn signed(&mut self) -> Option<f64> {
        match self.peek().cloned()? {
            Tok::Op('-') => {
                self.at += 1;
                Some(-self.unary()?)
            }
            Tok::Op('+') => {
                self.at += 1;
                self.unary()
            }
            _ => self.atom(),
        }
    }
    fn atom(&mut self) -> Option<f64> {
        let t = self.peek().cloned()?;
        self.at += 1;
        match t {
            Tok::Num(v) => Some(v),
            Tok::Param(name) => self.params.get(&name).copied(),
            Tok::Open => {
                let v = self.sum()?;
                if self.peek() != Some(&Tok::Close) {
                    return None;
                }
                self.at += 1;
                Some(v)
            }
            Tok::Func(f) => {
                if self.peek() != Some(&Tok::Open) {
                    return None;
                }
                let a = self.atom()?;
                match f.as_str() {
                    "SQRT" if a >= 0.0 => Some(a.sqrt()),
                    "ABS" => Some(a.abs()),
                    "SIN" => Some(a.to_radians().sin()),
                    "COS" => Some(a.to_radians().cos()),
                    "TAN" => Some(a.to_radians().tan()),
                    _ => None,
                }
            }
            _ => None,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn arithmetic_and_parameters() {
        let mut p = Params::new();
        p.insert("<xscale>".into(), 2.0);
        p.insert("3".into(), 0.5);
        assert_eq!(eval("[#<xscale>*53.]", &p), Some(106.0));
        assert_eq!(eval("[#<XScale>*-1]", &p), Some(-2.0));
        assert_eq!(eval("[2019*#3+1]", &p), Some(1010.5));
        assert_eq!(eval("[0-#3]", &p), Some(-0.5));
        assert_eq!(eval("#3", &p), Some(0.5));
        assert_eq!(eval("[[1+2]*3]", &p), Some(9.0));
        assert_eq!(eval("[2**3]", &p), Some(8.0));
        assert_eq!(eval("[7 MOD 4]", &p), Some(3.0));
        assert_eq!(eval("SQRT[16]", &p), Some(4.0));
        assert_eq!(eval("[#4*2]", &p), None); // unknown parameter
        assert_eq!(eval("[#<level> EQ 0]", &p), None); // comparisons are not evaluated
        assert_eq!(eval("[1/0]", &p), None);
    }

    #[test]
    fn deep_nesting_is_unknown_not_a_stack_overflow() {
        let p = Params::new();
        let nested = |n: usize| format!("{}1{}", "[".repeat(n), "]".repeat(n));
        assert_eq!(eval(&nested(50), &p), Some(1.0));
        assert_eq!(eval(&nested(200_000), &p), None);
        assert_eq!(eval(&format!("[{}1]", "-".repeat(200_000)), &p), None);
        assert_eq!(eval(&format!("[1{}]", "**1".repeat(200_000)), &p), None);
    }
}
