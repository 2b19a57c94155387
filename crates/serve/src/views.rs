//! The pages and APIs behind the login: live (page, SSE stream, state), operator commands, history (live cycles, campaigns, models) and the runs folder.

use super::app::{fail, html, json, log, see_other, with_type, App, Auth, RUN_FILE_CSP};
use super::login::csrf_ok;
use super::runs::{self, Resolved};
use super::store::{self, Command};
use super::svg::{self, Series};
use super::users::Role;
use super::{clock, pages};
use axum::extract::rejection::{FormRejection, QueryRejection};
use axum::extract::{ConnectInfo, Path as UrlPath, Query, State};
use axum::http::{header, HeaderMap, HeaderValue, StatusCode};
use axum::response::sse::{Event, KeepAlive, Sse};
use axum::response::{IntoResponse, Response};
use axum::{Extension, Form};
use serde::Deserialize;
use std::convert::Infallible;
use std::fmt::Write as _;
use std::net::SocketAddr;
use std::sync::atomic::Ordering;
use std::sync::Arc;
use std::time::Duration;

/// `GET /live`: the live page (its values arrive by the stream of `/api/live`).
pub async fn live_page(Extension(auth): Extension<Auth>) -> Response {
    html(StatusCode::OK, pages::live(&auth.viewer()))
}

/// `GET /api/state`: the latest snapshot as JSON (`{"state", "problem", "stale", "read_utc"}`).
pub async fn live_state(State(app): State<Arc<App>>) -> Response {
    let p = app.feed.rx.borrow().clone();
    json(StatusCode::OK, p.json.clone())
}

/// Releases a live client's place when its stream ends.
struct ClientSlot(Arc<App>);

impl Drop for ClientSlot {
    fn drop(&mut self) {
        self.0.live_clients.fetch_sub(1, Ordering::Relaxed);
    }
}

/// How often an idle stream checks that its session still lives.
const SESSION_CHECK: Duration = Duration::from_secs(5);

/// `GET /api/live`, Server-Sent Events: the current snapshot at once, then every new one
/// (event `state`, id the publication count; at most 10 a second, as the feed reads the file),
/// with a keep-alive every 15 s. Before each event and every 5 s the session is checked with
/// [`crate::session::Sessions::alive`]: the stream ends at logout, the user's removal or the
/// absolute lifetime, not at the idle timeout. Beyond `max_live_clients` streams: 503.
pub async fn live_stream(
    State(app): State<Arc<App>>,
    Extension(auth): Extension<Auth>,
) -> Response {
    if app.live_clients.fetch_add(1, Ordering::Relaxed) >= app.max_live_clients {
        app.live_clients.fetch_sub(1, Ordering::Relaxed);
        return fail(
            StatusCode::SERVICE_UNAVAILABLE,
            true,
            "too many live clients",
        );
    }
    let slot = ClientSlot(app.clone());
    let rx = app.feed.rx.clone();
    let state = (rx, slot, true, auth.session_id);
    let stream = futures_util::stream::unfold(state, |(mut rx, slot, first, id)| async move {
        if !first {
            loop {
                match tokio::time::timeout(SESSION_CHECK, rx.changed()).await {
                    Ok(Ok(())) => break,
                    Ok(Err(_)) => return None,
                    Err(_) if !slot.0.sessions.alive(&id) => return None,
                    Err(_) => {}
                }
            }
        }
        if !slot.0.sessions.alive(&id) {
            return None;
        }
        let p = rx.borrow_and_update().clone();
        let event = Event::default()
            .event("state")
            .id(p.seq.to_string())
            .data(p.json.clone());
        Some((Ok::<_, Infallible>(event), (rx, slot, false, id)))
    });
    Sse::new(stream)
        .keep_alive(KeepAlive::new().interval(Duration::from_secs(15)))
        .into_response()
}

/// The fields of `POST /live/command`: `csrf`, `command` (`pause`, `resume`, `ack`) and, for
/// `ack`, `alarm_id`; all optional here so that a missing one gets its own refusal.
#[derive(Deserialize)]
pub struct CommandForm {
    csrf: Option<String>,
    command: Option<String>,
    alarm_id: Option<String>,
}

