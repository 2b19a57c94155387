//! A reference tracer for Heidenhain conversational (Klartext) programs, written from the TNC user's manual rules and independent of errmap's reader: moves in mm, or the construct it does not follow.
//!
//! Rules followed: a block is its number, a function and words; `;` starts a comment and `*`
//! blocks are comments; `BEGIN PGM … MM|INCH` gives the units. `L` moves straight to X/Y/Z
//! (`IX` … incremental from the last position), at `FMAX` rapid for that block only, else at
//! feed; `CC` sets the circle centre (the last position when it names no axis); `C` arcs about
//! CC to its end, `DR+` counter-clockwise, `DR-` clockwise; `CR` arcs with radius `R` (`R+`
//! up to 180°, `R-` more), `CP` arcs about CC by the polar angle `PA` / `IPA` (more than a turn
//! allowed) with the third axis moving linearly (helix). The working plane is XY (tool axis
//! Z); a `CC` that names Z with X or Y puts the arcs after it in that plane (the TNC's circle
//! plane is the plane of the centre's two axes), with the polar angle measured from the
//! plane's angle reference axis (XY: +X, YZ: +Y, ZX: +Z) and `DR+` turning toward the plane's
//! second axis (counter-clockwise seen from the positive third axis: Z, X, Y);
//! `M91`/`M92` and `M140` (with or without `L`) go to machine positions: the axes they move
//! become unknown; cycle 7 shifts the datum (`7.1 X+a`, `IX` adds); the first preset of cycle
//! 247 is the program's frame (selecting it again is no change; another is not followed); a
//! cycle's parameters continued on lines after `~` belong to its block. A drilling cycle
//! (200–209) called by `M99` on a positioning block or by `CYCL CALL` is read as its envelope
//! along the tool axis: rapid to the set-up clearance above the surface (Q203 + Q200), feed to
//! the depth (Q203 + Q201), rapid to the higher of the two clearances (Q200, Q204) — its pecks,
//! chip breaks and dwells go up and down that line. The old cycle 1 PECKING (`1.1 DIST`
//! set-up clearance, `1.2 DEPTH` hole depth, TNC 426/430 User's Manual "PECKING (Cycle 1)": the
//! tool starts at the set-up clearance above the surface, drills at feed to the bottom and
//! returns to the starting position at rapid) is read as feed from the start to
//! start + sign(DEPTH)·(|DIST| + |DEPTH|), rapid back. `PLANE RESET` and cycle 19 without an angle
//! tilt nothing; an `L` block without a coordinate moves nothing.
//! Control flow and Q parameters (TNC 370 User's Manual ch. 6 "Subprograms and Program Section
//! Repeats", ch. 7 "Q Parameters") are run first, into the blocks in the order the TNC runs them:
//! a label `LBL n` marks a place; `CALL LBL n` runs the blocks after the label up to `LBL 0`
//! and comes back after the call (nesting at most 8 deep); `CALL LBL n REP m` after its label
//! runs the section from the label to the call m more times; `LBL 0` outside a subprogram is
//! passed over; M2, M30 and END PGM end the program. `FN 0`–`FN 8` and `Qn = formula` set Q
//! parameters (+ − * / DIV, LEN = root of the sum of squares, ^, brackets, SIN COS TAN ASIN
//! ACOS ATAN in degrees, SQRT SQ ABS INT); `FN 9`–`12` jump to a label when the operands are
//! equal, unequal, greater, less; `FN 18 SYSREAD` leaves its parameter unknown; `FN 15/16`
//! print. A `Qn` (`X+Q1`, `X-Q1`, `F Q5`) in a block is its value; an unknown or unset one is
//! refused.
//! `RL`/`RR` (tool radius compensation, until `R0`) offset the programmed contour in the
//! working plane: the moves traced are the programmed ones, and [`plane_less_blocks_under_comp`]
//! counts the blocks the TNC must look past while compensation is on. What moves otherwise
//! (cycles other than the drilling ones and their calls, PLANE, APPR/DEP, RND, CT, rotary axes,
//! CALL PGM) is refused: the judge cannot vouch for it.
// Each test binary that includes this module uses only part of it.
#![allow(dead_code)]

use super::path_judge::{sweep, ArcSeg, Seg};
use std::collections::HashMap;

/// The moves of `text`, mm: its control flow run first ([`run_flow`]), then its blocks traced
/// in the order they run.
pub fn trace(text: &str) -> Result<Vec<Seg>, String> {
    let ran = run_flow(text)?;
    trace_lines(&ran)
}

