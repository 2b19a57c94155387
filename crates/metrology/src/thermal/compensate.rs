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
use errmap_core::error::{Error, Location, Result};
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
    /// Machine-log rows compensated.
    pub rows: u64,
    /// Rows whose position lies outside the fitted travel (Er(x) held at the nearest end).
    pub outside_travel: u64,
    /// Largest |compensation value| written, µm (that is, the largest |E|).
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

pub use errmap_core::numeric::format::{format_fixed4, FIXED4_BUF_LEN};

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
    let mut coolant = CoolantLookup::default();
    let mut summary = CompensateSummary::default();
    let (mut e_buf, mut c_buf) = ([0u8; FIXED4_BUF_LEN], [0u8; FIXED4_BUF_LEN]);
    while reader
        .read_byte_record(&mut record)
        .map_err(|e| csv_error(source, e))?
    {
        let line = record.position().map(|p| p.line()).unwrap_or(0);
        let row = Row {
            record: &record,
            line,
            source,
        };
        row.check_width(headers.len())?;
        row.number(cols.time, "time_s")?;
        let x_mm = row.number(cols.position, "position_mm")?;
        let dir_bytes = row.field(cols.direction);
        let direction = row.direction(dir_bytes)?;
        row.read_state(model, &cols, &mut coolant, &mut state)?;
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
                row.field(cols.time),
                row.field(cols.position),
                dir_bytes,
                &e_buf[..ne],
                &c_buf[..nc],
            ])
            .map_err(write_failed)?;
    }
    writer.flush().map_err(write_failed)?;
    Ok(summary)
}

/// One row of the machine log being read, with its line for messages.
struct Row<'a> {
    record: &'a csv::ByteRecord,
    line: u64,
    source: &'a Path,
}

impl Row<'_> {
    /// A field, trimmed (empty when missing).
    fn field(&self, col: usize) -> &[u8] {
        self.record.get(col).unwrap_or(b"").trim_ascii()
    }

    #[inline]
    fn number(&self, col: usize, name: &str) -> Result<f64> {
        number(self.record, col, self.line, name, self.source)
    }

    /// Every row has one value per header column.
    fn check_width(&self, header_len: usize) -> Result<()> {
        if self.record.len() == header_len {
            return Ok(());
        }
        Err(Error::input(
            Location::line(self.source, self.line),
            format!(
                "{} fields, but the header names {}",
                self.record.len(),
                header_len
            ),
            "give every row one value per header column",
        ))
    }

    /// `+`/`-`, or a direction's name.
    fn direction(&self, bytes: &[u8]) -> Result<Direction> {
        match bytes {
            b"+" => Ok(Direction::Forward),
            b"-" => Ok(Direction::Reverse),
            other => std::str::from_utf8(other)
                .ok()
                .and_then(Direction::parse)
                .ok_or_else(|| {
                    Error::input(
                        Location::cell(self.source, self.line, "direction"),
                        format!("'{}' is not a direction", String::from_utf8_lossy(other)),
                        "write + (forward) or - (reverse)",
                    )
                }),
        }
    }

    /// A raw sensor reading in column `col` converted to °C and calibrated.
    fn celsius(&self, col: usize, name: &str, sensor: &Sensor) -> Result<f64> {
        let raw = self.number(col, name)?;
        let celsius = sensor.unit.to_celsius(raw).map_err(|e| {
            Error::input(
                Location::cell(self.source, self.line, name.to_string()),
                e.to_string(),
                "",
            )
        })?;
        Ok(sensor.calibration.apply(celsius))
    }

    /// The row's sensor temperatures, ambient and coolant state into `state`.
    fn read_state(
        &self,
        model: &ThermalModel,
        cols: &Columns,
        coolant: &mut CoolantLookup,
        state: &mut ThermalState,
    ) -> Result<()> {
        for (k, (c, sensor)) in cols.sensors.iter().enumerate() {
            state.sensors_c[k] = self.celsius(*c, &sensor.name, sensor)?;
        }
        if let Some((c, sensor)) = &cols.ambient {
            state.ambient_c = Some(self.celsius(*c, "ambient_c", sensor)?);
        }
        if let Some(c) = cols.coolant {
            state.coolant = coolant.index(model, self.field(c), self)?;
        }
        Ok(())
    }
}

/// The model's index of a coolant state, looked up again only when the state changes.
#[derive(Default)]
struct CoolantLookup {
    last: Vec<u8>,
    index: usize,
}

impl CoolantLookup {
    fn index(&mut self, model: &ThermalModel, value: &[u8], row: &Row) -> Result<usize> {
        if value != self.last.as_slice() {
            self.index = model
                .coolant_states
                .iter()
                .position(|s| s.as_bytes() == value)
                .ok_or_else(|| {
                    Error::input(
                        Location::cell(row.source, row.line, "coolant"),
                        format!(
                            "coolant state '{}' has no gains in the model",
                            String::from_utf8_lossy(value)
                        ),
                        format!("the model knows: {}", model.coolant_states.join(", ")),
                    )
                })?;
            self.last.clear();
            self.last.extend_from_slice(value);
        }
        Ok(self.index)
    }
}

/// Compensate a log file into `output` (written atomically).
pub fn compensate_file(
    model: &ThermalModel,
    input: &Path,
    output: &Path,
) -> Result<CompensateSummary> {
    let file = errmap_core::io::open(input)?;
    let mut failure: Option<Error> = None;
    let mut summary = CompensateSummary::default();
    let written = errmap_core::io::write_atomic(output, |w| {
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
    errmap_core::io::csv_error_hinted(path, e, "save the log as plain comma-separated UTF-8 text")
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
