//! Controller dialects: which one a program is written for (given or detected), and each one's table of G codes.
//!
//! A dialect is a table ([`g_code`]) plus a small delta of lexing rules (see `lexer`) and of
//! instructions errmap follows or refuses (see `gcode`). Detection looks for constructs only one
//! dialect has; a program with none of them is read as common ISO G-code only when every
//! coordinate has a decimal point (a decimal-less `X10` means 10 mm on LinuxCNC and Sinumerik but
//! 10 µm on a Fanuc in increment input), otherwise errmap asks for `--dialect`.

use crate::error::DialectError;
use crate::setting::Setting;
use errmap_core::error::{Error, Location, Result};
use errmap_core::setting::words;
use serde::{Deserialize, Serialize};
use std::path::Path;

/// A controller's G-code dialect.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Dialect {
    /// LinuxCNC RS274/NGC.
    Linuxcnc,
    /// Fanuc (Series 0i/30i, ISO with macro B).
    Fanuc,
    /// Siemens Sinumerik 840D (Siemens mode).
    Sinumerik,
    /// Heidenhain TNC: Klartext (refused) or ISO programs.
    Heidenhain,
}

impl Dialect {
    /// Parse a `--dialect` value.
    pub fn parse(text: &str) -> Option<Dialect> {
        match text.trim().to_ascii_lowercase().as_str() {
            "linuxcnc" | "rs274" | "ngc" => Some(Dialect::Linuxcnc),
            "fanuc" => Some(Dialect::Fanuc),
            "sinumerik" | "siemens" => Some(Dialect::Sinumerik),
            "heidenhain" => Some(Dialect::Heidenhain),
            _ => None,
        }
    }

    /// The name `--dialect` and the job file take (`linuxcnc`, `fanuc`, `sinumerik`,
    /// `heidenhain`).
    pub fn name(self) -> &'static str {
        match self {
            Dialect::Linuxcnc => "linuxcnc",
            Dialect::Fanuc => "fanuc",
            Dialect::Sinumerik => "sinumerik",
            Dialect::Heidenhain => "heidenhain",
        }
    }
}

/// How a Fanuc reads a coordinate without a decimal point (parameter 3401 bit 0, DPI, and the
/// increment system of parameter 1013): `Calculator` = millimetres/inches (DPI = 1); otherwise
/// least input increments of IS-A (0.01 mm / 0.001 in), IS-B (0.001 mm / 0.0001 in) or IS-C
/// (0.0001 mm / 0.00001 in).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum FanucNumbers {
    /// Pocket-calculator input (DPI = 1): `X10` is 10 mm (10 in under G20).
    Calculator,
    /// Increment system IS-A: `X10` is 0.1 mm (0.01 in).
    IsA,
    /// Increment system IS-B, the common one: `X10` is 0.01 mm (0.001 in).
    IsB,
    /// Increment system IS-C: `X10` is 0.001 mm (0.0001 in).
    IsC,
}

impl FanucNumbers {
    /// Parse a `--fanuc-numbers` value: `calculator`, `is-a`, `is-b` (or `increment`), `is-c`.
    pub fn parse(text: &str) -> Option<FanucNumbers> {
        match text.trim().to_ascii_lowercase().as_str() {
            "calculator" => Some(FanucNumbers::Calculator),
            "is-a" => Some(FanucNumbers::IsA),
            "is-b" | "increment" => Some(FanucNumbers::IsB),
            "is-c" => Some(FanucNumbers::IsC),
            _ => None,
        }
    }

    /// Value of one unit of a decimal-less number, in program units.
    pub fn unit(self, inches: bool) -> f64 {
        let mm = match self {
            FanucNumbers::Calculator => return 1.0,
            FanucNumbers::IsA => 0.01,
            FanucNumbers::IsB => 0.001,
            FanucNumbers::IsC => 0.0001,
        };
        if inches {
            mm / 10.0
        } else {
            mm
        }
    }
}

/// The motion mode a controller powers on in (Fanuc parameter 3402#0 G01, Sinumerik MD20150
/// `$MC_GCODE_RESET_VALUES[0]`): what a block with axis words and no motion word yet does.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum PowerOnMotion {
    /// G0, rapid traverse (Fanuc 3402#0 = 0).
    #[serde(rename = "g0")]
    Rapid,
    /// G1, linear interpolation (Fanuc 3402#0 = 1; the Sinumerik default).
    #[serde(rename = "g1")]
    Linear,
}

