//! Headless Chromium for the browser tests (report_browser, serve_browser), driven over `--remote-debugging-pipe`: calls that may fail (a page navigating away), a wait for an event, and a polled wait for a page condition.
//!
//! Chromium reads DevTools commands on file descriptor 3 and writes replies and events on 4,
//! each a JSON message ended by a NUL byte. `sh` maps the test's pipes onto those descriptors,
//! so no WebSocket client and no unsafe code are needed. Without a browser a test is skipped
//! (and says so), unless `ERRMAP_REQUIRE_BROWSER=1`, as in CI, which makes it fail.
// Each test binary uses only part of it.
#![allow(dead_code)]

use serde_json::{json, Value};
use std::io::{Read, Write};
use std::path::{Path, PathBuf};
use std::process::{Child, ChildStdin, Command, Stdio};
use std::sync::mpsc::Receiver;
use std::time::{Duration, Instant};

/// The browser: `$ERRMAP_CHROMIUM`, else the first Chromium or Chrome on the PATH.
pub fn browser() -> Option<PathBuf> {
    if let Some(p) = std::env::var_os("ERRMAP_CHROMIUM").filter(|p| !p.is_empty()) {
        return Some(PathBuf::from(p)).filter(|p| p.is_file());
    }
    let path = std::env::var_os("PATH")?;
    [
        "chromium",
        "chromium-browser",
        "google-chrome",
        "google-chrome-stable",
    ]
    .iter()
    .find_map(|name| {
        std::env::split_paths(&path)
            .map(|d| d.join(name))
            .find(|c| c.is_file())
    })
}

/// The browser, or `None` after a visible skip note; a panic under ERRMAP_REQUIRE_BROWSER=1.
pub fn browser_or_skip(test: &str) -> Option<PathBuf> {
    let found = browser();
    if found.is_none() {
        if std::env::var("ERRMAP_REQUIRE_BROWSER").as_deref() == Ok("1") {
            panic!("ERRMAP_REQUIRE_BROWSER=1 but no Chromium was found (install the Debian package `chromium` or set ERRMAP_CHROMIUM)");
        }
        eprintln!("SKIPPED {test}: no Chromium (install `chromium` or set ERRMAP_CHROMIUM)");
    }
    found
}

/// A DevTools session over Chromium's pipe; the browser is killed when dropped.
pub struct DevTools {
    child: Child,
    to_browser: ChildStdin,
    from_browser: Receiver<Value>,
    next_id: u64,
    /// Every event received so far, in order.
    pub events: Vec<Value>,
    _profile: tempfile::TempDir,
}

const TIMEOUT: Duration = Duration::from_secs(90);

