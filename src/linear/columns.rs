//! Column mapping for instrument exports: `target=Position,deviation=Error [mm],direction=Dir` maps an export's own columns (by name or 1-based index, with units) onto a run file's.
//!
//! A mapping is a comma-separated list of `FIELD=COLUMN` with an optional unit in brackets at
//! the end of `COLUMN`: `deviation=Error[mm]`, `target=2`, `pressure=Baro [hPa]`. `COLUMN` is a
//! header name or a 1-based column number; when the text before the brackets is not a column,
//! the whole text is the header (so a header `Error [mm]` written as it stands also declares
//! mm). Fields: `target` (mm), `actual` or `deviation` (µm) — exactly one — `direction`,
//! optional `run` (else each pass is numbered in file order), `air_temp`, `pressure`,
//! `humidity`, `material_temp`, `time`. Other columns of the export are ignored.

use crate::direction::Direction;
use crate::error::{Error, Location, Result};
use crate::io::{CsvRow, CsvTable};

/// One mapped field.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Field {
    Run,
    Direction,
    Target,
    Actual,
    Deviation,
    AirTemp,
    Pressure,
    Humidity,
    MaterialTemp,
    Time,
}

const FIELDS: &[(&str, Field, &str)] = &[
    ("run", Field::Run, "run"),
    ("direction", Field::Direction, "direction"),
    ("target", Field::Target, "target_mm"),
    ("actual", Field::Actual, "actual_mm"),
    ("deviation", Field::Deviation, "deviation_um"),
    ("air_temp", Field::AirTemp, "air_temp_c"),
    ("pressure", Field::Pressure, "pressure_kpa"),
    ("humidity", Field::Humidity, "humidity_pct"),
    ("material_temp", Field::MaterialTemp, "material_temp_c"),
    ("time", Field::Time, "time_s"),
];

/// A value in `unit` → the run file's unit: `v * scale + offset`.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Conversion {
    scale: f64,
    offset: f64,
}

fn units(field: Field) -> &'static [(&'static str, f64, f64)] {
    match field {
        Field::Target | Field::Actual => &[
            ("mm", 1.0, 0.0),
            ("um", 1e-3, 0.0),
            ("µm", 1e-3, 0.0),
            ("m", 1e3, 0.0),
            ("in", 25.4, 0.0),
        ],
        Field::Deviation => &[
            ("um", 1.0, 0.0),
            ("µm", 1.0, 0.0),
            ("mm", 1e3, 0.0),
            ("nm", 1e-3, 0.0),
            ("in", 25_400.0, 0.0),
            ("uin", 0.0254, 0.0),
        ],
        Field::AirTemp | Field::MaterialTemp => &[
            ("C", 1.0, 0.0),
            ("°C", 1.0, 0.0),
            ("degC", 1.0, 0.0),
            ("K", 1.0, -273.15),
            ("F", 5.0 / 9.0, -32.0 * 5.0 / 9.0),
        ],
        Field::Pressure => &[
            ("kPa", 1.0, 0.0),
            ("hPa", 0.1, 0.0),
            ("mbar", 0.1, 0.0),
            ("Pa", 1e-3, 0.0),
            ("mmHg", 0.133_322_387_415, 0.0),
        ],
        Field::Humidity => &[("%", 1.0, 0.0), ("pct", 1.0, 0.0)],
        Field::Time => &[
            ("s", 1.0, 0.0),
            ("ms", 1e-3, 0.0),
            ("min", 60.0, 0.0),
            ("h", 3600.0, 0.0),
        ],
        Field::Run | Field::Direction => &[],
    }
}

/// Where a field's column is, as given.
#[derive(Debug, Clone, PartialEq)]
enum ColumnRef {
    Name(String),
    Index(usize),
}

/// One `FIELD=COLUMN[unit]` of a mapping.
#[derive(Debug, Clone, PartialEq)]
struct Entry {
    field: Field,
    canonical: &'static str,
    column: ColumnRef,
    /// The text after `=`, for messages.
    text: String,
    /// A unit in brackets at the end of the text, if it names a unit of the field.
    unit: Option<(String, Conversion)>,
}

/// A parsed `--columns` mapping.
#[derive(Debug, Clone, PartialEq)]
pub struct ColumnMap {
    entries: Vec<Entry>,
}

fn spec_error(message: String) -> Error {
    Error::usage(
        message,
        "write --columns target=COLUMN,deviation=COLUMN[um|mm|nm],direction=COLUMN (names or 1-based numbers; see docs/linear.md)",
    )
}

