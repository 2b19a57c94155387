//! `errmap serve`'s live feed, history and TLS against the real server: the state file (written as `errmap live` writes it) pushed by Server-Sent Events to every client at most 10 times a second, refusals of files that are not the contract's, the stream ending with its session, the history charts drawn from live_cycles and the campaigns, and HTTPS with `Secure` `__Host-` cookies.

mod serve_support;

use serde_json::Value;
use serve_support::*;
use std::time::{Duration, Instant};

fn stream(c: &reqwest::blocking::Client, url: &str, s: &Login) -> reqwest::blocking::Response {
    let r = c
        .get(format!("{url}/api/live"))
        .header("cookie", &s.cookie)
        .send()
        .unwrap();
    assert_eq!(r.status(), 200);
    assert_eq!(
        r.headers()["content-type"].to_str().unwrap(),
        "text/event-stream"
    );
    r
}

/// A client without an overall timeout, for streams that stay open.
fn stream_client() -> reqwest::blocking::Client {
    reqwest::blocking::Client::builder()
        .redirect(reqwest::redirect::Policy::none())
        .timeout(None)
        .build()
        .unwrap()
}

#[test]
fn every_client_gets_each_rewrite_of_the_state_file() {
    let site = Site::new();
    let state = site.path().join("live").join("state.json");
    std::fs::create_dir_all(state.parent().unwrap()).unwrap();
    let server = Server::start(&site, &["--live", state.to_str().unwrap()]);
    let c = stream_client();
    let a = login(&c, &server.url, "view");
    let b = login(&c, &server.url, "op");
    // No file yet: the problem, no state.
    let first = read_events(stream(&c, &server.url, &a), Duration::from_secs(10), |_| {
        true
    });
    assert_eq!(first[0]["state"], Value::Null);
    assert!(
        first[0]["problem"].as_str().unwrap().contains("state file"),
        "{first:?}"
    );
    let sa = stream(&c, &server.url, &a);
    let sb = stream(&c, &server.url, &b);
    let writer = {
        let state = state.clone();
        std::thread::spawn(move || {
            for cycle in 1..=3u64 {
                std::thread::sleep(Duration::from_millis(400));
                write_state(
                    &state,
                    cycle,
                    20.0 + cycle as f64,
                    1.5 * cycle as f64,
                    &[(7, "T3 <open> RTD")],
                );
            }
        })
    };
    for s in [sa, sb] {
        let events = read_events(s, Duration::from_secs(20), |v| v["state"]["cycle"] == 3);
        let last = events.last().unwrap();
        assert_eq!(last["problem"], Value::Null);
        assert_eq!(last["stale"], false);
        let st = &last["state"];
        assert_eq!(st["schema"], "errmap-live-state/1");
        assert_eq!(st["sensors"][0]["value_c"], 23.0);
        assert_eq!(st["sensors"][1]["value_c"], Value::Null);
        assert_eq!(st["axes"][0]["written_um"], 4.5);
        assert_eq!(st["alarms"][0]["message"], "T3 <open> RTD");
        // Cycles arrive in order.
        let cycles: Vec<u64> = events
            .iter()
            .filter_map(|e| e["state"]["cycle"].as_u64())
            .collect();
        assert!(cycles.windows(2).all(|w| w[0] < w[1]), "{cycles:?}");
    }
    writer.join().unwrap();
    let now: Value = serde_json::from_str(&body(
        c.get(format!("{}/api/state", server.url))
            .header("cookie", &a.cookie)
            .send()
            .unwrap(),
    ))
    .unwrap();
    assert_eq!(now["state"]["cycle"], 3);
}

#[test]
fn the_stream_carries_at_most_ten_states_a_second() {
    let site = Site::new();
    let state = site.path().join("state.json");
    write_state(&state, 0, 20.0, 0.0, &[]);
    let server = Server::start(&site, &["--live", state.to_str().unwrap()]);
    let c = stream_client();
    let s = login(&c, &server.url, "view");
    let r = stream(&c, &server.url, &s);
    // Rewrite the file as fast as it goes for 2 s (far more than 10 times a second).
    let stop = Instant::now() + Duration::from_secs(2);
    let writer = {
        let state = state.clone();
        std::thread::spawn(move || {
            let mut cycle = 1;
            while Instant::now() < stop {
                write_state(&state, cycle, 20.0, 0.0, &[]);
                cycle += 1;
                std::thread::sleep(Duration::from_millis(2));
            }
            cycle - 1
        })
    };
    let mut seen = 0;
    let mut last_cycle = 0;
    let events = read_events(r, Duration::from_secs(20), |v| {
        seen += 1;
        last_cycle = v["state"]["cycle"].as_u64().unwrap_or(0);
        Instant::now() > stop + Duration::from_millis(500)
    });
    let written = writer.join().unwrap();
    assert!(written > 100, "the writer made {written} rewrites");
    // 2.5 s of stream at 10 a second, plus the first snapshot: at most 26 events.
    assert!(
        events.len() <= 26,
        "{} events for {written} rewrites",
        events.len()
    );
    assert!(events.len() >= 5, "{} events", events.len());
}

