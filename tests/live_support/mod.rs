//! Shared by the `errmap live` tests: a scratch folder with the sample model, configs, running
//! the binary, reading the store, and an independent evaluation of the thermal model (Legendre
//! recurrence, IEC 60751 inverse in closed form, causal median and Savitzky–Golay by an SVD
//! least-squares fit) written from docs/thermal.md, not from errmap's code.
#![allow(dead_code)]

use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

pub const ERRMAP: &str = env!("CARGO_BIN_EXE_errmap");

pub fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// A scratch folder holding a copy of the sample model.
pub fn scratch() -> tempfile::TempDir {
    let dir = tempfile::tempdir().unwrap();
    std::fs::copy(
        repo().join("data/thermal-live/model.json"),
        dir.path().join("model.json"),
    )
    .unwrap();
    dir
}

/// A config for the sample model: one CSV source `log` (file `log.csv`), the three sensors,
/// coolant, axis X with position and direction; `extra_loop` and `extra_source` add keys.
pub fn config(loop_keys: &str, source_keys: &str, axis_keys: &str, sensor_keys: &str) -> String {
    format!(
        r#"[loop]
{loop_keys}

[store]
path = "live.sqlite"

[[sources]]
name = "log"
kind = "csv"
path = "log.csv"
{source_keys}

[sensors.nut]
channel = "log.nut"
{sensor_keys}

[sensors.bearing]
channel = "log.bearing"
{sensor_keys}

[sensors.room]
channel = "log.ambient_c"
{sensor_keys}

[coolant]
channel = "log.coolant"

[[axes]]
name = "X"
model = "model.json"
position = "log.position_mm"
direction = "log.direction"
{axis_keys}
"#
    )
}

pub fn run(args: &[&str], dir: &Path) -> Output {
    Command::new(ERRMAP)
        .args(args)
        .current_dir(dir)
        .output()
        .unwrap()
}

/// The replay both comparisons with `errmap thermal compensate` use: 2 h of a row every 10 s,
/// campaign 3, the coolant switching every 10 minutes (both gain tables are used).
pub fn two_hours_coolant_switching(dir: &Path) -> Vec<String> {
    synth_replay(
        dir,
        &[
            "--hours",
            "2",
            "--period-s",
            "10",
            "--coolant-every-s",
            "600",
            "--campaign",
            "3",
        ],
    )
}

/// Rows of a replay made by `errmap synth live-replay` (header first).
pub fn synth_replay(dir: &Path, args: &[&str]) -> Vec<String> {
    let out = dir.join("synth.csv");
    let mut all = vec!["synth", "live-replay", "-o", out.to_str().unwrap()];
    all.extend_from_slice(args);
    let o = run(&all, dir);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    std::fs::read_to_string(out)
        .unwrap()
        .lines()
        .map(str::to_string)
        .collect()
}

/// One logged cycle.
#[derive(Debug, Clone)]
pub struct Cycle {
    pub cycle: i64,
    pub at_utc: String,
    pub mode: String,
    pub inputs: Value,
    pub outputs: Value,
    pub note: Option<String>,
}

impl Cycle {
    pub fn time_s(&self) -> f64 {
        self.inputs["time_s"].as_f64().unwrap()
    }
    pub fn x(&self, key: &str) -> Option<f64> {
        self.outputs["X"][key].as_f64()
    }
}

pub fn cycles(db: &Path) -> Vec<Cycle> {
    let conn = rusqlite::Connection::open(db).unwrap();
    let mut stmt = conn
        .prepare("SELECT cycle, at_utc, mode, inputs_json, outputs_json, note FROM live_cycles ORDER BY cycle")
        .unwrap();
    stmt.query_map([], |r| {
        Ok(Cycle {
            cycle: r.get(0)?,
            at_utc: r.get(1)?,
            mode: r.get(2)?,
            inputs: serde_json::from_str(&r.get::<_, String>(3)?).unwrap(),
            outputs: serde_json::from_str(&r.get::<_, String>(4)?).unwrap(),
            note: r.get(5)?,
        })
    })
    .unwrap()
    .collect::<rusqlite::Result<Vec<_>>>()
    .unwrap()
}

/// The sample model, read as plain JSON.
pub struct Model {
    pub json: Value,
}

