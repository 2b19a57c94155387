//! `errmap live --dry-run` on the wall clock, following a CSV file the test appends to like a
//! data logger: operators' pause, resume and acknowledgements through the store's
//! `live_commands` table, the watchdog when the logger stops and its release after an
//! acknowledgement, and SIGTERM/SIGINT leaving the target ramped to zero or held. The test
//! waits for states (never for a fixed time) and asserts on what the store and state file say.

mod live_support;
use live_support::*;
use std::io::Write;
use std::path::Path;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::Duration;

/// Appends one row every 50 ms while `on` is set, cycling through `rows`.
fn logger(
    path: &Path,
    rows: Vec<String>,
    on: Arc<AtomicBool>,
    quit: Arc<AtomicBool>,
) -> std::thread::JoinHandle<()> {
    let path = path.to_path_buf();
    std::thread::spawn(move || {
        let mut i = 0;
        while !quit.load(Ordering::SeqCst) {
            if on.load(Ordering::SeqCst) {
                let mut f = std::fs::OpenOptions::new()
                    .append(true)
                    .open(&path)
                    .unwrap();
                writeln!(f, "{}", rows[i % rows.len()]).unwrap();
                i += 1;
            }
            std::thread::sleep(Duration::from_millis(50));
        }
    })
}

fn db(d: &Path) -> rusqlite::Connection {
    let c = rusqlite::Connection::open(d.join("live.sqlite")).unwrap();
    c.busy_timeout(Duration::from_millis(2000)).unwrap();
    c
}

fn command(d: &Path, command: &str, alarm: Option<i64>) -> i64 {
    let c = db(d);
    c.execute(
        "INSERT INTO live_commands (issued_utc, user, command, alarm_id) VALUES (strftime('%Y-%m-%dT%H:%M:%fZ', 'now'), 'operator', ?1, ?2)",
        rusqlite::params![command, alarm],
    )
    .unwrap();
    c.last_insert_rowid()
}

fn outcome(d: &Path, id: i64) -> Option<String> {
    db(d)
        .query_row(
            "SELECT outcome FROM live_commands WHERE id = ?1 AND handled_utc IS NOT NULL",
            [id],
            |r| r.get(0),
        )
        .ok()
}

fn setup(on_stop: &str) -> (tempfile::TempDir, Vec<String>) {
    let dir = scratch();
    let d = dir.path();
    let rows = synth_replay(d, &["--hours", "4", "--period-s", "1", "--campaign", "1"]);
    // Warm rows (the machine has run two hours): a sizeable slope to hold and ramp.
    let warm: Vec<String> = rows[7200..7300].to_vec();
    std::fs::write(d.join("log.csv"), format!("{}\n{}\n", rows[0], warm[0])).unwrap();
    let text = config(
        &format!("period_ms = 100\non_stop = \"{on_stop}\"\nstop_ramp_s = 30"),
        "follow = true\ntimeout_ms = 1500\nramp_timeout_ms = 3000",
        "limit_um = 60\nslope_limit_um_per_m = 120\nrate_limit_um_s = 20",
        // Rows repeat every 5 s of the logger: allow the jump from the last row to the first.
        "min_c = 5\nmax_c = 60\nmax_step_c = 2",
    );
    std::fs::write(d.join("live.toml"), text).unwrap();
    (dir, warm)
}