/// The moves of blocks in the order they run, each with its source line, mm.
fn trace_lines(lines: &[(u64, String)]) -> Result<Vec<Seg>, String> {
    let mut pos: [Option<f64>; 3] = [None; 3];
    let mut cc: Option<(f64, f64)> = None;
    // Datum shift of cycle 7, mm: positions are kept from the original datum.
    let mut shift = [0.0f64; 3];
    let mut scale = 1.0;
    let mut out = Vec::new();
    // The plane of the circles: the axes of the last CC (first, second, third).
    let mut plane = (0usize, 1usize, 2usize);
    // A block continued with `~` on the lines after it (the `~` ends the line, after any
    // comment), the cycle whose Q parameters are being read, the preset of cycle 247 and the
    // drilling cycle defined.
    let mut continued = false;
    let mut reading: Option<(u32, HashMap<u32, f64>)> = None;
    let mut preset: Option<f64> = None;
    let mut drill: Option<HashMap<u32, f64>> = None;
    // Cycle 1 PECKING, when it is the cycle defined last: (DIST, DEPTH).
    let mut pecking: Option<(Option<f64>, Option<f64>)> = None;
    for (line, raw) in lines {
        let (line, raw) = (*line, raw.as_str());
        let was_continued = continued;
        continued = raw.trim_end().ends_with('~');
        if was_continued {
            if let Some((_, q)) = reading.as_mut() {
                read_q(raw, q);
            }
            if !continued {
                if let Some((number, q)) = reading.take() {
                    define(line, number, q, &mut preset, &mut drill)?;
                }
            }
            continue;
        }
        let code = raw.split(';').next().unwrap_or("").trim();
        let code = code.trim_start_matches('/').trim_start();
        let code = code.trim_start_matches(|c: char| c.is_ascii_digit()).trim();
        let upper = code.to_ascii_uppercase();
        let mut toks = upper.split_whitespace();
        let Some(head) = toks.next() else { continue };
        let words: Vec<&str> = toks.collect();
        let err = |what: &str| Err(format!("line {line}: {what} is not followed"));
        match head {
            "*" => continue,
            "BEGIN" | "END" => {
                if words.contains(&"INCH") {
                    scale = 25.4;
                }
                continue;
            }
            "BLK" | "TOOL" | "STOP" => {
                if head == "TOOL" && words.first() == Some(&"CALL") {
                    let axis = words.iter().find(|w| ["X", "Y", "Z"].contains(w));
                    if axis.is_some_and(|a| *a != "Z") {
                        return err("a tool axis other than Z");
                    }
                }
                continue;
            }
            "CYCL" => {
                // Tolerance (32) and dwell (9) move nothing; every other cycle may.
                let number = words
                    .get(1)
                    .map_or("", |w| w.split('.').next().unwrap_or(""));
                if words.first() == Some(&"DEF") && (number == "32" || number == "9") {
                    continue;
                }
                // Cycle 19 with no angle (`19.0 WORKING PLANE`, an empty `19.1`) tilts nothing.
                if words.first() == Some(&"DEF") && number == "19" {
                    let tilts = words[2..].iter().any(|w| {
                        w.starts_with(['A', 'B', 'C'])
                            && w[1..].parse::<f64>().is_ok_and(|v| v != 0.0)
                    });
                    if tilts {
                        return err("a tilted working plane (cycle 19)");
                    }
                    continue;
                }
                if words.first() == Some(&"DEF") && number == "1" {
                    drill = None;
                    pecking_def(line, &words, &mut pecking)?;
                    continue;
                }
                // Cycle 247 selects a datum preset; 200–209 define a drilling cycle.
                let read = number
                    .parse::<u32>()
                    .ok()
                    .filter(|c| *c == 247 || (200..=209).contains(c));
                if let (Some(&"DEF"), Some(c)) = (words.first(), read) {
                    if c != 247 {
                        pecking = None;
                    }
                    let mut q = HashMap::new();
                    read_q(code, &mut q);
                    if continued {
                        reading = Some((c, q));
                    } else {
                        define(line, c, q, &mut preset, &mut drill)?;
                    }
                    continue;
                }
                if words.first() == Some(&"CALL") && words.len() == 1 {
                    if let Some(p) = pecking {
                        pecking_hole(line, p, &mut pos, &mut out)?;
                        continue;
                    }
                }
                if words.first() == Some(&"CALL") {
                    let Some(q) = &drill else {
                        return err("a cycle call with no drilling cycle defined");
                    };
                    hole(line, q, &mut pos, &shift, &mut out)?;
                    continue;
                }
                // Cycle 7, datum shift: `7.0` heads it, `7.1 X+a` / `7.2 IY+b` … set the shift
                // (absolute, or added with I); later coordinates are read from the shifted datum.
                if words.first() == Some(&"DEF") && number == "7" {
                    for w in &words[2..] {
                        let (incremental, w) = match w.strip_prefix('I') {
                            Some(rest) => (true, rest),
                            None => (false, *w),
                        };
                        let k = match w.as_bytes().first() {
                            Some(b'X') => 0,
                            Some(b'Y') => 1,
                            Some(b'Z') => 2,
                            _ => continue, // NULLPUNKT / DATUM SHIFT
                        };
                        let v: f64 = w[1..]
                            .parse()
                            .map_err(|_| format!("line {line}: cycle 7 `{w}`"))?;
                        shift[k] = if incremental {
                            shift[k] + v * scale
                        } else {
                            v * scale
                        };
                    }
                    continue;
                }
                return err(&format!("`{code}`"));
            }
            "L" | "CC" | "C" | "CR" | "CP" => {}
            "PLANE" if words.first() == Some(&"RESET") => continue,
            // `M140 MB MAX` alone: the tool axis retracts to a machine position.
            "M140" => {
                pos[2] = None;
                continue;
            }
            // A block of M functions alone (`M30`, `M5 M9`): no move unless it goes to a machine
            // position or calls a cycle.
            m if m.starts_with('M')
                && upper.split_whitespace().all(|w| {
                    w.starts_with('M')
                        && w[1..]
                            .parse::<u32>()
                            .is_ok_and(|n| !matches!(n, 89 | 91 | 92 | 99 | 140))
                }) =>
            {
                continue
            }
            _ => return err(&format!("`{code}`")),
        }
        // Words of a path block.
        let mut abs: [Option<f64>; 3] = [None; 3];
        let mut inc: [Option<f64>; 3] = [None; 3];
        let (mut rapid, mut cw, mut ccw) = (false, false, false);
        let (mut r, mut pa, mut ipa) = (None, None, None);
        let mut machine = false;
        let mut call = false;
        for w in &words {
            let num = |s: &str| s.parse::<f64>().ok();
            let axis = |c: char| (c as u8 - b'X') as usize;
            match *w {
                "FMAX" | "F" | "MAX" => rapid |= *w != "F",
                "R0" | "AUTO" | "MB" => {}
                // Tool radius compensation offsets the programmed contour, which is what the
                // judge compares (see `plane_less_blocks_under_comp` for what the TNC needs).
                "RL" | "RR" => {}
                "R+" | "R-" => return err(&format!("`{w}`")),
                "DR+" => ccw = true,
                "DR-" => cw = true,
                _ => {
                    let (letter, rest) = w.split_at(1);
                    match letter {
                        "X" | "Y" | "Z" => {
                            abs[axis(letter.chars().next().unwrap())] =
                                Some(num(rest).ok_or(format!("line {line}: `{w}`"))? * scale)
                        }
                        "I" if rest.starts_with("PA") => ipa = num(&rest[2..]),
                        "I" if ["X", "Y", "Z"].iter().any(|a| rest.starts_with(a)) => {
                            let (a, v) = rest.split_at(1);
                            inc[axis(a.chars().next().unwrap())] =
                                Some(num(v).ok_or(format!("line {line}: `{w}`"))? * scale)
                        }
                        "P" if rest.starts_with('A') => pa = num(&rest[1..]),
                        // A rotary axis to 0 (`L B0.0 C0.0 FMAX`): the untilted table, the
                        // orientation a 3-axis map is measured in; any other angle tilts.
                        "A" | "B" | "C" if num(rest) == Some(0.0) && words.contains(&"FMAX") => {}
                        "R" => r = Some(num(rest).ok_or(format!("line {line}: `{w}`"))? * scale),
                        "F" if num(rest).is_some() => {}
                        "M" => match num(rest) {
                            Some(m) if m == 91.0 || m == 92.0 || m == 140.0 => machine = true,
                            Some(99.0) => call = true,
                            Some(89.0) => return err("a modal cycle call M89"),
                            Some(_) => {}
                            None => return err(&format!("`{w}`")),
                        },
                        _ => return err(&format!("`{w}`")),
                    }
                }
            }
        }
        if words.iter().any(|w| w.contains('Q')) {
            return err("a Q parameter");
        }
        // An L block without a coordinate (`L M30`, `L R0 F AUTO`) moves nothing.
        if head == "L" && abs.iter().chain(&inc).all(|v| v.is_none()) && !machine {
            // `L FMAX M99`: the cycle runs where the tool stands.
            if let (true, Some(p)) = (call, pecking) {
                pecking_hole(line, p, &mut pos, &mut out)?;
            } else if call {
                let Some(q) = &drill else {
                    return err("M99 with no drilling cycle defined");
                };
                hole(line, q, &mut pos, &shift, &mut out)?;
            }
            continue;
        }
        if machine {
            // Machine positions: the axes named (or the tool axis for M140) become unknown.
            for k in 0..3 {
                if abs[k].is_some()
                    || inc[k].is_some()
                    || (head == "L" && k == 2 && words.contains(&"M140"))
                {
                    pos[k] = None;
                }
            }
            continue;
        }
        let target = |pos: &[Option<f64>; 3]| -> [f64; 3] {
            let mut e = [f64::NAN; 3];
            for k in 0..3 {
                e[k] = match (abs[k], inc[k], pos[k]) {
                    (Some(v), _, _) => v + shift[k],
                    (None, Some(d), Some(p)) => p + d,
                    (None, None, Some(p)) => p,
                    _ => f64::NAN,
                };
            }
            e
        };
        if head == "CC" {
            let e = target(&pos);
            let named = |k: usize| abs[k].is_some() || inc[k].is_some();
            plane = match (named(0), named(1), named(2)) {
                (true, false, true) => (2, 0, 1),
                (false, true, true) => (1, 2, 0),
                (_, _, false) => (0, 1, 2),
                _ => return err("a CC naming three axes"),
            };
            cc = Some((e[plane.0], e[plane.1]));
            if cc.is_some_and(|c| c.0.is_nan() || c.1.is_nan()) {
                return err("a circle centre from an unknown position");
            }
            continue;
        }
        let start = pos.map(|p| p.unwrap_or(f64::NAN));
        let mut end = target(&pos);
        let arc = match head {
            "L" => None,
            "C" | "CR" | "CP" => {
                if !(cw || ccw) && head != "CP" {
                    return err("an arc without DR");
                }
                let centre = match head {
                    "CR" => {
                        let rv = r.ok_or(format!("line {line}: CR without R"))?;
                        let (i, j) = (plane.0, plane.1);
                        let (du, dv) = (end[i] - start[i], end[j] - start[j]);
                        let d = du.hypot(dv);
                        if !(d > 0.0 && d <= 2.0 * rv.abs() + 1e-6) {
                            return err("a CR arc with no centre");
                        }
                        let h = (rv * rv - d * d / 4.0).max(0.0).sqrt();
                        let left = ccw == (rv > 0.0);
                        let s = if left { 1.0 } else { -1.0 };
                        (
                            start[i] + du / 2.0 - s * h * dv / d,
                            start[j] + dv / 2.0 + s * h * du / d,
                        )
                    }
                    _ => cc.ok_or(format!("line {line}: an arc before any CC"))?,
                };
                if head == "CP" {
                    if !(cw || ccw) {
                        return err("CP without DR");
                    }
                    let (i, j) = (plane.0, plane.1);
                    let radius = (start[i] - centre.0).hypot(start[j] - centre.1);
                    let th0 = (start[j] - centre.1).atan2(start[i] - centre.0);
                    let sweep_deg = match (ipa, pa) {
                        (Some(i), _) => i,
                        (None, Some(a)) => {
                            // Absolute polar angle: the turn in the DR direction.
                            let d = a - th0.to_degrees();
                            if ccw {
                                d.rem_euclid(360.0)
                            } else {
                                -(-d).rem_euclid(360.0)
                            }
                        }
                        _ => return err("CP without PA/IPA"),
                    };
                    let th1 = th0 + sweep_deg.to_radians();
                    end[i] = centre.0 + radius * th1.cos();
                    end[j] = centre.1 + radius * th1.sin();
                    if (sweep_deg > 0.0) != ccw {
                        return err("CP whose IPA sign differs from DR");
                    }
                    Some(ArcSeg {
                        axes: plane,
                        centre,
                        sweep_rad: sweep_deg.to_radians(),
                    })
                } else {
                    Some(ArcSeg {
                        axes: plane,
                        centre,
                        sweep_rad: sweep(plane, centre, &start, &end, cw, 0),
                    })
                }
            }
            _ => unreachable!(),
        };
        let cut = !rapid;
        if cut && start.iter().chain(&end).any(|v| v.is_nan()) {
            return err("a cut from or to an unknown position");
        }
        out.push(Seg {
            cut,
            line,
            start,
            end,
            arc,
        });
        pos = end.map(|v| (!v.is_nan()).then_some(v));
        if let (true, Some(p)) = (call, pecking) {
            pecking_hole(line, p, &mut pos, &mut out)?;
        } else if call {
            let Some(q) = &drill else {
                return err("M99 with no drilling cycle defined");
            };
            hole(line, q, &mut pos, &shift, &mut out)?;
        }
    }
    Ok(out)
}

