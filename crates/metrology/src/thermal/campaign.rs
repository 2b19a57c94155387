//! A thermal campaign: laser measurements of one axis at increasing times with the temperatures
//! averaged over each measurement; read from a folder with `campaign.toml`.
//!
//! ```toml
//! name = "warmup-a"          # unique name of the campaign (default: the folder name)
//! axis = "X"
//! coolant = "off"            # coolant state label: gains are fitted per state
//! runs = "runs.csv"          # linear-axis run file with a time_s column
//! temperatures = "temperatures.csv"
//! sensors = "../sensors.csv"
//! measurement_s = 300        # temperatures are averaged over [time_s, time_s + measurement_s]
//! reference_point_mm = 0.0   # Px, the point the thermal error lines fan about
//! ```
//! Every row of one measurement carries the same `time_s` (the measurement's start); rows with
//! different `time_s` are different measurements. The earliest measurement is the cold one.

pub use super::runs::LaserPoint;
use super::sensors::{ProcessedLog, SensorTable, TemperatureLog};
use errmap_core::error::{Error, Location, Result};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

pub use crate::linear::Direction;

/// Forward then reverse: the order of per-direction results everywhere in thermal.
pub const DIRECTIONS: [Direction; 2] = [Direction::Forward, Direction::Reverse];

/// "forward" or "reverse".
pub fn direction_name(d: Direction) -> &'static str {
    d.name()
}

/// All laser readings taken at one thermal state, with its temperatures.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Measurement {
    /// Start time of the measurement (its rows' `time_s`), s, in the temperature log's time base.
    pub time_s: f64,
    /// The laser readings of the measurement: all its runs, both directions.
    pub points: Vec<LaserPoint>,
    /// Mean calibrated, denoised temperature of each sensor over the measurement (°C).
    pub temperatures_c: BTreeMap<String, f64>,
}

/// The campaign file's settings.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CampaignFile {
    /// Unique campaign name, the store's key; `None`: the folder's name.
    pub name: Option<String>,
    /// Axis name (default `X`); the model's default name in the store.
    #[serde(default = "default_axis")]
    pub axis: String,
    /// Coolant state label (default `off`); gains are fitted per state.
    #[serde(default = "default_coolant")]
    pub coolant: String,
    /// Run file, relative to the campaign folder (default `runs.csv`); every row needs `time_s`.
    #[serde(default = "default_runs")]
    pub runs: PathBuf,
    /// Temperature log, relative to the campaign folder (default `temperatures.csv`).
    #[serde(default = "default_temperatures")]
    pub temperatures: PathBuf,
    /// Sensor table, relative to the campaign folder (default `sensors.csv`); campaigns may share
    /// one.
    #[serde(default = "default_sensors")]
    pub sensors: PathBuf,
    /// Duration of one measurement, s (default 300): temperatures are averaged over
    /// [time_s, time_s + measurement_s].
    #[serde(default = "default_measurement_s")]
    pub measurement_s: f64,
    /// Px, mm (default 0): the point of the axis the thermal error lines fan about, where thermal
    /// growth is zero.
    #[serde(default)]
    pub reference_point_mm: f64,
}

fn default_axis() -> String {
    "X".into()
}
fn default_coolant() -> String {
    "off".into()
}
fn default_runs() -> PathBuf {
    "runs.csv".into()
}
fn default_temperatures() -> PathBuf {
    "temperatures.csv".into()
}
fn default_sensors() -> PathBuf {
    "sensors.csv".into()
}
fn default_measurement_s() -> f64 {
    300.0
}

/// A campaign in memory: settings, sensors and the measurements in time order.
#[derive(Debug, Clone, PartialEq)]
pub struct Campaign {
    /// The campaign's name: from the file, else the folder's.
    pub name: String,
    /// Folder of the campaign file (outputs and the default store go beside it).
    pub dir: PathBuf,
    /// Axis name from the campaign file.
    pub axis: String,
    /// Coolant state label from the campaign file.
    pub coolant: String,
    /// Px, the point the thermal error lines fan about, mm.
    pub reference_point_mm: f64,
    /// Duration of one measurement, s: the averaging window of its temperatures.
    pub measurement_s: f64,
    /// The sensor table, with the calibrations and filters applied to the log.
    pub sensors: SensorTable,
    /// The run file the readings came from (for messages).
    pub runs_path: PathBuf,
    /// The temperature log as read (°C, before calibration).
    pub raw_log: TemperatureLog,
    /// Processed temperatures (calibrated, denoised).
    pub log: ProcessedLog,
    /// Measurements sorted by time; the first is the cold one.
    pub measurements: Vec<Measurement>,
}

