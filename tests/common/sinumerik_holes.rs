//! A reader of the holes a Sinumerik program drills with CYCLE81–89/CYCLE840, direct or under `MCALL`, written for the tests from the 840D sl manuals (nc-gcode-interpreter records cycle calls but drills nothing); it shares no code with errmap.
//!
//! Rules (SINUMERIK 840D sl Fundamentals, "Modal subprogram call": after `MCALL name(…)` the
//! subprogram runs after every block with path motion, until a bare `MCALL`; a direct call runs
//! at the current position. Cycles manual, CYCLE81: RTP, RFP, SDIS, DP, DPR as the first five
//! parameters; DPR, relative to RFP and without sign, gives the depth when it is not 0).
//! Reads plain G90 programs only: X/Y/Z numbers (`X10`, `X=10`), `;` comments, N numbers.
// Each test binary that includes this module uses only part of it.
#![allow(dead_code)]

/// One hole: where, which cycle, and its levels.
#[derive(Debug, Clone, PartialEq)]
pub struct Hole {
    pub x: f64,
    pub y: f64,
    pub cycle: String,
    pub rtp: f64,
    pub rfp: f64,
    pub bottom: f64,
    /// The arguments other than RFP, DP and CYCLE83's FDEP (index 5), as written.
    pub others: Vec<String>,
}

/// What the program does: the tool positions after every motion block (holes not included),
/// and the holes in order.
#[derive(Debug, Default)]
pub struct Read {
    pub positions: Vec<[f64; 3]>,
    pub holes: Vec<Hole>,
}

fn call(text: &str) -> Option<(String, Vec<String>)> {
    let open = text.find('(')?;
    let inner = text[open + 1..].trim_end().strip_suffix(')')?;
    Some((
        text[..open].trim().to_uppercase(),
        inner.split(',').map(|a| a.trim().to_string()).collect(),
    ))
}

fn num(args: &[String], i: usize) -> Result<Option<f64>, String> {
    match args.get(i).map(String::as_str) {
        None | Some("") => Ok(None),
        Some(a) => a
            .parse::<f64>()
            .map(Some)
            .map_err(|_| format!("argument {} `{a}` is no number", i + 1)),
    }
}

fn hole(pos: [f64; 3], name: &str, args: &[String]) -> Result<Hole, String> {
    let rtp = num(args, 0)?.ok_or("no RTP")?;
    let rfp = num(args, 1)?.ok_or("no RFP")?;
    let dp = num(args, 3)?;
    let dpr = num(args, 4)?.unwrap_or(0.0);
    let bottom = if dpr != 0.0 {
        rfp - dpr
    } else {
        dp.ok_or("no depth")?
    };
    let others = args
        .iter()
        .enumerate()
        .filter(|(i, _)| !([1, 3].contains(i) || (name == "CYCLE83" && *i == 5)))
        .map(|(_, a)| a.clone())
        .collect();
    Ok(Hole {
        x: pos[0],
        y: pos[1],
        cycle: name.to_string(),
        rtp,
        rfp,
        bottom,
        others,
    })
}

/// Read a program. `Err` for what this reader does not read.
pub fn read(text: &str) -> Result<Read, String> {
    let mut r = Read::default();
    let mut pos = [f64::NAN; 3];
    let mut modal: Option<(String, Vec<String>)> = None;
    for (n, raw) in text.lines().enumerate() {
        let at = |e: String| format!("line {}: {e}", n + 1);
        let code = raw.split(';').next().unwrap_or("").trim();
        let mut code = code.to_string();
        if code.starts_with(['N', 'n']) {
            let rest = code[1..].trim_start_matches(|c: char| c.is_ascii_digit());
            code = rest.trim().to_string();
        }
        let upper = code.to_uppercase();
        if upper == "MCALL" {
            modal = None;
            continue;
        }
        if let Some(rest) = upper.strip_prefix("MCALL ") {
            modal = Some(call(rest).ok_or_else(|| at("bad MCALL".into()))?);
            continue;
        }
        if upper.starts_with("CYCLE") {
            let (name, args) = call(&upper).ok_or_else(|| at("bad call".into()))?;
            if name != "CYCLE832" {
                r.holes.push(hole(pos, &name, &args).map_err(at)?);
                pos[2] = num(&args, 0).map_err(at)?.unwrap_or(f64::NAN);
            }
            continue;
        }
        let mut moved = false;
        for w in upper.split_whitespace() {
            let (l, v) = w.split_at(1);
            let v = v.trim_start_matches('=');
            match l {
                "X" | "Y" | "Z" => {
                    let i = (l.as_bytes()[0] - b'X') as usize;
                    pos[i] = v.parse().map_err(|_| at(format!("`{w}`")))?;
                    moved = true;
                }
                "G" if v == "91" => return Err(at("G91".into())),
                _ => {}
            }
        }
        if moved {
            r.positions.push(pos);
            if let Some((name, args)) = &modal {
                r.holes.push(hole(pos, name, args).map_err(at)?);
                pos[2] = num(args, 0).map_err(at)?.unwrap_or(f64::NAN);
            }
        }
    }
    Ok(r)
}
