//! The live configuration file (TOML): the loop, the store, the sources and their channels, the
//! model sensors and coolant, the axes with their models and safety limits, and the targets.
//! Every error names the file, the key and the line of the offending value.

use crate::ConfigError;
use errmap_core::error::{Error, Location, Result};
use errmap_core::io::line_col;
use serde::Deserialize;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// The whole file.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LiveConfig {
    /// The `[loop]` table: period, stop behaviour, replay speed, write retries.
    #[serde(rename = "loop", default)]
    pub cycle: LoopConfig,
    /// The `[store]` table: the temperature history store and its retention.
    pub store: StoreConfig,
    /// The `[[sources]]` the readings come from, in file order.
    pub sources: Vec<SourceConfig>,
    /// Model sensor name → where its reading comes from and what is plausible.
    #[serde(default)]
    pub sensors: BTreeMap<String, SensorConfig>,
    /// The `[coolant]` table; None: every model must have a single coolant state, which is used
    /// (a model with gains for more than one is a config error).
    pub coolant: Option<CoolantConfig>,
    /// The `[[axes]]` compensated, in file order.
    pub axes: Vec<AxisConfig>,
    /// The `[[targets]]` the axes are written to (empty is allowed with `--dry-run`).
    #[serde(default)]
    pub targets: Vec<TargetConfig>,
    /// The file read (messages, relative paths).
    #[serde(skip)]
    pub path: PathBuf,
    /// Its text, to find the line of a key named in a later message.
    #[serde(skip)]
    pub text: String,
}

/// What the target is left with when errmap live stops (SIGTERM, SIGINT, end of a replay).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum OnStop {
    /// Leave the last written values in place.
    #[default]
    Hold,
    /// Ramp every axis to zero at its rate limit, then stop.
    RampToZero,
}

impl OnStop {
    /// The value's spelling in the config (`hold`, `ramp_to_zero`).
    pub fn name(self) -> &'static str {
        match self {
            OnStop::Hold => "hold",
            OnStop::RampToZero => "ramp_to_zero",
        }
    }
}

/// The `[loop]` table: how the cycle runs and how it stops.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct LoopConfig {
    /// Cycle period (ms).
    pub period_ms: u64,
    /// What the targets are left with at SIGTERM, SIGINT or the end of a replay.
    pub on_stop: OnStop,
    /// Longest ramp to zero at a stop (s); past it the values are held and errmap stops.
    pub stop_ramp_s: f64,
    /// Replay: the CSV sources' `time_s` drives the loop clock, this many times faster than
    /// real time (0: as fast as the cycle runs). Absent: the wall clock.
    pub replay_speed: Option<f64>,
    /// Further tries of a failed write within the same cycle.
    pub write_retries: u32,
}

impl Default for LoopConfig {
    fn default() -> Self {
        LoopConfig {
            period_ms: 100,
            on_stop: OnStop::Hold,
            stop_ramp_s: 60.0,
            replay_speed: None,
            write_retries: 2,
        }
    }
}

/// The `[store]` table: the temperature history store the cycles and samples are logged into.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct StoreConfig {
    /// The SQLite temperature history store (relative to the config's folder).
    pub path: PathBuf,
    /// Cycles and live temperature samples older than this are deleted (days).
    #[serde(default = "default_retention_days")]
    pub retention_days: f64,
}

fn default_retention_days() -> f64 {
    30.0
}

/// The kinds of source.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum SourceKind {
    /// A CSV stream in the machine-log format of `errmap thermal compensate`.
    Csv,
    /// Modbus TCP registers and coils.
    Modbus,
    /// OPC UA nodes.
    Opcua,
    /// LinuxCNC HAL pins, read through errmap's HAL component.
    Linuxcnc,
}

impl SourceKind {
    /// The kind's spelling in the config (`csv`, `modbus`, `opcua`).
    pub fn name(self) -> &'static str {
        match self {
            SourceKind::Csv => "csv",
            SourceKind::Modbus => "modbus",
            SourceKind::Opcua => "opcua",
            SourceKind::Linuxcnc => "linuxcnc",
        }
    }
}

