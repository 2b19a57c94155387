//! The judge of a compensated program, independent of errmap's code: given the moves of the original and of the output as an outside executor read them (mm), every cutting point of the output lies on the original path lowered by E along Z, and the rapids are the original ones (or, for a drilling cycle's reference level moved with its hole, the original's lowered by E) except return steps of +E.
// Each test binary that includes this module uses only part of it.
#![allow(dead_code)]

/// A straight move or an arc, mm, as an executor (rs274, a reference tracer) reads it.
#[derive(Debug, Clone, PartialEq)]
pub struct Seg {
    /// Feed move (G1/G2/G3, L/C/CP at feed) or rapid (G0, FMAX).
    pub cut: bool,
    /// The source line it came from (0 when the executor does not say).
    pub line: u64,
    pub start: [f64; 3],
    pub end: [f64; 3],
    pub arc: Option<ArcSeg>,
}

/// An arc (or helix) in a plane: the centre in the plane's two axes, and the signed sweep, rad
/// (positive counter-clockwise seen from the plane's positive third axis).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ArcSeg {
    /// Plane axes (first, second, third), indices into x, y, z.
    pub axes: (usize, usize, usize),
    pub centre: (f64, f64),
    pub sweep_rad: f64,
}

impl Seg {
    /// The point at parameter `t` ∈ [0, 1].
    pub fn at(&self, t: f64) -> [f64; 3] {
        let lerp = |a: f64, b: f64| a + (b - a) * t;
        match &self.arc {
            None => [
                lerp(self.start[0], self.end[0]),
                lerp(self.start[1], self.end[1]),
                lerp(self.start[2], self.end[2]),
            ],
            Some(a) => {
                let (i, j, k) = a.axes;
                let (r0, th0) = polar(a, self.start[i], self.start[j]);
                let (r1, _) = polar(a, self.end[i], self.end[j]);
                let th = th0 + a.sweep_rad * t;
                let r = lerp(r0, r1);
                let mut p = [0.0; 3];
                p[i] = a.centre.0 + r * th.cos();
                p[j] = a.centre.1 + r * th.sin();
                p[k] = lerp(self.start[k], self.end[k]);
                p
            }
        }
    }

    /// Distance from `q` to the move, mm.
    pub fn distance(&self, q: &[f64; 3]) -> f64 {
        match &self.arc {
            None => {
                let d: Vec<f64> = (0..3).map(|n| self.end[n] - self.start[n]).collect();
                let len2: f64 = d.iter().map(|v| v * v).sum();
                let t = if len2 > 0.0 {
                    ((0..3).map(|n| (q[n] - self.start[n]) * d[n]).sum::<f64>() / len2)
                        .clamp(0.0, 1.0)
                } else {
                    0.0
                };
                dist(&self.at(t), q)
            }
            Some(a) => {
                // Every turn of the sweep that passes q's angle, and both ends.
                let (i, j, _) = a.axes;
                let (_, th0) = polar(a, self.start[i], self.start[j]);
                let (_, phi) = polar(a, q[i], q[j]);
                let mut best = dist(&self.at(0.0), q).min(dist(&self.at(1.0), q));
                if a.sweep_rad.abs() > 0.0 {
                    let tau = std::f64::consts::TAU;
                    let base = (phi - th0).rem_euclid(tau);
                    let (lo, hi) = if a.sweep_rad > 0.0 {
                        (-base, a.sweep_rad - base)
                    } else {
                        (a.sweep_rad - base, -base)
                    };
                    let (k0, k1) = ((lo / tau).ceil() as i64, (hi / tau).floor() as i64);
                    for k in k0..=k1.min(k0 + 10_000) {
                        let t = (base + k as f64 * tau) / a.sweep_rad;
                        best = best.min(dist(&self.at(t.clamp(0.0, 1.0)), q));
                    }
                }
                best
            }
        }
    }
}

fn polar(a: &ArcSeg, u: f64, v: f64) -> (f64, f64) {
    let (du, dv) = (u - a.centre.0, v - a.centre.1);
    (du.hypot(dv), dv.atan2(du))
}

fn dist(a: &[f64; 3], b: &[f64; 3]) -> f64 {
    (0..3).map(|n| (a[n] - b[n]).powi(2)).sum::<f64>().sqrt()
}

