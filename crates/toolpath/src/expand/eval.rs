//! Expressions of Fanuc custom macro B and LinuxCNC, compiled once and evaluated exactly as the controller does (precedence, degrees, rounding functions), vacant values kept apart from 0.

/// Which controller's rules an expression follows.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Rules {
    /// Fanuc macro B: `AND OR XOR` are bitwise at the level of `*` / `+`; `FIX` truncates
    /// toward 0 and `FUP` away from 0; comparisons only in `IF`/`WHILE` conditions.
    Fanuc,
    /// LinuxCNC: `**` binds tightest, comparisons below `+ -`, logical `AND OR XOR` lowest;
    /// `FIX` = floor, `FUP` = ceiling.
    Linuxcnc,
}

/// A parameter reference.
#[derive(Debug, Clone, PartialEq)]
pub(crate) enum Var {
    Number(u32),
    /// LinuxCNC `#<name>` (lower-cased, spaces removed).
    Named(String),
    /// `#[expr]` / `##n`.
    Indirect(Box<Expr>),
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Op {
    Add,
    Sub,
    Mul,
    Div,
    Mod,
    Pow,
    Eq,
    Ne,
    Gt,
    Ge,
    Lt,
    Le,
    And,
    Or,
    Xor,
}

#[derive(Debug, Clone, PartialEq)]
pub(crate) enum Expr {
    Num(f64),
    Var(Var),
    Neg(Box<Expr>),
    Bin(Op, Box<Expr>, Box<Expr>),
    Func(String, Box<Expr>),
    /// `ATAN[a]/[b]`: the angle of (b, a), degrees.
    Atan2(Box<Expr>, Box<Expr>),
    /// LinuxCNC `EXISTS[#<name>]`.
    Exists(String),
}

/// Where parameter values come from: `Ok(None)` is a vacant (never set) variable, `Err` a
/// variable whose value only the machine knows (the message names it).
pub(crate) trait Env {
    fn get(&self, var: &Var, number: Option<u32>) -> Result<Option<f64>, String>;
}

/// Deepest nesting compiled; deeper is refused so a hostile line cannot overflow the stack.
const MAX_NESTING: usize = 64;

/// How deep an expression parser has nested (brackets, unary operators, operator levels): past
/// [`MAX_NESTING`] the expression is refused, so a hostile one cannot exhaust the stack. Shared
/// by the Fanuc/LinuxCNC and the Sinumerik parsers.
#[derive(Debug, Default)]
pub(crate) struct Nesting(usize);

impl Nesting {
    /// One level deeper, refused past [`MAX_NESTING`].
    pub(crate) fn enter(&mut self) -> Result<(), String> {
        self.0 += 1;
        if self.0 > MAX_NESTING {
            return Err(format!(
                "an expression nested deeper than {MAX_NESTING} levels"
            ));
        }
        Ok(())
    }

    /// Back one level.
    pub(crate) fn leave(&mut self) {
        self.0 -= 1;
    }
}

/// Compile `text` (a word value, an assignment's right side or a condition in brackets).
pub(crate) fn parse(text: &str, rules: Rules) -> Result<Expr, String> {
    let toks = tokenize(text)?;
    let mut p = Parser {
        toks,
        at: 0,
        rules,
        depth: Nesting::default(),
    };
    let e = p.top()?;
    if p.at != p.toks.len() {
        return Err(format!("cannot read the expression `{}`", text.trim()));
    }
    Ok(e)
}

#[derive(Debug, Clone, PartialEq)]
enum Tok {
    Num(f64),
    Hash,
    Name(String),
    Word(String),
    Op(u8),
    Pow,
    Open,
    Close,
    Comma,
}

fn tokenize(text: &str) -> Result<Vec<Tok>, String> {
    let b = text.as_bytes();
    let mut out = Vec::new();
    let mut i = 0;
    while i < b.len() {
        let c = b[i];
        match c {
            b' ' | b'\t' => i += 1,
            b'0'..=b'9' | b'.' => {
                let s = i;
                while i < b.len() && (b[i].is_ascii_digit() || b[i] == b'.') {
                    i += 1;
                }
                let t = &text[s..i];
                let fixed = match (t.starts_with('.'), t.ends_with('.')) {
                    (_, true) if t == "." => return Err("a lone `.` is not a number".into()),
                    (true, _) => format!("0{t}"),
                    (_, true) => format!("{t}0"),
                    _ => t.to_string(),
                };
                out.push(Tok::Num(
                    fixed
                        .parse()
                        .map_err(|_| format!("`{t}` is not a number"))?,
                ));
            }
            b'#' => {
                out.push(Tok::Hash);
                i += 1;
                if i < b.len() && b[i] == b'<' {
                    let e = text[i..]
                        .find('>')
                        .ok_or_else(|| "a `#<` name without its `>`".to_string())?;
                    out.push(Tok::Name(crate::lexer::param_name(&text[i..i + e + 1])));
                    i += e + 1;
                }
            }
            b'*' if b.get(i + 1) == Some(&b'*') => {
                out.push(Tok::Pow);
                i += 2;
            }
            b'+' | b'-' | b'*' | b'/' => {
                out.push(Tok::Op(c));
                i += 1;
            }
            b'[' => {
                out.push(Tok::Open);
                i += 1;
            }
            b']' => {
                out.push(Tok::Close);
                i += 1;
            }
            b',' => {
                out.push(Tok::Comma);
                i += 1;
            }
            _ if c.is_ascii_alphabetic() => {
                let s = i;
                while i < b.len() && b[i].is_ascii_alphabetic() {
                    i += 1;
                }
                out.push(Tok::Word(text[s..i].to_ascii_uppercase()));
            }
            _ => {
                let ch = text[i..].chars().next().unwrap_or('?');
                return Err(format!("`{ch}` has no meaning in an expression"));
            }
        }
    }
    Ok(out)
}

struct Parser {
    toks: Vec<Tok>,
    at: usize,
    rules: Rules,
    depth: Nesting,
}

const FUNCTIONS: [&str; 16] = [
    "SIN", "COS", "TAN", "ASIN", "ACOS", "ATAN", "SQRT", "SQR", "ABS", "ROUND", "FIX", "FUP", "LN",
    "EXP", "BIN", "BCD",
];

impl Parser {
    fn peek(&self) -> Option<&Tok> {
        self.toks.get(self.at)
    }