/// The `Qn=value` parameters of a cycle block's line (text before its comment); `MAX`,
/// `AUTO` and other words are not numbers and are left out.
fn read_q(raw: &str, q: &mut HashMap<u32, f64>) {
    let code = raw.split(';').next().unwrap_or("");
    for w in code.split_whitespace() {
        let Some(rest) = w.strip_prefix('Q') else {
            continue;
        };
        let Some((n, v)) = rest.split_once('=') else {
            continue;
        };
        if let (Ok(n), Ok(v)) = (n.parse::<u32>(), v.trim_end_matches('~').parse::<f64>()) {
            q.insert(n, v);
        }
    }
}

/// A cycle definition read whole: cycle 247's preset (the first is the program's frame), or a
/// drilling cycle's parameters.
fn define(
    line: u64,
    number: u32,
    q: HashMap<u32, f64>,
    preset: &mut Option<f64>,
    drill: &mut Option<HashMap<u32, f64>>,
) -> Result<(), String> {
    if number == 247 {
        let p = q.get(&339).copied();
        match (*preset, p) {
            (_, None) => {
                return Err(format!(
                    "line {line}: cycle 247 without Q339 is not followed"
                ))
            }
            (None, Some(p)) => *preset = Some(p),
            (Some(a), Some(b)) if a == b => {}
            _ => {
                return Err(format!(
                    "line {line}: a second datum preset (cycle 247) is not followed"
                ))
            }
        }
        return Ok(());
    }
    for k in [200, 201, 203] {
        if !q.contains_key(&k) {
            return Err(format!(
                "line {line}: drilling cycle {number} without Q{k} is not followed"
            ));
        }
    }
    *drill = Some(q);
    Ok(())
}

