//! `errmap serve`: a small web server with login over errmap's own data — the live loop's state (pushed by Server-Sent Events), the temperature history store, and the batch runs (read-only) — for engineers watching from the office. See docs/monitor.md.
//!
//! Modules: `users` (the users file, argon2id), `session` (ids, CSRF tokens, cookies),
//! `throttle` (failed logins), `store` (live_commands, audit_log, history queries), `live`
//! (the state file feed), `runs` (paths confined to the runs folder), `svg` (charts), `pages`
//! (HTML), `app` (shared state and helpers), `routes` (routes and layers), `login`, `views`
//! (handlers), `clock` (UTC stamps).
#![forbid(unsafe_code)]
#![warn(missing_docs)]
#![deny(rustdoc::broken_intra_doc_links)]

pub mod app;
pub mod clock;
mod error;
pub mod live;
pub mod login;
pub mod pages;
pub mod routes;
pub mod runs;
pub mod session;
mod setting;
pub mod store;
pub mod svg;
pub mod throttle;
pub mod users;
pub mod views;

pub use error::{ServeError, UsersError};
pub use setting::Setting;

use errmap_core::error::{Error, Location};
use errmap_core::setting::words;
use std::net::{IpAddr, SocketAddr};
use std::path::{Path, PathBuf};
use std::sync::{Arc, RwLock};
use std::time::Duration;

/// Everything `errmap serve` is started with.
#[derive(Debug, Clone)]
pub struct Config {
    /// The temperature-history store (`--db`, SQLite); must exist. Opened in WAL mode with a
    /// 2000 ms busy timeout, as `errmap live` opens it.
    pub db: PathBuf,
    /// The folder of batch runs served read-only under `/runs/` (`--runs`); `None`: no runs pages.
    pub runs: Option<PathBuf>,
    /// The state file a running `errmap live --state` rewrites (`--live`); it may not exist yet.
    /// `None`: the live page has no feed.
    pub live: Option<PathBuf>,
    /// Address and port to listen on (`--bind`); port 0 lets the system pick a free port.
    pub bind: SocketAddr,
    /// Certificate chain and private key, PEM (`--tls-cert`, `--tls-key`); `None`: plain HTTP,
    /// which [`check_transport`] allows only on loopback or with `insecure_http`.
    pub tls: Option<(PathBuf, PathBuf)>,
    /// The users file (`--users`; by default [`default_users_path`]); must exist at start.
    pub users: PathBuf,
    /// Reverse proxies whose `X-Forwarded-For` is believed (`--trusted-proxy`); from any other
    /// peer the header is ignored.
    pub trusted_proxies: Vec<IpAddr>,
    /// Allow plain HTTP on a non-loopback address (`--insecure-http`; a warning is logged).
    pub insecure_http: bool,
    /// A session unused this long ends (`--idle-timeout`, default 1800 s); an open live stream
    /// does not count as idle.
    pub idle_timeout: Duration,
    /// A session ends this long after its login, used or not (`--session-lifetime`, default 8 h).
    pub absolute_timeout: Duration,
    /// Live streams (`/api/live`) open at once; beyond it a new stream gets 503
    /// (`--max-live-clients`, default 1000, at least 1).
    pub max_live_clients: usize,
}

/// The users file's default place: `users.toml` beside the store.
pub fn default_users_path(db: &Path) -> PathBuf {
    db.parent()
        .filter(|p| !p.as_os_str().is_empty())
        .map_or_else(|| PathBuf::from("users.toml"), |p| p.join("users.toml"))
}

