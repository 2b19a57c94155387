//! Stopping on the hold-out RMS: segments that carry Adam's state equal one fixed-epoch run bit for bit, a fit whose hold-out RMS provably turns stops early and keeps its best parameters, time-to-accuracy on a hand-made curve, the job keys' errors, and a batch with `stop = "holdout"`.

mod common;

use errmap::batch::Job;
use errmap::nn::stop::{
    time_to_accuracy, train_until_holdout_stops, CurvePoint, Holdout, StopGroup,
};
use errmap::nn::{
    initial_networks, layer_spans, AdamRun, CpuTrainer, FastCpuTrainer, Mlp, ModelConfig,
    Normalisation, Stop, Trainer, TrainingSet,
};
use std::path::Path;

fn bits(net: &Mlp) -> Vec<u32> {
    net.params.iter().map(|p| p.to_bits()).collect()
}

fn small_config(epochs: u32) -> ModelConfig {
    ModelConfig {
        hidden: vec![8, 8],
        epochs,
        loss_every: epochs,
        ..ModelConfig::default()
    }
}

#[test]
fn segments_carry_adam_state_and_equal_one_fixed_run_bit_for_bit() {
    let sets = errmap::synth::training::plate_family(3, 203);
    let config = small_config(60);
    let trainers: [(&str, &dyn Trainer); 2] = [
        ("cpu-reference", &CpuTrainer::reference()),
        ("cpu", &FastCpuTrainer),
    ];
    for (name, trainer) in trainers {
        let initial = initial_networks(sets.len(), &config);
        let fixed = trainer.train_from(initial.clone(), &sets, &config).unwrap();
        let mut runs: Vec<AdamRun> = initial.into_iter().map(AdamRun::new).collect();
        for to in [7, 20, 20, 59, 60] {
            trainer
                .train_segment(&mut runs, &sets, &config, to)
                .unwrap();
        }
        for (k, (run, net)) in runs.iter().zip(&fixed).enumerate() {
            assert_eq!(run.epoch, 60);
            assert_eq!(bits(&run.net), bits(net), "{name}: network {k}");
        }
        // Restarting the moments mid-way (what a trainer without state would do) differs,
        // so the equality above is the state being carried, not an accident.
        let mut restarted: Vec<AdamRun> = initial_networks(sets.len(), &config)
            .into_iter()
            .map(AdamRun::new)
            .collect();
        trainer
            .train_segment(&mut restarted, &sets, &config, 30)
            .unwrap();
        for run in &mut restarted {
            run.m.fill(0.0);
            run.v.fill(0.0);
        }
        trainer
            .train_segment(&mut restarted, &sets, &config, 60)
            .unwrap();
        assert_ne!(bits(&restarted[0].net), bits(&fixed[0]), "{name}");
    }
}

/// Hold-out points equal to a network's own training samples (its standardised targets read
/// as µm): the hold-out RMS is the root of its training loss.
fn own_samples(set: &TrainingSet) -> Holdout {
    let domain = errmap::synth::training::plate_domain();
    Holdout {
        inputs: set.inputs.clone(),
        e_um: set.targets.iter().map(|&t| t as f64).collect(),
        norm: Normalisation {
            e_mean_um: 0.0,
            e_std_um: 1.0,
            ..Normalisation::new(&domain, &[])
        },
    }
}