/// A drilling cycle's hole at the current position, as its envelope along Z.
fn hole(
    line: u64,
    q: &HashMap<u32, f64>,
    pos: &mut [Option<f64>; 3],
    shift: &[f64; 3],
    out: &mut Vec<Seg>,
) -> Result<(), String> {
    let (Some(x), Some(y)) = (pos[0], pos[1]) else {
        return Err(format!(
            "line {line}: a hole at an unknown position is not followed"
        ));
    };
    let surface = q[&203] + shift[2];
    let clearance = surface + q[&200];
    let bottom = surface + q[&201];
    let top = surface + q[&200].max(q.get(&204).copied().unwrap_or(0.0));
    // From a tool-axis position the program never gave, the cycle's first move (at FMAX to the
    // set-up clearance, from wherever the tool is) is judged from the clearance on.
    let mut from = [x, y, pos[2].unwrap_or(clearance)];
    for (cut, level) in [(false, clearance), (true, bottom), (false, top)] {
        let to = [x, y, level];
        out.push(Seg {
            cut,
            line,
            start: from,
            end: to,
            arc: None,
        });
        from = to;
    }
    pos[2] = Some(top);
    Ok(())
}

/// A block's code: the text after the block skip `/` and the block number, before the comment,
/// upper case.
fn code_of(raw: &str) -> String {
    let code = raw.split(';').next().unwrap_or("").trim();
    let code = code.trim_start_matches('/').trim_start();
    let code = code
        .trim_start_matches(|c: char| c.is_ascii_digit())
        .trim_start();
    code.trim_start_matches('/').trim().to_ascii_uppercase()
}

