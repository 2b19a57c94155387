//! Column mappings of instrument exports, shared by every reader that takes `--columns`: `FIELD=COLUMN[unit],…` parsed against the reader's own field table, columns found by header name or 1-based number, units converted.
//!
//! `COLUMN` is a header name or a 1-based column number, with an optional unit in brackets at
//! the end: `z=Z[um]`, `target=2`, `pressure=Baro [hPa]`. When the text before the brackets is
//! not a column, the whole text is the header (a header `Error [mm]` written as it stands also
//! declares mm). Which fields exist, their units and which are required is the reader's
//! business ([`FieldTable`]); this module only parses, resolves and converts.

use crate::error::{Error, Location, Result};
use crate::io::CsvTable;

/// A value in a column's unit → the reader's unit: `v * scale + offset`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Conversion {
    /// Reader's units per column unit (1000 for a column in mm read as µm).
    pub scale: f64,
    /// Added after scaling, in the reader's unit (non-zero only for units with another zero,
    /// such as K or °F read as °C).
    pub offset: f64,
}

impl Conversion {
    /// No conversion.
    pub const IDENTITY: Conversion = Conversion {
        scale: 1.0,
        offset: 0.0,
    };

    /// A value in the column's unit converted to the reader's unit.
    pub fn apply(self, value: f64) -> f64 {
        value * self.scale + self.offset
    }
}

/// The units a field accepts: `(name, scale, offset)` into the reader's unit.
pub type Units = &'static [(&'static str, f64, f64)];

/// A reader's fields: their keys, their units, and the usage line shown with a bad mapping.
#[derive(Debug, Clone, Copy)]
pub struct FieldTable<F: 'static> {
    /// `(key, field)` in the order messages list them.
    pub fields: &'static [(&'static str, F)],
    /// The units each field accepts in brackets (empty for a field without a unit).
    pub units: fn(F) -> Units,
    /// The hint of every error in the mapping text (how to write the mapping for this reader),
    /// formed when needed so that it names the setting as the front end words it.
    pub usage: fn() -> String,
    /// The setting the user wrote the mapping with, for "fix …" hints, as the front end words
    /// it.
    pub flag: fn() -> String,
}

impl<F: Copy + PartialEq> FieldTable<F> {
    /// The key of a field, as the user writes it.
    pub fn key(&self, field: F) -> &'static str {
        self.fields
            .iter()
            .find(|f| f.1 == field)
            .map_or("", |f| f.0)
    }

    /// An error in the mapping text.
    pub fn spec_error(&self, message: String) -> Error {
        Error::usage(message, (self.usage)())
    }
}

/// Where a field's column is, as given.
#[derive(Debug, Clone, PartialEq)]
pub enum ColumnRef {
    /// A header name: the whole text after `=`, brackets included.
    Name(String),
    /// A 1-based column number.
    Index(usize),
}

/// One `FIELD=COLUMN[unit]` of a mapping.
#[derive(Debug, Clone, PartialEq)]
pub struct Entry<F> {
    /// The reader's field the column feeds.
    pub field: F,
    /// The column as written: header name or 1-based number.
    pub column: ColumnRef,
    /// The text after `=`, for messages.
    pub text: String,
    /// A unit in brackets at the end of the text, if it names a unit of the field.
    pub unit: Option<(String, Conversion)>,
}

/// `text` split into (column, unit) when it ends with `[unit]`.
pub fn split_unit(text: &str) -> Option<(&str, &str)> {
    let body = text.strip_suffix(']')?;
    let open = body.rfind('[')?;
    Some((body[..open].trim(), body[open + 1..].trim()))
}