/// The signed sweep of an arc from `start` to `end` about `centre` in plane `axes`, clockwise
/// (`cw`) or not, with `turns` full turns beyond the first (0 for most arcs); a closed arc is
/// one full turn.
pub fn sweep(
    axes: (usize, usize, usize),
    centre: (f64, f64),
    start: &[f64; 3],
    end: &[f64; 3],
    cw: bool,
    turns: u32,
) -> f64 {
    let (i, j, _) = axes;
    let th0 = (start[j] - centre.1).atan2(start[i] - centre.0);
    let th1 = (end[j] - centre.1).atan2(end[i] - centre.0);
    let tau = std::f64::consts::TAU;
    let mut s = if cw {
        -(th0 - th1).rem_euclid(tau)
    } else {
        (th1 - th0).rem_euclid(tau)
    };
    if s.abs() < 1e-9 {
        s = if cw { -tau } else { tau };
    }
    s + f64::from(turns) * tau * s.signum()
}

/// What the judge found: cutting points checked, or why the output is wrong.
#[derive(Debug)]
pub struct Verdict {
    pub points_checked: usize,
}

/// Tolerances, mm: a vertex of the output's cut, raised by E, within `on_path_mm` of the
/// original path (vertices lie on the arc; chords only sag between them); a rapid's end within
/// `rapid_mm` of the original's (copied, so only the executor's print rounding differs).
pub const ON_PATH_MM: f64 = 0.003;
pub const RAPID_MM: f64 = 0.002;

/// Check `out` against `orig` for a flat map of `e_mm` along Z. Errors name the output move.
pub fn judge(orig: &[Seg], out: &[Seg], e_mm: f64) -> Result<Verdict, String> {
    // A step of +E along Z (the return to the original after a compensated cut), or a rapid
    // step of −E (a drilling cycle whose R level moved down by E to below where the tool
    // already stands, which the original reached without a move).
    let is_return = |s: &Seg| {
        let dz = s.end[2] - s.start[2];
        (s.end[0] - s.start[0]).abs() < RAPID_MM
            && (s.end[1] - s.start[1]).abs() < RAPID_MM
            && ((dz - e_mm).abs() < RAPID_MM || (!s.cut && (dz + e_mm).abs() < RAPID_MM))
            && s.arc.is_none()
    };
    // Rapids: the same ends in the same order, once the output's return steps are set aside.
    rapids_agree(orig, out, e_mm, &is_return)?;
    // Cuts: every vertex (and arc midpoint) of the output, raised by E, on the original cuts,
    // in order; and every original cut's end reached by an output vertex.
    // A feed that moves nothing (rs274 reports one for a `G1` block without axis words) is no
    // cut.
    let moves = |s: &&Seg| s.arc.is_some() || dist(&s.start, &s.end) > 0.0;
    let orig_cuts: Vec<&Seg> = orig.iter().filter(|s| s.cut).filter(moves).collect();
    let out_cuts: Vec<&Seg> = out
        .iter()
        .filter(|s| s.cut && !is_return(s))
        .filter(moves)
        .collect();
    if orig_cuts.is_empty() {
        return Err("the original has no cutting move".into());
    }
    let raise = |p: [f64; 3]| [p[0], p[1], p[2] + e_mm];
    let mut k = 0usize;
    let mut points = 0usize;
    let mut reached = vec![false; orig_cuts.len()];
    for s in &out_cuts {
        // Each probe: the points it may be (one, or two where a piece may carry a step).
        let mut probes: Vec<Vec<[f64; 3]>> = vec![vec![raise(s.end)]];
        if s.arc.is_some() {
            let mid = s.at(0.5);
            let mut alternatives = vec![raise(mid)];
            // An arc piece that also carries the step of ±E onto or off the compensated path
            // (under cutter compensation no block may move along Z alone, so the step rides
            // on the piece) has its middle half a step lowered.
            if ((s.end[2] - s.start[2]).abs() - e_mm).abs() < RAPID_MM {
                alternatives.push([mid[0], mid[1], mid[2] + 0.5 * e_mm]);
            }
            probes.push(alternatives);
        }
        for alternatives in probes {
            let on = |j: usize| {
                alternatives
                    .iter()
                    .copied()
                    .find(|q| orig_cuts[j].distance(q) <= ON_PATH_MM)
            };
            let found = (k..orig_cuts.len()).find_map(|j| on(j).map(|q| (j, q)));
            let Some((j, q)) = found else {
                let q = alternatives[0];
                let nearest = orig_cuts
                    .iter()
                    .map(|o| (o.distance(&q), o.line))
                    .min_by(|a, b| a.0.total_cmp(&b.0))
                    .unwrap_or((f64::NAN, 0));
                return Err(format!(
                    "output cut (line {}) reaches {:?}: raised by E = {e_mm} mm it is {:.4} mm from the original path (nearest: line {}), or out of order",
                    s.line, s.end, nearest.0, nearest.1
                ));
            };
            k = j;
            points += 1;
            if dist(&orig_cuts[j].end, &q) <= ON_PATH_MM {
                reached[j] = true;
            }
        }
    }
    // A cut whose end the output stops at only as the start of the next one still counts.
    for j in 0..orig_cuts.len() {
        let end = orig_cuts[j].end;
        if !reached[j]
            && !out_cuts
                .iter()
                .any(|s| dist(&raise(s.end), &end) <= ON_PATH_MM)
        {
            return Err(format!(
                "the original cut at line {} ending at {:?} is not reached by the output lowered by E",
                orig_cuts[j].line, end
            ));
        }
    }
    Ok(Verdict {
        points_checked: points,
    })
}

