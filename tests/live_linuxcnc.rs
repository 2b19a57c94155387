//! `errmap live` against the real LinuxCNC (Debian's linuxcnc-uspace), headless: a simulated
//! three-axis mill (trivkins, LinuxCNC's basic_sim HAL) with external offsets on X
//! (`[AXIS_X] OFFSET_AV_RATIO = 0.2`), whose display is a small Python program driving it
//! through LinuxCNC's own `linuxcnc` module (tests/live_support/linuxcnc_display.py: machine on,
//! home, MDI moves, machine off/on). errmap reads X's position and velocity from HAL pins (a
//! `linuxcnc` source), temperatures from a CSV file, and writes X's compensation as an external
//! offset (a `linuxcnc` target). The offset LinuxCNC applies (`axis.x.eoffset`, read with
//! `halcmd`) must equal the compensation computed here by hand from the model file
//! (−tanβ·(x − Px), tanβ = Σ k·(ΔT − rise) + ρ·ΔT_env, tests/live_support) within half a count
//! (0.05 µm): standing at 250 mm with no direction seen yet (the mean of both directions), then
//! at 400 mm after a forward move; after a machine off/on (which zeroes LinuxCNC's offsets)
//! errmap ramps back from zero with an alarm; SIGTERM with `on_stop = "ramp_to_zero"` leaves
//! the offset at zero and errmap's HAL component gone. Skipped when LinuxCNC is missing unless
//! ERRMAP_REQUIRE_LINUXCNC=1. LinuxCNC's HAL is one per machine: this file has one test.

mod live_support;
use live_support::*;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::{Child, ChildStdin, Command, Stdio};
use std::time::{Duration, Instant};

/// The Python of a Debian LinuxCNC (its `hal` and `linuxcnc` modules are built for it).
const PYTHON: &str = "/usr/bin/python3";
/// µm per count written to `axis.x.eoffset-counts`.
const RESOLUTION_UM: f64 = 0.1;

/// Whether LinuxCNC can run here: `linuxcnc` and `halcmd` on the PATH and its Python modules.
fn linuxcnc_present() -> bool {
    let on_path = |p: &str| {
        Command::new("sh")
            .args(["-c", &format!("command -v {p}")])
            .output()
            .is_ok_and(|o| o.status.success())
    };
    on_path("linuxcnc")
        && on_path("halcmd")
        && Command::new(PYTHON)
            .args(["-c", "import hal, linuxcnc"])
            .output()
            .is_ok_and(|o| o.status.success())
}

/// The LinuxCNC process group (the `linuxcnc` script, its servers and the display); dropped,
/// it ends the display's input (LinuxCNC shuts down in order), then kills what is left of its
/// group and unloads HAL with LinuxCNC's own `halrun -U` if HAL is still up.
struct LinuxCnc {
    child: Child,
    stdin: Option<ChildStdin>,
    dir: PathBuf,
    sent: usize,
}

impl LinuxCnc {
    fn start(dir: &Path) -> LinuxCnc {
        use std::os::unix::process::CommandExt;
        let log = std::fs::File::create(dir.join("linuxcnc.out")).unwrap();
        let mut cmd = Command::new("linuxcnc");
        cmd.arg(dir.join("mill.ini"))
            .current_dir(dir)
            .env_remove("DISPLAY")
            .stdin(Stdio::piped())
            .stdout(log.try_clone().unwrap())
            .stderr(log)
            .process_group(0);
        if is_root() {
            // LinuxCNC's rtapi_app refuses to run as root without a user to drop to.
            let fifo = dir.join("rtapi");
            std::fs::create_dir_all(&fifo).unwrap();
            std::fs::set_permissions(&fifo, std::os::unix::fs::PermissionsExt::from_mode(0o777))
                .unwrap();
            cmd.env("RTAPI_UID", "65534")
                .env("RTAPI_FIFO_PATH", fifo.join(".rtapi_fifo"));
        }
        let mut child = cmd.spawn().unwrap();
        let stdin = child.stdin.take();
        LinuxCnc {
            child,
            stdin,
            dir: dir.to_path_buf(),
            sent: 0,
        }
    }

    fn display_log(&self) -> String {
        std::fs::read_to_string(self.dir.join("display.log")).unwrap_or_default()
    }

    /// Send the display a command and wait until it is done.
    fn command(&mut self, line: &str) {
        let stdin = self.stdin.as_mut().unwrap();
        writeln!(stdin, "{line}").unwrap();
        stdin.flush().unwrap();
        self.sent += 1;
        let want = format!("done {line}");
        wait_for(&format!("LinuxCNC to do '{line}'"), || {
            let log = self.display_log();
            assert!(
                !log.contains(&format!("failed {line}")),
                "the display: {log}"
            );
            (log.matches(&want).count() >= 1).then_some(())
        });
    }
}

