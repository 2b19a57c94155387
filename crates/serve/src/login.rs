//! Login and logout: the form with its pre-session token, the password check (throttled, the same generic answer for a wrong name or password), a new session id at each login, and logout ending the session.

use super::app::{fail, html, log, see_other, App, Auth, HASH_WAIT};
use super::pages;
use super::throttle::Blocked;
use super::users::{normalise_name, verify_password, MAX_NAME_CHARS};
use axum::extract::rejection::FormRejection;
use axum::extract::{ConnectInfo, State};
use axum::http::{header, HeaderMap, HeaderValue, StatusCode};
use axum::response::Response;
use axum::{Extension, Form};
use serde::Deserialize;
use std::net::SocketAddr;
use std::sync::Arc;

/// The one answer to a wrong name or password (OWASP Authentication Cheat Sheet: generic
/// error messages).
pub const WRONG: &str = "Login failed: wrong user name or password.";

fn now_s() -> i64 {
    super::clock::now_ms() / 1000
}

/// The login page with a fresh pre-session cookie and the form token tied to it.
fn login_page(app: &App, status: StatusCode, message: Option<&str>) -> Response {
    let (pre, token) = app.login_tokens.issue(now_s());
    let mut r = html(status, pages::login(&token, message));
    if let Ok(v) = HeaderValue::from_str(&app.cookies.set(app.cookies.login_name(), &pre)) {
        r.headers_mut().append(header::SET_COOKIE, v);
    }
    r
}

/// `GET /login`: the login form, with a new pre-session cookie and the form token tied to it.
pub async fn form(State(app): State<Arc<App>>) -> Response {
    login_page(&app, StatusCode::OK, None)
}

/// The fields `POST /login` needs: `user`, `password` and `csrf` (the form's token).
#[derive(Deserialize)]
pub struct LoginForm {
    user: String,
    password: String,
    csrf: String,
}

/// `POST /login`, in order: a form that parses (else 400, or 413 over 16 KiB); the form's token
/// must be the HMAC of this browser's pre-session cookie and under an hour old (else 403 and a
/// fresh form); the throttle (5 failures in 15 min per name or address: 429 with `Retry-After`,
/// audited); the password, checked against the user's argon2id hash or a dummy one for an
/// unknown name, at most 2 at once (401 with one message for both cases, counted and audited;
/// 503 after waiting 10 s for a slot). On success the user's failures are forgotten, the
/// session the browser carried ends, a new session is made and its cookie set, the pre-session
/// cookie cleared, the login audited, and the answer is 303 to `/live`.
pub async fn submit(
    State(app): State<Arc<App>>,
    ConnectInfo(peer): ConnectInfo<SocketAddr>,
    headers: HeaderMap,
    form: Result<Form<LoginForm>, FormRejection>,
) -> Response {
    let addr = app.client_addr(peer, &headers);
    let form = match form {
        Ok(Form(f)) => f,
        Err(rejection) if rejection.status() == StatusCode::PAYLOAD_TOO_LARGE => {
            return fail(
                StatusCode::PAYLOAD_TOO_LARGE,
                false,
                "the request is too large",
            );
        }
        Err(_) => {
            return fail(
                StatusCode::BAD_REQUEST,
                false,
                "the login form needs the fields user, password and csrf",
            )
        }
    };
    // Login CSRF: the form must come from this browser's pre-session.
    let pre = super::session::cookie(&headers, app.cookies.login_name()).unwrap_or("");
    if !app.login_tokens.check(pre, &form.csrf, now_s()) {
        log(&format!(
            "login refused (form token) for {:?} from {addr}",
            truncate(&form.user)
        ));
        return login_page(
            &app,
            StatusCode::FORBIDDEN,
            Some(
                "The login form had expired or did not come from this server; please log in again.",
            ),
        );
    }
    // Throttling counts the name as typed (bounded), existing or not.
    let key = normalise_name(&form.user).unwrap_or_else(|| truncate(&form.user).to_lowercase());
    if let Some(blocked) = app.throttle.check(&key, addr) {
        let (what, s) = match blocked {
            Blocked::User { retry_after_s } => ("user", retry_after_s),
            Blocked::Address { retry_after_s } => ("address", retry_after_s),
        };
        log(&format!(
            "login throttled for {key:?} from {addr}: 5 failures of this {what} in 15 min, retry after {s} s"
        ));
        app.audit(
            Some(&key),
            addr,
            "login_throttled",
            Some(format!("{what}; retry after {s} s")),
        )
        .await;
        let mut r = login_page(
            &app,
            StatusCode::TOO_MANY_REQUESTS,
            Some(&format!(
                "Too many failed logins: try again in {} min.",
                blocked.retry_after_s().div_ceil(60)
            )),
        );
        r.headers_mut().insert(
            header::RETRY_AFTER,
            HeaderValue::from(blocked.retry_after_s()),
        );
        return r;
    }
    let user = app.users().get(&key).cloned();
    let hash = user
        .as_ref()
        .map_or_else(|| app.dummy_hash.clone(), |u| u.password_hash.clone());
    let password = form.password;
    let Ok(Ok(_permit)) = tokio::time::timeout(HASH_WAIT, app.hash_gate.acquire()).await else {
        return fail(
            StatusCode::SERVICE_UNAVAILABLE,
            false,
            "the server is busy; try again",
        );
    };
    let good = tokio::task::spawn_blocking(move || verify_password(&password, &hash))
        .await
        .unwrap_or(false);
    drop(_permit);
    let Some(user) = user.filter(|_| good) else {
        let (by_user, by_addr) = app.throttle.fail(&key, addr);
        log(&format!(
            "login failed for {key:?} from {addr} ({by_user} failures of this user, {by_addr} of this address in 15 min)"
        ));
        app.audit(Some(&key), addr, "login_failed", None).await;
        return login_page(&app, StatusCode::UNAUTHORIZED, Some(WRONG));
    };
    app.throttle.succeed(&user.name);
    // A session the browser still carries ends: the new one gets a new id.
    if let Some(old) = super::session::cookie(&headers, app.cookies.session_name()) {
        app.sessions.remove(old);
    }
    let Some((id, _)) = app.sessions.create(&user.name, user.role) else {
        return fail(
            StatusCode::SERVICE_UNAVAILABLE,
            false,
            "too many sessions; try again later",
        );
    };
    log(&format!(
        "login of {:?} ({}) from {addr}",
        user.name,
        user.role.as_str()
    ));
    app.audit(
        Some(&user.name),
        addr,
        "login",
        Some(user.role.as_str().to_string()),
    )
    .await;
    let mut r = see_other("/live");
    for c in [
        app.cookies.set(app.cookies.session_name(), &id),
        app.cookies.clear(app.cookies.login_name()),
    ] {
        if let Ok(v) = HeaderValue::from_str(&c) {
            r.headers_mut().append(header::SET_COOKIE, v);
        }
    }
    r
}

