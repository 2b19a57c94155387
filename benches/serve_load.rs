//! Load bench of `errmap serve` on loopback, bounded in clients and time: N live clients on the SSE stream while the state file is rewritten 10 times a second, plus steady page and API requests; prints request latency percentiles, errors, the push delay of the stream and the server's peak memory.
//!
//! `cargo bench --bench serve_load -- [--clients 200] [--seconds 30] [--rate 20] [--json]`
//! (the release binary of this checkout; `--errmap PATH` for another). The client runs on the
//! same machine as the server, on one thread.

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

const PASSWORD: &str = "correct horse battery";

struct Options {
    clients: usize,
    seconds: u64,
    rate: u64,
    json: bool,
    errmap: PathBuf,
}

fn options() -> Options {
    let mut o = Options {
        clients: 200,
        seconds: 30,
        rate: 20,
        json: false,
        errmap: PathBuf::from(env!("CARGO_BIN_EXE_errmap")),
    };
    let args: Vec<String> = std::env::args().skip(1).collect();
    let mut i = 0;
    while i < args.len() {
        let next = args.get(i + 1).cloned().unwrap_or_default();
        match args[i].as_str() {
            "--clients" => o.clients = next.parse::<usize>().expect("--clients N").clamp(1, 2000),
            "--seconds" => o.seconds = next.parse::<u64>().expect("--seconds S").clamp(1, 600),
            "--rate" => o.rate = next.parse::<u64>().expect("--rate R").clamp(1, 1000),
            "--errmap" => o.errmap = PathBuf::from(next),
            "--json" => {
                o.json = true;
                i += 1;
                continue;
            }
            // cargo bench passes --bench; ignore what is not ours.
            _ => {
                i += 1;
                continue;
            }
        }
        i += 2;
    }
    o
}

fn run(cmd: &mut Command) {
    let out = cmd.output().expect("run errmap");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
}

/// ms since the epoch as the contract's UTC stamp.
fn utc_ms(ms: i64) -> String {
    errmap::io::stamp::utc_rfc3339_ms(ms)
}

fn now_ms() -> i64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .unwrap()
        .as_millis() as i64
}

/// The state file as errmap live writes it: 6 sensors, 3 axes, atomic rewrite.
fn write_state(path: &Path, cycle: u64) {
    let t = now_ms();
    let sensors: Vec<serde_json::Value> = (1..=6)
        .map(|i| serde_json::json!({"name": format!("T{i}"), "value_c": 20.0 + (cycle % 100) as f64 * 0.01 + i as f64,
                                     "ok": true, "source": "rack", "age_ms": 40, "problem": null}))
        .collect();
    let axes: Vec<serde_json::Value> = ["X", "Y", "Z"]
        .iter()
        .map(|a| serde_json::json!({"axis": a, "position_mm": 100.0, "direction": "forward", "computed_um": 3.2,
                                     "written_um": 3.1, "limit_um": 50.0, "rate_limit_um_s": 5.0, "target": "ctl", "held": false}))
        .collect();
    let state = serde_json::json!({
        "schema": "errmap-live-state/1", "written_utc": utc_ms(t), "cycle": cycle, "period_ms": 100,
        "mode": "running", "dry_run": true, "coolant_on": true, "sensors": sensors, "axes": axes,
        "sources": [{"name": "rack", "kind": "modbus", "healthy": true, "last_ok_utc": utc_ms(t), "problem": null}],
        "alarms": []
    });
    let tmp = path.with_extension("tmp");
    std::fs::write(&tmp, serde_json::to_vec(&state).unwrap()).unwrap();
    std::fs::rename(&tmp, path).unwrap();
}

/// One hour of live cycles at 1 Hz in the store, for the history page.
fn fill_history(db: &Path) -> String {
    let conn = rusqlite::Connection::open(db).unwrap();
    conn.execute_batch(
        "CREATE TABLE IF NOT EXISTS live_cycles (cycle INTEGER NOT NULL, at_utc TEXT NOT NULL, mode TEXT NOT NULL,
         inputs_json TEXT NOT NULL, outputs_json TEXT NOT NULL, note TEXT, PRIMARY KEY (cycle, at_utc));",
    )
    .unwrap();
    let start = now_ms() - 3_600_000;
    let tx = conn.unchecked_transaction().unwrap();
    for i in 0..3600i64 {
        tx.execute(
            "INSERT INTO live_cycles VALUES (?1, ?2, 'running', ?3, ?4, NULL)",
            rusqlite::params![
                i,
                utc_ms(start + i * 1000),
                format!(
                    "{{\"T1\": {}, \"T2\": {}, \"coolant_on\": true}}",
                    20.0 + i as f64 * 1e-3,
                    21.0
                ),
                "{\"X\": {\"computed_um\": 3.2, \"written_um\": 3.1, \"target\": \"ctl\"}}"
            ],
        )
        .unwrap();
    }
    tx.commit().unwrap();
    utc_ms(start)
}

fn percentile(sorted: &[f64], p: f64) -> f64 {
    if sorted.is_empty() {
        return f64::NAN;
    }
    let rank = ((p / 100.0) * sorted.len() as f64).ceil() as usize;
    sorted[rank.clamp(1, sorted.len()) - 1]
}