/// `POST /live/command`, an operator's pause, resume or alarm acknowledgement. Checked in order:
/// the session's CSRF token (else 403, audited), the operator role as the users file says now
/// (else 403, audited), the command (else 400), for `ack` a whole `alarm_id` ≥ 0 (else 400; it
/// is not checked against the live alarms: the live loop records `unknown alarm N`). Then one
/// row in `live_commands` and one in `audit_log`, in one transaction, and 303 to `/live`.
pub async fn command(
    State(app): State<Arc<App>>,
    Extension(auth): Extension<Auth>,
    ConnectInfo(peer): ConnectInfo<SocketAddr>,
    headers: HeaderMap,
    form: Result<Form<CommandForm>, FormRejection>,
) -> Response {
    let addr = app.client_addr(peer, &headers);
    let form = form.ok().map(|Form(f)| f);
    let token = form.as_ref().and_then(|f| f.csrf.as_deref());
    if !csrf_ok(&app, &auth, token, addr, "live command").await {
        return fail(
            StatusCode::FORBIDDEN,
            false,
            "missing or wrong CSRF token: reload the page",
        );
    }
    if auth.role != Role::Operator {
        log(&format!(
            "live command refused for {:?} from {addr}: role viewer",
            auth.user
        ));
        app.audit(
            Some(&auth.user),
            addr,
            "refused",
            Some("live command: not an operator".into()),
        )
        .await;
        return fail(
            StatusCode::FORBIDDEN,
            false,
            "only operators may pause, resume or acknowledge",
        );
    }
    let form = form.unwrap_or(CommandForm {
        csrf: None,
        command: None,
        alarm_id: None,
    });
    let Some(cmd) = form.command.as_deref().and_then(Command::parse) else {
        return fail(
            StatusCode::BAD_REQUEST,
            false,
            "command must be pause, resume or ack",
        );
    };
    let alarm_id = match (cmd, form.alarm_id.as_deref().map(str::trim)) {
        (Command::Ack, Some(a)) => match a.parse::<i64>() {
            Ok(id) if id >= 0 => Some(id),
            _ => {
                return fail(
                    StatusCode::BAD_REQUEST,
                    false,
                    "alarm_id must be a whole number",
                )
            }
        },
        (Command::Ack, None) => {
            return fail(StatusCode::BAD_REQUEST, false, "ack needs the alarm_id")
        }
        (_, _) => None,
    };
    let db = app.db.clone();
    let user = auth.user.clone();
    let issued =
        tokio::task::spawn_blocking(move || db.issue(&user, &addr.to_string(), cmd, alarm_id))
            .await;
    match issued {
        Ok(Ok(id)) => {
            log(&format!(
                "{} by {:?} from {addr} (live_commands id {id})",
                cmd.as_str(),
                auth.user
            ));
            see_other("/live")
        }
        Ok(Err(e)) => {
            log(&format!("live command not stored: {e}"));
            fail(
                StatusCode::SERVICE_UNAVAILABLE,
                false,
                "the store did not take the command; try again",
            )
        }
        Err(_) => fail(StatusCode::INTERNAL_SERVER_ERROR, false, "internal error"),
    }
}

/// Longest time range of the history page.
pub const MAX_RANGE_MS: i64 = 31 * 24 * 3600 * 1000;
/// Most points of one chart line.
pub const MAX_POINTS: usize = 2000;

/// The query of `/history`: `from` and `to`, UTC times (`YYYY-MM-DDThh:mm[:ss[.fff]][Z]`,
/// at most 40 characters each); absent or empty: the hour up to the newest cycle.
#[derive(Deserialize)]
pub struct RangeQuery {
    from: Option<String>,
    to: Option<String>,
}

fn bad_range(text: &str) -> Response {
    fail(StatusCode::BAD_REQUEST, false, text)
}

