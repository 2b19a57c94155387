//! Compensation values for a machine log, streamed row by row in constant memory: for each
//! `time_s,position_mm,direction,<sensor…>,ambient_c,coolant` row, the modelled error of that
//! direction with the ambient and coolant adjustments, and the compensation value −E
//! (P' = P − E) that the seed's real-time module would send to the controller.
//!
//! Sensor columns hold raw readings in each sensor's unit (°C, or Ω for a Pt100); the model's
//! calibration is applied. Values are used as logged (no smoothing across rows).

use super::campaign::Direction;
use super::model::{ThermalModel, ThermalState};
use super::sensors::Sensor;
use crate::error::{Error, Location, Result};
use serde::Serialize;
use std::io::{Read, Write};
use std::path::Path;

/// Output columns.
pub const OUTPUT_HEADER: [&str; 5] = [
    "time_s",
    "position_mm",
    "direction",
    "error_um",
    "compensation_um",
];

/// What a compensation run did.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Default)]
pub struct CompensateSummary {
    pub rows: u64,
    /// Rows whose position lies outside the fitted travel (Er(x) held at the nearest end).
    pub outside_travel: u64,
    pub max_abs_compensation_um: f64,
}

struct Columns {
    time: usize,
    position: usize,
    direction: usize,
    sensors: Vec<(usize, Sensor)>,
    ambient: Option<(usize, Sensor)>,
    coolant: Option<usize>,
}

fn columns(model: &ThermalModel, headers: &csv::ByteRecord, source: &Path) -> Result<Columns> {
    // Fields are trimmed where they are used (cheaper than trimming whole records).
    let find = |name: &str| {
        headers
            .iter()
            .position(|h| h.trim_ascii() == name.as_bytes())
    };
    let need = |name: &str, hint: &str| {
        find(name).ok_or_else(|| {
            Error::input(
                Location::line(source, 1),
                format!("missing column '{name}'"),
                hint.to_string(),
            )
        })
    };
    let sensor_def = |name: &str| {
        model
            .sensors
            .iter()
            .find(|s| s.name == name)
            .cloned()
            .ok_or_else(|| {
                Error::Internal(format!("model lacks the definition of sensor '{name}'"))
            })
    };
    let mut sensors = Vec::new();
    for name in &model.gain_sensors {
        let c = need(
            name,
            "log one column per model sensor, named as in the sensor table",
        )?;
        sensors.push((c, sensor_def(name)?));
    }
    let ambient = match &model.ambient_sensor {
        Some(a) => Some((
            need("ambient_c", "log the ambient sensor's reading as ambient_c")?,
            sensor_def(a)?,
        )),
        None => None,
    };
    let coolant = find("coolant");
    if coolant.is_none() && model.coolant_states.len() > 1 {
        return Err(Error::input(
            Location::line(source, 1),
            "missing column 'coolant'",
            format!(
                "the model has gains for coolant {}; log the state of each row",
                model.coolant_states.join(", ")
            ),
        ));
    }
    Ok(Columns {
        time: need(
            "time_s",
            "the first columns are time_s,position_mm,direction",
        )?,
        position: need("position_mm", "log the axis position in mm")?,
        direction: need("direction", "log the travel direction as + or -")?,
        sensors,
        ambient,
        coolant,
    })
}

#[inline]
fn number(
    record: &csv::ByteRecord,
    col: usize,
    line: u64,
    name: &str,
    source: &Path,
) -> Result<f64> {
    let bytes = record.get(col).unwrap_or(b"").trim_ascii();
    let value = std::str::from_utf8(bytes)
        .ok()
        .and_then(|t| t.parse::<f64>().ok())
        .filter(|v| v.is_finite());
    value.ok_or_else(|| {
        Error::input(
            Location::cell(source, line, name),
            format!(
                "'{}' is not a finite number",
                String::from_utf8_lossy(bytes)
            ),
            "write a decimal number such as 12.5",
        )
    })
}