/// One source; the keys of other kinds are refused.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SourceConfig {
    /// The source's name, the `<source>` of `source.channel` references.
    pub name: String,
    /// Which kind of source; the keys of other kinds are refused.
    pub kind: SourceKind,
    /// Silent this long: the loop holds (ms).
    pub timeout_ms: u64,
    /// Silent this long: every axis ramps to zero and an alarm is raised (ms).
    pub ramp_timeout_ms: u64,
    /// Poll period of a polled source (ms); default: the loop's.
    pub period_ms: Option<u64>,
    // csv
    /// The CSV file (`-`: standard input).
    pub path: Option<PathBuf>,
    /// Keep reading lines appended to the file (a data logger writing it).
    pub follow: Option<bool>,
    // modbus
    /// `host:port`.
    pub address: Option<String>,
    /// Modbus unit (slave) id of the device (default 1).
    pub unit_id: Option<u8>,
    /// Modbus registers or OPC UA nodes, one per channel.
    #[serde(default)]
    pub channels: Vec<ChannelConfig>,
    // opcua
    /// OPC UA: the server's endpoint URL (`opc.tcp://host:port`).
    pub endpoint: Option<String>,
    /// OPC UA: the security policy of the session.
    pub security_policy: Option<String>,
    /// OPC UA: the user name to log in with.
    pub user: Option<String>,
    /// OPC UA: the password of `user`.
    pub password: Option<String>,
    // linuxcnc
    /// LinuxCNC: the Python 3 that has LinuxCNC's `hal` module (default `/usr/bin/python3`).
    pub python: Option<String>,
    /// LinuxCNC: the name of errmap's HAL component (default `errmap-<name>`).
    pub component: Option<String>,
}

/// One channel of a Modbus or OPC UA source.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ChannelConfig {
    /// The channel's name, the `<channel>` of `source.channel` references.
    pub name: String,
    /// Modbus: `input`, `holding`, `coil`, `discrete`.
    pub table: Option<String>,
    /// Modbus: the 0-based register or coil address.
    pub register: Option<u16>,
    /// Modbus: `u16`, `s16`, `u32`, `s32`, `f32`.
    #[serde(rename = "type")]
    pub data_type: Option<String>,
    /// Modbus 32-bit values: `big` (high word first) or `little`.
    pub word_order: Option<String>,
    /// value = scale·raw + offset.
    pub scale: Option<f64>,
    /// Added after scaling, in the channel's unit (default 0).
    pub offset: Option<f64>,
    /// OPC UA: the node id, e.g. `ns=2;s=Temperatures.T1`.
    pub node: Option<String>,
    /// LinuxCNC: the HAL pin, signal or parameter read, e.g. `axis.z.pos-cmd`.
    pub pin: Option<String>,
}

/// Denoising of a live sensor.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize, Default)]
#[serde(rename_all = "lowercase")]
pub enum FilterChoice {
    /// The model's own running median and Savitzky–Golay windows, applied causally.
    #[default]
    Model,
    /// Readings used as they arrive (as `errmap thermal compensate` uses a log).
    None,
}

/// A model sensor: its channel and the plausibility of its readings (°C, after calibration).
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SensorConfig {
    /// `source.channel`.
    pub channel: String,
    /// Lowest plausible temperature after calibration (°C; default 0).
    #[serde(default = "default_min_c")]
    pub min_c: f64,
    /// Highest plausible temperature after calibration (°C; default 60).
    #[serde(default = "default_max_c")]
    pub max_c: f64,
    /// Largest plausible change between two readings: max_step_c + max_rate_c_per_s·Δt.
    #[serde(default = "default_rate")]
    pub max_rate_c_per_s: f64,
    /// The step part of the largest plausible change (°C; default 0.5); the rate part is
    /// `max_rate_c_per_s` (°C/s; default 0.1).
    #[serde(default = "default_step")]
    pub max_step_c: f64,
    /// A reading above this is an open RTD (a module's overrange value).
    #[serde(default = "default_open")]
    pub open_above_c: f64,
    /// A reading below this is a shorted RTD.
    #[serde(default = "default_short")]
    pub short_below_c: f64,
    /// The denoising of the sensor's readings (default: the model's own filter).
    #[serde(default)]
    pub filter: FilterChoice,
}

fn default_min_c() -> f64 {
    0.0
}
fn default_max_c() -> f64 {
    60.0
}
fn default_rate() -> f64 {
    0.1
}
fn default_step() -> f64 {
    0.5
}
fn default_open() -> f64 {
    200.0
}
fn default_short() -> f64 {
    -50.0
}