/// `text` split into (column, unit) when it ends with `[unit]`.
fn split_unit(text: &str) -> Option<(&str, &str)> {
    let body = text.strip_suffix(']')?;
    let open = body.rfind('[')?;
    Some((body[..open].trim(), body[open + 1..].trim()))
}

impl ColumnMap {
    /// Parse `FIELD=COLUMN[unit],…`.
    pub fn parse(spec: &str) -> Result<ColumnMap> {
        let mut entries: Vec<Entry> = Vec::new();
        for part in spec.split(',').map(str::trim).filter(|p| !p.is_empty()) {
            let (key, value) = part
                .split_once('=')
                .ok_or_else(|| spec_error(format!("'{part}' is not FIELD=COLUMN")))?;
            let key = key.trim().to_ascii_lowercase();
            let &(_, field, canonical) = FIELDS.iter().find(|f| f.0 == key).ok_or_else(|| {
                let names: Vec<&str> = FIELDS.iter().map(|f| f.0).collect();
                spec_error(format!(
                    "'{key}' is not a field (fields: {})",
                    names.join(", ")
                ))
            })?;
            if entries.iter().any(|e| e.field == field) {
                return Err(spec_error(format!("'{key}' is mapped twice")));
            }
            let value = value.trim();
            if value.is_empty() {
                return Err(spec_error(format!("'{key}=' names no column")));
            }
            let unit = match split_unit(value) {
                Some((_, u)) => units(field)
                    .iter()
                    .find(|(name, ..)| *name == u)
                    .map(|&(name, scale, offset)| (name.to_string(), Conversion { scale, offset })),
                None => None,
            };
            let column = match value.parse::<usize>() {
                Ok(0) => {
                    return Err(spec_error(format!(
                        "'{key}=0': columns are numbered from 1"
                    )))
                }
                Ok(i) => ColumnRef::Index(i),
                Err(_) => ColumnRef::Name(value.to_string()),
            };
            entries.push(Entry {
                field,
                canonical,
                column,
                text: value.to_string(),
                unit,
            });
        }
        let has = |f: Field| entries.iter().any(|e| e.field == f);
        for (f, name) in [(Field::Target, "target"), (Field::Direction, "direction")] {
            if !has(f) {
                return Err(spec_error(format!("the mapping has no '{name}'")));
            }
        }
        if has(Field::Actual) == has(Field::Deviation) {
            return Err(spec_error(
                "the mapping needs exactly one of 'actual' (position) or 'deviation' (actual - target)"
                    .into(),
            ));
        }
        Ok(ColumnMap { entries })
    }
}

/// Resolve an entry to (column index, conversion) in `table`; a missing column names the file,
/// the header line and the mapping.
fn resolve(table: &CsvTable, e: &Entry) -> Result<(usize, Conversion)> {
    let plain = Conversion {
        scale: 1.0,
        offset: 0.0,
    };
    let by_text = |text: &str| -> Option<usize> {
        match text.parse::<usize>() {
            Ok(i) if i >= 1 && i <= table.headers.len() => Some(i - 1),
            Ok(_) => None,
            Err(_) => table.column(text),
        }
    };
    // `Error[mm]` with a column `Error`: the unit is declared; else the whole text is a header.
    let before_unit = split_unit(&e.text).map(|(c, _)| c);
    let found = match (&e.unit, before_unit.and_then(by_text)) {
        (Some((_, conv)), Some(i)) => Some((i, *conv)),
        _ => match &e.column {
            ColumnRef::Index(i) => by_text(&i.to_string()).map(|c| (c, plain)),
            ColumnRef::Name(n) => table
                .column(n)
                .map(|c| (c, e.unit.as_ref().map_or(plain, |u| u.1))),
        },
    };
    if let (None, Some((_, u))) = (&found, split_unit(&e.text)) {
        if e.unit.is_none() && table.column(&e.text).is_none() {
            let known: Vec<&str> = units(e.field).iter().map(|u| u.0).collect();
            return Err(spec_error(format!(
                "'{u}' in '{}' is not a unit errmap knows for this field (known: {})",
                e.text,
                if known.is_empty() {
                    "none, the field has no unit".to_string()
                } else {
                    known.join(", ")
                }
            )));
        }
    }
    found.ok_or_else(|| {
        let column = match &e.column {
            ColumnRef::Index(i) => format!("#{i}"),
            ColumnRef::Name(n) => n.clone(),
        };
        Error::input(
            Location::cell(&table.path, 1, column),
            format!(
                "the mapped column '{}' for '{}' is not in the file (header has {} columns: {})",
                e.text,
                FIELDS.iter().find(|f| f.1 == e.field).map_or("", |f| f.0),
                table.headers.len(),
                table.headers.join(",")
            ),
            "fix --columns: name a header exactly as written, or give its 1-based number",
        )
    })
}

