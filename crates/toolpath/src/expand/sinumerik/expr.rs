//! Sinumerik arithmetic (R parameters, DEF variables, operators by the manual's priority, functions in degrees), parsed from the front of a text so a block's values end where their expression does.
//!
//! Priority, highest first (SINUMERIK 840D sl Job Planning, "Priority of the operators"): NOT
//! B_NOT, then `* / DIV MOD`, `+ -`, B_AND, B_XOR, B_OR, AND, XOR, OR, `<<`, and the comparisons
//! last. So `R1>5 AND R2<3` reads as `R1 > (5 AND R2) < 3`: a comparison next to a logical
//! operator or another comparison without parentheses is refused, not guessed.

use super::super::eval::Nesting;

/// A binary operator.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum B {
    Add,
    Sub,
    Mul,
    Div,
    IntDiv,
    Mod,
    BitAnd,
    BitXor,
    BitOr,
    And,
    Xor,
    Or,
    Concat,
    Eq,
    Ne,
    Gt,
    Ge,
    Lt,
    Le,
}

impl B {
    /// Binding strength: higher binds tighter.
    fn level(self) -> u8 {
        use B::*;
        match self {
            Eq | Ne | Gt | Ge | Lt | Le => 1,
            Concat => 2,
            Or => 3,
            Xor => 4,
            And => 5,
            BitOr => 6,
            BitXor => 7,
            BitAnd => 8,
            Add | Sub => 9,
            Mul | Div | IntDiv | Mod => 10,
        }
    }

    fn comparison(self) -> bool {
        self.level() == 1
    }

    fn logical(self) -> bool {
        matches!(self, B::And | B::Or | B::Xor)
    }
}

#[derive(Debug, Clone, PartialEq)]
pub(super) enum X {
    Num(f64),
    Str(String),
    /// An R parameter by its number (`R7`, `R[expr]`).
    R(Box<X>),
    /// A name: a DEF variable of the program, or one the program does not define.
    Name(String),
    /// A system variable (`$P_…`, `$AA_…`, `$TC_…` …), indices left out.
    System(String),
    Neg(Box<X>),
    Not(Box<X>),
    BNot(Box<X>),
    Bin(B, Box<X>, Box<X>),
    Call(String, Vec<X>),
    /// An expression in parentheses (kept for the ambiguity check).
    Paren(Box<X>),
}

#[derive(Debug, Clone, PartialEq)]
enum T {
    Num(f64),
    Str(String),
    Ident(String),
    Sym(&'static str),
}

/// Tokens and their start offsets; stops quietly at a character no expression holds (the
/// parser then ends there).
fn tokenize(text: &str) -> Vec<(T, usize)> {
    let b = text.as_bytes();
    let mut out = Vec::new();
    let mut i = 0;
    while i < b.len() {
        let c = b[i];
        let start = i;
        let tok = match c {
            b' ' | b'\t' => {
                i += 1;
                continue;
            }
            b'0'..=b'9' | b'.' => {
                while i < b.len() && (b[i].is_ascii_digit() || b[i] == b'.') {
                    i += 1;
                }
                let t = &text[start..i];
                let fixed = if t.starts_with('.') {
                    format!("0{t}")
                } else if t.ends_with('.') {
                    format!("{t}0")
                } else {
                    t.to_string()
                };
                match fixed.parse::<f64>() {
                    Ok(v) => T::Num(v),
                    Err(_) => break,
                }
            }
            b'"' => match text[i + 1..].find('"') {
                Some(e) => {
                    i += e + 2;
                    T::Str(text[start + 1..i - 1].to_string())
                }
                None => break,
            },
            _ if c.is_ascii_alphabetic() || c == b'_' || c == b'$' => {
                while i < b.len() && (b[i].is_ascii_alphanumeric() || b[i] == b'_' || b[i] == b'$')
                {
                    i += 1;
                }
                T::Ident(text[start..i].to_ascii_uppercase())
            }
            _ => {
                let two = text.get(i..i + 2).unwrap_or("");
                let sym = match two {
                    "==" => Some("=="),
                    "<>" => Some("<>"),
                    "<=" => Some("<="),
                    ">=" => Some(">="),
                    "<<" => Some("<<"),
                    _ => None,
                };
                if let Some(s) = sym {
                    i += 2;
                    T::Sym(s)
                } else {
                    let one = match c {
                        b'+' => "+",
                        b'-' => "-",
                        b'*' => "*",
                        b'/' => "/",
                        b'(' => "(",
                        b')' => ")",
                        b'[' => "[",
                        b']' => "]",
                        b',' => ",",
                        b'<' => "<",
                        b'>' => ">",
                        b'=' => "=",
                        _ => break,
                    };
                    i += 1;
                    T::Sym(one)
                }
            }
        };
        out.push((tok, start));
    }
    out
}

/// Deepest nesting parsed; deeper is refused so a hostile line cannot overflow the stack.
struct P<'t> {
    toks: &'t [(T, usize)],
    at: usize,
    depth: Nesting,
}