/// The coolant state: a channel and the model's labels for on and off.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CoolantConfig {
    /// `source.channel` of the coolant state: a bit (on/off), a number (≠ 0: on) or the state's
    /// label itself.
    pub channel: String,
    /// The model's label of the coolant-on state (default `on`).
    #[serde(default = "default_on")]
    pub on: String,
    /// The model's label of the coolant-off state (default `off`).
    #[serde(default = "default_off")]
    pub off: String,
}

fn default_on() -> String {
    "on".into()
}
fn default_off() -> String {
    "off".into()
}

/// One compensated axis.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AxisConfig {
    /// The axis's name; must be the axis of its model.
    pub name: String,
    /// The model file `errmap thermal fit` wrote (relative to the config's folder).
    pub model: PathBuf,
    /// `source.channel` of the axis position (mm, machine coordinates).
    pub position: Option<String>,
    /// `source.channel` of the travel direction (`+`/`-`, or a number's sign); without it
    /// the mean of the forward and reverse models is used.
    pub direction: Option<String>,
    /// A number on the direction channel within ±this is standstill, which keeps the last
    /// direction (a velocity's noise at rest; default 0, in the channel's unit).
    #[serde(default)]
    pub direction_deadband: f64,
    /// Largest |compensation| (µm) anywhere on the fitted travel.
    pub limit_um: f64,
    /// Largest |tanβ| (µm/m).
    pub slope_limit_um_per_m: f64,
    /// Fastest change of the compensation anywhere on the travel (µm/s).
    pub rate_limit_um_s: f64,
    /// Add Er(x), the cold pitch error, to a point target's value (false: it is in the
    /// controller's pitch table, errmap writes only the thermal part).
    #[serde(default)]
    pub include_geometric: bool,
    /// Name of a `[[targets]]` entry (not needed with --dry-run).
    pub target: Option<String>,
}

/// The kinds of target.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum TargetKind {
    /// Siemens Sinumerik temperature compensation (K3): SD43900/43910/43920 through OPC UA.
    SinumerikOpcua,
    /// Generic OPC UA node writes of the value at the axis's position.
    OpcuaNodes,
    /// Modbus holding-register writes of the value at the axis's position.
    ModbusRegisters,
    /// LinuxCNC external offsets through HAL.
    Linuxcnc,
}

impl TargetKind {
    /// The kind's spelling in the config (`sinumerik-opcua`, `modbus-registers`, ...).
    pub fn name(self) -> &'static str {
        match self {
            TargetKind::SinumerikOpcua => "sinumerik-opcua",
            TargetKind::OpcuaNodes => "opcua-nodes",
            TargetKind::ModbusRegisters => "modbus-registers",
            TargetKind::Linuxcnc => "linuxcnc",
        }
    }
}

/// One target; per-axis settings under `axes.<AXIS>`.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TargetConfig {
    /// The target's name, as an axis's `target` names it.
    pub name: String,
    /// Which kind of target.
    pub kind: TargetKind,
    /// OPC UA targets: the server's endpoint URL.
    pub endpoint: Option<String>,
    /// Modbus: `host:port` of the PLC gateway.
    pub address: Option<String>,
    /// Modbus: the unit (slave) id (default 1).
    pub unit_id: Option<u8>,
    /// OPC UA targets: the security policy of the session.
    pub security_policy: Option<String>,
    /// OPC UA targets: the user name to log in with.
    pub user: Option<String>,
    /// OPC UA targets: the password of `user`.
    pub password: Option<String>,
    /// LinuxCNC: the Python 3 that has LinuxCNC's `hal` module (default `/usr/bin/python3`).
    pub python: Option<String>,
    /// LinuxCNC: the name of errmap's HAL component (default `errmap-<name>`).
    pub component: Option<String>,
    /// Axis name → where this target writes that axis.
    #[serde(default)]
    pub axes: BTreeMap<String, TargetAxisConfig>,
}