#[test]
fn files_that_are_not_the_contracts_state_are_reported_and_not_shown() {
    let site = Site::new();
    let state = site.path().join("state.json");
    write_state(&state, 5, 20.0, 0.0, &[]);
    let server = Server::start(&site, &["--live", state.to_str().unwrap()]);
    let c = stream_client();
    let s = login(&c, &server.url, "view");
    let r = stream(&c, &server.url, &s);
    let writer = {
        let state = state.clone();
        std::thread::spawn(move || {
            std::thread::sleep(Duration::from_millis(500));
            let text = std::fs::read_to_string(&state)
                .unwrap()
                .replace("errmap-live-state/1", "errmap-live-state/2");
            std::fs::write(state.with_extension("tmp"), text).unwrap();
            std::fs::rename(state.with_extension("tmp"), &state).unwrap();
        })
    };
    let events = read_events(r, Duration::from_secs(10), |v| v["state"].is_null());
    writer.join().unwrap();
    assert_eq!(events[0]["state"]["cycle"], 5);
    let last = events.last().unwrap();
    assert!(
        last["problem"].as_str().unwrap().contains("schema"),
        "{last}"
    );
    // A state no longer rewritten turns stale (3 periods, at least 2 s).
    write_state(&state, 6, 20.0, 0.0, &[]);
    let r = stream(&c, &server.url, &s);
    let events = read_events(r, Duration::from_secs(10), |v| {
        v["stale"] == true && v["state"]["cycle"] == 6
    });
    assert!(
        events
            .iter()
            .any(|v| v["stale"] == false && v["state"]["cycle"] == 6),
        "{events:?}"
    );
}

#[test]
fn the_stream_ends_when_its_session_does() {
    let site = Site::new();
    let state = site.path().join("state.json");
    write_state(&state, 1, 20.0, 0.0, &[]);
    let server = Server::start(&site, &["--live", state.to_str().unwrap()]);
    let c = stream_client();
    let s = login(&c, &server.url, "view");
    let r = stream(&c, &server.url, &s);
    let (tx, rx) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        let mut all = String::new();
        let _ = std::io::Read::read_to_string(&mut { r }, &mut all);
        let _ = tx.send(all);
    });
    let out = c
        .post(format!("{}/logout", server.url))
        .header("cookie", &s.cookie)
        .form(&[("csrf", s.csrf.as_str())])
        .send()
        .unwrap();
    assert_eq!(out.status(), 303);
    let all = rx
        .recv_timeout(Duration::from_secs(15))
        .expect("the stream did not end after logout");
    assert!(all.contains("\"cycle\":1"), "{all}");
}

