//! `errmap bench live`: the cycle's cost on this machine. A synthetic set-up of N sensors and
//! M axes (the sample model with N gain sensors, one model per axis) replays a log paced at the
//! loop's own rate on the wall clock (`replay_speed = 1`), dry-run, with the store and the
//! state file written every cycle; the figures are the time per cycle (its own work, polling to
//! state file), the process's CPU time per wall-clock second, and the missed cycles.

use super::config::LiveConfig;
use super::cycle::{Live, RunOptions, StopFlags};
use crate::Setting;
use errmap_core::error::{Error, Result};
use errmap_core::setting::words;
use serde::Serialize;
use std::fmt::Write as _;

/// What to measure.
#[derive(Debug, Clone)]
pub struct LiveBench {
    /// Gain sensors of the synthetic model, each a channel of the bench's source.
    pub sensors: usize,
    /// Axes compensated, each with its own copy of the model.
    pub axes: usize,
    /// Cycle rate asked for, Hz.
    pub hz: f64,
    /// How long the bench runs, wall-clock seconds.
    pub seconds: f64,
}

/// The figures.
#[derive(Debug, Clone, Serialize)]
pub struct LiveBenchReport {
    /// Gain sensors, as asked.
    pub sensors: usize,
    /// Axes, as asked.
    pub axes: usize,
    /// Cycle rate, Hz, as asked.
    pub hz: f64,
    /// Cycles the loop counted (missed ones included).
    pub cycles: u64,
    /// Cycles skipped because the loop fell a whole period behind its clock.
    pub missed_cycles: u64,
    /// Mean time of a cycle from polling the sources to the state file, µs.
    pub cycle_mean_us: f64,
    /// Slowest cycle, µs.
    pub cycle_max_us: f64,
    /// Wall-clock time of the run, s.
    pub wall_s: f64,
    /// CPU time of the process over the run (all threads), s.
    pub cpu_s: f64,
    /// CPU seconds per wall-clock second (1.0 = one core busy).
    pub cpu_share_of_one_core: f64,
}

const SAMPLE_MODEL: &str = include_str!("../../../data/thermal-live/model.json");

/// The sample model with `sensors` gain sensors s1…sN (°C, identity calibration, the model's
/// filter), 0.4 µm/m/K each, for axis `axis`.
fn model_json(axis: &str, sensors: usize) -> Result<String> {
    let mut m: serde_json::Value = serde_json::from_str(SAMPLE_MODEL)
        .map_err(|e| Error::Internal(format!("sample model: {e}")))?;
    let names: Vec<String> = (1..=sensors).map(|k| format!("s{k}")).collect();
    m["axis"] = axis.into();
    m["gain_sensors"] = serde_json::json!(names);
    let room = m["sensors"]
        .as_array()
        .and_then(|a| a.iter().find(|s| s["name"] == "room").cloned())
        .ok_or_else(|| Error::Internal("sample model has no room sensor".into()))?;
    let mut defs = vec![room];
    let mut rises = serde_json::Map::new();
    for n in &names {
        defs.push(serde_json::json!({
            "name": n, "role": "other", "unit": "c",
            "calibration": {"offset_c": 0.0, "scale": 1.0},
            "filter": {"median_window": 5, "sg_window": 11, "sg_order": 2}
        }));
        rises.insert(n.clone(), 0.0.into());
    }
    m["sensors"] = defs.into();
    m["reference_rise_c"] = rises.into();
    let gains: serde_json::Map<String, serde_json::Value> =
        names.iter().map(|n| (n.clone(), 0.4.into())).collect();
    if let Some(dirs) = m["directions"].as_array_mut() {
        for d in dirs {
            if let Some(gs) = d["gains"].as_array_mut() {
                for g in gs {
                    g["k_um_per_m_k"] = gains.clone().into();
                    g["k_se_um_per_m_k"] = serde_json::Value::Object(Default::default());
                }
            }
        }
    }
    serde_json::to_string(&m).map_err(|e| Error::Internal(format!("model JSON: {e}")))
}

