//! Shared helpers of the `errmap serve` tests: a store from the sample thermal data, users, the real server on a free loopback port, an HTTP client that keeps cookies by hand, and the one writer of the live state file.
// Each test binary uses only part of it.
#![allow(dead_code)]

use std::io::{BufRead, BufReader, Read};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::mpsc;
use std::time::Duration;

pub const PASSWORD: &str = "correct horse battery";

/// The repository root.
pub fn root() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

pub fn errmap() -> Command {
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_errmap"));
    cmd.env(
        "ERRMAP_CACHE_DIR",
        std::env::temp_dir().join(format!("errmap-test-cache-{}", std::process::id())),
    );
    cmd
}

/// A store holding the first sample campaign, in `dir`.
pub fn make_store(dir: &Path) -> PathBuf {
    let db = dir.join("store.sqlite");
    let out = errmap()
        .args(["thermal", "ingest", "-q", "--db"])
        .arg(&db)
        .arg(root().join("data/thermal/campaign-1-coolant-off"))
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    db
}

/// `errmap serve user add` with the password on stdin; the run's output.
pub fn user_add(users: &Path, name: &str, role: &str, password: &str) -> std::process::Output {
    let mut child = errmap()
        .args([
            "serve",
            "user",
            "add",
            name,
            "--role",
            role,
            "--password-stdin",
            "--users",
        ])
        .arg(users)
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    use std::io::Write;
    child
        .stdin
        .take()
        .unwrap()
        .write_all(format!("{password}\n").as_bytes())
        .unwrap();
    child.wait_with_output().unwrap()
}

/// A folder with a store and a users file of two users: `op` (operator) and `view` (viewer).
pub struct Site {
    pub dir: tempfile::TempDir,
    pub db: PathBuf,
    pub users: PathBuf,
}

impl Site {
    pub fn new() -> Site {
        let dir = tempfile::tempdir().unwrap();
        let db = make_store(dir.path());
        let users = dir.path().join("users.toml");
        for (name, role) in [("op", "operator"), ("view", "viewer")] {
            let out = user_add(&users, name, role, PASSWORD);
            assert!(
                out.status.success(),
                "{}",
                String::from_utf8_lossy(&out.stderr)
            );
        }
        Site { dir, db, users }
    }

    pub fn path(&self) -> &Path {
        self.dir.path()
    }
}

/// A running `errmap serve`, killed when dropped; stderr (its log) collected.
pub struct Server {
    child: Child,
    pub url: String,
    log: mpsc::Receiver<String>,
    pub log_lines: Vec<String>,
}

impl Server {
    /// Start `errmap serve --db … --users … --bind 127.0.0.1:0 extra…` and wait for its address.
    pub fn start(site: &Site, extra: &[&str]) -> Server {
        let mut cmd = errmap();
        cmd.arg("serve")
            .arg("--db")
            .arg(&site.db)
            .arg("--users")
            .arg(&site.users);
        if !extra.contains(&"--bind") {
            cmd.args(["--bind", "127.0.0.1:0"]);
        }
        cmd.args(extra);
        Server::spawn(cmd)
    }

    pub fn spawn(mut cmd: Command) -> Server {
        let mut child = cmd
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .expect("start errmap serve");
        let stdout = child.stdout.take().unwrap();
        let stderr = child.stderr.take().unwrap();
        let (tx, rx) = mpsc::channel();
        std::thread::spawn(move || {
            let mut line = String::new();
            let _ = BufReader::new(stdout).read_line(&mut line);
            let _ = tx.send(line);
        });
        let (ltx, lrx) = mpsc::channel();
        std::thread::spawn(move || {
            for line in BufReader::new(stderr).lines().map_while(Result::ok) {
                if ltx.send(line).is_err() {
                    return;
                }
            }
        });
        let line = rx.recv_timeout(Duration::from_secs(60)).unwrap_or_default();
        let url = match line.trim().strip_prefix("errmap serve: listening on ") {
            Some(u) => u.to_string(),
            None => {
                let _ = child.kill();
                let _ = child.wait();
                let log: Vec<String> = lrx.try_iter().collect();
                panic!("errmap serve did not start: {line:?}\n{}", log.join("\n"));
            }
        };
        Server {
            child,
            url,
            log: lrx,
            log_lines: Vec::new(),
        }
    }

