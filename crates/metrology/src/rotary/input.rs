//! Reading rotary-axis measurement files: sphere centres or raw touch points per sphere, position and repeat.

use errmap_core::error::{Error, Location, Result};
use errmap_core::io::{CsvRow, CsvTable};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::fmt;
use std::path::{Path, PathBuf};

/// Columns a measurement file may have (`point` is optional).
pub const COLUMNS: [&str; 9] = [
    "axis",
    "direction",
    "repeat",
    "angle_deg",
    "sphere",
    "x_mm",
    "y_mm",
    "z_mm",
    "point",
];

/// A rotary axis by its letter: A turns about X, B about Y, C about Z (ISO 841).
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
pub enum RotaryAxis {
    /// Turns about X.
    A,
    /// Turns about Y.
    B,
    /// Turns about Z.
    C,
}

impl RotaryAxis {
    /// Parse `A`, `B` or `C` (either case).
    pub fn parse(text: &str) -> Option<RotaryAxis> {
        match text.trim() {
            "A" | "a" => Some(RotaryAxis::A),
            "B" | "b" => Some(RotaryAxis::B),
            "C" | "c" => Some(RotaryAxis::C),
            _ => None,
        }
    }

    /// Nominal direction of the axis: the unit vector of X, Y or Z.
    pub fn nominal_direction(self) -> [f64; 3] {
        match self {
            RotaryAxis::A => [1.0, 0.0, 0.0],
            RotaryAxis::B => [0.0, 1.0, 0.0],
            RotaryAxis::C => [0.0, 0.0, 1.0],
        }
    }

    /// Index (0, 1, 2) of the linear axis this one turns about.
    pub fn index(self) -> usize {
        match self {
            RotaryAxis::A => 0,
            RotaryAxis::B => 1,
            RotaryAxis::C => 2,
        }
    }
}

/// `A`, `B` or `C` (either case), for command-line parsers; the error says what is expected.
impl std::str::FromStr for RotaryAxis {
    type Err = String;

    fn from_str(s: &str) -> std::result::Result<RotaryAxis, String> {
        RotaryAxis::parse(s).ok_or_else(|| format!("'{s}' is not A, B or C"))
    }
}

impl fmt::Display for RotaryAxis {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let letter = match self {
            RotaryAxis::A => "A",
            RotaryAxis::B => "B",
            RotaryAxis::C => "C",
        };
        f.write_str(letter)
    }
}

pub use errmap_core::direction::Direction;

/// The measured points of one sphere at one position: one centre, or the touch points.
#[derive(Debug, Clone, Default)]
pub struct SphereData {
    /// 1-based file lines of the rows, in file order.
    pub lines: Vec<u64>,
    /// The rows' coordinates (sphere centres, or stylus-centre touch points).
    pub points_mm: Vec<[f64; 3]>,
}

/// One commanded position of the axis in one repeat: both spheres.
#[derive(Debug, Clone)]
pub struct Position {
    /// Approach direction from the `direction` column (`+` increasing angle, `-` decreasing).
    pub direction: Direction,
    /// Repeat number from the `repeat` column (non-negative integer).
    pub repeat: u32,
    /// Commanded angle α from the `angle_deg` column, degrees (within ten turns, ±3600).
    pub angle_deg: f64,
    /// Sphere 1 and sphere 2.
    pub spheres: [SphereData; 2],
}

impl Position {
    /// First file line of this position (for messages).
    pub fn first_line(&self) -> u64 {
        self.spheres
            .iter()
            .filter_map(|s| s.lines.first().copied())
            .min()
            .unwrap_or(0)
    }
}

/// A whole measurement file, validated and grouped by position.
#[derive(Debug, Clone)]
pub struct Measurement {
    /// The file read, as messages name it.
    pub path: PathBuf,
    /// The rotary axis measured (one per file).
    pub axis: RotaryAxis,
    /// True when the file has a `point` column: rows are touch points, not centres.
    pub touch_points: bool,
    /// Positions sorted by direction, repeat, angle.
    pub positions: Vec<Position>,
}

/// Grouping key of a position: direction, repeat and the angle in micro-degrees.
type Key = (Direction, u32, i64);

