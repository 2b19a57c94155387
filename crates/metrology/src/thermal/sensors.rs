//! Sensor table and temperature log files; Pt100 conversion, calibration against the reference
//! sensor (offset and scale by least squares) and denoising of every channel.
//!
//! Sensor table (CSV), one row per sensor:
//! `name,role,unit,offset_c,scale[,median_window,sg_window,sg_order]` — role is one of
//! nut|bearing|ambient|reference|other, unit is c (°C) or ohm (Pt100), the calibration maps a
//! raw reading to temperature as `T = scale·T_raw + offset_c` (empty cells: 0 and 1).
//! Temperature log (CSV): `time_s,<sensor>,<sensor>…`, one column per sensor of the table,
//! time strictly increasing.

use super::filter::FilterSpec;
use super::pt100;
use crate::Setting;
use errmap_core::error::{Error, Location, Result};
use errmap_core::io::{write_atomic, CsvRow, CsvTable};
use errmap_core::setting::words;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// What a sensor measures.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, PartialOrd, Ord, Hash)]
#[serde(rename_all = "lowercase")]
pub enum Role {
    /// At the ball-screw nut; a gain sensor of the model by default.
    Nut,
    /// At the screw's bearing; a gain sensor of the model by default.
    Bearing,
    /// The room air (at most one): rises are taken above it, and its change drives the ρ term.
    Ambient,
    /// The sensor the others are calibrated against (at most one).
    Reference,
    /// Any other place; a gain sensor only when named with `--sensors`.
    Other,
}

impl Role {
    /// The role written in a sensor table's `role` cell (any case); `None` for an unknown word.
    pub fn parse(text: &str) -> Option<Role> {
        match text.to_ascii_lowercase().as_str() {
            "nut" => Some(Role::Nut),
            "bearing" => Some(Role::Bearing),
            "ambient" => Some(Role::Ambient),
            "reference" => Some(Role::Reference),
            "other" => Some(Role::Other),
            _ => None,
        }
    }
    /// The role's word as the sensor table and the store write it (`nut`, `bearing`, …).
    pub fn name(self) -> &'static str {
        match self {
            Role::Nut => "nut",
            Role::Bearing => "bearing",
            Role::Ambient => "ambient",
            Role::Reference => "reference",
            Role::Other => "other",
        }
    }
}

/// The unit a sensor's log column is written in.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Unit {
    /// Degrees Celsius.
    C,
    /// Ohms of a Pt100 (converted by IEC 60751).
    Ohm,
}

impl Unit {
    /// The unit written in a sensor table's `unit` cell: `c`, `degc`, `°c`, `ohm` or `Ω` (any
    /// case); `None` otherwise.
    pub fn parse(text: &str) -> Option<Unit> {
        match text.to_ascii_lowercase().as_str() {
            "c" | "degc" | "°c" => Some(Unit::C),
            "ohm" | "ω" => Some(Unit::Ohm),
            _ => None,
        }
    }
    /// The unit's word as the sensor table and the store write it (`c`, `ohm`).
    pub fn name(self) -> &'static str {
        match self {
            Unit::C => "c",
            Unit::Ohm => "ohm",
        }
    }
    /// A raw reading in this unit as °C (before calibration).
    pub fn to_celsius(self, value: f64) -> Result<f64> {
        match self {
            Unit::C => Ok(value),
            Unit::Ohm => pt100::temperature_c(value),
        }
    }
}

/// Calibration of one sensor against the reference sensor: `T = scale·T_raw + offset_c`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Calibration {
    /// Offset added after scaling, °C.
    pub offset_c: f64,
    /// Factor on the raw reading (dimensionless, 1 = none).
    pub scale: f64,
}

impl Default for Calibration {
    fn default() -> Self {
        Calibration {
            offset_c: 0.0,
            scale: 1.0,
        }
    }
}

impl Calibration {
    /// The calibrated temperature scale·raw + offset, °C, of a raw reading already in °C.
    #[inline]
    pub fn apply(&self, raw_c: f64) -> f64 {
        self.scale * raw_c + self.offset_c
    }
}