/// Parse `FIELD=COLUMN[unit],…` against `table`: unknown fields, a field mapped twice, an empty
/// column and column 0 are errors. Which fields are required is the caller's check.
pub fn parse<F: Copy + PartialEq>(spec: &str, table: &FieldTable<F>) -> Result<Vec<Entry<F>>> {
    let mut entries: Vec<Entry<F>> = Vec::new();
    for part in spec.split(',').map(str::trim).filter(|p| !p.is_empty()) {
        let (key, value) = part
            .split_once('=')
            .ok_or_else(|| table.spec_error(format!("'{part}' is not FIELD=COLUMN")))?;
        let key = key.trim().to_ascii_lowercase();
        let &(_, field) = table.fields.iter().find(|f| f.0 == key).ok_or_else(|| {
            let names: Vec<&str> = table.fields.iter().map(|f| f.0).collect();
            table.spec_error(format!(
                "'{key}' is not a field (fields: {})",
                names.join(", ")
            ))
        })?;
        if entries.iter().any(|e| e.field == field) {
            return Err(table.spec_error(format!("'{key}' is mapped twice")));
        }
        let value = value.trim();
        if value.is_empty() {
            return Err(table.spec_error(format!("'{key}=' names no column")));
        }
        let unit = match split_unit(value) {
            Some((_, u)) => (table.units)(field)
                .iter()
                .find(|(name, ..)| *name == u)
                .map(|&(name, scale, offset)| (name.to_string(), Conversion { scale, offset })),
            None => None,
        };
        let column = match value.parse::<usize>() {
            Ok(0) => {
                return Err(table.spec_error(format!("'{key}=0': columns are numbered from 1")))
            }
            Ok(i) => ColumnRef::Index(i),
            Err(_) => ColumnRef::Name(value.to_string()),
        };
        entries.push(Entry {
            field,
            column,
            text: value.to_string(),
            unit,
        });
    }
    Ok(entries)
}

/// The column of `e` among `headers` and its conversion, or `None`: a number is a 1-based
/// position; `Name[unit]` with a column `Name` declares the unit; else the whole text is a
/// header.
pub fn find<F>(headers: &[String], e: &Entry<F>) -> Option<(usize, Conversion)> {
    let by_name = |text: &str| headers.iter().position(|h| h == text);
    let by_text = |text: &str| -> Option<usize> {
        match text.parse::<usize>() {
            Ok(i) if i >= 1 && i <= headers.len() => Some(i - 1),
            Ok(_) => None,
            Err(_) => by_name(text),
        }
    };
    let before_unit = split_unit(&e.text).map(|(c, _)| c);
    match (&e.unit, before_unit.and_then(by_text)) {
        (Some((_, conv)), Some(i)) => Some((i, *conv)),
        _ => match &e.column {
            ColumnRef::Index(i) => by_text(&i.to_string()).map(|c| (c, Conversion::IDENTITY)),
            ColumnRef::Name(n) => {
                by_name(n).map(|c| (c, e.unit.as_ref().map_or(Conversion::IDENTITY, |u| u.1)))
            }
        },
    }
}

/// Resolve an entry to (column index, conversion) in `table`; a missing column names the file,
/// the header line and the mapping; an unknown unit lists the field's units.
pub fn resolve<F: Copy + PartialEq>(
    table: &CsvTable,
    e: &Entry<F>,
    fields: &FieldTable<F>,
) -> Result<(usize, Conversion)> {
    let found = find(&table.headers, e);
    if let (None, Some((_, u))) = (&found, split_unit(&e.text)) {
        if e.unit.is_none() && table.column(&e.text).is_none() {
            let known: Vec<&str> = (fields.units)(e.field).iter().map(|u| u.0).collect();
            return Err(fields.spec_error(format!(
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
            Location::cell(&table.path, table.header_line, column),
            format!(
                "the mapped column '{}' for '{}' is not in the file (header has {} columns: {})",
                e.text,
                fields.key(e.field),
                table.headers.len(),
                table.headers.join(",")
            ),
            format!(
                "fix {}: name a header exactly as written, or give its 1-based number",
                (fields.flag)()
            ),
        )
    })
}