pub use crate::numeric::format::{format_fixed4, FIXED4_BUF_LEN};

/// Stream a machine log through the model. `source` names the input in messages.
pub fn compensate_stream<R: Read, W: Write>(
    model: &ThermalModel,
    input: R,
    source: &Path,
    output: W,
) -> Result<CompensateSummary> {
    let mut reader = csv::ReaderBuilder::new()
        .has_headers(true)
        .comment(Some(b'#'))
        .buffer_capacity(1 << 16)
        .from_reader(input);
    let headers = reader
        .byte_headers()
        .map_err(|e| csv_error(source, e))?
        .clone();
    let cols = columns(model, &headers, source)?;
    let mut writer = csv::WriterBuilder::new()
        .buffer_capacity(1 << 16)
        .from_writer(output);
    writer.write_record(OUTPUT_HEADER).map_err(write_failed)?;
    let mut record = csv::ByteRecord::new();
    let mut state = ThermalState {
        sensors_c: vec![0.0; cols.sensors.len()],
        ambient_c: None,
        coolant: 0,
    };
    let mut summary = CompensateSummary::default();
    let (mut e_buf, mut c_buf) = ([0u8; FIXED4_BUF_LEN], [0u8; FIXED4_BUF_LEN]);
    let mut last_coolant: Vec<u8> = Vec::new();
    let mut last_coolant_index = 0usize;
    loop {
        let more = reader
            .read_byte_record(&mut record)
            .map_err(|e| csv_error(source, e))?;
        if !more {
            break;
        }
        let line = record.position().map(|p| p.line()).unwrap_or(0);
        if record.len() != headers.len() {
            return Err(Error::input(
                Location::line(source, line),
                format!(
                    "{} fields, but the header names {}",
                    record.len(),
                    headers.len()
                ),
                "give every row one value per header column",
            ));
        }
        number(&record, cols.time, line, "time_s", source)?;
        let x_mm = number(&record, cols.position, line, "position_mm", source)?;
        let dir_bytes = record.get(cols.direction).unwrap_or(b"").trim_ascii();
        let direction = match dir_bytes {
            b"+" => Direction::Forward,
            b"-" => Direction::Reverse,
            other => std::str::from_utf8(other)
                .ok()
                .and_then(Direction::parse)
                .ok_or_else(|| {
                    Error::input(
                        Location::cell(source, line, "direction"),
                        format!("'{}' is not a direction", String::from_utf8_lossy(other)),
                        "write + (forward) or - (reverse)",
                    )
                })?,
        };
        for (k, (c, sensor)) in cols.sensors.iter().enumerate() {
            let raw = number(&record, *c, line, &sensor.name, source)?;
            let celsius = sensor.unit.to_celsius(raw).map_err(|e| {
                Error::input(
                    Location::cell(source, line, sensor.name.clone()),
                    e.to_string(),
                    "",
                )
            })?;
            state.sensors_c[k] = sensor.calibration.apply(celsius);
        }
        if let Some((c, sensor)) = &cols.ambient {
            let raw = number(&record, *c, line, "ambient_c", source)?;
            let celsius = sensor.unit.to_celsius(raw).map_err(|e| {
                Error::input(Location::cell(source, line, "ambient_c"), e.to_string(), "")
            })?;
            state.ambient_c = Some(sensor.calibration.apply(celsius));
        }
        if let Some(c) = cols.coolant {
            let value = record.get(c).unwrap_or(b"").trim_ascii();
            if value != last_coolant.as_slice() {
                last_coolant_index = model
                    .coolant_states
                    .iter()
                    .position(|s| s.as_bytes() == value)
                    .ok_or_else(|| {
                        Error::input(
                            Location::cell(source, line, "coolant"),
                            format!(
                                "coolant state '{}' has no gains in the model",
                                String::from_utf8_lossy(value)
                            ),
                            format!("the model knows: {}", model.coolant_states.join(", ")),
                        )
                    })?;
                last_coolant.clear();
                last_coolant.extend_from_slice(value);
            }
            state.coolant = last_coolant_index;
        }
        if !(model.x_min_mm..=model.x_max_mm).contains(&x_mm) {
            summary.outside_travel += 1;
        }
        let error_um = model.error_um(direction, x_mm, &state);
        let compensation_um = -error_um;
        summary.rows += 1;
        summary.max_abs_compensation_um =
            summary.max_abs_compensation_um.max(compensation_um.abs());
        let ne = format_fixed4(error_um, &mut e_buf);
        let nc = format_fixed4(compensation_um, &mut c_buf);
        writer
            .write_record([
                record.get(cols.time).unwrap_or(b"").trim_ascii(),
                record.get(cols.position).unwrap_or(b"").trim_ascii(),
                dir_bytes,
                &e_buf[..ne],
                &c_buf[..nc],
            ])
            .map_err(write_failed)?;
    }
    writer.flush().map_err(write_failed)?;
    Ok(summary)
}