#[test]
fn commands_watchdog_and_sigterm_ramp_to_zero() {
    let (dir, warm) = setup("ramp_to_zero");
    let d = dir.path();
    let on = Arc::new(AtomicBool::new(true));
    let quit = Arc::new(AtomicBool::new(false));
    let log = logger(&d.join("log.csv"), warm, on.clone(), quit.clone());
    let mut child = std::process::Command::new(ERRMAP)
        .args(["live", "live.toml", "--dry-run", "--state", "state.json"])
        .current_dir(d)
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();

    let running = wait_for("running", || newest(d).filter(|c| c.mode == "running"));
    let slope = |c: &Cycle| c.x("written_slope_um_per_m").unwrap();
    assert!(slope(&running) < -20.0, "{}", slope(&running));

    // Pause: values held, the command marked applied, the cycle's note names it.
    let pause = command(d, "pause", None);
    assert_eq!(wait_for("pause handled", || outcome(d, pause)), "applied");
    let first = wait_for("paused", || newest(d).filter(|c| c.mode == "paused"));
    let later = wait_for("5 paused cycles", || {
        newest(d).filter(|c| c.cycle >= first.cycle + 5)
    });
    assert_eq!(later.mode, "paused");
    assert_eq!(slope(&later), slope(&first), "held while paused");
    let noted: i64 = db(d)
        .query_row(
            "SELECT COUNT(*) FROM live_cycles WHERE note LIKE ?1",
            [format!("%pause by operator (command {pause}): applied%")],
            |r| r.get(0),
        )
        .unwrap();
    assert_eq!(noted, 1);
    let state: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(d.join("state.json")).unwrap()).unwrap();
    assert_eq!(state["mode"], "paused");
    assert_eq!(state["axes"][0]["held"], true);

    // Resume, and an acknowledgement of an alarm that does not exist.
    let resume = command(d, "resume", None);
    assert_eq!(wait_for("resume handled", || outcome(d, resume)), "applied");
    wait_for("running again", || {
        newest(d).filter(|c| c.mode == "running")
    });
    let bogus = command(d, "ack", Some(99));
    assert_eq!(
        wait_for("ack handled", || outcome(d, bogus)),
        "unknown alarm 99"
    );

    // The logger stops: hold, then ramp to zero with alarm 1, at zero and latched.
    on.store(false, Ordering::SeqCst);
    wait_for("holding", || newest(d).filter(|c| c.mode == "holding"));
    let ramp = wait_for("ramping", || {
        newest(d).filter(|c| c.mode == "ramping_to_zero")
    });
    assert!(
        ramp.note
            .as_deref()
            .unwrap_or("")
            .contains("alarm 1 raised")
            || {
                let n: i64 = db(d)
            .query_row("SELECT COUNT(*) FROM live_cycles WHERE note LIKE '%alarm 1 raised: log silent%'", [], |r| r.get(0))
            .unwrap();
                n == 1
            }
    );
    wait_for("at zero", || {
        newest(d).filter(|c| slope(c) == 0.0 && c.mode == "ramping_to_zero")
    });
    // The data comes back: still at zero until the alarm is acknowledged.
    on.store(true, Ordering::SeqCst);
    let back = wait_for("source healthy", || {
        let s: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(d.join("state.json")).ok()?).ok()?;
        (s["sources"][0]["healthy"] == true).then_some(s)
    });
    assert_eq!(back["mode"], "ramping_to_zero");
    assert_eq!(back["alarms"][0]["id"], 1);
    let ack = command(d, "ack", Some(1));
    assert_eq!(wait_for("ack 1 handled", || outcome(d, ack)), "applied");
    let again = wait_for("running after the ack", || {
        newest(d).filter(|c| c.mode == "running")
    });
    assert!(slope(&again) < -20.0);

    // SIGTERM with on_stop = ramp_to_zero: the last cycle is at zero and says why.
    let kill = std::process::Command::new("kill")
        .args(["-TERM", &child.id().to_string()])
        .status()
        .unwrap();
    assert!(kill.success());
    let status = child.wait().unwrap();
    quit.store(true, Ordering::SeqCst);
    log.join().unwrap();
    assert!(status.success(), "exit {status:?}");
    let all = cycles(&d.join("live.sqlite"));
    let last = all.last().unwrap();
    assert_eq!(last.mode, "stopped");
    assert_eq!(slope(last), 0.0);
    assert!(
        last.note
            .as_deref()
            .unwrap()
            .contains("stopped by SIGTERM: targets at zero"),
        "{:?}",
        last.note
    );
    let began = all
        .iter()
        .rposition(|c| {
            c.note
                .as_deref()
                .is_some_and(|n| n.contains("stopped by SIGTERM: targets ramping to zero"))
        })
        .unwrap();
    // The ramp after the signal moved at most 20 µm/s · 0.1 s per cycle at the travel end.
    for w in all[began..].windows(2) {
        let ch = (slope(&w[1]) - slope(&w[0])).abs() * 0.5;
        assert!(ch <= 2.0 + 1e-9, "{ch}");
    }
    for w in all.windows(2) {
        assert_eq!(w[1].cycle, w[0].cycle + 1, "every cycle logged");
    }
}

#[test]
fn sigint_holds_the_last_values() {
    let (dir, warm) = setup("hold");
    let d = dir.path();
    let on = Arc::new(AtomicBool::new(true));
    let quit = Arc::new(AtomicBool::new(false));
    let log = logger(&d.join("log.csv"), warm, on.clone(), quit.clone());
    let mut child = std::process::Command::new(ERRMAP)
        .args(["live", "live.toml", "--dry-run"])
        .current_dir(d)
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    wait_for("running", || newest(d).filter(|c| c.mode == "running"));
    std::process::Command::new("kill")
        .args(["-INT", &child.id().to_string()])
        .status()
        .unwrap();
    let status = child.wait().unwrap();
    quit.store(true, Ordering::SeqCst);
    log.join().unwrap();
    assert!(status.success());
    let all = cycles(&d.join("live.sqlite"));
    let (last, before) = (&all[all.len() - 1], &all[all.len() - 2]);
    assert_eq!(last.mode, "stopped");
    assert_eq!(
        last.note.as_deref(),
        Some("stopped by SIGINT: targets held at their last values")
    );
    assert!(last.x("written_slope_um_per_m").unwrap() < -20.0);
    assert_eq!(
        last.x("written_slope_um_per_m").unwrap(),
        before.x("written_slope_um_per_m").unwrap()
    );
}