/// Legendre polynomials by Bonnet's recurrence: n·P_n = (2n−1)s·P_{n−1} − (n−1)·P_{n−2}.
fn legendre(coefficients: &[f64], s: f64) -> f64 {
    let (mut pm2, mut pm1, mut sum) = (0.0, 0.0, 0.0);
    for (n, c) in coefficients.iter().enumerate() {
        let p = match n {
            0 => 1.0,
            1 => s,
            _ => {
                let nf = n as f64;
                ((2.0 * nf - 1.0) * s * pm1 - (nf - 1.0) * pm2) / nf
            }
        };
        pm2 = pm1;
        pm1 = p;
        sum += c * p;
    }
    sum
}

impl Model {
    pub fn read(path: &Path) -> Model {
        Model {
            json: serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap(),
        }
    }

    fn sensor(&self, name: &str) -> &Value {
        self.json["sensors"]
            .as_array()
            .unwrap()
            .iter()
            .find(|s| s["name"] == name)
            .unwrap()
    }

    /// A raw reading as calibrated °C: Pt100 Ω inverted in closed form above 0 °C
    /// (R = R0(1 + A·t + B·t²)), then T = scale·t + offset.
    pub fn celsius(&self, name: &str, raw: f64) -> f64 {
        let s = self.sensor(name);
        let t = if s["unit"] == "ohm" {
            let (a, b) = (3.9083e-3, -5.775e-7);
            (-a + (a * a - 4.0 * b * (1.0 - raw / 100.0)).sqrt()) / (2.0 * b)
        } else {
            raw
        };
        s["calibration"]["scale"].as_f64().unwrap() * t
            + s["calibration"]["offset_c"].as_f64().unwrap()
    }

    /// The raw reading that calibrates to `t_c` (the inverse of [`Model::celsius`]).
    pub fn raw(&self, name: &str, t_c: f64) -> f64 {
        let s = self.sensor(name);
        let t = (t_c - s["calibration"]["offset_c"].as_f64().unwrap())
            / s["calibration"]["scale"].as_f64().unwrap();
        if s["unit"] == "ohm" {
            100.0 * (1.0 + 3.9083e-3 * t - 5.775e-7 * t * t)
        } else {
            t
        }
    }

    pub fn filter(&self, name: &str) -> (usize, usize, usize) {
        let f = &self.sensor(name)["filter"];
        let g = |k: &str| f[k].as_u64().unwrap() as usize;
        (g("median_window"), g("sg_window"), g("sg_order"))
    }

    /// tanβ (µm/m) of a direction (0 forward, 1 reverse) for calibrated temperatures.
    pub fn tan_beta(&self, d: usize, temps: &dyn Fn(&str) -> f64, coolant: &str) -> f64 {
        let m = &self.json;
        let dir = &m["directions"][d];
        let gains = dir["gains"]
            .as_array()
            .unwrap()
            .iter()
            .find(|g| g["coolant"] == coolant)
            .unwrap();
        let amb_name = m["ambient_sensor"].as_str().unwrap();
        let ta = temps(amb_name);
        let mut slope = 0.0;
        for name in m["gain_sensors"].as_array().unwrap() {
            let name = name.as_str().unwrap();
            let k = gains["k_um_per_m_k"][name].as_f64().unwrap();
            let r0 = m["reference_rise_c"][name].as_f64().unwrap();
            slope += k * ((temps(name) - ta) - r0);
        }
        slope
            + dir["rho_um_per_m_k"].as_f64().unwrap()
                * (ta - m["reference_ambient_c"].as_f64().unwrap())
    }

    /// E(x, T) (µm) of a direction.
    pub fn error_um(&self, d: usize, x: f64, temps: &dyn Fn(&str) -> f64, coolant: &str) -> f64 {
        let m = &self.json;
        let (lo, hi) = (
            m["x_min_mm"].as_f64().unwrap(),
            m["x_max_mm"].as_f64().unwrap(),
        );
        let s = ((2.0 * x - lo - hi) / (hi - lo)).clamp(-1.0, 1.0);
        let c: Vec<f64> = m["directions"][d]["legendre_um"]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_f64().unwrap())
            .collect();
        legendre(&c, s) + self.tan_beta(d, temps, coolant) * (x - self.px()) / 1000.0
    }

    pub fn px(&self) -> f64 {
        self.json["reference_point_mm"].as_f64().unwrap()
    }
}

/// The causal filter docs/live.md describes: the median of the last `median` readings (the
/// mean of the middle two for an even count while filling), then the order-`order` least-
/// squares polynomial through the last `window` medians evaluated at the newest (the median
/// itself until `window` medians exist).
pub struct Causal {
    median: usize,
    window: usize,
    order: usize,
    raw: Vec<f64>,
    medians: Vec<f64>,
}

impl Causal {
    pub fn new((median, window, order): (usize, usize, usize)) -> Causal {
        Causal {
            median,
            window,
            order,
            raw: Vec::new(),
            medians: Vec::new(),
        }
    }