/// One row of the sensor table.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Sensor {
    /// Sensor name: its column in the temperature log and in a machine log.
    pub name: String,
    /// Where the sensor sits, which decides how the model uses it.
    pub role: Role,
    /// Unit of the sensor's log column (°C, or Ω of a Pt100).
    pub unit: Unit,
    /// Calibration from raw °C to temperature, against the reference sensor.
    pub calibration: Calibration,
    /// Denoising of the channel: running-median window, then Savitzky–Golay window and order.
    pub filter: FilterSpec,
}

/// The sensor table of a campaign.
#[derive(Debug, Clone, PartialEq)]
pub struct SensorTable {
    /// The table file read, as messages name it.
    pub path: PathBuf,
    /// The sensors in table order.
    pub sensors: Vec<Sensor>,
}

const TABLE_COLUMNS: [&str; 8] = [
    "name",
    "role",
    "unit",
    "offset_c",
    "scale",
    "median_window",
    "sg_window",
    "sg_order",
];

impl SensorTable {
    /// Read and validate a sensor table.
    pub fn read(path: &Path) -> Result<SensorTable> {
        Self::from_csv(&CsvTable::read(path)?)
    }

    /// Validate a sensor table already read as CSV (errors name `t.path`).
    pub fn from_csv(t: &CsvTable) -> Result<SensorTable> {
        t.reject_unknown(&TABLE_COLUMNS)?;
        let cols = TableColumns::find(t)?;
        let mut sensors: Vec<Sensor> = Vec::new();
        for row in &t.rows {
            let sensor = sensor_row(t, &cols, row, &sensors)?;
            sensors.push(sensor);
        }
        check_roles(&t.path, &sensors)?;
        Ok(SensorTable {
            path: t.path.clone(),
            sensors,
        })
    }

    /// Write the table (with every column) atomically.
    pub fn write(&self, path: &Path) -> Result<()> {
        write_atomic(path, |w| {
            writeln!(w, "{}", TABLE_COLUMNS.join(","))?;
            for s in &self.sensors {
                writeln!(
                    w,
                    "{},{},{},{},{},{},{},{}",
                    s.name,
                    s.role.name(),
                    s.unit.name(),
                    s.calibration.offset_c,
                    s.calibration.scale,
                    s.filter.median_window,
                    s.filter.sg_window,
                    s.filter.sg_order
                )?;
            }
            Ok(())
        })
    }

    /// Store fitted calibrations in the table (sensors not in `fits` keep theirs).
    pub fn apply_calibrations(&mut self, fits: &[CalibrationFit]) {
        for f in fits {
            if let Some(s) = self.sensors.iter_mut().find(|s| s.name == f.sensor) {
                s.calibration = f.calibration;
            }
        }
    }

    /// The sensor named `name`, if the table lists it.
    pub fn get(&self, name: &str) -> Option<&Sensor> {
        self.sensors.iter().find(|s| s.name == name)
    }

    /// The one sensor with a role, if any.
    pub fn with_role(&self, role: Role) -> Option<&Sensor> {
        self.sensors.iter().find(|s| s.role == role)
    }
}

/// Column indices of a sensor table: five required, the filter settings optional.
struct TableColumns {
    name: usize,
    role: usize,
    unit: usize,
    offset: usize,
    scale: usize,
    median_window: Option<usize>,
    sg_window: Option<usize>,
    sg_order: Option<usize>,
}

impl TableColumns {
    fn find(t: &CsvTable) -> Result<TableColumns> {
        Ok(TableColumns {
            name: t.require("name")?,
            role: t.require("role")?,
            unit: t.require("unit")?,
            offset: t.require("offset_c")?,
            scale: t.require("scale")?,
            median_window: t.column("median_window"),
            sg_window: t.column("sg_window"),
            sg_order: t.column("sg_order"),
        })
    }
}