/// Where a target writes one axis.
#[derive(Debug, Clone, Deserialize, Default)]
#[serde(deny_unknown_fields)]
pub struct TargetAxisConfig {
    /// Sinumerik: node ids of SD43900, SD43910, SD43920 of the axis.
    pub sd43900: Option<String>,
    /// Sinumerik: node id of SD43910 `$SA_TEMP_COMP_SLOPE` (tanβ).
    pub sd43910: Option<String>,
    /// Sinumerik: node id of SD43920 `$SA_TEMP_COMP_REF_POSITION` (P0).
    pub sd43920: Option<String>,
    /// Generic OPC UA: the node receiving the value (µm unless `unit`).
    pub node: Option<String>,
    /// Modbus: holding register, type and scale of the written value (raw = value/scale).
    pub register: Option<u16>,
    /// Modbus: the register type, `u16`, `s16`, `u32`, `s32` (default) or `f32`.
    #[serde(rename = "type")]
    pub data_type: Option<String>,
    /// Modbus 32-bit types: `big` (high word first, default) or `little`.
    pub word_order: Option<String>,
    /// Modbus: µm per count (the register holds value/scale, rounded).
    pub scale: Option<f64>,
    /// Units of the written value: `um` or `mm` (OPC UA nodes); the machine's linear units,
    /// `mm` or `inch` (LinuxCNC).
    pub unit: Option<String>,
    /// LinuxCNC: µm per count of `axis.L.eoffset-counts` (default 0.1).
    pub resolution_um: Option<f64>,
    /// LinuxCNC: the axis letter of the `axis.L.*` pins (default: the axis's name in lower case).
    pub letter: Option<String>,
}

/// A `source.channel` reference.
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub struct ChannelRef {
    /// The source's name.
    pub source: String,
    /// The channel's name within the source.
    pub channel: String,
}

impl LiveConfig {
    /// Read and check a config file.
    pub fn read(path: &Path) -> Result<LiveConfig, ConfigError> {
        let text = errmap_core::io::read_text(path)?;
        LiveConfig::parse(path, &text)
    }

    /// Parse and check config text; `path` names it in messages and anchors relative paths.
    pub fn parse(path: &Path, text: &str) -> Result<LiveConfig, ConfigError> {
        let mut config: LiveConfig = toml::from_str(text).map_err(|e| {
            let (line, col) = e.span().map_or((1, 1), |s| line_col(text, s.start));
            Error::input(
                Location::cell(path, line, col.to_string()),
                e.message().trim().to_string(),
                "see docs/live.md for every key and its type",
            )
        })?;
        config.path = path.to_path_buf();
        config.text = text.to_string();
        config.validate()?;
        Ok(config)
    }

    /// The config's folder (relative paths are taken from it).
    pub fn dir(&self) -> PathBuf {
        match self.path.parent() {
            Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
            _ => PathBuf::from("."),
        }
    }

    /// A path of the config, relative to its folder.
    pub fn resolve(&self, p: &Path) -> PathBuf {
        if p.is_absolute() || p == Path::new("-") {
            p.to_path_buf()
        } else {
            self.dir().join(p)
        }
    }

    /// An error about a key (dotted, arrays by index: `axes.0.limit_um`), at the line of its
    /// value (or of its table when the key is absent).
    pub fn key_error(
        &self,
        key: &str,
        message: impl Into<String>,
        hint: impl Into<String>,
    ) -> Error {
        let (line, col) = key_line_col(&self.text, key).unwrap_or((1, 1));
        Error::input(
            Location::cell(&self.path, line, col.to_string()),
            format!("{}: {}", display_key(key), message.into()),
            hint,
        )
    }

    /// Parse a `source.channel` reference held by `key`.
    pub fn channel_ref(&self, key: &str, text: &str) -> Result<ChannelRef> {
        let Some((source, channel)) = text.split_once('.') else {
            return Err(self.key_error(
                key,
                format!("'{text}' is not a channel reference"),
                "write source.channel, e.g. \"rack.T1\"",
            ));
        };
        if !self.sources.iter().any(|s| s.name == source) {
            return Err(self.key_error(
                key,
                format!("no source named '{source}'"),
                format!("the sources are: {}", self.source_names().join(", ")),
            ));
        }
        Ok(ChannelRef {
            source: source.to_string(),
            channel: channel.to_string(),
        })
    }

    fn source_names(&self) -> Vec<&str> {
        self.sources.iter().map(|s| s.name.as_str()).collect()
    }

    fn validate(&self) -> Result<()> {
        self.check_loop_and_store()?;
        self.check_sources()?;
        self.check_sensors()?;
        self.check_axes()
    }