/// Parse an expression from the start of `text`: the expression and the byte offset where it
/// ends (the first token that cannot continue it).
pub(super) fn parse_prefix(text: &str) -> Result<(X, usize), String> {
    let toks = tokenize(text);
    let mut p = P {
        toks: &toks,
        at: 0,
        depth: Nesting::default(),
    };
    let e = p.binary(1)?;
    let end = toks.get(p.at).map_or(text.len(), |t| t.1);
    Ok((e, end))
}

/// Parse all of `text` as one expression.
pub(super) fn parse(text: &str) -> Result<X, String> {
    let (e, end) = parse_prefix(text)?;
    if text[end..].trim().is_empty() {
        Ok(e)
    } else {
        Err(format!(
            "cannot read `{}` in the expression `{}`",
            text[end..].trim(),
            text.trim()
        ))
    }
}

impl P<'_> {
    fn peek(&self) -> Option<&T> {
        self.toks.get(self.at).map(|t| &t.0)
    }

    fn op(&self) -> Option<B> {
        Some(match self.peek()? {
            T::Sym("+") => B::Add,
            T::Sym("-") => B::Sub,
            T::Sym("*") => B::Mul,
            T::Sym("/") => B::Div,
            T::Sym("==") => B::Eq,
            T::Sym("<>") => B::Ne,
            T::Sym(">") => B::Gt,
            T::Sym(">=") => B::Ge,
            T::Sym("<") => B::Lt,
            T::Sym("<=") => B::Le,
            T::Sym("<<") => B::Concat,
            T::Ident(w) => match w.as_str() {
                "DIV" => B::IntDiv,
                "MOD" => B::Mod,
                "B_AND" => B::BitAnd,
                "B_XOR" => B::BitXor,
                "B_OR" => B::BitOr,
                "AND" => B::And,
                "XOR" => B::Xor,
                "OR" => B::Or,
                _ => return None,
            },
            _ => return None,
        })
    }

    fn binary(&mut self, min: u8) -> Result<X, String> {
        self.depth.enter()?;
        let mut left = self.unary()?;
        while let Some(op) = self.op() {
            let l = op.level();
            if l < min {
                break;
            }
            self.at += 1;
            let right = self.binary(l + 1)?;
            if op.comparison() {
                for side in [&left, &right] {
                    let bare = match side {
                        X::Bin(o, ..) => o.comparison() || o.logical(),
                        X::Not(_) => true,
                        _ => false,
                    };
                    if bare {
                        return Err("a comparison next to another comparison or to AND/OR/XOR/NOT without parentheses: the controller compares last, so this is rarely what it seems".into());
                    }
                }
            }
            left = X::Bin(op, Box::new(left), Box::new(right));
        }
        self.depth.leave();
        Ok(left)
    }

    fn unary(&mut self) -> Result<X, String> {
        let wrap: fn(Box<X>) -> X = match self.peek() {
            Some(T::Sym("-")) => X::Neg,
            Some(T::Sym("+")) => |e| *e,
            Some(T::Ident(w)) if w == "NOT" => X::Not,
            Some(T::Ident(w)) if w == "B_NOT" => X::BNot,
            _ => return self.atom(),
        };
        self.at += 1;
        self.depth.enter()?;
        let e = self.unary()?;
        self.depth.leave();
        Ok(wrap(Box::new(e)))
    }

    fn expect(&mut self, sym: &'static str) -> Result<(), String> {
        if self.peek() == Some(&T::Sym(sym)) {
            self.at += 1;
            Ok(())
        } else {
            Err(format!("`{sym}` expected"))
        }
    }

    fn atom(&mut self) -> Result<X, String> {
        let t = self
            .peek()
            .cloned()
            .ok_or_else(|| "an expression ends too early".to_string())?;
        self.at += 1;
        match t {
            T::Num(v) => Ok(X::Num(v)),
            T::Str(s) => Ok(X::Str(s)),
            T::Sym("(") => {
                self.depth.enter()?;
                let e = self.binary(1)?;
                self.depth.leave();
                self.expect(")")?;
                Ok(X::Paren(Box::new(e)))
            }
            T::Ident(name) => {
                if name.starts_with('$') {
                    // Indices of a system variable (`$TC_DP3[1,2]`) are read and dropped.
                    if self.peek() == Some(&T::Sym("[")) {
                        self.args("]")?;
                    }
                    return Ok(X::System(name));
                }
                if let Some(n) = name.strip_prefix('R') {
                    if !n.is_empty() && n.bytes().all(|c| c.is_ascii_digit()) {
                        let v: f64 = n.parse().map_err(|_| format!("`{name}`"))?;
                        return Ok(X::R(Box::new(X::Num(v))));
                    }
                    if n.is_empty() && self.peek() == Some(&T::Sym("[")) {
                        self.at += 1;
                        self.depth.enter()?;
                        let e = self.binary(1)?;
                        self.depth.leave();
                        self.expect("]")?;
                        return Ok(X::R(Box::new(e)));
                    }
                }
                match self.peek() {
                    Some(T::Sym("(")) => {
                        let args = self.args(")")?;
                        Ok(X::Call(name, args))
                    }
                    Some(T::Sym("[")) => Err(format!(
                        "`{name}[…]`: arrays are not run by errmap's {}",
                        super::super::expand_words()
                    )),
                    _ => Ok(X::Name(name)),
                }
            }
            T::Sym(s) => Err(format!("`{s}` where a value is expected")),
        }
    }

    /// `( a, b, … )` or `[ … ]` after a name: the arguments.
    fn args(&mut self, close: &'static str) -> Result<Vec<X>, String> {
        self.at += 1;
        let mut out = Vec::new();
        if self.peek() == Some(&T::Sym(close)) {
            self.at += 1;
            return Ok(out);
        }
        loop {
            self.depth.enter()?;
            out.push(self.binary(1)?);
            self.depth.leave();
            match self.peek() {
                Some(T::Sym(",")) => self.at += 1,
                Some(T::Sym(s)) if *s == close => {
                    self.at += 1;
                    return Ok(out);
                }
                _ => return Err(format!("`{close}` expected after the arguments")),
            }
        }
    }
}

