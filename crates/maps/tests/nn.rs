//! Tests of the CPU reference trainer: layout, initialisation, normalisation, backprop, Adam, fitting, determinism, config validation.

use errmap_core::geom::Domain;
use errmap_maps::nn::*;

fn small_set() -> TrainingSet {
    // 70 samples (more than the 64 gradient lanes) of a smooth function on [-1, 1]².
    let mut set = TrainingSet::default();
    for j in 0..7 {
        for i in 0..10 {
            let x = [-1.0 + 2.0 * i as f32 / 9.0, -1.0 + 2.0 * j as f32 / 6.0];
            set.inputs.push(x);
            set.targets.push((1.3 * x[0]).sin() * x[1] + 0.2);
        }
    }
    set
}

#[test]
fn layout_is_w_row_major_then_bias_per_layer() {
    let spans = layer_spans(&[2, 3, 1]);
    assert_eq!(spans.len(), 2);
    assert_eq!((spans[0].weight_offset, spans[0].bias_offset), (0, 6));
    assert_eq!((spans[1].weight_offset, spans[1].bias_offset), (9, 12));
    assert_eq!(
        param_count(&[2, 32, 32, 1]),
        2 * 32 + 32 + 32 * 32 + 32 + 32 + 1
    );
}

#[test]
fn forward_matches_hand_computation() {
    // 2 → 2 → 1, tanh. W0 = [[1, 2], [-1, 0.5]], b0 = [0.1, -0.2], W1 = [3, -2], b1 = 0.5.
    let net = Mlp {
        layer_sizes: vec![2, 2, 1],
        activation: Activation::Tanh,
        params: vec![1.0, 2.0, -1.0, 0.5, 0.1, -0.2, 3.0, -2.0, 0.5],
    };
    let (x0, x1) = (0.3f64, -0.4f64);
    let h0 = (0.1 + 1.0 * x0 + 2.0 * x1).tanh();
    let h1 = (-0.2 - 1.0 * x0 + 0.5 * x1).tanh();
    let expected = 0.5 + 3.0 * h0 - 2.0 * h1;
    let got = net.forward([0.3, -0.4]) as f64;
    assert!((got - expected).abs() < 1e-6, "{got} vs {expected}");
    let relu = Mlp {
        activation: Activation::Relu,
        ..net
    };
    let expected_relu =
        0.5 + 3.0 * (0.1f64 + x0 + 2.0 * x1).max(0.0) - 2.0 * (-0.2 - x0 + 0.5 * x1).max(0.0);
    assert!((relu.forward([0.3, -0.4]) as f64 - expected_relu).abs() < 1e-6);
}

#[test]
fn glorot_init_is_seeded_bounded_and_zero_biased() {
    let a = Mlp::init(&[2, 32, 32, 1], Activation::Tanh, 7);
    let b = Mlp::init(&[2, 32, 32, 1], Activation::Tanh, 7);
    let c = Mlp::init(&[2, 32, 32, 1], Activation::Tanh, 8);
    assert_eq!(a, b);
    assert_ne!(a.params, c.params);
    for span in layer_spans(&a.layer_sizes) {
        let limit = (6.0f32 / (span.inputs + span.outputs) as f32).sqrt();
        let w = &a.params[span.weight_offset..span.bias_offset];
        assert!(w.iter().all(|x| x.abs() <= limit));
        // Uniform on ±limit: the largest |w| of 32+ draws comes close to the limit.
        assert!(w.iter().fold(0.0f32, |m, x| m.max(x.abs())) > 0.8 * limit);
        let biases = &a.params[span.bias_offset..span.bias_offset + span.outputs];
        assert!(biases.iter().all(|&b| b == 0.0));
    }
    assert_ne!(network_seed(1, 0), network_seed(1, 1));
}