impl PowerOnMotion {
    /// Parse a power-on motion value: `g0`/`g00` or `g1`/`g01` (any case).
    pub fn parse(text: &str) -> Option<PowerOnMotion> {
        match text.trim().to_ascii_lowercase().as_str() {
            "g0" | "g00" => Some(PowerOnMotion::Rapid),
            "g1" | "g01" => Some(PowerOnMotion::Linear),
            _ => None,
        }
    }
}

/// Program units.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Units {
    /// Millimetres (G21; G71 on a Heidenhain).
    Mm,
    /// Inches (G20; G70 on a Heidenhain).
    Inch,
}

impl Units {
    /// Parse a units value: `mm`, `inch` or `in` (any case).
    pub fn parse(text: &str) -> Option<Units> {
        match text.trim().to_ascii_lowercase().as_str() {
            "mm" => Some(Units::Mm),
            "inch" | "in" => Some(Units::Inch),
            _ => None,
        }
    }
}

/// Kind of a motion mode (group 1).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Motion {
    /// Rapid traverse (G0).
    Rapid,
    /// Linear interpolation at feed (G1).
    Linear,
    /// Clockwise arc (G2).
    ArcCw,
    /// Counter-clockwise arc (G3).
    ArcCcw,
    /// Drilling/boring canned cycle (G73, G74, G76, G81–G89 …).
    Canned,
    /// Splines, NURBS, threading, rigid tapping: never compensated.
    Special,
    /// Probing (LinuxCNC G38.x): stops where it touches, so its end point is unknown.
    Probe,
}

/// A coordinate transformation errmap does not follow: cuts in the zone are refused while one
/// is active.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Frame {
    /// Local coordinate system (G52).
    Local,
    /// Coordinate rotation (G68).
    Rotation,
    /// Scaling (G51).
    Scaling,
    /// Programmable mirror image (G51.1).
    Mirror,
    /// Polar coordinate command (Fanuc G16).
    Polar,
    /// Position set by G92 (offsets from the work coordinates).
    Shift,
    /// A work offset other than the program's first one (G54–G59 …).
    WorkOffset,
    /// Offsets or parameters set by G10 L2/L20/L50.
    Data,
}

/// A G code as written: `G38.2` is `GCode { number: 38, decimal: 2 }`. Only the table
/// ([`g_code`]) gives it a meaning.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct GCode {
    /// The whole part of the code (G38.2 → 38).
    pub number: u16,
    /// The digit after the decimal point (G38.2 → 2; G1 → 0).
    pub decimal: u8,
}

impl GCode {
    /// The code of a G word's value (`38.2`), rounded to one decimal; `None` for a value no
    /// controller has (negative, not finite, or beyond G9999).
    pub fn from_value(v: f64) -> Option<GCode> {
        let tenths = (v * 10.0).round();
        if !(0.0..100_000.0).contains(&tenths) {
            return None;
        }
        let tenths = tenths as u32;
        Some(GCode {
            number: (tenths / 10) as u16,
            decimal: (tenths % 10) as u8,
        })
    }

    /// A whole code (`G1`).
    pub const fn whole(number: u16) -> GCode {
        GCode { number, decimal: 0 }
    }
}

impl std::fmt::Display for GCode {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self.decimal {
            0 => write!(f, "G{}", self.number),
            d => write!(f, "G{}.{d}", self.number),
        }
    }
}

/// What a G code means to the rewrite.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum G {
    /// Selects a motion mode (modal group 1).
    Motion(Motion),
    /// Cancel the motion mode (G80).
    MotionCancel,
    /// Selects the arc plane (G17, G18, G19).
    Plane(super::arc::Plane),
    /// Units: `true` for inches.
    Units(bool),
    /// Absolute (`true`) or incremental distance mode.
    Distance(bool),
    /// Absolute (`true`) or incremental arc centres (G90.1/G91.1).
    ArcDistance(bool),
    /// Cutter radius compensation on (`true`) or off.
    CutterComp(bool),
    /// G92: the current position takes the values of the block's axis words.
    SetPosition,
    /// Starts a transformation (its axis words are its parameters, not a move).
    Frame(Frame),
    /// Cancels a transformation.
    FrameCancel(Frame),
    /// Reference-point return (G28, G30): position unknown afterwards.
    Home,
    /// Machine coordinates for one block (G53).
    Machine,
    /// Work offset selection (G54–G59, G54.1, G500 …); the code tells which.
    WorkOffset,
    /// Data setting (G10): work offsets with L2/L20, tool data otherwise.
    DataSetting,
    /// Macro or subprogram call (Fanuc G65/G66).
    Call,
    /// A code with no effect on the geometry errmap follows (dwell, feed modes, path control …).
    Neutral,
}

