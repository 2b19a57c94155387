//! An OPC UA source: a thread reads every channel's node each `period_ms` in one Read request
//! and hands the values to the loop; a node with a bad status, or a failed request, is the
//! source's problem (no update: the watchdog sees the age grow), and the thread reconnects.

use super::poll::{poll_period, Device, Failure, PolledSource};
use super::Value;
use crate::config::{LiveConfig, SourceConfig};
use crate::opcua::{denied_error, node_id, ConnectError, NodeValue, OpcUa};
use crate::LinkError;
use errmap_core::error::Result;
use opcua::types::NodeId;
use std::time::Duration;

/// How to connect (again), and the nodes to read.
struct Login {
    what: String,
    endpoint: String,
    user: Option<String>,
    password: Option<String>,
    timeout: Duration,
    nodes: Vec<NodeId>,
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

/// Connect the source `sources[index]` of `config` (an error when the server cannot be
/// reached or the config asks for what it cannot do).
pub fn connect(
    config: &LiveConfig,
    index: usize,
    s: &SourceConfig,
) -> Result<PolledSource, LinkError> {
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
        nodes,
    };
    let client = login.connect().map_err(|e| match e {
        // The login refused, as the server said: the `user` key is the one to fix.
        ConnectError::Denied(code) => LinkError::Refused(denied_error(
            config,
            &key,
            &login.what,
            &login.endpoint,
            login.user.as_deref(),
            &code,
        )),
        ConnectError::Failed(e) => LinkError::from(e),
    })?;
    let place = format!("{} at {}", login.what, login.endpoint);
    let names = s.channels.iter().map(|c| c.name.clone()).collect();
    let period = poll_period(config, s);
    Ok(PolledSource::start(
        "opcua", &s.name, &place, names, login, client, period,
    )?)
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

impl Device for Login {
    type Link = OpcUa;
    fn reconnect(&self) -> Option<OpcUa> {
        self.connect().ok()
    }
    fn unreachable(&self) -> String {
        format!("cannot connect to {}", self.endpoint)
    }
    fn read(&self, client: &mut OpcUa) -> std::result::Result<Vec<Value>, Failure> {
        match client.read(&self.nodes) {
            Ok(values) => Ok(values
                .into_iter()
                .map(|v| match v {
                    NodeValue::Number(x) => Value::Number(x),
                    NodeValue::Flag(b) => Value::Flag(b),
                })
                .collect()),
            // A bad node keeps the session; a failed request reconnects.
            Err(message) => Err(Failure {
                reconnect: !message.contains("status"),
                message,
            }),
        }
    }
}
