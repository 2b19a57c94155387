//! `errmap live --dry-run` replaying CSV machine logs (the clock driven by their `time_s`, as
//! fast as the loop computes): every logged value against an independent evaluation of the
//! model (tests/live_support), the logged period recomputed by `errmap thermal compensate`, and
//! the safety rules (watchdog, plausibility, bounds, rate limit) acting on crafted logs.

mod live_support;
use live_support::*;
use std::path::Path;

const LOOP_10S: &str = "period_ms = 10000\nreplay_speed = 0";
const SOURCE_10S: &str = "timeout_ms = 15000\nramp_timeout_ms = 60000";
const AXIS: &str = "limit_um = 60\nslope_limit_um_per_m = 120\nrate_limit_um_s = 1.0";
const SENSOR: &str = "min_c = 5\nmax_c = 60";

fn live_dry(dir: &Path) -> std::process::Output {
    let o = run(
        &["live", "live.toml", "--dry-run", "--state", "state.json"],
        dir,
    );
    assert!(
        o.status.success(),
        "errmap live failed: {}",
        String::from_utf8_lossy(&o.stderr)
    );
    o
}

/// The sample replay, replayed: every cycle logged, each value the model's.
#[test]
fn sample_replay_matches_an_independent_evaluation() {
    let dir = scratch();
    let d = dir.path();
    std::fs::copy(
        repo().join("data/thermal-live/replay.csv"),
        d.join("log.csv"),
    )
    .unwrap();
    std::fs::write(
        d.join("live.toml"),
        config(LOOP_10S, SOURCE_10S, AXIS, SENSOR),
    )
    .unwrap();
    live_dry(d);

    let model = Model::read(&d.join("model.json"));
    let log = std::fs::read_to_string(d.join("log.csv")).unwrap();
    let mut lines = log.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let col = |n: &str| header.iter().position(|h| *h == n).unwrap();
    let mut filters: Vec<(String, Causal)> = ["nut", "bearing", "room"]
        .iter()
        .map(|n| (n.to_string(), Causal::new(model.filter(n))))
        .collect();
    let cycles = cycles(&d.join("live.sqlite"));
    let rows: Vec<&str> = lines.collect();
    assert_eq!(cycles.len(), rows.len(), "one cycle per row, none missed");
    for (i, (row, c)) in rows.iter().zip(&cycles).enumerate() {
        assert_eq!(c.cycle, i as i64);
        let f: Vec<&str> = row.split(',').collect();
        let t: f64 = f[col("time_s")].parse().unwrap();
        assert_eq!(c.time_s(), t);
        let mut temps = std::collections::HashMap::new();
        for (name, filter) in &mut filters {
            let column = if name == "room" {
                "ambient_c"
            } else {
                name.as_str()
            };
            let raw: f64 = f[col(column)].parse().unwrap();
            temps.insert(name.clone(), filter.push(model.celsius(name, raw)));
        }
        let x: f64 = f[col("position_mm")].parse().unwrap();
        let d_ix = if f[col("direction")] == "+" { 0 } else { 1 };
        let coolant = f[col("coolant")];
        let get = |n: &str| temps[n];
        let e = model.error_um(d_ix, x, &get, coolant);
        let tb = model.tan_beta(d_ix, &get, coolant);
        let close = |a: f64, b: f64, what: &str| {
            assert!((a - b).abs() < 1e-9, "cycle {i} (t {t}): {what} {a} vs {b}");
        };
        for name in ["nut", "bearing", "room"] {
            close(c.inputs[name].as_f64().unwrap(), temps[name], name);
        }
        close(c.x("error_um").unwrap(), e, "error_um");
        close(c.x("tan_beta_um_per_m").unwrap(), tb, "tanβ");
        // The axis carries the thermal part only (Er(x) is in the controller's pitch table).
        close(
            c.x("computed_um").unwrap(),
            -tb * (x - model.px()) / 1000.0,
            "computed_um",
        );
        // 1 µm/s over a 10 s cycle covers every change of this log: written = computed.
        close(
            c.x("written_um").unwrap(),
            c.x("computed_um").unwrap(),
            "written_um",
        );
        let want = if i + 1 == rows.len() {
            "stopped"
        } else {
            "running"
        };
        assert_eq!(c.mode, want, "cycle {i}");
    }
    let last = cycles.last().unwrap();
    assert_eq!(
        last.note.as_deref(),
        Some("end of the replay data: targets held at their last values")
    );
    // The state file of the last cycle.
    let state: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(d.join("state.json")).unwrap()).unwrap();
    assert_eq!(state["schema"], "errmap-live-state/1");
    assert_eq!(state["mode"], "stopped");
    assert_eq!(state["dry_run"], true);
    assert_eq!(state["coolant_on"], true);
    assert_eq!(state["cycle"], rows.len() as u64 - 1);
    assert_eq!(state["axes"][0]["target"], "dry-run");
    assert_eq!(state["sources"][0]["healthy"], true);
    let written = state["written_utc"].as_str().unwrap();
    assert!(written.ends_with('Z') && written.len() == 24, "{written}");
}