impl Drop for LinuxCnc {
    fn drop(&mut self) {
        drop(self.stdin.take());
        let until = Instant::now() + Duration::from_secs(20);
        while Instant::now() < until && matches!(self.child.try_wait(), Ok(None)) {
            std::thread::sleep(Duration::from_millis(50));
        }
        if matches!(self.child.try_wait(), Ok(None)) {
            let group = format!("-{}", self.child.id());
            let _ = Command::new("kill").args(["-TERM", "--", &group]).status();
            std::thread::sleep(Duration::from_secs(2));
            let _ = Command::new("kill").args(["-KILL", "--", &group]).status();
            let _ = self.child.wait();
        }
        if hal_up() {
            let _ = Command::new("halrun")
                .arg("-U")
                .env("RTAPI_FIFO_PATH", self.dir.join("rtapi/.rtapi_fifo"))
                .env("RTAPI_UID", "65534")
                .stdout(Stdio::null())
                .stderr(Stdio::null())
                .status();
        }
    }
}

/// errmap live, killed by its id if the test fails before it stops.
struct Live(Child);

impl Drop for Live {
    fn drop(&mut self) {
        if matches!(self.0.try_wait(), Ok(None)) {
            let _ = self.0.kill();
            let _ = self.0.wait();
        }
    }
}

fn is_root() -> bool {
    Command::new("id")
        .arg("-u")
        .output()
        .is_ok_and(|o| String::from_utf8_lossy(&o.stdout).trim() == "0")
}

/// Whether a HAL session is up: a component other than the asking halcmd itself (the test
/// LinuxCNC's own shutdown script uses).
fn hal_up() -> bool {
    Command::new("halcmd")
        .args(["-s", "list", "comp"])
        .stderr(Stdio::null())
        .output()
        .is_ok_and(|o| {
            String::from_utf8_lossy(&o.stdout)
                .split_whitespace()
                .count()
                > 1
        })
}

fn halcmd(args: &[&str]) -> String {
    let o = Command::new("halcmd")
        .arg("-s")
        .args(args)
        .output()
        .unwrap();
    assert!(
        o.status.success(),
        "halcmd {args:?}: {}",
        String::from_utf8_lossy(&o.stderr)
    );
    String::from_utf8_lossy(&o.stdout).trim().to_string()
}

/// A HAL pin's value as a number.
fn getp(pin: &str) -> f64 {
    let v = halcmd(&["getp", pin]);
    v.parse()
        .unwrap_or_else(|_| panic!("{pin} = '{v}' is not a number"))
}

const INI: &str = r#"[EMC]
VERSION = 1.1
MACHINE = errmap live test mill
DEBUG = 0

[DISPLAY]
DISPLAY = DISPLAY_PROGRAM

[TASK]
TASK = milltask
CYCLE_TIME = 0.010

[RS274NGC]
PARAMETER_FILE = sim.var

[EMCMOT]
EMCMOT = motmod
COMM_TIMEOUT = 1.0
SERVO_PERIOD = 1000000

[EMCIO]
EMCIO = io
CYCLE_TIME = 0.100
TOOL_TABLE = tool.tbl

[HAL]
HALFILE = LIB:basic_sim.tcl -no_use_hal_manualtoolchange

[TRAJ]
COORDINATES = XYZ
LINEAR_UNITS = mm
ANGULAR_UNITS = degree
MAX_LINEAR_VELOCITY = 100

[KINS]
JOINTS = 3
KINEMATICS = trivkins coordinates=XYZ

[AXIS_X]
OFFSET_AV_RATIO = 0.2
MAX_VELOCITY = 100
MAX_ACCELERATION = 1000
MIN_LIMIT = -10
MAX_LIMIT = 510

[JOINT_0]
TYPE = LINEAR
HOME_SEQUENCE = 0
MAX_VELOCITY = 100
MAX_ACCELERATION = 1000
MIN_LIMIT = -10
MAX_LIMIT = 510

[AXIS_Y]
MAX_VELOCITY = 100
MAX_ACCELERATION = 1000
MIN_LIMIT = -10
MAX_LIMIT = 510

[JOINT_1]
TYPE = LINEAR
HOME_SEQUENCE = 0
MAX_VELOCITY = 100
MAX_ACCELERATION = 1000
MIN_LIMIT = -10
MAX_LIMIT = 510

[AXIS_Z]
MAX_VELOCITY = 100
MAX_ACCELERATION = 1000
MIN_LIMIT = -300
MAX_LIMIT = 10