impl G {
    /// Group 1: a motion mode or its cancel.
    pub fn is_motion(self) -> bool {
        matches!(self, G::Motion(_) | G::MotionCancel)
    }
}

/// The meaning of `code` in `dialect`, or `None` if errmap does not know it there (such a code
/// is refused: a G code errmap does not know may move the machine).
pub fn g_code(dialect: Dialect, code: GCode) -> Option<G> {
    let c = (code.number, code.decimal);
    if dialect == Dialect::Heidenhain {
        if let Some(g) = heidenhain_iso(c) {
            return Some(g);
        }
    }
    common(c).or_else(|| match dialect {
        Dialect::Linuxcnc => linuxcnc(c),
        Dialect::Fanuc => fanuc(c),
        Dialect::Sinumerik => sinumerik(c),
        Dialect::Heidenhain => None,
    })
}

/// Codes every dialect reads alike.
fn common(c: (u16, u8)) -> Option<G> {
    use super::arc::Plane;
    use Motion::*;
    Some(match c {
        (0, 0) => G::Motion(Rapid),
        (1, 0) => G::Motion(Linear),
        (2, 0) => G::Motion(ArcCw),
        (3, 0) => G::Motion(ArcCcw),
        (4 | 9 | 94 | 95 | 64 | 49 | 43 | 44, 0) => G::Neutral,
        (17, 0) => G::Plane(Plane::G17),
        (18, 0) => G::Plane(Plane::G18),
        (19, 0) => G::Plane(Plane::G19),
        (90, 0) => G::Distance(true),
        (91, 0) => G::Distance(false),
        (40, 0) => G::CutterComp(false),
        (41 | 42, 0) => G::CutterComp(true),
        (53, 0) => G::Machine,
        _ => return None,
    })
}

/// TNC ISO: G02/G03 take the centre from I/J (absolute) or G29; errmap follows G00/G01 only.
fn heidenhain_iso(c: (u16, u8)) -> Option<G> {
    Some(match c {
        (2 | 3 | 5 | 6 | 10 | 11 | 12 | 13 | 15 | 16 | 24 | 25 | 26 | 27 | 79, 0) => {
            G::Motion(Motion::Special)
        }
        (70, 0) => G::Units(true),
        (71, 0) => G::Units(false),
        (28, 0) => G::Frame(Frame::Mirror),
        (73, 0) => G::Frame(Frame::Rotation),
        (72, 0) => G::Frame(Frame::Scaling),
        (54, 0) => G::Frame(Frame::Local),
        (29 | 98 | 99, 0) => G::Neutral,
        _ => return None,
    })
}

/// LinuxCNC G-code reference (milling).
fn linuxcnc(c: (u16, u8)) -> Option<G> {
    use Motion::*;
    Some(match c {
        (20, 0) => G::Units(true),
        (21, 0) => G::Units(false),
        (90, 1) => G::ArcDistance(true),
        (91, 1) => G::ArcDistance(false),
        (41 | 42, 1) => G::CutterComp(true),
        (92, 0) => G::SetPosition,
        (92, 1 | 2) => G::FrameCancel(Frame::Shift),
        (92, 3) => G::Frame(Frame::Shift),
        (52, 0) => G::Frame(Frame::Local),
        (10, 0) => G::DataSetting,
        (28 | 30, 0 | 1) => G::Home,
        (54..=58, _) | (59, 0..=3) => G::WorkOffset,
        (80, 0) => G::MotionCancel,
        (73 | 74, 0) | (81..=89, 0) => G::Motion(Canned),
        (5, 0..=3) | (33, 0 | 1) | (76, 0) => G::Motion(Special),
        (38, 0..=5) => G::Motion(Probe),
        (7 | 8 | 61 | 93 | 96 | 97 | 98 | 99 | 60 | 65, 0) | (93 | 64 | 95, 1) | (43, 1..=3) => {
            G::Neutral
        }
        _ => return None,
    })
}