/// The temperatures, positions, directions and coolant states a run logged, written back as a
/// machine log (raw readings by the inverse of the calibration and IEC 60751), and compensated
/// by `errmap thermal compensate`: the same E as the loop logged.
#[test]
fn logged_period_recomputes_with_thermal_compensate() {
    let dir = scratch();
    let d = dir.path();
    // Coolant switching every 10 minutes: both gain tables are used.
    let rows = two_hours_coolant_switching(d);
    std::fs::write(d.join("log.csv"), rows.join("\n") + "\n").unwrap();
    std::fs::write(
        d.join("live.toml"),
        config(LOOP_10S, SOURCE_10S, AXIS, SENSOR),
    )
    .unwrap();
    live_dry(d);

    let model = Model::read(&d.join("model.json"));
    let db = d.join("live.sqlite");
    let conn = rusqlite::Connection::open(&db).unwrap();
    let campaign: String = conn
        .query_row(
            "SELECT name FROM campaigns WHERE source = 'errmap live'",
            [],
            |r| r.get(0),
        )
        .unwrap();
    assert!(campaign.starts_with("live-20"), "{campaign}");
    let mut stmt = conn
        .prepare(
            "SELECT s.name, t.time_s, t.temperature_c FROM temperature_samples t
             JOIN sensors s ON s.id = t.sensor_id JOIN campaigns c ON c.id = t.campaign_id
             WHERE c.name = ?1",
        )
        .unwrap();
    let mut samples = std::collections::HashMap::new();
    for r in stmt
        .query_map([&campaign], |r| {
            Ok((
                r.get::<_, String>(0)?,
                r.get::<_, f64>(1)?,
                r.get::<_, f64>(2)?,
            ))
        })
        .unwrap()
    {
        let (name, t, v) = r.unwrap();
        samples.insert((name, t.to_bits()), v);
    }
    let cycles = cycles(&db);
    assert_eq!(samples.len(), 3 * cycles.len(), "three sensors every cycle");
    let mut log = String::from("time_s,position_mm,direction,nut,bearing,ambient_c,coolant\n");
    for c in &cycles {
        let t = c.time_s();
        let temp = |n: &str| samples[&(n.to_string(), t.to_bits())];
        log.push_str(&format!(
            "{t},{},{},{},{},{},{}\n",
            c.inputs["X.position_mm"].as_f64().unwrap(),
            c.inputs["X.direction"].as_str().unwrap(),
            model.raw("nut", temp("nut")),
            model.raw("bearing", temp("bearing")),
            model.raw("room", temp("room")),
            c.inputs["coolant"].as_str().unwrap(),
        ));
    }
    std::fs::write(d.join("recompute.csv"), log).unwrap();
    let o = run(
        &[
            "thermal",
            "compensate",
            "--model",
            "model.json",
            "recompute.csv",
            "-o",
            "out.csv",
        ],
        d,
    );
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let out = std::fs::read_to_string(d.join("out.csv")).unwrap();
    let mut n = 0;
    let mut coolant_states = std::collections::BTreeSet::new();
    for (line, c) in out.lines().skip(1).zip(&cycles) {
        let f: Vec<&str> = line.split(',').collect();
        let e: f64 = f[3].parse().unwrap();
        let live = c.x("error_um").unwrap();
        // compensate writes 4 decimals.
        assert!(
            (e - live).abs() <= 0.6e-4,
            "t {}: compensate {e}, live {live}",
            c.time_s()
        );
        coolant_states.insert(c.inputs["coolant"].as_str().unwrap().to_string());
        n += 1;
    }
    assert_eq!(n, cycles.len());
    assert_eq!(coolant_states.len(), 2, "both coolant states replayed");
}

