//! `errmap live` against real Modbus TCP servers (Python `pymodbus`, tests/live_support/
//! modbus_server.py): a temperature module (input registers of each data type and word order,
//! a coil for the coolant, a discrete input for the direction, a holding register for the
//! position) and a PLC gateway taking the compensation in a holding register. The written
//! register must equal the model's value for the served readings (independent evaluation,
//! tests/live_support); the start ramps from the gateway's present value; an open RTD holds;
//! a gateway that goes away is retried, reported and written again once back; a module that
//! goes silent ramps the register to zero. Skipped without pymodbus unless
//! ERRMAP_REQUIRE_MODBUS=1.

mod live_support;
use live_support::*;
use serde_json::json;

fn set(s: &mut PyServer, fc: u8, address: u16, values: Vec<serde_json::Value>) {
    assert_eq!(
        s.ask(&json!({"op": "set", "fc": fc, "address": address, "values": values})),
        "ok"
    );
}

/// The gateway's register 20–21: s32, low word first, 0.01 µm per count.
fn written_um(gw: &mut PyServer) -> f64 {
    let words: Vec<u32> =
        serde_json::from_str(&gw.ask(&json!({"op": "get", "fc": 3, "address": 20, "count": 2})))
            .unwrap();
    ((words[1] << 16 | words[0]) as i32) as f64 * 0.01
}

struct Served {
    nut_counts: u16,
    bearing: f32,
    room_counts: i16,
    x_counts: i32,
    forward: bool,
}

fn serve(m: &mut PyServer, v: &Served) {
    let bits = v.bearing.to_bits();
    set(m, 4, 0, vec![json!(v.nut_counts)]);
    set(m, 4, 2, vec![json!(bits & 0xFFFF), json!(bits >> 16)]);
    set(m, 4, 4, vec![json!(v.room_counts as u16)]);
    set(m, 1, 0, vec![json!(false)]);
    set(m, 2, 0, vec![json!(v.forward)]);
    let x = v.x_counts as u32;
    set(m, 3, 10, vec![json!(x >> 16), json!(x & 0xFFFF)]);
}

/// The model's compensation (thermal part, µm) for what is served.
fn expected_um(model: &Model, v: &Served) -> f64 {
    let nut = model.celsius("nut", v.nut_counts as f64 * 0.01);
    let bearing = model.celsius("bearing", v.bearing as f64);
    let room = model.celsius("room", 0.1 * v.room_counts as f64 + 20.0);
    let temps = |n: &str| match n {
        "nut" => nut,
        "bearing" => bearing,
        _ => room,
    };
    let x = v.x_counts as f64 * 0.001;
    let d = if v.forward { 0 } else { 1 };
    -model.tan_beta(d, &temps, "off") * (x - model.px()) / 1000.0
}