#[test]
fn normalisation_scales_and_guards_zero_spread() {
    let domain = Domain {
        u_min_mm: 100.0,
        v_min_mm: -50.0,
        u_max_mm: 700.0,
        v_max_mm: 250.0,
    };
    let n = Normalisation::new(&domain, &[1.0, 3.0, 5.0]);
    assert_eq!(n.scale_input(100.0, -50.0), [-1.0, -1.0]);
    assert_eq!(n.scale_input(700.0, 250.0), [1.0, 1.0]);
    assert_eq!(n.scale_input(400.0, 100.0), [0.0, 0.0]);
    assert!((n.e_mean_um - 3.0).abs() < 1e-12);
    let std = (8.0f64 / 3.0).sqrt(); // population std of 1, 3, 5
    assert!((n.e_std_um - std).abs() < 1e-12);
    assert!((n.scale_target(5.0) as f64 - 2.0 / std).abs() < 1e-6);
    assert!((n.unscale_output(n.scale_target(4.2)) - 4.2).abs() < 1e-6);
    let flat = Normalisation::new(&domain, &[2.5, 2.5]);
    assert_eq!(flat.e_std_um, 1.0);
    assert_eq!(flat.scale_target(2.5), 0.0);
}

#[test]
fn backprop_matches_finite_differences() {
    for activation in [Activation::Tanh, Activation::Relu] {
        let set = small_set();
        let net = Mlp::init(&[2, 5, 4, 1], activation, 3);
        let (_, grad) = loss_gradient(&net, &set).unwrap();
        // Central differences of an independent f64 implementation of the loss.
        let spans = layer_spans(&net.layer_sizes);
        let loss64 = |p: &[f64]| -> f64 {
            let mut sum = 0.0;
            for (x, t) in set.inputs.iter().zip(&set.targets) {
                let mut a: Vec<f64> = vec![x[0] as f64, x[1] as f64];
                for (l, s) in spans.iter().enumerate() {
                    a = (0..s.outputs)
                        .map(|i| {
                            let z = p[s.bias_offset + i]
                                + (0..s.inputs)
                                    .map(|j| p[s.weight_offset + i * s.inputs + j] * a[j])
                                    .sum::<f64>();
                            if l + 1 == spans.len() {
                                z
                            } else if activation == Activation::Tanh {
                                z.tanh()
                            } else {
                                z.max(0.0)
                            }
                        })
                        .collect();
                }
                sum += (a[0] - *t as f64).powi(2);
            }
            sum / set.len() as f64
        };
        let base: Vec<f64> = net.params.iter().map(|&p| p as f64).collect();
        let h = 1e-6;
        for (k, g) in grad.iter().enumerate() {
            let mut plus = base.clone();
            plus[k] += h;
            let mut minus = base.clone();
            minus[k] -= h;
            let fd = (loss64(&plus) - loss64(&minus)) / (2.0 * h);
            assert!(
                (*g as f64 - fd).abs() <= 1e-4 + 1e-3 * fd.abs(),
                "{activation:?} param {k}: backprop {g}, finite difference {fd}"
            );
        }
    }
}

#[test]
fn adam_step_matches_hand_computation() {
    let config = ModelConfig {
        learning_rate: 0.01,
        lr_decay: 1.0,
        epochs: 10,
        ..Default::default()
    };
    let (mut p, mut m, mut v) = (1.0f32, 0.0f32, 0.0f32);
    // Step 1, g = 0.5: m = 0.05, v = 0.00025, m̂ = 0.5, v̂ = 0.25, p = 1 − 0.01·0.5/(0.5 + 1e-8).
    adam_update(&mut p, &mut m, &mut v, 0.5, &AdamScalars::at(&config, 0));
    assert!((m - 0.05).abs() < 1e-9 && (v - 0.00025).abs() < 1e-10);
    assert!(
        (p as f64 - (1.0 - 0.01 * 0.5 / (0.5 + 1e-8))).abs() < 1e-7,
        "{p}"
    );
    // Step 2, g = −1: m = 0.045 − 0.1 = −0.055, v = 0.00024975 + 0.001 = 0.00124975,
    // m̂ = −0.055/(1 − 0.9²), v̂ = 0.00124975/(1 − 0.999²), p −= 0.01·m̂/(√v̂ + 1e-8).
    let p1 = p as f64;
    adam_update(&mut p, &mut m, &mut v, -1.0, &AdamScalars::at(&config, 1));
    let m_hat = -0.055 / (1.0 - 0.81);
    let v_hat = 0.00124975 / (1.0 - 0.999f64 * 0.999);
    let expected = p1 - 0.01 * m_hat / (v_hat.sqrt() + 1e-8);
    assert!((p as f64 - expected).abs() < 1e-6, "{p} vs {expected}");
    // Learning-rate schedule: exponential from lr to lr·decay.
    let decaying = ModelConfig {
        learning_rate: 0.02,
        lr_decay: 0.25,
        epochs: 3,
        ..Default::default()
    };
    assert!((decaying.learning_rate_at(0) - 0.02).abs() < 1e-9);
    assert!((decaying.learning_rate_at(1) - 0.01).abs() < 1e-9);
    assert!((decaying.learning_rate_at(2) - 0.005).abs() < 1e-9);
}