fn angle_key(angle_deg: f64) -> i64 {
    (angle_deg * 1e6).round() as i64
}

/// Read and validate a measurement file (see `docs/rotary.md` for the format).
pub fn read_measurement(path: &Path) -> Result<Measurement> {
    let table = CsvTable::read(path)?;
    parse_measurement(table)
}

/// Validate an already read CSV table as a measurement file: columns → rows (each checked
/// and grouped by position) → both spheres at every position.
pub fn parse_measurement(table: CsvTable) -> Result<Measurement> {
    let cols = Columns::find(&table)?;
    if table.rows.is_empty() {
        return Err(Error::input(
            Location::file(&table.path),
            "the file has a header but no measurements",
            "add one row per sphere centre (or touch point) and position",
        ));
    }
    let mut grouping = Grouping::default();
    for row in &table.rows {
        let r = read_row(&table, &cols, row, &mut grouping.axis)?;
        grouping.add(&table, row, &cols, r)?;
    }
    let Some((axis, _)) = grouping.axis else {
        return Err(Error::Internal("rows without an axis".into()));
    };
    check_both_spheres(&table.path, &grouping.positions)?;
    Ok(Measurement {
        path: table.path.clone(),
        axis,
        touch_points: cols.point.is_some(),
        positions: grouping.positions.into_values().collect(),
    })
}

/// Column indices of a measurement file.
struct Columns {
    axis: usize,
    direction: usize,
    repeat: usize,
    angle: usize,
    sphere: usize,
    xyz: [usize; 3],
    point: Option<usize>,
}

impl Columns {
    /// Find the columns; an unknown or missing one is an error.
    fn find(table: &CsvTable) -> Result<Columns> {
        table.reject_unknown(&COLUMNS)?;
        Ok(Columns {
            axis: table.require("axis")?,
            direction: table.require("direction")?,
            repeat: table.require("repeat")?,
            angle: table.require("angle_deg")?,
            sphere: table.require("sphere")?,
            xyz: [
                table.require("x_mm")?,
                table.require("y_mm")?,
                table.require("z_mm")?,
            ],
            point: table.column("point"),
        })
    }
}

/// One validated row: a sphere centre or a touch point.
struct Row {
    direction: Direction,
    repeat: u32,
    angle_deg: f64,
    /// 0 for sphere 1, 1 for sphere 2.
    sphere: usize,
    point_mm: [f64; 3],
    /// The touch point's id; empty for a centre.
    point_id: String,
}

/// Read and check one row, cell by cell in file order; `axis` holds the file's axis and the
/// line that set it, and a row naming another axis is an error.
fn read_row(
    table: &CsvTable,
    cols: &Columns,
    row: &CsvRow,
    axis: &mut Option<(RotaryAxis, u64)>,
) -> Result<Row> {
    let row_axis = cell(table, row, cols.axis, RotaryAxis::parse, AXIS)?;
    match *axis {
        None => *axis = Some((row_axis, row.line)),
        Some((first, first_line)) if first != row_axis => {
            return Err(table.error_at(
                row,
                Some(cols.axis),
                format!("axis {row_axis}, but line {first_line} says axis {first}"),
                "measure one rotary axis per file; split the file by axis",
            ));
        }
        Some(_) => {}
    }
    let direction = cell(
        table,
        row,
        cols.direction,
        Direction::parse_symbol,
        DIRECTION,
    )?;
    let repeat = cell(table, row, cols.repeat, |t| t.parse::<u32>().ok(), REPEAT)?;
    let angle_deg = read_angle(table, cols, row)?;
    let sphere = read_sphere(table, cols, row)?;
    let [cx, cy, cz] = cols.xyz;
    let point_mm = [
        table.f64(row, cx)?,
        table.f64(row, cy)?,
        table.f64(row, cz)?,
    ];
    let point_id = read_point_id(table, cols, row)?;
    Ok(Row {
        direction,
        repeat,
        angle_deg,
        sphere,
        point_mm,
        point_id,
    })
}

