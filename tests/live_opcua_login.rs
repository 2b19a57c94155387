//! `errmap live` logging in to a real OPC UA server (Python `asyncua`, tests/live_support/
//! opcua_server.py with its user manager taking one user name and password) and writing a
//! generic node (`kind = "opcua-nodes"`): with the right password the node takes the axis's
//! compensation at its position, equal to −E(x, T) of the model file evaluated in the test
//! (tests/live_support, from docs/thermal.md) for the served readings within 0.01 µm, for both
//! directions; with a wrong password errmap refuses at start (exit 2, naming the target or
//! source and its `user`/`password` keys) and writes nothing. Skipped without asyncua unless
//! ERRMAP_REQUIRE_OPCUA=1.

mod live_support;
use live_support::*;
use serde_json::json;

const USER: &str = "errmap";
const PASSWORD: &str = "s3cret-K3";

fn logins(s: &mut PyServer) -> (u64, u64) {
    let v: serde_json::Value = serde_json::from_str(&s.ask(&json!({"op": "logins"}))).unwrap();
    (
        v["accepted"].as_u64().unwrap(),
        v["refused"].as_u64().unwrap(),
    )
}

/// A config reading temperatures, coolant, position and direction from the server as `source_pw`
/// and writing X's compensation (µm, geometric part included) to `Comp[X]` as `target_pw`.
fn login_config(port: u16, source_pw: &str, target_pw: &str) -> String {
    format!(
        r#"[loop]
period_ms = 100
on_stop = "hold"

[store]
path = "live.sqlite"

{tables}
[[axes]]
name = "X"
model = "model.json"
position = "nc.x"
direction = "nc.dir"
limit_um = 200
slope_limit_um_per_m = 200
rate_limit_um_s = 100
include_geometric = true
target = "plc"

[[targets]]
name = "plc"
kind = "opcua-nodes"
endpoint = "opc.tcp://127.0.0.1:{port}/"
security_policy = "None"
user = "{USER}"
password = "{target_pw}"
[targets.axes.X]
node = "ns=2;s=Comp[X]"
unit = "um"
"#,
        tables = ua_source_tables(
            port,
            &format!("user = \"{USER}\"\npassword = \"{source_pw}\""),
            2000,
            5000
        ),
    )
}

/// The server with the one login, serving row 7201 of a synthetic campaign (warm, coolant on)
/// with X at 250 mm going forward; returns it and the served (nut Ω, bearing °C, room °C).
fn serve(python: &std::path::Path, d: &std::path::Path) -> (PyServer, (f64, f64, f64)) {
    let (nut, bearing, room) = warm_readings(d);
    let mut ua = PyServer::start(python, "opcua_server.py", &[USER, PASSWORD]);
    ua_set(&mut ua, "T.nut", json!(nut));
    ua_set(&mut ua, "T.bearing", json!(bearing));
    ua_set(&mut ua, "T.room", json!(room));
    ua_set(&mut ua, "Coolant", json!(true));
    ua_set(&mut ua, "X.position", json!(250.0));
    ua_set(&mut ua, "X.direction", json!(1));
    (ua, (nut, bearing, room))
}

