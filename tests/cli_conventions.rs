//! The command-line conventions, on the real binary: `-o/--output FILE`, `--out-dir DIR`,
//! `--json`, `-q`/`-v`, help in users' words, and the old spellings kept for one release with a
//! deprecation note.

mod common;

use common::{errmap, ok, Run};
use std::path::Path;

/// The note an old spelling prints (the exact sentence the docs quote).
fn note(old: &str, new: &str) -> String {
    format!("`{old}` is deprecated, use `{new}`; it will be removed in the next release")
}

/// Every command path (`["linear", "table"]`, …), read from the help's "Commands:" sections,
/// so a command added later is covered without editing this test.
fn command_paths(dir: &Path) -> Vec<Vec<String>> {
    let mut found = Vec::new();
    let mut todo = vec![Vec::<String>::new()];
    while let Some(path) = todo.pop() {
        let mut args: Vec<&str> = path.iter().map(String::as_str).collect();
        args.push("--help");
        let run = ok(dir, &args);
        let mut in_commands = false;
        for line in run.stdout.lines() {
            if line.starts_with("Commands:") {
                in_commands = true;
                continue;
            }
            if in_commands {
                if !line.starts_with("  ") || line.trim().is_empty() {
                    break;
                }
                // A command's row starts two spaces in; wrapped text is indented further.
                if line.starts_with("   ") {
                    continue;
                }
                let name = line.split_whitespace().next().unwrap().to_string();
                if name != "help" {
                    let mut sub = path.clone();
                    sub.push(name);
                    todo.push(sub);
                }
            }
        }
        if !path.is_empty() {
            found.push(path);
        }
    }
    found.sort();
    found
}

#[test]
fn every_command_has_help_that_exits_0_in_users_words() {
    let dir = tempfile::tempdir().unwrap();
    let paths = command_paths(dir.path());
    // The commands this release has, at least (new ones are picked up from the help).
    for expected in [
        "batch",
        "map",
        "merge",
        "grid",
        "compensate",
        "linear table",
        "thermal difference",
        "thermal evaluate",
        "rotary table",
        "circular",
        "synth web-plate",
        "k8s",
        "slurm",
        "bench training",
    ] {
        assert!(
            paths.iter().any(|p| p.join(" ") == expected),
            "{expected} missing from {paths:?}"
        );
    }
    // Words of errmap's insides a user never sees anywhere else.
    let forbidden = [
        "seed 000",
        "seed 001",
        "seed 002",
        "seed 003",
        "seed 004",
        "seed 005",
        "lane",
        "lanes",
        "kernel",
        "kernels",
        "wgsl",
        "shader",
        "shaders",
        "workgroup",
        "adam",
        "todo",
        "fixme",
        "issue",
    ];
    for path in &paths {
        let mut args: Vec<&str> = path.iter().map(String::as_str).collect();
        args.push("--help");
        let help = ok(dir.path(), &args).stdout.to_lowercase();
        let words: Vec<&str> = help
            .split(|c: char| !c.is_alphanumeric() && c != '-')
            .collect();
        for bad in forbidden {
            let hit = if bad.contains(' ') {
                help.contains(bad)
            } else {
                words.contains(&bad)
            };
            assert!(
                !hit,
                "`errmap {}` mentions '{bad}':\n{help}",
                args.join(" ")
            );
        }
        // Conventions visible in the help: no --out, and -o always names one file.
        assert!(!help.contains("--out "), "{}: {help}", path.join(" "));
        for line in help
            .lines()
            .filter(|l| l.trim_start().starts_with("-o, --output"))
        {
            assert!(!line.contains("<DIR>") && !line.contains("<dir>"), "{line}");
        }
        // The global verbosity flags are everywhere.
        assert!(
            help.contains("-q, --quiet") && help.contains("-v, --verbose"),
            "{help}"
        );
    }
}

