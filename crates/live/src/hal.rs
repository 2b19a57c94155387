//! The link to LinuxCNC's HAL: a small userspace HAL component written in Python
//! (`hal_helper.py`, built into errmap) that errmap starts as a child process with LinuxCNC's
//! own interpreter and talks to over a pipe, one numbered request line and one reply line at a
//! time. errmap links no LinuxCNC library: without LinuxCNC only a `linuxcnc` source or target
//! fails, at start, with what to install.

use errmap_core::error::{Error, Result};
use serde::Serialize;
use std::collections::VecDeque;
use std::io::{BufRead, BufReader, Write};
use std::process::{Child, ChildStdin, Command, Stdio};
use std::sync::mpsc::{self, Receiver, RecvTimeoutError};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

/// The helper's source, run with `python -c`.
const HELPER: &str = include_str!("hal_helper.py");

/// How long the helper may take to start (Python, the `hal` module, `halcmd` for each link).
const START_TIMEOUT: Duration = Duration::from_secs(15);

/// An output pin of errmap's component, optionally linked to another HAL pin.
#[derive(Debug, Clone, Serialize)]
pub struct PinSpec {
    /// The pin's name within the component (`z.counts`).
    pub name: String,
    /// HAL type: `bit`, `float`, `s32`, `u32`.
    #[serde(rename = "type")]
    pub hal_type: &'static str,
    /// The HAL pin it drives (`axis.z.eoffset-counts`), linked at start.
    pub net: Option<String>,
    /// The signal a link creates when that pin is on none.
    pub signal: String,
}

/// A value read from HAL.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum HalValue {
    /// A bit pin or signal.
    Bit(bool),
    /// An s32 or u32.
    Integer(i64),
    /// A float.
    Float(f64),
}

impl HalValue {
    /// The value as a number (a bit as 1 or 0).
    pub fn as_f64(self) -> f64 {
        match self {
            HalValue::Bit(b) => f64::from(u8::from(b)),
            HalValue::Integer(i) => i as f64,
            HalValue::Float(x) => x,
        }
    }
}

/// A running helper: errmap's HAL component.
pub struct HalLink {
    /// What it serves, for messages (`LinuxCNC target 'mill'`).
    pub what: String,
    child: Child,
    stdin: Option<ChildStdin>,
    lines: Receiver<String>,
    stderr: Arc<Mutex<VecDeque<String>>>,
    next: u64,
    timeout: Duration,
}

impl HalLink {
    /// Start the helper with `python` as component `component` with `pins` (linked as they
    /// say) and wait for it to be ready. A helper that cannot start (no LinuxCNC, no `hal`
    /// module, a pin already driven) is an error naming why (exit 3).
    pub fn start(
        what: &str,
        python: &str,
        component: &str,
        pins: &[PinSpec],
        timeout: Duration,
    ) -> Result<HalLink> {
        let spec = serde_json::json!({ "component": component, "pins": pins }).to_string();
        let mut child = Command::new(python)
            .arg("-c")
            .arg(HELPER)
            .arg(spec)
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .map_err(|e| {
                Error::io(
                    "start",
                    format!("{what}: {python}"),
                    std::io::Error::new(
                        e.kind(),
                        format!("{e} (set the key python to LinuxCNC's Python 3, which has its hal module)"),
                    ),
                )
            })?;
        let (tx, lines) = mpsc::channel();
        let stdout = child.stdout.take();
        std::thread::Builder::new()
            .name("hal-helper-out".into())
            .spawn(move || {
                let Some(out) = stdout else { return };
                for line in BufReader::new(out).lines() {
                    let Ok(line) = line else { return };
                    if tx.send(line).is_err() {
                        return;
                    }
                }
            })
            .map_err(|e| Error::io("start the reader of", what, e))?;
        let stderr = Arc::new(Mutex::new(VecDeque::new()));
        let kept = stderr.clone();
        let err_pipe = child.stderr.take();
        std::thread::Builder::new()
            .name("hal-helper-err".into())
            .spawn(move || {
                let Some(err) = err_pipe else { return };
                for line in BufReader::new(err).lines() {
                    let Ok(line) = line else { return };
                    if let Ok(mut k) = kept.lock() {
                        if k.len() == 8 {
                            k.pop_front();
                        }
                        k.push_back(line);
                    }
                }
            })
            .map_err(|e| Error::io("start the reader of", what, e))?;
        let stdin = child.stdin.take();
        let mut link = HalLink {
            what: what.to_string(),
            child,
            stdin,
            lines,
            stderr,
            next: 1,
            timeout,
        };
        match link.reply(0, START_TIMEOUT) {
            Ok(r) if r == "ready" => Ok(link),
            Ok(r) => Err(link.unreachable(r.strip_prefix("err ").unwrap_or(&r).to_string())),
            Err(e) => Err(link.unreachable(e)),
        }
    }