/// The output's rapids are the original's, in order. Two readings are tried, and either
/// clears the output: (1) the output's ±E steps along Z set aside, the rest paired one by one
/// with the original's; (2) each output rapid is the original's next one (a `G0 Z10` up from a
/// compensated cut is one, though it also is a step of +E), or else a ±E step. A rapid of a
/// drilling cycle to its reference level (R, Q203 + Q200) moved by −E with the hole
/// (`--compensate-holes`) may end E lower; every other rapid is copied.
fn rapids_agree(
    orig: &[Seg],
    out: &[Seg],
    e_mm: f64,
    is_step: &dyn Fn(&Seg) -> bool,
) -> Result<(), String> {
    let orig_rapids: Vec<&Seg> = orig.iter().filter(|s| !s.cut).collect();
    let same = |a: &Seg, b: &Seg| {
        let same_at = |dz: f64| {
            (0..3).all(|k| {
                let (ak, bk) = (a.end[k], b.end[k]);
                let ak = if k == 2 { ak - dz } else { ak };
                (ak.is_nan() && bk.is_nan()) || (ak - bk).abs() <= RAPID_MM
            })
        };
        same_at(0.0) || same_at(e_mm)
    };
    let mismatch = |n: usize, a: &Seg, b: &Seg| {
        format!(
            "rapid {} (output line {}) ends at {:?}, the original's (line {}) at {:?}",
            n + 1,
            b.line,
            b.end,
            a.line,
            a.end
        )
    };
    // (1) Steps set aside, then pairs.
    let paired = || -> Result<(), String> {
        let out_rapids: Vec<&Seg> = out.iter().filter(|s| !s.cut && !is_step(s)).collect();
        for (n, (a, b)) in orig_rapids.iter().zip(&out_rapids).enumerate() {
            if !same(a, b) {
                return Err(mismatch(n, a, b));
            }
        }
        if orig_rapids.len() != out_rapids.len() {
            return Err(format!(
                "{} rapids in the output (besides steps of ±E), {} in the original",
                out_rapids.len(),
                orig_rapids.len()
            ));
        }
        Ok(())
    };
    // (2) In order, a step only where the original's next rapid does not fit.
    let in_order = || -> Result<(), String> {
        let mut next = 0;
        for b in out.iter().filter(|s| !s.cut) {
            if orig_rapids.get(next).is_some_and(|a| same(a, b)) {
                next += 1;
            } else if !is_step(b) {
                return Err(match orig_rapids.get(next) {
                    Some(a) => mismatch(next, a, b),
                    None => format!(
                        "a rapid (output line {}) to {:?} after the original's last",
                        b.line, b.end
                    ),
                });
            }
        }
        if next != orig_rapids.len() {
            return Err(format!(
                "{next} of the original's {} rapids in the output",
                orig_rapids.len()
            ));
        }
        Ok(())
    };
    paired().or_else(|first| in_order().map_err(|_| first))
}