#[test]
fn modbus_module_to_modbus_gateway() {
    let Some(python) = venv_python("pymodbus", "MODBUS") else {
        return;
    };
    let dir = scratch();
    let d = dir.path();
    let model = Model::read(&d.join("model.json"));
    // A warm machine (campaign 1, coolant off, two hours in): raw readings of t = 7200 s.
    let rows = synth_replay(d, &["--hours", "4", "--period-s", "1", "--campaign", "1"]);
    let f: Vec<f64> = rows[7201]
        .split(',')
        .take(6)
        .skip(3)
        .map(|v| v.parse().unwrap())
        .collect();
    let mut served = Served {
        nut_counts: (f[0] * 100.0).round() as u16,
        bearing: f[1] as f32,
        room_counts: ((f[2] - 20.0) * 10.0).round() as i16,
        x_counts: 250_000,
        forward: true,
    };
    let mut module = PyServer::start(&python, "modbus_server.py", &[]);
    let mut gateway = PyServer::start(&python, "modbus_server.py", &[]);
    serve(&mut module, &served);
    // The gateway holds 5.00 µm: the start ramps from there.
    set(&mut gateway, 3, 20, vec![json!(500), json!(0)]);
    let text = format!(
        r#"[loop]
period_ms = 100
on_stop = "hold"
write_retries = 2

[store]
path = "live.sqlite"

[[sources]]
name = "module"
kind = "modbus"
address = "127.0.0.1:{m}"
unit_id = 1
period_ms = 100
timeout_ms = 1000
ramp_timeout_ms = 2500
channels = [
  {{ name = "nut", table = "input", register = 0, type = "u16", scale = 0.01 }},
  {{ name = "bearing", table = "input", register = 2, type = "f32", word_order = "little" }},
  {{ name = "room", table = "input", register = 4, type = "s16", scale = 0.1, offset = 20.0 }},
  {{ name = "coolant", table = "coil", register = 0 }},
  {{ name = "dir", table = "discrete", register = 0 }},
  {{ name = "x", table = "holding", register = 10, type = "s32", scale = 0.001 }},
]

[sensors.nut]
channel = "module.nut"
filter = "none"
[sensors.bearing]
channel = "module.bearing"
filter = "none"
[sensors.room]
channel = "module.room"
filter = "none"

[coolant]
channel = "module.coolant"

[[axes]]
name = "X"
model = "model.json"
position = "module.x"
direction = "module.dir"
limit_um = 60
slope_limit_um_per_m = 120
rate_limit_um_s = 5
target = "plc"

[[targets]]
name = "plc"
kind = "modbus-registers"
address = "127.0.0.1:{g}"
unit_id = 1
[targets.axes.X]
register = 20
type = "s32"
word_order = "little"
scale = 0.01
"#,
        m = module.port,
        g = gateway.port
    );
    std::fs::write(d.join("live.toml"), text).unwrap();
    let mut live = std::process::Command::new(ERRMAP)
        .args(["live", "live.toml", "--state", "state.json"])
        .current_dir(d)
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();

    // The first cycle moves from the gateway's 5.00 µm by at most 5 µm/s · 0.1 s.
    let first = wait_for("the first cycle", || newest(d));
    let c0 = cycles(&d.join("live.sqlite")).remove(0);
    assert_eq!(c0.mode, "starting", "{:?} {:?}", c0.note, c0.inputs);
    assert!(
        (c0.x("written_um").unwrap() - 5.0).abs() <= 0.5 + 1e-9,
        "{:?}",
        c0.outputs
    );
    drop(first);

    // Running: the register holds the model's value for the served readings.
    let want = expected_um(&model, &served);
    assert!(want < -10.0, "a warm axis: {want}");
    wait_for("running", || newest(d).filter(|c| c.mode == "running"));
    let got = written_um(&mut gateway);
    assert!(
        (got - want).abs() <= 0.005 + 1e-9,
        "register {got} µm, model {want} µm"
    );
    let c = newest(d).unwrap();
    assert_eq!(
        c.inputs["raw"]["nut"].as_f64().unwrap(),
        served.nut_counts as f64 * 0.01
    );
    assert_eq!(
        c.inputs["raw"]["bearing"].as_f64().unwrap(),
        served.bearing as f64
    );
    assert_eq!(
        c.inputs["raw"]["room"].as_f64().unwrap(),
        0.1 * served.room_counts as f64 + 20.0
    );
    assert_eq!(c.inputs["coolant"], "off");
    assert_eq!(c.inputs["X.position_mm"].as_f64().unwrap(), 250.0);

    // The axis moves to 400 mm in reverse: the register follows (the reverse model).
    served.x_counts = 400_000;
    served.forward = false;
    serve(&mut module, &served);
    let want = expected_um(&model, &served);
    wait_for("the reverse value at 400 mm", || {
        ((written_um(&mut gateway) - want).abs() <= 0.005 + 1e-9).then_some(())
    });

    // An open RTD: held, alarmed, the register unchanged.
    let before = written_um(&mut gateway);
    set(&mut module, 4, 0, vec![json!(65535)]);
    wait_for("holding on the open RTD", || {
        newest(d).filter(|c| c.mode == "holding")
    });
    assert!(noted(d, "nut open RTD"));
    served.x_counts = 100_000; // a move while held changes nothing either
    set(
        &mut module,
        3,
        10,
        vec![
            json!(served.x_counts as u32 >> 16),
            json!(served.x_counts as u32 & 0xFFFF),
        ],
    );
    let held = wait_for("a held cycle at 100 mm", || {
        newest(d)
            .filter(|c| c.inputs["X.position_mm"].as_f64() == Some(100.0) && c.mode == "holding")
    });
    // The held line, at the new position: the thermal state is held, the axis is where it is.
    let slope = held.x("written_slope_um_per_m").unwrap();
    assert!(
        (slope * 0.4 - before).abs() <= 0.005 + 1e-9,
        "{slope} µm/m, {before} µm at 400 mm"
    );
    wait_for("the held line at 100 mm in the register", || {
        ((written_um(&mut gateway) - slope * 0.1).abs() <= 0.005 + 1e-9).then_some(())
    });
    serve(&mut module, &served);
    wait_for("running again", || {
        newest(d).filter(|c| c.mode == "running")
    });

    // The gateway goes away: writes are retried and reported; back on its port, written again.
    let port = gateway.port;
    gateway.stop();
    served.x_counts = 300_000;
    serve(&mut module, &served);
    wait_for("a failed write reported", || {
        noted(d, "write to plc failed after 3 tries").then_some(())
    });
    let mut gateway = PyServer::start_on(&python, "modbus_server.py", &[], port);
    let want = expected_um(&model, &served);
    served.x_counts = 300_001; // a new value to write
    serve(&mut module, &served);
    let want2 = expected_um(&model, &served);
    wait_for("written again", || {
        let g = written_um(&mut gateway);
        ((g - want2).abs() <= 0.005 + 1e-9 || (g - want).abs() <= 0.005 + 1e-9).then_some(())
    });

    // The module goes silent: hold, then the register ramps to zero.
    module.stop();
    wait_for("holding", || newest(d).filter(|c| c.mode == "holding"));
    wait_for("ramping", || {
        newest(d).filter(|c| c.mode == "ramping_to_zero")
    });
    assert!(noted(d, "module silent past its ramp timeout"));
    wait_for("zero in the register", || {
        (written_um(&mut gateway) == 0.0).then_some(())
    });
    let all = cycles(&d.join("live.sqlite"));
    for w in all.windows(2) {
        let (a, b) = (w[0].x("written_um"), w[1].x("written_um"));
        if let (Some(a), Some(b)) = (a, b) {
            // The position jumps with the module's moves; the rate limit acts on the line.
            let line = |c: &Cycle| {
                c.x("written_offset_um").unwrap() + c.x("written_slope_um_per_m").unwrap() * 0.5
            };
            let ch = (line(&w[1]) - line(&w[0])).abs();
            assert!(
                ch <= 0.5 + 1e-9,
                "cycle {}: {ch} µm in 0.1 s ({a} → {b})",
                w[1].cycle
            );
        }
    }

    std::process::Command::new("kill")
        .args(["-TERM", &live.id().to_string()])
        .status()
        .unwrap();
    assert!(live.wait().unwrap().success());
    let last = cycles(&d.join("live.sqlite")).pop().unwrap();
    assert_eq!(last.mode, "stopped");
}
