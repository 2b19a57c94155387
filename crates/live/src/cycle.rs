//! The live loop: every cycle it polls the sources, applies operators' commands, checks and
//! filters every reading, evaluates each axis's model, applies the safety rules, writes the
//! targets, logs the cycle into the store and rewrites the state file.
//!
//! Safety rules (docs/live.md, Safety):
//! - a source silent past its `timeout_ms`, an implausible reading, an unknown coolant state,
//!   a missing position or a value beyond an axis's bounds: the values are **held**;
//! - a source silent past its `ramp_timeout_ms`, or a reading implausible that long: every
//!   axis **ramps to zero** at its rate limit and an alarm is raised; the loop stays at zero
//!   until the causes are gone and every alarm is acknowledged;
//! - the written line moves toward the model's at most `rate_limit_um_s` anywhere on the
//!   travel, also at the start (from the controller's present value) and on the way to zero;
//! - SIGTERM/SIGINT (or the end of a replay) leave the targets as `loop.on_stop` says.

use super::alarms::Alarms;
use super::axis::{AxisModel, Limits, Line};
use super::config::{ChannelRef, FilterChoice, LiveConfig, OnStop, SensorConfig, SourceKind};
use super::filter::CausalFilter;
use super::log::{CycleRecord, LinkSettings, StoreLink};
use super::plausibility;
use super::source::{csv::CsvSource, Source, Value};
use super::state::{self, AxisState, Mode, SensorState, SourceState, State, StateWriter};
use super::target::{Output, Present, Target};
use super::{LinkError, LiveError};
use crate::Setting;
use errmap_core::direction::Direction;
use errmap_core::error::{Error, Result};
use errmap_core::setting::words;
use errmap_metrology::thermal::model::{ThermalModel, ThermalState};
use errmap_metrology::thermal::sensors::Sensor;
use serde_json::{json, Map, Value as Json};
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant, SystemTime};

/// How a run is asked for.
#[derive(Debug, Clone, Default)]
pub struct RunOptions {
    /// Compute and log only: no target is contacted or written.
    pub dry_run: bool,
    /// One cycle, written at once without the start ramp.
    pub once: bool,
    /// The state file for the monitor.
    pub state: Option<PathBuf>,
}

/// What a run did.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct RunSummary {
    /// Cycles counted in the run, the missed ones included (the loop's last cycle number + 1).
    pub cycles: u64,
    /// Why the run stopped: "stopped by SIGTERM", "stopped by SIGINT", "end of the replay data",
    /// or "--once".
    pub stop_reason: String,
    /// The store campaign the run's temperatures were logged under (`live-<start time>`).
    pub campaign: String,
    /// Cycles skipped because the loop fell more than a whole period behind its clock.
    pub missed_cycles: u64,
    /// Alarms raised during the run.
    pub alarms_raised: u64,
    /// Time a cycle took from polling the sources to the state file, mean, µs.
    pub cycle_mean_us: f64,
    /// Time the slowest cycle took from polling the sources to the state file, µs.
    pub cycle_max_us: f64,
    /// The mode of the last cycle (`stopped`, or the cycle's own mode with `--once`).
    pub final_mode: &'static str,
}

/// Stop requests: SIGTERM, SIGINT (registered with [`StopFlags::register_signals`]) or a caller.
#[derive(Debug, Clone, Default)]
pub struct StopFlags {
    term: Arc<AtomicBool>,
    int: Arc<AtomicBool>,
}

impl StopFlags {
    /// Flags with no stop requested; signals are not yet registered.
    pub fn new() -> StopFlags {
        StopFlags::default()
    }

    /// Set the flags from SIGTERM and SIGINT (the default actions are replaced).
    pub fn register_signals(&self) -> Result<(), LiveError> {
        use signal_hook::consts::{SIGINT, SIGTERM};
        for (sig, flag) in [(SIGTERM, &self.term), (SIGINT, &self.int)] {
            signal_hook::flag::register(sig, flag.clone()).map_err(|e| {
                LiveError::Internal(Error::Internal(format!(
                    "cannot install the handler of signal {sig}: {e}"
                )))
            })?;
        }
        Ok(())
    }

    /// Ask the loop to stop as if by SIGTERM.
    pub fn request(&self) {
        self.term.store(true, Ordering::SeqCst);
    }

    /// The stop asked for, if any: `SIGTERM` (also a caller's [`request`](StopFlags::request)) or
    /// `SIGINT`, SIGTERM winning when both are set.
    pub fn reason(&self) -> Option<&'static str> {
        if self.term.load(Ordering::SeqCst) {
            Some("SIGTERM")
        } else if self.int.load(Ordering::SeqCst) {
            Some("SIGINT")
        } else {
            None
        }
    }
}

/// A model sensor in the loop.
struct SensorSlot {
    def: Sensor,
    cfg: SensorConfig,
    source: usize,
    channel: String,
    filter: CausalFilter,
    last_seq: u64,
    last_accepted: Option<(f64, f64)>,
    /// The value the model uses (calibrated, filtered, °C).
    value_c: Option<f64>,
    raw: Option<f64>,
    age_s: Option<f64>,
    problem: Option<String>,
    problem_since_s: Option<f64>,
}

/// A source in the loop with its timeouts.
struct SourceSlot {
    source: Box<dyn Source>,
    timeout_s: f64,
    ramp_timeout_s: f64,
    silent_since_s: Option<f64>,
}

/// An axis in the loop.
struct AxisSlot {
    model: AxisModel,
    position: Option<(usize, String)>,
    direction: Option<(usize, String)>,
    /// A number on the direction channel within ±this is standstill.
    direction_deadband: f64,
    /// Indices into the sensor slots of the model's gain sensors (model order) and ambient.
    gain_sensors: Vec<usize>,
    ambient: Option<usize>,
    target: Option<usize>,
    target_name: String,
    written: Line,
    last_direction: Option<Direction>,
    /// What the target last took (a write is skipped while it would be the same).
    last_output: Option<Output>,
}

/// The coolant state's channel and the model labels of its two states.
struct CoolantSlot {
    source: usize,
    channel: String,
    on: String,
    off: String,
}