/// The history page: temperatures and compensation of the live cycles in a time range, the
/// stored campaigns and model versions.
pub async fn history(
    State(app): State<Arc<App>>,
    Extension(auth): Extension<Auth>,
    query: Result<Query<RangeQuery>, QueryRejection>,
) -> Response {
    let Ok(Query(q)) = query else {
        return bad_range("from and to are times, e.g. 2026-11-27T09:00");
    };
    let parse = |v: &Option<String>| -> Result<Option<i64>, &'static str> {
        match v.as_deref().map(str::trim).filter(|s| !s.is_empty()) {
            None => Ok(None),
            Some(s) if s.len() > 40 => Err("a time is at most 40 characters"),
            Some(s) => clock::parse_utc_ms(s).map(Some).ok_or(
                "from and to are UTC times like 2026-11-27T09:00 or 2026-11-27T09:00:00.000Z",
            ),
        }
    };
    let (from, to) = match (parse(&q.from), parse(&q.to)) {
        (Ok(f), Ok(t)) => (f, t),
        (Err(r), _) | (_, Err(r)) => return bad_range(r),
    };
    let db = app.db.clone();
    let result = tokio::task::spawn_blocking(move || {
        let conn = db.reader();
        let latest = store::latest_cycle_utc(&conn)?
            .and_then(|t| clock::parse_utc_ms(&t))
            .unwrap_or_else(clock::now_ms);
        let to = to.unwrap_or(latest);
        let from = from.unwrap_or(to - 3600 * 1000);
        if from >= to || to - from > MAX_RANGE_MS {
            return Ok(Err((from, to)));
        }
        let (cycles, total) =
            store::cycles(&conn, &clock::utc_ms(from), &clock::utc_ms(to), MAX_POINTS)?;
        let campaigns = store::campaigns(&conn)?;
        let models = store::models(&conn)?;
        Ok::<_, rusqlite::Error>(Ok((from, to, cycles, total, campaigns, models)))
    })
    .await;
    let (from, to, cycles, total, campaigns, models) = match result {
        Ok(Ok(Ok(v))) => v,
        Ok(Ok(Err(_))) => {
            return bad_range("from must be before to, and the range at most 31 days")
        }
        Ok(Err(e)) => {
            log(&format!("history query failed: {e}"));
            return fail(
                StatusCode::SERVICE_UNAVAILABLE,
                false,
                "the store could not be read; try again",
            );
        }
        Err(_) => return fail(StatusCode::INTERNAL_SERVER_ERROR, false, "internal error"),
    };
    let mut b = String::new();
    let minute = |ms: i64| clock::utc_ms(ms)[..16].to_string();
    let _ = write!(
        b,
        "<form method=\"get\" action=\"/history\" id=\"range\">From <input type=\"datetime-local\" name=\"from\" value=\"{}\"> to <input type=\"datetime-local\" name=\"to\" value=\"{}\"> (UTC) <button type=\"submit\">Show</button></form>",
        minute(from),
        minute(to)
    );
    let _ = write!(
        b,
        "<p id=\"cycles\" data-total=\"{total}\" data-shown=\"{}\">{total} live cycles from {} to {}{}.</p>",
        cycles.len(),
        clock::utc_ms(from),
        clock::utc_ms(to),
        if cycles.len() as u64 != total {
            format!(", {} drawn (every {}th)", cycles.len(), total.div_ceil(cycles.len().max(1) as u64))
        } else {
            String::new()
        }
    );
    let hours = to - from > 3 * 3600 * 1000;
    let unit_ms = if hours { 3_600_000.0 } else { 60_000.0 };
    let x_label = format!(
        "time since {} UTC ({})",
        minute(from).replace('T', " "),
        if hours { "h" } else { "min" }
    );
    let x_of = |at: i64| (at - from) as f64 / unit_ms;
    let mut temps: Vec<Series> = Vec::new();
    let mut comp: Vec<Series> = Vec::new();
    let push = |list: &mut Vec<Series>, name: String, point: (f64, f64)| match list
        .iter()
        .position(|s| s.name == name)
    {
        Some(i) => list[i].points.push(point),
        None if list.len() < 16 => list.push(Series {
            name,
            points: vec![point],
        }),
        None => {}
    };
    for c in &cycles {
        let x = x_of(c.at_ms);
        for (k, v) in &c.inputs {
            if let Some(t) = v.as_f64() {
                push(&mut temps, k.clone(), (x, t));
            }
        }
        for (axis, v) in &c.outputs {
            for (field, label) in [("written_um", "written"), ("computed_um", "computed")] {
                if let Some(u) = v.get(field).and_then(|f| f.as_f64()) {
                    push(&mut comp, format!("{axis} {label}"), (x, u));
                }
            }
        }
    }
    b.push_str("<h2>Temperatures</h2>");
    b.push_str(&svg::line_chart(
        "Temperatures of the live cycles",
        &x_label,
        "temperature (°C)",
        &temps,
    ));
    b.push_str("<h2>Compensation</h2>");
    b.push_str(&svg::line_chart(
        "Compensation per axis",
        &x_label,
        "compensation (µm)",
        &comp,
    ));
    b.push_str("<h2>Campaigns</h2>");
    if campaigns.is_empty() {
        b.push_str("<p>No campaign in the store.</p>");
    } else {
        b.push_str("<table id=\"campaigns\"><thead><tr><th>campaign</th><th>axis</th><th>coolant</th><th>sensors</th><th>samples</th></tr></thead><tbody>");
        for c in &campaigns {
            let _ = write!(
                b,
                "<tr><td><a href=\"/history/campaign?name={}\">{}</a></td><td>{}</td><td>{}</td><td class=\"num\">{}</td><td class=\"num\">{}</td></tr>",
                pages::url_encode(&c.name),
                svg::escape(&c.name),
                svg::escape(&c.axis),
                svg::escape(&c.coolant),
                c.sensors,
                c.samples
            );
        }
        b.push_str("</tbody></table>");
    }
    b.push_str("<h2>Fitted models</h2>");
    if models.is_empty() {
        b.push_str("<p>No model in the store.</p>");
    } else {
        let rows: Vec<Vec<String>> = models
            .iter()
            .map(|m| {
                vec![
                    m.name.clone(),
                    m.version.to_string(),
                    errmap_core::io::stamp::utc_rfc3339(m.created_unix),
                    m.campaigns.clone(),
                    m.loco_rms_um.map_or("—".into(), |v| format!("{v:.3}")),
                ]
            })
            .collect();
        b.push_str(&pages::table(
            "models",
            &[
                "model",
                "version",
                "fitted (UTC)",
                "campaigns",
                "LOCO RMS (µm)",
            ],
            &rows,
        ));
    }
    html(
        StatusCode::OK,
        pages::page("History", "/history", &auth.viewer(), "history", &b),
    )
}