/// One validated row of a sensor table; `before` holds the rows above it (names are unique).
fn sensor_row(
    t: &CsvTable,
    cols: &TableColumns,
    row: &CsvRow,
    before: &[Sensor],
) -> Result<Sensor> {
    let name = t.text(row, cols.name).to_string();
    if name.is_empty() || name == "time_s" || name.contains(',') {
        return Err(t.error_at(
            row,
            Some(cols.name),
            format!("'{name}' is not a usable sensor name"),
            "give each sensor a short unique name, used as its column in the temperature log",
        ));
    }
    if before.iter().any(|s| s.name == name) {
        return Err(t.error_at(
            row,
            Some(cols.name),
            format!("sensor '{name}' is listed twice"),
            "keep one row per sensor",
        ));
    }
    let role = Role::parse(t.text(row, cols.role)).ok_or_else(|| {
        t.error_at(
            row,
            Some(cols.role),
            format!("unknown role '{}'", t.text(row, cols.role)),
            "use one of nut, bearing, ambient, reference, other",
        )
    })?;
    let unit = Unit::parse(t.text(row, cols.unit)).ok_or_else(|| {
        t.error_at(
            row,
            Some(cols.unit),
            format!("unknown unit '{}'", t.text(row, cols.unit)),
            "use c for °C or ohm for a Pt100 resistance",
        )
    })?;
    let offset_c = t.f64_opt(row, cols.offset)?.unwrap_or(0.0);
    let scale = t.f64_opt(row, cols.scale)?.unwrap_or(1.0);
    if scale <= 0.0 {
        return Err(t.error_at(
            row,
            Some(cols.scale),
            format!("scale {scale} must be positive"),
            "a calibration scale is close to 1; leave the cell empty for 1",
        ));
    }
    Ok(Sensor {
        name,
        role,
        unit,
        calibration: Calibration { offset_c, scale },
        filter: filter_row(t, cols, row)?,
    })
}

/// The filter settings of a sensor-table row (empty cells and absent columns: the defaults).
fn filter_row(t: &CsvTable, cols: &TableColumns, row: &CsvRow) -> Result<FilterSpec> {
    let int = |c: Option<usize>, default: usize| -> Result<usize> {
        match c {
            None => Ok(default),
            Some(c) => match t.text(row, c) {
                "" => Ok(default),
                text => text.parse::<usize>().map_err(|_| {
                    t.error_at(
                        row,
                        Some(c),
                        format!("'{text}' is not a whole number of samples"),
                        "write an odd count such as 5 (1 = off)",
                    )
                }),
            },
        }
    };
    let mut filter = FilterSpec::default();
    filter.median_window = int(cols.median_window, filter.median_window)?;
    filter.sg_window = int(cols.sg_window, filter.sg_window)?;
    filter.sg_order = int(cols.sg_order, filter.sg_order)?;
    filter.validate().map_err(|message| {
        t.error_at(
            row,
            cols.sg_window.or(cols.median_window),
            message,
            "windows are odd sample counts (1 = off), the order below the window",
        )
    })?;
    Ok(filter)
}

/// A table lists at least one sensor, and at most one reference and one ambient sensor.
fn check_roles(path: &Path, sensors: &[Sensor]) -> Result<()> {
    if sensors.is_empty() {
        return Err(Error::input(
            Location::file(path),
            "the sensor table lists no sensors",
            "add one row per sensor: name,role,unit,offset_c,scale",
        ));
    }
    for role in [Role::Reference, Role::Ambient] {
        let n = sensors.iter().filter(|s| s.role == role).count();
        if n > 1 {
            return Err(Error::input(
                Location::file(path),
                format!("{n} sensors have the role {}", role.name()),
                format!("mark exactly one sensor as {}", role.name()),
            ));
        }
    }
    Ok(())
}

/// A temperature log as read: times and, per sensor, readings converted to °C (uncalibrated).
#[derive(Debug, Clone, PartialEq)]
pub struct TemperatureLog {
    /// The log file read, as messages name it.
    pub path: PathBuf,
    /// Sample times, s, strictly increasing.
    pub time_s: Vec<f64>,
    /// Sensor names in column order.
    pub sensors: Vec<String>,
    /// `raw_c[k][i]`: sensor k at time i, °C before calibration.
    pub raw_c: Vec<Vec<f64>>,
}

