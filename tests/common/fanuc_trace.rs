//! A reference tracer for Fanuc-style ISO milling programs (Series 0i-MF / 30i, G-code system A), written from the operator's manual rules and independent of errmap's reader: moves in mm, or the construct it does not follow.
//!
//! Rules followed: words are a letter and a number (`;` ends a block, `( … )` is a comment,
//! `%` lines and `O` numbers are no moves); group 01 G0/G1/G2/G3 is modal, a block with axis
//! words and no motion code before any moves in the power-on mode; G90/G91 (absolute,
//! incremental), G20/G21 (inch, mm), G17/G18/G19 planes; arcs take I/J/K as the distance from
//! the start to the centre (always incremental), or R (R > 0 the arc up to 180°, R < 0 the
//! longer one); the axis off the plane moves linearly (helix); a decimal-less number is read
//! in least input increments (is-a/is-b/is-c) or as it stands (calculator). G4 X/P is a dwell,
//! G10 sets data; G8 (look-ahead), G9 (exact stop), G40, G43/G44/G49 H, G54–G59, G61, G64,
//! G80, G94, G98/G99, G15 move nothing here
//! (the same in the original and the output). G28, G53 and G30 go to machine positions: the
//! axes they name become unknown. G52 shifts the named axes, G92 names the current position.
//! G41/G42 (cutter compensation) and G40 are followed as the programmed contour, and the moves
//! without motion in the plane under them are counted. Subprograms in the same file: `M98 P<n> L<k>` runs program `O<n>` k times (once without
//! L), its `M99` returns to the block after the call; the main program is the first one that
//! ends in `M30`/`M02` (a program ending in `M99` is a subprogram), and `M30`/`M02` ends the
//! run. Anything else that moves (G91 cycles, G68, G51, macro variables, Fadal L)
//! is refused: the judge cannot vouch for it.
// Each test binary that includes this module uses only part of it.
#![allow(dead_code)]

use super::path_judge::{sweep, ArcSeg, Seg};

/// How the machine reads what the program leaves open.
#[derive(Debug, Clone, Copy)]
pub struct FanucSetup {
    /// Units when the program has no G20/G21: true = inch.
    pub inch: Option<bool>,
    /// Least input increment in mm for a decimal-less number (is-b: 0.001), `None` =
    /// calculator (the number as it stands); inch programs use a tenth of it in inches.
    pub increment_mm: Option<f64>,
    /// Power-on motion: true = G1.
    pub power_on_g1: Option<bool>,
}

/// The moves of `text`, mm.
pub fn trace(text: &str, setup: FanucSetup) -> Result<Vec<Seg>, String> {
    trace_counted(text, setup, &mut 0)
}

/// How many moves without motion in the plane run while cutter compensation is on (a control
/// looks ahead past only a few of them before it gouges or alarms); 0 when the program is not
/// followed.
pub fn plane_less_moves_under_comp(text: &str, setup: FanucSetup) -> usize {
    let mut n = 0;
    match trace_counted(text, setup, &mut n) {
        Ok(_) => n,
        Err(_) => 0,
    }
}