/// Everything the loop holds.
pub struct Live {
    period_s: f64,
    period_ms: u64,
    on_stop: OnStop,
    stop_ramp_s: f64,
    replay_speed: Option<f64>,
    write_retries: u32,
    retention_s: f64,
    dry_run: bool,
    once: bool,
    sensors: Vec<SensorSlot>,
    sources: Vec<SourceSlot>,
    axes: Vec<AxisSlot>,
    coolant: Option<CoolantSlot>,
    targets: Vec<Box<dyn Target>>,
    alarms: Alarms,
    paused: bool,
    /// Ramp to zero latched by a source or sensor past its ramp timeout.
    ramp_latched: bool,
    starting: bool,
    link: StoreLink,
    state_writer: Option<StateWriter>,
    start_wall: SystemTime,
    t0_s: f64,
    cycle: u64,
    missed: u64,
    coolant_label: Option<String>,
}

fn sensor_filter(def: &Sensor, cfg: &SensorConfig) -> Result<CausalFilter> {
    CausalFilter::new(match cfg.filter {
        FilterChoice::Model => Some(def.filter),
        FilterChoice::None => None,
    })
}

/// Each axis's model file, checked to be of that axis.
fn read_models(config: &LiveConfig) -> Result<Vec<ThermalModel>, LiveError> {
    let mut models = Vec::new();
    for (i, a) in config.axes.iter().enumerate() {
        let model = ThermalModel::read(&config.resolve(&a.model)).map_err(LiveError::model)?;
        if model.axis != a.name {
            return Err(LiveError::Config(config.key_error(
                &format!("axes.{i}.model"),
                format!("the model is of axis '{}', not '{}'", model.axis, a.name),
                "give the model `errmap thermal fit` wrote for this axis",
            )));
        }
        models.push(model);
    }
    Ok(models)
}

/// The sensors the models need (gain sensors and ambient, each once, in model order), checked
/// against the config's `[sensors.*]` both ways and across the models.
fn model_sensors(config: &LiveConfig, models: &[ThermalModel]) -> Result<Vec<Sensor>> {
    let mut defs: Vec<Sensor> = Vec::new();
    for (i, m) in models.iter().enumerate() {
        for name in m.gain_sensors.iter().chain(m.ambient_sensor.iter()) {
            let def = m
                .sensors
                .iter()
                .find(|s| &s.name == name)
                .cloned()
                .ok_or_else(|| Error::Internal(format!("model lacks sensor '{name}'")))?;
            match defs.iter().find(|d| d.name == def.name) {
                Some(d) if d.unit != def.unit || d.calibration != def.calibration => {
                    return Err(config.key_error(
                        &format!("axes.{i}.model"),
                        format!("sensor '{name}' has another unit or calibration than in an earlier axis's model"),
                        "fit the axes' models with the same sensor table",
                    ))
                }
                Some(_) => {}
                None => {
                    if !config.sensors.contains_key(name) {
                        return Err(config.key_error(
                            "sensors",
                            format!("the model of axis {} needs sensor '{name}'", config.axes[i].name),
                            format!("add [sensors.{name}] with its channel = \"source.channel\""),
                        ));
                    }
                    defs.push(def);
                }
            }
        }
    }
    for name in config.sensors.keys() {
        if !defs.iter().any(|d| &d.name == name) {
            return Err(config.key_error(
                &format!("sensors.{name}"),
                format!("no axis's model has a sensor '{name}'"),
                format!(
                    "the models' sensors: {}",
                    defs.iter()
                        .map(|d| d.name.as_str())
                        .collect::<Vec<_>>()
                        .join(", ")
                ),
            ));
        }
    }
    Ok(defs)
}

/// A `[coolant]` channel is needed when a model has gains for more than one coolant state;
/// `--once` takes live readings, which a replay does not have.
fn check_coolant_and_once(
    config: &LiveConfig,
    options: &RunOptions,
    models: &[ThermalModel],
) -> Result<()> {
    if config.coolant.is_none() {
        if let Some((i, m)) = models
            .iter()
            .enumerate()
            .find(|(_, m)| m.coolant_states.len() > 1)
        {
            return Err(config.key_error(
                "coolant",
                format!(
                    "the model of axis {} has gains for coolant {}; the loop needs the coolant state",
                    config.axes[i].name,
                    m.coolant_states.join(", ")
                ),
                "add [coolant] with channel = \"source.channel\"",
            ));
        }
    }
    if options.once && config.cycle.replay_speed.is_some() {
        return Err(Error::usage(
            format!(
                "{} takes one cycle of live readings; a replay has no present value",
                words(Setting::Once)
            ),
            format!(
                "remove loop.replay_speed, or run the replay without {}",
                words(Setting::Once)
            ),
        ));
    }
    Ok(())
}

/// Open every source (one that cannot be reached is exit 3).
fn open_sources(config: &LiveConfig) -> Result<Vec<SourceSlot>, LiveError> {
    let replay = config.cycle.replay_speed.is_some();
    let mut sources = Vec::new();
    for (index, s) in config.sources.iter().enumerate() {
        let source: Box<dyn Source> = match s.kind {
            SourceKind::Csv => {
                let path = config.resolve(s.path.as_deref().unwrap_or(std::path::Path::new("-")));
                Box::new(
                    CsvSource::open(
                        &s.name,
                        &path,
                        s.follow.unwrap_or(false),
                        replay,
                        s.timeout_ms,
                    )
                    .map_err(LiveError::source)?,
                )
            }
            other => super::connect_source(config, index, s, other).map_err(LiveError::Source)?,
        };
        sources.push(SourceSlot {
            source,
            timeout_s: s.timeout_ms as f64 / 1000.0,
            ramp_timeout_s: s.ramp_timeout_ms as f64 / 1000.0,
            silent_since_s: None,
        });
    }
    Ok(sources)
}

/// The (source index, channel) a `source.channel` reference held by `key` names, checked
/// against the channels the opened source delivers.
fn find_channel(
    config: &LiveConfig,
    sources: &[SourceSlot],
    key: &str,
    text: &str,
) -> Result<(usize, String)> {
    let r: ChannelRef = config.channel_ref(key, text)?;
    let i = config
        .sources
        .iter()
        .position(|s| s.name == r.source)
        .ok_or_else(|| Error::Internal(format!("source {} vanished", r.source)))?;
    let names = sources[i].source.channel_names();
    if !names.iter().any(|n| n == &r.channel) {
        return Err(config.key_error(
            key,
            format!("source '{}' has no channel '{}'", r.source, r.channel),
            format!("its channels: {}", names.join(", ")),
        ));
    }
    Ok((i, r.channel))
}

