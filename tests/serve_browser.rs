//! `errmap serve` in a real browser (headless Chromium over DevTools): log in through the form, watch the live page follow a real `errmap live --dry-run` replaying the sample thermal data, pause and resume that loop as an operator, and (with a state file written by the test, for exact values and hostile text) open a run's report; no console error, no CSP violation, no request outside the server. Skipped without Chromium unless ERRMAP_REQUIRE_BROWSER=1.

mod devtools;
mod serve_support;

use devtools::{browser_or_skip, DevTools};
use serde_json::Value;
use serve_support::*;
use std::path::Path;
use std::process::{Child, Stdio};
use std::time::{Duration, Instant};

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

/// Log in through the form as the operator `op` from a fresh page; ends on the live page.
fn log_in_as_operator(dt: &mut DevTools, s: &str, url: &str) {
    dt.call(
        Some(s),
        "Page.navigate",
        serde_json::json!({"url": format!("{url}/live")}),
    );
    // Without a session: the login form.
    dt.wait_until(
        s,
        "location.pathname === '/login' && document.readyState === 'complete'",
        Duration::from_secs(30),
        "the login page",
    );
    dt.eval(
        s,
        &format!(
            "document.querySelector('input[name=user]').value = 'op';
             document.querySelector('input[name=password]').value = '{PASSWORD}';
             document.querySelector('form.login').submit(); true"
        ),
    );
    dt.wait_until(
        s,
        "location.pathname === '/live'",
        Duration::from_secs(30),
        "the live page after login",
    );
}

/// No console error, exception, CSP violation or failed load (a live stream cancelled by
/// leaving its page is not a failure), and no request outside the server.
fn assert_browser_clean(dt: &DevTools, url: &str) {
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
    for e in dt
        .events
        .iter()
        .filter(|e| e["method"] == "Network.requestWillBeSent")
    {
        let r = e["params"]["request"]["url"].as_str().unwrap_or("");
        assert!(
            r.starts_with(&format!("{url}/")) || r.starts_with("data:") || r == "about:blank",
            "request outside the server: {r}"
        );
    }
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
    log_in_as_operator(&mut dt, &s, &url);
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
    assert_browser_clean(&dt, &url);
}

/// Rows of the sample replay the live test keeps (the first 15 minutes of data time).
const REPLAY_ROWS: usize = 90;

/// Data time per wall-clock second in the live test: one 10 s row every 50 ms, so the loop
/// runs for about 5 s, long enough to be seen, paused and resumed.
const REPLAY_SPEED: u32 = 200;

/// The sample live config, model and the head of its replay in `dir`, logging into `db` (the
/// monitor's store, so an operator's pause reaches the loop), replayed at [`REPLAY_SPEED`].
fn sample_live(dir: &Path, db: &Path) -> std::path::PathBuf {
    let sample = root().join("data/thermal-live");
    std::fs::copy(sample.join("model.json"), dir.join("model.json")).unwrap();
    let replay = std::fs::read_to_string(sample.join("replay.csv")).unwrap();
    let head: Vec<&str> = replay.lines().take(REPLAY_ROWS + 1).collect();
    std::fs::write(dir.join("replay.csv"), head.join("\n") + "\n").unwrap();
    let config = std::fs::read_to_string(sample.join("live.toml")).unwrap();
    let line = |start: &str| {
        config
            .lines()
            .find(|l| l.trim_start().starts_with(start))
            .unwrap_or_else(|| panic!("the sample config has a `{start}` line"))
            .to_string()
    };
    let config = config
        .replace(
            &line("path = \"../../out/"),
            &format!("path = {:?}", db.to_str().unwrap()),
        )
        .replace(
            &line("replay_speed"),
            &format!("replay_speed = {REPLAY_SPEED}"),
        );
    let path = dir.join("live.toml");
    std::fs::write(&path, config).unwrap();
    path
}

/// A running `errmap live`, killed when dropped (a failing test leaves no loop behind).
struct LiveLoop(Child);