/// `LBL 1`, `LBL1`, `LBL 01` → `1`; `LBL "A"` → `"A"`.
fn label_of(rest: &str) -> String {
    let t = rest.trim();
    if t.starts_with('"') {
        return t
            .split('"')
            .nth(1)
            .map(|n| format!("\"{n}\""))
            .unwrap_or_default();
    }
    let t = t.split_whitespace().next().unwrap_or("");
    t.parse::<u64>()
        .map(|n| n.to_string())
        .unwrap_or_else(|_| t.to_string())
}

/// The program's control flow run: each block that moves or defines something (not labels,
/// calls, jumps or Q arithmetic), with its source line, in the order the TNC runs it; Q
/// parameters in its words replaced by their values.
pub fn run_flow(text: &str) -> Result<Vec<(u64, String)>, String> {
    let raw: Vec<&str> = text.lines().collect();
    // Blocks: a line ending in `~` goes on on the next.
    let mut blocks: Vec<(usize, usize)> = Vec::new();
    let mut i = 0;
    while i < raw.len() {
        let mut j = i;
        while raw[j].trim_end().ends_with('~') && j + 1 < raw.len() {
            j += 1;
        }
        blocks.push((i, j));
        i = j + 1;
    }
    let mut labels: HashMap<String, usize> = HashMap::new();
    for (k, &(f, _)) in blocks.iter().enumerate() {
        if let Some(rest) = code_of(raw[f]).strip_prefix("LBL") {
            labels.entry(label_of(rest)).or_insert(k);
        }
    }
    let find = |name: &str, line: usize| {
        labels
            .get(name)
            .copied()
            .ok_or(format!("line {}: no label {name}", line + 1))
    };
    // Q parameters: a value, or None when only the machine knows it (FN 18).
    let mut q: HashMap<String, Option<f64>> = HashMap::new();
    let mut returns: Vec<usize> = Vec::new();
    let mut repeats: HashMap<(usize, usize), u64> = HashMap::new();
    let mut out = Vec::new();
    let mut k = 0;
    let mut steps = 0u64;
    while k < blocks.len() {
        steps += 1;
        if steps > 3_000_000 {
            return Err("more than 3 000 000 blocks run: an endless loop?".into());
        }
        let (f, l) = blocks[k];
        let code = code_of(raw[f]);
        if let Some(rest) = code.strip_prefix("LBL") {
            // LBL 0 ends a subprogram; elsewhere a label is passed over.
            if label_of(rest) == "0" {
                if let Some(back) = returns.pop() {
                    repeats.retain(|(depth, _), _| *depth <= returns.len());
                    k = back;
                    continue;
                }
            }
            k += 1;
            continue;
        }
        if let Some(rest) = code.strip_prefix("CALL LBL") {
            let name = label_of(rest);
            let target = find(&name, f)?;
            let rep = rest.split("REP").nth(1).map(|r| {
                r.trim()
                    .chars()
                    .take_while(char::is_ascii_digit)
                    .collect::<String>()
                    .parse::<u64>()
                    .unwrap_or(0)
            });
            match rep {
                Some(m) => {
                    if target > k {
                        return Err(format!("line {}: REP with the label after the call", f + 1));
                    }
                    let left = repeats.entry((returns.len(), k)).or_insert(m);
                    if *left > 0 {
                        *left -= 1;
                        k = target + 1;
                    } else {
                        repeats.remove(&(returns.len(), k));
                        k += 1;
                    }
                }
                None => {
                    returns.push(k + 1);
                    if returns.len() > 8 {
                        return Err(format!("line {}: subprograms nested deeper than 8", f + 1));
                    }
                    k = target + 1;
                }
            }
            continue;
        }
        if let Some(rest) = code.strip_prefix("FN") {
            let rest = rest.trim_start();
            let number: String = rest.chars().take_while(char::is_ascii_digit).collect();
            let body = rest[number.len()..]
                .trim_start()
                .trim_start_matches(':')
                .trim();
            match number.parse::<u32>().unwrap_or(99) {
                0..=8 => {
                    let (target, formula) = body
                        .split_once('=')
                        .ok_or(format!("line {}: FN without =", f + 1))?;
                    let v =
                        formula_value(formula, &q).map_err(|e| format!("line {}: {e}", f + 1))?;
                    q.insert(target.trim().to_string(), v);
                }
                n @ 9..=12 => {
                    let cond = body
                        .strip_prefix("IF")
                        .ok_or(format!("line {}: FN {n}", f + 1))?;
                    let (cond, goto) = cond
                        .split_once("GOTO")
                        .ok_or(format!("line {}: FN {n} without GOTO", f + 1))?;
                    let op = ["EQU", "NE", "GT", "LT"][(n - 9) as usize];
                    let (a, b) = cond
                        .split_once(&format!(" {op} "))
                        .ok_or(format!("line {}: FN {n} without {op}", f + 1))?;
                    let a = formula_value(a, &q).map_err(|e| format!("line {}: {e}", f + 1))?;
                    let b = formula_value(b, &q).map_err(|e| format!("line {}: {e}", f + 1))?;
                    let (Some(a), Some(b)) = (a, b) else {
                        return Err(format!(
                            "line {}: a jump on a value read from the machine",
                            f + 1
                        ));
                    };
                    let jump = match n {
                        9 => a == b,
                        10 => a != b,
                        11 => a > b,
                        _ => a < b,
                    };
                    if jump {
                        let name = label_of(goto.trim().trim_start_matches("LBL"));
                        k = find(&name, f)? + 1;
                        continue;
                    }
                }
                15 | 16 => {}
                18 => {
                    let target = body
                        .split_whitespace()
                        .find(|w| w.starts_with('Q'))
                        .ok_or(format!("line {}: FN 18 without Q", f + 1))?;
                    q.insert(target.to_string(), None);
                }
                _ => return Err(format!("line {}: `FN {number}` is not followed", f + 1)),
            }
            k += 1;
            continue;
        }
        if code.starts_with('Q') {
            if let Some((target, formula)) = code.split_once('=') {
                let v = formula_value(formula, &q).map_err(|e| format!("line {}: {e}", f + 1))?;
                q.insert(target.trim().to_string(), v);
                k += 1;
                continue;
            }
        }
        if code.starts_with("END") {
            out.push(((f + 1) as u64, raw[f].to_string()));
            break;
        }
        let mut ends = false;
        for (n, line) in raw.iter().enumerate().take(l + 1).skip(f) {
            let mut text = code_of(line);
            if n == f {
                ends = text
                    .split_whitespace()
                    .any(|w| matches!(w, "M2" | "M02" | "M30"));
            } else {
                // A continuation line keeps all its text (`Q200=+2`).
                text = line
                    .split(';')
                    .next()
                    .unwrap_or("")
                    .trim()
                    .to_ascii_uppercase();
            }
            let mut with_values =
                values_in(&text, &q).map_err(|e| format!("line {}: {e}", n + 1))?;
            if line.trim_end().ends_with('~') && !with_values.ends_with('~') {
                with_values.push_str(" ~");
            }
            out.push(((n + 1) as u64, with_values));
        }
        if ends {
            break;
        }
        k += 1;
    }
    Ok(out)
}