    fn word_op(&self) -> Option<Op> {
        match self.peek()? {
            Tok::Word(w) => Some(match w.as_str() {
                "EQ" => Op::Eq,
                "NE" => Op::Ne,
                "GT" => Op::Gt,
                "GE" => Op::Ge,
                "LT" => Op::Lt,
                "LE" => Op::Le,
                "AND" => Op::And,
                "OR" => Op::Or,
                "XOR" => Op::Xor,
                "MOD" => Op::Mod,
                _ => return None,
            }),
            Tok::Op(b'+') => Some(Op::Add),
            Tok::Op(b'-') => Some(Op::Sub),
            Tok::Op(b'*') => Some(Op::Mul),
            Tok::Op(b'/') => Some(Op::Div),
            Tok::Pow => Some(Op::Pow),
            _ => None,
        }
    }

    /// Binding level of a binary operator (higher binds tighter).
    fn level(&self, op: Op) -> u8 {
        use Op::*;
        match (self.rules, op) {
            (_, Pow) => 5,
            (Rules::Fanuc, Mul | Div | Mod | And) => 4,
            (Rules::Fanuc, Add | Sub | Or | Xor) => 3,
            (Rules::Linuxcnc, Mul | Div | Mod) => 4,
            (Rules::Linuxcnc, Add | Sub) => 3,
            (_, Eq | Ne | Gt | Ge | Lt | Le) => 2,
            (Rules::Linuxcnc, And | Or | Xor) => 1,
        }
    }

    fn top(&mut self) -> Result<Expr, String> {
        self.binary(1)
    }

    fn binary(&mut self, min: u8) -> Result<Expr, String> {
        self.depth.enter()?;
        let mut left = self.unary()?;
        while let Some(op) = self.word_op() {
            let l = self.level(op);
            if l < min {
                break;
            }
            self.at += 1;
            // Operators of one level group left to right (LinuxCNC: also `**`).
            let right = self.binary(l + 1)?;
            left = Expr::Bin(op, Box::new(left), Box::new(right));
        }
        self.depth.leave();
        Ok(left)
    }

    fn unary(&mut self) -> Result<Expr, String> {
        match self.peek() {
            Some(Tok::Op(b'-')) => {
                self.at += 1;
                self.depth.enter()?;
                let e = self.unary()?;
                self.depth.leave();
                Ok(Expr::Neg(Box::new(e)))
            }
            Some(Tok::Op(b'+')) => {
                self.at += 1;
                self.depth.enter()?;
                let e = self.unary();
                self.depth.leave();
                e
            }
            _ => self.atom(),
        }
    }

    fn bracket(&mut self) -> Result<Expr, String> {
        if self.peek() != Some(&Tok::Open) {
            return Err("`[` expected".into());
        }
        self.at += 1;
        let e = self.top()?;
        if self.peek() != Some(&Tok::Close) {
            return Err("a `[` without its `]`".into());
        }
        self.at += 1;
        Ok(e)
    }