/// A slot per model sensor, on its configured channel.
fn sensor_slots(
    config: &LiveConfig,
    defs: Vec<Sensor>,
    sources: &[SourceSlot],
) -> Result<Vec<SensorSlot>> {
    let mut sensors = Vec::new();
    for def in defs {
        let cfg = config.sensors[&def.name].clone();
        let key = format!("sensors.{}.channel", def.name);
        let (source, channel) = find_channel(config, sources, &key, &cfg.channel)?;
        sensors.push(SensorSlot {
            filter: sensor_filter(&def, &cfg)?,
            def,
            cfg,
            source,
            channel,
            last_seq: 0,
            last_accepted: None,
            value_c: None,
            raw: None,
            age_s: None,
            problem: None,
            problem_since_s: None,
        });
    }
    Ok(sensors)
}

/// The coolant channel, when configured.
fn coolant_slot(config: &LiveConfig, sources: &[SourceSlot]) -> Result<Option<CoolantSlot>> {
    let Some(c) = &config.coolant else {
        return Ok(None);
    };
    let (source, channel) = find_channel(config, sources, "coolant.channel", &c.channel)?;
    Ok(Some(CoolantSlot {
        source,
        channel,
        on: c.on.clone(),
        off: c.off.clone(),
    }))
}

/// The connected target axis `i` writes to (None in a dry run); a point target needs the
/// axis's position.
fn axis_target(
    config: &LiveConfig,
    options: &RunOptions,
    i: usize,
    has_position: bool,
    targets: &[Box<dyn Target>],
) -> Result<Option<usize>> {
    if options.dry_run {
        return Ok(None);
    }
    let a = &config.axes[i];
    let name = a.target.as_deref().ok_or_else(|| {
        config.key_error(
            &format!("axes.{i}"),
            format!("axis {} has no target", a.name),
            format!(
                "name a [[targets]] entry with target = \"…\", or run with {}",
                words(Setting::DryRun)
            ),
        )
    })?;
    let t = targets
        .iter()
        .position(|t| t.name() == name)
        .ok_or_else(|| Error::Internal(format!("target {name} was not connected")))?;
    if targets[t].is_point() && !has_position {
        return Err(config.key_error(
            &format!("axes.{i}.target"),
            format!("target '{name}' writes the value at the axis's position, but axis {} has no position channel", a.name),
            "add position = \"source.channel\" to the axis",
        ));
    }
    Ok(Some(t))
}

/// A slot per axis: its model with the configured limits, channels, sensors and target.
fn axis_slots(
    config: &LiveConfig,
    options: &RunOptions,
    models: Vec<ThermalModel>,
    sensors: &[SensorSlot],
    sources: &[SourceSlot],
    targets: &[Box<dyn Target>],
) -> Result<Vec<AxisSlot>> {
    let mut axes = Vec::new();
    for (i, (a, model)) in config.axes.iter().zip(models).enumerate() {
        let channel = |k: &str, text: &Option<String>| -> Result<Option<(usize, String)>> {
            text.as_deref()
                .map(|t| find_channel(config, sources, &format!("axes.{i}.{k}"), t))
                .transpose()
        };
        let position = channel("position", &a.position)?;
        let direction = channel("direction", &a.direction)?;
        let index = |name: &str| sensors.iter().position(|s| s.def.name == name);
        let gain_sensors = model
            .gain_sensors
            .iter()
            .map(|n| index(n).ok_or_else(|| Error::Internal(format!("sensor {n} missing"))))
            .collect::<Result<Vec<_>>>()?;
        let ambient = model.ambient_sensor.as_deref().and_then(index);
        let target = axis_target(config, options, i, position.is_some(), targets)?;
        let target_name = match (options.dry_run, &a.target) {
            (true, _) => "dry-run".to_string(),
            (false, Some(t)) => t.clone(),
            (false, None) => String::new(),
        };
        axes.push(AxisSlot {
            model: AxisModel::new(
                a.name.clone(),
                model,
                Limits {
                    limit_um: a.limit_um,
                    slope_limit_um_per_m: a.slope_limit_um_per_m,
                    rate_limit_um_s: a.rate_limit_um_s,
                },
                a.include_geometric,
            ),
            position,
            direction,
            direction_deadband: a.direction_deadband,
            gain_sensors,
            ambient,
            target,
            target_name,
            written: Line::default(),
            last_direction: None,
            last_output: None,
        });
    }
    Ok(axes)
}

/// The run's record: the store (its campaign named by the start time) and the state file.
fn open_record(
    config: &LiveConfig,
    options: &RunOptions,
    sensors: &[SensorSlot],
    axes: &[AxisSlot],
    start_wall: SystemTime,
) -> Result<(StoreLink, Option<StateWriter>), LiveError> {
    let start_utc = state::utc_ms(start_wall);
    let logged: Vec<Sensor> = sensors.iter().map(|s| s.def.clone()).collect();
    let link = StoreLink::open(LinkSettings {
        path: &config.resolve(&config.store.path),
        campaign: format!("live-{start_utc}"),
        axis: &axes[0].model.name,
        px_mm: axes[0].model.px_mm(),
        sensors: &logged,
        start_utc: &start_utc,
        now_unix: start_wall
            .duration_since(SystemTime::UNIX_EPOCH)
            .map_or(0, |d| d.as_secs() as i64),
    })
    .map_err(LiveError::record)?;
    let state_writer = match &options.state {
        Some(p) => Some(StateWriter::new(p).map_err(LiveError::record)?),
        None => None,
    };
    Ok((link, state_writer))
}

impl Live {
    /// Check the config against the models and sources, open the sources, the targets and the
    /// store. Nothing is written to a target here.
    pub fn prepare(
        config: &LiveConfig,
        options: &RunOptions,
        targets: Vec<Box<dyn Target>>,
    ) -> Result<Live, LiveError> {
        let models = read_models(config)?;
        let defs = model_sensors(config, &models)?;
        check_coolant_and_once(config, options, &models)?;
        let sources = open_sources(config)?;
        let sensors = sensor_slots(config, defs, &sources)?;
        let coolant = coolant_slot(config, &sources)?;
        let axes = axis_slots(config, options, models, &sensors, &sources, &targets)?;
        let start_wall = SystemTime::now();
        let (link, state_writer) = open_record(config, options, &sensors, &axes, start_wall)?;
        Ok(Live {
            period_s: config.cycle.period_ms as f64 / 1000.0,
            period_ms: config.cycle.period_ms,
            on_stop: config.cycle.on_stop,
            stop_ramp_s: config.cycle.stop_ramp_s,
            replay_speed: config.cycle.replay_speed,
            write_retries: config.cycle.write_retries,
            retention_s: config.store.retention_days * 86_400.0,
            dry_run: options.dry_run,
            once: options.once,
            sensors,
            sources,
            axes,
            coolant,
            targets,
            alarms: Alarms::default(),
            paused: false,
            ramp_latched: false,
            starting: true,
            link,
            state_writer,
            start_wall,
            t0_s: 0.0,
            cycle: 0,
            missed: 0,
            coolant_label: None,
        })
    }