    /// The server's log so far.
    pub fn log(&mut self) -> String {
        std::thread::sleep(Duration::from_millis(100));
        self.log_lines.extend(self.log.try_iter());
        self.log_lines.join("\n")
    }

    pub fn pid(&self) -> u32 {
        self.child.id()
    }
}

impl Drop for Server {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// Run a server command that must fail to start: (exit code, stderr).
pub fn refused(site: &Site, extra: &[&str]) -> (i32, String) {
    let out = errmap()
        .arg("serve")
        .arg("--db")
        .arg(&site.db)
        .arg("--users")
        .arg(&site.users)
        .args(extra)
        .stdin(Stdio::null())
        .output()
        .unwrap();
    (
        out.status.code().unwrap_or(-1),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

/// An HTTP client that follows no redirect and keeps cookies by hand.
pub fn client() -> reqwest::blocking::Client {
    reqwest::blocking::Client::builder()
        .redirect(reqwest::redirect::Policy::none())
        .timeout(Duration::from_secs(30))
        .build()
        .unwrap()
}

/// The `Set-Cookie` headers of a response.
pub fn set_cookies(r: &reqwest::blocking::Response) -> Vec<String> {
    r.headers()
        .get_all("set-cookie")
        .iter()
        .map(|v| v.to_str().unwrap().to_string())
        .collect()
}

/// The value a `Set-Cookie` list gives a cookie name.
pub fn cookie_value(cookies: &[String], name: &str) -> Option<String> {
    cookies.iter().find_map(|c| {
        let first = c.split(';').next()?;
        let (k, v) = first.split_once('=')?;
        (k == name && !v.is_empty()).then(|| v.to_string())
    })
}

/// The value of the first hidden `csrf` field of a page.
pub fn csrf_field(html: &str) -> Option<String> {
    let at = html.find("name=\"csrf\" value=\"")? + "name=\"csrf\" value=\"".len();
    Some(html[at..at + html[at..].find('"')?].to_string())
}

/// A logged-in browser: its session cookie (as `name=value`) and its CSRF token.
#[derive(Debug, Clone)]
pub struct Login {
    pub cookie: String,
    pub csrf: String,
}

/// The login form: (pre-session cookie `name=value`, form token).
pub fn login_form(c: &reqwest::blocking::Client, url: &str) -> (String, String) {
    let r = c.get(format!("{url}/login")).send().unwrap();
    assert_eq!(r.status(), 200);
    let cookies = set_cookies(&r);
    let name = if url.starts_with("https") {
        "__Host-errmap_login"
    } else {
        "errmap_login"
    };
    let pre = cookie_value(&cookies, name).expect("pre-session cookie");
    let token = csrf_field(&r.text().unwrap()).expect("csrf field");
    (format!("{name}={pre}"), token)
}

/// POST the login form (fresh form) with a user and password; the response.
pub fn post_login(
    c: &reqwest::blocking::Client,
    url: &str,
    user: &str,
    password: &str,
) -> reqwest::blocking::Response {
    let (pre, token) = login_form(c, url);
    c.post(format!("{url}/login"))
        .header("cookie", pre)
        .form(&[("user", user), ("password", password), ("csrf", &token)])
        .send()
        .unwrap()
}

/// Log in and read the session's CSRF token from the live page.
pub fn login(c: &reqwest::blocking::Client, url: &str, user: &str) -> Login {
    let r = post_login(c, url, user, PASSWORD);
    assert_eq!(r.status(), 303, "login of {user}");
    let name = if url.starts_with("https") {
        "__Host-errmap_session"
    } else {
        "errmap_session"
    };
    let id = cookie_value(&set_cookies(&r), name).expect("session cookie");
    let cookie = format!("{name}={id}");
    let page = c
        .get(format!("{url}/live"))
        .header("cookie", &cookie)
        .send()
        .unwrap();
    assert_eq!(page.status(), 200);
    let csrf = csrf_field(&page.text().unwrap()).expect("csrf on the live page");
    Login { cookie, csrf }
}

/// Read an SSE stream until `want` returns true for an event's data, or panic after `wait`.
pub fn read_events(
    r: reqwest::blocking::Response,
    wait: Duration,
    mut want: impl FnMut(&serde_json::Value) -> bool,
) -> Vec<serde_json::Value> {
    let (tx, rx) = mpsc::channel();
    std::thread::spawn(move || {
        let mut reader = BufReader::new(r);
        let mut data = String::new();
        let mut line = String::new();
        loop {
            line.clear();
            match reader.read_line(&mut line) {
                Ok(0) | Err(_) => return,
                Ok(_) => {}
            }
            let l = line.trim_end_matches(['\r', '\n']);
            if let Some(d) = l.strip_prefix("data:") {
                data.push_str(d.trim_start());
            } else if l.is_empty() && !data.is_empty() {
                if let Ok(v) = serde_json::from_str(&data) {
                    if tx.send(v).is_err() {
                        return;
                    }
                }
                data.clear();
            }
        }
    });
    let deadline = std::time::Instant::now() + wait;
    let mut seen = Vec::new();
    loop {
        let left = deadline.saturating_duration_since(std::time::Instant::now());
        match rx.recv_timeout(left) {
            Ok(v) => {
                let done = want(&v);
                seen.push(v);
                if done {
                    return seen;
                }
            }
            Err(_) => panic!("no wanted event in {wait:?}; got {seen:?}"),
        }
    }
}

/// The state file as `errmap live --state` writes it (the contract's schema, rewritten
/// atomically: a temporary file in the same folder, renamed). The one writer of the tests:
/// swap it for a real `errmap live --dry-run` (data/thermal-live/live.toml) once that exists.
pub fn write_state(path: &Path, cycle: u64, nut_c: f64, written_um: f64, alarms: &[(i64, &str)]) {
    let now = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .unwrap();
    let written_utc = utc_ms(now.as_millis() as i64);
    let alarms: Vec<serde_json::Value> = alarms
        .iter()
        .map(|(id, msg)| {
            serde_json::json!({"id": id, "raised_utc": written_utc, "source": "modbus-rack",
                               "message": msg, "acknowledged": false})
        })
        .collect();
    let state = serde_json::json!({
        "schema": "errmap-live-state/1",
        "written_utc": written_utc,
        "cycle": cycle,
        "period_ms": 100,
        "mode": "running",
        "dry_run": true,
        "coolant_on": false,
        "sensors": [
            {"name": "nut", "value_c": nut_c, "ok": true, "source": "modbus-rack", "age_ms": 80, "problem": null},
            {"name": "room", "value_c": null, "ok": false, "source": "modbus-rack", "age_ms": 5000,
             "problem": "<b>open RTD</b>"}
        ],
        "axes": [
            {"axis": "X", "position_mm": 123.456, "direction": "forward", "computed_um": written_um + 0.2,
             "written_um": written_um, "limit_um": 50.0, "rate_limit_um_s": 5.0, "target": "sinumerik-opcua", "held": false}
        ],
        "sources": [
            {"name": "modbus-rack", "kind": "modbus", "healthy": true, "last_ok_utc": written_utc, "problem": null}
        ],
        "alarms": alarms
    });
    let dir = path.parent().unwrap();
    let tmp = dir.join(format!(".state-{cycle}.tmp"));
    std::fs::write(&tmp, serde_json::to_vec_pretty(&state).unwrap()).unwrap();
    std::fs::rename(&tmp, path).unwrap();
}

/// ms since the epoch as `YYYY-MM-DDThh:mm:ss.mmmZ` (civil_from_days, written out here so the
/// tests do not use the server's own formatter).
pub fn utc_ms(ms: i64) -> String {
    let secs = ms.div_euclid(1000);
    let days = secs.div_euclid(86_400);
    let rem = secs.rem_euclid(86_400);
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z - era * 146_097;
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = doy - (153 * mp + 2) / 5 + 1;
    let m = if mp < 10 { mp + 3 } else { mp - 9 };
    let y = yoe + era * 400 + i64::from(m <= 2);
    format!(
        "{y:04}-{m:02}-{d:02}T{:02}:{:02}:{:02}.{:03}Z",
        rem / 3600,
        rem % 3600 / 60,
        rem % 60,
        ms.rem_euclid(1000)
    )
}

/// Read a whole body, bounded.
pub fn body(r: reqwest::blocking::Response) -> String {
    let mut s = String::new();
    let _ = r.take(8 << 20).read_to_string(&mut s);
    s
}