/// A block's words with each `Qn` (`X+Q1`, `IY-Q2`, `F Q5`, `FQ5`) replaced by its value; a
/// cycle parameter's own name (`Q200=`) is kept.
fn values_in(code: &str, q: &HashMap<String, Option<f64>>) -> Result<String, String> {
    let mut words: Vec<String> = Vec::new();
    let mut feed_next = false;
    for w in code.split_whitespace() {
        if w == "F" {
            feed_next = true;
            words.push(w.to_string());
            continue;
        }
        let at = w.find('Q');
        let replaced = match at {
            Some(a)
                if !w.contains('=')
                    && w[a + 1..].chars().all(|c| c.is_ascii_digit())
                    && a + 1 < w.len() =>
            {
                let name = &w[a..];
                let v = q
                    .get(name)
                    .copied()
                    .ok_or(format!("{name} is read before it is set"))?
                    .ok_or(format!("{name} is read from the machine"))?;
                let head = &w[..a];
                let (letters, sign) = match head.strip_suffix('-') {
                    Some(l) => (l, -1.0),
                    None => (head.strip_suffix('+').unwrap_or(head), 1.0),
                };
                if feed_next && letters.is_empty() {
                    words.pop();
                    format!("F{v}")
                } else if letters == "F" {
                    format!("F{v}")
                } else {
                    let v = sign * v;
                    format!("{letters}{}{}", if v < 0.0 { "-" } else { "+" }, v.abs())
                }
            }
            _ => w.to_string(),
        };
        feed_next = false;
        words.push(replaced);
    }
    Ok(words.join(" "))
}