fn status_kib(pid: u32, key: &str) -> Option<u64> {
    let text = std::fs::read_to_string(format!("/proc/{pid}/status")).ok()?;
    text.lines()
        .find(|l| l.starts_with(key))?
        .split_whitespace()
        .nth(1)?
        .parse()
        .ok()
}

fn main() {
    let o = options();
    let dir = tempfile::tempdir().unwrap();
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let db = dir.path().join("store.sqlite");
    run(Command::new(&o.errmap)
        .args(["thermal", "ingest", "-q", "--db"])
        .arg(&db)
        .arg(root.join("data/thermal/campaign-1-coolant-off")));
    let history_from = fill_history(&db);
    let users = dir.path().join("users.toml");
    let mut add = Command::new(&o.errmap)
        .args([
            "serve",
            "user",
            "add",
            "op",
            "--role",
            "operator",
            "--password-stdin",
            "-q",
            "--users",
        ])
        .arg(&users)
        .stdin(Stdio::piped())
        .spawn()
        .unwrap();
    std::io::Write::write_all(
        &mut add.stdin.take().unwrap(),
        format!("{PASSWORD}\n").as_bytes(),
    )
    .unwrap();
    assert!(add.wait().unwrap().success());
    let runs = dir.path().join("runs/r1");
    std::fs::create_dir_all(&runs).unwrap();
    std::fs::write(
        runs.join("report.html"),
        format!(
            "<!DOCTYPE html><style>p{{}}</style>{}",
            "<p>row</p>".repeat(2000)
        ),
    )
    .unwrap();
    let state = dir.path().join("state.json");
    write_state(&state, 0);
    let mut server = Command::new(&o.errmap)
        .args([
            "serve",
            "--bind",
            "127.0.0.1:0",
            "--max-live-clients",
            "5000",
            "--db",
        ])
        .arg(&db)
        .arg("--users")
        .arg(&users)
        .arg("--live")
        .arg(&state)
        .arg("--runs")
        .arg(dir.path().join("runs"))
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let pid = server.id();
    let mut line = String::new();
    std::io::BufRead::read_line(
        &mut std::io::BufReader::new(server.stdout.take().unwrap()),
        &mut line,
    )
    .unwrap();
    let url = line
        .trim()
        .strip_prefix("errmap serve: listening on ")
        .expect("server address")
        .to_string();
    let rss_idle_kib = status_kib(pid, "VmRSS:").unwrap_or(0);

    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .unwrap();
    let report = rt.block_on(async {
        let c = reqwest::Client::builder()
            .redirect(reqwest::redirect::Policy::none())
            .pool_max_idle_per_host(64)
            .build()
            .unwrap();
        // Log in once; every client shares the session.
        let form = c.get(format!("{url}/login")).send().await.unwrap();
        let pre = form.headers()["set-cookie"].to_str().unwrap().split(';').next().unwrap().to_string();
        let html = form.text().await.unwrap();
        let at = html.find("name=\"csrf\" value=\"").unwrap() + 19;
        let token = html[at..at + html[at..].find('"').unwrap()].to_string();
        let r = c
            .post(format!("{url}/login"))
            .header("cookie", pre)
            .form(&[("user", "op"), ("password", PASSWORD), ("csrf", token.as_str())])
            .send()
            .await
            .unwrap();
        assert_eq!(r.status(), 303);
        let cookie = r.headers()["set-cookie"].to_str().unwrap().split(';').next().unwrap().to_string();

        let stop = Instant::now() + Duration::from_secs(o.seconds);
        let events = Arc::new(AtomicU64::new(0));
        let stream_errors = Arc::new(AtomicU64::new(0));
        let delays = Arc::new(Mutex::new(Vec::<f64>::new()));
        let connected = Arc::new(AtomicU64::new(0));
        let mut tasks = Vec::new();
        for _ in 0..o.clients {
            let (c, url, cookie) = (c.clone(), url.clone(), cookie.clone());
            let (events, errors, delays, connected) = (events.clone(), stream_errors.clone(), delays.clone(), connected.clone());
            tasks.push(tokio::spawn(async move {
                let mut r = match c.get(format!("{url}/api/live")).header("cookie", cookie).send().await {
                    Ok(r) if r.status() == 200 => r,
                    _ => {
                        errors.fetch_add(1, Ordering::Relaxed);
                        return;
                    }
                };
                connected.fetch_add(1, Ordering::Relaxed);
                let mut buf = String::new();
                loop {
                    let left = stop.saturating_duration_since(Instant::now());
                    match tokio::time::timeout(left, r.chunk()).await {
                        Err(_) => return,
                        Ok(Ok(Some(bytes))) => {
                            buf.push_str(&String::from_utf8_lossy(&bytes));
                            while let Some(end) = buf.find("\n\n") {
                                let event: String = buf.drain(..end + 2).collect();
                                if let Some(data) = event.lines().find_map(|l| l.strip_prefix("data:")) {
                                    if let Ok(v) = serde_json::from_str::<serde_json::Value>(data.trim()) {
                                        events.fetch_add(1, Ordering::Relaxed);
                                        if let Some(w) = v["state"]["written_utc"].as_str() {
                                            if let Some(ms) = parse_ms(w) {
                                                delays.lock().unwrap().push((now_ms() - ms) as f64);
                                            }
                                        }
                                    }
                                }
                            }
                        }
                        _ => {
                            if Instant::now() < stop {
                                errors.fetch_add(1, Ordering::Relaxed);
                            }
                            return;
                        }
                    }
                }
            }));
        }
        // The live loop: a rewrite every 100 ms.
        let writer = {
            let state = state.clone();
            tokio::spawn(async move {
                let mut tick = tokio::time::interval(Duration::from_millis(100));
                let mut cycle = 1;
                while Instant::now() < stop {
                    tick.tick().await;
                    write_state(&state, cycle);
                    cycle += 1;
                }
                cycle - 1
            })
        };
        // Steady page and API requests.
        let paths = [
            "/live".to_string(),
            "/api/state".to_string(),
            format!("/history?from={}", &history_from[..16]),
            "/runs/r1/report.html".to_string(),
            "/static/app.css".to_string(),
        ];
        let latencies = Arc::new(Mutex::new(Vec::<f64>::new()));
        let request_errors = Arc::new(AtomicU64::new(0));
        let mut requests = Vec::new();
        let mut tick = tokio::time::interval(Duration::from_micros(1_000_000 / o.rate));
        let mut i = 0usize;
        let mut peak_rss_kib = 0;
        while Instant::now() < stop {
            tick.tick().await;
            let (c, url, cookie, path) = (c.clone(), url.clone(), cookie.clone(), paths[i % paths.len()].clone());
            let (lat, errs) = (latencies.clone(), request_errors.clone());
            requests.push(tokio::spawn(async move {
                let t0 = Instant::now();
                let ok = match c.get(format!("{url}{path}")).header("cookie", cookie).send().await {
                    Ok(r) if r.status().is_success() => r.bytes().await.is_ok(),
                    _ => false,
                };
                if ok {
                    lat.lock().unwrap().push(t0.elapsed().as_secs_f64() * 1000.0);
                } else {
                    errs.fetch_add(1, Ordering::Relaxed);
                }
            }));
            i += 1;
            if i.is_multiple_of(10) {
                peak_rss_kib = peak_rss_kib.max(status_kib(pid, "VmRSS:").unwrap_or(0));
            }
        }
        for t in requests {
            let _ = t.await;
        }
        for t in tasks {
            let _ = t.await;
        }
        let rewrites = writer.await.unwrap_or(0);
        let mut lat = latencies.lock().unwrap().clone();
        lat.sort_by(f64::total_cmp);
        let mut del = delays.lock().unwrap().clone();
        del.sort_by(f64::total_cmp);
        serde_json::json!({
            "clients": o.clients,
            "clients_connected": connected.load(Ordering::Relaxed),
            "seconds": o.seconds,
            "state_rewrites": rewrites,
            "requests": lat.len() as u64 + request_errors.load(Ordering::Relaxed),
            "request_errors": request_errors.load(Ordering::Relaxed),
            "request_ms": {"p50": percentile(&lat, 50.0), "p95": percentile(&lat, 95.0), "p99": percentile(&lat, 99.0), "max": lat.last().copied().unwrap_or(f64::NAN)},
            "stream_errors": stream_errors.load(Ordering::Relaxed),
            "events": events.load(Ordering::Relaxed),
            "push_delay_ms": {"p50": percentile(&del, 50.0), "p99": percentile(&del, 99.0), "max": del.last().copied().unwrap_or(f64::NAN)},
            "server_rss_idle_kib": rss_idle_kib,
            "server_rss_peak_sampled_kib": peak_rss_kib,
        })
    });
    let hwm = status_kib(pid, "VmHWM:");
    let _ = server.kill();
    let _ = server.wait();
    let mut report = report;
    report["server_peak_rss_kib"] = serde_json::json!(hwm);
    if o.json {
        println!("{report}");
    } else {
        println!("errmap serve under load on loopback ({})", url);
        println!("{}", serde_json::to_string_pretty(&report).unwrap());
    }
}

/// A contract stamp `YYYY-MM-DDThh:mm:ss.mmmZ` in ms since the epoch.
fn parse_ms(t: &str) -> Option<i64> {
    let n = |a: usize, b: usize| t.get(a..b)?.parse::<i64>().ok();
    let (y, m, d) = (n(0, 4)?, n(5, 7)?, n(8, 10)?);
    let (hh, mm, ss, ms) = (n(11, 13)?, n(14, 16)?, n(17, 19)?, n(20, 23)?);
    let yy = if m <= 2 { y - 1 } else { y };
    let era = yy.div_euclid(400);
    let yoe = yy - era * 400;
    let doy = (153 * ((m + 9) % 12) + 2) / 5 + d - 1;
    let doe = yoe * 365 + yoe / 4 - yoe / 100 + doy;
    let days = era * 146_097 + doe - 719_468;
    Some(((days * 24 + hh) * 60 + mm) * 60_000 + ss * 1000 + ms)
}