#[test]
fn holdout_stopping_that_never_triggers_equals_the_fixed_epoch_run() {
    let sets = errmap::synth::training::plate_family(3, 203);
    let fixed_config = small_config(60);
    let config = ModelConfig {
        stop: Stop::Holdout,
        check_every_epochs: 7,
        patience_checks: 1000,
        ..fixed_config.clone()
    };
    // Network 0 judged on its own samples (with network 1 as its partner), network 2 in no group.
    let groups = [StopGroup {
        judge: 0,
        members: vec![0, 1],
        holdout: own_samples(&sets[0]),
    }];
    for trainer in [&CpuTrainer::reference() as &dyn Trainer, &FastCpuTrainer] {
        let initial = initial_networks(sets.len(), &config);
        let fixed = trainer
            .train_from(initial.clone(), &sets, &fixed_config)
            .unwrap();
        let (nets, outcomes) =
            train_until_holdout_stops(trainer, initial, &sets, &groups, &config).unwrap();
        let o = &outcomes[0];
        let epochs: Vec<u32> = o.curve.iter().map(|p| p.epochs).collect();
        assert_eq!(epochs, [0, 7, 14, 21, 28, 35, 42, 49, 56, 60]);
        // The training loss falls at every check here, so the best check is the last.
        assert!(o
            .curve
            .windows(2)
            .all(|w| w[1].holdout_rmse_um < w[0].holdout_rmse_um));
        assert_eq!((o.best_epochs, o.stopped_epochs), (60, 60));
        for k in 0..3 {
            assert_eq!(bits(&nets[k]), bits(&fixed[k]), "network {k}");
        }
        // The last check's RMS is the fixed run's own training loss, computed independently
        // (`mse` subtracts in f32, the hold-out RMS in f64: equal to f32 precision).
        let rms = errmap::nn::mse(&fixed[0], &sets[0]).sqrt();
        let last = o.curve.last().unwrap().holdout_rmse_um;
        assert!((last - rms).abs() < 1e-5 * rms, "{last} vs {rms}");
    }
}

/// A network whose only moving parameter is the output bias: all weights 0, so every
/// hidden unit outputs tanh(0) = 0 and the output is the bias b everywhere; the weights'
/// gradients are exactly 0 (δ·a with a = 0, and δ_hidden = W_out·δ = 0), so Adam leaves
/// them at 0 and moves b from 0 towards the training target 1 by about the learning rate
/// per step. Held out at 0.5 µm, the RMS is |b − 0.5|: it falls until b passes 0.5, then
/// rises for good.
fn bias_only(config: &ModelConfig) -> Mlp {
    let mut net = Mlp::init(&config.layer_sizes(), config.activation, 1);
    net.params.fill(0.0);
    net
}

fn constant_set(value: f32) -> TrainingSet {
    let inputs: Vec<[f32; 2]> = (0..16)
        .map(|i| [(i % 4) as f32 / 2.0 - 0.75, (i / 4) as f32 / 2.0 - 0.75])
        .collect();
    TrainingSet {
        targets: vec![value; inputs.len()],
        inputs,
    }
}