    /// `[loop]` and `[store]`.
    fn check_loop_and_store(&self) -> Result<()> {
        let c = &self.cycle;
        if c.period_ms == 0 || c.period_ms > 60_000 {
            return Err(self.key_error(
                "loop.period_ms",
                format!("{} ms is not a cycle period", c.period_ms),
                "give 1 … 60000 ms, e.g. 100",
            ));
        }
        if !(c.stop_ramp_s.is_finite() && c.stop_ramp_s >= 0.0) {
            return Err(self.key_error(
                "loop.stop_ramp_s",
                "must be a finite number of seconds ≥ 0",
                "e.g. 60",
            ));
        }
        if let Some(s) = c.replay_speed {
            if !(s.is_finite() && s >= 0.0) {
                return Err(self.key_error(
                    "loop.replay_speed",
                    format!("{s} is not a speed"),
                    "give a factor ≥ 0 (0: as fast as the cycle runs)",
                ));
            }
        }
        if !(self.store.retention_days.is_finite() && self.store.retention_days > 0.0) {
            return Err(self.key_error(
                "store.retention_days",
                "must be a positive number of days",
                "e.g. 30",
            ));
        }
        Ok(())
    }

    /// At least one source, each valid and named once.
    fn check_sources(&self) -> Result<()> {
        if self.sources.is_empty() {
            return Err(self.key_error("sources", "no source", "add a [[sources]] table"));
        }
        let mut names = std::collections::BTreeSet::new();
        for (i, s) in self.sources.iter().enumerate() {
            self.check_source(i, s)?;
            if !names.insert(s.name.as_str()) {
                return Err(self.key_error(
                    &format!("sources.{i}.name"),
                    format!("a second source named '{}'", s.name),
                    "give every source its own name",
                ));
            }
        }
        Ok(())
    }

    /// Each sensor's channel reference and plausibility limits, and the coolant channel's.
    fn check_sensors(&self) -> Result<()> {
        for (name, s) in &self.sensors {
            let key = format!("sensors.{name}");
            self.channel_ref(&format!("{key}.channel"), &s.channel)?;
            if !(s.min_c < s.max_c && s.max_c < s.open_above_c && s.short_below_c < s.min_c) {
                return Err(self.key_error(
                    &key,
                    format!(
                        "limits must satisfy short_below_c < min_c < max_c < open_above_c ({} < {} < {} < {})",
                        s.short_below_c, s.min_c, s.max_c, s.open_above_c
                    ),
                    "e.g. short_below_c = -50, min_c = 0, max_c = 60, open_above_c = 200",
                ));
            }
            if !(s.max_rate_c_per_s > 0.0 && s.max_step_c >= 0.0) {
                return Err(self.key_error(
                    &format!("{key}.max_rate_c_per_s"),
                    "max_rate_c_per_s must be > 0 and max_step_c ≥ 0",
                    "e.g. max_rate_c_per_s = 0.1, max_step_c = 0.5",
                ));
            }
        }
        if let Some(cool) = &self.coolant {
            self.channel_ref("coolant.channel", &cool.channel)?;
        }
        Ok(())
    }

    /// At least one axis, each named once and valid.
    fn check_axes(&self) -> Result<()> {
        if self.axes.is_empty() {
            return Err(self.key_error("axes", "no axis", "add an [[axes]] table"));
        }
        let mut axis_names = std::collections::BTreeSet::new();
        for (i, a) in self.axes.iter().enumerate() {
            if !axis_names.insert(a.name.as_str()) {
                return Err(self.key_error(
                    &format!("axes.{i}.name"),
                    format!("a second axis named '{}'", a.name),
                    "give every axis its own name",
                ));
            }
            self.check_axis(i, a)?;
        }
        Ok(())
    }