    pub fn push(&mut self, v: f64) -> f64 {
        self.raw.push(v);
        let from = self.raw.len().saturating_sub(self.median);
        let mut w = self.raw[from..].to_vec();
        w.sort_by(|a, b| a.partial_cmp(b).unwrap());
        let n = w.len();
        let med = if n % 2 == 1 {
            w[n / 2]
        } else {
            0.5 * (w[n / 2 - 1] + w[n / 2])
        };
        if self.window <= 1 {
            return med;
        }
        self.medians.push(med);
        if self.medians.len() < self.window {
            return med;
        }
        let ys = &self.medians[self.medians.len() - self.window..];
        // Abscissae −(window−1) … 0: the value at 0 is the fitted constant term.
        let a = nalgebra::DMatrix::from_fn(self.window, self.order + 1, |i, j| {
            ((i as f64) - (self.window as f64 - 1.0)).powi(j as i32)
        });
        let y = nalgebra::DVector::from_column_slice(ys);
        let coef = a.svd(true, true).solve(&y, 1e-12).unwrap();
        coef[0]
    }
}

/// The Python of the CI virtualenv (`ERRMAP_LIVE_VENV`, else `ERRMAP_NCI_VENV`, else
/// `.ci/venv`) when it can import `module`; otherwise None, and a test whose
/// `ERRMAP_REQUIRE_<require>` is 1 fails.
pub fn venv_python(module: &str, require: &str) -> Option<PathBuf> {
    let venv = std::env::var_os("ERRMAP_LIVE_VENV")
        .or_else(|| std::env::var_os("ERRMAP_NCI_VENV"))
        .map(PathBuf::from)
        .unwrap_or_else(|| repo().join(".ci/venv"));
    let python = venv.join("bin/python");
    let ok = Command::new(&python)
        .args(["-c", &format!("import {module}")])
        .output()
        .is_ok_and(|o| o.status.success());
    if ok {
        return Some(python);
    }
    let var = format!("ERRMAP_REQUIRE_{require}");
    if std::env::var(&var).as_deref() == Ok("1") {
        panic!(
            "{var}=1 but {} cannot import {module}: run .ci/run or pip install it there",
            python.display()
        );
    }
    eprintln!(
        "skipped: {} cannot import {module} (set ERRMAP_LIVE_VENV)",
        python.display()
    );
    None
}

/// A free loopback port (the OS picks it; released for the server to bind).
pub fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port()
}

/// A Python server process driven by JSON lines on its stdin.
pub struct PyServer {
    pub child: std::process::Child,
    stdin: std::process::ChildStdin,
    stdout: std::io::BufReader<std::process::ChildStdout>,
    pub port: u16,
}

impl PyServer {
    /// Start `script` (in tests/live_support) with the port as its argument; waits for `ready`.
    pub fn start(python: &Path, script: &str, args: &[&str]) -> PyServer {
        PyServer::start_on(python, script, args, free_port())
    }

    /// [`PyServer::start`] on a given port (a server started again where it was).
    pub fn start_on(python: &Path, script: &str, args: &[&str], port: u16) -> PyServer {
        use std::io::BufRead;
        let mut child = Command::new(python)
            .arg(repo().join("tests/live_support").join(script))
            .arg(port.to_string())
            .args(args)
            .stdin(std::process::Stdio::piped())
            .stdout(std::process::Stdio::piped())
            .spawn()
            .unwrap();
        let stdin = child.stdin.take().unwrap();
        let mut stdout = std::io::BufReader::new(child.stdout.take().unwrap());
        let mut line = String::new();
        stdout.read_line(&mut line).unwrap();
        assert_eq!(line.trim(), "ready", "server {script} did not start");
        PyServer {
            child,
            stdin,
            stdout,
            port,
        }
    }

    /// Send one command, return its answer line.
    pub fn ask(&mut self, command: &Value) -> String {
        use std::io::{BufRead, Write};
        writeln!(self.stdin, "{command}").unwrap();
        self.stdin.flush().unwrap();
        let mut line = String::new();
        self.stdout.read_line(&mut line).unwrap();
        line.trim().to_string()
    }

