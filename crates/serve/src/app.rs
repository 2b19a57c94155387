//! The server's shared state (store, users, sessions, throttle, live feed), the logged-in user of a request, the client address rule, the content security policies and the small response helpers every handler uses.

use super::live::Feed;
use super::session::{CookieStyle, LoginTokens, Sessions};
use super::store::Db;
use super::throttle::Throttle;
use super::users::{Role, Users};
use axum::http::{header, HeaderMap, HeaderValue, StatusCode};
use axum::response::Response;
use std::net::{IpAddr, SocketAddr};
use std::path::PathBuf;
use std::sync::atomic::AtomicUsize;
use std::sync::{Arc, RwLock};
use std::time::Duration;

/// The policy of every page of the server: its own style sheet and script only, nothing
/// framed, no form posted elsewhere.
pub const PAGE_CSP: &str = "default-src 'none'; script-src 'self'; style-src 'self'; img-src 'self'; connect-src 'self'; form-action 'self'; frame-ancestors 'none'; base-uri 'none'";
/// The policy of a run's files (report.html: inline style, `data:` images, no script).
pub const RUN_FILE_CSP: &str = "default-src 'none'; style-src 'unsafe-inline'; img-src data:; font-src data:; frame-ancestors 'none'; base-uri 'none'; form-action 'none'";
/// Largest request body (login and command forms are a few hundred bytes).
pub const MAX_BODY_BYTES: usize = 16 * 1024;

/// What a running server holds.
pub struct App {
    pub db: Arc<Db>,
    pub runs: Option<PathBuf>,
    pub users_path: PathBuf,
    pub users: RwLock<Arc<Users>>,
    pub sessions: Sessions,
    pub login_tokens: LoginTokens,
    pub throttle: Throttle,
    pub feed: Feed,
    pub cookies: CookieStyle,
    pub trusted_proxies: Vec<IpAddr>,
    /// At most this many password checks at once (each takes 19 MiB and tens of ms).
    pub hash_gate: tokio::sync::Semaphore,
    /// A hash checked when the user does not exist, so the answer takes as long.
    pub dummy_hash: String,
    pub live_clients: AtomicUsize,
    pub max_live_clients: usize,
}

/// The logged-in user of a request (put there by [`require_session`]).
#[derive(Debug, Clone)]
pub struct Auth {
    pub session_id: String,
    pub user: String,
    pub role: Role,
    pub csrf: String,
}

impl Auth {
    pub fn viewer(&self) -> super::pages::Viewer<'_> {
        super::pages::Viewer {
            user: &self.user,
            role: self.role,
            csrf: &self.csrf,
        }
    }
}

/// A line of the server's log on stderr, time-stamped; names are quoted with escapes so a
/// submitted name cannot forge log lines.
pub fn log(line: &str) {
    eprintln!("{} errmap serve: {line}", super::clock::utc_now_ms());
}

impl App {
    pub fn users(&self) -> Arc<Users> {
        self.users.read().unwrap_or_else(|p| p.into_inner()).clone()
    }

    /// The client's address: the peer's, or, when the peer is a trusted proxy, the last
    /// address in X-Forwarded-For that is not itself a trusted proxy.
    pub fn client_addr(&self, peer: SocketAddr, headers: &HeaderMap) -> IpAddr {
        let peer_ip = canonical_ip(peer.ip());
        if !self.trusted_proxies.contains(&peer_ip) {
            return peer_ip;
        }
        let forwarded: Vec<IpAddr> = headers
            .get_all("x-forwarded-for")
            .iter()
            .filter_map(|v| v.to_str().ok())
            .flat_map(|v| v.split(','))
            .map(|s| s.trim().parse::<IpAddr>().map(canonical_ip))
            .collect::<Result<_, _>>()
            .unwrap_or_default();
        forwarded
            .into_iter()
            .rev()
            .find(|ip| !self.trusted_proxies.contains(ip))
            .unwrap_or(peer_ip)
    }

    /// Write an audit row before the request is answered; a failure is logged.
    pub async fn audit(
        &self,
        user: Option<&str>,
        address: IpAddr,
        action: &str,
        detail: Option<String>,
    ) {
        let db = self.db.clone();
        let user = user.map(str::to_string);
        let action = action.to_string();
        let written = tokio::task::spawn_blocking(move || {
            db.audit(
                user.as_deref(),
                &address.to_string(),
                &action,
                detail.as_deref(),
            )
        })
        .await;
        if let Ok(Err(e)) = written {
            log(&format!("audit log write failed: {e}"));
        }
    }
}

/// IPv4-mapped IPv6 addresses as IPv4, so one client has one key.
pub fn canonical_ip(ip: IpAddr) -> IpAddr {
    match ip {
        IpAddr::V6(v6) => v6.to_ipv4_mapped().map_or(ip, IpAddr::V4),
        v4 => v4,
    }
}

/// A response with a content type and body.
pub fn with_type(
    status: StatusCode,
    content_type: &'static str,
    body: impl Into<axum::body::Body>,
) -> Response {
    let mut r = Response::new(body.into());
    *r.status_mut() = status;
    r.headers_mut()
        .insert(header::CONTENT_TYPE, HeaderValue::from_static(content_type));
    r
}

pub fn html(status: StatusCode, body: String) -> Response {
    with_type(status, "text/html; charset=utf-8", body)
}

pub fn json(status: StatusCode, body: String) -> Response {
    with_type(status, "application/json", body)
}

/// An error page (or JSON under /api/).
pub fn fail(status: StatusCode, api: bool, text: &str) -> Response {
    if api {
        json(status, serde_json::json!({ "error": text }).to_string())
    } else {
        html(
            status,
            super::pages::error(status.canonical_reason().unwrap_or("Error"), text),
        )
    }
}

/// A redirect that makes the browser GET the target.
pub fn see_other(location: &str) -> Response {
    let mut r = Response::new(axum::body::Body::empty());
    *r.status_mut() = StatusCode::SEE_OTHER;
    if let Ok(v) = HeaderValue::from_str(location) {
        r.headers_mut().insert(header::LOCATION, v);
    }
    r
}

/// How long a request may wait for a password check before 503.
pub const HASH_WAIT: Duration = Duration::from_secs(10);