    /// An axis's deadband, limits, channel references and target.
    fn check_axis(&self, i: usize, a: &AxisConfig) -> Result<()> {
        let key = |k: &str| format!("axes.{i}.{k}");
        if !(a.direction_deadband.is_finite() && a.direction_deadband >= 0.0) {
            return Err(self.key_error(
                &key("direction_deadband"),
                format!("{} is not a deadband", a.direction_deadband),
                "give a finite number ≥ 0 in the direction channel's unit",
            ));
        }
        for (k, v) in [
            ("limit_um", a.limit_um),
            ("slope_limit_um_per_m", a.slope_limit_um_per_m),
            ("rate_limit_um_s", a.rate_limit_um_s),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return Err(self.key_error(
                    &key(k),
                    format!("{v} is not a positive limit"),
                    "give a positive finite number",
                ));
            }
        }
        if let Some(p) = &a.position {
            self.channel_ref(&key("position"), p)?;
        }
        if let Some(d) = &a.direction {
            self.channel_ref(&key("direction"), d)?;
        }
        if let Some(t) = &a.target {
            if !self.targets.iter().any(|x| &x.name == t) {
                return Err(self.key_error(
                    &key("target"),
                    format!("no target named '{t}'"),
                    "name a [[targets]] entry",
                ));
            }
        }
        Ok(())
    }

    fn check_source(&self, i: usize, s: &SourceConfig) -> Result<()> {
        let key = |k: &str| format!("sources.{i}.{k}");
        if s.name.is_empty() || s.name.contains('.') {
            return Err(self.key_error(
                &key("name"),
                format!("'{}' cannot name a source", s.name),
                "use letters, digits, - and _ (no dot: channels are source.channel)",
            ));
        }
        if s.timeout_ms == 0 || s.ramp_timeout_ms <= s.timeout_ms {
            return Err(self.key_error(
                &key("ramp_timeout_ms"),
                format!(
                    "the ramp timeout ({} ms) must exceed the hold timeout ({} ms), which must exceed 0",
                    s.ramp_timeout_ms, s.timeout_ms
                ),
                "e.g. timeout_ms = 1000, ramp_timeout_ms = 10000",
            ));
        }
        let allowed: &[&str] = match s.kind {
            SourceKind::Csv => &["path", "follow"],
            SourceKind::Modbus => &["address", "unit_id", "channels", "period_ms"],
            SourceKind::Opcua => &[
                "endpoint",
                "security_policy",
                "user",
                "password",
                "channels",
                "period_ms",
            ],
            SourceKind::Linuxcnc => &["python", "component", "channels", "period_ms"],
        };
        let given: [(&str, bool); 11] = [
            ("path", s.path.is_some()),
            ("follow", s.follow.is_some()),
            ("address", s.address.is_some()),
            ("unit_id", s.unit_id.is_some()),
            ("channels", !s.channels.is_empty()),
            ("endpoint", s.endpoint.is_some()),
            ("security_policy", s.security_policy.is_some()),
            ("user", s.user.is_some()),
            ("password", s.password.is_some()),
            ("python", s.python.is_some()),
            ("component", s.component.is_some()),
        ];
        for (k, present) in given {
            if present && !allowed.contains(&k) {
                return Err(self.key_error(
                    &key(k),
                    format!("a {} source has no key '{k}'", s.kind.name()),
                    format!(
                        "its keys: name, kind, timeout_ms, ramp_timeout_ms, {}",
                        allowed.join(", ")
                    ),
                ));
            }
        }
        let need = |k: &str, present: bool| {
            if present {
                Ok(())
            } else {
                Err(self.key_error(
                    &format!("sources.{i}"),
                    format!("a {} source needs '{k}'", s.kind.name()),
                    "see docs/live.md, Sources",
                ))
            }
        };
        match s.kind {
            SourceKind::Csv => need("path", s.path.is_some())?,
            SourceKind::Modbus => {
                need("address", s.address.is_some())?;
                need("channels", !s.channels.is_empty())?;
            }
            SourceKind::Opcua => {
                need("endpoint", s.endpoint.is_some())?;
                need("channels", !s.channels.is_empty())?;
            }
            SourceKind::Linuxcnc => need("channels", !s.channels.is_empty())?,
        }
        if self.cycle.replay_speed.is_some() && s.kind != SourceKind::Csv {
            return Err(self.key_error(
                "loop.replay_speed",
                format!(
                    "a replay drives the clock from CSV files, but source '{}' is {}",
                    s.name,
                    s.kind.name()
                ),
                "remove replay_speed to run on the wall clock",
            ));
        }
        Ok(())
    }
}

/// `axes.0.limit_um` as the file spells it: `axes[0].limit_um`.
fn display_key(key: &str) -> String {
    let mut out = String::new();
    for part in key.split('.') {
        if part.parse::<usize>().is_ok() {
            out.push_str(&format!("[{part}]"));
        } else {
            if !out.is_empty() {
                out.push('.');
            }
            out.push_str(part);
        }
    }
    out
}