/// Fanuc Series 0i-MF / 30i-B (milling), G-code system A.
fn fanuc(c: (u16, u8)) -> Option<G> {
    use Motion::*;
    Some(match c {
        (20, 0) => G::Units(true),
        (21, 0) => G::Units(false),
        (92, 0) => G::SetPosition,
        (92, 1) => G::FrameCancel(Frame::Shift),
        (52, 0) => G::Frame(Frame::Local),
        (68, 0) => G::Frame(Frame::Rotation),
        (69, 0) => G::FrameCancel(Frame::Rotation),
        (51, 0) => G::Frame(Frame::Scaling),
        (50, 0) => G::FrameCancel(Frame::Scaling),
        (51, 1) => G::Frame(Frame::Mirror),
        (50, 1) => G::FrameCancel(Frame::Mirror),
        (16, 0) => G::Frame(Frame::Polar),
        (15, 0) => G::FrameCancel(Frame::Polar),
        (10, 0) => G::DataSetting,
        (28..=30, 0) => G::Home,
        (54..=58, _) | (59, 0) => G::WorkOffset,
        (80, 0) => G::MotionCancel,
        (73 | 74 | 76 | 81..=89, 0) => G::Motion(Canned),
        (33 | 31, 0) | (6, 2) | (12, 1) => G::Motion(Special),
        (65 | 66, 0) | (66, 1) => G::Call,
        (67 | 5 | 8 | 61 | 62 | 63 | 98 | 99 | 11 | 187, 0) | (5 | 13, 1) => G::Neutral,
        _ => return None,
    })
}

/// Sinumerik 840D sl, Siemens mode: G70/G71 (G700/G710) are units.
fn sinumerik(c: (u16, u8)) -> Option<G> {
    Some(match c {
        (70 | 700, 0) => G::Units(true),
        (71 | 710, 0) => G::Units(false),
        (500, 0) | (54..=56, _) | (57, 0) | (505..=598, _) | (599, 0) => G::WorkOffset,
        (74 | 75, 0) => G::Home,
        (153, 0) => G::Machine,
        (25 | 26 | 110 | 111 | 112 | 60 | 601 | 602 | 603 | 93 | 96 | 97, 0) | (64, 1..=5) => {
            G::Neutral
        }
        (33, 0..=2) | (34 | 35 | 63, 0) => G::Motion(Motion::Special),
        _ => return None,
    })
}

/// A construct that only one dialect has, found at `line`.
#[derive(Debug, Clone)]
struct Marker {
    dialect: Dialect,
    line: u64,
    what: String,
}

/// The dialect of `text`: `given` if set, else detected. A program whose meaning depends on the
/// dialect and that shows no construct of one is refused with a hint to pass `--dialect`.
pub fn resolve(text: &str, source: &Path, given: Option<Dialect>) -> Result<Dialect, DialectError> {
    if let Some(d) = given {
        return Ok(d);
    }
    let mut found: Vec<Marker> = Vec::new();
    let mut decimal_less: Option<(u64, String)> = None;
    for (i, raw) in text.lines().enumerate() {
        let line = i as u64 + 1;
        let upper = strip_comments(raw).to_ascii_uppercase();
        for m in markers(&upper) {
            if !found.iter().any(|f| f.dialect == m.0) {
                found.push(Marker {
                    dialect: m.0,
                    line,
                    what: m.1.to_string(),
                });
            }
        }
        if decimal_less.is_none() {
            if let Some(w) = decimal_less_coordinate(&upper) {
                decimal_less = Some((line, w));
            }
        }
    }
    match found.as_slice() {
        [one] => Ok(one.dialect),
        [] => match decimal_less {
            None => Ok(Dialect::Linuxcnc),
            Some((line, w)) => Err(DialectError::Uncertain(Error::input(
                Location::cell(source, line, column_of(text, line, &w)),
                format!(
                    "cannot tell the controller dialect: `{w}` has no decimal point (whole mm or inches on LinuxCNC or Sinumerik, least input increments, e.g. 0.001 mm, on a Fanuc in increment input) and the program has nothing only one dialect has"
                ),
                dialect_hint(),
            ))),
        },
        many => {
            let list: Vec<String> = many
                .iter()
                .map(|m| format!("{} (`{}` on line {})", m.dialect.name(), m.what, m.line))
                .collect();
            Err(DialectError::Uncertain(Error::input(
                Location::cell(source, many[1].line, column_of(text, many[1].line, &many[1].what)),
                format!(
                    "cannot tell the controller dialect: the program has constructs of {}",
                    list.join(" and ")
                ),
                dialect_hint(),
            )))
        }
    }
}