impl DevTools {
    pub fn start(browser: &Path) -> DevTools {
        let profile = tempfile::tempdir().unwrap();
        let mut child = Command::new("sh")
            .arg("-c")
            .arg(r#"exec "$0" "$@" 3<&0 4>&1 0</dev/null 1>/dev/null"#)
            .arg(browser)
            .args([
                "--headless",
                "--no-sandbox",
                "--disable-gpu",
                "--no-first-run",
                "--remote-debugging-pipe",
            ])
            .arg(format!("--user-data-dir={}", profile.path().display()))
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .stderr(Stdio::null())
            .spawn()
            .expect("start the browser");
        let to_browser = child.stdin.take().unwrap();
        let mut out = child.stdout.take().unwrap();
        let (tx, rx) = std::sync::mpsc::channel();
        std::thread::spawn(move || {
            let mut buf = Vec::new();
            let mut chunk = [0u8; 1 << 16];
            while let Ok(n) = out.read(&mut chunk) {
                if n == 0 {
                    break;
                }
                buf.extend_from_slice(&chunk[..n]);
                while let Some(end) = buf.iter().position(|&b| b == 0) {
                    let msg: Vec<u8> = buf.drain(..=end).collect();
                    if let Ok(v) = serde_json::from_slice(&msg[..end]) {
                        if tx.send(v).is_err() {
                            return;
                        }
                    }
                }
            }
        });
        DevTools {
            child,
            to_browser,
            from_browser: rx,
            next_id: 1,
            events: Vec::new(),
            _profile: profile,
        }
    }

    /// Send a command (to a page session when given); its result or its error.
    pub fn try_call(
        &mut self,
        session: Option<&str>,
        method: &str,
        params: Value,
    ) -> Result<Value, Value> {
        let id = self.next_id;
        self.next_id += 1;
        let mut msg = json!({"id": id, "method": method, "params": params});
        if let Some(s) = session {
            msg["sessionId"] = json!(s);
        }
        let mut bytes = serde_json::to_vec(&msg).unwrap();
        bytes.push(0);
        self.to_browser.write_all(&bytes).unwrap();
        self.to_browser.flush().unwrap();
        let deadline = Instant::now() + TIMEOUT;
        loop {
            let left = deadline.saturating_duration_since(Instant::now());
            let v = self
                .from_browser
                .recv_timeout(left)
                .expect("the browser did not answer in time");
            if v.get("id").and_then(Value::as_u64) == Some(id) {
                return match v.get("error") {
                    Some(e) => Err(e.clone()),
                    None => Ok(v["result"].clone()),
                };
            }
            self.events.push(v);
        }
    }

    /// Send a command and wait for its result; a panic naming the method when it fails.
    pub fn call(&mut self, session: Option<&str>, method: &str, params: Value) -> Value {
        self.try_call(session, method, params)
            .unwrap_or_else(|e| panic!("{method} failed: {e}"))
    }

    /// Wait until an event `method` has arrived (it stays in [`DevTools::events`]).
    pub fn wait_for(&mut self, method: &str) {
        let deadline = Instant::now() + TIMEOUT;
        while !self.events.iter().any(|e| e["method"] == method) {
            let left = deadline.saturating_duration_since(Instant::now());
            let v = self
                .from_browser
                .recv_timeout(left)
                .unwrap_or_else(|_| panic!("the browser sent no {method} in time"));
            self.events.push(v);
        }
    }

    /// A new page: its session id, with the Page, Runtime, Log and Network events on.
    pub fn page(&mut self) -> String {
        let target = self.call(None, "Target.createTarget", json!({"url": "about:blank"}));
        let attached = self.call(
            None,
            "Target.attachToTarget",
            json!({"targetId": target["targetId"], "flatten": true}),
        );
        let session = attached["sessionId"].as_str().unwrap().to_string();
        for domain in [
            "Page.enable",
            "Runtime.enable",
            "Log.enable",
            "Network.enable",
        ] {
            self.call(Some(&session), domain, json!({}));
        }
        session
    }

    /// Evaluate an expression in the page; `None` while the page is between documents.
    pub fn eval(&mut self, session: &str, expr: &str) -> Option<Value> {
        let r = self
            .try_call(
                Some(session),
                "Runtime.evaluate",
                json!({"expression": expr, "returnByValue": true}),
            )
            .ok()?;
        if r.get("exceptionDetails").is_some() {
            return None;
        }
        Some(r["result"]["value"].clone())
    }

    /// Poll an expression until it is `true`; panics with `what` after `wait`.
    pub fn wait_until(&mut self, session: &str, expr: &str, wait: Duration, what: &str) {
        let deadline = Instant::now() + wait;
        loop {
            if self.eval(session, expr) == Some(Value::Bool(true)) {
                return;
            }
            if Instant::now() > deadline {
                let page = self.eval(session, "document.documentElement.outerHTML");
                panic!("{what}: not seen in {wait:?}; page: {page:?}");
            }
            std::thread::sleep(Duration::from_millis(100));
        }
    }

    /// Collect what arrives for a short while.
    pub fn drain(&mut self, wait: Duration) {
        let deadline = Instant::now() + wait;
        while let Ok(v) = self
            .from_browser
            .recv_timeout(deadline.saturating_duration_since(Instant::now()))
        {
            self.events.push(v);
        }
    }
}

impl Drop for DevTools {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}