/// Path of the campaign file for a folder or a file argument.
pub fn campaign_file_path(arg: &Path) -> PathBuf {
    if arg.is_dir() {
        arg.join("campaign.toml")
    } else {
        arg.to_path_buf()
    }
}

impl Campaign {
    /// Read a campaign folder (or its `campaign.toml`), its run file, sensor table and log.
    pub fn read(arg: &Path) -> Result<Campaign> {
        let file = campaign_file_path(arg);
        let text = errmap_core::io::read_text(&file)?;
        let settings: CampaignFile = toml::from_str(&text).map_err(|e| {
            let line = e
                .span()
                .map(|s| 1 + text[..s.start.min(text.len())].matches('\n').count() as u64);
            Error::input(
                Location {
                    file: file.clone(),
                    line,
                    column: None,
                },
                format!("bad campaign file: {}", e.message()),
                "keys: name, axis, coolant, runs, temperatures, sensors, measurement_s, reference_point_mm",
            )
        })?;
        let dir = file
            .parent()
            .filter(|p| !p.as_os_str().is_empty())
            .map(Path::to_path_buf)
            .unwrap_or_else(|| PathBuf::from("."));
        let name = settings.name.clone().unwrap_or_else(|| {
            dir.canonicalize()
                .ok()
                .and_then(|p| p.file_name().map(|n| n.to_string_lossy().into_owned()))
                .unwrap_or_else(|| "campaign".into())
        });
        if !settings.measurement_s.is_finite() || settings.measurement_s < 0.0 {
            return Err(Error::input(
                Location::file(&file),
                format!(
                    "measurement_s = {} must be zero or more",
                    settings.measurement_s
                ),
                "give the duration of one measurement in seconds",
            ));
        }
        let sensors = SensorTable::read(&dir.join(&settings.sensors))?;
        let raw = TemperatureLog::read(&dir.join(&settings.temperatures), &sensors)?;
        let log = raw.process(&sensors)?;
        let runs_path = dir.join(&settings.runs);
        let timed = super::runs::read_timed_points(&runs_path)?;
        Campaign::assemble(name, dir, &settings, sensors, raw, log, timed, &runs_path)
    }

    /// Group timed laser points into measurements and attach their mean temperatures.
    #[allow(clippy::too_many_arguments)] // every part of a campaign, from files or the store
    pub fn assemble(
        name: String,
        dir: PathBuf,
        settings: &CampaignFile,
        sensors: SensorTable,
        raw_log: TemperatureLog,
        log: ProcessedLog,
        timed: Vec<(f64, LaserPoint)>,
        runs_path: &Path,
    ) -> Result<Campaign> {
        let mut groups: BTreeMap<u64, (f64, Vec<LaserPoint>)> = BTreeMap::new();
        for (time_s, point) in timed {
            // Total order on finite times: the bit pattern of a non-negative-shifted value.
            groups
                .entry(time_key(time_s))
                .or_insert_with(|| (time_s, Vec::new()))
                .1
                .push(point);
        }
        let mut measurements = Vec::with_capacity(groups.len());
        for (_, (time_s, points)) in groups {
            let mut temperatures_c = BTreeMap::new();
            for sensor in &log.sensors {
                let mean = log
                    .mean_over(sensor, time_s, time_s + settings.measurement_s)
                    .ok_or_else(|| {
                        let line = points.first().map(|p| p.line).unwrap_or(0);
                        Error::input(
                            Location::cell(runs_path, line, "time_s"),
                            format!(
                                "the measurement at {time_s} s lies outside the temperature log"
                            ),
                            "log temperatures over the whole campaign, or fix time_s",
                        )
                    })?;
                temperatures_c.insert(sensor.clone(), mean);
            }
            measurements.push(Measurement {
                time_s,
                points,
                temperatures_c,
            });
        }
        if measurements.is_empty() {
            return Err(Error::input(
                Location::file(runs_path),
                "the run file holds no readings",
                "add the laser readings of the campaign",
            ));
        }
        Ok(Campaign {
            name,
            dir,
            axis: settings.axis.clone(),
            coolant: settings.coolant.clone(),
            reference_point_mm: settings.reference_point_mm,
            measurement_s: settings.measurement_s,
            sensors,
            runs_path: runs_path.to_path_buf(),
            raw_log,
            log,
            measurements,
        })
    }
}

/// A key that sorts finite times in numeric order.
pub(crate) fn time_key(t: f64) -> u64 {
    let bits = t.to_bits();
    if t.is_sign_negative() {
        !bits
    } else {
        bits | (1 << 63)
    }
}
