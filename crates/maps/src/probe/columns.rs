//! Column mapping of probe files (`--columns x=X,y=Y,z=Z[um],i=I,j=J,k=K,id=POINT`): the probe fields, their units, and the rule that finds the header of an export.

use crate::Setting;
use errmap_core::error::Result;
use errmap_core::io::columns::{self as shared, Entry, FieldTable, Units};
use errmap_core::setting::words;

/// One mapped probe field.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Field {
    X,
    Y,
    Z,
    Nx,
    Ny,
    Nz,
    I,
    J,
    K,
    Id,
}

const FIELDS: &[(&str, Field)] = &[
    ("x", Field::X),
    ("y", Field::Y),
    ("z", Field::Z),
    ("nx", Field::Nx),
    ("ny", Field::Ny),
    ("nz", Field::Nz),
    ("i", Field::I),
    ("j", Field::J),
    ("k", Field::K),
    ("id", Field::Id),
];

fn units(field: Field) -> Units {
    match field {
        Field::X | Field::Y | Field::Z | Field::Nx | Field::Ny | Field::Nz => &[
            ("mm", 1.0, 0.0),
            ("um", 1e-3, 0.0),
            ("µm", 1e-3, 0.0),
            ("m", 1e3, 0.0),
            ("in", 25.4, 0.0),
        ],
        Field::I | Field::J | Field::K | Field::Id => &[],
    }
}

pub(super) const TABLE: FieldTable<Field> = FieldTable {
    fields: FIELDS,
    units,
    usage: || {
        format!(
            "write {} x=COLUMN,y=COLUMN,z=COLUMN[,nx=…,ny=…,nz=…][,i=…,j=…,k=…][,id=COLUMN] (header names or 1-based numbers, an optional unit such as z=Z[um]; see docs/probe-files.md)",
            words(Setting::Columns)
        )
    },
    flag: || {
        format!(
            "the column mapping ({}, or `columns` in the job)",
            words(Setting::Columns)
        )
    },
};

/// A parsed probe column mapping: x, y, z required; nx, ny, nz all or none; i, j, k all or
/// none; id optional.
#[derive(Debug, Clone, PartialEq)]
pub struct ProbeColumns {
    pub(super) entries: Vec<Entry<Field>>,
}

impl ProbeColumns {
    /// Parse `FIELD=COLUMN[unit],…`.
    pub fn parse(spec: &str) -> Result<ProbeColumns> {
        let entries = shared::parse(spec, &TABLE)?;
        let has = |f: Field| entries.iter().any(|e| e.field == f);
        for (f, name) in [(Field::X, "x"), (Field::Y, "y"), (Field::Z, "z")] {
            if !has(f) {
                return Err(TABLE.spec_error(format!("the mapping has no '{name}'")));
            }
        }
        for (group, names) in [
            ([Field::Nx, Field::Ny, Field::Nz], "nx,ny,nz"),
            ([Field::I, Field::J, Field::K], "i,j,k"),
        ] {
            let n = group.iter().filter(|&&f| has(f)).count();
            if n != 0 && n != 3 {
                return Err(TABLE.spec_error(format!("map all three of {names} or none of them")));
            }
        }
        Ok(ProbeColumns { entries })
    }

    /// The mapped columns as written, for messages.
    pub(super) fn columns_named(&self) -> String {
        let named: Vec<&str> = self.entries.iter().map(|e| e.text.as_str()).collect();
        named.join(", ")
    }

    pub(super) fn entry(&self, field: Field) -> Option<&Entry<Field>> {
        self.entries.iter().find(|e| e.field == field)
    }

    /// The header rule: a line is the header when it names every mapped column (a column
    /// given by number only needs the line to have that many cells).
    pub(super) fn is_header(&self, cells: &[String]) -> bool {
        self.entries
            .iter()
            .all(|e| shared::find(cells, e).is_some())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_probe_mapping_needs_xyz_and_whole_groups() {
        let m = ProbeColumns::parse("x=X,y=Y,z=Z[um],i=I,j=J,k=K,id=1").unwrap();
        assert_eq!(m.entries.len(), 7);
        let z = m.entry(Field::Z).unwrap();
        assert_eq!(z.unit.as_ref().unwrap().1.scale, 1e-3);
        for bad in [
            "x=X,y=Y",
            "x=X,y=Y,z=Z,i=I,j=J",
            "x=X,y=Y,z=Z,nx=A",
            "x=X,y=Y,z=Z,w=W",
            "x=0,y=Y,z=Z",
        ] {
            let err = ProbeColumns::parse(bad).expect_err(bad);
            assert!(
                err.to_string().contains("`columns` x=COLUMN"),
                "{bad}: {err}"
            );
        }
    }
}
