//! An OPC UA source: a thread reads every channel's node each `period_ms` in one Read request
//! and hands the values to the loop; a node with a bad status, or a failed request, is the
//! source's problem (no update: the watchdog sees the age grow), and the thread reconnects.

use super::{Snapshot, Source, Value};
use crate::config::{LiveConfig, SourceConfig};
use crate::opcua::{denied_error, node_id, ConnectError, NodeValue, OpcUa};
use errmap_core::error::{Error, Result};
use opcua::types::NodeId;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

#[derive(Default)]
struct Shared {
    values: Vec<NodeValue>,
    at: Option<Instant>,
    fresh: bool,
    problem: Option<String>,
    quit: bool,
}

/// A source whose channels are OPC UA nodes, read each poll over one session.
pub struct OpcUaSource {
    name: String,
    channels: Vec<String>,
    shared: Arc<Mutex<Shared>>,
    snap: Snapshot,
    thread: Option<std::thread::JoinHandle<()>>,
}

/// How to connect again.
struct Login {
    what: String,
    endpoint: String,
    user: Option<String>,
    password: Option<String>,
    timeout: Duration,
}

impl Login {
    fn connect(&self) -> std::result::Result<OpcUa, ConnectError> {
        OpcUa::connect(
            &self.what,
            &self.endpoint,
            self.user.as_deref(),
            self.password.as_deref(),
            self.timeout,
        )
    }
}

impl OpcUaSource {
    /// Connect the source `sources[index]` of `config` (an error when the server cannot be
    /// reached or the config asks for what it cannot do).
    pub fn connect(config: &LiveConfig, index: usize, s: &SourceConfig) -> Result<OpcUaSource> {
        let key = format!("sources.{index}");
        check_security(config, &key, s.security_policy.as_deref())?;
        let mut nodes = Vec::new();
        for (j, c) in s.channels.iter().enumerate() {
            let k = format!("{key}.channels.{j}");
            let text = c.node.as_deref().ok_or_else(|| {
                config.key_error(
                    &k,
                    format!("channel '{}' has no node", c.name),
                    "node = \"ns=2;s=…\"",
                )
            })?;
            nodes.push(node_id(text).map_err(|e| {
                config.key_error(&format!("{k}.node"), e, "e.g. ns=2;s=Temperatures.T1")
            })?);
        }
        let login = Login {
            what: format!("OPC UA source '{}'", s.name),
            endpoint: s.endpoint.clone().unwrap_or_default(),
            user: s.user.clone(),
            password: s.password.clone(),
            timeout: Duration::from_millis(s.timeout_ms),
        };
        let client = login.connect().map_err(|e| match e {
            ConnectError::Denied(code) => denied_error(
                config,
                &key,
                &login.what,
                &login.endpoint,
                login.user.as_deref(),
                &code,
            ),
            ConnectError::Failed(e) => e,
        })?;
        let first = client.read(&nodes).map_err(|e| {
            Error::io(
                "read from",
                format!("{} at {}", login.what, login.endpoint),
                std::io::Error::other(e),
            )
        })?;
        let shared = Arc::new(Mutex::new(Shared {
            values: first,
            at: Some(Instant::now()),
            fresh: true,
            problem: None,
            quit: false,
        }));
        let period = Duration::from_millis(s.period_ms.unwrap_or(config.cycle.period_ms).max(1));
        let poller = shared.clone();
        let thread = std::thread::Builder::new()
            .name(format!("opcua-{}", s.name))
            .spawn(move || poll_loop(client, login, nodes, poller, period))
            .map_err(|e| Error::io("start the poller of", &s.name, e))?;
        Ok(OpcUaSource {
            name: s.name.clone(),
            channels: s.channels.iter().map(|c| c.name.clone()).collect(),
            shared,
            snap: Snapshot::default(),
            thread: Some(thread),
        })
    }
}

/// Only security policy None is built in.
pub fn check_security(config: &LiveConfig, key: &str, policy: Option<&str>) -> Result<()> {
    match policy {
        None | Some("None") => Ok(()),
        Some(other) => Err(config.key_error(
            &format!("{key}.security_policy"),
            format!("security policy '{other}' is not built into errmap live"),
            "use \"None\" on a protected machine network (user and password still apply)",
        )),
    }
}

fn poll_loop(
    client: OpcUa,
    login: Login,
    nodes: Vec<NodeId>,
    shared: Arc<Mutex<Shared>>,
    period: Duration,
) {
    let mut client = Some(client);
    let mut next = Instant::now() + period;
    loop {
        let now = Instant::now();
        if next > now {
            std::thread::sleep(next - now);
        }
        next += period;
        if Instant::now() > next {
            next = Instant::now() + period;
        }
        if shared.lock().map(|s| s.quit).unwrap_or(true) {
            return;
        }
        if client.is_none() {
            client = login.connect().ok();
        }
        let result = match &client {
            Some(c) => c.read(&nodes),
            None => Err(format!("cannot connect to {}", login.endpoint)),
        };
        let Ok(mut s) = shared.lock() else { return };
        match result {
            Ok(values) => {
                s.values = values;
                s.at = Some(Instant::now());
                s.fresh = true;
                s.problem = None;
            }
            Err(e) => {
                // A bad node keeps the session; a failed request reconnects.
                let bad_node = e.contains("status");
                s.problem = Some(e);
                drop(s);
                if !bad_node {
                    client = None;
                }
            }
        }
    }
}

impl Source for OpcUaSource {
    fn name(&self) -> &str {
        &self.name
    }
    fn kind(&self) -> &'static str {
        "opcua"
    }
    fn channel_names(&self) -> Vec<String> {
        self.channels.clone()
    }
    fn poll(&mut self, now_s: f64) {
        let Ok(mut s) = self.shared.lock() else {
            return;
        };
        self.snap.problem = s.problem.clone();
        if !s.fresh {
            return;
        }
        s.fresh = false;
        let at_s = now_s - s.at.map_or(0.0, |a| a.elapsed().as_secs_f64());
        for (name, v) in self.channels.iter().zip(&s.values) {
            let value = match v {
                NodeValue::Number(x) => Value::Number(*x),
                NodeValue::Flag(b) => Value::Flag(*b),
            };
            self.snap.set(name, value, at_s);
        }
        self.snap.last_ok_s = Some(at_s);
    }
    fn snapshot(&self) -> &Snapshot {
        &self.snap
    }
}

impl Drop for OpcUaSource {
    fn drop(&mut self) {
        if let Ok(mut s) = self.shared.lock() {
            s.quit = true;
        }
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}