[JOINT_2]
TYPE = LINEAR
HOME_SEQUENCE = 0
MAX_VELOCITY = 100
MAX_ACCELERATION = 1000
MIN_LIMIT = -300
MAX_LIMIT = 10
"#;

const LIVE: &str = r#"[loop]
period_ms = 50
on_stop = "ramp_to_zero"
stop_ramp_s = 20

[store]
path = "live.sqlite"

[[sources]]
name = "log"
kind = "csv"
path = "log.csv"
follow = true
timeout_ms = 600000
ramp_timeout_ms = 1200000

[[sources]]
name = "hal"
kind = "linuxcnc"
python = "/usr/bin/python3"
period_ms = 50
timeout_ms = 1000
ramp_timeout_ms = 10000
channels = [
  { name = "x", pin = "axis.x.pos-cmd" },
  { name = "xvel", pin = "joint.0.vel-cmd" },
]

[sensors.nut]
channel = "log.nut"
filter = "none"
[sensors.bearing]
channel = "log.bearing"
filter = "none"
[sensors.room]
channel = "log.ambient_c"
filter = "none"

[coolant]
channel = "log.coolant"

[[axes]]
name = "X"
model = "model.json"
position = "hal.x"
direction = "hal.xvel"
direction_deadband = 0.001
limit_um = 60
slope_limit_um_per_m = 120
rate_limit_um_s = 100
target = "mill"

[[targets]]
name = "mill"
kind = "linuxcnc"
python = "/usr/bin/python3"
[targets.axes.X]
resolution_um = 0.1
"#;

/// `axis.x.eoffset` (what LinuxCNC applies) in µm once it has settled within half a count of
/// `want_um`; the last value seen when it does not within the wait.
fn settled_offset_um(want_um: f64) -> f64 {
    let until = Instant::now() + Duration::from_secs(20);
    loop {
        let now = getp("axis.x.eoffset") * 1000.0;
        if (now - want_um).abs() <= RESOLUTION_UM / 2.0 + 1e-6 || Instant::now() > until {
            return now;
        }
        std::thread::sleep(Duration::from_millis(50));
    }
}