/// A name as typed, cut to the longest a name may be (for logs and throttling keys).
fn truncate(text: &str) -> String {
    text.chars().take(MAX_NAME_CHARS).collect()
}

/// A form carrying only the session's CSRF token (`csrf`), as `POST /logout` sends it.
#[derive(Deserialize)]
pub struct CsrfForm {
    csrf: String,
}

/// Whether a state-changing request carries its session's token (compared in constant time;
/// `None`: no token sent); a refusal is logged and audited as `refused` with `what`. The caller
/// must still answer 403 on `false`, and check the role where the action needs one.
pub async fn csrf_ok(
    app: &App,
    auth: &Auth,
    token: Option<&str>,
    addr: std::net::IpAddr,
    what: &str,
) -> bool {
    if token.is_some_and(|t| super::session::same_secret(t, &auth.csrf)) {
        return true;
    }
    log(&format!(
        "{what} refused for {:?} from {addr}: missing or wrong CSRF token",
        auth.user
    ));
    app.audit(
        Some(&auth.user),
        addr,
        "refused",
        Some(format!("{what}: CSRF token")),
    )
    .await;
    false
}

/// `POST /logout`: with the session's CSRF token (else 403, audited), ends the session on the
/// server, audits it, clears the session cookie and answers 303 to `/login`. Its live stream
/// ends at its next check.
pub async fn logout(
    State(app): State<Arc<App>>,
    Extension(auth): Extension<Auth>,
    ConnectInfo(peer): ConnectInfo<SocketAddr>,
    headers: HeaderMap,
    form: Result<Form<CsrfForm>, FormRejection>,
) -> Response {
    let addr = app.client_addr(peer, &headers);
    let token = form.as_ref().ok().map(|f| f.csrf.as_str());
    if !csrf_ok(&app, &auth, token, addr, "logout").await {
        return fail(
            StatusCode::FORBIDDEN,
            false,
            "missing or wrong CSRF token: reload the page",
        );
    }
    app.sessions.remove(&auth.session_id);
    log(&format!("logout of {:?} from {addr}", auth.user));
    app.audit(Some(&auth.user), addr, "logout", None).await;
    let mut r = see_other("/login");
    if let Ok(v) = HeaderValue::from_str(&app.cookies.clear(app.cookies.session_name())) {
        r.headers_mut().append(header::SET_COOKIE, v);
    }
    r
}