    /// The store campaign of this run.
    pub fn campaign(&self) -> &str {
        &self.link.campaign
    }

    fn utc_at(&self, t_s: f64) -> String {
        let dt = (t_s - self.t0_s).max(0.0);
        state::utc_ms(self.start_wall + Duration::from_secs_f64(dt))
    }

    /// Wait for the first reading of every source (a source that sends nothing within its
    /// timeout cannot be reached: exit 3), and read the targets' present values.
    fn start(&mut self) -> Result<(), LiveError> {
        if self.replay_speed.is_some() {
            self.t0_s = self
                .sources
                .iter()
                .filter_map(|s| s.source.replay_start_s())
                .fold(f64::NEG_INFINITY, f64::max);
            if !self.t0_s.is_finite() {
                return Err(LiveError::Source(LinkError::Unreachable(Error::io(
                    "replay",
                    "the CSV sources",
                    std::io::Error::other("no data row to replay"),
                ))));
            }
            for s in &mut self.sources {
                s.source.poll(self.t0_s);
            }
        } else {
            let begun = Instant::now();
            loop {
                let now = begun.elapsed().as_secs_f64();
                let mut waiting = None;
                for s in &mut self.sources {
                    s.source.poll(0.0);
                    if s.source.snapshot().last_ok_s.is_none() {
                        waiting = Some((
                            s.source.name().to_string(),
                            s.timeout_s,
                            s.source.snapshot().problem.clone(),
                        ));
                    }
                }
                match waiting {
                    None => break,
                    Some((name, timeout, problem)) if now > timeout => {
                        return Err(LiveError::Source(LinkError::Unreachable(Error::io(
                            "reach",
                            format!("source '{name}'"),
                            std::io::Error::new(
                                std::io::ErrorKind::TimedOut,
                                format!(
                                    "no reading within its timeout of {:.0} ms at start{}",
                                    timeout * 1000.0,
                                    problem.map(|p| format!(" ({p})")).unwrap_or_default()
                                ),
                            ),
                        ))));
                    }
                    Some(_) => std::thread::sleep(Duration::from_millis(5)),
                }
            }
        }
        // The start ramps from what the controller holds now (a dry run starts from zero).
        for a in 0..self.axes.len() {
            let Some(t) = self.axes[a].target else {
                continue;
            };
            if self.once {
                continue;
            }
            let present = self.targets[t]
                .present(&self.axes[a].model.name)
                .map_err(LiveError::target)?;
            self.axes[a].written = self.line_of_present(&self.axes[a], present);
        }
        Ok(())
    }

    /// The thermal line a controller's present compensation stands for, which the loop ramps
    /// from.
    fn line_of_present(&self, a: &AxisSlot, present: Present) -> Line {
        match present {
            Present::Line(l) => l,
            Present::K3 {
                abs_mm,
                slope,
                reference_mm,
            } => super::target::opcua::line_of_k3(abs_mm, slope, reference_mm, a.model.px_mm()),
            Present::Value(v) => {
                // A point target: its value as an offset of the thermal line (the geometric
                // part, when carried, is not ramped).
                let geometric = a
                    .position
                    .as_ref()
                    .and_then(|(s, c)| self.sources[*s].source.snapshot().channels.get(c))
                    .and_then(|r| r.value.as_number())
                    .filter(|_| a.model.include_geometric)
                    .map_or(0.0, |x| {
                        -0.5 * (a.model.model.geometric_um(Direction::Forward, x)
                            + a.model.model.geometric_um(Direction::Reverse, x))
                    });
                Line {
                    offset_um: v - geometric,
                    slope_um_per_m: 0.0,
                }
            }
        }
    }

    /// A target whose value changed under errmap (a LinuxCNC machine-off/on zeroes its external
    /// offsets): the axis ramps from the controller's present value as at a start, and an alarm
    /// says so until the controller takes errmap's values again. A failed read is left to the
    /// write that follows, which reports it.
    fn resync_axis(&mut self, a: usize, utc: &str, notes: &mut Vec<String>) {
        let Some(t) = self.axes[a].target else { return };
        let name = self.axes[a].model.name.clone();
        let key = format!("moved:{name}");
        let present = match self.targets[t].moved(&name) {
            Ok(Some(present)) => present,
            Ok(None) => return self.alarms.clear(&key),
            Err(_) => return,
        };
        let line = self.line_of_present(&self.axes[a], present);
        let axis = &mut self.axes[a];
        let message = format!(
            "{name}: {} holds {:.4} µm at Px, not the {:.4} µm errmap wrote (machine off/on, offsets cleared or not taken): ramping from its value",
            self.targets[t].name(),
            line.offset_um,
            axis.written.offset_um,
        );
        axis.written = line;
        axis.last_output = None;
        self.starting = true;
        if let Some(id) = self
            .alarms
            .raise(&key, self.targets[t].name(), message.clone(), utc)
        {
            notes.push(format!("alarm {id} raised: {message}"));
        }
    }

