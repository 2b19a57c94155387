//! LinuxCNC O-word control flow run into plain blocks: `sub`/`endsub`/`call`/`return`, `if`/`elseif`/`else`/`endif`, `while`/`endwhile`, `do`/`while`, `repeat`/`endrepeat`, `break`/`continue`, numbered and named parameters.

use super::eval::{self, Env, Rules, Var};
use super::{format_value, Flat, MAX_CALL_DEPTH, MAX_ITERATIONS};
use crate::dialect::Dialect;
use crate::lexer::{self, Line, TokenKind, WordValue};
use errmap_core::error::{Error, Location, Result};
use std::collections::HashMap;
use std::path::Path;

/// The parameters a subroutine call passes and keeps local (#1–#30).
const ARGS: usize = 30;

/// An O-word line: its label (`100`, `<name>`), keyword and the text after the keyword.
struct OLine {
    name: String,
    keyword: String,
    rest: String,
}

struct Frame {
    return_pc: usize,
    caller_chain: u32,
    /// The caller's #1–#30 and named locals, restored at the return.
    saved_args: Vec<Option<f64>>,
    saved_locals: HashMap<String, f64>,
    /// The sub's own label, for `return`.
    name: String,
}

struct Params<'a> {
    global: &'a HashMap<String, f64>,
    local: &'a HashMap<String, f64>,
    args: &'a [Option<f64>],
}

/// Whether a parameter is only known on the machine.
fn runtime(name: &str) -> Option<String> {
    if let Ok(n) = name.parse::<u32>() {
        if n >= 5000 {
            return Some(format!("#{n} is a system parameter (positions, offsets, probe results, tool data) whose value only the machine knows"));
        }
        return None;
    }
    None
}

impl Env for Params<'_> {
    fn get(&self, var: &Var, n: Option<u32>) -> std::result::Result<Option<f64>, String> {
        match (var, n) {
            // A name without `_` belongs to the scope it is set in.
            (Var::Named(name), _) if !name.starts_with("<_") => Ok(self.local.get(name).copied()),
            (Var::Named(name), _) => Ok(self.global.get(name).copied()),
            (_, Some(n)) if n >= 5000 => Err(runtime(&n.to_string()).unwrap_or_default()),
            (_, Some(n)) if (1..=ARGS as u32).contains(&n) => {
                Ok(self.args.get(n as usize - 1).copied().flatten())
            }
            (_, Some(n)) => Ok(self.global.get(&n.to_string()).copied()),
            _ => Err("an indirect parameter errmap cannot read".into()),
        }
    }
}

fn oline(text: &str, line: &Line) -> Option<OLine> {
    line.tokens.iter().find_map(|t| match &t.kind {
        TokenKind::OWord { name, keyword } => {
            let body = text.get(t.span.clone()).unwrap_or("");
            // After `o`, the label (`<name>` or digits), spaces and the keyword.
            let b = body.as_bytes();
            let mut at = 1;
            if b.get(at) == Some(&b'<') {
                at = body.find('>').map_or(body.len(), |e| e + 1);
            } else {
                while at < b.len() && (b[at].is_ascii_digit() || b[at] == b' ') {
                    at += 1;
                }
            }
            while at < b.len() && b[at].is_ascii_whitespace() {
                at += 1;
            }
            let at = (at + keyword.len()).min(body.len());
            Some(OLine {
                name: name.clone(),
                keyword: keyword.clone(),
                rest: body.get(at..).unwrap_or("").trim().to_string(),
            })
        }
        _ => None,
    })
}

/// The `[…]` groups of an O-word's rest, in order.
fn groups(rest: &str) -> std::result::Result<Vec<&str>, String> {
    let mut out = Vec::new();
    let (mut depth, mut start) = (0i32, None);
    for (i, c) in rest.char_indices() {
        match c {
            '[' => {
                if depth == 0 {
                    start = Some(i);
                }
                depth += 1;
            }
            ']' => {
                depth -= 1;
                if depth == 0 {
                    if let Some(s) = start.take() {
                        out.push(&rest[s..=i]);
                    }
                }
            }
            c if depth == 0 && !c.is_whitespace() => {
                return Err(format!(
                    "`{rest}`: values after an O-word are written in [ ]"
                ))
            }
            _ => {}
        }
    }
    if depth != 0 {
        return Err(format!("`{rest}`: a `[` without its `]`"));
    }
    Ok(out)
}