/// The value of a TNC formula; `None` when it reads a value only the machine knows.
fn formula_value(text: &str, q: &HashMap<String, Option<f64>>) -> Result<Option<f64>, String> {
    // Tokens: numbers, names (Q parameters, functions, DIV/LEN), operators.
    let mut toks: Vec<String> = Vec::new();
    let chars: Vec<char> = text.chars().collect();
    let mut i = 0;
    while i < chars.len() {
        let c = chars[i];
        if c.is_whitespace() {
            i += 1;
        } else if c.is_ascii_alphanumeric() || c == '.' {
            let start = i;
            // A name runs on into its digits (`Q12`); a number into its decimals.
            while i < chars.len() && (chars[i].is_ascii_alphanumeric() || chars[i] == '.') {
                i += 1;
            }
            toks.push(chars[start..i].iter().collect());
        } else {
            toks.push(c.to_string());
            i += 1;
        }
    }
    let mut at = 0;
    let v = sum(&toks, &mut at, q)?;
    if at != toks.len() {
        return Err(format!("`{text}`: `{}` not read", toks[at..].join(" ")));
    }
    Ok(v)
}

type Num = Result<Option<f64>, String>;

fn sum(t: &[String], at: &mut usize, q: &HashMap<String, Option<f64>>) -> Num {
    let mut v = product(t, at, q)?;
    while let Some(op) = t.get(*at).filter(|o| *o == "+" || *o == "-").cloned() {
        *at += 1;
        let r = product(t, at, q)?;
        v = v.zip(r).map(|(a, b)| if op == "+" { a + b } else { a - b });
    }
    Ok(v)
}

fn product(t: &[String], at: &mut usize, q: &HashMap<String, Option<f64>>) -> Num {
    let mut v = factor(t, at, q)?;
    while let Some(op) = t
        .get(*at)
        .filter(|o| matches!(o.as_str(), "*" | "/" | "DIV" | "LEN"))
        .cloned()
    {
        *at += 1;
        let r = factor(t, at, q)?;
        if (op == "/" || op == "DIV") && r == Some(0.0) {
            return Err("division by zero".into());
        }
        v = v.zip(r).map(|(a, b)| match op.as_str() {
            "*" => a * b,
            "LEN" => (a * a + b * b).sqrt(),
            _ => a / b,
        });
    }
    Ok(v)
}

fn factor(t: &[String], at: &mut usize, q: &HashMap<String, Option<f64>>) -> Num {
    let base = signed_value(t, at, q)?;
    if t.get(*at).is_some_and(|o| o == "^") {
        *at += 1;
        let e = factor(t, at, q)?;
        return Ok(base.zip(e).map(|(a, b)| a.powf(b)));
    }
    Ok(base)
}

fn signed_value(t: &[String], at: &mut usize, q: &HashMap<String, Option<f64>>) -> Num {
    let tok = t.get(*at).cloned().ok_or("a formula ends early")?;
    *at += 1;
    match tok.as_str() {
        "+" => signed_value(t, at, q),
        "-" => Ok(signed_value(t, at, q)?.map(|v| -v)),
        "(" => {
            let v = sum(t, at, q)?;
            if t.get(*at).map(String::as_str) != Some(")") {
                return Err("( without )".into());
            }
            *at += 1;
            Ok(v)
        }
        "PI" => Ok(Some(std::f64::consts::PI)),
        f @ ("SIN" | "COS" | "TAN" | "ASIN" | "ACOS" | "ATAN" | "SQRT" | "SQ" | "ABS" | "INT") => {
            let x = signed_value(t, at, q)?;
            let Some(x) = x else { return Ok(None) };
            let deg = std::f64::consts::PI / 180.0;
            Ok(Some(match f {
                "SIN" => (x * deg).sin(),
                "COS" => (x * deg).cos(),
                "TAN" => (x * deg).tan(),
                "ASIN" => x.asin() / deg,
                "ACOS" => x.acos() / deg,
                "ATAN" => x.atan() / deg,
                "SQRT" if x < 0.0 => return Err("square root of a negative number".into()),
                "SQRT" => x.sqrt(),
                "SQ" => x * x,
                "ABS" => x.abs(),
                _ => x.trunc(),
            }))
        }
        name if name.starts_with('Q') => q
            .get(name)
            .copied()
            .ok_or(format!("{name} is read before it is set")),
        number => number
            .parse::<f64>()
            .map(Some)
            .map_err(|_| format!("`{number}` is not a number or function")),
    }
}

