//! A CSV source reading standard input (`path = "-"`): a machine log piped into
//! `errmap live --dry-run`, replayed by its `time_s` as fast as the loop computes, gives one
//! logged cycle per row whose E(x, T) equals `errmap thermal compensate` over the same rows
//! (to compensate's 4 decimals), in both coolant states. The sensors are unfiltered
//! (`filter = "none"`), as compensate does not smooth a log.

mod live_support;
use live_support::*;
use std::io::Write;

#[test]
fn csv_from_stdin_matches_thermal_compensate() {
    let dir = scratch();
    let d = dir.path();
    // 2 h of a row every 10 s, the coolant switching every 10 minutes.
    let rows = two_hours_coolant_switching(d);
    let log = rows.join("\n") + "\n";
    std::fs::write(d.join("log.csv"), &log).unwrap();
    let text = config(
        "period_ms = 10000\nreplay_speed = 0",
        "timeout_ms = 15000\nramp_timeout_ms = 60000",
        "limit_um = 60\nslope_limit_um_per_m = 120\nrate_limit_um_s = 1.0",
        "min_c = 5\nmax_c = 60\nfilter = \"none\"",
    )
    .replace("path = \"log.csv\"", "path = \"-\"");
    assert!(text.contains("path = \"-\""));
    std::fs::write(d.join("live.toml"), text).unwrap();

    let mut live = std::process::Command::new(ERRMAP)
        .args(["live", "live.toml", "--dry-run"])
        .current_dir(d)
        .stdin(std::process::Stdio::piped())
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let mut stdin = live.stdin.take().unwrap();
    // Written from a thread, so a full pipe never stalls the test; closing it ends the replay.
    let feeder = std::thread::spawn(move || {
        stdin.write_all(log.as_bytes()).unwrap();
    });
    let o = live.wait_with_output().unwrap();
    feeder.join().unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));

    let o = run(
        &[
            "thermal",
            "compensate",
            "--model",
            "model.json",
            "log.csv",
            "-o",
            "out.csv",
        ],
        d,
    );
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let out = std::fs::read_to_string(d.join("out.csv")).unwrap();
    let expected: Vec<(f64, f64)> = out
        .lines()
        .skip(1)
        .map(|line| {
            let f: Vec<&str> = line.split(',').collect();
            (f[0].parse().unwrap(), f[3].parse().unwrap())
        })
        .collect();

    let cycles = cycles(&d.join("live.sqlite"));
    assert_eq!(cycles.len(), rows.len() - 1, "one cycle per row");
    assert_eq!(cycles.len(), expected.len());
    let mut coolant_states = std::collections::BTreeSet::new();
    for (c, (t, e)) in cycles.iter().zip(&expected) {
        assert_eq!(c.time_s(), *t, "cycle {}", c.cycle);
        let live_e = c.x("error_um").unwrap();
        assert!(
            (live_e - e).abs() <= 0.6e-4,
            "t {t}: compensate {e}, live {live_e}"
        );
        coolant_states.insert(c.inputs["coolant"].as_str().unwrap().to_string());
    }
    assert_eq!(coolant_states.len(), 2, "both coolant states replayed");
    assert_eq!(
        cycles.last().unwrap().note.as_deref(),
        Some("end of the replay data: targets held at their last values")
    );
}
