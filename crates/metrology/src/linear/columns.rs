//! Column mapping for instrument exports: `target=Position,deviation=Error [mm],direction=Dir` maps an export's own columns (by name or 1-based index, with units) onto a run file's.
//!
//! A mapping is a comma-separated list of `FIELD=COLUMN` with an optional unit in brackets at
//! the end of `COLUMN`: `deviation=Error[mm]`, `target=2`, `pressure=Baro [hPa]`. `COLUMN` is a
//! header name or a 1-based column number; when the text before the brackets is not a column,
//! the whole text is the header (so a header `Error [mm]` written as it stands also declares
//! mm). Fields: `target` (mm), `actual` or `deviation` (µm) — exactly one — `direction`,
//! optional `run` (else each pass is numbered in file order), `air_temp`, `pressure`,
//! `humidity`, `material_temp`, `time`. Other columns of the export are ignored.

use crate::Setting;
use errmap_core::direction::Direction;
use errmap_core::error::{Error, Result};
use errmap_core::io::columns::{self as shared, Conversion, Entry, FieldTable, Units};
use errmap_core::io::{CsvRow, CsvTable};
use errmap_core::setting::words;

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

const FIELDS: &[(&str, Field)] = &[
    ("run", Field::Run),
    ("direction", Field::Direction),
    ("target", Field::Target),
    ("actual", Field::Actual),
    ("deviation", Field::Deviation),
    ("air_temp", Field::AirTemp),
    ("pressure", Field::Pressure),
    ("humidity", Field::Humidity),
    ("material_temp", Field::MaterialTemp),
    ("time", Field::Time),
];

/// The run file's column of a field.
fn canonical(field: Field) -> &'static str {
    match field {
        Field::Run => "run",
        Field::Direction => "direction",
        Field::Target => "target_mm",
        Field::Actual => "actual_mm",
        Field::Deviation => "deviation_um",
        Field::AirTemp => "air_temp_c",
        Field::Pressure => "pressure_kpa",
        Field::Humidity => "humidity_pct",
        Field::MaterialTemp => "material_temp_c",
        Field::Time => "time_s",
    }
}

fn units(field: Field) -> Units {
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

const TABLE: FieldTable<Field> = FieldTable {
    fields: FIELDS,
    units,
    usage: || {
        format!(
            "write {} target=COLUMN,deviation=COLUMN[um|mm|nm],direction=COLUMN (names or 1-based numbers; see docs/linear.md)",
            words(Setting::Columns)
        )
    },
    flag: || words(Setting::Columns),
};

/// A parsed `--columns` mapping.
#[derive(Debug, Clone, PartialEq)]
pub struct ColumnMap {
    entries: Vec<Entry<Field>>,
}

impl ColumnMap {
    /// Parse `FIELD=COLUMN[unit],…`.
    pub fn parse(spec: &str) -> Result<ColumnMap> {
        let entries = shared::parse(spec, &TABLE)?;
        let has = |f: Field| entries.iter().any(|e| e.field == f);
        for (f, name) in [(Field::Target, "target"), (Field::Direction, "direction")] {
            if !has(f) {
                return Err(TABLE.spec_error(format!("the mapping has no '{name}'")));
            }
        }
        if has(Field::Actual) == has(Field::Deviation) {
            return Err(TABLE.spec_error(
                "the mapping needs exactly one of 'actual' (position) or 'deviation' (actual - target)"
                    .into(),
            ));
        }
        Ok(ColumnMap { entries })
    }
}

/// The export mapped onto a run file's columns and units; numbers are converted here, so every
/// bad value is reported at the export's own line and column.
pub(super) fn map_table(table: &CsvTable, map: &ColumnMap) -> Result<CsvTable> {
    let resolved: Vec<(&Entry<Field>, usize, Conversion)> = map
        .entries
        .iter()
        .map(|e| shared::resolve(table, e, &TABLE).map(|(c, conv)| (e, c, conv)))
        .collect::<Result<_>>()?;
    let mut headers: Vec<String> = resolved
        .iter()
        .map(|r| canonical(r.0.field).to_string())
        .collect();
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
            format!("{}", conv.apply(v))
        }
    })
}

/// Number the passes in file order: a pass ends where the direction changes or a target comes
/// again; run k is the k-th pass of its direction.
fn number_passes(
    resolved: &[(&Entry<Field>, usize, Conversion)],
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
    use errmap_core::io::columns::ColumnRef;

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
                err.to_string().contains("`columns` target=COLUMN"),
                "{bad}: {err}"
            );
        }
    }
}