#[test]
fn a_fit_whose_holdout_rms_turns_stops_early_and_keeps_its_best_parameters() {
    let config = ModelConfig {
        hidden: vec![4],
        epochs: 1000,
        learning_rate: 0.01,
        lr_decay: 1.0, // a constant rate: a shorter fixed run takes the same steps
        loss_every: 1,
        stop: Stop::Holdout,
        check_every_epochs: 5,
        patience_checks: 4,
        ..ModelConfig::default()
    };
    let sets = vec![constant_set(1.0), constant_set(2.0), constant_set(1.0)];
    let domain = errmap::synth::training::plate_domain();
    let holdout = Holdout {
        inputs: vec![[0.1, 0.2], [-0.4, 0.3], [0.6, -0.7]],
        e_um: vec![0.5; 3],
        norm: Normalisation {
            e_mean_um: 0.0,
            e_std_um: 1.0,
            ..Normalisation::new(&domain, &[])
        },
    };
    // Network 0 judges, network 1 stops with it, network 2 is in no group.
    let groups = [StopGroup {
        judge: 0,
        members: vec![0, 1],
        holdout,
    }];
    let initial = vec![bias_only(&config); 3];
    let trainer = CpuTrainer::reference();
    let (nets, outcomes) =
        train_until_holdout_stops(&trainer, initial.clone(), &sets, &groups, &config).unwrap();
    let o = &outcomes[0];
    let rms: Vec<f64> = o.curve.iter().map(|p| p.holdout_rmse_um).collect();
    let best_check = (0..rms.len())
        .min_by(|&a, &b| rms[a].total_cmp(&rms[b]))
        .unwrap();
    assert_eq!(o.best_epochs, o.curve[best_check].epochs);
    // Stopped 4 checks after the best, long before the 1000 epochs.
    assert_eq!(o.stopped_epochs, o.best_epochs + 4 * 5, "{rms:?}");
    assert_eq!(o.curve.len(), best_check + 5);
    assert!(o.stopped_epochs < 200, "{}", o.stopped_epochs);
    // The kept judge: weights still 0, output bias within half a check (5 steps of ~0.01)
    // of the held-out 0.5.
    let bias = layer_spans(&nets[0].layer_sizes)
        .last()
        .unwrap()
        .bias_offset;
    assert!(nets[0].params[..bias].iter().all(|&w| w == 0.0));
    assert!(
        (nets[0].params[bias] - 0.5).abs() <= 0.05,
        "{}",
        nets[0].params[bias]
    );
    assert!(
        (o.curve[best_check].holdout_rmse_um - (nets[0].params[bias] as f64 - 0.5).abs()).abs()
            < 1e-6
    );
    // Judge and partner hold their parameters of the best check: a fixed run of that many
    // steps; the ungrouped network trained all 1000.
    let fixed_best = trainer
        .train_from(
            initial[..2].to_vec(),
            &sets[..2],
            &ModelConfig {
                epochs: o.best_epochs,
                stop: Stop::Epochs,
                ..config.clone()
            },
        )
        .unwrap();
    assert_eq!(bits(&nets[0]), bits(&fixed_best[0]));
    assert_eq!(bits(&nets[1]), bits(&fixed_best[1]));
    let fixed_all = trainer
        .train_from(
            initial[2..].to_vec(),
            &sets[2..],
            &ModelConfig {
                stop: Stop::Epochs,
                ..config.clone()
            },
        )
        .unwrap();
    assert_eq!(bits(&nets[2]), bits(&fixed_all[0]));
}

#[test]
fn time_to_accuracy_is_the_first_check_within_5_percent_of_the_lowest_rms() {
    let point = |epochs, seconds, holdout_rmse_um| CurvePoint {
        epochs,
        seconds,
        holdout_rmse_um,
    };
    // Lowest 2.0 at epoch 40; 5 % above it is 2.1: epoch 30 (2.1) is the first within,
    // epoch 20 (2.11) is not, and the later rise to 2.5 does not matter.
    let curve = [
        point(0, 0.0, 10.0),
        point(10, 0.5, 3.0),
        point(20, 1.0, 2.11),
        point(30, 1.5, 2.1),
        point(40, 2.0, 2.0),
        point(50, 2.5, 2.5),
    ];
    let a = time_to_accuracy(&curve, 0.05).unwrap();
    assert_eq!(a.converged_rmse_um, 2.0);
    assert_eq!(a.epochs, 30);
    assert_eq!(a.seconds, 1.5);
    // A NaN check is skipped; a curve without a finite RMS has no time-to-accuracy.
    let curve = [point(0, 0.0, f64::NAN), point(10, 0.3, 4.0)];
    assert_eq!(time_to_accuracy(&curve, 0.05).unwrap().epochs, 10);
    assert!(time_to_accuracy(&[point(0, 0.0, f64::NAN)], 0.05).is_none());
}

#[track_caller]
fn parse_error(text: &str) -> String {
    Job::parse(Path::new("j.toml"), text)
        .unwrap_err()
        .to_string()
}