/// The query of `/history/campaign`: `name`, a stored campaign's name (1 to 256 bytes).
#[derive(Deserialize)]
pub struct CampaignQuery {
    name: Option<String>,
}

/// `GET /history/campaign?name=…`: one campaign's temperatures from the store as a chart
/// (at most 2000 points per sensor); 400 for a missing or over-long name, 404 for an unknown one.
pub async fn campaign(
    State(app): State<Arc<App>>,
    Extension(auth): Extension<Auth>,
    query: Result<Query<CampaignQuery>, QueryRejection>,
) -> Response {
    let name = match query {
        Ok(Query(CampaignQuery { name: Some(n) })) if !n.is_empty() && n.len() <= 256 => n,
        _ => {
            return fail(
                StatusCode::BAD_REQUEST,
                false,
                "name: a campaign name of at most 256 bytes",
            )
        }
    };
    let db = app.db.clone();
    let key = name.clone();
    let result = tokio::task::spawn_blocking(move || {
        store::campaign_temperatures(&db.reader(), &key, MAX_POINTS)
    })
    .await;
    let sensors = match result {
        Ok(Ok(Some(s))) => s,
        Ok(Ok(None)) => return fail(StatusCode::NOT_FOUND, false, "no campaign of that name"),
        Ok(Err(e)) => {
            log(&format!("campaign query failed: {e}"));
            return fail(
                StatusCode::SERVICE_UNAVAILABLE,
                false,
                "the store could not be read; try again",
            );
        }
        Err(_) => return fail(StatusCode::INTERNAL_SERVER_ERROR, false, "internal error"),
    };
    let series: Vec<Series> = sensors
        .into_iter()
        .map(|(name, pts)| Series {
            name,
            points: pts.into_iter().map(|(t, c)| (t / 60.0, c)).collect(),
        })
        .collect();
    let mut b = String::from("<p><a href=\"/history\">History</a></p>");
    b.push_str(&svg::line_chart(
        &format!("Temperatures of {name} (calibrated, as stored)"),
        "time since the campaign's start (min)",
        "temperature (°C)",
        &series,
    ));
    html(
        StatusCode::OK,
        pages::page(
            &format!("Campaign {name}"),
            "/history",
            &auth.viewer(),
            "campaign",
            &b,
        ),
    )
}