/// The checks before anything is opened: a non-loopback address needs TLS (or the explicit
/// `--insecure-http`, with a warning); a certificate needs its key.
pub fn check_transport(cfg: &Config) -> Result<Option<String>, ServeError> {
    if cfg.tls.is_none() && !cfg.bind.ip().is_loopback() {
        if !cfg.insecure_http {
            return Err(ServeError::Transport(Error::usage(
                format!(
                    "{} is not a loopback address and no TLS certificate was given: passwords and session cookies would cross the network in clear text",
                    cfg.bind.ip()
                ),
                format!(
                    "give {} PEM {} PEM, bind to 127.0.0.1 behind a TLS reverse proxy (with {}), or accept the risk with {}",
                    words(Setting::TlsCert),
                    words(Setting::TlsKey),
                    words(Setting::TrustedProxy),
                    words(Setting::InsecureHttp)
                ),
            )));
        }
        return Ok(Some(format!(
            "warning: serving plain HTTP on {} ({}): passwords and session cookies cross the network unencrypted",
            cfg.bind,
            words(Setting::InsecureHttp)
        )));
    }
    Ok(None)
}

/// Start the server and serve until SIGINT or SIGTERM. `on_listening` gets the bound
/// address (the command prints it; port 0 asks the system for a free port).
pub fn run(cfg: Config, on_listening: impl FnOnce(&str) + Send) -> Result<(), ServeError> {
    if let Some(warning) = check_transport(&cfg)? {
        app::log(&warning);
    }
    let users = users::Users::load(&cfg.users, false).map_err(|e| match e {
        UsersError::Missing(_) => UsersError::Missing(Error::input(
            Location::file(&cfg.users),
            "no users file",
            format!(
                "add a user first: errmap serve user add NAME {} operator {} {} {}",
                words(Setting::Role),
                words(Setting::Users),
                cfg.users.display(),
                words(Setting::PasswordStdin)
            ),
        )),
        other => other,
    })?;
    if users.users.is_empty() {
        app::log(&format!(
            "warning: {} lists no user: nobody can log in",
            cfg.users.display()
        ));
    }
    let runs = match &cfg.runs {
        Some(r) => Some(
            r.canonicalize()
                .ok()
                .filter(|c| c.is_dir())
                .ok_or_else(|| {
                    ServeError::Runs(Error::input(
                        Location::file(r),
                        "the runs folder does not exist or is not a folder",
                        "give the folder that holds the batch runs (e.g. out/)",
                    ))
                })?,
        ),
        None => None,
    };
    let db = Arc::new(store::Db::open(&cfg.db).map_err(ServeError::store)?);
    let tls_pem = match &cfg.tls {
        Some((cert, key)) => Some((
            std::fs::read(cert).map_err(|e| ServeError::Tls(Error::read(cert, e)))?,
            std::fs::read(key).map_err(|e| ServeError::Tls(Error::read(key, e)))?,
        )),
        None => None,
    };
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()
        .map_err(|e| {
            ServeError::Internal(Error::Internal(format!(
                "cannot start the async runtime: {e}"
            )))
        })?;
    runtime.block_on(async move {
        let tls = match (tls_pem, &cfg.tls) {
            (Some((cert, key)), Some((cert_path, _))) => Some(
                axum_server::tls_rustls::RustlsConfig::from_pem(cert, key)
                    .await
                    .map_err(|e| {
                        ServeError::Tls(Error::input(
                            Location::file(cert_path),
                            format!("not a usable TLS certificate and key: {e}"),
                            format!(
                                "give a PEM certificate chain with {} and its PEM private key with {}",
                                words(Setting::TlsCert),
                                words(Setting::TlsKey)
                            ),
                        ))
                    })?,
            ),
            _ => None,
        };
        let listener = std::net::TcpListener::bind(cfg.bind)
            .map_err(|e| ServeError::Bind(Error::io("listen on", cfg.bind.to_string(), e)))?;
        let local = listener
            .local_addr()
            .map_err(|e| ServeError::Bind(Error::io("listen on", cfg.bind.to_string(), e)))?;
        let dummy_hash =
            users::hash_password(&session::random_token()).map_err(ServeError::Internal)?;
        let app = Arc::new(app::App {
            db,
            runs,
            users_path: cfg.users.clone(),
            users: RwLock::new(Arc::new(users)),
            sessions: session::Sessions::new(session::Timeouts {
                idle: cfg.idle_timeout,
                absolute: cfg.absolute_timeout,
            }),
            login_tokens: session::LoginTokens::new(),
            throttle: throttle::Throttle::default(),
            feed: live::Feed::start(cfg.live.clone()),
            cookies: session::CookieStyle {
                secure: tls.is_some(),
            },
            trusted_proxies: cfg.trusted_proxies.iter().copied().map(app::canonical_ip).collect(),
            hash_gate: tokio::sync::Semaphore::new(2),
            dummy_hash,
            live_clients: std::sync::atomic::AtomicUsize::new(0),
            max_live_clients: cfg.max_live_clients,
        });
        tokio::spawn(reload_users(app.clone()));
        let service = routes::router(app.clone()).into_make_service_with_connect_info::<SocketAddr>();
        let handle = axum_server::Handle::new();
        tokio::spawn(shutdown_on_signal(handle.clone()));
        let scheme = if tls.is_some() { "https" } else { "http" };
        on_listening(&format!("{scheme}://{local}"));
        let served = match tls {
            Some(tls) => {
                axum_server::from_tcp_rustls(listener, tls)
                    .map_err(|e| ServeError::Bind(Error::io("listen on", local.to_string(), e)))?
                    .handle(handle)
                    .first_request_timeout(Duration::from_secs(10))
                    .serve(service)
                    .await
            }
            None => {
                axum_server::from_tcp(listener)
                    .map_err(|e| ServeError::Bind(Error::io("listen on", local.to_string(), e)))?
                    .handle(handle)
                    .first_request_timeout(Duration::from_secs(10))
                    .serve(service)
                    .await
            }
        };
        served.map_err(|e| ServeError::Bind(Error::io("serve on", local.to_string(), e)))
    })
}