    /// Run until stopped (or one cycle with `once`).
    pub fn run(&mut self, stop: &StopFlags, notes: &dyn Fn(&str)) -> Result<RunSummary, LiveError> {
        self.start()?;
        if self.once {
            notes(&format!(
                "{}: one cycle, written without the start ramp",
                words(Setting::Once)
            ));
        }
        let wall_start = Instant::now();
        let mut stopping: Option<(String, f64)> = None;
        let mut final_mode;
        // (sum µs, largest µs, cycles) of the cycles' own work
        let mut timed = (0.0f64, 0.0f64, 0u64);
        loop {
            let t = self.t0_s + self.cycle as f64 * self.period_s;
            // Pace the cycle: the wall clock, a time-accelerated replay, or as fast as it runs.
            let pace = match self.replay_speed {
                None => Some(1.0),
                Some(s) if s > 0.0 => Some(s),
                Some(_) => None,
            };
            if let Some(speed) = pace {
                let due = Duration::from_secs_f64((t - self.t0_s) / speed);
                let now = wall_start.elapsed();
                if due > now {
                    std::thread::sleep(due - now);
                } else if now - due > Duration::from_secs_f64(self.period_s / speed)
                    && self.cycle > 0
                {
                    // Later than a whole period: the cycles in between are missed; catch up.
                    let behind = ((now - due).as_secs_f64() * speed / self.period_s) as u64;
                    self.missed += behind;
                    self.cycle += behind;
                    continue;
                }
            }
            let began = Instant::now();
            for s in &mut self.sources {
                s.source.poll(t);
            }
            let mut notes_of_cycle: Vec<String> = Vec::new();
            if stopping.is_none() {
                if let Some(sig) = stop.reason() {
                    stopping = Some((format!("stopped by {sig}"), t));
                } else if self.replay_speed.is_some()
                    && self.sources.iter().all(|s| s.source.finished())
                {
                    stopping = Some(("end of the replay data".to_string(), t));
                }
                if let Some((why, _)) = &stopping {
                    notes_of_cycle.push(format!(
                        "{why}: targets {}",
                        match self.on_stop {
                            OnStop::Hold => "held at their last values",
                            OnStop::RampToZero => "ramping to zero",
                        }
                    ));
                }
            }
            let stop_goal = stopping.as_ref().map(|_| self.on_stop);
            let mode = self.step(t, stop_goal, &mut notes_of_cycle)?;
            let mut done = self.once;
            if let Some((why, since)) = &stopping {
                let at_zero = self.axes.iter().all(|a| a.written == Line::default());
                done = match self.on_stop {
                    OnStop::Hold => true,
                    OnStop::RampToZero if at_zero => true,
                    OnStop::RampToZero if t - since >= self.stop_ramp_s => {
                        notes_of_cycle.push(format!(
                            "{why}: not at zero after {} s (loop.stop_ramp_s): values held",
                            self.stop_ramp_s
                        ));
                        true
                    }
                    OnStop::RampToZero => false,
                };
                if done && self.on_stop == OnStop::RampToZero && at_zero {
                    notes_of_cycle.push(format!("{why}: targets at zero"));
                }
            }
            let mode = if done && !self.once {
                Mode::Stopped
            } else {
                mode
            };
            final_mode = mode;
            self.record(
                t,
                mode,
                notes_of_cycle,
                stopping.as_ref().filter(|_| done).map(|s| s.0.clone()),
            )
            .map_err(LiveError::record)?;
            let took_us = began.elapsed().as_secs_f64() * 1e6;
            timed.0 += took_us;
            timed.1 = timed.1.max(took_us);
            timed.2 += 1;
            self.cycle += 1;
            if done {
                break;
            }
        }
        self.link.close().map_err(LiveError::record)?;
        if let Some(w) = self.state_writer.as_mut() {
            w.close().map_err(LiveError::record)?;
        }
        Ok(RunSummary {
            cycles: self.cycle,
            stop_reason: stopping
                .map(|s| s.0)
                .unwrap_or_else(|| words(Setting::Once)),
            campaign: self.link.campaign.clone(),
            missed_cycles: self.missed,
            alarms_raised: self.alarms.raised(),
            cycle_mean_us: timed.0 / timed.2.max(1) as f64,
            cycle_max_us: timed.1,
            final_mode: final_mode.name(),
        })
    }

    /// One cycle's decisions and writes; returns the mode. The stages: operators' commands,
    /// the sources' watchdog, the sensors' readings, the coolant state, the ramp-to-zero latch,
    /// then each axis's line moved toward its goal and written.
    fn step(&mut self, t: f64, stop_goal: Option<OnStop>, notes: &mut Vec<String>) -> Result<Mode> {
        let ramp_stop = stop_goal == Some(OnStop::RampToZero);
        let hold_stop = stop_goal == Some(OnStop::Hold);
        let utc = self.utc_at(t);
        self.apply_commands(&utc, notes);
        let (sources_hold, sources_ramp) = self.watch_sources(t, &utc, notes);
        let (sensors_hold, sensors_ramp) = self.take_readings(t, &utc, notes);
        let coolant_missing = !self.read_coolant();
        let hold = sources_hold || sensors_hold || coolant_missing;
        self.latch_ramp(sources_ramp || sensors_ramp, hold, notes);
        let (all_reached, any_held) = self.step_axes(hold || hold_stop, ramp_stop, &utc, notes);

        let ramping = ramp_stop || self.ramp_latched;
        if self.starting && all_reached && !hold && !ramping {
            self.starting = false;
        }
        Ok(if ramping {
            Mode::RampingToZero
        } else if self.paused {
            Mode::Paused
        } else if hold || any_held {
            Mode::Holding
        } else if self.starting {
            Mode::Starting
        } else {
            Mode::Running
        })
    }

    /// The watchdog: a source silent past its timeout holds, past its ramp timeout it raises
    /// an alarm and asks for the ramp to zero. Returns (hold, ramp cause).
    fn watch_sources(&mut self, t: f64, utc: &str, notes: &mut Vec<String>) -> (bool, bool) {
        let mut hold = false;
        let mut ramp_cause = false;
        for s in &mut self.sources {
            let snap = s.source.snapshot();
            let age = snap.last_ok_s.map_or(f64::INFINITY, |at| t - at);
            let name = s.source.name().to_string();
            let key = format!("source:{name}");
            if age > s.timeout_s {
                hold = true;
                s.silent_since_s.get_or_insert(t);
                if age > s.ramp_timeout_s {
                    ramp_cause = true;
                    if let Some(id) = self.alarms.raise(
                        &key,
                        &name,
                        format!(
                            "{name} silent for {:.1} s (ramp timeout {:.1} s): ramping to zero",
                            age, s.ramp_timeout_s
                        ),
                        utc,
                    ) {
                        notes.push(format!(
                            "alarm {id} raised: {name} silent past its ramp timeout"
                        ));
                    }
                }
            } else {
                s.silent_since_s = None;
                self.alarms.clear(&key);
            }
        }
        (hold, ramp_cause)
    }

