//! The state file the real `errmap live` writes is the one `errmap serve` reads: the sample
//! live config's replay run through in `--dry-run`, its last state file parsed by the monitor's
//! own reader, and each axis's values equal to the cycle the loop logged in the store.

use std::path::Path;
use std::process::Command;

const ERRMAP: &str = env!("CARGO_BIN_EXE_errmap");

/// The sample live config, model and replay in a scratch folder, its store beside them.
fn sample_live(dir: &Path) {
    let sample = Path::new(env!("CARGO_MANIFEST_DIR")).join("data/thermal-live");
    for file in ["model.json", "replay.csv"] {
        std::fs::copy(sample.join(file), dir.join(file)).unwrap();
    }
    let config = std::fs::read_to_string(sample.join("live.toml")).unwrap();
    let store_line = config
        .lines()
        .find(|l| l.trim_start().starts_with("path = \"../../out/"))
        .expect("the sample config names its store under out/");
    let speed_line = config
        .lines()
        .find(|l| l.trim_start().starts_with("replay_speed"))
        .expect("the sample config replays its log");
    // The store beside the copy; the replay as fast as it computes.
    let config = config
        .replace(store_line, "path = \"live.sqlite\"")
        .replace(speed_line, "replay_speed = 0");
    std::fs::write(dir.join("live.toml"), config).unwrap();
}

#[test]
fn the_monitor_reads_the_state_file_the_live_loop_writes() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    sample_live(d);
    let state_path = d.join("state.json");
    let out = Command::new(ERRMAP)
        .args(["live", "live.toml", "--dry-run", "--state"])
        .arg(&state_path)
        .current_dir(d)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );

    let text = std::fs::read_to_string(&state_path).unwrap();
    let state = errmap::serve::live::parse_state(&text)
        .unwrap_or_else(|e| panic!("the monitor refuses the live loop's state file: {e}\n{text}"));
    assert!(state.dry_run);
    assert!(state.cycle >= 1);
    assert!(!state.axes.is_empty() && !state.sensors.is_empty() && !state.sources.is_empty());

    // Each axis as the monitor shows it is the cycle the loop logged.
    let conn = rusqlite::Connection::open(d.join("live.sqlite")).unwrap();
    let outputs: String = conn
        .query_row(
            "SELECT outputs_json FROM live_cycles WHERE cycle = ?1",
            [state.cycle as i64],
            |row| row.get(0),
        )
        .unwrap();
    let outputs: serde_json::Value = serde_json::from_str(&outputs).unwrap();
    let state_json: serde_json::Value = serde_json::from_str(&text).unwrap();
    for axis in state_json["axes"].as_array().unwrap() {
        let name = axis["axis"].as_str().unwrap();
        let logged = &outputs[name];
        assert!(
            logged.is_object(),
            "axis {name} not in the logged cycle: {outputs}"
        );
        for key in ["computed_um", "written_um"] {
            let shown = axis[key].as_f64();
            let stored = logged[key].as_f64();
            assert!(
                shown.is_some() && shown == stored,
                "{name}.{key}: state file {shown:?}, store {stored:?}"
            );
        }
    }
}
