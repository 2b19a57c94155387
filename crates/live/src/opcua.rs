//! OPC UA client (crate `async-opcua`) for the live loop: a session on a one-worker tokio
//! runtime, with blocking reads and writes of node values bounded by a timeout. Security
//! policy `None` (message security mode None), anonymous or user name and password.

use errmap_core::error::Error;
use opcua::client::{ClientBuilder, IdentityToken, Password, Session};
use opcua::types::{
    AttributeId, DataValue, EndpointDescription, MessageSecurityMode, NodeId, NumericRange,
    ReadValueId, StatusCode, TimestampsToReturn, UserTokenPolicy, Variant, WriteValue,
};
use std::str::FromStr;
use std::sync::Arc;
use std::time::Duration;

/// A node's value as read.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum NodeValue {
    /// A numeric node (any integer or floating type), as f64.
    Number(f64),
    /// A Boolean node (e.g. coolant on).
    Flag(bool),
}

/// A connected session.
pub struct OpcUa {
    rt: tokio::runtime::Runtime,
    session: Arc<Session>,
    /// The server's endpoint URL, for messages.
    pub endpoint: String,
    timeout: Duration,
}

/// Parse a node id (`ns=2;s=Temperatures.T1`, `ns=2;i=1001`); `key` names it in messages.
pub fn node_id(text: &str) -> std::result::Result<NodeId, String> {
    NodeId::from_str(text).map_err(|_| format!("'{text}' is not a node id"))
}

/// Why a connection failed.
#[derive(Debug)]
pub enum ConnectError {
    /// The server refused the session's user identity (`BadUserAccessDenied`,
    /// `BadIdentityTokenRejected`, `BadIdentityTokenInvalid`): a wrong user name or password,
    /// or a login the server does not take. The status code's name.
    Denied(String),
    /// The server could not be reached or the session failed otherwise (exit 3).
    Failed(Error),
}

impl From<ConnectError> for Error {
    fn from(e: ConnectError) -> Error {
        match e {
            ConnectError::Failed(e) => e,
            ConnectError::Denied(code) => Error::io(
                "log in to",
                "the OPC UA server",
                std::io::Error::other(code),
            ),
        }
    }
}

impl std::fmt::Display for ConnectError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            ConnectError::Denied(code) => write!(f, "the server refused the login ({code})"),
            ConnectError::Failed(e) => write!(f, "{e}"),
        }
    }
}

/// The error of a login the server refused, for a source or target at `key` of `config`
/// (`what` names it): the `user` key (or the source or target itself when it logs in
/// anonymously), exit 2 with what to check.
pub fn denied_error(
    config: &crate::config::LiveConfig,
    key: &str,
    what: &str,
    endpoint: &str,
    user: Option<&str>,
    code: &str,
) -> Error {
    let (at, how) = match user {
        Some(u) => (
            format!("{key}.user"),
            format!("user '{u}' with the configured password"),
        ),
        None => (key.to_string(), "an anonymous session".to_string()),
    };
    config.key_error(
        &at,
        format!("{what} at {endpoint} refused {how} ({code})"),
        "check the `user` and `password` keys against the server's user accounts (a user allowed \
         to read and write these nodes); without `user` errmap logs in anonymously",
    )
}

/// The status codes with which a server refuses a session's user identity.
fn is_denial(code: StatusCode) -> bool {
    matches!(
        code,
        StatusCode::BadUserAccessDenied
            | StatusCode::BadIdentityTokenRejected
            | StatusCode::BadIdentityTokenInvalid
    )
}

impl OpcUa {
    /// Connect: [`ConnectError::Denied`] when the server refuses the user identity (the caller
    /// names the `user` and `password` keys, exit 2), [`ConnectError::Failed`] when it cannot
    /// be reached or the session fails otherwise (exit 3).
    pub fn connect(
        what: &str,
        endpoint: &str,
        user: Option<&str>,
        password: Option<&str>,
        timeout: Duration,
    ) -> std::result::Result<OpcUa, ConnectError> {
        let unreachable = |e: String| {
            ConnectError::Failed(Error::io(
                "connect to",
                format!("{what} at {endpoint}"),
                std::io::Error::other(e),
            ))
        };
        let rt = tokio::runtime::Builder::new_multi_thread()
            .worker_threads(1)
            .enable_all()
            .build()
            .map_err(|e| unreachable(e.to_string()))?;
        let mut client = ClientBuilder::new()
            .application_name("errmap live")
            .application_uri("urn:errmap:live")
            .product_uri("urn:errmap")
            .create_sample_keypair(false)
            .trust_server_certs(true)
            .pki_dir(std::env::temp_dir().join("errmap-live-pki"))
            .session_retry_limit(0)
            .request_timeout(timeout)
            .client()
            .map_err(|e| unreachable(e.join("; ")))?;
        let description: EndpointDescription = (
            endpoint,
            "None",
            MessageSecurityMode::None,
            UserTokenPolicy::anonymous(),
        )
            .into();
        let identity = match user {
            Some(u) => {
                IdentityToken::UserName(u.to_string(), Password::new(password.unwrap_or("")))
            }
            None => IdentityToken::Anonymous,
        };
        let session = rt.block_on(async {
            let (session, event_loop) = tokio::time::timeout(
                timeout,
                client.connect_to_matching_endpoint(description, identity),
            )
            .await
            .map_err(|_| unreachable(format!("no answer within {} ms", timeout.as_millis())))?
            .map_err(|e| {
                if is_denial(e.status()) {
                    ConnectError::Denied(format!("{}", e.status()))
                } else {
                    unreachable(e.to_string())
                }
            })?;
            let mut ended = event_loop.spawn();
            // The event loop ends with the status of a session it could not establish (a
            // refused login among them); the session never reports a connection then.
            let outcome = tokio::time::timeout(timeout, async {
                tokio::select! {
                    connected = session.wait_for_connection() => Ok(connected),
                    code = &mut ended => Err(code),
                }
            })
            .await;
            match outcome {
                Ok(Ok(true)) => Ok(session),
                Ok(Err(Ok(code))) if is_denial(code) => {
                    Err(ConnectError::Denied(format!("{code}")))
                }
                Ok(Err(Ok(code))) => Err(unreachable(format!(
                    "the session was not established ({code})"
                ))),
                _ => Err(unreachable(
                    "the session was not established (user, password, security policy?)"
                        .to_string(),
                )),
            }
        });
        let session = session?;
        Ok(OpcUa {
            rt,
            session,
            endpoint: endpoint.to_string(),
            timeout,
        })
    }