    /// Every sensor's new reading checked, calibrated and filtered; an implausible one raises
    /// an alarm. Returns (hold: a sensor without a good value, ramp cause: one implausible past
    /// its source's ramp timeout).
    fn take_readings(&mut self, t: f64, utc: &str, notes: &mut Vec<String>) -> (bool, bool) {
        for s in self.sensors.iter_mut() {
            let src = &self.sources[s.source];
            let Some(r) = src.source.snapshot().channels.get(&s.channel) else {
                s.problem = Some(format!("{} has no reading", s.def.name));
                continue;
            };
            s.age_s = Some(t - r.at_s);
            if r.seq == s.last_seq {
                continue;
            }
            s.last_seq = r.seq;
            let raw = r.value.as_number();
            s.raw = raw;
            let checked = match raw {
                None => Err(plausibility::Implausible {
                    kind: "range",
                    message: format!("{} reading {:?} is not a number", s.def.name, r.value),
                }),
                Some(raw) => match s.def.unit.to_celsius(raw) {
                    Err(_) => Err(plausibility::unconvertible(&s.def.name, raw)),
                    Ok(c) => {
                        let value = s.def.calibration.apply(c);
                        plausibility::check(&s.def.name, &s.cfg, value, r.at_s, s.last_accepted)
                            .map(|()| value)
                    }
                },
            };
            let key = format!("sensor:{}", s.def.name);
            match checked {
                Ok(v) => {
                    s.last_accepted = Some((r.at_s, v));
                    s.value_c = Some(s.filter.push(v));
                    s.problem = None;
                    s.problem_since_s = None;
                    self.alarms.clear(&key);
                }
                Err(bad) => {
                    s.problem = Some(bad.message.clone());
                    s.problem_since_s.get_or_insert(t);
                    let source = src.source.name().to_string();
                    if let Some(id) = self.alarms.raise(&key, &source, bad.message.clone(), utc) {
                        notes.push(format!("alarm {id} raised: {}", bad.message));
                    }
                }
            }
        }
        let mut hold = false;
        let mut ramp_cause = false;
        for s in &self.sensors {
            if s.problem.is_some() || s.value_c.is_none() {
                hold = true;
            }
            if let Some(since) = s.problem_since_s {
                if t - since > self.sources[s.source].ramp_timeout_s {
                    ramp_cause = true;
                }
            }
        }
        (hold, ramp_cause)
    }

    /// The coolant state's label this cycle (a bit, a number ≠ 0 or the label itself); false
    /// when a coolant channel is configured and has no reading (the values are held).
    fn read_coolant(&mut self) -> bool {
        self.coolant_label = None;
        let Some(c) = &self.coolant else {
            return true;
        };
        self.coolant_label = match self.sources[c.source]
            .source
            .snapshot()
            .channels
            .get(&c.channel)
            .map(|r| &r.value)
        {
            Some(Value::Flag(b)) => Some(if *b { c.on.clone() } else { c.off.clone() }),
            Some(Value::Number(v)) => Some(if *v != 0.0 {
                c.on.clone()
            } else {
                c.off.clone()
            }),
            Some(Value::Text(label)) => Some(label.clone()),
            None => return false,
        };
        true
    }

    /// Latch the ramp to zero on a cause; release it once the causes are gone and every alarm
    /// is acknowledged (the way back up is a start: at the rate limit, mode `starting`).
    fn latch_ramp(&mut self, ramp_cause: bool, hold: bool, notes: &mut Vec<String>) {
        if ramp_cause && !self.ramp_latched {
            self.ramp_latched = true;
            notes.push(
                "ramping to zero until the causes are gone and every alarm is acknowledged".into(),
            );
        }
        if self.ramp_latched && !ramp_cause && !hold && self.alarms.all_acknowledged() {
            self.ramp_latched = false;
            self.starting = true;
            notes.push("ramp to zero released: causes gone, alarms acknowledged".into());
        }
    }

    /// Each axis: a target's value changed under errmap taken in, the goal (held, zero or the
    /// model's line within its bounds), one rate-limited step toward it, written. Returns
    /// (every axis reached its goal, any axis held).
    fn step_axes(
        &mut self,
        hold: bool,
        ramp_stop: bool,
        utc: &str,
        notes: &mut Vec<String>,
    ) -> (bool, bool) {
        let dt = if self.once {
            f64::INFINITY
        } else {
            self.period_s
        };
        let mut all_reached = true;
        let mut any_held = false;
        for a in 0..self.axes.len() {
            self.direction_of(a);
            self.resync_axis(a, utc, notes);
            let (goal, held, problem) = self.goal_of(a, hold, ramp_stop);
            if let Some((key, message)) = problem {
                if let Some(id) =
                    self.alarms
                        .raise(&key, &self.axes[a].model.name.clone(), message.clone(), utc)
                {
                    notes.push(format!("alarm {id} raised: {message}"));
                }
            } else {
                self.alarms
                    .clear(&format!("bounds:{}", self.axes[a].model.name));
            }
            let axis = &mut self.axes[a];
            let next = axis.model.step_toward(axis.written, goal, dt);
            if next != goal {
                all_reached = false;
            }
            any_held |= held;
            axis.written = next;
            self.write_axis(a, utc, notes);
        }
        (all_reached, any_held)
    }

    /// The line an axis moves toward this cycle, whether it is held, and a bounds problem
    /// (alarm key, message).
    fn goal_of(
        &mut self,
        a: usize,
        hold: bool,
        ramp_stop: bool,
    ) -> (Line, bool, Option<(String, String)>) {
        if ramp_stop || self.ramp_latched {
            return (Line::default(), false, None);
        }
        let held_line = self.axes[a].written;
        if self.paused || hold {
            return (held_line, true, None);
        }
        let Some((demand, _x, direction)) = self.demand_of(a) else {
            return (held_line, true, None);
        };
        let axis = &self.axes[a];
        match axis.model.check_bounds(&demand.line, direction) {
            Ok(()) => (demand.line, false, None),
            Err(message) => (
                held_line,
                true,
                Some((format!("bounds:{}", axis.model.name), message)),
            ),
        }
    }

    /// The axis's direction (the last one known while the axis stands).
    fn direction_of(&mut self, a: usize) -> Option<Direction> {
        let axis = &self.axes[a];
        let (s, c) = axis.direction.as_ref()?;
        let d = match self.sources[*s]
            .source
            .snapshot()
            .channels
            .get(c)
            .map(|r| &r.value)
        {
            Some(Value::Text(t)) => match t.trim() {
                "+" => Some(Direction::Forward),
                "-" => Some(Direction::Reverse),
                other => Direction::parse(other),
            },
            Some(Value::Number(v)) if *v > axis.direction_deadband => Some(Direction::Forward),
            Some(Value::Number(v)) if *v < -axis.direction_deadband => Some(Direction::Reverse),
            Some(Value::Flag(b)) => Some(if *b {
                Direction::Forward
            } else {
                Direction::Reverse
            }),
            _ => None,
        };
        if d.is_some() {
            self.axes[a].last_direction = d;
        }
        self.axes[a].last_direction
    }