/// Compensate a log file into `output` (written atomically).
pub fn compensate_file(
    model: &ThermalModel,
    input: &Path,
    output: &Path,
) -> Result<CompensateSummary> {
    let file = crate::io::open(input)?;
    let mut failure: Option<Error> = None;
    let mut summary = CompensateSummary::default();
    let written = crate::io::write_atomic(output, |w| {
        match compensate_stream(
            model,
            std::io::BufReader::with_capacity(1 << 16, file),
            input,
            w,
        ) {
            Ok(s) => {
                summary = s;
                Ok(())
            }
            // A failed write goes back to `write_atomic`, which names the output (or the size
            // limit it reached); anything else is the input's fault and keeps its own place.
            Err(Error::Io {
                action: "write",
                source,
                ..
            }) => Err(source),
            Err(e) => {
                failure = Some(e);
                Err(std::io::Error::other("compensation stopped"))
            }
        }
    });
    if let Some(e) = failure {
        return Err(e);
    }
    written?;
    Ok(summary)
}

/// A write to the output stream failed; [`compensate_file`] names the file.
fn write_failed(e: impl Into<std::io::Error>) -> Error {
    Error::write("the output", e.into())
}

fn csv_error(path: &Path, e: csv::Error) -> Error {
    let line = e.position().map(|p| p.line());
    let message = format!("unreadable CSV: {e}");
    match e.into_kind() {
        // The file itself could not be read (a folder, a device error): an io error, not content.
        csv::ErrorKind::Io(source) => Error::read(path, source),
        _ => Error::input(
            Location {
                file: path.to_path_buf(),
                line,
                column: None,
            },
            message,
            "save the log as plain comma-separated UTF-8 text",
        ),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fixed_point_formatting() {
        let mut buf = [0u8; FIXED4_BUF_LEN];
        let f = |v: f64, buf: &mut [u8; FIXED4_BUF_LEN]| {
            let n = format_fixed4(v, buf);
            String::from_utf8(buf[..n].to_vec()).unwrap()
        };
        assert_eq!(f(0.0, &mut buf), "0.0000");
        assert_eq!(f(1.23456, &mut buf), "1.2346");
        assert_eq!(f(-1.23454, &mut buf), "-1.2345");
        assert_eq!(f(-0.00004, &mut buf), "0.0000");
        assert_eq!(f(0.05, &mut buf), "0.0500");
        assert_eq!(f(-12345.6789, &mut buf), "-12345.6789");
        assert_eq!(f(1e20, &mut buf), format!("{:.4}", 1e20));
        // The widest values (absurd temperatures can produce them) are written whole.
        assert_eq!(f(-f64::MAX, &mut buf), format!("{:.4}", -f64::MAX));
        assert_eq!(f(1e45, &mut buf), format!("{:.4}", 1e45));
    }
}