#[test]
fn training_fits_a_quadratic_bowl() {
    // f(x, y) = x² + 0.5·y² − 0.3 on a 21 × 21 grid.
    let mut set = TrainingSet::default();
    for j in 0..21 {
        for i in 0..21 {
            let x = [-1.0 + i as f32 * 0.1, -1.0 + j as f32 * 0.1];
            set.inputs.push(x);
            set.targets.push(x[0] * x[0] + 0.5 * x[1] * x[1] - 0.3);
        }
    }
    let mean = set.targets.iter().sum::<f32>() / set.len() as f32;
    let var0 = set
        .targets
        .iter()
        .map(|t| (t - mean) * (t - mean))
        .sum::<f32>()
        / set.len() as f32;
    let config = ModelConfig {
        hidden: vec![16, 16],
        epochs: 600,
        ..Default::default()
    };
    let nets = CpuTrainer::reference()
        .train_batch(std::slice::from_ref(&set), &config)
        .unwrap();
    let before = mse(&initial_networks(1, &config)[0], &set);
    let after = mse(&nets[0], &set);
    // Below 0.3 % of the target variance (RMS ≈ 5 % of its standard deviation).
    assert!(
        after < 3e-3 * var0 as f64 && after < before / 100.0,
        "mse {after} (variance {var0}, initial {before})"
    );
}

fn bits(nets: &[Mlp]) -> Vec<u32> {
    nets.iter()
        .flat_map(|n| n.params.iter().map(|p| p.to_bits()))
        .collect()
}

#[test]
fn training_is_deterministic_and_independent_of_batch_company() {
    let set = small_set();
    let mut other = small_set();
    other.inputs.truncate(40);
    other.targets.truncate(40);
    let config = ModelConfig {
        hidden: vec![8, 8],
        epochs: 50,
        ..Default::default()
    };
    let a = CpuTrainer::reference()
        .train_batch(&[set.clone(), other.clone()], &config)
        .unwrap();
    let b = CpuTrainer::reference()
        .train_batch(&[set.clone(), other], &config)
        .unwrap();
    assert_eq!(bits(&a), bits(&b));
    // Network 0 alone gets the same seed and therefore the same result.
    let alone = CpuTrainer::reference()
        .train_batch(&[set], &config)
        .unwrap();
    assert_eq!(bits(&alone), bits(&a[..1]));
    assert_ne!(a[0].params, a[1].params);
}

#[test]
fn evaluate_batch_equals_forward() {
    let config = ModelConfig::default();
    let nets = initial_networks(3, &config);
    let inputs: Vec<[f32; 2]> = (0..5000)
        .map(|i| [(i % 71) as f32 / 35.0 - 1.0, (i / 71) as f32 / 35.0 - 1.0])
        .collect();
    let out = CpuTrainer::reference()
        .evaluate_batch(&nets, &inputs)
        .unwrap();
    assert_eq!(out.len(), 3);
    for (net, ys) in nets.iter().zip(&out) {
        assert_eq!(ys.len(), inputs.len());
        for (x, y) in inputs.iter().zip(ys).step_by(97) {
            assert_eq!(net.forward(*x).to_bits(), y.to_bits());
        }
    }
}