    fn position_of(&self, a: usize) -> Option<f64> {
        let (s, c) = self.axes[a].position.as_ref()?;
        self.sources[*s]
            .source
            .snapshot()
            .channels
            .get(c)?
            .value
            .as_number()
    }

    /// The model's demand for an axis, when every input it needs is good.
    fn demand_of(
        &mut self,
        a: usize,
    ) -> Option<(super::axis::Demand, Option<f64>, Option<Direction>)> {
        let direction = self.direction_of(a);
        let x = self.position_of(a);
        let axis = &self.axes[a];
        let coolant = match &self.coolant_label {
            Some(label) => axis.model.model.coolant_index(label)?,
            None if axis.model.model.coolant_states.len() == 1 => 0,
            None => return None,
        };
        let mut sensors_c = Vec::with_capacity(axis.gain_sensors.len());
        for &k in &axis.gain_sensors {
            sensors_c.push(self.sensors[k].value_c?);
        }
        let ambient_c = match axis.ambient {
            Some(k) => Some(self.sensors[k].value_c?),
            None => None,
        };
        let state = ThermalState {
            sensors_c,
            ambient_c,
            coolant,
        };
        Some((axis.model.demand(direction, x, &state), x, direction))
    }

    /// Write an axis's line to its target, retrying; a failure raises an alarm.
    fn write_axis(&mut self, a: usize, utc: &str, notes: &mut Vec<String>) {
        let Some(t) = self.axes[a].target else { return };
        let x = self.position_of(a);
        let direction = self.axes[a].last_direction;
        let axis = &self.axes[a];
        let geometric = if axis.model.include_geometric {
            x.map(|x| match direction {
                Some(d) => -axis.model.model.geometric_um(d, x),
                None => {
                    -0.5 * (axis.model.model.geometric_um(Direction::Forward, x)
                        + axis.model.model.geometric_um(Direction::Reverse, x))
                }
            })
        } else {
            Some(0.0)
        };
        let output = Output {
            line: axis.written,
            px_mm: axis.model.px_mm(),
            value_um: x
                .zip(geometric)
                .map(|(x, g)| axis.written.at(x, axis.model.px_mm()) + g),
        };
        // A point target takes the value at the position; a line target the line.
        let same = match &axis.last_output {
            Some(last) if self.targets[t].is_point() => last.value_um == output.value_um,
            Some(last) => last.line == output.line && last.px_mm == output.px_mm,
            None => false,
        };
        if same {
            return;
        }
        let name = axis.model.name.clone();
        let key = format!("write:{name}");
        let mut last_err = None;
        for attempt in 0..=self.write_retries {
            match self.targets[t].write(&name, &output) {
                Ok(()) => {
                    if attempt > 0 {
                        notes.push(format!(
                            "{name}: write retried {attempt} time(s), then written"
                        ));
                    }
                    last_err = None;
                    break;
                }
                Err(e) => last_err = Some(e.to_string()),
            }
        }
        self.axes[a].last_output = last_err.is_none().then_some(output);
        match last_err {
            None => self.alarms.clear(&key),
            Some(e) => {
                let message = format!(
                    "{name}: write to {} failed after {} tries: {e}",
                    self.targets[t].name(),
                    self.write_retries + 1
                );
                if let Some(id) =
                    self.alarms
                        .raise(&key, self.targets[t].name(), message.clone(), utc)
                {
                    notes.push(format!("alarm {id} raised: {message}"));
                } else {
                    notes.push(message);
                }
            }
        }
    }

    /// Operators' commands from the store, each applied and logged.
    fn apply_commands(&mut self, utc: &str, notes: &mut Vec<String>) {
        for c in self.link.commands() {
            let outcome = match c.command.as_str() {
                "pause" => {
                    self.paused = true;
                    "applied".to_string()
                }
                "resume" if self.paused => {
                    self.paused = false;
                    "applied".to_string()
                }
                "resume" => "not applied: not paused".to_string(),
                "ack" => match c.alarm_id {
                    Some(id) => match self.alarms.acknowledge(id as u64) {
                        Some(key) => {
                            // A sensor held for its rate of change takes its next reading afresh.
                            if let Some(name) = key.strip_prefix("sensor:") {
                                if let Some(s) =
                                    self.sensors.iter_mut().find(|s| s.def.name == name)
                                {
                                    s.last_accepted = None;
                                    s.filter.reset();
                                }
                            }
                            "applied".to_string()
                        }
                        None => format!("unknown alarm {id}"),
                    },
                    None => "not applied: ack without alarm_id".to_string(),
                },
                other => format!("not applied: unknown command '{other}'"),
            };
            notes.push(format!(
                "{} by {} (command {}): {outcome}",
                c.command, c.user, c.id
            ));
            self.link.handled(c.id, utc.to_string(), outcome);
        }
    }

    /// Log the cycle and rewrite the state file.
    fn record(
        &mut self,
        t: f64,
        mode: Mode,
        notes: Vec<String>,
        stop_reason: Option<String>,
    ) -> Result<()> {
        let utc = self.utc_at(t);
        let (mut inputs, samples) = self.sensor_inputs(t);
        let coolant_on = self.coolant_on();
        inputs.insert("coolant_on".into(), json!(coolant_on));
        inputs.insert("coolant".into(), json!(self.coolant_label));
        let (outputs, axis_states) = self.axis_outputs(mode, &mut inputs);
        let note = if notes.is_empty() {
            None
        } else {
            Some(notes.join("; "))
        };
        self.watch_store(&utc);
        self.link.log(CycleRecord {
            cycle: self.cycle,
            at_utc: utc,
            mode: mode.name(),
            inputs_json: Json::Object(inputs).to_string(),
            outputs_json: Json::Object(outputs).to_string(),
            note,
            time_s: t,
            samples,
        });
        self.retain(t);
        if self.state_writer.is_some() {
            let state = self.state(t, mode, coolant_on, axis_states, stop_reason);
            if let Some(w) = self.state_writer.as_mut() {
                w.write(&state)?;
            }
        }
        Ok(())
    }