/// How many blocks run while RL/RR is in force (after the block that gives it, up to the block
/// with R0) that do not move in the working plane XY: an `L` with only Z, or any block that
/// is not a contour element (`L`, `C`, `CR`, `CP`) or a circle centre `CC` (TNC manual, "Tool
/// radius compensation": compensation starts in an `L` block with RL/RR in the working plane
/// and the TNC computes the offset path from the contour elements that follow). Comments do
/// not count.
pub fn plane_less_blocks_under_comp(text: &str) -> usize {
    let mut on = false;
    let mut count = 0;
    for raw in text.lines() {
        let code = raw.split(';').next().unwrap_or("").trim();
        let code = code.trim_start_matches(|c: char| c.is_ascii_digit()).trim();
        let upper = code.to_ascii_uppercase();
        let words: Vec<&str> = upper.split_whitespace().collect();
        let Some(&head) = words.first() else { continue };
        if head == "*" {
            continue;
        }
        let gives = |w: &str| words.contains(&w);
        if gives("RL") || gives("RR") {
            on = true;
            continue;
        }
        if gives("R0") {
            on = false;
            continue;
        }
        if !on || head == "CC" {
            continue;
        }
        let in_plane = match head {
            "C" | "CR" | "CP" => true,
            "L" => words[1..]
                .iter()
                .any(|w| ["X", "Y", "IX", "IY"].iter().any(|a| w.starts_with(a))),
            _ => false,
        };
        if !in_plane {
            count += 1;
        }
    }
    count
}

/// A block of cycle 1 PECKING's definition: `1.0` starts it, `1.1 DIST…` (or `SET UP`) and
/// `1.2 DEPTH…` give its levels; the plunging depth, dwell and feed move along the same line.
fn pecking_def(
    line: u64,
    words: &[&str],
    pecking: &mut Option<(Option<f64>, Option<f64>)>,
) -> Result<(), String> {
    let id = words.get(1).copied().unwrap_or("");
    let value = |key: &str| -> Result<f64, String> {
        let joined = words[2..].join(" ");
        let at = joined
            .find(key)
            .ok_or(format!("line {line}: cycle 1 block without {key}"))?;
        let text = joined[at + key.len()..].trim_start();
        let num = text.split_whitespace().next().unwrap_or("");
        num.parse()
            .map_err(|_| format!("line {line}: cycle 1 {key} `{num}` is not followed"))
    };
    match id {
        "1.0" => *pecking = Some((None, None)),
        "1.1" => {
            let d = value(if words.iter().any(|w| w.starts_with("DIST")) {
                "DIST"
            } else {
                "SET UP"
            })?;
            pecking
                .as_mut()
                .ok_or(format!("line {line}: 1.1 before 1.0"))?
                .0 = Some(d);
        }
        "1.2" => {
            let d = value("DEPTH")?;
            pecking
                .as_mut()
                .ok_or(format!("line {line}: 1.2 before 1.0"))?
                .1 = Some(d);
        }
        "1.3" | "1.4" | "1.5" => {}
        _ => return Err(format!("line {line}: cycle 1 block `{id}` is not followed")),
    }
    Ok(())
}

/// Cycle 1's hole at the current position: feed from the start to the bottom, rapid back.
fn pecking_hole(
    line: u64,
    (dist, depth): (Option<f64>, Option<f64>),
    pos: &mut [Option<f64>; 3],
    out: &mut Vec<Seg>,
) -> Result<(), String> {
    let (Some(x), Some(y), Some(z), Some(dist), Some(depth)) =
        (pos[0], pos[1], pos[2], dist, depth)
    else {
        return Err(format!("line {line}: a cycle 1 hole at an unknown position or without DIST and DEPTH is not followed"));
    };
    let bottom = z + depth.signum() * (dist.abs() + depth.abs());
    let (top, low) = ([x, y, z], [x, y, bottom]);
    out.push(Seg {
        cut: true,
        line,
        start: top,
        end: low,
        arc: None,
    });
    out.push(Seg {
        cut: false,
        line,
        start: low,
        end: top,
        arc: None,
    });
    Ok(())
}
