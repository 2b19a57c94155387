//! DMIS output (ISO 22093) as PC-DMIS, Calypso and Modus export it: nominal `F(label)=FEAT/POINT,CART,x,y,z,i,j,k` and actual `FA(label)=FEAT/POINT,CART,…` statements paired by label, units from `UNITS/`, `$` continuation and `$$` comments.
//!
//! Every other statement (DMISMN, MEAS, PTMEAS, OUTPUT, datums, tolerances …) is ignored;
//! features other than points (planes, circles …) are skipped and counted. See
//! `docs/probe-files.md`, "DMIS".

use std::collections::HashMap;
use std::io::BufRead;
use std::path::Path;

use super::point::{point_row, Place, RawPoint, Row};
use super::ProbeSpec;
use errmap_core::error::{Error, Location, Result};

/// One `FEAT/POINT,CART` statement: where it is, its point (mm) and vector as written.
struct Feature {
    label: String,
    line: u64,
    point_mm: [f64; 3],
    vector: [f64; 3],
}

/// Read the point features of a DMIS file: (rows, features of other types skipped).
pub(super) fn read(path: &Path, spec: &ProbeSpec) -> Result<(Vec<Row>, usize)> {
    let mut nominals: Vec<Feature> = Vec::new();
    let mut nominal_of: HashMap<String, usize> = HashMap::new();
    let mut actuals: Vec<Feature> = Vec::new();
    let mut skipped = 0usize;
    let mut mm_per_unit = 1.0;
    for statement in statements(path)? {
        let (line, text) = statement?;
        let upper = text.to_ascii_uppercase();
        if let Some(args) = upper.strip_prefix("UNITS/") {
            mm_per_unit = units(path, line, args)?;
            continue;
        }
        let actual = upper.starts_with("FA(");
        if !(actual || upper.starts_with("F(")) {
            continue;
        }
        let Some((label, definition)) = split_label(&text) else {
            continue; // F(x) used as an argument, not a definition
        };
        let def_upper = definition.to_ascii_uppercase();
        let Some(feature) = def_upper.strip_prefix("FEAT/") else {
            continue;
        };
        let kind = feature.split(',').next().unwrap_or("").trim();
        if kind != "POINT" {
            skipped += 1;
            continue;
        }
        let point = point(
            path,
            line,
            &label,
            &definition["FEAT/".len()..],
            mm_per_unit,
        )?;
        if actual {
            actuals.push(point);
        } else {
            if let Some(&first) = nominal_of.get(&label) {
                return Err(Error::input(
                    Location::line(path, line),
                    format!(
                        "the nominal F({label}) is defined again (first at line {})",
                        nominals[first].line
                    ),
                    "give every point feature its own label",
                ));
            }
            nominal_of.insert(label, nominals.len());
            nominals.push(point);
        }
    }
    let mut measured = vec![false; nominals.len()];
    let mut rows = Vec::with_capacity(actuals.len());
    for a in actuals {
        let Some(&n) = nominal_of.get(&a.label) else {
            return Err(Error::input(
                Location::line(path, a.line),
                format!("the actual FA({}) has no nominal F({})", a.label, a.label),
                "export the nominal F(label)=FEAT/POINT statement with the actual, or remove the actual",
            ));
        };
        measured[n] = true;
        let nominal = &nominals[n];
        check_unit(path, a.line, &a.label, a.vector)?;
        let place = Place {
            row: Location::line(path, a.line),
            normal: Location::line(path, a.line),
            vector: Location::line(path, nominal.line),
            prefix: format!("F({}): ", a.label),
        };
        let raw = RawPoint {
            id: Some(a.label.clone()),
            line: a.line,
            measured_mm: a.point_mm,
            nominal_mm: nominal.point_mm,
            vector: Some(nominal.vector),
        };
        rows.push(point_row(raw, &place, spec)?);
    }
    if let Some(n) = measured.iter().position(|m| !m) {
        let f = &nominals[n];
        return Err(Error::input(
            Location::line(path, f.line),
            format!("the nominal F({}) has no actual FA({})", f.label, f.label),
            "export the measured results (FA statements) with the nominals, or remove the point that was not measured",
        ));
    }
    Ok((rows, skipped))
}

/// The actual's own vector is checked as a vector; the nominal's is the one E is taken along.
fn check_unit(path: &Path, line: u64, label: &str, v: [f64; 3]) -> Result<()> {
    let norm = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
    if norm.is_finite() && (norm - 1.0).abs() <= super::VECTOR_NORM_TOLERANCE {
        return Ok(());
    }
    Err(Error::input(
        Location::line(path, line),
        format!(
            "FA({label}): the vector ({}, {}, {}) has length {norm}, not 1 (within {})",
            v[0],
            v[1],
            v[2],
            super::VECTOR_NORM_TOLERANCE
        ),
        "i, j, k are direction cosines; export the point with a unit vector",
    ))
}

/// `F(label)=rest` or `FA(label)=rest` → (label, rest after `=`), spaces around trimmed.
fn split_label(text: &str) -> Option<(String, &str)> {
    let open = text.find('(')?;
    let close = open + text[open..].find(')')?;
    let label = text[open + 1..close].trim().to_string();
    let rest = text[close + 1..].trim_start().strip_prefix('=')?;
    Some((label, rest.trim()))
}