impl Drop for LiveLoop {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// Two snapshots of the state file, at least two cycles apart, both paused.
fn paused_snapshots(state: &Path) -> Vec<Value> {
    let deadline = Instant::now() + Duration::from_secs(30);
    let mut seen: Vec<Value> = Vec::new();
    while seen.len() < 2 {
        assert!(
            Instant::now() < deadline,
            "no two paused cycles in the state file: {seen:?}"
        );
        // The file is replaced atomically, so every read is one whole cycle's state.
        let now: Value = serde_json::from_str(&std::fs::read_to_string(state).unwrap()).unwrap();
        let later = seen
            .first()
            .is_none_or(|first| now["cycle"].as_u64() >= first["cycle"].as_u64().map(|c| c + 2));
        if now["mode"] == "paused" && later {
            seen.push(now);
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    seen
}

/// The number a page cell shows, parsed.
fn shown(v: &Value) -> f64 {
    v.as_str()
        .and_then(|t| t.parse().ok())
        .unwrap_or_else(|| panic!("not a number on the page: {v}"))
}

#[test]
fn the_live_page_follows_errmap_live_replaying_the_sample_and_an_operator_pauses_it() {
    let Some(chrome) = browser_or_skip("serve_browser (live)") else {
        return;
    };
    let site = Site::new();
    let config = sample_live(site.path(), &site.db);
    let state = site.path().join("state.json");
    let server = Server::start(&site, &["--live", state.to_str().unwrap()]);
    let url = server.url.clone();
    let mut dt = DevTools::start(&chrome);
    let s = dt.page();
    log_in_as_operator(&mut dt, &s, &url);
    dt.wait_until(
        &s,
        "document.getElementById('mode').textContent === 'no state'",
        Duration::from_secs(30),
        "the live page before the loop runs",
    );

    // The real loop, replaying the sample log into the monitor's store.
    let started = Instant::now();
    let mut live = LiveLoop(
        errmap()
            .arg("live")
            .arg(&config)
            .args(["--dry-run", "--state"])
            .arg(&state)
            .current_dir(site.path())
            .stdout(Stdio::null())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap(),
    );
    dt.wait_until(
        &s,
        "Number(document.getElementById('cycle').textContent) >= 3 && document.getElementById('mode').textContent === 'running'",
        Duration::from_secs(30),
        "the loop running on the page",
    );
    let first = shown(
        &dt.eval(&s, "document.getElementById('cycle').textContent")
            .unwrap(),
    );
    dt.wait_until(
        &s,
        &format!(
            "Number(document.getElementById('cycle').textContent) >= {}",
            first + 5.0
        ),
        Duration::from_secs(30),
        "the cycle count advancing",
    );

    // An operator pauses: the loop reads the command from the store and holds its values.
    dt.eval(
        &s,
        "window.errmapOldPage = true; document.querySelector('#controls button[value=pause]').click(); true",
    );
    dt.wait_until(
        &s,
        "window.errmapOldPage === undefined && location.pathname === '/live' && document.getElementById('mode').textContent === 'paused' && document.querySelector('#axes tbody tr td:nth-child(9)').textContent === 'held'",
        Duration::from_secs(30),
        "the loop paused and its axis held",
    );
    // Paused, the written line is frozen: between two paused cycles the value at the axis's
    // position moves only along that line (slope × distance travelled), whatever the model asks.
    let paused_states = paused_snapshots(&state);
    let (a, b) = (&paused_states[0]["axes"][0], &paused_states[1]["axes"][0]);
    let slope_um_per_m = a["written_slope_um_per_m"].as_f64().unwrap();
    assert_eq!(
        b["written_slope_um_per_m"].as_f64().unwrap(),
        slope_um_per_m
    );
    let travel_mm = b["position_mm"].as_f64().unwrap() - a["position_mm"].as_f64().unwrap();
    let moved_um = b["written_um"].as_f64().unwrap() - a["written_um"].as_f64().unwrap();
    assert!(
        (moved_um - slope_um_per_m * travel_mm / 1000.0).abs() < 1e-6,
        "paused, the written value moved {moved_um} µm over {travel_mm} mm at {slope_um_per_m} µm/m"
    );
    dt.eval(
        &s,
        "window.errmapOldPage = true; document.querySelector('#controls button[value=resume]').click(); true",
    );
    dt.wait_until(
        &s,
        "window.errmapOldPage === undefined && location.pathname === '/live' && document.getElementById('mode').textContent === 'running'",
        Duration::from_secs(30),
        "the loop running again",
    );

    // The replay ends; the page settles on the loop's last state file.
    let status = loop {
        if let Some(status) = live.0.try_wait().unwrap() {
            break status;
        }
        assert!(
            started.elapsed() < Duration::from_secs(120),
            "errmap live did not finish its replay in 120 s"
        );
        std::thread::sleep(Duration::from_millis(100));
    };
    let mut stderr = String::new();
    std::io::Read::read_to_string(&mut live.0.stderr.take().unwrap(), &mut stderr).unwrap();
    assert!(status.success(), "errmap live failed: {stderr}");
    let last: Value = serde_json::from_str(&std::fs::read_to_string(&state).unwrap()).unwrap();
    let cycle = last["cycle"].as_u64().unwrap();
    assert!(
        cycle as usize >= REPLAY_ROWS / 2,
        "the loop ran {cycle} cycles for {REPLAY_ROWS} rows"
    );
    dt.wait_until(
        &s,
        &format!("document.getElementById('cycle').textContent === '{cycle}'"),
        Duration::from_secs(30),
        "the last cycle on the page",
    );
    let page = dt
        .eval(
            &s,
            "({sensors: Array.from(document.querySelectorAll('#sensors tbody tr')).map(r => [r.cells[0].textContent, r.cells[1].textContent]),
              axes: Array.from(document.querySelectorAll('#axes tbody tr')).map(r => [r.cells[0].textContent, r.cells[3].textContent, r.cells[4].textContent])})",
        )
        .unwrap();
    // Each value as the page shows it is the state file's, to the two decimals shown.
    let sensors = last["sensors"].as_array().unwrap();
    assert_eq!(page["sensors"].as_array().unwrap().len(), sensors.len());
    for (row, sensor) in page["sensors"].as_array().unwrap().iter().zip(sensors) {
        assert_eq!(row[0], sensor["name"]);
        let value = sensor["value_c"].as_f64().unwrap();
        assert!(
            (shown(&row[1]) - value).abs() <= 0.005 + 1e-9,
            "{row} vs {sensor}"
        );
    }
    let axes = last["axes"].as_array().unwrap();
    assert_eq!(page["axes"].as_array().unwrap().len(), axes.len());
    for (row, axis) in page["axes"].as_array().unwrap().iter().zip(axes) {
        assert_eq!(row[0], axis["axis"]);
        for (cell, key) in [(&row[1], "computed_um"), (&row[2], "written_um")] {
            let value = axis[key].as_f64().unwrap();
            assert!(
                (shown(cell) - value).abs() <= 0.005 + 1e-9,
                "{key}: {row} vs {axis}"
            );
        }
    }

    // Both commands were handled by the loop and logged.
    let conn = rusqlite::Connection::open(&site.db).unwrap();
    let mut stmt = conn
        .prepare("SELECT user, command, handled_utc IS NOT NULL FROM live_commands ORDER BY id")
        .unwrap();
    let commands: Vec<(String, String, bool)> = stmt
        .query_map([], |r| Ok((r.get(0)?, r.get(1)?, r.get(2)?)))
        .unwrap()
        .map(Result::unwrap)
        .collect();
    assert_eq!(
        commands,
        vec![
            ("op".to_string(), "pause".to_string(), true),
            ("op".to_string(), "resume".to_string(), true)
        ]
    );
    dt.drain(Duration::from_millis(500));
    assert_browser_clean(&dt, &url);
}