#[test]
fn config_defaults_parse_and_validation_names_the_key() {
    let config: ModelConfig = toml::from_str("").unwrap();
    assert_eq!(config, ModelConfig::default());
    assert_eq!(config.hidden, vec![32, 32]);
    assert_eq!(config.activation, Activation::Tanh);
    assert_eq!(config.holdout_fraction, 0.1);
    assert_eq!(config.backend, Backend::Auto);
    let parsed: ModelConfig =
        toml::from_str("hidden = [16]\nactivation = \"relu\"\nbackend = \"cpu\"").unwrap();
    assert_eq!(parsed.hidden, vec![16]);
    assert_eq!(parsed.activation, Activation::Relu);
    assert_eq!(parsed.backend, Backend::Cpu);
    let unknown = toml::from_str::<ModelConfig>("epoch = 10")
        .unwrap_err()
        .to_string();
    assert!(unknown.contains("epoch"), "{unknown}");

    let bad = |c: ModelConfig, key: &str| {
        let e = c.validate().unwrap_err();
        assert_eq!(e.kind(), "input");
        assert!(e.to_string().contains(key), "{e}");
    };
    let d = ModelConfig::default;
    bad(ModelConfig { epochs: 0, ..d() }, "model.epochs");
    bad(
        ModelConfig {
            hidden: vec![],
            ..d()
        },
        "model.hidden",
    );
    bad(
        ModelConfig {
            hidden: vec![32, 0],
            ..d()
        },
        "model.hidden",
    );
    bad(
        ModelConfig {
            hidden: vec![100_000],
            ..d()
        },
        "model.hidden",
    );
    bad(
        ModelConfig {
            hidden: vec![8; 9],
            ..d()
        },
        "model.hidden",
    );
    bad(
        ModelConfig {
            learning_rate: 0.0,
            ..d()
        },
        "model.learning_rate",
    );
    bad(
        ModelConfig {
            learning_rate: f32::NAN,
            ..d()
        },
        "model.learning_rate",
    );
    bad(
        ModelConfig {
            holdout_fraction: 0.9,
            ..d()
        },
        "model.holdout_fraction",
    );
    bad(
        ModelConfig {
            lr_decay: 0.0,
            ..d()
        },
        "model.lr_decay",
    );
    bad(
        ModelConfig {
            loss_every: 0,
            ..d()
        },
        "model.loss_every",
    );
}

#[test]
fn bad_batches_are_errors_not_panics() {
    let config = ModelConfig {
        epochs: 2,
        ..Default::default()
    };
    let empty = CpuTrainer::reference()
        .train_batch(&[TrainingSet::default()], &config)
        .unwrap_err();
    assert!(empty.to_string().contains("training set 0"), "{empty}");
    let mut nan = small_set();
    nan.targets[3] = f32::NAN;
    let err = CpuTrainer::reference()
        .train_batch(&[nan], &config)
        .unwrap_err();
    assert!(err.to_string().contains("NaN"), "{err}");
    let mut broken = initial_networks(1, &config);
    broken[0].params.pop();
    assert!(broken[0].forward([0.0, 0.0]).is_nan());
    // A network whose sizes and parameters disagree is refused as bad input, saying so.
    let refused = |err: errmap_core::Error, words: &str| {
        assert_eq!(err.kind(), "input", "{err}");
        assert!(err.to_string().contains(words), "{err}");
    };
    refused(
        loss_gradient(&broken[0], &small_set()).unwrap_err(),
        "parameters, it has",
    );
    refused(
        CpuTrainer::reference()
            .evaluate_batch(&broken, &[[0.0, 0.0]])
            .unwrap_err(),
        "parameters, it has",
    );
    refused(
        CpuTrainer::reference()
            .train_from(broken, &[small_set()], &config)
            .unwrap_err(),
        "network 0",
    );
    assert!(CpuTrainer::reference()
        .train_batch(&[], &config)
        .unwrap()
        .is_empty());
    let diverging = ModelConfig {
        learning_rate: 1.0,
        lr_decay: 1.0,
        epochs: 3,
        ..Default::default()
    };
    let mut huge = small_set();
    huge.targets.iter_mut().for_each(|t| *t = 3e38);
    let err = CpuTrainer::reference()
        .train_batch(&[huge], &diverging)
        .unwrap_err();
    assert!(err.to_string().contains("diverged"), "{err}");
}