#[track_caller]
fn deprecated(run: &Run, old: &str, new: &str) {
    run.expect_code(0);
    assert!(run.stderr.contains(&note(old, new)), "{}", run.report());
}

#[test]
fn old_out_of_every_synth_command_still_works_with_a_note() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    for (cmd, extra, made) in [
        ("linear", &[][..], "runs.csv"),
        ("thermal", &["--campaigns", "2"][..], "sensors.csv"),
        (
            "rotary",
            &["--step-deg", "90", "--repeats", "1", "--points", "6"][..],
            "truth.json",
        ),
        ("circular", &["--step-deg", "1"][..], "run.csv"),
        ("web-plate", &["--parts", "2"][..], "job.toml"),
    ] {
        let mut args = vec!["synth", cmd, "--out", cmd];
        args.extend_from_slice(extra);
        deprecated(&errmap(d, &args), "--out", "--out-dir");
        assert!(
            d.join(cmd).join(made).exists(),
            "{cmd}: {:?}",
            common::listing(d)
        );
        // The new spelling says nothing about it.
        let mut args = vec!["synth", cmd, "--out-dir", "new"];
        args.extend_from_slice(extra);
        let run = ok(d, &args);
        assert!(!run.stderr.contains("deprecated"), "{}", run.report());
        assert!(d.join("new").join(made).exists());
        std::fs::remove_dir_all(d.join("new")).unwrap();
    }
    // Both spellings at once is a usage error, not a guess.
    let run = errmap(d, &["synth", "linear", "--out", "a", "--out-dir", "b"]);
    run.expect_code(2);
    assert!(
        run.stderr.contains("--out") && run.stderr.contains("cannot be used with"),
        "{}",
        run.report()
    );
    assert!(!d.join("a").exists() && !d.join("b").exists());
    // Without either, the new spelling is the one asked for.
    let run = errmap(d, &["synth", "linear"]);
    run.expect_code(2);
    assert!(run.stderr.contains("--out-dir"), "{}", run.report());
}

#[test]
fn old_out_of_batch_map_slurm_and_k8s_still_works_with_a_note() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    ok(
        d,
        &[
            "synth",
            "web-plate",
            "--parts",
            "2",
            "--epochs",
            "5",
            "--out-dir",
            "wp",
            "-q",
        ],
    );
    let run = errmap(
        d,
        &["batch", "wp/job.toml", "--backend", "cpu", "--out", "b"],
    );
    deprecated(&run, "--out", "--out-dir");
    assert!(d.join("b/summary.json").exists(), "{}", run.report());
    let run = errmap(
        d,
        &[
            "map",
            "wp/probes/p01.csv",
            "--nominal-plane",
            "5",
            "--backend",
            "cpu",
            "--epochs",
            "5",
            "--out",
            "m",
        ],
    );
    deprecated(&run, "--out", "--out-dir");
    assert!(d.join("m/summary.json").exists(), "{}", run.report());
    // The scripts a Slurm run writes use the new spelling, so shards print no note.
    let run = errmap(
        d,
        &[
            "slurm",
            "wp/job.toml",
            "--shards",
            "2",
            "--out",
            "s",
            "--dry-run",
        ],
    );
    deprecated(&run, "--out", "--out-dir");
    assert!(run.stdout.contains(" --out-dir "), "{}", run.report());
    assert!(!run.stdout.contains(" --out "), "{}", run.report());
    let k8s = [
        "k8s",
        "wp/job.toml",
        "--shards",
        "2",
        "--image",
        "img",
        "--pvc",
        "claim",
    ];
    let run = errmap(d, &[&k8s[..], &["--out", "o", "--dry-run"]].concat());
    deprecated(&run, "--out", "--out-dir");
    assert!(run.stdout.contains("\"--out-dir\""), "{}", run.report());
    for old in ["-o", "--output"] {
        let folder = format!("manifests{old}");
        let run = errmap(d, &[&k8s[..], &[old, &folder]].concat());
        deprecated(&run, "-o/--output", "--manifest-dir");
        assert!(
            d.join(&folder).join("shards-job.json").exists(),
            "{}",
            run.report()
        );
    }
    let run = ok(d, &[&k8s[..], &["--manifest-dir", "mf"]].concat());
    assert!(!run.stderr.contains("deprecated") && d.join("mf/merge-job.json").exists());
}