/// The rows of campaign 1 (coolant off, the machine warm after 2 h) between two times.
fn warm_rows(d: &Path, from_s: f64, to_s: f64) -> (String, Vec<Vec<String>>) {
    let rows = synth_replay(d, &["--hours", "4", "--period-s", "1", "--campaign", "1"]);
    let header = rows[0].clone();
    let body = rows[1..]
        .iter()
        .map(|r| r.split(',').map(str::to_string).collect::<Vec<_>>())
        .filter(|f| {
            let t: f64 = f[0].parse().unwrap();
            t >= from_s && t <= to_s
        })
        .collect();
    (header, body)
}

fn write_rows(d: &Path, header: &str, rows: &[Vec<String>]) {
    let mut s = format!("{header}\n");
    for r in rows {
        s.push_str(&r.join(","));
        s.push('\n');
    }
    std::fs::write(d.join("log.csv"), s).unwrap();
}

const LOOP_1S: &str = "period_ms = 1000\nreplay_speed = 0";
const SOURCE_1S: &str = "timeout_ms = 3000\nramp_timeout_ms = 10000";
const AXIS_FAST: &str = "limit_um = 60\nslope_limit_um_per_m = 120\nrate_limit_um_s = 2.0";

/// |change| of the written line at the far end of the travel (500 mm from Px = 0) between
/// consecutive cycles.
fn end_changes(cycles: &[Cycle]) -> Vec<f64> {
    cycles
        .windows(2)
        .map(|w| {
            let at = |c: &Cycle| {
                c.x("written_offset_um").unwrap() + c.x("written_slope_um_per_m").unwrap() * 0.5
            };
            (at(&w[1]) - at(&w[0])).abs()
        })
        .collect()
}

fn at(cycles: &[Cycle], t: f64) -> &Cycle {
    cycles
        .iter()
        .find(|c| c.time_s() == t)
        .unwrap_or_else(|| panic!("no cycle at {t}"))
}

/// A source silent past its timeout holds the values; past its ramp timeout every axis ramps
/// to zero at the rate limit with an alarm, and stays there after the data returns (the alarm
/// is not acknowledged).
#[test]
fn watchdog_holds_then_ramps_to_zero() {
    let dir = scratch();
    let d = dir.path();
    let (header, rows) = warm_rows(d, 7200.0, 7400.0);
    let kept: Vec<Vec<String>> = rows
        .into_iter()
        .filter(|f| {
            let t: f64 = f[0].parse().unwrap();
            t <= 7260.0 || t >= 7330.0
        })
        .collect();
    write_rows(d, &header, &kept);
    std::fs::write(
        d.join("live.toml"),
        config(LOOP_1S, SOURCE_1S, AXIS_FAST, SENSOR),
    )
    .unwrap();
    live_dry(d);
    let cycles = cycles(&d.join("live.sqlite"));
    assert_eq!(
        cycles.len(),
        201,
        "a cycle every second from 7200 to 7400 s"
    );
    // The start ramps from zero (a dry run's present value) at 2 µm/s.
    assert_eq!(cycles[0].mode, "starting");
    for ch in end_changes(&cycles) {
        assert!(ch <= 2.0 + 1e-9, "the written value moved {ch} µm in 1 s");
    }
    let slope = |t: f64| at(&cycles, t).x("written_slope_um_per_m").unwrap();
    assert!(slope(7250.0) < -30.0, "warm: {}", slope(7250.0));
    assert_eq!(at(&cycles, 7255.0).mode, "running");
    assert_eq!(
        at(&cycles, 7263.0).mode,
        "running",
        "3 s silent is within the timeout"
    );
    for t in 7264..=7270 {
        let c = at(&cycles, t as f64);
        assert_eq!(c.mode, "holding", "t {t}");
        assert_eq!(slope(t as f64), slope(7263.0), "held at t {t}");
    }
    let c = at(&cycles, 7271.0);
    assert_eq!(c.mode, "ramping_to_zero");
    let note = c.note.as_deref().unwrap();
    assert!(
        note.contains("alarm 1 raised") && note.contains("log silent past its ramp timeout"),
        "{note}"
    );
    // Zero after |slope|·0.5 m / 2 µm/s, and zero from then on, data back or not.
    let zero_from = 7271.0 + (slope(7270.0).abs() * 0.5 / 2.0).ceil() - 1.0;
    for c in cycles.iter().filter(|c| c.time_s() >= zero_from) {
        assert_eq!(
            c.x("written_slope_um_per_m").unwrap(),
            0.0,
            "t {}",
            c.time_s()
        );
        if c.time_s() < 7400.0 {
            assert_eq!(c.mode, "ramping_to_zero", "t {}", c.time_s());
        }
    }
    assert!(
        at(&cycles, zero_from - 1.0)
            .x("written_slope_um_per_m")
            .unwrap()
            != 0.0
    );
    let state: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(d.join("state.json")).unwrap()).unwrap();
    assert_eq!(state["alarms"][0]["id"], 1);
    assert_eq!(state["alarms"][0]["acknowledged"], false);
}