/// [`trace`], counting the moves without motion in the plane under cutter compensation.
fn trace_counted(
    text: &str,
    setup: FanucSetup,
    plane_less_under_comp: &mut usize,
) -> Result<Vec<Seg>, String> {
    // G41/G42 offset the tool from the programmed contour, G40 ends it: the judge compares
    // programmed contours, which the control offsets alike in both programs when they agree
    // in the plane.
    let mut comp = false;
    // A canned drilling cycle series (G73, G81–G89 until G80 or a G0–G3): its code, bottom Z,
    // R level and the Z it started from; G98 (back to that Z, the power-on mode) or G99 (to R).
    let mut cycle: Option<(u32, Option<f64>, Option<f64>, f64)> = None;
    let mut g98 = true;
    let mut pos: [Option<f64>; 3] = [None; 3];
    let mut motion: Option<u32> = setup.power_on_g1.map(u32::from);
    let mut inch = setup.inch;
    let mut absolute = true;
    let mut plane = (0usize, 1usize, 2usize);
    // G52 local shift and G92 setting, mm: positions are kept in the work coordinates.
    let (mut local, mut set) = ([0.0f64; 3], [0.0f64; 3]);
    let mut out = Vec::new();
    let lines: Vec<&str> = text.lines().collect();
    for n in run_order(&lines)? {
        let raw = lines[n];
        let line = n as u64 + 1;
        let words = words(raw).map_err(|w| format!("line {line}: cannot read `{w}`"))?;
        if words.is_empty() || words[0].0 == 'O' && words.len() == 1 {
            continue;
        }
        let mut block_motion = None;
        let mut block_cycle: Option<u32> = None;
        let mut cancel_cycle = false;
        let mut non_modal = None;
        let mut axes: [Option<(f64, bool)>; 3] = [None; 3];
        let mut ijk: [Option<f64>; 3] = [None; 3];
        let mut r = None;
        for &(letter, ref num) in &words {
            let value = |scale_axis: bool| -> Result<f64, String> {
                number(num, scale_axis, inch, setup.increment_mm)
                    .ok_or_else(|| format!("line {line}: `{letter}{num}` is no number"))
            };
            match letter {
                'G' => {
                    let g: f64 = num.parse().map_err(|_| format!("line {line}: G{num}"))?;
                    if g.fract() != 0.0 || g < 0.0 {
                        return Err(format!("line {line}: G{num} is not followed"));
                    }
                    match g as u32 {
                        m @ 0..=3 => block_motion = Some(m),
                        m @ (73 | 81..=89) => block_cycle = Some(m),
                        80 => cancel_cycle = true,
                        98 => g98 = true,
                        99 => g98 = false,
                        17 => plane = (0, 1, 2),
                        18 => plane = (2, 0, 1),
                        19 => plane = (1, 2, 0),
                        20 => inch = Some(true),
                        21 => inch = Some(false),
                        90 => absolute = true,
                        91 => absolute = false,
                        m @ (4 | 10 | 28 | 30 | 52 | 53 | 92) => non_modal = Some(m),
                        41 | 42 => comp = true,
                        40 => comp = false,
                        8 | 9 | 15 | 43 | 44 | 49 | 54..=59 | 61 | 64 | 94 => {}
                        _ => return Err(format!("line {line}: G{num} is not followed")),
                    }
                }
                'X' | 'Y' | 'Z' => {
                    let k = (letter as u8 - b'X') as usize;
                    axes[k] = Some((value(true)?, absolute));
                }
                'I' | 'J' | 'K' => ijk[(letter as u8 - b'I') as usize] = Some(value(true)?),
                'R' => r = Some(value(true)?),
                // The repeat count of an M98 call (run by `run_order`).
                'L' if words
                    .iter()
                    .any(|(l, v)| *l == 'M' && v.parse::<f64>().ok() == Some(98.0)) => {}
                'L' => {
                    // A repeat count (Fadal L on an arc) or a Fadal subprogram call: not followed.
                    return Err(format!("line {line}: L{num} is not followed"));
                }
                'M' => {
                    let m: f64 = num.parse().unwrap_or(-1.0);
                    if m == 97.0 {
                        return Err(format!("line {line}: M{num} calls a subprogram"));
                    }
                }
                'N' | 'F' | 'S' | 'T' | 'H' | 'D' | 'O' | 'E' | 'P' | 'Q' => {}
                _ => return Err(format!("line {line}: {letter}{num} is not followed")),
            }
        }
        if let Some(g) = non_modal {
            match g {
                4 | 10 => continue,
                52 | 92 => {
                    // G52: a local shift of the named axes; G92: the current position is named
                    // the given coordinates (Series 0i-MF manual, "Local coordinate system" and
                    // "Setting a workpiece coordinate system").
                    for k in 0..3 {
                        if let Some((v, _)) = axes[k] {
                            if g == 52 {
                                local[k] = v;
                            } else {
                                let p = pos[k].ok_or_else(|| {
                                    format!("line {line}: G92 at an unknown position")
                                })?;
                                set[k] = p - v - local[k];
                            }
                        }
                    }
                    continue;
                }
                _ => {
                    // To a machine position: the named axes leave the work coordinates known here.
                    for k in 0..3 {
                        if axes[k].is_some() {
                            pos[k] = None;
                        }
                    }
                    // G0/G1 may stand with G53 (it moves at rapid either way) and stays modal.
                    if let Some(m) = block_motion {
                        if m >= 2 {
                            return Err(format!("line {line}: an arc with G{g}"));
                        }
                        motion = Some(m);
                    }
                    continue;
                }
            }
        }
        if cancel_cycle || block_motion.is_some() {
            // G80, or a motion code of group 01, ends the series.
            cycle = None;
            if cancel_cycle && block_motion.is_none() {
                motion = None;
            }
        }
        if let Some(code) = block_cycle {
            let z_now = pos[2].ok_or(format!("line {line}: a cycle from an unknown Z"))?;
            cycle = Some((code, None, None, z_now));
        }
        if let Some((code, z_bottom, r_level, initial)) = cycle.as_mut() {
            // A hole at every block of the series that names X or Y (and the cycle's own block):
            // rapid to the position, rapid to R, feed to the bottom, rapid back to the start Z
            // (G98) or R (G99). Its pecks and dwells go up and down that line.
            if !absolute {
                return Err(format!("line {line}: a G91 canned cycle is not followed"));
            }
            if ijk[2].is_some_and(|k| k != 1.0) {
                return Err(format!(
                    "line {line}: a repeat count K on a cycle is not followed"
                ));
            }
            if let Some((z, _)) = axes[2] {
                *z_bottom = Some(z + local[2] + set[2]);
            }
            if let Some(rv) = r {
                *r_level = Some(rv + local[2] + set[2]);
            }
            let hole_here = block_cycle.is_some() || axes[0].is_some() || axes[1].is_some();
            if hole_here {
                let (Some(bottom), Some(rl)) = (*z_bottom, *r_level) else {
                    return Err(format!("line {line}: cycle G{code} without Z or R"));
                };
                let mut xy = [f64::NAN; 2];
                for k in 0..2 {
                    xy[k] = match (axes[k], pos[k]) {
                        (Some((v, _)), _) => v + local[k] + set[k],
                        (None, Some(p)) => p,
                        _ => return Err(format!("line {line}: a hole at an unknown position")),
                    };
                }
                let mut from = [
                    pos[0].unwrap_or(f64::NAN),
                    pos[1].unwrap_or(f64::NAN),
                    pos[2].unwrap_or(f64::NAN),
                ];
                let back = if g98 { initial.max(rl) } else { rl };
                let steps = [(false, from[2]), (false, rl), (true, bottom), (false, back)];
                for (cut, level) in steps {
                    let to = [xy[0], xy[1], level];
                    if (0..3).any(|k| (to[k] - from[k]).abs() > 0.0 || from[k].is_nan()) {
                        out.push(Seg {
                            cut,
                            line,
                            start: from,
                            end: to,
                            arc: None,
                        });
                    }
                    from = to;
                }
                pos = [Some(xy[0]), Some(xy[1]), Some(back)];
            }
            continue;
        }
        if let Some(m) = block_motion {
            motion = Some(m);
        }
        let arc_block = block_motion.is_some_and(|m| m >= 2);
        if axes.iter().all(Option::is_none) {
            // An arc with I/J/K and no end point is a full circle; with R it is nothing.
            if !arc_block || ijk.iter().all(Option::is_none) {
                if arc_block {
                    return Err(format!("line {line}: an arc with no end point"));
                }
                continue;
            }
        }
        let Some(m) = motion else {
            return Err(format!("line {line}: axis words before any motion code"));
        };
        if inch.is_none() {
            return Err(format!("line {line}: a move before G20/G21"));
        }
        // An axis at an unknown (machine) position stays NaN: a rapid may go on from there,
        // a cut may not.
        let mut end = [f64::NAN; 3];
        let mut start = [f64::NAN; 3];
        for k in 0..3 {
            end[k] = match (axes[k], pos[k]) {
                (Some((v, true)), _) => v + local[k] + set[k],
                (Some((v, false)), Some(p)) => p + v,
                (None, Some(p)) => p,
                _ => f64::NAN,
            };
            start[k] = pos[k].unwrap_or(f64::NAN);
        }
        if m != 0 && start.iter().chain(&end).any(|v| v.is_nan()) {
            return Err(format!("line {line}: a cut from or to an unknown position"));
        }
        let arc = if m >= 2 {
            let (i, j, _) = plane;
            let centre = if let Some(rv) = r {
                let (du, dv) = (end[i] - start[i], end[j] - start[j]);
                let d = du.hypot(dv);
                if d == 0.0 || d > 2.0 * rv.abs() + 1e-6 {
                    return Err(format!("line {line}: R arc with no centre"));
                }
                let h = (rv * rv - d * d / 4.0).max(0.0).sqrt();
                // Centre to the left of the chord for a CCW minor arc or a CW major arc.
                let left = (m == 3) == (rv > 0.0);
                let s = if left { 1.0 } else { -1.0 };
                (
                    start[i] + du / 2.0 - s * h * dv / d,
                    start[j] + dv / 2.0 + s * h * du / d,
                )
            } else {
                let off = |axis: usize| ijk[axis].unwrap_or(0.0);
                (start[i] + off(i), start[j] + off(j))
            };
            Some(ArcSeg {
                axes: plane,
                centre,
                sweep_rad: sweep(plane, centre, &start, &end, m == 2, 0),
            })
        } else {
            None
        };
        if comp
            && arc.is_none()
            && (end[plane.0] - start[plane.0]).hypot(end[plane.1] - start[plane.1]) < 1e-9
        {
            *plane_less_under_comp += 1;
        }
        out.push(Seg {
            cut: m != 0,
            line,
            start,
            end,
            arc,
        });
        pos = end.map(|v| (!v.is_nan()).then_some(v));
    }
    Ok(out)
}