/// The sample job's training load with the default model: 17 networks (8 parts + 8 hold-out
/// fits + 1 family) of ~1450 samples of a smooth ±40 µm field. Too slow for the dev profile;
/// run `cargo test --release --test nn -- --ignored` (docs/performance.md times it).
#[test]
#[ignore]
fn default_model_fits_a_sample_like_family_within_1_percent() {
    use std::f64::consts::PI;
    let domain = Domain {
        u_min_mm: 0.0,
        v_min_mm: 0.0,
        u_max_mm: 600.0,
        v_max_mm: 300.0,
    };
    let mut sets = Vec::new();
    let mut truth = Vec::new();
    for k in 0..17 {
        let (nu, nv) = (50 - k % 3, 30);
        let mut points = Vec::new();
        for j in 0..nv {
            for i in 0..nu {
                let u = 600.0 * i as f64 / (nu - 1) as f64;
                let v = 300.0 * j as f64 / (nv - 1) as f64;
                // Web deflection, tilt, curvature and a waviness across the web.
                let e = -40.0 * (PI * u / 600.0).sin() * (PI * v / 300.0).sin()
                    + 8.0 * (u / 600.0 - 0.5)
                    + 5.0 * ((u - 200.0) / 300.0).powi(2) * (1.0 + 0.02 * k as f64)
                    + 3.0 * (2.0 * PI * v / 300.0).cos() * (u / 600.0);
                points.push((u, v, e));
            }
        }
        let e: Vec<f64> = points.iter().map(|p| p.2).collect();
        let norm = Normalisation::new(&domain, &e);
        sets.push(TrainingSet {
            inputs: points.iter().map(|p| norm.scale_input(p.0, p.1)).collect(),
            targets: points.iter().map(|p| norm.scale_target(p.2)).collect(),
        });
        truth.push((norm, points));
    }
    let nets = CpuTrainer::reference()
        .train_batch(&sets, &ModelConfig::default())
        .unwrap();
    for (k, (net, (norm, points))) in nets.iter().zip(&truth).enumerate() {
        let (lo, hi) = points.iter().fold((f64::MAX, f64::MIN), |(lo, hi), p| {
            (lo.min(p.2), hi.max(p.2))
        });
        let rms = (points
            .iter()
            .map(|p| (norm.unscale_output(net.forward(norm.scale_input(p.0, p.1))) - p.2).powi(2))
            .sum::<f64>()
            / points.len() as f64)
            .sqrt();
        let share = rms / ((hi - lo) / 2.0);
        eprintln!(
            "part {k}: RMS misfit {rms:.3} µm = {:.2} % of the half peak-to-valley",
            100.0 * share
        );
        assert!(
            share <= 0.01,
            "part {k}: RMS misfit {rms} µm is {share} of the amplitude"
        );
    }
}

/// A set whose size exercises every edge of the fast trainer's blocking: several chunks
/// (512 samples each), a last chunk with an odd number of blocks, a partial last block.
fn ragged_set(n: usize) -> TrainingSet {
    let mut set = TrainingSet::default();
    for s in 0..n {
        let x = [
            -1.0 + 2.0 * ((s * 37) % 101) as f32 / 100.0,
            -1.0 + 2.0 * ((s * 53) % 89) as f32 / 88.0,
        ];
        set.inputs.push(x);
        set.targets
            .push((1.7 * x[0]).sin() * (0.9 * x[1]).cos() + 0.3 * x[1]);
    }
    set
}

fn max_relative_difference(a: &[f32], b: &[f32]) -> f64 {
    let scale = b
        .iter()
        .map(|v| v.abs() as f64)
        .fold(0.0, f64::max)
        .max(1e-30);
    a.iter()
        .zip(b)
        .map(|(x, y)| (*x as f64 - *y as f64).abs())
        .fold(0.0, f64::max)
        / scale
}