const LIVE_CYCLES_DDL: &str = "CREATE TABLE IF NOT EXISTS live_cycles (
    cycle INTEGER NOT NULL,
    at_utc TEXT NOT NULL,
    mode TEXT NOT NULL,                -- as the state file's \"mode\"
    inputs_json TEXT NOT NULL,         -- {\"T1\": 21.3, ..., \"coolant_on\": true}
    outputs_json TEXT NOT NULL,        -- {\"X\": {\"computed_um\": .., \"written_um\": .., \"target\": \"..\"}, ...}
    note TEXT,                         -- alarm raised, command applied, write retried, ...
    PRIMARY KEY (cycle, at_utc)
);";

/// The points of the polyline of a series in a page.
fn polyline(page: &str, series: &str) -> String {
    let tag = format!("<polyline data-series=\"{series}\"");
    let at = page
        .find(&tag)
        .unwrap_or_else(|| panic!("no line {series}"));
    let rest = &page[at..];
    let p = rest.find("points=\"").unwrap() + 8;
    rest[p..p + rest[p..].find('"').unwrap()].to_string()
}

#[test]
fn history_draws_the_live_cycles_and_lists_the_campaigns() {
    let site = Site::new();
    // Three cycles as errmap live writes them: 09:00, 09:30, 10:00 UTC.
    let conn = rusqlite::Connection::open(&site.db).unwrap();
    conn.execute_batch(LIVE_CYCLES_DDL).unwrap();
    for (i, (at, nut, x)) in [
        ("2026-11-27T09:00:00.000Z", 20.0, 0.0),
        ("2026-11-27T09:30:00.000Z", 21.0, 5.0),
        ("2026-11-27T10:00:00.000Z", 22.0, 10.0),
    ]
    .iter()
    .enumerate()
    {
        conn.execute(
            "INSERT INTO live_cycles VALUES (?1, ?2, 'running', ?3, ?4, NULL)",
            rusqlite::params![
                i as i64,
                at,
                format!("{{\"nut\": {nut}, \"coolant_on\": false}}"),
                format!(
                    "{{\"X\": {{\"computed_um\": {x}, \"written_um\": {x}, \"target\": \"t\"}}}}"
                )
            ],
        )
        .unwrap();
    }
    drop(conn);
    // A second campaign and a model fitted from the store.
    for args in [
        vec![
            "thermal".to_string(),
            "ingest".into(),
            "-q".into(),
            "--db".into(),
            site.db.display().to_string(),
            root()
                .join("data/thermal/campaign-2-coolant-on")
                .display()
                .to_string(),
        ],
        vec![
            "thermal".to_string(),
            "fit".into(),
            "--from-store".into(),
            "-q".into(),
            "--db".into(),
            site.db.display().to_string(),
            "-o".into(),
            site.path().join("model.json").display().to_string(),
        ],
    ] {
        let out = errmap().args(&args).output().unwrap();
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
    }
    let loco: Option<f64> = rusqlite::Connection::open(&site.db)
        .unwrap()
        .query_row(
            "SELECT loco_rms_um FROM models WHERE name = 'X' AND version = 1",
            [],
            |r| r.get(0),
        )
        .unwrap();
    let server = Server::start(&site, &[]);
    let c = client();
    let s = login(&c, &server.url, "view");
    let r = c
        .get(format!(
            "{}/history?from=2026-11-27T09:00&to=2026-11-27T10:00",
            server.url
        ))
        .header("cookie", &s.cookie)
        .send()
        .unwrap();
    assert_eq!(r.status(), 200);
    let page = body(r);
    assert!(page.contains("data-total=\"3\""), "{page}");
    // By hand: x 0…60 min on ticks of 10, y 20…22 °C on ticks of 0.5; the plot box is
    // x 64…610 px, y 256 (bottom) … 28 px: (0, 20) → (64, 256), (30, 21) → (337, 142),
    // (60, 22) → (610, 28).
    assert_eq!(
        polyline(&page, "nut"),
        "64.00,256.00 337.00,142.00 610.00,28.00"
    );
    // Compensation 0…10 µm on ticks of 2: 5 µm → 256 − 0.5 · 228 = 142.
    assert_eq!(
        polyline(&page, "X written"),
        "64.00,256.00 337.00,142.00 610.00,28.00"
    );
    assert!(!page.contains("data-series=\"coolant_on\""));
    // The campaign of the store, with its sample count: rows of its temperature log × 3 sensors.
    let log = std::fs::read_to_string(
        root().join("data/thermal/campaign-1-coolant-off/temperatures.csv"),
    )
    .unwrap();
    let samples = (log.lines().count() - 1) * 3;
    assert!(
        page.contains(&format!("<td class=\"num\">{samples}</td>")),
        "{samples}"
    );
    assert!(page.contains("/history/campaign?name=campaign-1-coolant-off"));
    assert!(page.contains("/history/campaign?name=campaign-2-coolant-on"));
    // The model version, with its leave-one-campaign-out RMS as stored.
    let models = &page[page.find("<table id=\"models\">").expect("models table")..];
    assert!(models.contains("<td>X</td><td>1</td>"), "{models}");
    // (This fit of two campaigns stores no LOCO RMS: the page shows —.)
    let shown = loco.map_or("—".to_string(), |v| format!("{v:.3}"));
    assert!(
        models.contains(&format!("<td>{shown}</td>")),
        "{loco:?} {models}"
    );
    let r = c
        .get(format!(
            "{}/history/campaign?name=campaign-1-coolant-off",
            server.url
        ))
        .header("cookie", &s.cookie)
        .send()
        .unwrap();
    assert_eq!(r.status(), 200);
    let camp = body(r);
    for sensor in ["nut", "bearing", "room"] {
        let pts = polyline(&camp, sensor);
        let n = pts.split(' ').count();
        assert!(n > 100 && n <= 2000, "{sensor}: {n} points");
    }
    let r = c
        .get(format!("{}/history/campaign?name=nothing", server.url))
        .header("cookie", &s.cookie)
        .send()
        .unwrap();
    assert_eq!(r.status(), 404);
    // Without a range: the hour up to the newest cycle.
    let page = body(
        c.get(format!("{}/history", server.url))
            .header("cookie", &s.cookie)
            .send()
            .unwrap(),
    );
    assert!(page.contains("data-total=\"3\""), "{page}");
}

#[test]
fn tls_serves_https_with_secure_host_prefixed_cookies() {
    let site = Site::new();
    let cert =
        rcgen::generate_simple_self_signed(vec!["localhost".to_string(), "127.0.0.1".to_string()])
            .unwrap();
    let cert_pem = site.path().join("cert.pem");
    let key_pem = site.path().join("key.pem");
    std::fs::write(&cert_pem, cert.cert.pem()).unwrap();
    std::fs::write(&key_pem, cert.signing_key.serialize_pem()).unwrap();
    // A non-loopback address is fine with TLS.
    let server = Server::start(
        &site,
        &[
            "--bind",
            "0.0.0.0:0",
            "--tls-cert",
            cert_pem.to_str().unwrap(),
            "--tls-key",
            key_pem.to_str().unwrap(),
        ],
    );
    assert!(server.url.starts_with("https://"), "{}", server.url);
    let port = server.url.rsplit(':').next().unwrap();
    let url = format!("https://localhost:{port}");
    let c = reqwest::blocking::Client::builder()
        .use_rustls_tls()
        .tls_built_in_root_certs(false)
        .add_root_certificate(reqwest::Certificate::from_pem(cert.cert.pem().as_bytes()).unwrap())
        .redirect(reqwest::redirect::Policy::none())
        .build()
        .unwrap();
    let r = post_login(&c, &url, "op", PASSWORD);
    assert_eq!(r.status(), 303);
    let cookie = set_cookies(&r)
        .into_iter()
        .find(|c| c.starts_with("__Host-errmap_session="))
        .expect("a __Host- session cookie");
    let attrs: Vec<&str> = cookie.split(';').map(str::trim).skip(1).collect();
    assert_eq!(
        attrs,
        ["Path=/", "HttpOnly", "SameSite=Strict", "Secure"],
        "{cookie}"
    );
    assert_eq!(r.headers()["strict-transport-security"], "max-age=31536000");
    let s = login(&c, &url, "op");
    let page = c
        .get(format!("{url}/live"))
        .header("cookie", &s.cookie)
        .send()
        .unwrap();
    assert_eq!(page.status(), 200);
    // Plain HTTP on the TLS port gets no page.
    let plain = client()
        .get(format!("http://127.0.0.1:{port}/login"))
        .send();
    assert!(plain.map(|r| r.status() != 200).unwrap_or(true));
    // A key that is not a key: refused at start.
    std::fs::write(&key_pem, "not a key").unwrap();
    let (code, err) = refused(
        &site,
        &[
            "--bind",
            "127.0.0.1:0",
            "--tls-cert",
            cert_pem.to_str().unwrap(),
            "--tls-key",
            key_pem.to_str().unwrap(),
        ],
    );
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("TLS"), "{err}");
}

#[test]
fn live_streams_beyond_the_limit_get_503() {
    let site = Site::new();
    let state = site.path().join("state.json");
    write_state(&state, 1, 20.0, 0.0, &[]);
    let server = Server::start(
        &site,
        &["--live", state.to_str().unwrap(), "--max-live-clients", "1"],
    );
    let c = stream_client();
    let s = login(&c, &server.url, "view");
    let first = stream(&c, &server.url, &s);
    let second = c
        .get(format!("{}/api/live", server.url))
        .header("cookie", &s.cookie)
        .send()
        .unwrap();
    assert_eq!(second.status(), 503);
    drop(first);
    // The place is given back when a stream closes.
    let deadline = Instant::now() + Duration::from_secs(10);
    loop {
        let r = c
            .get(format!("{}/api/live", server.url))
            .header("cookie", &s.cookie)
            .send()
            .unwrap();
        if r.status() == 200 {
            break;
        }
        assert!(
            Instant::now() < deadline,
            "the closed stream's place never came back"
        );
        std::thread::sleep(Duration::from_millis(200));
    }
}