/// The hint of a program whose dialect errmap cannot tell: give it.
fn dialect_hint() -> String {
    format!(
        "pass {} linuxcnc|fanuc|sinumerik|heidenhain (job key [toolpaths] dialect)",
        words(Setting::Dialect)
    )
}

/// `"7 (X10)"`: the 1-based character column of `word` on `line` (1 if not found), and the word.
fn column_of(text: &str, line: u64, word: &str) -> String {
    let l = text
        .lines()
        .nth(line.saturating_sub(1) as usize)
        .unwrap_or("");
    let at = l
        .to_ascii_uppercase()
        .find(&word.to_ascii_uppercase())
        .unwrap_or(0);
    format!("{} ({word})", l[..at].chars().count() + 1)
}

/// The line without `( … )` and `;` comments.
/// A G-code line without its `( … )` comments and what follows a `;` outside them.
pub(crate) fn strip_comments(line: &str) -> String {
    let mut out = String::with_capacity(line.len());
    let mut depth = 0;
    for c in line.chars() {
        match c {
            '(' => depth += 1,
            ')' if depth > 0 => depth -= 1,
            ';' if depth == 0 => break,
            _ if depth == 0 => out.push(c),
            _ => {}
        }
    }
    out
}

/// Dialect-only constructs on one upper-cased, comment-free line.
fn markers(l: &str) -> Vec<(Dialect, &'static str)> {
    let t = l.trim_start();
    let mut out = Vec::new();
    heidenhain_markers(t, &mut out);
    linuxcnc_markers(t, &mut out);
    let compact: String = t.chars().filter(|c| !c.is_whitespace()).collect();
    fanuc_markers(&compact, &mut out);
    sinumerik_markers(t, &compact, &mut out);
    out
}