async fn shutdown_on_signal(handle: axum_server::Handle<SocketAddr>) {
    let ctrl_c = tokio::signal::ctrl_c();
    #[cfg(unix)]
    {
        let mut term =
            match tokio::signal::unix::signal(tokio::signal::unix::SignalKind::terminate()) {
                Ok(t) => t,
                Err(_) => {
                    let _ = ctrl_c.await;
                    handle.graceful_shutdown(Some(Duration::from_secs(5)));
                    return;
                }
            };
        tokio::select! {
            _ = ctrl_c => {}
            _ = term.recv() => {}
        }
    }
    #[cfg(not(unix))]
    let _ = ctrl_c.await;
    app::log("stopping");
    handle.graceful_shutdown(Some(Duration::from_secs(5)));
}

/// Re-read the users file when it changes (checked every second): a removed user's sessions
/// end, a new password or role applies at the next request. A file that no longer reads is
/// logged and the last good list kept.
async fn reload_users(app: Arc<app::App>) {
    let stamp = |p: &Path| {
        std::fs::metadata(p)
            .ok()
            .map(|m| (m.modified().ok(), m.len()))
    };
    let mut last = stamp(&app.users_path);
    let mut tick = tokio::time::interval(Duration::from_secs(1));
    loop {
        tick.tick().await;
        let now = stamp(&app.users_path);
        if now == last {
            continue;
        }
        last = now;
        let path = app.users_path.clone();
        match tokio::task::spawn_blocking(move || users::Users::load(&path, true)).await {
            Ok(Ok(users)) => {
                let users = Arc::new(users);
                *app.users.write().unwrap_or_else(|p| p.into_inner()) = users.clone();
                app.sessions.retain_users(|u| users.get(u).is_some());
                app::log(&format!("users file re-read: {} users", users.users.len()));
            }
            Ok(Err(e)) => app::log(&format!(
                "users file not re-read, keeping the last good one: {e}"
            )),
            Err(_) => {}
        }
    }
}