#[test]
fn stop_keys_are_validated_with_line_and_column() {
    let err = parse_error("family = \"a\"\n[model]\nstop = \"sometimes\"\n");
    assert!(err.starts_with("j.toml:3, column 8:"), "{err}");
    assert!(err.contains("holdout"), "{err}");
    let err = parse_error("[model]\nstop = \"holdout\"\ncheck_every_epochs = 0\n");
    assert!(err.starts_with("j.toml:3, column 22:"), "{err}");
    assert!(err.contains("model.check_every_epochs"), "{err}");
    let err = parse_error("[model]\nstop = \"holdout\"\n\npatience_checks = 0\n");
    assert!(err.starts_with("j.toml:4, column 19:"), "{err}");
    let err = parse_error("[model]\nholdout_fraction = 0\n  stop = \"holdout\"\n");
    assert!(err.starts_with("j.toml:3, column 10:"), "{err}");
    assert!(err.contains("holdout_fraction"), "{err}");
    let err = parse_error("[model]\noptimizer = \"lbfgs\"\nstop = \"holdout\"\n");
    assert!(err.starts_with("j.toml:3, column 8:"), "{err}");
    assert!(err.contains("adam"), "{err}");
    let job = Job::parse(
        Path::new("j.toml"),
        "[model]\nstop = \"holdout\"\ncheck_every_epochs = 25\npatience_checks = 6\n",
    )
    .unwrap();
    assert_eq!(job.model.stop, Stop::Holdout);
    assert_eq!(
        (job.model.check_every_epochs, job.model.patience_checks),
        (25, 6)
    );
    // The defaults add nothing to the serialised settings, so existing jobs hash as before.
    let text = serde_json::to_string(&ModelConfig::default()).unwrap();
    assert!(!text.contains("stop") && !text.contains("check_every") && !text.contains("patience"));
}

#[test]
fn a_batch_that_stops_on_the_holdout_writes_its_timing_apart() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    common::ok(
        d,
        &[
            "synth",
            "web-plate",
            "--parts",
            "2",
            "--out",
            "data",
            "--epochs",
            "120",
        ],
    );
    let job = std::fs::read_to_string(d.join("data/job.toml")).unwrap();
    let job = job.replacen(
        "[model]\n",
        "[model]\nstop = \"holdout\"\ncheck_every_epochs = 20\npatience_checks = 2\n",
        1,
    );
    std::fs::write(d.join("data/job.toml"), job).unwrap();
    let args = ["batch", "data/job.toml", "--backend", "cpu", "--out", "out"];
    let first = common::ok(d, &args);
    assert!(
        first.stdout.contains("hold-out stopping: 2 parts"),
        "{}",
        first.report()
    );
    let summary: serde_json::Value =
        serde_json::from_slice(&std::fs::read(d.join("out/summary.json")).unwrap()).unwrap();
    let timing: serde_json::Value =
        serde_json::from_slice(&std::fs::read(d.join("out/timing.json")).unwrap()).unwrap();
    let manifest: serde_json::Value =
        serde_json::from_slice(&std::fs::read(d.join("out/run.json")).unwrap()).unwrap();
    assert!(manifest["files"]["timing.json"].is_string(), "{manifest}");
    assert_eq!(timing["format"], "errmap-timing/1");
    for (part, t) in summary["parts"]
        .as_array()
        .unwrap()
        .iter()
        .zip(timing["parts"].as_array().unwrap())
    {
        assert_eq!(part["part"], t["part"]);
        let stopping = &part["stopping"];
        assert_eq!(stopping["best_epochs"], t["best_epochs"]);
        assert_eq!(stopping["epochs_to_accuracy"], t["epochs_to_accuracy"]);
        assert!(stopping.get("seconds_to_accuracy").is_none());
        let best = stopping["best_epochs"].as_u64().unwrap();
        let stopped = stopping["stopped_epochs"].as_u64().unwrap();
        assert!(best <= stopped && stopped <= 120 && best % 20 == 0);
        // The kept hold-out network is the one summary.json reports.
        let converged = t["converged_holdout_rmse_um"].as_f64().unwrap();
        let reported = part["holdout_rmse_um"].as_f64().unwrap();
        assert!(
            (converged - reported).abs() < 1e-6 * reported,
            "{converged} {reported}"
        );
        let curve = t["curve"].as_array().unwrap();
        assert!(curve
            .windows(2)
            .all(|w| w[0]["seconds"].as_f64() <= w[1]["seconds"].as_f64()));
    }
    // Everything but the timing (and run.json, which lists its hash, and report.html, which
    // carries the run's date) is the same run to run.
    let keep = |p: &Path| {
        let name = p.file_name().unwrap().to_string_lossy().to_string();
        name != "timing.json" && name != "run.json" && name != "report.html"
    };
    let before: Vec<(std::path::PathBuf, Vec<u8>)> = common::files(&d.join("out"))
        .into_iter()
        .filter(|p| keep(p))
        .map(|p| (p.clone(), std::fs::read(&p).unwrap()))
        .collect();
    common::ok(d, &args);
    for (path, bytes) in &before {
        assert!(
            std::fs::read(path).unwrap() == *bytes,
            "{} changed",
            path.display()
        );
    }
}