/// Run the bench in a temporary folder.
pub fn run(b: &LiveBench) -> Result<LiveBenchReport> {
    if !(b.sensors >= 1
        && b.axes >= 1
        && b.axes <= 9
        && b.hz > 0.0
        && b.hz <= 1000.0
        && b.seconds > 0.0)
    {
        return Err(Error::usage(
            "the bench needs ≥ 1 sensor, 1 … 9 axes, 0 < hz ≤ 1000 and seconds > 0",
            format!(
                "e.g. {} 16 {} 3 {} 100 {} 10",
                words(Setting::Sensors),
                words(Setting::Axes),
                words(Setting::Hz),
                words(Setting::Seconds)
            ),
        ));
    }
    let dir = tempfile::tempdir()
        .map_err(|e| Error::io("create a temporary folder in", std::env::temp_dir(), e))?;
    let d = dir.path();
    let axes: Vec<String> = ["X", "Y", "Z", "U", "V", "W", "A", "B", "C"][..b.axes]
        .iter()
        .map(|s| s.to_string())
        .collect();
    let write = |name: &str, text: &str| {
        std::fs::write(d.join(name), text).map_err(|e| Error::write(d.join(name), e))
    };
    for a in &axes {
        write(&format!("model_{a}.json"), &model_json(a, b.sensors)?)?;
    }
    let rows = (b.seconds * b.hz).ceil() as usize + 1;
    let mut log = String::from("time_s,position_mm,direction,room,coolant");
    for k in 1..=b.sensors {
        let _ = write!(log, ",s{k}");
    }
    log.push('\n');
    for i in 0..rows {
        let t = i as f64 / b.hz;
        let (x, dir) = super::replay::motion(t, 500.0, 3000.0);
        let _ = write!(log, "{t:.4},{x:.3},{dir},{:.3},on", 20.0 + 0.001 * t);
        for k in 1..=b.sensors {
            let _ = write!(log, ",{:.3}", 22.0 + 0.1 * k as f64 + 0.01 * t);
        }
        log.push('\n');
    }
    write("log.csv", &log)?;
    let period_ms = (1000.0 / b.hz).round().max(1.0) as u64;
    let mut cfg = format!(
        "[loop]\nperiod_ms = {period_ms}\nreplay_speed = 1\n\n[store]\npath = \"live.sqlite\"\n\n\
         [[sources]]\nname = \"log\"\nkind = \"csv\"\npath = \"log.csv\"\ntimeout_ms = {}\nramp_timeout_ms = {}\n\n\
         [sensors.room]\nchannel = \"log.room\"\n\n[coolant]\nchannel = \"log.coolant\"\n\n",
        period_ms * 5,
        period_ms * 50
    );
    for k in 1..=b.sensors {
        let _ = write!(cfg, "[sensors.s{k}]\nchannel = \"log.s{k}\"\n\n");
    }
    for a in &axes {
        let _ = write!(
            cfg,
            "[[axes]]\nname = \"{a}\"\nmodel = \"model_{a}.json\"\nposition = \"log.position_mm\"\n\
             direction = \"log.direction\"\nlimit_um = 500\nslope_limit_um_per_m = 1000\nrate_limit_um_s = 100\n\n"
        );
    }
    write("live.toml", &cfg)?;
    let config = LiveConfig::read(&d.join("live.toml"))?;
    let options = RunOptions {
        dry_run: true,
        once: false,
        state: Some(d.join("state.json")),
    };
    let mut live = Live::prepare(&config, &options, Vec::new())?;
    let cpu0 = cpu_time::ProcessTime::now();
    let wall0 = std::time::Instant::now();
    let summary = live.run(&StopFlags::new(), &|_| {})?;
    let wall_s = wall0.elapsed().as_secs_f64();
    let cpu_s = cpu0.elapsed().as_secs_f64();
    Ok(LiveBenchReport {
        sensors: b.sensors,
        axes: b.axes,
        hz: b.hz,
        cycles: summary.cycles,
        missed_cycles: summary.missed_cycles,
        cycle_mean_us: summary.cycle_mean_us,
        cycle_max_us: summary.cycle_max_us,
        wall_s,
        cpu_s,
        cpu_share_of_one_core: cpu_s / wall_s,
    })
}