    fn atom(&mut self) -> Result<Expr, String> {
        let t = self
            .peek()
            .cloned()
            .ok_or_else(|| "an expression ends too early".to_string())?;
        self.at += 1;
        match t {
            Tok::Num(v) => Ok(Expr::Num(v)),
            Tok::Open => {
                self.at -= 1;
                self.bracket()
            }
            Tok::Hash => {
                let var = match self.peek().cloned() {
                    Some(Tok::Num(v)) if v.fract() == 0.0 && v < 1e9 => {
                        self.at += 1;
                        Var::Number(v as u32)
                    }
                    Some(Tok::Name(n)) => {
                        self.at += 1;
                        Var::Named(n)
                    }
                    Some(Tok::Open) | Some(Tok::Hash) => {
                        self.depth.enter()?;
                        let e = self.atom()?;
                        self.depth.leave();
                        Var::Indirect(Box::new(e))
                    }
                    _ => return Err("`#` without a parameter number".into()),
                };
                Ok(Expr::Var(var))
            }
            Tok::Word(w) if w == "EXISTS" && self.rules == Rules::Linuxcnc => {
                let ok = self.peek() == Some(&Tok::Open)
                    && self.toks.get(self.at + 1) == Some(&Tok::Hash)
                    && self.toks.get(self.at + 3) == Some(&Tok::Close);
                match (ok, self.toks.get(self.at + 2).cloned()) {
                    (true, Some(Tok::Name(n))) => {
                        self.at += 4;
                        Ok(Expr::Exists(n))
                    }
                    _ => Err("EXISTS takes one #<name>".into()),
                }
            }
            Tok::Word(w) if FUNCTIONS.contains(&w.as_str()) => {
                self.depth.enter()?;
                let arg = if w == "ATAN" && self.toks.get(self.at + 1).is_some() {
                    self.bracket_or_pair()?
                } else {
                    (self.bracket()?, None)
                };
                self.depth.leave();
                match (w.as_str(), arg) {
                    ("ATAN", (a, Some(b))) => Ok(Expr::Atan2(Box::new(a), Box::new(b))),
                    (_, (a, None)) => Ok(Expr::Func(w, Box::new(a))),
                    _ => Err("a function with two arguments".into()),
                }
            }
            Tok::Word(w) => Err(format!("`{w}` is not a function or operator errmap knows")),
            _ => Err("an expression errmap cannot read".into()),
        }
    }