/// An open RTD, a jump faster than the sensor's rate of change, and a reading out of range
/// each hold the values with an alarm; the out-of-range reading kept past the ramp timeout
/// ramps to zero.
#[test]
fn implausible_readings_hold_and_alarm() {
    let dir = scratch();
    let d = dir.path();
    let (header, mut rows) = warm_rows(d, 7200.0, 7300.0);
    let h: Vec<&str> = header.split(',').collect();
    let col = |n: &str| h.iter().position(|x| *x == n).unwrap();
    for r in &mut rows {
        let t: f64 = r[0].parse().unwrap();
        if t == 7250.0 {
            r[col("nut")] = "2000.0".into(); // beyond the Pt100 range: an open sensor
        }
        if t == 7260.0 {
            let b: f64 = r[col("bearing")].parse().unwrap();
            r[col("bearing")] = format!("{:.4}", b + 5.0);
        }
        if t >= 7270.0 {
            r[col("ambient_c")] = "80.0".into();
        }
    }
    write_rows(d, &header, &rows);
    let sensor = "min_c = 5\nmax_c = 45";
    std::fs::write(
        d.join("live.toml"),
        config(LOOP_1S, SOURCE_1S, AXIS_FAST, sensor),
    )
    .unwrap();
    live_dry(d);
    let cycles = cycles(&d.join("live.sqlite"));
    let mode = |t: f64| at(&cycles, t).mode.clone();
    let note = |t: f64| at(&cycles, t).note.clone().unwrap_or_default();
    assert_eq!(mode(7249.0), "running");
    assert_eq!(mode(7250.0), "holding");
    assert!(note(7250.0).contains("nut open RTD"), "{}", note(7250.0));
    assert_eq!(
        mode(7251.0),
        "running",
        "the next good reading releases the hold"
    );
    assert_eq!(mode(7260.0), "holding");
    assert!(
        note(7260.0).contains("bearing changed 4.9"),
        "{}",
        note(7260.0)
    );
    assert_eq!(mode(7261.0), "running");
    assert!(note(7270.0).contains("room reading 80"), "{}", note(7270.0));
    assert_eq!(mode(7280.0), "holding");
    assert_eq!(
        mode(7281.0),
        "ramping_to_zero",
        "implausible for longer than the ramp timeout"
    );
    let held = at(&cycles, 7270.0).x("written_slope_um_per_m").unwrap();
    assert_eq!(
        at(&cycles, 7280.0).x("written_slope_um_per_m").unwrap(),
        held
    );
    // The implausible value never reaches the model: the held cycles log the last good room.
    assert!(at(&cycles, 7275.0).inputs["room"].as_f64().unwrap() < 45.0);
}