/// The commanded angle of a row, within ten turns (−0 read as 0).
fn read_angle(table: &CsvTable, cols: &Columns, row: &CsvRow) -> Result<f64> {
    let angle_deg = table.f64(row, cols.angle)? + 0.0;
    if angle_deg.abs() > 3600.0 {
        return Err(table.error_at(
            row,
            Some(cols.angle),
            format!("angle {angle_deg}° is more than ten turns"),
            "write the commanded axis position in degrees, e.g. 0 … 360",
        ));
    }
    Ok(angle_deg)
}

/// The sphere of a row: `1` → 0, `2` → 1.
fn read_sphere(table: &CsvTable, cols: &Columns, row: &CsvRow) -> Result<usize> {
    let index = |text: &str| match text {
        "1" => Some(0),
        "2" => Some(1),
        _ => None,
    };
    cell(table, row, cols.sphere, index, SPHERE)
}

/// What a cell must be and how to write it, for the message of a cell that is not.
type Expected = (&'static str, &'static str);
const AXIS: Expected = (
    "a rotary axis",
    "write A (about X), B (about Y) or C (about Z)",
);
const DIRECTION: Expected = (
    "a direction",
    "write + (approached with increasing angle) or - (decreasing)",
);
const REPEAT: Expected = (
    "a repeat number",
    "write a whole number 0, 1, 2 … counting the runs",
);
const SPHERE: Expected = (
    "a sphere number",
    "write 1 for the first sphere of the bar, 2 for the second (vector a runs from 1 to 2)",
);

/// The cell of `row` in column `col` read by `parse`; a cell it refuses is an error at the
/// cell, "'TEXT' is not …" with the hint of `expected`.
fn cell<T>(
    table: &CsvTable,
    row: &CsvRow,
    col: usize,
    parse: impl FnOnce(&str) -> Option<T>,
    expected: Expected,
) -> Result<T> {
    let text = table.text(row, col);
    let (what, hint) = expected;
    parse(text)
        .ok_or_else(|| table.error_at(row, Some(col), format!("'{text}' is not {what}"), hint))
}

/// The touch-point id of a row (must not be empty); empty when the file has no `point` column.
fn read_point_id(table: &CsvTable, cols: &Columns, row: &CsvRow) -> Result<String> {
    let Some(c) = cols.point else {
        return Ok(String::new());
    };
    let id = table.text(row, c);
    if id.is_empty() {
        return Err(table.error_at(
            row,
            Some(c),
            "empty touch-point id",
            "number the touch points of each sphere and position 1, 2, 3 …",
        ));
    }
    Ok(id.to_string())
}

/// The rows grouped by position as they are read.
#[derive(Default)]
struct Grouping {
    /// The file's axis and the line that first named it.
    axis: Option<(RotaryAxis, u64)>,
    positions: BTreeMap<Key, Position>,
    /// (key, sphere, point id) → line, to catch repeated points or centres.
    seen: BTreeMap<(Key, usize, String), u64>,
}

impl Grouping {
    /// Add a row to its position; a centre or touch point given twice is an error.
    fn add(&mut self, table: &CsvTable, row: &CsvRow, cols: &Columns, r: Row) -> Result<()> {
        let key = (r.direction, r.repeat, angle_key(r.angle_deg));
        if let Some(first) = self
            .seen
            .insert((key, r.sphere, r.point_id.clone()), row.line)
        {
            let what = if cols.point.is_some() {
                format!("touch point '{}'", r.point_id)
            } else {
                "centre".to_string()
            };
            return Err(table.error_at(
                row,
                None,
                format!(
                    "{what} of sphere {} at {}° ({}) repeat {} is given twice (also on line {first})",
                    r.sphere + 1,
                    r.angle_deg,
                    r.direction,
                    r.repeat
                ),
                "keep one row per sphere, position and repeat (or number the repeats apart)",
            ));
        }
        let position = self.positions.entry(key).or_insert_with(|| Position {
            direction: r.direction,
            repeat: r.repeat,
            angle_deg: r.angle_deg,
            spheres: [SphereData::default(), SphereData::default()],
        });
        position.spheres[r.sphere].lines.push(row.line);
        position.spheres[r.sphere].points_mm.push(r.point_mm);
        Ok(())
    }
}