    /// `ATAN[a]/[b]` or `ATAN[a,b]` (two arguments), or `ATAN[a]`.
    fn bracket_or_pair(&mut self) -> Result<(Expr, Option<Expr>), String> {
        if self.peek() != Some(&Tok::Open) {
            return Err("`[` expected after ATAN".into());
        }
        self.at += 1;
        let a = self.top()?;
        if self.peek() == Some(&Tok::Comma) {
            self.at += 1;
            let b = self.top()?;
            if self.peek() != Some(&Tok::Close) {
                return Err("a `[` without its `]`".into());
            }
            self.at += 1;
            return Ok((a, Some(b)));
        }
        if self.peek() != Some(&Tok::Close) {
            return Err("a `[` without its `]`".into());
        }
        self.at += 1;
        if self.peek() == Some(&Tok::Op(b'/')) && self.toks.get(self.at + 1) == Some(&Tok::Open) {
            self.at += 1;
            let b = self.bracket()?;
            return Ok((a, Some(b)));
        }
        Ok((a, None))
    }
}

/// Evaluate; `Ok(None)` is vacant (a vacant variable read alone).
pub(crate) fn eval(e: &Expr, rules: Rules, env: &dyn Env) -> Result<Option<f64>, String> {
    match e {
        Expr::Var(v) => {
            let n = match v {
                Var::Indirect(i) => Some(index(&value(i, rules, env)?)?),
                Var::Number(n) => Some(*n),
                Var::Named(_) => None,
            };
            env.get(v, n)
        }
        Expr::Bin(op @ (Op::Eq | Op::Ne), a, b) if rules == Rules::Fanuc => {
            // Fanuc: in EQ and NE a vacant value differs from 0 (and equals vacant).
            let (a, b) = (eval(a, rules, env)?, eval(b, rules, env)?);
            let same = match (a, b) {
                (None, None) => true,
                (Some(x), Some(y)) => x == y,
                _ => false,
            };
            Ok(Some(f64::from(u8::from(same == (*op == Op::Eq)))))
        }
        _ => value(e, rules, env).map(Some),
    }
}

fn index(v: &f64) -> Result<u32, String> {
    if v.fract() == 0.0 && *v >= 0.0 && *v < 1e9 {
        Ok(*v as u32)
    } else {
        Err(format!("`{v}` is not a parameter number"))
    }
}

fn integer(v: f64, what: &str) -> Result<i64, String> {
    if v.fract() == 0.0 && v.abs() < 1e15 {
        Ok(v as i64)
    } else {
        Err(format!(
            "{what} of a value with a fraction ({v}), which errmap does not reproduce"
        ))
    }
}

/// Evaluate to a number: a vacant variable here is refused.
pub(crate) fn value(e: &Expr, rules: Rules, env: &dyn Env) -> Result<f64, String> {
    let v = match e {
        Expr::Num(v) => *v,
        Expr::Var(var) => match eval(e, rules, env)? {
            Some(v) => v,
            None => {
                return Err(format!(
                    "{} is read before the program sets it (vacant), so its value is not in the program",
                    var_name(var, rules, env)
                ))
            }
        },
        Expr::Neg(a) => -value(a, rules, env)?,
        Expr::Exists(n) => f64::from(u8::from(
            env.get(&Var::Named(n.clone()), None)?.is_some(),
        )),
        Expr::Bin(op, a, b) => {
            if matches!(op, Op::Eq | Op::Ne) && rules == Rules::Fanuc {
                return eval(e, rules, env)?.ok_or_else(|| "vacant".to_string());
            }
            let (x, y) = (value(a, rules, env)?, value(b, rules, env)?);
            let truth = |c: bool| f64::from(u8::from(c));
            match op {
                Op::Add => x + y,
                Op::Sub => x - y,
                Op::Mul => x * y,
                Op::Div if y == 0.0 => return Err("division by zero".into()),
                Op::Div => x / y,
                Op::Mod if y == 0.0 => return Err("MOD by zero".into()),
                Op::Mod => match rules {
                    // LinuxCNC: the result has the sign of the divisor's magnitude (fmod then +y if < 0).
                    Rules::Linuxcnc => {
                        let r = x % y;
                        if r < 0.0 {
                            r + y.abs()
                        } else {
                            r
                        }
                    }
                    Rules::Fanuc => x % y,
                },
                Op::Pow => x.powf(y),
                Op::Eq => truth(x == y),
                Op::Ne => truth(x != y),
                Op::Gt => truth(x > y),
                Op::Ge => truth(x >= y),
                Op::Lt => truth(x < y),
                Op::Le => truth(x <= y),
                Op::And | Op::Or | Op::Xor if rules == Rules::Linuxcnc => {
                    let (p, q) = (x != 0.0, y != 0.0);
                    truth(match op {
                        Op::And => p && q,
                        Op::Or => p || q,
                        _ => p != q,
                    })
                }
                Op::And => (integer(x, "AND")? & integer(y, "AND")?) as f64,
                Op::Or => (integer(x, "OR")? | integer(y, "OR")?) as f64,
                Op::Xor => (integer(x, "XOR")? ^ integer(y, "XOR")?) as f64,
            }
        }
        Expr::Atan2(a, b) => {
            let deg = value(a, rules, env)?.atan2(value(b, rules, env)?).to_degrees();
            angle(deg, rules, "ATAN")?
        }
        Expr::Func(f, a) => {
            let x = value(a, rules, env)?;
            match f.as_str() {
                "SIN" => x.to_radians().sin(),
                "COS" => x.to_radians().cos(),
                "TAN" => x.to_radians().tan(),
                "ASIN" if (-1.0..=1.0).contains(&x) => angle(x.asin().to_degrees(), rules, "ASIN")?,
                "ACOS" if (-1.0..=1.0).contains(&x) => x.acos().to_degrees(),
                "ATAN" => angle(x.atan().to_degrees(), rules, "ATAN")?,
                "SQRT" | "SQR" if x >= 0.0 => x.sqrt(),
                "ABS" => x.abs(),
                "ROUND" => x.round(),
                "FIX" if rules == Rules::Fanuc => x.trunc(),
                "FUP" if rules == Rules::Fanuc => {
                    if x.fract() == 0.0 {
                        x
                    } else {
                        x.trunc() + x.signum()
                    }
                }
                "FIX" => x.floor(),
                "FUP" => x.ceil(),
                "LN" if x > 0.0 => x.ln(),
                "EXP" => x.exp(),
                "BIN" | "BCD" => {
                    return Err(format!(
                        "{f}[…] converts signals for the machine's PMC, which errmap does not reproduce"
                    ))
                }
                _ => return Err(format!("{f}[{x}] is outside the function's domain")),
            }
        }
    };
    if v.is_finite() {
        Ok(v)
    } else {
        Err("the expression's value is not a finite number".into())
    }
}

/// Fanuc returns the angle of ATAN (and ASIN) in 0…360° or −180…180° by machine parameter
/// (No. 6004#0 NAT): a negative angle is refused there as its value depends on the machine.
fn angle(deg: f64, rules: Rules, f: &str) -> Result<f64, String> {
    if rules == Rules::Fanuc && deg < 0.0 {
        return Err(format!(
            "{f} gives {deg}°, which a Fanuc returns as {}° or {deg}° by machine parameter 6004#0 (NAT)",
            deg + 360.0
        ));
    }
    Ok(deg)
}

/// How a variable is written in messages: `#5021`, `#<_x>`.
pub(crate) fn var_name(var: &Var, rules: Rules, env: &dyn Env) -> String {
    match var {
        Var::Number(n) => format!("#{n}"),
        Var::Named(n) => format!("#{n}"),
        Var::Indirect(e) => match value(e, rules, env) {
            Ok(v) => format!("#{v}"),
            Err(_) => "#[…]".into(),
        },
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::collections::HashMap;

    struct M(HashMap<u32, f64>);
    impl Env for M {
        fn get(&self, _v: &Var, n: Option<u32>) -> Result<Option<f64>, String> {
            Ok(n.and_then(|n| self.0.get(&n).copied()))
        }
    }

    fn f(text: &str) -> Result<f64, String> {
        let env = M([(1, 1.2), (2, -1.2), (3, 2.0)].into_iter().collect());
        value(&parse(text, Rules::Fanuc)?, Rules::Fanuc, &env)
    }

    fn l(text: &str) -> Result<f64, String> {
        let env = M([(1, 1.2), (2, -1.2), (3, 2.0)].into_iter().collect());
        value(&parse(text, Rules::Linuxcnc)?, Rules::Linuxcnc, &env)
    }

    /// The Fanuc manual's examples: FIX[1.2] = 1, FIX[−1.2] = −1, FUP[1.2] = 2, FUP[−1.2] = −2;
    /// LinuxCNC's FIX/FUP are floor and ceiling.
    #[test]
    fn rounding_functions_follow_each_controller() {
        assert_eq!(f("FIX[#1]"), Ok(1.0));
        assert_eq!(f("FIX[#2]"), Ok(-1.0));
        assert_eq!(f("FUP[#1]"), Ok(2.0));
        assert_eq!(f("FUP[#2]"), Ok(-2.0));
        assert_eq!(l("FIX[#2]"), Ok(-2.0));
        assert_eq!(l("FUP[#2]"), Ok(-1.0));
        assert_eq!(f("ROUND[2.5]"), Ok(3.0));
    }

    #[test]
    fn precedence_brackets_and_functions() {
        assert_eq!(f("1+2*3"), Ok(7.0));
        assert_eq!(f("[1+2]*3"), Ok(9.0));
        assert!((f("#3*SIN[30]").unwrap() - 1.0).abs() < 1e-12);
        assert_eq!(f("SQRT[#3*8]"), Ok(4.0));
        assert_eq!(f("ATAN[1]/[1]"), Ok(45.0));
        assert_eq!(f("[#3 GT 1]"), Ok(1.0));
        assert_eq!(l("2**3"), Ok(8.0));
        assert_eq!(l("[1 LT 2] AND [3 GT 4]"), Ok(0.0));
        assert_eq!(f("6 AND 3"), Ok(2.0));
        assert_eq!(l("-7 MOD 3"), Ok(2.0));
        assert!(f("#9 + 1").unwrap_err().contains("#9 is read before"));
        assert!(f("ATAN[-1]/[1]").unwrap_err().contains("6004"));
        assert!(f("1/0").is_err());
    }

    #[test]
    fn fanuc_vacant_differs_from_zero_in_eq_and_ne() {
        let env = M(HashMap::new());
        let e = |t: &str| eval(&parse(t, Rules::Fanuc).unwrap(), Rules::Fanuc, &env);
        assert_eq!(e("[#1 EQ #0]"), Ok(Some(1.0)));
        assert_eq!(e("[#1 EQ 0]"), Ok(Some(0.0)));
        assert_eq!(e("[#1 NE 0]"), Ok(Some(1.0)));
    }

    #[test]
    fn deep_nesting_is_refused_not_a_stack_overflow() {
        let deep = format!("{}1{}", "[".repeat(10_000), "]".repeat(10_000));
        assert!(f(&deep).is_err());
        assert!(f(&"-".repeat(10_000)).is_err());
    }
}
