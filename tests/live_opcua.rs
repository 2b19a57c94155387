//! `errmap live` against a real OPC UA server (Python `asyncua`, tests/live_support/
//! opcua_server.py) serving Sinumerik-like nodes: temperatures, coolant, position and direction
//! in, the K3 setting data SD43900/SD43910/SD43920 out. The written values must equal the
//! model's for the served readings (independent evaluation, tests/live_support): SD43900 within
//! 0.01 µm, SD43910 within 1e-9, SD43920 exactly; the start ramps from the served present
//! values; the rate limit spreads a coolant switch over cycles; an open RTD holds; temperatures
//! going bad ramp SD43900/SD43910 to zero. Skipped without asyncua unless ERRMAP_REQUIRE_OPCUA=1.

mod live_support;
use live_support::*;
use serde_json::json;

#[test]
fn sinumerik_k3_setting_data_over_opcua() {
    let Some(python) = venv_python("asyncua", "OPCUA") else {
        return;
    };
    let dir = scratch();
    let d = dir.path();
    let model = Model::read(&d.join("model.json"));
    let (nut_ohm, bearing_c, room_c) = warm_readings(d);
    let mut ua = PyServer::start(&python, "opcua_server.py", &[]);
    ua_set(&mut ua, "T.nut", json!(nut_ohm));
    ua_set(&mut ua, "T.bearing", json!(bearing_c));
    ua_set(&mut ua, "T.room", json!(room_c));
    ua_set(&mut ua, "Coolant", json!(true));
    ua_set(&mut ua, "X.position", json!(250.0));
    ua_set(&mut ua, "X.direction", json!(1));
    // The control holds an error line of 2 µm at P0 = 0 (SD43900 = 0.002 mm).
    ua_set(&mut ua, "SD43900[X]", json!(0.002));
    let text = format!(
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
limit_um = 60
slope_limit_um_per_m = 120
rate_limit_um_s = 5
target = "k3"

[[targets]]
name = "k3"
kind = "sinumerik-opcua"
endpoint = "opc.tcp://127.0.0.1:{p}/"
security_policy = "None"
[targets.axes.X]
sd43900 = "ns=2;s=SD43900[X]"
sd43910 = "ns=2;s=SD43910[X]"
sd43920 = "ns=2;s=SD43920[X]"
"#,
        p = ua.port,
        tables = ua_source_tables(ua.port, "", 1000, 2500),
    );
    std::fs::write(d.join("live.toml"), text).unwrap();
    let mut live = std::process::Command::new(ERRMAP)
        .args(["live", "live.toml", "--state", "state.json"])
        .current_dir(d)
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();

    let tan_beta = |coolant: &str, nut: f64| {
        let (n, b, r) = (
            model.celsius("nut", nut),
            model.celsius("bearing", bearing_c),
            model.celsius("room", room_c),
        );
        model.tan_beta(
            0,
            &|s: &str| match s {
                "nut" => n,
                "bearing" => b,
                _ => r,
            },
            coolant,
        )
    };

    // The start: from the served line (compensation −2 µm about Px = 0) by at most
    // 5 µm/s · 0.1 s at the travel end.
    wait_for("the first cycle", || newest(d));
    let c0 = cycles(&d.join("live.sqlite")).remove(0);
    assert_eq!(c0.mode, "starting");
    let moved = (c0.x("written_offset_um").unwrap() + 2.0).abs()
        + c0.x("written_slope_um_per_m").unwrap().abs() * 0.5;
    assert!(moved <= 0.5 + 1e-9, "{:?}", c0.outputs);

    // Running: the setting data are the model's error line (K3 compensates the error curve).
    wait_for("running", || newest(d).filter(|c| c.mode == "running"));
    let want = tan_beta("on", nut_ohm);
    assert!(want > 10.0, "a warm axis: {want} µm/m");
    let (sd0, sd1, sd2) = (
        ua_get(&mut ua, "SD43900[X]"),
        ua_get(&mut ua, "SD43910[X]"),
        ua_get(&mut ua, "SD43920[X]"),
    );
    assert!(sd0.abs() <= 1e-5, "SD43900 {sd0} mm (0.01 µm = 1e-5 mm)");
    assert!(
        (sd1 - want * 1e-6).abs() <= 1e-9,
        "SD43910 {sd1}, model {}",
        want * 1e-6
    );
    assert_eq!(sd2, model.px(), "SD43920");

    // Coolant off: the other gains, reached through the rate limit (many cycles).
    let switched_at = newest(d).unwrap().cycle;
    ua_set(&mut ua, "Coolant", json!(false));
    let want_off = tan_beta("off", nut_ohm);
    wait_for("the coolant-off line", || {
        ((ua_get(&mut ua, "SD43910[X]") - want_off * 1e-6).abs() <= 1e-9).then_some(())
    });
    let all = cycles(&d.join("live.sqlite"));
    let ramp: Vec<&Cycle> = all
        .iter()
        .filter(|c| c.cycle > switched_at && c.inputs["coolant"] == "off")
        .take_while(|c| (c.x("written_slope_um_per_m").unwrap() + want_off).abs() > 1e-9)
        .collect();
    let jump_um = (want_off - want).abs() * 0.5;
    assert!(jump_um > 3.0, "{jump_um}");
    assert!(
        ramp.len() as f64 >= (jump_um / 0.5).floor() - 1.0,
        "{} cycles for {jump_um} µm",
        ramp.len()
    );
    for w in all.windows(2) {
        let ch = (w[1].x("written_slope_um_per_m").unwrap()
            - w[0].x("written_slope_um_per_m").unwrap())
        .abs()
            * 0.5
            + (w[1].x("written_offset_um").unwrap() - w[0].x("written_offset_um").unwrap()).abs();
        assert!(ch <= 0.5 + 1e-9, "cycle {}: {ch} µm", w[1].cycle);
    }

    // An open RTD (1000 Ω): held, alarmed, SD43910 unchanged.
    let before = ua_get(&mut ua, "SD43910[X]");
    ua_set(&mut ua, "T.nut", json!(1000.0));
    wait_for("holding", || newest(d).filter(|c| c.mode == "holding"));
    assert!(noted(d, "nut open RTD"));
    assert_eq!(ua_get(&mut ua, "SD43910[X]"), before);
    ua_set(&mut ua, "T.nut", json!(nut_ohm));
    wait_for("running again", || {
        newest(d).filter(|c| c.mode == "running")
    });

    // The temperatures go bad: hold, then SD43900 and SD43910 ramp to zero, alarmed.
    assert_eq!(ua.ask(&json!({"op": "bad", "node": "T.nut"})), "ok");
    wait_for("holding", || newest(d).filter(|c| c.mode == "holding"));
    wait_for("ramping", || {
        newest(d).filter(|c| c.mode == "ramping_to_zero")
    });
    assert!(noted(d, "nc silent past its ramp timeout"));
    wait_for("zero setting data", || {
        (ua_get(&mut ua, "SD43910[X]") == 0.0 && ua_get(&mut ua, "SD43900[X]") == 0.0).then_some(())
    });

    std::process::Command::new("kill")
        .args(["-TERM", &live.id().to_string()])
        .status()
        .unwrap();
    assert!(live.wait().unwrap().success());
}