/// Every position must have both spheres: the angle comes from the vector between them.
fn check_both_spheres(path: &Path, positions: &BTreeMap<Key, Position>) -> Result<()> {
    for p in positions.values() {
        for (k, s) in p.spheres.iter().enumerate() {
            if s.lines.is_empty() {
                let other = &p.spheres[1 - k];
                return Err(Error::input(
                    Location::line(path, other.lines.first().copied().unwrap_or(0)),
                    format!(
                        "sphere {} is measured at {}° ({}) repeat {} but sphere {} is not",
                        2 - k,
                        p.angle_deg,
                        p.direction,
                        p.repeat,
                        k + 1
                    ),
                    "measure both spheres at every position: the angle comes from the vector between them",
                ));
            }
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(text: &str) -> Result<Measurement> {
        parse_measurement(CsvTable::parse(Path::new("m.csv"), text)?)
    }

    const HEAD: &str = "axis,direction,repeat,angle_deg,sphere,x_mm,y_mm,z_mm\n";

    #[test]
    fn groups_centres_by_position() {
        let m = parse(&format!(
            "{HEAD}C,+,0,0,1,0,0,0\nC,+,0,0,2,200,0,0\nC,+,0,90,2,0,200,0\nC,+,0,90,1,0,0,0\n"
        ))
        .unwrap();
        assert_eq!(m.axis, RotaryAxis::C);
        assert!(!m.touch_points);
        assert_eq!(m.positions.len(), 2);
        assert_eq!(m.positions[1].angle_deg, 90.0);
        assert_eq!(m.positions[1].spheres[1].points_mm[0], [0.0, 200.0, 0.0]);
        assert_eq!(m.positions[1].spheres[0].lines, vec![5]);
    }

    fn err(text: &str) -> String {
        parse(&format!("{HEAD}{text}")).unwrap_err().to_string()
    }

    #[test]
    fn every_bad_row_names_file_line_and_column() {
        let e = err("D,+,0,0,1,0,0,0\n");
        assert!(
            e.contains("m.csv:2, column axis") && e.contains("'D'"),
            "{e}"
        );
        let e = err("C,+,0,0,1,0,0,0\nA,+,0,0,2,0,0,0\n");
        assert!(
            e.contains("m.csv:3, column axis") && e.contains("line 2"),
            "{e}"
        );
        let e = err("C,up,0,0,1,0,0,0\n");
        assert!(e.contains("m.csv:2, column direction"), "{e}");
        let e = err("C,+,-1,0,1,0,0,0\n");
        assert!(e.contains("m.csv:2, column repeat"), "{e}");
        let e = err("C,+,0,x,1,0,0,0\n");
        assert!(e.contains("m.csv:2, column angle_deg"), "{e}");
        let e = err("C,+,0,0,3,0,0,0\n");
        assert!(e.contains("m.csv:2, column sphere"), "{e}");
        let e = err("C,+,0,0,1,0,nan,0\n");
        assert!(e.contains("m.csv:2, column y_mm"), "{e}");
        let e = err("C,+,0,0,1,0,0,0\nC,+,0,0,1,1,0,0\n");
        assert!(e.contains("m.csv:3") && e.contains("also on line 2"), "{e}");
        let e = err("C,+,0,0,1,0,0,0\nC,+,0,90,2,1,0,0\nC,+,0,90,1,1,0,0\n");
        assert!(
            e.contains("m.csv:2") && e.contains("sphere 2 is not"),
            "{e}"
        );
        let e = parse("axis,direction,repeat,angle_deg,sphere,x_mm,y_mm,z_um\n")
            .unwrap_err()
            .to_string();
        assert!(e.contains("unknown column 'z_um'"), "{e}");
        let e = parse(HEAD).unwrap_err().to_string();
        assert!(e.contains("no measurements"), "{e}");
        let e = parse(&format!(
            "{}C,+,0,0,1,0,0,0,\n",
            HEAD.trim_end().to_string() + ",point\n"
        ))
        .unwrap_err()
        .to_string();
        assert!(e.contains("m.csv:2, column point"), "{e}");
    }
}