#[test]
fn login_and_generic_node_writes() {
    let Some(python) = venv_python("asyncua", "OPCUA") else {
        return;
    };
    let dir = scratch();
    let d = dir.path();
    let model = Model::read(&d.join("model.json"));
    let (mut ua, (nut_ohm, bearing_c, room_c)) = serve(&python, d);
    std::fs::write(
        d.join("live.toml"),
        login_config(ua.port, PASSWORD, PASSWORD),
    )
    .unwrap();
    let mut live = std::process::Command::new(ERRMAP)
        .args(["live", "live.toml"])
        .current_dir(d)
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();

    let temps = |s: &str| match s {
        "nut" => model.celsius("nut", nut_ohm),
        "bearing" => model.celsius("bearing", bearing_c),
        _ => model.celsius("room", room_c),
    };
    // The compensation at x is −E(x, T) (µm), geometric part included.
    let want = |d: usize, x: f64| -model.error_um(d, x, &temps, "on");

    let forward = want(0, 250.0);
    assert!(forward.abs() > 1.0, "a warm axis: {forward} µm");
    wait_for("the forward value at 250 mm", || {
        ((ua_get(&mut ua, "Comp[X]") - forward).abs() <= 0.01).then_some(())
    });
    wait_for("running", || newest(d).filter(|c| c.mode == "running"));
    let v = ua_get(&mut ua, "Comp[X]");
    assert!(
        (v - forward).abs() <= 0.01,
        "Comp[X] {v} µm, model {forward} µm"
    );

    // Reversing at 400 mm: the reverse model's value there.
    ua_set(&mut ua, "X.position", json!(400.0));
    ua_set(&mut ua, "X.direction", json!(-1));
    let reverse = want(1, 400.0);
    assert!(
        (reverse - want(0, 400.0)).abs() > 0.05,
        "the directions differ"
    );
    wait_for("the reverse value at 400 mm", || {
        ((ua_get(&mut ua, "Comp[X]") - reverse).abs() <= 0.01).then_some(())
    });
    wait_for("running", || {
        newest(d).filter(|c| c.mode == "running" && c.inputs["X.position_mm"] == 400.0)
    });
    let v = ua_get(&mut ua, "Comp[X]");
    assert!(
        (v - reverse).abs() <= 0.01,
        "Comp[X] {v} µm, model {reverse} µm"
    );

    let (accepted, refused) = logins(&mut ua);
    assert!(accepted >= 2, "source and target logged in: {accepted}");
    assert_eq!(refused, 0);

    std::process::Command::new("kill")
        .args(["-TERM", &live.id().to_string()])
        .status()
        .unwrap();
    assert!(live.wait().unwrap().success());
}

#[test]
fn wrong_password_is_refused_before_anything_is_written() {
    let Some(python) = venv_python("asyncua", "OPCUA") else {
        return;
    };
    let dir = scratch();
    let d = dir.path();
    let (mut ua, _) = serve(&python, d);
    // What the controller holds now; errmap must not touch it.
    ua_set(&mut ua, "Comp[X]", json!(7.5));

    // The target's password is wrong.
    std::fs::write(
        d.join("live.toml"),
        login_config(ua.port, PASSWORD, "wrong"),
    )
    .unwrap();
    let o = run(&["live", "live.toml"], d);
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{err}");
    for needle in [
        "target 'plc'",
        "targets[0].user",
        "`user`",
        "`password`",
        "refused",
    ] {
        assert!(err.contains(needle), "'{needle}' not in: {err}");
    }
    assert!(err.contains("live.toml:"), "the config's line: {err}");
    assert_eq!(ua_get(&mut ua, "Comp[X]"), 7.5, "nothing written");
    assert!(
        !d.join("live.sqlite").exists() || cycles(&d.join("live.sqlite")).is_empty(),
        "no cycle ran"
    );
    let (_, refused) = logins(&mut ua);
    assert!(refused >= 1, "the server refused the login: {refused}");

    // The source's password is wrong (a dry run contacts no target).
    std::fs::write(
        d.join("live.toml"),
        login_config(ua.port, "wrong", PASSWORD),
    )
    .unwrap();
    let o = run(&["live", "live.toml", "--dry-run"], d);
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{err}");
    for needle in ["source 'nc'", "sources[0].user", "`user`", "`password`"] {
        assert!(err.contains(needle), "'{needle}' not in: {err}");
    }
    assert!(
        !d.join("live.sqlite").exists() || cycles(&d.join("live.sqlite")).is_empty(),
        "no cycle ran"
    );
    assert_eq!(ua_get(&mut ua, "Comp[X]"), 7.5, "nothing written");
}