#[test]
fn fast_gradient_equals_the_reference_gradient_within_rounding() {
    // FMA changes only the rounding: the gradients agree to a few f32 ulps of their scale.
    for n in [1, 7, 8, 9, 530, 1100] {
        let set = ragged_set(n);
        let net = Mlp::init(&[2, 16, 12, 1], Activation::Tanh, 11);
        let (ref_loss, reference) = loss_gradient(&net, &set).unwrap();
        let mut fast = FastGradient::new(&net, &set);
        let loss = fast.compute(&net.params, &set);
        assert!(
            (loss - ref_loss).abs() <= 1e-6 * ref_loss.max(1e-12),
            "n {n}: {loss} vs {ref_loss}"
        );
        let d = max_relative_difference(&fast.sum, &reference);
        assert!(
            d < 2e-6,
            "n {n}: gradients differ by {d:e} of their largest entry"
        );
    }
}

#[test]
fn fast_gradient_matches_the_reference_on_every_tile_edge() {
    // Odd widths leave remainder rows and columns in every register tile of the fast pass;
    // 1, 13, 40 and 530 samples leave partial blocks, tiles and chunks; 2-32-32-1 is the
    // benchmark's network. The reference gradient (plain f32, no tiling) is the judge.
    let nets = [
        Mlp::init(&[2, 7, 5, 3, 1], Activation::Tanh, 3),
        Mlp::init(&[2, 9, 1], Activation::Relu, 4),
        Mlp::init(&[2, 1, 1], Activation::Tanh, 5),
        Mlp::init(&[2, 32, 32, 1], Activation::Tanh, 6),
    ];
    for net in &nets {
        for n in [1, 13, 40, 530, 1541] {
            let set = ragged_set(n);
            let (ref_loss, reference) = loss_gradient(net, &set).unwrap();
            let mut fast = FastGradient::new(net, &set);
            let loss = fast.compute(&net.params, &set);
            assert!(
                (loss - ref_loss).abs() <= 1e-6 * ref_loss.max(1e-12),
                "{:?} n {n}: {loss} vs {ref_loss}",
                net.layer_sizes
            );
            let d = max_relative_difference(&fast.sum, &reference);
            assert!(
                d < 2e-6,
                "{:?} n {n}: gradients differ by {d:e} of their largest entry",
                net.layer_sizes
            );
            // Chunks as tasks or one after the other: the same bits.
            let parallel = fast.sum.clone();
            fast.parallel_chunks = false;
            fast.compute(&net.params, &set);
            assert_eq!(
                parallel.iter().map(|g| g.to_bits()).collect::<Vec<_>>(),
                fast.sum.iter().map(|g| g.to_bits()).collect::<Vec<_>>()
            );
        }
    }
}

#[test]
fn fast_trainer_follows_the_reference_within_its_stated_tolerance() {
    // Stated tolerance (docs/gpu.md): after 200 Adam steps, parameters within 1e-3 of the
    // largest parameter and predictions within 1e-3 (standardised units) of the reference.
    let sets = vec![
        ragged_set(700),
        ragged_set(1100),
        ragged_set(64),
        ragged_set(333),
    ];
    let config = ModelConfig {
        hidden: vec![16, 16],
        epochs: 200,
        loss_every: 50,
        ..Default::default()
    };
    let reference = CpuTrainer::reference().train_batch(&sets, &config).unwrap();
    let fast = FastCpuTrainer.train_batch(&sets, &config).unwrap();
    for (k, (f, r)) in fast.iter().zip(&reference).enumerate() {
        let d = max_relative_difference(&f.params, &r.params);
        assert!(d < 1e-3, "network {k}: parameters differ by {d:e}");
        for x in &sets[k].inputs {
            assert!((f.forward(*x) - r.forward(*x)).abs() < 1e-3);
        }
        // And both actually learned: the loss fell well below the targets' variance.
        assert!(mse(f, &sets[k]) < 0.05, "network {k} did not fit");
    }
}

#[test]
fn fast_trainer_is_bitwise_repeatable_whatever_the_thread_count() {
    let sets = vec![ragged_set(1100), ragged_set(530)];
    let config = ModelConfig {
        hidden: vec![8, 8],
        epochs: 30,
        loss_every: 30,
        ..Default::default()
    };
    let on = |threads: usize| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap()
            .install(|| FastCpuTrainer.train_batch(&sets, &config).unwrap())
    };
    let one = on(1);
    assert_eq!(bits(&one), bits(&on(2)));
    assert_eq!(bits(&one), bits(&on(3)));
}