    /// An error for a helper that could not start (exit 3), with its last words on stderr.
    fn unreachable(&mut self, message: String) -> Error {
        // Give a dying interpreter a moment to finish its traceback.
        let until = Instant::now() + Duration::from_millis(500);
        while Instant::now() < until && matches!(self.child.try_wait(), Ok(None)) {
            std::thread::sleep(Duration::from_millis(20));
        }
        let stderr = self.stderr_tail();
        let hint = if stderr.contains("No module named 'hal'") {
            " (LinuxCNC's Python module hal is not importable: install LinuxCNC, e.g. Debian's linuxcnc-uspace, or set python to the interpreter that has it)"
        } else {
            ""
        };
        Error::io(
            "reach",
            &self.what,
            std::io::Error::other(format!(
                "{message}{}{hint}",
                if stderr.is_empty() {
                    String::new()
                } else {
                    format!("; it said: {stderr}")
                }
            )),
        )
    }

    fn stderr_tail(&self) -> String {
        self.stderr
            .lock()
            .map(|k| k.iter().cloned().collect::<Vec<_>>().join(" | "))
            .unwrap_or_default()
    }

    /// The reply to request `number` (replies to earlier, timed-out requests are skipped).
    fn reply(&mut self, number: u64, timeout: Duration) -> std::result::Result<String, String> {
        let until = Instant::now() + timeout;
        loop {
            let left = until.saturating_duration_since(Instant::now());
            match self.lines.recv_timeout(left) {
                Ok(line) => {
                    let mut parts = line.splitn(2, ' ');
                    let n = parts.next().and_then(|n| n.parse::<u64>().ok());
                    if n == Some(number) {
                        return Ok(parts.next().unwrap_or("").to_string());
                    }
                }
                Err(RecvTimeoutError::Timeout) => {
                    return Err(format!("no answer within {} ms", timeout.as_millis()))
                }
                Err(RecvTimeoutError::Disconnected) => {
                    return Err(format!(
                        "the HAL helper ended ({})",
                        match self.child.try_wait() {
                            Ok(Some(status)) => status.to_string(),
                            _ => "its output closed".to_string(),
                        }
                    ))
                }
            }
        }
    }

    /// Send one request and wait for its reply's payload (after `ok`).
    fn request(&mut self, verb: &str, args: &str) -> std::result::Result<String, String> {
        let number = self.next;
        self.next += 1;
        let stdin = self.stdin.as_mut().ok_or("the HAL helper is closed")?;
        writeln!(stdin, "{number} {verb} {args}")
            .and_then(|()| stdin.flush())
            .map_err(|e| format!("the HAL helper's pipe: {e}"))?;
        let reply = self.reply(number, self.timeout)?;
        match reply.strip_prefix("ok") {
            Some(rest) => Ok(rest.trim().to_string()),
            None => Err(reply.strip_prefix("err ").unwrap_or(&reply).to_string()),
        }
    }

    /// Read pins, parameters or signals by name.
    pub fn get(&mut self, names: &[String]) -> std::result::Result<Vec<HalValue>, String> {
        let payload = self.request("get", &names.join(" "))?;
        let values = payload
            .split_whitespace()
            .map(|v| {
                let (tag, x) = v.split_at(1.min(v.len()));
                match tag {
                    "b" => Ok(HalValue::Bit(x == "1")),
                    "i" => x.parse().map(HalValue::Integer).map_err(|_| v.to_string()),
                    "f" => x.parse().map(HalValue::Float).map_err(|_| v.to_string()),
                    _ => Err(v.to_string()),
                }
            })
            .collect::<std::result::Result<Vec<_>, _>>()
            .map_err(|v| format!("the HAL helper answered '{v}'"))?;
        if values.len() != names.len() {
            return Err(format!(
                "the HAL helper answered {} values for {} names",
                values.len(),
                names.len()
            ));
        }
        Ok(values)
    }

    /// Set the component's own pins (`z.counts`, …).
    pub fn set(&mut self, values: &[(String, String)]) -> std::result::Result<(), String> {
        let args: Vec<String> = values.iter().map(|(k, v)| format!("{k}={v}")).collect();
        self.request("set", &args.join(" ")).map(|_| ())
    }
}

impl Drop for HalLink {
    /// Close the pipe (the helper exits and HAL removes its component; the signals keep their
    /// last values), then make sure the process is gone.
    fn drop(&mut self) {
        drop(self.stdin.take());
        let until = Instant::now() + Duration::from_secs(2);
        while Instant::now() < until {
            if !matches!(self.child.try_wait(), Ok(None)) {
                return;
            }
            std::thread::sleep(Duration::from_millis(10));
        }
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}