impl TemperatureLog {
    /// Read a log whose columns are `time_s` and sensors of `table`; Pt100 columns are converted.
    pub fn read(path: &Path, table: &SensorTable) -> Result<TemperatureLog> {
        Self::from_csv(&CsvTable::read(path)?, table)
    }

    /// [`TemperatureLog::read`] for a log already read as CSV (errors name `t.path`).
    pub fn from_csv(t: &CsvTable, table: &SensorTable) -> Result<TemperatureLog> {
        let path = t.path.as_path();
        let c_time = t.require("time_s")?;
        let mut columns = Vec::new();
        for (c, h) in t.headers.iter().enumerate() {
            if c == c_time {
                continue;
            }
            let sensor = table.get(h).ok_or_else(|| {
                Error::input(
                    Location::cell(path, 1, h.clone()),
                    format!("column '{h}' is not a sensor of {}", table.path.display()),
                    "add the sensor to the sensor table or rename the column",
                )
            })?;
            columns.push((c, sensor.clone()));
        }
        if columns.is_empty() {
            return Err(Error::input(
                Location::line(path, 1),
                "the log has no sensor columns",
                "write time_s followed by one column per sensor",
            ));
        }
        let mut time_s = Vec::with_capacity(t.rows.len());
        let mut raw_c = vec![Vec::with_capacity(t.rows.len()); columns.len()];
        for row in &t.rows {
            let time = t.f64(row, c_time)?;
            if let Some(&last) = time_s.last() {
                if time <= last {
                    return Err(t.error_at(
                        row,
                        Some(c_time),
                        format!("time {time} s does not follow {last} s"),
                        "sort the log by time and remove duplicate rows",
                    ));
                }
            }
            time_s.push(time);
            for (k, (c, sensor)) in columns.iter().enumerate() {
                let value = t.f64(row, *c)?;
                let celsius = sensor.unit.to_celsius(value).map_err(|e| {
                    t.error_at(row, Some(*c), e.to_string(), "a Pt100 reads 18.5 … 390.5 Ω")
                })?;
                raw_c[k].push(celsius);
            }
        }
        if time_s.is_empty() {
            return Err(Error::input(
                Location::file(path),
                "the temperature log has no rows",
                "add one row per sample: time_s,<sensor>…",
            ));
        }
        Ok(TemperatureLog {
            path: path.to_path_buf(),
            time_s,
            sensors: columns.into_iter().map(|(_, s)| s.name).collect(),
            raw_c,
        })
    }

    fn index(&self, sensor: &str) -> Option<usize> {
        self.sensors.iter().position(|s| s == sensor)
    }

    /// Calibrated and denoised channels, with the calibrations and filters of `table`.
    pub fn process(&self, table: &SensorTable) -> Result<ProcessedLog> {
        let mut channels = Vec::with_capacity(self.sensors.len());
        for (name, raw) in self.sensors.iter().zip(&self.raw_c) {
            let sensor = table.get(name).ok_or_else(|| {
                Error::usage(
                    format!(
                        "sensor '{name}' of {} is not in the sensor table",
                        self.path.display()
                    ),
                    "use the sensor table the log was read with",
                )
            })?;
            let calibrated: Vec<f64> = raw.iter().map(|&v| sensor.calibration.apply(v)).collect();
            channels.push(sensor.filter.apply(&calibrated)?);
        }
        Ok(ProcessedLog {
            time_s: self.time_s.clone(),
            sensors: self.sensors.clone(),
            temperature_c: channels,
        })
    }
}

/// Calibrated, denoised temperatures.
#[derive(Debug, Clone, PartialEq)]
pub struct ProcessedLog {
    /// Sample times, s, strictly increasing (those of the log).
    pub time_s: Vec<f64>,
    /// Sensor names in the log's column order.
    pub sensors: Vec<String>,
    /// `temperature_c[k][i]`: sensor k at time i.
    pub temperature_c: Vec<Vec<f64>>,
}

impl ProcessedLog {
    /// The calibrated, denoised series of `sensor` (°C, one value per sample time); `None` when the
    /// log has no such column.
    pub fn channel(&self, sensor: &str) -> Option<&[f64]> {
        let k = self.sensors.iter().position(|s| s == sensor)?;
        Some(&self.temperature_c[k])
    }