/// Where values come from: an R parameter by number, a name (upper-cased).
pub(super) trait Env {
    fn r(&self, n: u32) -> Result<f64, String>;
    fn name(&self, name: &str) -> Result<f64, String>;
}

/// Evaluate to a number.
pub(super) fn value(e: &X, env: &dyn Env) -> Result<f64, String> {
    let v = match e {
        X::Num(v) => *v,
        X::Str(s) => return Err(format!("the text \"{s}\" where a number is needed")),
        X::Paren(a) => value(a, env)?,
        X::R(i) => {
            let n = value(i, env)?;
            if n.fract() != 0.0 || !(0.0..1e6).contains(&n) {
                return Err(format!("R[{n}] is not an R parameter"));
            }
            env.r(n as u32)?
        }
        X::Name(n) => match n.as_str() {
            "TRUE" => 1.0,
            "FALSE" => 0.0,
            _ => env.name(n)?,
        },
        X::System(n) => {
            return Err(format!(
                "{n} is a system variable, whose value the controller knows only at run time"
            ))
        }
        X::Neg(a) => -value(a, env)?,
        X::Not(a) => f64::from(u8::from(value(a, env)? == 0.0)),
        X::BNot(a) => !integer(value(a, env)?, "B_NOT")? as f64,
        X::Bin(op, a, b) => {
            if *op == B::Concat {
                return Err("`<<` joins texts, which errmap does not evaluate".into());
            }
            let (x, y) = (value(a, env)?, value(b, env)?);
            let truth = |c: bool| f64::from(u8::from(c));
            match op {
                B::Add => x + y,
                B::Sub => x - y,
                B::Mul => x * y,
                B::Div | B::IntDiv | B::Mod if y == 0.0 => return Err("division by zero".into()),
                B::Div => x / y,
                // DIV: the quotient without its fraction; MOD: the remainder of the integer
                // division. The manual gives no example with a negative operand: refused.
                B::IntDiv | B::Mod if x < 0.0 || y < 0.0 => {
                    return Err(format!(
                        "{} of a negative value ({x}, {y}), whose sign the manual does not state",
                        if *op == B::Mod { "MOD" } else { "DIV" }
                    ))
                }
                B::IntDiv => (x / y).trunc(),
                B::Mod => x % y,
                B::BitAnd => (integer(x, "B_AND")? & integer(y, "B_AND")?) as f64,
                B::BitXor => (integer(x, "B_XOR")? ^ integer(y, "B_XOR")?) as f64,
                B::BitOr => (integer(x, "B_OR")? | integer(y, "B_OR")?) as f64,
                B::And => truth(x != 0.0 && y != 0.0),
                B::Xor => truth((x != 0.0) != (y != 0.0)),
                B::Or => truth(x != 0.0 || y != 0.0),
                B::Eq => truth(x == y),
                B::Ne => truth(x != y),
                B::Gt => truth(x > y),
                B::Ge => truth(x >= y),
                B::Lt => truth(x < y),
                B::Le => truth(x <= y),
                B::Concat => return Err("`<<`".into()),
            }
        }
        X::Call(f, args) => function(f, args, env)?,
    };
    if v.is_finite() {
        Ok(v)
    } else {
        Err("the expression's value is not a finite number".into())
    }
}

