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
    /// The store: `live_commands` and `audit_log` written, history read.
    pub db: Arc<Db>,
    /// The canonical runs folder (symlinks resolved at start); `None`: no `--runs`, so
    /// `/runs/` answers 404.
    pub runs: Option<PathBuf>,
    /// The users file, re-read within a second of a change.
    pub users_path: PathBuf,
    /// The last good read of the users file; read through [`App::users`].
    pub users: RwLock<Arc<Users>>,
    /// The logged-in sessions (in memory only: a restart logs everyone out).
    pub sessions: Sessions,
    /// Issues and checks the login form's token (login CSRF), under a key made at start.
    pub login_tokens: LoginTokens,
    /// Failed logins per user name and per client address (5 in 15 min give 429).
    pub throttle: Throttle,
    /// The state file's latest snapshot, shared by every live stream.
    pub feed: Feed,
    /// Cookie names and attributes: `__Host-` and `Secure` when serving TLS (also turns HSTS on).
    pub cookies: CookieStyle,
    /// `--trusted-proxy` addresses, IPv4-mapped IPv6 written as IPv4 ([`canonical_ip`]).
    pub trusted_proxies: Vec<IpAddr>,
    /// At most this many password checks at once (each takes 19 MiB and tens of ms); a login
    /// waits at most [`HASH_WAIT`] for a permit, then gets 503.
    pub hash_gate: tokio::sync::Semaphore,
    /// A hash checked when the user does not exist, so the answer takes as long.
    pub dummy_hash: String,
    /// Live streams (`/api/live`) open now.
    pub live_clients: AtomicUsize,
    /// Most live streams at once (`--max-live-clients`); a stream beyond it gets 503.
    pub max_live_clients: usize,
}

/// The logged-in user of a request, put in its extensions by the session check of
/// [`crate::routes::router`] (a live session of a user still in the users file).
#[derive(Debug, Clone)]
pub struct Auth {
    /// The session id as the cookie carried it (a secret: never log or show it).
    pub session_id: String,
    /// The user name (lower case, as in the users file).
    pub user: String,
    /// The role from the users file as it is at this request, not as it was at login.
    pub role: Role,
    /// The session's synchronizer token; a handler that changes state must still compare the
    /// submitted form's token with it ([`crate::session::same_secret`]) and check the role.
    pub csrf: String,
}

impl Auth {
    /// The user, role and CSRF token a page needs to draw its header, logout form and
    /// operator buttons.
    pub fn viewer(&self) -> super::pages::Viewer<'_> {
        super::pages::Viewer {
            user: &self.user,
            role: self.role,
            csrf: &self.csrf,
        }
    }
}

/// A line of the server's log on stderr, prefixed with the UTC time (ms). The line is written
/// as given: callers quote submitted names with `{:?}` so a name cannot forge log lines.
pub fn log(line: &str) {
    eprintln!("{} errmap serve: {line}", super::clock::utc_now_ms());
}

impl App {
    /// The users file as last read (a cheap shared copy; a concurrent reload does not change it).
    pub fn users(&self) -> Arc<Users> {
        self.users.read().unwrap_or_else(|p| p.into_inner()).clone()
    }

    /// The client's address, for throttling and the audit log: the peer's, or, when the peer is
    /// a trusted proxy, the right-most address in `X-Forwarded-For` (all such headers, in order)
    /// that is not itself a trusted proxy. Entries are read from the right, the side the proxies
    /// append to, so what a client writes in front of them is never reached; when the right-most
    /// untrusted entry does not parse as an IP address, or every entry is a trusted proxy, the
    /// peer's address is used.
    pub fn client_addr(&self, peer: SocketAddr, headers: &HeaderMap) -> IpAddr {
        let peer_ip = canonical_ip(peer.ip());
        if !self.trusted_proxies.contains(&peer_ip) {
            return peer_ip;
        }
        let entries: Vec<&str> = headers
            .get_all("x-forwarded-for")
            .iter()
            .filter_map(|v| v.to_str().ok())
            .flat_map(|v| v.split(','))
            .collect();
        for entry in entries.into_iter().rev() {
            match entry.trim().parse::<IpAddr>().map(canonical_ip) {
                Ok(ip) if self.trusted_proxies.contains(&ip) => continue,
                Ok(ip) => return ip,
                Err(_) => return peer_ip,
            }
        }
        peer_ip
    }

    /// Write an `audit_log` row (`user`: the user acting, or the name tried for a failed login;
    /// `action` as in the table's comment) and wait for it, so it is written before the request
    /// is answered; a failed write is logged on stderr, not returned.
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

/// An HTML page with this status.
pub fn html(status: StatusCode, body: String) -> Response {
    with_type(status, "text/html; charset=utf-8", body)
}

/// A JSON answer (`application/json`) with this status; `body` must already be JSON.
pub fn json(status: StatusCode, body: String) -> Response {
    with_type(status, "application/json", body)
}

/// An error answer: an HTML page with the text, or, with `api`, `{"error": text}` as JSON.
/// The text is shown to the client: put no secret in it.
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

/// A 303 See Other redirect, so the browser GETs `location` (after a POST); an invalid
/// header value leaves the `Location` header out.
pub fn see_other(location: &str) -> Response {
    let mut r = Response::new(axum::body::Body::empty());
    *r.status_mut() = StatusCode::SEE_OTHER;
    if let Ok(v) = HeaderValue::from_str(location) {
        r.headers_mut().insert(header::LOCATION, v);
    }
    r
}

/// How long a login may wait for a free password-check slot ([`App::hash_gate`]) before 503.
pub const HASH_WAIT: Duration = Duration::from_secs(10);