    /// The cycle's inputs so far (`time_s`, each sensor's °C as the model used it, `raw`
    /// readings) and the temperature samples to log (the sensors with a value and no problem).
    fn sensor_inputs(&self, t: f64) -> (Map<String, Json>, Vec<(usize, f64)>) {
        let mut inputs = Map::new();
        inputs.insert("time_s".into(), json!(t));
        let mut raw = Map::new();
        let mut samples = Vec::with_capacity(self.sensors.len());
        for (k, s) in self.sensors.iter().enumerate() {
            inputs.insert(s.def.name.clone(), json!(s.value_c));
            raw.insert(s.def.name.clone(), json!(s.raw));
            if let (Some(v), None) = (s.value_c, &s.problem) {
                samples.push((k, v));
            }
        }
        inputs.insert("raw".into(), Json::Object(raw));
        (inputs, samples)
    }

    /// Whether the coolant is on (None without a coolant channel or with an unknown label).
    fn coolant_on(&self) -> Option<bool> {
        self.coolant
            .as_ref()
            .and_then(|c| match &self.coolant_label {
                Some(l) if *l == c.on => Some(true),
                Some(l) if *l == c.off => Some(false),
                _ => None,
            })
    }

    /// Each axis's outputs for the store and its state for the state file; its position and
    /// direction go into `inputs`.
    fn axis_outputs(
        &mut self,
        mode: Mode,
        inputs: &mut Map<String, Json>,
    ) -> (Map<String, Json>, Vec<AxisState>) {
        let mut outputs = Map::new();
        let mut axis_states = Vec::with_capacity(self.axes.len());
        for a in 0..self.axes.len() {
            let x = self.position_of(a);
            let demand = self.demand_of(a);
            // (After demand_of, which takes in this cycle's direction.)
            let direction = self.axes[a].last_direction;
            let axis = &self.axes[a];
            let px = axis.model.px_mm();
            let geometric = |d: &super::axis::Demand| d.geometric_comp_um.unwrap_or(0.0);
            let computed_um = demand
                .as_ref()
                .and_then(|(d, x, _)| x.map(|x| d.line.at(x, px) + geometric(d)));
            let g_now = demand.as_ref().map_or(0.0, |(d, _, _)| geometric(d));
            let written_um = x.map(|x| axis.written.at(x, px) + g_now);
            let held = matches!(mode, Mode::Holding | Mode::Paused)
                || demand
                    .as_ref()
                    .is_some_and(|(d, _, _)| axis.written != d.line)
                    && !self.starting
                    && mode != Mode::RampingToZero;
            inputs.insert(format!("{}.position_mm", axis.model.name), json!(x));
            inputs.insert(
                format!("{}.direction", axis.model.name),
                json!(direction.map(|d| d.symbol())),
            );
            outputs.insert(
                axis.model.name.clone(),
                json!({
                    "computed_um": computed_um,
                    "written_um": written_um,
                    "target": axis.target_name,
                    "error_um": demand.as_ref().and_then(|(d, _, _)| d.error_um),
                    "tan_beta_um_per_m": demand.as_ref().map(|(d, _, _)| d.tan_beta_um_per_m),
                    "written_offset_um": axis.written.offset_um,
                    "written_slope_um_per_m": axis.written.slope_um_per_m,
                    "px_mm": px,
                    "held": held,
                }),
            );
            axis_states.push(AxisState {
                axis: axis.model.name.clone(),
                position_mm: x,
                direction: direction.map(|d| d.name()),
                computed_um,
                written_um,
                limit_um: axis.model.limits.limit_um,
                rate_limit_um_s: axis.model.limits.rate_limit_um_s,
                target: axis.target_name.clone(),
                held,
                computed_slope_um_per_m: demand
                    .as_ref()
                    .map_or(0.0, |(d, _, _)| d.line.slope_um_per_m),
                written_slope_um_per_m: axis.written.slope_um_per_m,
            });
        }
        (outputs, axis_states)
    }

    /// An alarm while the store cannot be written (raised once while the failure lasts).
    fn watch_store(&mut self, utc: &str) {
        if let Some(f) = self.link.failure() {
            // Raised once while the failure lasts (raise ignores an active key).
            self.alarms.raise(
                "store",
                "store",
                format!("the store cannot be written: {f}"),
                utc,
            );
        } else {
            self.alarms.clear("store");
        }
    }

    /// Retention: about once an hour of loop time, delete what is older than `retention_days`.
    fn retain(&mut self, t: f64) {
        let every = (3600.0 / self.period_s).max(1.0) as u64;
        if self.cycle % every == every - 1 {
            let cutoff_t = t - self.retention_s;
            if cutoff_t > self.t0_s {
                self.link.retain(self.utc_at(cutoff_t), cutoff_t);
            }
        }
    }

    /// The state file's content for this cycle.
    fn state(
        &self,
        t: f64,
        mode: Mode,
        coolant_on: Option<bool>,
        axes: Vec<AxisState>,
        stop_reason: Option<String>,
    ) -> State {
        let sensors = self
            .sensors
            .iter()
            .map(|s| SensorState {
                name: s.def.name.clone(),
                value_c: s.value_c,
                ok: s.problem.is_none() && s.value_c.is_some(),
                source: self.sources[s.source].source.name().to_string(),
                age_ms: s.age_s.map(|a| (a.max(0.0) * 1000.0).round() as u64),
                problem: s.problem.clone(),
            })
            .collect();
        let sources = self
            .sources
            .iter()
            .map(|s| {
                let snap = s.source.snapshot();
                let age = snap.last_ok_s.map_or(f64::INFINITY, |at| t - at);
                SourceState {
                    name: s.source.name().to_string(),
                    kind: s.source.kind(),
                    healthy: age <= s.timeout_s && snap.problem.is_none(),
                    last_ok_utc: snap.last_ok_s.map(|at| self.utc_at(at)),
                    problem: snap.problem.clone().or_else(|| {
                        (age > s.timeout_s).then(|| format!("silent for {:.1} s", age))
                    }),
                }
            })
            .collect();
        State {
            schema: state::SCHEMA,
            written_utc: state::utc_ms(SystemTime::now()),
            cycle: self.cycle,
            period_ms: self.period_ms,
            mode,
            dry_run: self.dry_run,
            coolant_on,
            sensors,
            axes,
            sources,
            alarms: self.alarms.states(),
            missed_cycles: self.missed,
            stop_reason,
        }
    }
}

/// Load, check and run a config: the whole of `errmap live`.
pub fn run(
    config: &LiveConfig,
    options: &RunOptions,
    stop: &StopFlags,
    notes: &dyn Fn(&str),
) -> Result<RunSummary, LiveError> {
    let targets = if options.dry_run {
        Vec::new()
    } else {
        super::connect_targets(config).map_err(LiveError::Target)?
    };
    let mut live = Live::prepare(config, options, targets)?;
    live.run(stop, notes)
}