/// A model asking for more than the axis's bound is held (here at the dry run's zero) with an
/// alarm naming the excess.
#[test]
fn beyond_the_bound_holds_with_an_alarm() {
    let dir = scratch();
    let d = dir.path();
    let (header, rows) = warm_rows(d, 7200.0, 7210.0);
    write_rows(d, &header, &rows);
    let axis = "limit_um = 5\nslope_limit_um_per_m = 120\nrate_limit_um_s = 2.0";
    std::fs::write(
        d.join("live.toml"),
        config(LOOP_1S, SOURCE_1S, axis, SENSOR),
    )
    .unwrap();
    live_dry(d);
    let cycles = cycles(&d.join("live.sqlite"));
    assert_eq!(cycles[0].mode, "holding");
    let note = cycles[0].note.as_deref().unwrap();
    assert!(
        note.contains("alarm 1 raised: X compensation") && note.contains("beyond ±5 µm"),
        "{note}"
    );
    for c in &cycles {
        assert_eq!(c.x("written_slope_um_per_m").unwrap(), 0.0);
        assert!(c.x("tan_beta_um_per_m").unwrap().abs() > 10.0);
    }
}

/// A slow rate limit: the start ramps at exactly the limit until it reaches the model.
#[test]
fn start_ramps_at_the_rate_limit() {
    let dir = scratch();
    let d = dir.path();
    let (header, rows) = warm_rows(d, 7200.0, 7300.0);
    write_rows(d, &header, &rows);
    let axis = "limit_um = 60\nslope_limit_um_per_m = 120\nrate_limit_um_s = 0.5";
    std::fs::write(
        d.join("live.toml"),
        config(LOOP_1S, SOURCE_1S, axis, SENSOR),
    )
    .unwrap();
    live_dry(d);
    let cycles = cycles(&d.join("live.sqlite"));
    let changes = end_changes(&cycles);
    // Cycle 0 moves from zero by 0.5 µm; later cycles by exactly 0.5 µm while starting.
    let first = cycles[0].x("written_slope_um_per_m").unwrap() * 0.5;
    assert!((first.abs() - 0.5).abs() < 1e-9, "{first}");
    let starting = cycles.iter().take_while(|c| c.mode == "starting").count();
    assert!(starting > 20, "{starting} starting cycles");
    for ch in &changes[..starting - 1] {
        assert!((ch - 0.5).abs() < 1e-9, "{ch}");
    }
    assert_eq!(cycles[starting].mode, "running");
    assert_eq!(
        cycles[starting].x("written_um").unwrap(),
        cycles[starting].x("computed_um").unwrap()
    );
}

/// Exit 2 for a bad config (key and line named) or model, exit 3 for a source that cannot be
/// reached at start.
#[test]
fn exit_codes_for_bad_config_model_and_unreachable_source() {
    let dir = scratch();
    let d = dir.path();
    let (header, rows) = warm_rows(d, 7200.0, 7205.0);
    write_rows(d, &header, &rows);
    let good = config(LOOP_1S, SOURCE_1S, AXIS_FAST, SENSOR);
    let check = |text: &str, code: i32, needles: &[&str]| {
        std::fs::write(d.join("live.toml"), text).unwrap();
        let o = run(&["live", "live.toml", "--dry-run"], d);
        let err = String::from_utf8_lossy(&o.stderr).to_string();
        assert_eq!(o.status.code(), Some(code), "{err}");
        for n in needles {
            assert!(err.contains(n), "{n:?} not in {err}");
        }
    };
    let typo = good.replace(
        "rate_limit_um_s = 2.0",
        "rate_limit_um_s = 2.0\nrate_limt = 3",
    );
    let line = typo
        .lines()
        .position(|l| l.starts_with("rate_limt"))
        .unwrap()
        + 1;
    check(&typo, 2, &[&format!("live.toml:{line}"), "rate_limt"]);
    let neg = good.replace("rate_limit_um_s = 2.0", "rate_limit_um_s = -2.0");
    let line = neg
        .lines()
        .position(|l| l.starts_with("rate_limit_um_s"))
        .unwrap()
        + 1;
    check(
        &neg,
        2,
        &[&format!("live.toml:{line}"), "axes[0].rate_limit_um_s"],
    );
    let chan = good.replace("\"log.nut\"", "\"log.nutt\"");
    let line = chan.lines().position(|l| l.contains("log.nutt")).unwrap() + 1;
    check(
        &chan,
        2,
        &[&format!("live.toml:{line}"), "no channel 'nutt'"],
    );
    check(
        &good.replace(
            "[sensors.bearing]\nchannel = \"log.bearing\"\nmin_c = 5\nmax_c = 60",
            "",
        ),
        2,
        &["needs sensor 'bearing'"],
    );
    check(
        &good.replace("model.json", "missing.json"),
        2,
        &["missing.json"],
    );
    std::fs::write(d.join("broken.json"), "{\"format\": 1}").unwrap();
    check(
        &good.replace("model.json", "broken.json"),
        2,
        &["broken.json", "not a thermal model"],
    );
    check(
        &good.replace("path = \"log.csv\"", "path = \"absent.csv\""),
        3,
        &["absent.csv"],
    );
    assert!(!d.join("live.sqlite").exists() || cycles(&d.join("live.sqlite")).is_empty());
}