    /// Mean of a sensor over `[from_s, to_s]` (the samples inside; if none, the value
    /// interpolated at the middle of the span). `None` when the sensor is absent or the span
    /// lies outside the log.
    pub fn mean_over(&self, sensor: &str, from_s: f64, to_s: f64) -> Option<f64> {
        let values = self.channel(sensor)?;
        let (first, last) = (*self.time_s.first()?, *self.time_s.last()?);
        if to_s < first || from_s > last {
            return None;
        }
        let (mut sum, mut n) = (0.0, 0usize);
        for (t, v) in self.time_s.iter().zip(values) {
            if *t >= from_s && *t <= to_s {
                sum += v;
                n += 1;
            }
        }
        if n > 0 {
            return Some(sum / n as f64);
        }
        let mid = 0.5 * (from_s + to_s);
        let i = self.time_s.partition_point(|t| *t < mid);
        if i == 0 || i >= self.time_s.len() {
            return None;
        }
        let (t0, t1) = (self.time_s[i - 1], self.time_s[i]);
        let w = (mid - t0) / (t1 - t0);
        Some(values[i - 1] + w * (values[i] - values[i - 1]))
    }
}

/// Result of calibrating one sensor against the reference.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct CalibrationFit {
    /// Name of the sensor calibrated.
    pub sensor: String,
    /// The fitted calibration (offset only, scale 1, when `scale_fitted` is false).
    pub calibration: Calibration,
    /// RMS of reference − calibrated reading over the period (°C).
    pub residual_rms_c: f64,
    /// Log samples in the calibration period.
    pub samples: usize,
    /// False when the period held too little temperature range to fit a scale (scale kept at 1).
    pub scale_fitted: bool,
}

/// Least-squares calibration of every non-reference sensor against the reference sensor over
/// `[from_s, to_s]`: `T_ref ≈ scale·T_raw + offset_c`. The reference's own calibration is
/// applied to it first. A period whose readings span less than `min_span_c` fits the offset only.
pub fn calibrate(
    log: &TemperatureLog,
    table: &SensorTable,
    from_s: f64,
    to_s: f64,
    min_span_c: f64,
) -> Result<Vec<CalibrationFit>> {
    if min_span_c.is_nan() || min_span_c < 0.0 {
        return Err(Error::usage(
            format!("minimum span {min_span_c} °C is not a temperature span"),
            format!(
                "give {} as 0 or more degrees, e.g. 1",
                words(Setting::MinSpanC)
            ),
        ));
    }
    let (reference, k_ref) = reference_column(log, table)?;
    let idx = period_samples(log, from_s, to_s)?;
    let reference_c: Vec<f64> = idx
        .iter()
        .map(|&i| reference.calibration.apply(log.raw_c[k_ref][i]))
        .collect();
    let fits = log
        .sensors
        .iter()
        .enumerate()
        .filter(|&(k, _)| k != k_ref)
        .map(|(k, name)| {
            let raw: Vec<f64> = idx.iter().map(|&i| log.raw_c[k][i]).collect();
            fit_against_reference(name, &raw, &reference_c, min_span_c)
        })
        .collect();
    Ok(fits)
}

/// The reference sensor of the table and its column in the log.
fn reference_column<'t>(
    log: &TemperatureLog,
    table: &'t SensorTable,
) -> Result<(&'t Sensor, usize)> {
    let reference = table.with_role(Role::Reference).ok_or_else(|| {
        Error::input(
            Location::file(&table.path),
            "no sensor has the role reference",
            "mark the trusted sensor of the calibration period as reference",
        )
    })?;
    let k_ref = log.index(&reference.name).ok_or_else(|| {
        Error::input(
            Location::line(&log.path, 1),
            format!(
                "the log has no column for the reference sensor '{}'",
                reference.name
            ),
            "log the reference sensor during the calibration period",
        )
    })?;
    Ok((reference, k_ref))
}

