//! Polar path blocks of Klartext: `LP PR… PA…` (a line to the point at radius PR and angle PA about the pole CC) and `CP PA…` / `CP IPA…` (an arc about CC from the current position; with a coordinate of the third axis, a helix), in the plane of the last CC block's two axes.

use super::super::arc::{Arc, Plane};
use super::block::{Block, Value};
use super::interp::{known, Refusal};
use super::{Kt, Point};
use errmap_core::error::Result;
use std::f64::consts::PI;

const AXES: [&str; 3] = ["X", "Y", "Z"];

/// End point, arc (CP) and what forbids compensating an LP or CP block.
pub(super) type PolarMove = (Point, Option<Arc>, Option<Refusal>);

impl Kt<'_> {
    /// The plane of the circle centre / pole: that of the CC block's two axes (`CC X… Z…`: ZX),
    /// else the working plane of the tool axis.
    pub(super) fn circle_plane(&self) -> Plane {
        self.cc_plane.unwrap_or_else(|| self.plane())
    }

    /// Read an `LP` or `CP` block from `start`.
    pub(super) fn polar_move(&self, n: u64, b: &Block, start: Point) -> Result<PolarMove> {
        let plane = self.circle_plane();
        let (a1, a2, ax) = plane.axes();
        for i in [a1, a2] {
            for a in [AXES[i].to_string(), format!("I{}", AXES[i])] {
                if let Some(w) = b.word(&a) {
                    return Err(self.err(
                        n,
                        w.col,
                        &w.text,
                        format!("`{}` in an {} block: its end point in the plane of the pole CC is given by polar coordinates (PR, PA)", w.text, b.head),
                        "give the end point as PR/PA about CC, or write an L / C block with Cartesian coordinates",
                    ));
                }
            }
        }
        // The third axis: absolute or incremental, linear along the move (a helix for CP).
        let mut end = start;
        if let Some(w) = b.word(AXES[ax]) {
            end[ax] = w.num();
        } else if let Some(w) = b.word(&format!("I{}", AXES[ax])) {
            end[ax] = start[ax].zip(w.num()).map(|(s, d)| s + d);
        }
        end[a1] = None;
        end[a2] = None;
        let (Some(c1), Some(c2)) = (self.centre[a1], self.centre[a2]) else {
            return Ok((end, None, Some((
                b.head_col,
                b.head.clone(),
                format!("{} with an unknown pole CC (none since the program start, a label or a block errmap does not follow)", b.head),
                "program CC with the two coordinates of the plane before the polar block".into(),
            ))));
        };
        let angle = |addr: &str| b.word(addr).map(|w| (w.num(), w.col, w.text.clone()));
        if b.head == "LP" {
            let (pr, pa) = (angle("PR"), angle("PA"));
            let (Some((Some(pr), ..)), Some((Some(pa), ..))) = (pr, pa) else {
                let w = b
                    .words
                    .iter()
                    .find(|w| matches!(w.addr.as_str(), "IPR" | "IPA"));
                return Ok((end, None, Some((
                    w.map_or(b.head_col, |w| w.col),
                    w.map_or(b.head.clone(), |w| w.text.clone()),
                    "LP without both an absolute radius PR and angle PA: the TNC takes an omitted or incremental one from the last polar block, which errmap does not follow".into(),
                    "give LP both PR+… and PA+… (absolute), or post the line as an L block".into(),
                ))));
            };
            let t = pa.to_radians();
            end[a1] = Some(c1 + pr * t.cos());
            end[a2] = Some(c2 + pr * t.sin());
            return Ok((end, None, None));
        }
        // CP: the radius is the distance from the start point to the pole.
        let Some(ccw) = b.word("DR").and_then(|w| match w.value {
            Value::Sign(ccw) => Some(ccw),
            _ => None,
        }) else {
            return Err(self.err(
                n,
                b.head_col,
                "CP",
                "CP block without a direction of rotation DR+ or DR-".into(),
                "add DR+ (counterclockwise) or DR- (clockwise)",
            ));
        };
        let (ipa, pa) = (angle("IPA"), angle("PA"));
        let Some((value, col, text)) = ipa.clone().or(pa) else {
            return Err(self.err(
                n,
                b.head_col,
                "CP",
                "CP block without an end angle PA or IPA".into(),
                "give the end angle: PA+… (absolute) or IPA+… (the angle swept, for a helix the total angle)",
            ));
        };
        let (Some(s1), Some(s2)) = (start[a1], start[a2]) else {
            return Ok((end, None, None));
        };
        let Some(value) = value else {
            return Ok((end, None, None));
        };
        let r = (s1 - c1).hypot(s2 - c2);
        if r < 1e-9 {
            return Err(self.err(
                n,
                b.head_col,
                "CP",
                "CP starts on its pole CC (radius 0)".into(),
                "move to a point on the circle before the CP block, or fix the CC",
            ));
        }
        let theta_start = (s2 - c2).atan2(s1 - c1);
        let sweep = if ipa.is_some() {
            let sweep = value.to_radians();
            if sweep == 0.0 || (sweep > 0.0) != ccw {
                return Ok((end, None, Some((
                    col,
                    text,
                    format!("CP {} with DR{}: an incremental angle and the direction of rotation must have the same sign", b.word("IPA").map_or("", |w| w.text.as_str()), if ccw { "+" } else { "-" }),
                    "give IPA the sign of DR (IPA+… with DR+, IPA-… with DR-)".into(),
                ))));
            }
            sweep
        } else {
            let d = (value.to_radians() - theta_start).rem_euclid(2.0 * PI);
            let sweep = if ccw { d } else { d - 2.0 * PI };
            if d.abs() < 1e-12 || (2.0 * PI - d).abs() < 1e-12 {
                return Ok((
                    end,
                    None,
                    Some((
                        col,
                        text,
                        "CP PA… at the angle of its start point: a full circle or no move".into(),
                        "program a full circle as CP IPA+360 DR+ (or IPA-360 DR-)".into(),
                    )),
                ));
            }
            sweep
        };
        let t = theta_start + sweep;
        end[a1] = Some(c1 + r * t.cos());
        end[a2] = Some(c2 + r * t.sin());
        let (Some(s), Some(e)) = (known(start), known(end)) else {
            return Ok((end, None, None));
        };
        let arc = Arc {
            plane,
            start: s,
            end: e,
            centre: (c1, c2),
            r_start: r,
            r_end: r,
            theta_start,
            sweep,
        };
        Ok((end, Some(arc), None))
    }
}