/// A trainer that only knows whole fits (as the GPU trainers do), so segments take the
/// trait's default: moments restarted, learning-rate schedule continued.
struct WholeFitsOnly(CpuTrainer);

impl Trainer for WholeFitsOnly {
    fn name(&self) -> String {
        "whole fits only".into()
    }
    fn train_from(
        &self,
        initial: Vec<Mlp>,
        sets: &[TrainingSet],
        config: &ModelConfig,
    ) -> errmap::Result<Vec<Mlp>> {
        self.0.train_from(initial, sets, config)
    }
    fn evaluate_batch(&self, nets: &[Mlp], inputs: &[[f32; 2]]) -> errmap::Result<Vec<Vec<f32>>> {
        self.0.evaluate_batch(nets, inputs)
    }
}

#[test]
fn trainers_without_adam_state_restart_the_moments_each_segment() {
    let sets = errmap::synth::training::plate_family(2, 203);
    let config = ModelConfig {
        lr_decay: 1.0, // a constant rate, so a restarted segment is a fresh fit of its length
        ..small_config(40)
    };
    let trainer = WholeFitsOnly(CpuTrainer::reference());
    let initial = initial_networks(sets.len(), &config);
    let mut runs: Vec<AdamRun> = initial.iter().cloned().map(AdamRun::new).collect();
    trainer
        .train_segment(&mut runs, &sets, &config, 15)
        .unwrap();
    trainer
        .train_segment(&mut runs, &sets, &config, 40)
        .unwrap();
    let steps = |n| ModelConfig {
        epochs: n,
        loss_every: n,
        ..config.clone()
    };
    let first = CpuTrainer::reference()
        .train_from(initial.clone(), &sets, &steps(15))
        .unwrap();
    let chained = CpuTrainer::reference()
        .train_from(first, &sets, &steps(25))
        .unwrap();
    let whole = CpuTrainer::reference()
        .train_from(initial, &sets, &config)
        .unwrap();
    for k in 0..2 {
        assert_eq!(runs[k].epoch, 40);
        assert_eq!(bits(&runs[k].net), bits(&chained[k]), "network {k}");
        assert_ne!(bits(&runs[k].net), bits(&whole[k]), "network {k}");
    }
    // Hold-out stopping on such a trainer is still repeatable.
    let groups = [StopGroup {
        judge: 0,
        members: vec![0],
        holdout: own_samples(&sets[1]),
    }];
    let config = ModelConfig {
        stop: Stop::Holdout,
        check_every_epochs: 5,
        patience_checks: 2,
        ..config
    };
    let run = || {
        train_until_holdout_stops(
            &trainer,
            initial_networks(2, &config),
            &sets,
            &groups,
            &config,
        )
        .unwrap()
    };
    let (a, oa) = run();
    let (b, ob) = run();
    assert_eq!(oa[0].best_epochs, ob[0].best_epochs);
    assert_eq!(bits(&a[0]), bits(&b[0]));
    assert_eq!(bits(&a[1]), bits(&b[1]));
}