/// The value of a word in mm: `scale_axis` words (coordinates, I/J/K/R) follow the units and,
/// without a decimal point, the increment.
fn number(
    num: &str,
    scale_axis: bool,
    inch: Option<bool>,
    increment_mm: Option<f64>,
) -> Option<f64> {
    let v: f64 = num.parse().ok()?;
    if !scale_axis {
        return Some(v);
    }
    let per_unit = if inch == Some(true) { 25.4 } else { 1.0 };
    match increment_mm {
        Some(inc) if !num.contains('.') => {
            let unit_inc = if inch == Some(true) { inc / 10.0 } else { inc };
            Some(v * unit_inc * per_unit)
        }
        _ => Some(v * per_unit),
    }
}

/// The words of a line, comments removed: (letter, number text). A block-delete `/` is read
/// as switched off (the block runs).
/// The order the control runs the lines in: the main program from its O number, through
/// `M98 P… L…` calls of subprograms in the same file and their `M99` returns, to `M30`/`M02`.
fn run_order(lines: &[&str]) -> Result<Vec<usize>, String> {
    let parsed: Vec<Vec<(char, String)>> =
        lines.iter().map(|l| words(l).unwrap_or_default()).collect();
    let has = |n: usize, letter: char, v: f64| {
        parsed[n]
            .iter()
            .any(|(l, num)| *l == letter && num.parse::<f64>().ok() == Some(v))
    };
    let value = |n: usize, letter: char| {
        parsed[n]
            .iter()
            .find(|(l, _)| *l == letter)
            .and_then(|(_, num)| num.parse::<f64>().ok())
    };
    // Where each O program starts, and whether it ends the run (M30/M02) or returns (M99).
    let mut starts: Vec<(u32, usize)> = Vec::new();
    for (n, words) in parsed.iter().enumerate() {
        if let Some(o) = words.first().filter(|(l, _)| *l == 'O') {
            let number =
                o.1.parse::<u32>()
                    .map_err(|_| format!("line {}: O{}", n + 1, o.1))?;
            starts.push((number, n));
        }
    }
    let ends_run = |from: usize| {
        (from..lines.len())
            .take_while(|&n| n == from || parsed[n].first().is_none_or(|(l, _)| *l != 'O'))
            .any(|n| has(n, 'M', 30.0) || has(n, 'M', 2.0))
    };
    let main = match starts.iter().find(|(_, n)| ends_run(*n)) {
        Some(&(_, n)) => n,
        None if starts.is_empty() => 0,
        None => return Err("no main program (ending in M30 or M02) is followed".into()),
    };
    let mut order = Vec::new();
    let mut stack: Vec<(usize, usize, u32)> = Vec::new(); // (call line, sub start, runs left)
    let mut n = main;
    while n < lines.len() {
        if order.len() > 10_000_000 {
            return Err("more than 10 million blocks run".into());
        }
        order.push(n);
        if has(n, 'M', 98.0) {
            let p = value(n, 'P').ok_or(format!("line {}: M98 without P", n + 1))? as u32;
            let times = value(n, 'L').unwrap_or(1.0) as u32;
            let start = starts
                .iter()
                .find(|(o, _)| *o == p)
                .map(|&(_, s)| s)
                .ok_or(format!("line {}: O{p} is not in the file", n + 1))?;
            if times > 0 {
                stack.push((n, start, times));
                n = start + 1;
                continue;
            }
        } else if has(n, 'M', 99.0) {
            let Some((call, start, left)) = stack.pop() else {
                return Err(format!(
                    "line {}: M99 in the main program is not followed",
                    n + 1
                ));
            };
            if left > 1 {
                stack.push((call, start, left - 1));
                n = start + 1;
            } else {
                n = call + 1;
            }
            continue;
        } else if has(n, 'M', 30.0) || has(n, 'M', 2.0) {
            break;
        }
        n += 1;
    }
    Ok(order)
}

fn words(raw: &str) -> Result<Vec<(char, String)>, String> {
    let mut out = Vec::new();
    let mut chars = raw.trim_end_matches(['\r', '\n']).chars().peekable();
    while let Some(c) = chars.next() {
        match c {
            '(' => {
                for d in chars.by_ref() {
                    if d == ')' {
                        break;
                    }
                }
            }
            ';' => break,
            '%' | '/' => {}
            c if c.is_whitespace() => {}
            c if c.is_ascii_alphabetic() => {
                let mut num = String::new();
                while let Some(&d) = chars.peek() {
                    if d.is_ascii_digit() || d == '.' || d == '-' || d == '+' {
                        num.push(d);
                        chars.next();
                    } else if d == ' ' || d == '\t' {
                        chars.next();
                        // spaces inside a number are allowed; stop at the next letter
                        if !chars
                            .peek()
                            .is_some_and(|e| e.is_ascii_digit() || *e == '.')
                        {
                            break;
                        }
                    } else {
                        break;
                    }
                }
                if num.is_empty() {
                    return Err(c.to_string());
                }
                out.push((c.to_ascii_uppercase(), num));
            }
            other => return Err(other.to_string()),
        }
    }
    Ok(out)
}