#[test]
fn lbfgs_reaches_the_closed_form_minimiser_of_a_quadratic() {
    // f(x) = ½xᵀAx − bᵀx, A = [[4,1,0],[1,3,1],[0,1,2]], b = [1,2,3]: the minimiser solves
    // Ax = b, x = (2/9, 1/9, 13/9) (check: 4·2/9 + 1/9 = 1; 2/9 + 3/9 + 13/9 = 2; 1/9 + 26/9 = 3).
    let a = [[4.0, 1.0, 0.0], [1.0, 3.0, 1.0], [0.0, 1.0, 2.0]];
    let b = [1.0, 2.0, 3.0];
    let f = |x: &[f64]| {
        let ax: Vec<f64> = a
            .iter()
            .map(|row| row.iter().zip(x).map(|(r, v)| r * v).sum())
            .collect();
        let value = 0.5 * x.iter().zip(&ax).map(|(v, w)| v * w).sum::<f64>()
            - x.iter().zip(&b).map(|(v, w)| v * w).sum::<f64>();
        (value, ax.iter().zip(&b).map(|(w, c)| w - c).collect())
    };
    let m = lbfgs::minimize(f, vec![5.0, -3.0, 0.0], 200, 1e-8);
    let expected = [2.0 / 9.0, 1.0 / 9.0, 13.0 / 9.0];
    // Stopped at ‖∇f‖ ≤ 1e-8: |x − x*| ≤ ‖∇f‖ / λ_min(A), and λ_min(A) ≈ 1.27.
    for (got, want) in m.x.iter().zip(expected) {
        assert!((got - want).abs() < 1e-8, "{:?} vs {expected:?}", m.x);
    }
    assert_eq!(m.stop, lbfgs::Stop::Converged);
    // A quadratic in 3 unknowns takes few iterations, far fewer than the budget.
    assert!(m.evaluations < 40, "{} evaluations", m.evaluations);
}

#[test]
fn lbfgs_finds_the_rosenbrock_minimum() {
    // f = (1 − x)² + 100(y − x²)², minimum 0 at (1, 1), from the classic start (−1.2, 1).
    let f = |p: &[f64]| {
        let (x, y) = (p[0], p[1]);
        let value = (1.0 - x).powi(2) + 100.0 * (y - x * x).powi(2);
        let gx = -2.0 * (1.0 - x) - 400.0 * x * (y - x * x);
        let gy = 200.0 * (y - x * x);
        (value, vec![gx, gy])
    };
    let m = lbfgs::minimize(f, vec![-1.2, 1.0], 1000, 1e-10);
    assert!(
        (m.x[0] - 1.0).abs() < 1e-6 && (m.x[1] - 1.0).abs() < 1e-6,
        "{:?}",
        m
    );
}

#[test]
fn lbfgs_fits_networks_on_both_cpu_trainers() {
    let sets = vec![ragged_set(300), ragged_set(520)];
    let adam = ModelConfig {
        hidden: vec![16, 16],
        epochs: 150,
        loss_every: 150,
        ..Default::default()
    };
    let lbfgs = ModelConfig {
        optimizer: Optimizer::Lbfgs,
        ..adam.clone()
    };
    let by_adam = CpuTrainer::reference().train_batch(&sets, &adam).unwrap();
    for trainer in [&CpuTrainer::reference() as &dyn Trainer, &FastCpuTrainer] {
        let nets = trainer.train_batch(&sets, &lbfgs).unwrap();
        for (k, (n, a)) in nets.iter().zip(&by_adam).enumerate() {
            // With the same budget of loss evaluations L-BFGS ends far below Adam.
            let (l, la) = (mse(n, &sets[k]), mse(a, &sets[k]));
            assert!(
                l < 0.5 * la,
                "{}: set {k}: lbfgs {l:e}, adam {la:e}",
                trainer.name()
            );
        }
    }
}