struct Run<'a> {
    text: &'a str,
    source: &'a Path,
    lines: std::rc::Rc<Vec<Line>>,
    owords: std::rc::Rc<Vec<Option<OLine>>>,
    /// Block partners found so far (`find`, `loop_head`), so a loop turn does not rescan.
    partners: std::cell::RefCell<HashMap<(usize, &'static str), usize>>,
    subs: HashMap<String, (usize, usize)>,
    global: HashMap<String, f64>,
    local: HashMap<String, f64>,
    args: Vec<Option<f64>>,
    frames: Vec<Frame>,
    /// Remaining turns of each active `repeat`, by line (and call depth).
    repeats: HashMap<(usize, usize), u64>,
    flat: Flat,
    iterations: u64,
    /// The call chain of the line running.
    chain: u32,
    percents: u32,
    compiled: std::cell::RefCell<HashMap<(usize, usize), eval::Expr>>,
}

pub(super) fn flatten(text: &str, source: &Path, trial: bool) -> Result<Option<Flat>> {
    let lines = lexer::lex_dialect(text, Dialect::Linuxcnc);
    let owords: Vec<Option<OLine>> = lines.iter().map(|l| oline(text, l)).collect();
    let flow = owords.iter().any(Option::is_some)
        || lines.iter().any(|l| {
            l.tokens.iter().any(|t| {
                matches!(
                    t.kind,
                    TokenKind::Assignment { .. }
                        | TokenKind::Word {
                            value: WordValue::Expr(_),
                            ..
                        }
                )
            })
        });
    if !flow {
        return Ok(None);
    }
    let mut run = Run {
        text,
        source,
        lines: std::rc::Rc::new(lines),
        owords: std::rc::Rc::new(owords),
        partners: Default::default(),
        subs: HashMap::new(),
        global: HashMap::new(),
        local: HashMap::new(),
        args: vec![None; ARGS],
        frames: Vec::new(),
        repeats: HashMap::new(),
        flat: Flat::new(text.len() * 2, trial),
        iterations: 0,
        chain: 0,
        percents: 0,
        compiled: Default::default(),
    };
    let owords = std::rc::Rc::clone(&run.owords);
    for (i, o) in owords.iter().enumerate() {
        if let Some(o) = o {
            if o.keyword == "sub" {
                let end = run.find(i, &o.name, &["endsub"])?;
                run.subs.insert(o.name.clone(), (i, end));
            }
        }
    }
    run.run()?;
    Ok(Some(run.flat))
}