/// `POINT,CART,x,y,z,i,j,k` (after `FEAT/`) in mm.
fn point(path: &Path, line: u64, label: &str, args: &str, mm_per_unit: f64) -> Result<Feature> {
    let parts: Vec<&str> = args.split(',').map(str::trim).collect();
    let system = parts.get(1).map(|s| s.to_ascii_uppercase());
    if system.as_deref() != Some("CART") {
        return Err(Error::input(
            Location::line(path, line),
            format!(
                "F({label}): FEAT/POINT,{} is not read; only cartesian points (FEAT/POINT,CART,x,y,z,i,j,k) are",
                system.unwrap_or_default()
            ),
            "export the points in cartesian coordinates (CART)",
        ));
    }
    let numbers = &parts[2..];
    if numbers.len() != 6 {
        return Err(Error::input(
            Location::line(path, line),
            format!(
                "F({label}): FEAT/POINT,CART has {} values; it needs 6 (x,y,z,i,j,k)",
                numbers.len()
            ),
            "write FEAT/POINT,CART,x,y,z,i,j,k",
        ));
    }
    let mut v = [0.0; 6];
    for (k, text) in numbers.iter().enumerate() {
        let value: f64 = text.parse().map_err(|_| {
            Error::input(
                Location::line(path, line),
                format!(
                    "F({label}): '{text}' ({}) is not a number",
                    ["x", "y", "z", "i", "j", "k"][k]
                ),
                "write a decimal number such as 12.5",
            )
        })?;
        if !value.is_finite() {
            return Err(Error::input(
                Location::line(path, line),
                format!("F({label}): '{text}' is not a finite number"),
                "NaN and infinity are not measurements",
            ));
        }
        v[k] = value;
    }
    Ok(Feature {
        label: label.to_string(),
        line,
        point_mm: [v[0] * mm_per_unit, v[1] * mm_per_unit, v[2] * mm_per_unit],
        vector: [v[3], v[4], v[5]],
    })
}

/// `UNITS/MM|INCH|…[,ANGDEC|ANGDMS|ANGRAD]`: mm per length unit (angles are not read).
fn units(path: &Path, line: u64, args: &str) -> Result<f64> {
    let length = args.split(',').next().unwrap_or("").trim();
    match length {
        "MM" => Ok(1.0),
        "CM" => Ok(10.0),
        "METER" => Ok(1000.0),
        "INCH" => Ok(25.4),
        "FEET" => Ok(304.8),
        other => Err(Error::input(
            Location::line(path, line),
            format!("UNITS/{other} is not a length unit errmap knows"),
            "DMIS length units are MM, CM, METER, INCH or FEET",
        )),
    }
}

/// The statements of the file, each with the line it starts on: a line ending in `$` (after
/// its `$$` comment is cut) continues on the next line.
fn statements(path: &Path) -> Result<impl Iterator<Item = Result<(u64, String)>>> {
    let file = errmap_core::io::open(path)?;
    let reader = std::io::BufReader::new(file);
    let path = path.to_path_buf();
    let mut lines = reader.split(b'\n').enumerate();
    Ok(std::iter::from_fn(move || {
        let mut text = String::new();
        let mut start = 0u64;
        loop {
            let Some((i, bytes)) = lines.next() else {
                return (!text.trim().is_empty()).then_some(Ok((start, text.clone())));
            };
            let line = i as u64 + 1;
            let bytes = match bytes {
                Ok(b) => b,
                Err(e) => return Some(Err(Error::read(&path, e))),
            };
            let raw = String::from_utf8_lossy(&bytes);
            let code = strip_comment(raw.trim_start_matches('\u{feff}')).trim();
            if text.is_empty() {
                if code.is_empty() {
                    continue;
                }
                start = line;
            }
            match code.strip_suffix('$') {
                Some(head) => text.push_str(head.trim_end()),
                None => {
                    text.push_str(code);
                    return Some(Ok((start, text)));
                }
            }
        }
    }))
}

/// The line without its `$$` comment (a `$$` inside single quotes is text).
fn strip_comment(line: &str) -> &str {
    let mut quoted = false;
    let bytes = line.as_bytes();
    for (i, &b) in bytes.iter().enumerate() {
        match b {
            b'\'' => quoted = !quoted,
            b'$' if !quoted && bytes.get(i + 1) == Some(&b'$') => return &line[..i],
            _ => {}
        }
    }
    line
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn comments_and_labels_split() {
        assert_eq!(strip_comment("F(A)=FEAT/POINT $$ note"), "F(A)=FEAT/POINT ");
        assert_eq!(
            strip_comment("DMISMN/'a $$ b',05.2"),
            "DMISMN/'a $$ b',05.2"
        );
        assert_eq!(
            strip_comment("F(A)=FEAT/POINT,CART,$"),
            "F(A)=FEAT/POINT,CART,$"
        );
        let (label, rest) = split_label("FA(PT 1) = FEAT/POINT,CART").unwrap();
        assert_eq!((label.as_str(), rest), ("PT 1", "FEAT/POINT,CART"));
        assert!(split_label("MEAS/POINT,F(PT1),1").is_none());
    }
}
