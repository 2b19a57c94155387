//! `errmap serve` in a real browser (headless Chromium over DevTools): log in through the form, watch the live page follow the state file as it is rewritten, pause the loop as an operator, open a run's report; no console error, no CSP violation, no request outside the server. Skipped without Chromium unless ERRMAP_REQUIRE_BROWSER=1.

mod serve_support;

use serde_json::Value;
use serve_support::devtools::{browser_or_skip, DevTools};
use serve_support::*;
use std::time::Duration;

/// A run folder with a result and its report.html (linear analysis of the sample runs).
fn make_run(runs: &std::path::Path) {
    let dir = runs.join("axis-x");
    std::fs::create_dir_all(&dir).unwrap();
    let out = errmap()
        .args(["linear", "analyze", "-q", "--standard", "iso230-2:2014"])
        .arg(root().join("data/linear/runs.csv"))
        .arg("--chart")
        .arg(dir.join("x.png"))
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let out = errmap().args(["report", "-q"]).arg(&dir).output().unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(dir.join("report.html").is_file());
}

#[test]
fn log_in_watch_the_live_page_follow_the_state_file_and_open_a_report() {
    let Some(chrome) = browser_or_skip("serve_browser") else {
        return;
    };
    let site = Site::new();
    let runs = site.path().join("runs");
    make_run(&runs);
    let state = site.path().join("state.json");
    write_state(&state, 1, 21.25, 3.5, &[(7, "T3 <b>open</b> RTD")]);
    let server = Server::start(
        &site,
        &[
            "--live",
            state.to_str().unwrap(),
            "--runs",
            runs.to_str().unwrap(),
        ],
    );
    let url = server.url.clone();
    let mut dt = DevTools::start(&chrome);
    let s = dt.page();
    dt.call(
        Some(&s),
        "Page.navigate",
        serde_json::json!({"url": format!("{url}/live")}),
    );
    // Without a session: the login form.
    dt.wait_until(
        &s,
        "location.pathname === '/login' && document.readyState === 'complete'",
        Duration::from_secs(30),
        "the login page",
    );
    dt.eval(
        &s,
        &format!(
            "document.querySelector('input[name=user]').value = 'op';
             document.querySelector('input[name=password]').value = '{PASSWORD}';
             document.querySelector('form.login').submit(); true"
        ),
    );
    dt.wait_until(
        &s,
        "location.pathname === '/live'",
        Duration::from_secs(30),
        "the live page after login",
    );
    // The script fills the page from the stream.
    dt.wait_until(
        &s,
        "document.getElementById('cycle').textContent === '1'",
        Duration::from_secs(30),
        "cycle 1",
    );
    let row: Value = dt
        .eval(&s, "Array.from(document.querySelectorAll('#sensors tbody tr')[0].cells).map(c => c.textContent)")
        .unwrap();
    assert_eq!(row[0], "nut");
    assert_eq!(row[1], "21.25");
    // Markup in a message stays text.
    let alarm = dt
        .eval(&s, "[document.querySelector('#alarms tbody td:nth-child(4)').textContent, document.querySelectorAll('#alarms b').length]")
        .unwrap();
    assert_eq!(alarm[0], "T3 <b>open</b> RTD");
    assert_eq!(alarm[1], 0);
    // Rewrites of the state file show up.
    for cycle in 2..=4u64 {
        write_state(
            &state,
            cycle,
            21.0 + cycle as f64 / 4.0,
            3.5 + cycle as f64,
            &[],
        );
        dt.wait_until(
            &s,
            &format!("document.getElementById('cycle').textContent === '{cycle}'"),
            Duration::from_secs(30),
            &format!("cycle {cycle}"),
        );
    }
    let axis = dt
        .eval(&s, "Array.from(document.querySelectorAll('#axes tbody tr')[0].cells).map(c => c.textContent)")
        .unwrap();
    assert_eq!(axis[0], "X");
    assert_eq!(axis[4], "7.50", "written µm of cycle 4");
    // An operator pauses: the form posts with its token, the command lands in the store.
    dt.eval(
        &s,
        "window.errmapOldPage = true; document.querySelector('#controls button[value=pause]').click(); true",
    );
    // A new document (the old one was marked), back on /live after the 303.
    dt.wait_until(&s, "window.errmapOldPage === undefined && location.pathname === '/live' && document.readyState === 'complete' && document.getElementById('cycle').textContent === '4'", Duration::from_secs(30), "back on the live page");
    let conn = rusqlite::Connection::open(&site.db).unwrap();
    let cmd: (String, String) = conn
        .query_row("SELECT user, command FROM live_commands", [], |r| {
            Ok((r.get(0)?, r.get(1)?))
        })
        .unwrap();
    assert_eq!(cmd, ("op".to_string(), "pause".to_string()));
    // The history page draws its charts.
    dt.call(
        Some(&s),
        "Page.navigate",
        serde_json::json!({"url": format!("{url}/history")}),
    );
    dt.wait_until(&s, "location.pathname === '/history' && document.readyState === 'complete' && document.querySelectorAll('svg.chart').length === 2", Duration::from_secs(30), "the history page");
    // A run's report, every image decoded.
    let report = format!("{url}/runs/axis-x/report.html");
    dt.call(
        Some(&s),
        "Page.navigate",
        serde_json::json!({"url": report}),
    );
    dt.wait_until(
        &s,
        "location.pathname === '/runs/axis-x/report.html' && document.readyState === 'complete' && document.images.length > 0 && Array.from(document.images).every(i => i.complete && i.naturalWidth > 0)",
        Duration::from_secs(30),
        "the report with its images",
    );
    let sections = dt
        .eval(&s, "document.querySelectorAll('section').length")
        .unwrap();
    assert!(sections.as_u64().unwrap() >= 1);
    dt.drain(Duration::from_millis(500));
    // No console error, exception, CSP violation or failed load (the live stream cancelled by
    // leaving its page is not a failure).
    for e in &dt.events {
        let m = e["method"].as_str().unwrap_or("");
        let p = &e["params"];
        let bad = match m {
            "Runtime.consoleAPICalled" => matches!(p["type"].as_str(), Some("error" | "assert")),
            "Runtime.exceptionThrown" => true,
            "Log.entryAdded" => p["entry"]["level"] == "error",
            "Network.loadingFailed" => p["canceled"] != true,
            _ => false,
        };
        assert!(!bad, "browser reported: {e}");
    }
    let requests: Vec<&str> = dt
        .events
        .iter()
        .filter(|e| e["method"] == "Network.requestWillBeSent")
        .filter_map(|e| e["params"]["request"]["url"].as_str())
        .collect();
    assert!(
        requests.iter().any(|r| r.ends_with("/api/live")),
        "{requests:?}"
    );
    assert!(requests.contains(&report.as_str()), "{requests:?}");
    for r in &requests {
        assert!(
            r.starts_with(&format!("{url}/")) || r.starts_with("data:") || *r == "about:blank",
            "request outside the server: {r}"
        );
    }
}
