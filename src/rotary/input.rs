//! Reading rotary-axis measurement files: sphere centres or raw touch points per sphere, position and repeat.

use crate::error::{Error, Location, Result};
use crate::io::CsvTable;
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
    A,
    B,
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

pub use crate::direction::Direction;

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
    pub direction: Direction,
    pub repeat: u32,
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
    pub path: PathBuf,
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

/// Validate an already read CSV table as a measurement file.
pub fn parse_measurement(table: CsvTable) -> Result<Measurement> {
    table.reject_unknown(&COLUMNS)?;
    let c_axis = table.require("axis")?;
    let c_dir = table.require("direction")?;
    let c_rep = table.require("repeat")?;
    let c_ang = table.require("angle_deg")?;
    let c_sph = table.require("sphere")?;
    let c_x = table.require("x_mm")?;
    let c_y = table.require("y_mm")?;
    let c_z = table.require("z_mm")?;
    let c_point = table.column("point");
    if table.rows.is_empty() {
        return Err(Error::input(
            Location::file(&table.path),
            "the file has a header but no measurements",
            "add one row per sphere centre (or touch point) and position",
        ));
    }

    let mut axis: Option<(RotaryAxis, u64)> = None;
    let mut groups: BTreeMap<Key, Position> = BTreeMap::new();
    // (key, sphere, point id) → line, to catch repeated points or centres.
    let mut seen: BTreeMap<(Key, usize, String), u64> = BTreeMap::new();

    for row in &table.rows {
        let text = table.text(row, c_axis);
        let row_axis = RotaryAxis::parse(text).ok_or_else(|| {
            table.error_at(
                row,
                Some(c_axis),
                format!("'{text}' is not a rotary axis"),
                "write A (about X), B (about Y) or C (about Z)",
            )
        })?;
        match axis {
            None => axis = Some((row_axis, row.line)),
            Some((first, first_line)) if first != row_axis => {
                return Err(table.error_at(
                    row,
                    Some(c_axis),
                    format!("axis {row_axis}, but line {first_line} says axis {first}"),
                    "measure one rotary axis per file; split the file by axis",
                ));
            }
            Some(_) => {}
        }
        let text = table.text(row, c_dir);
        let direction = Direction::parse_symbol(text).ok_or_else(|| {
            table.error_at(
                row,
                Some(c_dir),
                format!("'{text}' is not a direction"),
                "write + (approached with increasing angle) or - (decreasing)",
            )
        })?;
        let text = table.text(row, c_rep);
        let repeat: u32 = text.parse().map_err(|_| {
            table.error_at(
                row,
                Some(c_rep),
                format!("'{text}' is not a repeat number"),
                "write a whole number 0, 1, 2 … counting the runs",
            )
        })?;
        let angle_deg = table.f64(row, c_ang)? + 0.0;
        if angle_deg.abs() > 3600.0 {
            return Err(table.error_at(
                row,
                Some(c_ang),
                format!("angle {angle_deg}° is more than ten turns"),
                "write the commanded axis position in degrees, e.g. 0 … 360",
            ));
        }
        let text = table.text(row, c_sph);
        let sphere = match text {
            "1" => 0usize,
            "2" => 1usize,
            _ => {
                return Err(table.error_at(
                    row,
                    Some(c_sph),
                    format!("'{text}' is not a sphere number"),
                    "write 1 for the first sphere of the bar, 2 for the second (vector a runs from 1 to 2)",
                ))
            }
        };
        let point = [
            table.f64(row, c_x)?,
            table.f64(row, c_y)?,
            table.f64(row, c_z)?,
        ];
        let point_id = match c_point {
            Some(c) => {
                let id = table.text(row, c);
                if id.is_empty() {
                    return Err(table.error_at(
                        row,
                        Some(c),
                        "empty touch-point id",
                        "number the touch points of each sphere and position 1, 2, 3 …",
                    ));
                }
                id.to_string()
            }
            None => String::new(),
        };
        let key = (direction, repeat, angle_key(angle_deg));
        if let Some(first) = seen.insert((key, sphere, point_id.clone()), row.line) {
            let what = if c_point.is_some() {
                format!("touch point '{point_id}'")
            } else {
                "centre".to_string()
            };
            return Err(table.error_at(
                row,
                None,
                format!(
                    "{what} of sphere {} at {angle_deg}° ({direction}) repeat {repeat} is given twice (also on line {first})",
                    sphere + 1
                ),
                "keep one row per sphere, position and repeat (or number the repeats apart)",
            ));
        }
        let position = groups.entry(key).or_insert_with(|| Position {
            direction,
            repeat,
            angle_deg,
            spheres: [SphereData::default(), SphereData::default()],
        });
        position.spheres[sphere].lines.push(row.line);
        position.spheres[sphere].points_mm.push(point);
    }

    let Some((axis, _)) = axis else {
        return Err(Error::Internal("rows without an axis".into()));
    };
    for p in groups.values() {
        for (k, s) in p.spheres.iter().enumerate() {
            if s.lines.is_empty() {
                let other = &p.spheres[1 - k];
                return Err(Error::input(
                    Location::line(&table.path, other.lines.first().copied().unwrap_or(0)),
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
    Ok(Measurement {
        path: table.path.clone(),
        axis,
        touch_points: c_point.is_some(),
        positions: groups.into_values().collect(),
    })
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