/// The export mapped onto a run file's columns and units; numbers are converted here, so every
/// bad value is reported at the export's own line and column.
pub(super) fn map_table(table: &CsvTable, map: &ColumnMap) -> Result<CsvTable> {
    let resolved: Vec<(&Entry, usize, Conversion)> = map
        .entries
        .iter()
        .map(|e| resolve(table, e).map(|(c, conv)| (e, c, conv)))
        .collect::<Result<_>>()?;
    let mut headers: Vec<String> = resolved.iter().map(|r| r.0.canonical.to_string()).collect();
    let infer_runs = !map.entries.iter().any(|e| e.field == Field::Run);
    if infer_runs {
        headers.push("run".into());
    }
    let mut rows = Vec::with_capacity(table.rows.len());
    for row in &table.rows {
        let mut fields = Vec::with_capacity(headers.len());
        for &(e, c, conv) in &resolved {
            fields.push(cell(table, row, e.field, c, conv)?);
        }
        rows.push((row.line, fields));
    }
    if infer_runs {
        number_passes(&resolved, &mut rows)?;
    }
    let rows = rows
        .into_iter()
        .map(|(line, fields)| CsvRow {
            line,
            fields: csv::StringRecord::from(fields),
        })
        .collect();
    CsvTable::from_records(&table.path, headers, rows)
}

fn cell(
    table: &CsvTable,
    row: &CsvRow,
    field: Field,
    c: usize,
    conv: Conversion,
) -> Result<String> {
    let text = table.text(row, c);
    Ok(match field {
        Field::Run => text.to_string(),
        Field::Direction => match Direction::parse(text) {
            Some(d) => d.symbol().to_string(),
            None => return Err(table.error_at(
                row,
                Some(c),
                format!("'{text}' is not a direction"),
                "the direction column holds +/- (or forward/reverse, fwd/bwd, up/down, pos/neg)",
            )),
        },
        _ if text.is_empty() => String::new(),
        _ => {
            let v = table.f64(row, c)?;
            format!("{}", v * conv.scale + conv.offset)
        }
    })
}

/// Number the passes in file order: a pass ends where the direction changes or a target comes
/// again; run k is the k-th pass of its direction.
fn number_passes(
    resolved: &[(&Entry, usize, Conversion)],
    rows: &mut [(u64, Vec<String>)],
) -> Result<()> {
    let pos = |f: Field| resolved.iter().position(|r| r.0.field == f);
    let (Some(d), Some(t)) = (pos(Field::Direction), pos(Field::Target)) else {
        return Err(Error::Internal(
            "mapping without direction or target".into(),
        ));
    };
    let mut runs = [0u32; 2];
    let mut current: Option<(String, Vec<String>)> = None;
    for (_, fields) in rows.iter_mut() {
        let (dir, target) = (fields[d].clone(), fields[t].clone());
        let new_pass = match &current {
            Some((cd, seen)) => *cd != dir || seen.contains(&target),
            None => true,
        };
        if new_pass {
            runs[usize::from(dir == "-")] += 1;
            current = Some((dir.clone(), Vec::new()));
        }
        if let Some((_, seen)) = current.as_mut() {
            seen.push(target);
        }
        fields.push(runs[usize::from(dir == "-")].to_string());
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_mapping_parses_names_indices_and_units() {
        let m = ColumnMap::parse("target=Position,deviation=Error[mm],direction=3").unwrap();
        assert_eq!(m.entries.len(), 3);
        assert_eq!(m.entries[1].unit.as_ref().unwrap().1.scale, 1e3);
        assert_eq!(m.entries[2].column, ColumnRef::Index(3));
        for bad in [
            "target=P,direction=D",
            "target=P,deviation=E,actual=A,direction=D",
            "target=P,deviation=E,direction=D,speed=S",
            "target=0,deviation=E,direction=D",
            "target=P,target=Q,deviation=E,direction=D",
        ] {
            let err = ColumnMap::parse(bad).expect_err(bad);
            assert_eq!(err.kind(), "input", "{bad}: {err}");
            assert!(
                err.to_string().contains("--columns target=COLUMN"),
                "{bad}: {err}"
            );
        }
    }
}