    pub fn stop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

impl Drop for PyServer {
    fn drop(&mut self) {
        self.stop();
    }
}

/// Waits for a condition (a state of the system under test, never a fixed time), 60 s at most.
pub fn wait_for<T>(what: &str, mut f: impl FnMut() -> Option<T>) -> T {
    let start = std::time::Instant::now();
    loop {
        if let Some(v) = f() {
            return v;
        }
        assert!(
            start.elapsed() < std::time::Duration::from_secs(60),
            "timed out waiting for {what}"
        );
        std::thread::sleep(std::time::Duration::from_millis(50));
    }
}

/// The newest logged cycle, once the store has any.
pub fn newest(dir: &Path) -> Option<Cycle> {
    let db = dir.join("live.sqlite");
    if !db.exists() {
        return None;
    }
    let conn = rusqlite::Connection::open(&db).ok()?;
    conn.busy_timeout(std::time::Duration::from_millis(2000))
        .ok()?;
    let has: i64 = conn
        .query_row(
            "SELECT COUNT(*) FROM sqlite_master WHERE name = 'live_cycles'",
            [],
            |r| r.get(0),
        )
        .ok()?;
    if has == 0 {
        return None;
    }
    let (cycle, at_utc, mode, inputs, outputs, note) = conn
        .query_row(
            "SELECT cycle, at_utc, mode, inputs_json, outputs_json, note FROM live_cycles ORDER BY cycle DESC LIMIT 1",
            [],
            |r| {
                Ok((
                    r.get::<_, i64>(0)?,
                    r.get::<_, String>(1)?,
                    r.get::<_, String>(2)?,
                    r.get::<_, String>(3)?,
                    r.get::<_, String>(4)?,
                    r.get::<_, Option<String>>(5)?,
                ))
            },
        )
        .ok()?;
    Some(Cycle {
        cycle,
        at_utc,
        mode,
        inputs: serde_json::from_str(&inputs).ok()?,
        outputs: serde_json::from_str(&outputs).ok()?,
        note,
    })
}

/// Whether any logged note contains `needle`.
pub fn noted(dir: &Path, needle: &str) -> bool {
    let conn = rusqlite::Connection::open(dir.join("live.sqlite")).unwrap();
    conn.busy_timeout(std::time::Duration::from_millis(2000))
        .unwrap();
    conn.query_row(
        "SELECT COUNT(*) FROM live_cycles WHERE note LIKE ?1",
        [format!("%{needle}%")],
        |r| r.get::<_, i64>(0),
    )
    .unwrap()
        > 0
}

/// Readings of a warm machine: row 7201 (2 h in) of synthetic campaign 1, a row a second, as
/// (nut Ω, bearing °C, room °C).
pub fn warm_readings(dir: &Path) -> (f64, f64, f64) {
    let rows = synth_replay(dir, &["--hours", "4", "--period-s", "1", "--campaign", "1"]);
    let f: Vec<f64> = rows[7201]
        .split(',')
        .take(6)
        .skip(3)
        .map(|v| v.parse().unwrap())
        .collect();
    (f[0], f[1], f[2])
}

/// The OPC UA test server (tests/live_support/opcua_server.py): set a node's value.
pub fn ua_set(s: &mut PyServer, node: &str, value: Value) {
    assert_eq!(
        s.ask(&serde_json::json!({"op": "set", "node": node, "value": value})),
        "ok"
    );
}

/// The OPC UA test server: a node's value as the server holds it.
pub fn ua_get(s: &mut PyServer, node: &str) -> f64 {
    serde_json::from_str::<f64>(&s.ask(&serde_json::json!({"op": "get", "node": node}))).unwrap()
}

/// The config tables reading the OPC UA test server on `port` as source `nc` (its `login`
/// lines, e.g. `user = …`, and its timeouts) with the three sensors unfiltered and the coolant.
pub fn ua_source_tables(port: u16, login: &str, timeout_ms: u64, ramp_timeout_ms: u64) -> String {
    format!(
        r#"[[sources]]
name = "nc"
kind = "opcua"
endpoint = "opc.tcp://127.0.0.1:{port}/"
security_policy = "None"
{login}
period_ms = 100
timeout_ms = {timeout_ms}
ramp_timeout_ms = {ramp_timeout_ms}
channels = [
  {{ name = "nut", node = "ns=2;s=T.nut" }},
  {{ name = "bearing", node = "ns=2;s=T.bearing" }},
  {{ name = "room", node = "ns=2;s=T.room" }},
  {{ name = "coolant", node = "ns=2;s=Coolant" }},
  {{ name = "x", node = "ns=2;s=X.position" }},
  {{ name = "dir", node = "ns=2;s=X.direction" }},
]

[sensors.nut]
channel = "nc.nut"
filter = "none"
[sensors.bearing]
channel = "nc.bearing"
filter = "none"
[sensors.room]
channel = "nc.room"
filter = "none"

[coolant]
channel = "nc.coolant"
"#
    )
}