fn integer(v: f64, what: &str) -> Result<i64, String> {
    if v.fract() == 0.0 && v.abs() < 1e15 {
        Ok(v as i64)
    } else {
        Err(format!("{what} of a value with a fraction ({v})"))
    }
}

/// The functions whose value is in the program: angles in degrees.
fn function(f: &str, args: &[X], env: &dyn Env) -> Result<f64, String> {
    let arity = match f {
        "ATAN2" | "MINVAL" | "MAXVAL" => 2,
        "SIN" | "COS" | "TAN" | "ASIN" | "ACOS" | "SQRT" | "ABS" | "POT" | "TRUNC" | "ROUND"
        | "ROUNDUP" | "LN" | "EXP" => 1,
        "GETT" | "GETACTT" | "GETACTTD" | "GETT_ID" | "NEWT" | "GETEXET" | "GETSELT" | "TOOLENV"
        | "GETTENV" | "GETTCOR" | "SETTCOR" => {
            return Err(format!(
                "{f}(…) reads the tool management of the controller at run time"
            ))
        }
        _ => {
            return Err(format!(
                "{f}(…) is not a function errmap evaluates (SIN COS TAN ASIN ACOS ATAN2 SQRT ABS POT TRUNC ROUND ROUNDUP LN EXP MINVAL MAXVAL)"
            ))
        }
    };
    if args.len() != arity {
        return Err(format!("{f} takes {arity} argument(s)"));
    }
    let x = value(&args[0], env)?;
    let y = if arity == 2 {
        value(&args[1], env)?
    } else {
        0.0
    };
    Ok(match f {
        "SIN" => x.to_radians().sin(),
        "COS" => x.to_radians().cos(),
        "TAN" => x.to_radians().tan(),
        "ASIN" if (-1.0..=1.0).contains(&x) => x.asin().to_degrees(),
        "ACOS" if (-1.0..=1.0).contains(&x) => x.acos().to_degrees(),
        // ATAN2(y, x): the angle of the vector (x, y), −180° … 180°.
        "ATAN2" => x.atan2(y).to_degrees(),
        "SQRT" if x >= 0.0 => x.sqrt(),
        "ABS" => x.abs(),
        "POT" => x * x,
        "TRUNC" => x.trunc(),
        "ROUND" => x.round(),
        "ROUNDUP" => x.ceil(),
        "LN" if x > 0.0 => x.ln(),
        "EXP" => x.exp(),
        "MINVAL" => x.min(y),
        "MAXVAL" => x.max(y),
        _ => return Err(format!("{f}({x}) is outside the function's domain")),
    })
}