#[test]
fn old_output_folder_of_thermal_difference_and_evaluate_works_or_is_refused_when_ambiguous() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    ok(
        d,
        &[
            "synth",
            "thermal",
            "--campaigns",
            "2",
            "--out-dir",
            "t",
            "-q",
        ],
    );
    let campaign = "t/campaign-1-coolant-off";
    assert!(
        d.join(campaign).join("campaign.toml").exists(),
        "{:?}",
        common::listing(d)
    );
    for old in ["-o", "--output"] {
        let folder = format!("diff{old}");
        let run = errmap(d, &["thermal", "difference", campaign, old, &folder]);
        deprecated(&run, "-o/--output", "--out-dir");
        assert!(
            d.join(&folder).join("difference.csv").exists(),
            "{}",
            run.report()
        );
    }
    // -o now means one file: a value that looks like one is refused, and nothing is written.
    let run = errmap(d, &["thermal", "difference", campaign, "-o", "diff.csv"]);
    run.expect_code(2);
    assert!(run.stderr.contains("--out-dir"), "{}", run.report());
    assert!(!d.join("diff.csv").exists());
    ok(
        d,
        &["thermal", "difference", campaign, "--out-dir", "dd", "-q"],
    );
    let fan = image::open(d.join("dd/fan.png")).unwrap();
    assert_eq!((fan.width(), fan.height()), (1300, 560));

    let fit = [
        "thermal",
        "fit",
        "--no-loco",
        "--order",
        "2",
        "-o",
        "model.json",
        "-q",
    ];
    ok(
        d,
        &[
            &fit[..],
            &["t/campaign-1-coolant-off", "t/campaign-2-coolant-on"],
        ]
        .concat(),
    );
    let run = errmap(
        d,
        &[
            "thermal",
            "evaluate",
            "--model",
            "model.json",
            campaign,
            "--output",
            "ev",
        ],
    );
    deprecated(&run, "-o/--output", "--out-dir");
    assert!(d.join("ev/evaluate.csv").exists(), "{}", run.report());
    let run = errmap(
        d,
        &[
            "thermal",
            "evaluate",
            "--model",
            "model.json",
            campaign,
            "-o",
            "ev.png",
        ],
    );
    run.expect_code(2);
    assert!(run.stderr.contains("ev.png"), "{}", run.report());
    assert!(!d.join("ev.png").exists());
}

#[test]
fn quiet_runs_print_nothing_and_errors_still_show() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let runs = [
        vec!["synth", "linear", "--out-dir", "l", "-q"],
        vec![
            "linear",
            "table",
            "l/runs.csv",
            "--format",
            "linuxcnc",
            "--spacing",
            "50",
            "-o",
            "x.comp",
            "-q",
        ],
        vec![
            "synth",
            "circular",
            "--out-dir",
            "c",
            "--step-deg",
            "1",
            "--quiet",
        ],
    ];
    for args in &runs {
        let run = ok(d, args);
        assert!(
            run.stdout.is_empty() && run.stderr.is_empty(),
            "{}",
            run.report()
        );
    }
    assert!(d.join("x.comp").exists());
    // Without -q the same run says what it wrote.
    let run = ok(d, &["synth", "linear", "--out-dir", "l2"]);
    assert!(run.stderr.contains("wrote"), "{}", run.report());
    // An error is shown even with -q.
    let run = errmap(
        d,
        &[
            "linear",
            "table",
            "missing.csv",
            "--format",
            "csv",
            "--spacing",
            "50",
            "-o",
            "y.csv",
            "-q",
        ],
    );
    run.expect_code(2);
    assert!(run.stderr.contains("missing.csv"), "{}", run.report());
    // -q and -v contradict each other.
    let run = errmap(d, &["synth", "linear", "--out-dir", "l3", "-q", "-v"]);
    run.expect_code(2);
    assert!(
        run.stderr.contains("cannot be used with"),
        "{}",
        run.report()
    );
}

