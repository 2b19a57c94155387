//! The server's shared state, its routes and the layers every request passes: security headers, a bounded body, and the session check (302 to /login for pages, 401 under /api/).

use super::live::Feed;
use super::session::{CookieStyle, LoginTokens, Sessions};
use super::store::Db;
use super::throttle::Throttle;
use super::users::{Role, Users};
use axum::extract::{DefaultBodyLimit, Request, State};
use axum::http::{header, HeaderMap, HeaderValue, StatusCode};
use axum::middleware::{self, Next};
use axum::response::Response;
use axum::routing::{get, post};
use axum::Router;
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

/// Every response: the page policy unless the handler set its own, and the other headers.
async fn security_headers(State(app): State<Arc<App>>, req: Request, next: Next) -> Response {
    let mut res = next.run(req).await;
    let h = res.headers_mut();
    h.entry(header::CONTENT_SECURITY_POLICY)
        .or_insert(HeaderValue::from_static(PAGE_CSP));
    h.insert(
        header::X_CONTENT_TYPE_OPTIONS,
        HeaderValue::from_static("nosniff"),
    );
    h.insert(
        header::REFERRER_POLICY,
        HeaderValue::from_static("no-referrer"),
    );
    h.insert(header::X_FRAME_OPTIONS, HeaderValue::from_static("DENY"));
    h.insert(
        "cross-origin-opener-policy",
        HeaderValue::from_static("same-origin"),
    );
    h.insert(
        "cross-origin-resource-policy",
        HeaderValue::from_static("same-origin"),
    );
    h.entry(header::CACHE_CONTROL)
        .or_insert(HeaderValue::from_static("no-store"));
    if app.cookies.secure {
        h.insert(
            header::STRICT_TRANSPORT_SECURITY,
            HeaderValue::from_static("max-age=31536000"),
        );
    }
    res
}

/// The session check of every route but the login form and the static files.
async fn require_session(State(app): State<Arc<App>>, mut req: Request, next: Next) -> Response {
    let api = req.uri().path().starts_with("/api/");
    let name = app.cookies.session_name();
    let found = super::session::cookie(req.headers(), name)
        .map(str::to_string)
        .and_then(|id| app.sessions.touch(&id).map(|s| (id, s)));
    // The users file as it is now decides: a removed user's session ends, a changed role applies.
    let auth = found.and_then(|(id, s)| {
        let users = app.users();
        let u = users.get(&s.user)?;
        Some(Auth {
            session_id: id,
            user: s.user,
            role: u.role,
            csrf: s.csrf,
        })
    });
    match auth {
        Some(a) => {
            req.extensions_mut().insert(a);
            next.run(req).await
        }
        None if api => fail(StatusCode::UNAUTHORIZED, true, "log in first: POST /login"),
        None => {
            let mut r = Response::new(axum::body::Body::empty());
            *r.status_mut() = StatusCode::FOUND;
            r.headers_mut()
                .insert(header::LOCATION, HeaderValue::from_static("/login"));
            r
        }
    }
}

async fn style() -> Response {
    with_type(
        StatusCode::OK,
        "text/css; charset=utf-8",
        include_str!("assets/app.css"),
    )
}

async fn script() -> Response {
    with_type(
        StatusCode::OK,
        "text/javascript; charset=utf-8",
        include_str!("assets/live.js"),
    )
}

async fn not_found(req: Request) -> Response {
    let api = req.uri().path().starts_with("/api/");
    fail(StatusCode::NOT_FOUND, api, "no such page")
}

/// The routes.
pub fn router(app: Arc<App>) -> Router {
    use super::{login, views};
    let protected = Router::new()
        .route("/", get(|| async { see_other("/live") }))
        .route("/live", get(views::live_page))
        .route("/live/command", post(views::command))
        .route("/logout", post(login::logout))
        .route("/history", get(views::history))
        .route("/history/campaign", get(views::campaign))
        .route("/runs", get(|| async { see_other("/runs/") }))
        .route("/runs/", get(views::runs_root))
        .route("/runs/{*path}", get(views::run_file))
        .route("/api/live", get(views::live_stream))
        .route("/api/state", get(views::live_state))
        .fallback(not_found)
        // `layer`, not `route_layer`: unknown paths need a session too.
        .layer(middleware::from_fn_with_state(app.clone(), require_session));
    Router::new()
        .route("/login", get(login::form).post(login::submit))
        .route("/static/app.css", get(style))
        .route("/static/live.js", get(script))
        // Browsers ask for it on every site: an empty answer, not a 404 in their console.
        .route("/favicon.ico", get(|| async { StatusCode::NO_CONTENT }))
        .merge(protected)
        .layer(DefaultBodyLimit::max(MAX_BODY_BYTES))
        .layer(middleware::from_fn_with_state(
            app.clone(),
            security_headers,
        ))
        .with_state(app)
}

/// How long a request may wait for a password check before 503.
pub const HASH_WAIT: Duration = Duration::from_secs(10);