/// The first variable a failed evaluation names, for the column of its refusal: a system
/// variable, an R parameter or a name.
pub(super) fn names(e: &X, out: &mut Vec<String>) {
    match e {
        X::R(i) => {
            if let X::Num(n) = **i {
                out.push(format!("R{n}"));
            }
            names(i, out);
        }
        X::Name(n) | X::System(n) => out.push(n.clone()),
        X::Neg(a) | X::Not(a) | X::BNot(a) | X::Paren(a) => names(a, out),
        X::Bin(_, a, b) => {
            names(a, out);
            names(b, out);
        }
        X::Call(f, args) => {
            out.push(f.clone());
            for a in args {
                names(a, out);
            }
        }
        X::Num(_) | X::Str(_) => {}
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    struct E;
    impl Env for E {
        fn r(&self, n: u32) -> Result<f64, String> {
            match n {
                1 => Ok(2.0),
                2 => Ok(-2.5),
                _ => Err(format!("R{n} is not set")),
            }
        }
        fn name(&self, name: &str) -> Result<f64, String> {
            match name {
                "ZS" => Ok(5.0),
                _ => Err(format!("{name} undefined")),
            }
        }
    }

    fn v(t: &str) -> Result<f64, String> {
        value(&parse(t)?, &E)
    }

    #[test]
    fn priority_follows_the_manual() {
        assert_eq!(v("1+2*3"), Ok(7.0));
        assert_eq!(v("(1+2)*3"), Ok(9.0));
        assert_eq!(v("7 DIV 2"), Ok(3.0));
        assert_eq!(v("7 MOD 4"), Ok(3.0));
        assert_eq!(v("R1*ZS-1"), Ok(9.0));
        assert_eq!(v("R[1]+R[0+1]"), Ok(4.0));
        assert_eq!(v("(R1>1) AND (ZS<6)"), Ok(1.0));
        assert_eq!(v("NOT (R1==2)"), Ok(0.0));
        assert_eq!(v("R1<(ZS-0.5*R1)"), Ok(1.0));
        assert_eq!(v("6 B_AND 3"), Ok(2.0));
        // A comparison beside AND without parentheses is refused.
        assert!(v("R1>1 AND ZS<6").is_err());
        assert!(v("1<2<3").is_err());
    }

    #[test]
    fn functions_in_degrees_and_rounding() {
        assert!((v("SIN(30)").unwrap() - 0.5).abs() < 1e-12);
        assert!((v("ATAN2(1,-1)").unwrap() - 135.0).abs() < 1e-12);
        assert_eq!(v("TRUNC(R2)"), Ok(-2.0));
        assert_eq!(v("ROUND(2.5)"), Ok(3.0));
        assert_eq!(v("ROUNDUP(-3.6)"), Ok(-3.0));
        assert_eq!(v("POT(3)"), Ok(9.0));
        assert_eq!(v("MINVAL(R1,ZS)"), Ok(2.0));
        assert!(v("$AA_IM[X]+1").unwrap_err().contains("run time"));
        assert!(v("GETT(\"T1\")").unwrap_err().contains("run time"));
        assert!(v("R9").is_err());
    }

    #[test]
    fn a_prefix_ends_where_the_expression_does() {
        let t = "-(R1+1)*2 Y=3";
        let (e, end) = parse_prefix(t).unwrap();
        assert_eq!(&t[end..], "Y=3");
        assert_eq!(value(&e, &E), Ok(-6.0));
        let t = "R10<(R1-0.5) GOTOB LAB";
        let (_, end) = parse_prefix(t).unwrap();
        assert_eq!(&t[end..], "GOTOB LAB");
    }

    #[test]
    fn deep_nesting_is_refused_not_a_stack_overflow() {
        let deep = format!("{}1{}", "(".repeat(10_000), ")".repeat(10_000));
        assert!(v(&deep).is_err());
        assert!(v(&"-".repeat(10_000)).is_err());
    }
}
