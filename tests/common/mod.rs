//! Shared helper of the integration tests: runs the real `errmap` binary in a folder and, when a run is not what a test expected, prints the command, its output and the folder listing.
// Each test binary compiles this module and uses only part of it.
#![allow(dead_code)]

use std::path::{Path, PathBuf};
use std::process::Command;

/// One finished run of the binary, output decoded lossily as UTF-8. Failures panic at the
/// caller's line (`#[track_caller]`).
pub struct Run {
    /// The command line as a user would type it, for failure messages.
    pub cmd: String,
    /// The folder it ran in.
    pub dir: PathBuf,
    /// Exit code; -1 when killed by a signal.
    pub code: i32,
    pub stdout: String,
    pub stderr: String,
}

/// A `Command` for the binary under test, for tests that need to drive the process themselves.
/// errmap's cache (the `auto` probe's figures) is private to the test process, so a user's
/// cached choice never steers a test.
pub fn command() -> Command {
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_errmap"));
    cmd.env(
        "ERRMAP_CACHE_DIR",
        std::env::temp_dir().join(format!("errmap-test-cache-{}", std::process::id())),
    );
    cmd
}

/// Run `errmap args…` in `dir` and wait for it.
pub fn errmap(dir: &Path, args: &[&str]) -> Run {
    errmap_with(dir, args, |_| {})
}

/// Run `errmap args…` in `dir` after `configure` has adjusted the command (environment, …).
pub fn errmap_with(dir: &Path, args: &[&str], configure: impl FnOnce(&mut Command)) -> Run {
    let mut cmd = command();
    cmd.args(args).current_dir(dir);
    configure(&mut cmd);
    let out = cmd
        .output()
        .unwrap_or_else(|e| panic!("cannot run the errmap binary: {e}"));
    Run {
        cmd: format!("errmap {}", args.join(" ")),
        dir: dir.to_path_buf(),
        code: out.status.code().unwrap_or(-1),
        stdout: String::from_utf8_lossy(&out.stdout).into_owned(),
        stderr: String::from_utf8_lossy(&out.stderr).into_owned(),
    }
}

/// Run and require exit 0.
#[track_caller]
pub fn ok(dir: &Path, args: &[&str]) -> Run {
    let run = errmap(dir, args);
    run.expect_code(0);
    run
}

impl Run {
    /// Panic with the command, its output and the folder listing unless it exited with `code`.
    #[track_caller]
    pub fn expect_code(&self, code: i32) -> &Self {
        if self.code != code {
            panic!("expected exit {code}\n{}", self.report());
        }
        self
    }

    /// Command, exit code, stdout, stderr and the folder listing, for a failure message.
    pub fn report(&self) -> String {
        format!(
            "$ {}\nexit {}\n--- stdout ---\n{}\n--- stderr ---\n{}\n--- folder {} ---\n{}",
            self.cmd,
            self.code,
            self.stdout,
            self.stderr,
            self.dir.display(),
            listing(&self.dir).join("\n")
        )
    }
}

/// Stdout parsed as exactly one JSON document.
#[track_caller]
pub fn json(run: &Run) -> serde_json::Value {
    match serde_json::from_str(&run.stdout) {
        Ok(doc) => doc,
        Err(e) => panic!("stdout is not one JSON document ({e})\n{}", run.report()),
    }
}

/// Every file (not folder) below `dir`, as full paths, sorted.
pub fn files(dir: &Path) -> Vec<PathBuf> {
    let mut files = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        let Ok(entries) = std::fs::read_dir(&d) else {
            continue;
        };
        for entry in entries.flatten() {
            let path = entry.path();
            if path.is_dir() {
                stack.push(path);
            } else {
                files.push(path);
            }
        }
    }
    files.sort();
    files
}

/// Every file and folder below `dir`, relative and sorted (folders end in `/`).
pub fn listing(dir: &Path) -> Vec<String> {
    fn walk(root: &Path, dir: &Path, out: &mut Vec<String>) {
        let Ok(entries) = std::fs::read_dir(dir) else {
            return;
        };
        for entry in entries.flatten() {
            let path = entry.path();
            let rel = path
                .strip_prefix(root)
                .unwrap_or(&path)
                .display()
                .to_string();
            if path.is_dir() {
                out.push(format!("{rel}/"));
                walk(root, &path, out);
            } else {
                out.push(rel);
            }
        }
    }
    let mut out = Vec::new();
    walk(dir, dir, &mut out);
    out.sort();
    out
}

/// A model.json whose network is all zeros: E = e_mean_um = 20 µm everywhere in x, y ∈ [0, 100]
/// mm, measured over that square, probed surface at z = −1 mm.
pub const FLAT_MODEL_20UM: &str = r#"{
  "format": "errmap-map-model/1",
  "name": "flat",
  "normal": "z",
  "domain": {"u_min_mm": 0.0, "v_min_mm": 0.0, "u_max_mm": 100.0, "v_max_mm": 100.0},
  "normalisation": {"u_min_mm": 0.0, "u_max_mm": 100.0, "v_min_mm": 0.0, "v_max_mm": 100.0,
                    "e_mean_um": 20.0, "e_std_um": 1.0},
  "network": {"layer_sizes": [2, 1], "activation": "tanh", "params": [0.0, 0.0, 0.0]},
  "hull_mm": [[0.0, 0.0], [100.0, 0.0], [100.0, 100.0], [0.0, 100.0]],
  "surface_mm": [-1.0, -1.0]
}"#;
