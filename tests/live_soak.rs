//! The soak: a 24-hour thermal campaign (`errmap synth live-replay --hours 24`, a row a second,
//! the coolant switching every hour) replayed through `errmap live --dry-run` as fast as the
//! loop runs. The record must be complete (one `live_cycles` row per row of the log, numbered
//! without a gap, three temperature samples each), no cycle missed, and the process's memory
//! flat: its resident set, sampled from /proc while it runs, may not grow between the first
//! and the last quarter of the run by more than 3 MB (a leak of 40 bytes a cycle would).
//! `ERRMAP_SOAK_HOURS` shortens or lengthens it (default 24).

mod live_support;
use live_support::*;

fn rss_kb(pid: u32) -> Option<u64> {
    let status = std::fs::read_to_string(format!("/proc/{pid}/status")).ok()?;
    status
        .lines()
        .find(|l| l.starts_with("VmRSS:"))?
        .split_whitespace()
        .nth(1)?
        .parse()
        .ok()
}

#[test]
fn a_day_replayed_keeps_memory_flat_and_the_log_complete() {
    if !std::path::Path::new("/proc/self/status").exists() {
        eprintln!("skipped: no /proc to sample the memory from");
        return;
    }
    let hours: f64 = std::env::var("ERRMAP_SOAK_HOURS")
        .ok()
        .and_then(|h| h.parse().ok())
        .unwrap_or(24.0);
    let dir = scratch();
    let d = dir.path();
    let rows = synth_replay(
        d,
        &[
            "--hours",
            &hours.to_string(),
            "--period-s",
            "1",
            "--campaign",
            "1",
            "--coolant-every-s",
            "3600",
        ],
    );
    std::fs::write(d.join("log.csv"), rows.join("\n") + "\n").unwrap();
    let n = rows.len() as i64 - 1;
    std::fs::write(
        d.join("live.toml"),
        config(
            "period_ms = 1000\nreplay_speed = 0",
            "timeout_ms = 3000\nramp_timeout_ms = 10000",
            // The day-long run warms the axis to about 120 µm/m.
            "limit_um = 150\nslope_limit_um_per_m = 250\nrate_limit_um_s = 2",
            "min_c = 5\nmax_c = 60",
        ),
    )
    .unwrap();
    let mut child = std::process::Command::new(ERRMAP)
        .args([
            "live",
            "live.toml",
            "--dry-run",
            "--state",
            "state.json",
            "--json",
        ])
        .current_dir(d)
        .stdout(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    // (cycle from the state file, resident set kB) while it runs.
    let mut samples: Vec<(i64, u64)> = Vec::new();
    while child.try_wait().unwrap().is_none() {
        let cycle = std::fs::read_to_string(d.join("state.json"))
            .ok()
            .and_then(|t| serde_json::from_str::<serde_json::Value>(&t).ok())
            .and_then(|s| s["cycle"].as_i64());
        if let (Some(c), Some(r)) = (cycle, rss_kb(child.id())) {
            samples.push((c, r));
        }
        std::thread::sleep(std::time::Duration::from_millis(50));
    }
    let out = child.wait_with_output().unwrap();
    assert!(out.status.success());
    let summary: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(summary["missed_cycles"], 0);
    assert_eq!(summary["cycles"].as_i64().unwrap(), n);
    assert_eq!(summary["stop_reason"], "end of the replay data");

    let conn = rusqlite::Connection::open(d.join("live.sqlite")).unwrap();
    let (count, lo, hi): (i64, i64, i64) = conn
        .query_row(
            "SELECT COUNT(*), MIN(cycle), MAX(cycle) FROM live_cycles",
            [],
            |r| Ok((r.get(0)?, r.get(1)?, r.get(2)?)),
        )
        .unwrap();
    assert_eq!((count, lo, hi), (n, 0, n - 1), "one row per cycle, no gap");
    let samples_logged: i64 = conn
        .query_row("SELECT COUNT(*) FROM temperature_samples", [], |r| r.get(0))
        .unwrap();
    assert_eq!(samples_logged, 3 * n);
    let off_cycles: i64 = conn
        .query_row(
            "SELECT COUNT(*) FROM live_cycles WHERE mode <> 'running'",
            [],
            |r| r.get(0),
        )
        .unwrap();
    assert!(
        off_cycles <= 60,
        "{off_cycles} cycles not running (the start ramp and the stop)"
    );

    let quarter = |from: f64, to: f64| {
        samples
            .iter()
            .filter(|(c, _)| (*c as f64) >= from * n as f64 && (*c as f64) < to * n as f64)
            .map(|(_, r)| *r)
            .max()
    };
    let (early, late) = (quarter(0.1, 0.35), quarter(0.75, 1.0));
    eprintln!(
        "soak: {n} cycles, {} memory samples, resident set {early:?} kB → {late:?} kB",
        samples.len()
    );
    if let (Some(early), Some(late)) = (early, late) {
        assert!(
            late <= early + 3 * 1024,
            "resident set grew from {early} kB to {late} kB"
        );
    } else {
        panic!("too few memory samples ({}) to judge", samples.len());
    }
}