#[test]
fn external_offsets_on_a_running_linuxcnc() {
    if !linuxcnc_present() {
        assert!(
            std::env::var("ERRMAP_REQUIRE_LINUXCNC").as_deref() != Ok("1"),
            "LinuxCNC (linuxcnc, halcmd and Python's hal and linuxcnc modules in {PYTHON}) is missing and ERRMAP_REQUIRE_LINUXCNC=1: install linuxcnc-uspace"
        );
        eprintln!("skipped: LinuxCNC is not installed (Debian: apt-get install linuxcnc-uspace)");
        return;
    }
    assert!(
        !hal_up(),
        "a HAL session is running already (another LinuxCNC): this test needs the machine's HAL to itself"
    );
    let dir = scratch();
    let d = dir.path();
    let model = Model::read(&d.join("model.json"));

    // A warm machine: campaign 1's raw readings two hours in, held constant in the log.
    let rows = synth_replay(d, &["--hours", "4", "--period-s", "1", "--campaign", "1"]);
    let header: Vec<&str> = rows[0].split(',').collect();
    let row: Vec<&str> = rows[7201].split(',').collect();
    let field = |name: &str| row[header.iter().position(|h| *h == name).unwrap()];
    std::fs::write(d.join("log.csv"), format!("{}\n{}\n", rows[0], rows[7201])).unwrap();
    let coolant = field("coolant").to_string();
    let temps = {
        let nut = model.celsius("nut", field("nut").parse().unwrap());
        let bearing = model.celsius("bearing", field("bearing").parse().unwrap());
        let room = model.celsius("room", field("ambient_c").parse().unwrap());
        move |n: &str| match n {
            "nut" => nut,
            "bearing" => bearing,
            _ => room,
        }
    };
    // The compensation at x: −tanβ·(x − Px)/1000 µm, of a direction or the mean of both.
    let comp_um = |direction: Option<usize>, x: f64| {
        let tan_beta = match direction {
            Some(d) => model.tan_beta(d, &temps, &coolant),
            None => {
                0.5 * (model.tan_beta(0, &temps, &coolant) + model.tan_beta(1, &temps, &coolant))
            }
        };
        -tan_beta * (x - model.px()) / 1000.0
    };

    // LinuxCNC, headless.
    let display =
        std::fs::read_to_string(repo().join("tests/live_support/linuxcnc_display.py")).unwrap();
    let display_path = d.join("display.py");
    std::fs::write(&display_path, format!("#!{PYTHON}\n{display}")).unwrap();
    std::fs::set_permissions(
        &display_path,
        std::os::unix::fs::PermissionsExt::from_mode(0o755),
    )
    .unwrap();
    std::fs::write(
        d.join("mill.ini"),
        INI.replace("DISPLAY_PROGRAM", display_path.to_str().unwrap()),
    )
    .unwrap();
    std::fs::write(d.join("tool.tbl"), "").unwrap();
    let mut cnc = LinuxCnc::start(d);
    wait_for("LinuxCNC on and homed", || {
        if let Ok(Some(status)) = cnc.child.try_wait() {
            panic!(
                "linuxcnc exited ({status}): {}",
                std::fs::read_to_string(d.join("linuxcnc.out")).unwrap_or_default()
            );
        }
        cnc.display_log().contains("ready").then_some(())
    });
    cnc.command("mdi G0 X250");
    assert_eq!(getp("axis.x.eoffset"), 0.0);

    std::fs::write(d.join("live.toml"), LIVE).unwrap();
    let mut live = Live(
        Command::new(ERRMAP)
            .args(["live", "live.toml", "--state", "state.json"])
            .current_dir(d)
            .stderr(Stdio::piped())
            .spawn()
            .unwrap(),
    );

    // Standing at 250 mm, no direction seen yet: the mean of both directions' models.
    let want = comp_um(None, 250.0);
    assert!(want.abs() > 5.0, "a warm axis: {want} µm");
    wait_for("running", || {
        if let Ok(Some(status)) = live.0.try_wait() {
            let mut err = String::new();
            use std::io::Read;
            live.0
                .stderr
                .take()
                .unwrap()
                .read_to_string(&mut err)
                .unwrap();
            panic!("errmap live exited ({status}): {err}");
        }
        newest(d).filter(|c| c.mode == "running")
    });
    let got = settled_offset_um(want);
    assert!(
        (got - want).abs() <= RESOLUTION_UM / 2.0 + 1e-6,
        "axis.x.eoffset {got} µm, the model {want} µm; errmap's last cycle: {:?}",
        newest(d)
    );
    let request = getp("axis.x.eoffset-request") * 1000.0;
    assert!(
        (request - want).abs() <= RESOLUTION_UM / 2.0 + 1e-6,
        "{request}"
    );
    // errmap's pins drive LinuxCNC's: scale in mm per count, enabled.
    assert_eq!(getp("axis.x.eoffset-scale"), RESOLUTION_UM / 1000.0);
    assert_eq!(halcmd(&["getp", "axis.x.eoffset-enable"]), "TRUE");

    // A forward move to 400 mm: the offset follows the position with the forward model.
    cnc.command("mdi G0 X400");
    let want = comp_um(Some(0), 400.0);
    wait_for("the forward model at 400 mm", || {
        newest(d).filter(|c| {
            c.inputs["X.direction"] == "+"
                && (c.inputs["X.position_mm"].as_f64().unwrap() - 400.0).abs() < 0.01
                && c.mode == "running"
        })
    });
    let got = settled_offset_um(want);
    assert!(
        (got - want).abs() <= RESOLUTION_UM / 2.0 + 1e-6,
        "axis.x.eoffset {got} µm at 400 mm forward, the model {want} µm"
    );
    // (The offset moved the axis: LinuxCNC's joint position carries it.)
    assert!((getp("joint.0.pos-fb") - (400.0 + got / 1000.0)).abs() < 1e-6);

    // Machine off and on: LinuxCNC zeroes its offsets; errmap notices and ramps back from 0.
    cnc.command("off");
    cnc.command("on");
    wait_for("errmap to notice the zeroed offset", || {
        noted(d, "ramping from its value").then_some(())
    });
    let got = settled_offset_um(want);
    assert!(
        (got - want).abs() <= RESOLUTION_UM / 2.0 + 1e-6,
        "after machine off/on: axis.x.eoffset {got} µm, the model {want} µm"
    );

    // SIGTERM with on_stop = "ramp_to_zero": the offset goes to zero, errmap's component goes.
    let pid = live.0.id().to_string();
    assert!(Command::new("kill")
        .args(["-TERM", &pid])
        .status()
        .unwrap()
        .success());
    let status = wait_for("errmap live to stop", || live.0.try_wait().unwrap());
    assert!(status.success(), "{status}");
    assert!(getp("axis.x.eoffset-request").abs() * 1000.0 <= RESOLUTION_UM / 2.0 + 1e-6);
    assert!(settled_offset_um(0.0).abs() <= RESOLUTION_UM / 2.0 + 1e-6);
    let comps = halcmd(&["list", "comp"]);
    assert!(!comps.contains("errmap"), "{comps}");
    drop(cnc);
    assert!(!hal_up(), "HAL still up after LinuxCNC's shutdown");
}