/// `--once` on the wall clock: one cycle from the newest readings, written at once (no start
/// ramp, however slow the rate limit), and it says so.
#[test]
fn once_writes_one_cycle_without_the_start_ramp() {
    let dir = scratch();
    let d = dir.path();
    let (header, rows) = warm_rows(d, 7200.0, 7205.0);
    write_rows(d, &header, &rows);
    let axis = "limit_um = 60\nslope_limit_um_per_m = 120\nrate_limit_um_s = 0.001";
    std::fs::write(
        d.join("live.toml"),
        config("period_ms = 100", SOURCE_1S, axis, SENSOR),
    )
    .unwrap();
    let o = run(&["live", "live.toml", "--dry-run", "--once"], d);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{err}");
    assert!(
        err.contains("--once: one cycle, written without the start ramp"),
        "{err}"
    );
    let cycles = cycles(&d.join("live.sqlite"));
    assert_eq!(cycles.len(), 1);
    let c = &cycles[0];
    assert!(c.x("computed_um").unwrap().abs() > 1.0);
    assert_eq!(c.x("written_um").unwrap(), c.x("computed_um").unwrap());
    // The newest row of the file is the one used.
    assert_eq!(c.inputs["time_s"].as_f64().unwrap(), 0.0);
    let last: Vec<&str> = rows.last().unwrap().iter().map(String::as_str).collect();
    assert_eq!(
        c.inputs["X.position_mm"].as_f64().unwrap(),
        last[1].parse::<f64>().unwrap()
    );
}

/// A live run's temperature log in a store of laser campaigns leaves `thermal fit
/// --from-store` fitting the laser campaigns only.
#[test]
fn a_live_log_in_the_store_leaves_fit_from_store_working() {
    let dir = scratch();
    let d = dir.path();
    let campaigns: Vec<String> = (1..=4)
        .map(|i| {
            let name = format!(
                "campaign-{i}-coolant-{}",
                if i % 2 == 1 { "off" } else { "on" }
            );
            repo()
                .join("data/thermal")
                .join(name)
                .to_string_lossy()
                .into_owned()
        })
        .collect();
    let mut args = vec!["thermal", "ingest", "--db", "live.sqlite"];
    args.extend(campaigns.iter().map(String::as_str));
    let o = run(&args, d);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let (header, rows) = warm_rows(d, 7200.0, 7210.0);
    write_rows(d, &header, &rows);
    std::fs::write(
        d.join("live.toml"),
        config(LOOP_1S, SOURCE_1S, AXIS_FAST, SENSOR),
    )
    .unwrap();
    live_dry(d);
    let o = run(
        &[
            "thermal",
            "fit",
            "--from-store",
            "--db",
            "live.sqlite",
            "-o",
            "refit.json",
            "--json",
        ],
        d,
    );
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let fit: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let names: Vec<&str> = fit["model"]["campaigns"]
        .as_array()
        .or(fit["campaigns"].as_array())
        .unwrap()
        .iter()
        .map(|c| c["name"].as_str().unwrap())
        .collect();
    assert_eq!(names.len(), 4, "{names:?}");
    assert!(names.iter().all(|n| n.starts_with("campaign-")));
}