#[test]
fn the_trainer_note_appears_only_with_verbose() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    ok(
        d,
        &[
            "synth",
            "web-plate",
            "--parts",
            "2",
            "--epochs",
            "5",
            "--out-dir",
            "wp",
            "-q",
        ],
    );
    let batch = ["batch", "wp/job.toml", "--backend", "cpu"];
    let plain = ok(d, &[&batch[..], &["--out-dir", "a"]].concat());
    assert!(
        !plain.stderr.contains("training ") && !plain.stderr.contains("trainer:"),
        "{}",
        plain.report()
    );
    let verbose = ok(d, &[&batch[..], &["--out-dir", "b", "-v"]].concat());
    assert!(
        verbose.stderr.contains("trainer: --backend cpu"),
        "{}",
        verbose.report()
    );
    assert!(verbose.stderr.contains("training "), "{}", verbose.report());
    // The results are the same whatever the verbosity.
    let rows = |r: &Run| -> Vec<String> {
        r.stdout
            .lines()
            .filter(|l| l.starts_with("p0"))
            .map(String::from)
            .collect()
    };
    assert_eq!(rows(&plain).len(), 2, "{}", plain.report());
    assert_eq!(rows(&plain), rows(&verbose));
    let quiet = ok(d, &[&batch[..], &["--out-dir", "c", "-q"]].concat());
    assert!(quiet.stderr.is_empty(), "{}", quiet.report());
}

#[test]
fn json_outputs_parse() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    ok(d, &["synth", "linear", "--out-dir", "l", "-q"]);
    ok(
        d,
        &[
            "synth",
            "circular",
            "--out-dir",
            "c",
            "--step-deg",
            "1",
            "-q",
        ],
    );
    ok(
        d,
        &[
            "synth",
            "rotary",
            "--out-dir",
            "r",
            "--step-deg",
            "90",
            "--repeats",
            "1",
            "--points",
            "6",
            "-q",
        ],
    );
    ok(
        d,
        &[
            "synth",
            "web-plate",
            "--parts",
            "2",
            "--epochs",
            "5",
            "--out-dir",
            "wp",
            "-q",
        ],
    );
    for args in [
        &[
            "linear",
            "analyze",
            "l/runs.csv",
            "--standard",
            "iso230-2:2014",
            "--json",
        ][..],
        &[
            "linear",
            "air-index",
            "--temp-c",
            "20",
            "--pressure-kpa",
            "101.325",
            "--humidity-pct",
            "50",
            "--wavelength-nm",
            "633",
            "--json",
        ][..],
        &["circular", "c/run.csv", "--radius", "100", "--json"][..],
        &["rotary", "analyze", "r/touch_points.csv", "--json"][..],
        &[
            "batch",
            "wp/job.toml",
            "--backend",
            "cpu",
            "--out-dir",
            "b",
            "--json",
        ][..],
        &[
            "bench",
            "training",
            "--backend",
            "cpu",
            "--parts",
            "1",
            "--samples",
            "64",
            "--epochs",
            "2",
            "--json",
        ][..],
    ] {
        let run = ok(d, args);
        let doc: serde_json::Value =
            serde_json::from_str(&run.stdout).unwrap_or_else(|e| panic!("{e}\n{}", run.report()));
        assert!(doc.is_object(), "{}", run.report());
    }
    // Shown as ordinary text without --json.
    let run = ok(
        d,
        &[
            "linear",
            "analyze",
            "l/runs.csv",
            "--standard",
            "iso230-2:2014",
        ],
    );
    assert!(serde_json::from_str::<serde_json::Value>(&run.stdout).is_err());
}