impl Run<'_> {
    fn err(&self, pc: usize, word: &str, message: String, hint: &str) -> Error {
        let content = &self.text[self.lines[pc].span.clone()];
        let at = content
            .to_ascii_lowercase()
            .find(&word.to_ascii_lowercase())
            .unwrap_or(0);
        Error::input(
            Location::cell(
                self.source,
                self.lines[pc].number,
                format!("{} ({word})", content[..at].chars().count() + 1),
            ),
            format!("{message}{}", self.flat.calls(self.chain)),
            hint,
        )
    }

    fn label(&self, pc: usize) -> String {
        self.owords[pc]
            .as_ref()
            .map_or("o".into(), |o| format!("o{} {}", o.name, o.keyword))
    }

    /// The next line after `from` with O-word `name` and one of `keywords`, skipping nested
    /// blocks of the same name.
    fn find(&self, from: usize, name: &str, keywords: &[&'static str]) -> Result<usize> {
        let key = (from, keywords.first().copied().unwrap_or(""));
        if let Some(&j) = self.partners.borrow().get(&key) {
            return Ok(j);
        }
        for j in from + 1..self.owords.len() {
            if let Some(o) = &self.owords[j] {
                if o.name == name && keywords.contains(&o.keyword.as_str()) {
                    self.partners.borrow_mut().insert(key, j);
                    return Ok(j);
                }
            }
        }
        Err(self.err(
            from,
            &self.label(from),
            format!(
                "`{}` has no matching `o{name} {}`",
                self.label(from),
                keywords.join("/")
            ),
            "close the block with its O-word",
        ))
    }

    /// The loop a `break`/`continue` at `pc` leaves: a `while` or `do` (LinuxCNC has no break
    /// out of a `repeat`: "no matching while/do label").
    fn break_head(&self, pc: usize, name: &str) -> Result<usize> {
        let head = self.loop_head(pc, name)?;
        match self.owords[head].as_ref().map(|o| o.keyword.as_str()) {
            Some("while" | "do") => Ok(head),
            _ => Err(self.err(
                pc,
                &self.label(pc),
                format!(
                    "`{}`: LinuxCNC breaks out of and continues while and do loops only",
                    self.label(pc)
                ),
                "end the repeat with its count, or write the loop as while",
            )),
        }
    }

    /// The innermost loop (`while`, `do`, `repeat`) named `name` that contains `pc`.
    fn loop_head(&self, pc: usize, name: &str) -> Result<usize> {
        if let Some(&j) = self.partners.borrow().get(&(pc, "head")) {
            return Ok(j);
        }
        for j in (0..pc).rev() {
            if let Some(o) = &self.owords[j] {
                if o.name == name && matches!(o.keyword.as_str(), "while" | "do" | "repeat") {
                    self.partners.borrow_mut().insert((pc, "head"), j);
                    return Ok(j);
                }
            }
        }
        Err(self.err(
            pc,
            &self.label(pc),
            format!("`{}` is not inside a loop o{name}", self.label(pc)),
            "break or continue a loop by its own O-word name",
        ))
    }

    /// Whether the `while` at `pc` closes a `do` of the same name.
    fn closes_do(&self, pc: usize, name: &str) -> bool {
        for j in (0..pc).rev() {
            if let Some(o) = &self.owords[j] {
                if o.name == name && matches!(o.keyword.as_str(), "do" | "while" | "endwhile") {
                    return o.keyword == "do";
                }
            }
        }
        false
    }

    fn params(&self) -> Params<'_> {
        Params {
            global: &self.global,
            local: &self.local,
            args: &self.args,
        }
    }

    fn value(&self, pc: usize, word: &str, text: &str) -> Result<f64> {
        let hint = "set the parameter in the program before this line, or move the zone away from the moves that depend on it";
        // Each expression is compiled once, however often its line runs.
        // (The text lies in the program or an O-word's kept rest, neither changed while running:
        // its address and length name it.)
        let key = (text.as_ptr() as usize, text.len());
        let mut cache = self.compiled.borrow_mut();
        let e = match cache.entry(key) {
            std::collections::hash_map::Entry::Occupied(e) => e.into_mut(),
            std::collections::hash_map::Entry::Vacant(v) => v.insert(
                eval::parse(text, Rules::Linuxcnc)
                    .map_err(|m| self.err(pc, word, format!("`{word}`: {m}"), hint))?,
            ),
        };
        eval::value(e, Rules::Linuxcnc, &self.params())
            .map_err(|m| self.err(pc, word, format!("`{word}`: {m}"), hint))
    }

    fn set(&mut self, name: &str, v: f64) -> std::result::Result<(), String> {
        if let Some(m) = runtime(name) {
            return Err(m);
        }
        if let Ok(n) = name.parse::<usize>() {
            if (1..=ARGS).contains(&n) {
                self.args[n - 1] = Some(v);
                return Ok(());
            }
        }
        // A name without `_` belongs to the scope it is set in (the main program or a call).
        if name.starts_with('<') && !name.starts_with("<_") {
            self.local.insert(name.to_string(), v);
        } else {
            self.global.insert(name.to_string(), v);
        }
        Ok(())
    }

    /// A backward jump to `target`; refused past [`MAX_ITERATIONS`].
    fn turn(&mut self, pc: usize, target: usize) -> Result<()> {
        self.iterations += 1;
        if let Some(stop) = self.flat.over_budget(self.iterations) {
            return Err(stop);
        }
        if self.iterations > MAX_ITERATIONS {
            return Err(self.err(
                target,
                &self.label(target),
                format!(
                    "the loop from line {} back to this line runs more than {MAX_ITERATIONS} times (an endless loop?)",
                    self.lines[pc].number
                ),
                "check the loop's condition and counter",
            ));
        }
        Ok(())
    }

    fn cond(&self, pc: usize, rest: &str) -> Result<bool> {
        let g = groups(rest)
            .map_err(|m| self.err(pc, &self.label(pc), m, "write the condition in [ ]"))?;
        match g.as_slice() {
            [c] => Ok(self.value(pc, c, c)? != 0.0),
            _ => Err(self.err(
                pc,
                &self.label(pc),
                format!("`{}` takes one condition in [ ]", self.label(pc)),
                "write the condition in [ ]",
            )),
        }
    }

    fn run(&mut self) -> Result<()> {
        let mut pc = 0;
        let owords = std::rc::Rc::clone(&self.owords);
        while pc < self.lines.len() {
            let Some(o) = owords[pc].as_ref() else {
                if self.block(pc)? {
                    return Ok(());
                }
                pc += 1;
                continue;
            };
            let (name, keyword, rest) = (o.name.as_str(), o.keyword.as_str(), o.rest.as_str());
            pc = match keyword {
                "sub" => self.subs.get(name).map_or(pc + 1, |&(_, end)| end + 1),
                "endsub" | "return" => {
                    let Some(f) = self.frames.pop() else {
                        return Err(self.err(
                            pc,
                            &self.label(pc),
                            format!("`{}` outside a called subroutine", self.label(pc)),
                            "call the subroutine with o<name> call",
                        ));
                    };
                    if keyword == "return" && f.name != name {
                        return Err(self.err(
                            pc,
                            &self.label(pc),
                            format!("`{}` inside subroutine o{}", self.label(pc), f.name),
                            "return with the subroutine's own O-word name",
                        ));
                    }
                    let g = groups(rest)
                        .map_err(|m| self.err(pc, &self.label(pc), m, "write the value in [ ]"))?;
                    // `#<_value>`: the returned value, 0 when none (`#<_value_returned>` says which).
                    let returned = match g.first() {
                        Some(v) => Some(self.value(pc, v, v)?),
                        None => None,
                    };
                    self.global
                        .insert("<_value>".into(), returned.unwrap_or(0.0));
                    self.global.insert(
                        "<_value_returned>".into(),
                        f64::from(u8::from(returned.is_some())),
                    );
                    self.args = f.saved_args;
                    self.local = f.saved_locals;
                    self.chain = f.caller_chain;
                    f.return_pc
                }
                "call" => {
                    let Some(&(start, _)) = self.subs.get(name) else {
                        return Err(self.err(pc, &self.label(pc), format!("`o{name} call`: subroutine o{name} is not in this file (LinuxCNC would search its subroutine path): errmap runs subroutines of the same file only"), "copy the subroutine into this file before the call, or move the zone away"));
                    };
                    if self.frames.len() >= MAX_CALL_DEPTH {
                        return Err(self.err(
                            pc,
                            &self.label(pc),
                            format!("calls nested deeper than {MAX_CALL_DEPTH} levels"),
                            "check the calls",
                        ));
                    }
                    let g = groups(rest).map_err(|m| {
                        self.err(pc, &self.label(pc), m, "write each argument in [ ]")
                    })?;
                    if g.len() > ARGS {
                        return Err(self.err(
                            pc,
                            &self.label(pc),
                            format!("more than {ARGS} arguments"),
                            "pass at most 30 arguments",
                        ));
                    }
                    // #N+1 to #30 keep the caller's values ("O Codes": call).
                    let mut args = self.args.clone();
                    for (k, a) in g.iter().enumerate() {
                        args[k] = Some(self.value(pc, a, a)?);
                    }
                    self.iterations += 1;
                    let inner =
                        self.flat
                            .chain(self.chain, self.lines[pc].number, format!("o{name}"));
                    self.frames.push(Frame {
                        return_pc: pc + 1,
                        caller_chain: self.chain,
                        saved_args: std::mem::replace(&mut self.args, args),
                        saved_locals: std::mem::take(&mut self.local),
                        name: name.to_string(),
                    });
                    self.chain = inner;
                    start + 1
                }
                "if" => {
                    if self.cond(pc, rest)? {
                        pc + 1
                    } else {
                        self.next_branch(pc, name)?
                    }
                }
                "elseif" | "else" => self.find(pc, name, &["endif"])? + 1,
                "endif" => pc + 1,
                "while" if self.closes_do(pc, name) => {
                    if self.cond(pc, rest)? {
                        let head = self.loop_head(pc, name)?;
                        self.turn(pc, head)?;
                        head + 1
                    } else {
                        pc + 1
                    }
                }
                "while" => {
                    if self.cond(pc, rest)? {
                        pc + 1
                    } else {
                        self.find(pc, name, &["endwhile"])? + 1
                    }
                }
                "endwhile" => {
                    let head = self.loop_head(pc, name)?;
                    self.turn(pc, head)?;
                    head
                }
                "do" => pc + 1,
                "repeat" => {
                    let g = groups(rest)
                        .map_err(|m| self.err(pc, &self.label(pc), m, "write the count in [ ]"))?;
                    let n = match g.as_slice() {
                        [c] => self.value(pc, c, c)?,
                        _ => {
                            return Err(self.err(
                                pc,
                                &self.label(pc),
                                "repeat takes one count in [ ]".into(),
                                "write the count in [ ]",
                            ))
                        }
                    };
                    let n = n.round().max(0.0) as u64;
                    if n == 0 {
                        self.find(pc, name, &["endrepeat"])? + 1
                    } else {
                        self.repeats.insert((self.frames.len(), pc), n - 1);
                        pc + 1
                    }
                }
                "endrepeat" => {
                    let head = self.loop_head(pc, name)?;
                    let key = (self.frames.len(), head);
                    match self.repeats.get_mut(&key) {
                        Some(left) if *left > 0 => {
                            *left -= 1;
                            self.turn(pc, head)?;
                            head + 1
                        }
                        _ => pc + 1,
                    }
                }
                "break" => {
                    let head = self.break_head(pc, name)?;
                    let kw = self.owords[head]
                        .as_ref()
                        .map_or("", |o| o.keyword.as_str());
                    let end = match kw {
                        "while" => self.find(head, name, &["endwhile"])?,
                        "repeat" => self.find(head, name, &["endrepeat"])?,
                        _ => self.find(head, name, &["while"])?,
                    };
                    self.repeats.remove(&(self.frames.len(), head));
                    end + 1
                }
                "continue" => {
                    let head = self.break_head(pc, name)?;
                    let kw = self.owords[head]
                        .as_ref()
                        .map_or("", |o| o.keyword.as_str());
                    match kw {
                        "while" => {
                            self.turn(pc, head)?;
                            head
                        }
                        "repeat" => self.find(head, name, &["endrepeat"])?,
                        _ => self.find(head, name, &["while"])?,
                    }
                }
                _ => {
                    return Err(self.err(
                        pc,
                        &self.label(pc),
                        format!("`{}`: an O-word errmap does not run", self.label(pc)),
                        "write it as plain G-code, or move the zone away",
                    ))
                }
            };
        }
        Ok(())
    }

    /// After a false `if`/`elseif` at `pc`: the next branch whose condition holds, its `else`,
    /// or the `endif`.
    fn next_branch(&mut self, pc: usize, name: &str) -> Result<usize> {
        let mut at = pc;
        loop {
            let j = self.find(at, name, &["elseif", "else", "endif"])?;
            let o = self.owords[j]
                .as_ref()
                .map(|o| (o.keyword.clone(), o.rest.clone()));
            match o {
                Some((k, rest)) if k == "elseif" => {
                    if self.cond(j, &rest)? {
                        return Ok(j + 1);
                    }
                    at = j;
                }
                _ => return Ok(j + 1),
            }
        }
    }

    /// A block of words: values evaluated, assignments applied after (LinuxCNC reads every
    /// parameter of a line before it sets any), the block written. `true` at M2/M30.
    fn block(&mut self, pc: usize) -> Result<bool> {
        let lines = std::rc::Rc::clone(&self.lines);
        let line = &lines[pc];
        let number = line.number;
        let mut out = String::new();
        let mut assignments: Vec<(String, f64, String)> = Vec::new();
        let mut words = 0;
        let mut end = false;
        for t in &line.tokens {
            let tt = &self.text[t.span.clone()];
            match &t.kind {
                TokenKind::Word { letter, value } => {
                    words += 1;
                    match value {
                        WordValue::Expr(r) => {
                            if *letter == b'G' {
                                return Err(self.err(
                                    pc,
                                    tt,
                                    format!("`{tt}`: a G code given by a parameter"),
                                    "write the G code as a number",
                                ));
                            }
                            let v = self.value(pc, tt, &self.text[r.clone()])?;
                            let v = if b"MSTHDNPLO".contains(letter) {
                                v.round()
                            } else {
                                v
                            };
                            out.push_str(&tt[..1]);
                            out.push_str(&format_value(*letter, v));
                            if *letter == b'M' && (v == 2.0 || v == 30.0) {
                                end = true;
                            }
                        }
                        WordValue::Number(v) => {
                            out.push_str(tt);
                            if *letter == b'M' && (*v == 2.0 || *v == 30.0) {
                                end = true;
                            }
                        }
                        _ => out.push_str(tt),
                    }
                }
                TokenKind::Assignment { target, value_span } => {
                    let v = self.value(pc, tt, &self.text[value_span.clone()])?;
                    assignments.push((target.clone(), v, tt.to_string()));
                }
                _ => out.push_str(tt),
            }
        }
        for (name, v, tt) in assignments {
            self.set(&name, v).map_err(|m| {
                self.err(
                    pc,
                    &tt,
                    format!("`{tt}` sets {m}"),
                    "remove the assignment, or move the zone away",
                )
            })?;
        }
        let written = out.trim_end();
        let comment_only = words == 0;
        if !(comment_only
            && written.trim().is_empty()
            && !self.text[line.span.clone()].trim().is_empty())
        {
            self.flat.push(self.source, number, self.chain, written)?;
        }
        if line.tokens.iter().any(|t| t.kind == TokenKind::Percent) {
            self.percents += 1;
            // The second `%` ends the program: nothing after it runs.
            end |= self.percents == 2;
        }
        Ok(end)
    }
}
