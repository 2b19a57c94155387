//! The routes and the layers every request passes: security headers, a bounded body, and the session check (302 to /login for pages, 401 under /api/).

use super::app::{fail, see_other, with_type, App, Auth, MAX_BODY_BYTES, PAGE_CSP};
use super::{login, views};
use axum::extract::{DefaultBodyLimit, Request, State};
use axum::http::{header, HeaderValue, StatusCode};
use axum::middleware::{self, Next};
use axum::response::Response;
use axum::routing::{get, post};
use axum::Router;
use std::sync::Arc;

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