/// `GET /runs/`: the listing of the runs folder (404 without `--runs`).
pub async fn runs_root(State(app): State<Arc<App>>, Extension(auth): Extension<Auth>) -> Response {
    serve_run_path(&app, &auth, String::new()).await
}

/// `GET /runs/{path}`: a folder listing or a file of the runs folder, the path confined to it
/// by [`crate::runs::resolve`] (anything refused or outside: 404). Files carry [`RUN_FILE_CSP`]
/// and their content type; types not shown inline are sent as downloads.
pub async fn run_file(
    State(app): State<Arc<App>>,
    Extension(auth): Extension<Auth>,
    path: Result<UrlPath<String>, axum::extract::rejection::PathRejection>,
) -> Response {
    let Ok(UrlPath(path)) = path else {
        return fail(StatusCode::BAD_REQUEST, false, "not a path");
    };
    serve_run_path(&app, &auth, path).await
}

async fn serve_run_path(app: &App, auth: &Auth, path: String) -> Response {
    let Some(root) = app.runs.clone() else {
        return fail(
            StatusCode::NOT_FOUND,
            false,
            &format!(
                "errmap serve was started without {}",
                errmap_core::setting::words(crate::Setting::Runs)
            ),
        );
    };
    let request = path.clone();
    let resolved = {
        let root = root.clone();
        tokio::task::spawn_blocking(move || runs::resolve(&root, &request)).await
    };
    match resolved {
        Ok(Some(Resolved::Dir(dir))) => {
            // Folder links are relative: a folder's address ends in '/'.
            if !path.is_empty() && !path.ends_with('/') {
                let last = path.rsplit('/').next().unwrap_or("");
                return see_other(&format!("{}/", pages::url_encode(last)));
            }
            let entries = {
                let root = root.clone();
                tokio::task::spawn_blocking(move || runs::list(&root, &dir))
                    .await
                    .unwrap_or_default()
            };
            html(
                StatusCode::OK,
                pages::runs_listing(&auth.viewer(), path.trim_end_matches('/'), &entries),
            )
        }
        Ok(Some(Resolved::File(file))) => send_file(&file).await,
        _ => fail(
            StatusCode::NOT_FOUND,
            false,
            "no such file under the runs folder",
        ),
    }
}

async fn send_file(file: &std::path::Path) -> Response {
    let (content_type, inline) = runs::content_type(file);
    let opened = match tokio::fs::File::open(file).await {
        Ok(f) => f,
        Err(_) => {
            return fail(
                StatusCode::NOT_FOUND,
                false,
                "no such file under the runs folder",
            )
        }
    };
    let len = opened.metadata().await.map(|m| m.len()).ok();
    let body = axum::body::Body::from_stream(tokio_util::io::ReaderStream::new(opened));
    let mut r = with_type(StatusCode::OK, content_type, body);
    let h = r.headers_mut();
    if let Some(len) = len {
        h.insert(header::CONTENT_LENGTH, HeaderValue::from(len));
    }
    // A run's files get the report's policy: inline style and data: images, no script.
    h.insert(
        header::CONTENT_SECURITY_POLICY,
        HeaderValue::from_static(RUN_FILE_CSP),
    );
    if !inline {
        h.insert(
            header::CONTENT_DISPOSITION,
            HeaderValue::from_static("attachment"),
        );
    }
    r
}