    /// Read nodes' values; a node whose status is not Good is an error naming it.
    pub fn read(&self, nodes: &[NodeId]) -> std::result::Result<Vec<NodeValue>, String> {
        let ids: Vec<ReadValueId> = nodes.iter().map(|n| ReadValueId::from(n.clone())).collect();
        let values = self.rt.block_on(async {
            tokio::time::timeout(
                self.timeout,
                self.session.read(&ids, TimestampsToReturn::Neither, 0.0),
            )
            .await
        });
        let values = values
            .map_err(|_| format!("no answer within {} ms", self.timeout.as_millis()))?
            .map_err(|e| e.to_string())?;
        if values.len() != nodes.len() {
            return Err(format!("{} values for {} nodes", values.len(), nodes.len()));
        }
        values
            .iter()
            .zip(nodes)
            .map(|(dv, n)| value_of(dv).map_err(|e| format!("{n}: {e}")))
            .collect()
    }

    /// Write doubles to nodes in one request; a refused node is an error naming it.
    pub fn write(&self, values: &[(NodeId, f64)]) -> std::result::Result<(), String> {
        let writes: Vec<WriteValue> = values
            .iter()
            .map(|(n, v)| WriteValue {
                node_id: n.clone(),
                attribute_id: AttributeId::Value as u32,
                index_range: NumericRange::None,
                value: DataValue::value_only(Variant::Double(*v)),
            })
            .collect();
        let result = self.rt.block_on(async {
            tokio::time::timeout(self.timeout, self.session.write(&writes)).await
        });
        let codes = result
            .map_err(|_| format!("no answer within {} ms", self.timeout.as_millis()))?
            .map_err(|e| e.to_string())?;
        for ((n, _), code) in values.iter().zip(&codes) {
            if !code.is_good() {
                return Err(format!("{n}: {code}"));
            }
        }
        if codes.len() != values.len() {
            return Err(format!(
                "{} results for {} writes",
                codes.len(),
                values.len()
            ));
        }
        Ok(())
    }
}

impl Drop for OpcUa {
    fn drop(&mut self) {
        let session = self.session.clone();
        let _ = self.rt.block_on(async {
            tokio::time::timeout(Duration::from_millis(500), session.disconnect()).await
        });
    }
}

/// A data value as a number or a bit; a bad status or a non-numeric type is an error.
fn value_of(dv: &DataValue) -> std::result::Result<NodeValue, String> {
    if let Some(status) = &dv.status {
        if !status.is_good() {
            return Err(format!("status {status}"));
        }
    }
    match &dv.value {
        Some(Variant::Boolean(b)) => Ok(NodeValue::Flag(*b)),
        Some(Variant::Double(v)) => Ok(NodeValue::Number(*v)),
        Some(Variant::Float(v)) => Ok(NodeValue::Number(f64::from(*v))),
        Some(Variant::Int16(v)) => Ok(NodeValue::Number(f64::from(*v))),
        Some(Variant::UInt16(v)) => Ok(NodeValue::Number(f64::from(*v))),
        Some(Variant::Int32(v)) => Ok(NodeValue::Number(f64::from(*v))),
        Some(Variant::UInt32(v)) => Ok(NodeValue::Number(f64::from(*v))),
        Some(Variant::Int64(v)) => Ok(NodeValue::Number(*v as f64)),
        Some(Variant::UInt64(v)) => Ok(NodeValue::Number(*v as f64)),
        Some(Variant::SByte(v)) => Ok(NodeValue::Number(f64::from(*v))),
        Some(Variant::Byte(v)) => Ok(NodeValue::Number(f64::from(*v))),
        Some(other) => Err(format!("value {other:?} is not a number")),
        None => Err("no value".into()),
    }
}