/// (line, column) of the deepest part of a dotted key present in the text (array elements by
/// index): the value itself, or the table that lacks it.
fn key_line_col(text: &str, key: &str) -> Option<(u64, u64)> {
    let doc = toml::de::DeTable::parse(text).ok()?;
    let mut value = toml::de::DeValue::Table(doc.into_inner());
    let mut span = None;
    for part in key.split('.') {
        let next = match part.parse::<usize>() {
            Ok(i) => value.get(i),
            Err(_) => value.get(part),
        };
        let Some(next) = next else { break };
        span = Some(next.span());
        value = next.get_ref().clone();
    }
    span.map(|s| line_col(text, s.start))
}

#[cfg(test)]
mod tests {
    use super::*;

    const MINIMAL: &str = r#"
[store]
path = "live.sqlite"

[[sources]]
name = "log"
kind = "csv"
path = "log.csv"
timeout_ms = 1000
ramp_timeout_ms = 5000

[sensors.nut]
channel = "log.nut"

[[axes]]
name = "X"
model = "model.json"
limit_um = 50
slope_limit_um_per_m = 150
rate_limit_um_s = 2
"#;

    /// 1-based line of the first line containing `needle`.
    fn line_of(text: &str, needle: &str) -> usize {
        text.lines().position(|l| l.contains(needle)).unwrap() + 1
    }

    #[test]
    fn minimal_config_parses_with_defaults() {
        let c = LiveConfig::parse(Path::new("live.toml"), MINIMAL).unwrap();
        assert_eq!(c.cycle.period_ms, 100);
        assert_eq!(c.cycle.on_stop, OnStop::Hold);
        assert_eq!(c.sensors["nut"].max_c, 60.0);
        assert_eq!(c.store.retention_days, 30.0);
    }

    #[test]
    fn unknown_key_names_its_line() {
        let text = MINIMAL.replace("rate_limit_um_s = 2", "rate_limit_um_s = 2\nrate_limt = 3");
        let e = LiveConfig::parse(Path::new("live.toml"), &text).unwrap_err();
        let msg = e.to_string();
        assert!(
            msg.contains(&format!("live.toml:{}", line_of(&text, "rate_limt"))),
            "{msg}"
        );
        assert!(msg.contains("rate_limt"), "{msg}");
        assert!(matches!(e, ConfigError::Key(_)), "{e:?}");
    }

    #[test]
    fn validation_names_key_and_line() {
        let text = MINIMAL.replace("limit_um = 50", "limit_um = -5");
        let msg = LiveConfig::parse(Path::new("live.toml"), &text)
            .unwrap_err()
            .to_string();
        assert!(
            msg.contains(&format!("live.toml:{}", line_of(&text, "limit_um = -5"))),
            "{msg}"
        );
        assert!(msg.contains("axes[0].limit_um"), "{msg}");

        let text = MINIMAL.replace("\"log.nut\"", "\"rack.nut\"");
        let msg = LiveConfig::parse(Path::new("live.toml"), &text)
            .unwrap_err()
            .to_string();
        assert!(
            msg.contains(&format!("live.toml:{}", line_of(&text, "rack.nut"))),
            "{msg}"
        );
        assert!(
            msg.contains("sensors.nut.channel") && msg.contains("no source named 'rack'"),
            "{msg}"
        );

        let text = MINIMAL.replace("ramp_timeout_ms = 5000", "ramp_timeout_ms = 500");
        let msg = LiveConfig::parse(Path::new("live.toml"), &text)
            .unwrap_err()
            .to_string();
        let line = line_of(&text, "ramp_timeout_ms");
        assert!(
            msg.contains(&format!("live.toml:{line}")) && msg.contains("ramp timeout"),
            "{msg}"
        );
    }

    #[test]
    fn keys_of_another_kind_are_refused() {
        let text = MINIMAL.replace(
            "path = \"log.csv\"",
            "path = \"log.csv\"\naddress = \"1.2.3.4:502\"",
        );
        let msg = LiveConfig::parse(Path::new("live.toml"), &text)
            .unwrap_err()
            .to_string();
        let line = line_of(&text, "address");
        assert!(
            msg.contains(&format!("live.toml:{line}")) && msg.contains("no key 'address'"),
            "{msg}"
        );
    }
}