/// Indices of the log samples inside `[from_s, to_s]`; at least three.
fn period_samples(log: &TemperatureLog, from_s: f64, to_s: f64) -> Result<Vec<usize>> {
    let idx: Vec<usize> = (0..log.time_s.len())
        .filter(|&i| log.time_s[i] >= from_s && log.time_s[i] <= to_s)
        .collect();
    if idx.len() < 3 {
        return Err(Error::usage(
            format!(
                "only {} log samples lie in the calibration period {from_s} … {to_s} s",
                idx.len()
            ),
            "give a period that covers at least three samples of the log",
        ));
    }
    Ok(idx)
}

/// The straight line reference_c ≈ scale·raw + offset_c by least squares; the offset alone
/// (scale 1) when the readings span less than `min_span_c`.
fn fit_against_reference(
    sensor: &str,
    raw: &[f64],
    reference_c: &[f64],
    min_span_c: f64,
) -> CalibrationFit {
    let n = raw.len() as f64;
    let span = raw.iter().cloned().fold(f64::NEG_INFINITY, f64::max)
        - raw.iter().cloned().fold(f64::INFINITY, f64::min);
    // reference = offset + scale·raw by least squares when the span can tell the scale, else
    // the offset alone (scale 1: the mean difference).
    let line = errmap_core::numeric::lsq::fit_line(raw, reference_c).filter(|_| span >= min_span_c);
    let scale_fitted = line.is_some();
    let calibration = match line {
        Some(l) => Calibration {
            offset_c: l.intercept,
            scale: l.slope,
        },
        None => Calibration {
            offset_c: reference_c.iter().sum::<f64>() / n - raw.iter().sum::<f64>() / n,
            scale: 1.0,
        },
    };
    let residual_rms_c = (raw
        .iter()
        .zip(reference_c)
        .map(|(x, y)| (y - calibration.apply(*x)).powi(2))
        .sum::<f64>()
        / n)
        .sqrt();
    CalibrationFit {
        sensor: sensor.to_string(),
        calibration,
        residual_rms_c,
        samples: raw.len(),
        scale_fitted,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn write(dir: &Path, name: &str, text: &str) -> PathBuf {
        let p = dir.join(name);
        std::fs::write(&p, text).unwrap();
        p
    }

    const TABLE: &str = "name,role,unit,offset_c,scale,median_window,sg_window,sg_order\n\
        nut,nut,ohm,,,1,1,0\n\
        bearing,bearing,c,0.5,1.0,1,1,0\n\
        room,ambient,c,,,,,\n\
        ref,reference,c,0,1,1,1,0\n";

    #[test]
    fn table_and_log_read_with_pt100_and_calibration() {
        let dir = tempfile::tempdir().unwrap();
        let tp = write(dir.path(), "sensors.csv", TABLE);
        let table = SensorTable::read(&tp).unwrap();
        assert_eq!(table.sensors.len(), 4);
        assert_eq!(table.with_role(Role::Ambient).unwrap().name, "room");
        assert_eq!(table.get("room").unwrap().filter, FilterSpec::default());
        // 107.79 Ω is 20 °C in the IEC 60751 table.
        let lp = write(
            dir.path(),
            "log.csv",
            "time_s,nut,bearing,room\n0,107.79,20,20\n10,111.67,21,20\n",
        );
        let log = TemperatureLog::read(&lp, &table).unwrap();
        assert!((log.raw_c[0][0] - 20.0).abs() < 0.02);
        assert!((log.raw_c[0][1] - 30.0).abs() < 0.02);
        let processed = log.process(&table).unwrap();
        // bearing offset 0.5 applied, no filter on it.
        assert_eq!(processed.channel("bearing").unwrap(), &[20.5, 21.5]);
        assert_eq!(processed.mean_over("bearing", 0.0, 10.0), Some(21.0));
        // A span between samples interpolates at its middle.
        assert_eq!(processed.mean_over("bearing", 2.0, 3.0), Some(20.5 + 0.25));
        assert_eq!(processed.mean_over("bearing", 20.0, 30.0), None);
    }

    #[test]
    fn errors_name_file_line_and_column() {
        let dir = tempfile::tempdir().unwrap();
        let tp = write(
            dir.path(),
            "s.csv",
            "name,role,unit,offset_c,scale\nnut,screw,c,,\n",
        );
        let err = SensorTable::read(&tp).unwrap_err().to_string();
        assert!(
            err.contains("s.csv:2, column role") && err.contains("screw"),
            "{err}"
        );
        let tp = write(
            dir.path(),
            "s2.csv",
            "name,role,unit,offset_c,scale,sg_window\nnut,nut,c,,,4\n",
        );
        let err = SensorTable::read(&tp).unwrap_err().to_string();
        assert!(err.contains("s2.csv:2") && err.contains("odd"), "{err}");
        let table = SensorTable::read(&write(dir.path(), "t.csv", TABLE)).unwrap();
        let lp = write(dir.path(), "l.csv", "time_s,nut,spindle\n0,100,20\n");
        let err = TemperatureLog::read(&lp, &table).unwrap_err().to_string();
        assert!(err.contains("l.csv:1, column spindle"), "{err}");
        let lp = write(dir.path(), "l2.csv", "time_s,nut\n0,100\n\n0,100\n");
        let err = TemperatureLog::read(&lp, &table).unwrap_err().to_string();
        assert!(err.contains("l2.csv:4, column time_s"), "{err}");
        let lp = write(dir.path(), "l3.csv", "time_s,nut\n0,100\n1,5000\n");
        let err = TemperatureLog::read(&lp, &table).unwrap_err().to_string();
        assert!(
            err.contains("l3.csv:3, column nut") && err.contains("Pt100"),
            "{err}"
        );
    }

    #[test]
    fn calibration_recovers_offset_and_scale() {
        // Reference ramps 18 → 35 °C; bearing reads (T − 0.4)/1.02 and room T + 0.25:
        // calibration must find scale 1.02, offset 0.4 and scale 1, offset −0.25.
        let dir = tempfile::tempdir().unwrap();
        let table = SensorTable::read(&write(dir.path(), "t.csv", TABLE)).unwrap();
        let mut text = String::from("time_s,ref,bearing,room\n");
        for i in 0..=100 {
            let t = 18.0 + 0.17 * i as f64;
            text.push_str(&format!(
                "{},{},{},{}\n",
                i * 10,
                t,
                (t - 0.4) / 1.02,
                t + 0.25
            ));
        }
        let log = TemperatureLog::read(&write(dir.path(), "cal.csv", &text), &table).unwrap();
        let fits = calibrate(&log, &table, 0.0, 1000.0, 1.0).unwrap();
        let bearing = fits.iter().find(|f| f.sensor == "bearing").unwrap();
        assert!((bearing.calibration.scale - 1.02).abs() < 1e-9);
        assert!((bearing.calibration.offset_c - 0.4).abs() < 1e-9);
        let room = fits.iter().find(|f| f.sensor == "room").unwrap();
        assert!((room.calibration.scale - 1.0).abs() < 1e-9);
        assert!((room.calibration.offset_c + 0.25).abs() < 1e-9);
        assert!(room.residual_rms_c < 1e-9 && room.scale_fitted);
        // A flat period fits the offset only.
        let fits = calibrate(&log, &table, 0.0, 30.0, 1.0).unwrap();
        let room = fits.iter().find(|f| f.sensor == "room").unwrap();
        assert!(!room.scale_fitted && room.calibration.scale == 1.0);
        assert!((room.calibration.offset_c + 0.25).abs() < 1e-9);
        // A minimum span that is not a span is refused rather than read as "offset only".
        for bad in [f64::NAN, -1.0] {
            let err = calibrate(&log, &table, 0.0, 1000.0, bad).unwrap_err();
            assert_eq!(err.kind(), "input", "{err}");
            assert!(
                err.to_string().contains("is not a temperature span"),
                "{err}"
            );
        }
    }

    #[test]
    fn table_write_read_round_trip() {
        let dir = tempfile::tempdir().unwrap();
        let table = SensorTable::read(&write(dir.path(), "t.csv", TABLE)).unwrap();
        let out = dir.path().join("out.csv");
        table.write(&out).unwrap();
        let back = SensorTable::read(&out).unwrap();
        assert_eq!(back.sensors, table.sensors);
    }
}