/// Heidenhain Klartext and ISO headers.
fn heidenhain_markers(t: &str, out: &mut Vec<(Dialect, &'static str)>) {
    let words: Vec<&str> = t.split_whitespace().collect();
    // Heidenhain Klartext: `0 BEGIN PGM`, `5 L X+10 R0 FMAX`, `7 CC X…`, `TOOL CALL`, `CYCL DEF`.
    if t.contains("BEGIN PGM") || t.contains("END PGM") {
        out.push((Dialect::Heidenhain, "BEGIN PGM"));
    }
    if words.len() >= 2 && words[0].chars().all(|c| c.is_ascii_digit()) {
        let kw = words[1];
        if matches!(
            kw,
            "L" | "CC"
                | "C"
                | "CR"
                | "CT"
                | "RND"
                | "CHF"
                | "LBL"
                | "CALL"
                | "TOOL"
                | "CYCL"
                | "BLK"
                | "LP"
                | "CP"
                | "FK"
                | "FL"
                | "FC"
        ) {
            out.push((Dialect::Heidenhain, "Klartext block"));
        }
    }
    // Heidenhain ISO: `%NAME G71 *`, blocks ending in `*`.
    if t.starts_with('%') && (t.contains("G70") || t.contains("G71")) && t.ends_with('*') {
        out.push((Dialect::Heidenhain, "%… G71 *"));
    }
}

/// LinuxCNC O-words with keywords and named parameters.
fn linuxcnc_markers(t: &str, out: &mut Vec<(Dialect, &'static str)>) {
    // LinuxCNC: O-words with keywords, named parameters, G64 P, G38.x, G5.x.
    if t.starts_with('O') || t.contains(" O") {
        for k in [
            "SUB",
            "ENDSUB",
            "CALL",
            "WHILE",
            "ENDWHILE",
            "REPEAT",
            "ENDREPEAT",
            "IF",
            "ENDIF",
            "DO",
        ] {
            if let Some(p) = t.find(k) {
                let before = &t[..p];
                if before.trim_start().starts_with('O') && !before.contains('[') {
                    out.push((Dialect::Linuxcnc, "O-word"));
                    break;
                }
            }
        }
    }
    if t.contains("#<") {
        out.push((Dialect::Linuxcnc, "#<name>"));
    }
}

/// Fanuc subprograms, macro calls, macro B flow and transformations.
fn fanuc_markers(compact: &str, out: &mut Vec<(Dialect, &'static str)>) {
    // Fanuc: M98/M99 subprograms, G65/G66 macro calls, macro B flow, G68/G51/G52.
    for (pat, what) in [
        ("M98", "M98"),
        ("M99", "M99"),
        ("G65P", "G65"),
        ("G66P", "G66"),
        ("WHILE[", "WHILE"),
        ("GOTO", "GOTO"),
        ("G68", "G68"),
        ("G51", "G51"),
    ] {
        if compact.contains(pat) && !out.iter().any(|(d, _)| *d == Dialect::Fanuc) {
            out.push((Dialect::Fanuc, what));
        }
    }
    if compact.starts_with('O')
        && compact.len() > 1
        && compact[1..].chars().all(|c| c.is_ascii_digit())
        && !out.iter().any(|(d, _)| *d == Dialect::Linuxcnc)
    {
        out.push((Dialect::Fanuc, "O program number"));
    }
}

/// Sinumerik assignments, frames, instructions and R parameters.
fn sinumerik_markers(t: &str, compact: &str, out: &mut Vec<(Dialect, &'static str)>) {
    // Sinumerik: `X=…`, `CR=`, AC()/IC(), frames, DEF, R-parameter assignment, MSG, G500/G710.
    let siemens = [
        "CR=", "X=", "Y=", "Z=", "=AC(", "=IC(", "TRANS", "ROT ", "SCALE", "MIRROR", "DEF ",
        "MSG(", "G500", "G710", "G700", "M17", "REPEAT ", "CALL ", "CYCLE", "SUPA",
    ];
    if let Some(s) = siemens
        .iter()
        .find(|s| compact.contains(*s) || t.contains(*s))
    {
        let klartext = out.iter().any(|(d, _)| *d == Dialect::Heidenhain);
        let lcnc_call =
            (*s == "CALL " || *s == "REPEAT ") && out.iter().any(|(d, _)| *d == Dialect::Linuxcnc);
        if !klartext && !lcnc_call {
            out.push((Dialect::Sinumerik, s.trim()));
        }
    }
    if is_r_assignment(compact) {
        out.push((Dialect::Sinumerik, "R parameter"));
    }
}

fn is_r_assignment(compact: &str) -> bool {
    let mut rest = compact;
    if let Some(p) = rest.find(|c: char| !(c == 'N' || c.is_ascii_digit())) {
        if rest.starts_with('N') {
            rest = &rest[p..];
        }
    }
    let Some(r) = rest.strip_prefix('R') else {
        return false;
    };
    let digits = r.chars().take_while(|c| c.is_ascii_digit()).count();
    digits > 0 && r[digits..].starts_with('=')
}

/// A coordinate word (X Y Z I J K R) whose number has no decimal point, e.g. `X10`.
fn decimal_less_coordinate(l: &str) -> Option<String> {
    let b = l.as_bytes();
    let mut i = 0;
    while i < b.len() {
        let c = b[i];
        let prev_alpha = i > 0 && b[i - 1].is_ascii_alphabetic();
        if matches!(c, b'X' | b'Y' | b'Z' | b'I' | b'J' | b'K' | b'R') && !prev_alpha {
            let mut j = i + 1;
            while j < b.len() && (b[j] == b' ' || b[j] == b'+' || b[j] == b'-') {
                j += 1;
            }
            let ds = j;
            while j < b.len() && b[j].is_ascii_digit() {
                j += 1;
            }
            let next_alpha = j < b.len() && b[j].is_ascii_alphabetic();
            let next_ok = j >= b.len() || b[j] != b'.' && b[j] != b'=' && b[j] != b'[';
            let value_nonzero = b[ds..j].iter().any(|&d| d != b'0');
            if j > ds
                && next_ok
                && value_nonzero
                && (next_alpha || j >= b.len() || b[j] == b' ' || b[j] == b'*')
            {
                return Some(l[i..j].trim().to_string());
            }
            i = j.max(i + 1);
        } else {
            i += 1;
        }
    }
    None
}

#[cfg(test)]
mod tests {
    use super::*;

    fn detect(text: &str) -> Result<Dialect, DialectError> {
        resolve(text, Path::new("t.nc"), None)
    }

    #[test]
    fn g_codes_are_read_as_written_and_meant_per_dialect() {
        let g = |v: f64| GCode::from_value(v).unwrap();
        assert_eq!(
            g(38.2),
            GCode {
                number: 38,
                decimal: 2
            }
        );
        assert_eq!(g(1.0).to_string(), "G1");
        assert_eq!(g(38.2).to_string(), "G38.2");
        assert_eq!(g(710.0).to_string(), "G710");
        assert_eq!(GCode::from_value(-1.0), None);
        assert_eq!(GCode::from_value(f64::NAN), None);
        // The same code means different things in different controllers.
        assert_eq!(g_code(Dialect::Linuxcnc, g(70.0)), None);
        assert_eq!(g_code(Dialect::Sinumerik, g(70.0)), Some(G::Units(true)));
        assert_eq!(
            g_code(Dialect::Fanuc, g(51.0)),
            Some(G::Frame(Frame::Scaling))
        );
        assert_eq!(
            g_code(Dialect::Heidenhain, g(2.0)),
            Some(G::Motion(Motion::Special))
        );
        assert_eq!(
            g_code(Dialect::Linuxcnc, g(2.0)),
            Some(G::Motion(Motion::ArcCw))
        );
        assert_eq!(
            g_code(Dialect::Linuxcnc, g(38.3)),
            Some(G::Motion(Motion::Probe))
        );
        assert_eq!(g_code(Dialect::Linuxcnc, g(59.3)), Some(G::WorkOffset));
        assert_eq!(g_code(Dialect::Fanuc, g(59.3)), None);
        assert_eq!(
            g_code(Dialect::Linuxcnc, g(90.1)),
            Some(G::ArcDistance(true))
        );
    }

    #[test]
    fn each_dialect_is_detected_from_its_own_constructs() {
        assert_eq!(
            detect("O1000\nG21 G90\nG1 X1. Y2.\nM98 P2000\nM30\n").unwrap(),
            Dialect::Fanuc
        );
        assert_eq!(
            detect("N10 G1 X=10.5 Y20\nN20 G2 X0 Y0 CR=5\n").unwrap(),
            Dialect::Sinumerik
        );
        assert_eq!(
            detect("0 BEGIN PGM P1 MM\n1 L X+10 Y+5 R0 FMAX\n").unwrap(),
            Dialect::Heidenhain
        );
        assert_eq!(
            detect("o100 sub\nG1 X1\no100 endsub\n").unwrap(),
            Dialect::Linuxcnc
        );
        assert_eq!(
            detect("%P1 G71 *\nN10 G01 X+10 Y+5 F100 *\n").unwrap(),
            Dialect::Heidenhain
        );
    }

    #[test]
    fn plain_programs_need_decimal_points_or_the_flag() {
        assert_eq!(
            detect("G21 G90\nG1 X1.5 Y0. Z0.\n").unwrap(),
            Dialect::Linuxcnc
        );
        let e = detect("G21 G90\nG1 X1.5 Y80000\n").unwrap_err().to_string();
        assert!(
            e.contains("t.nc:2") && e.contains("Y80000") && e.contains("`dialect`"),
            "{e}"
        );
        // Zero means the same everywhere.
        assert_eq!(
            detect("G21 G90\nG1 X0 Y0 Z0.5\n").unwrap(),
            Dialect::Linuxcnc
        );
    }

    #[test]
    fn mixed_constructs_are_refused() {
        let e = detect("o100 sub\nM98 P10\n").unwrap_err().to_string();
        assert!(e.contains("linuxcnc") && e.contains("fanuc"), "{e}");
    }

    #[test]
    fn fanuc_increments() {
        assert_eq!(FanucNumbers::IsB.unit(false), 0.001);
        assert_eq!(FanucNumbers::IsB.unit(true), 0.0001);
        assert_eq!(FanucNumbers::Calculator.unit(false), 1.0);
    }
}
