//! GPU (wgpu, lavapipe on CI) against the CPU reference trainer: training parity of both kernel families, evaluation parity, batch splitting, struct layouts.
//!
//! Without an adapter these tests print why they skip, unless ERRMAP_REQUIRE_GPU=1, where they fail.
//! The hardware kernels are compared with `CpuTrainer::with_lanes(GRAD_LANES)` (their order);
//! the CPU-adapter kernels with `CpuTrainer::reference()`, bit for bit.

#[path = "common/plate_sets.rs"]
mod plate_sets;

use std::sync::OnceLock;

use errmap::gpu::layout::{Dims, LayerInfo, NetInfo, Sample, Step};
use errmap::gpu::{GpuTrainer, KernelFamily};
use errmap::nn::*;
use plate_sets::sets;

/// A trainer with the hardware-GPU kernels, on whatever adapter there is.
fn gpu(test: &str) -> Option<&'static GpuTrainer> {
    static TRAINER: OnceLock<Result<GpuTrainer, String>> = OnceLock::new();
    trainer(test, &TRAINER, KernelFamily::Hardware)
}

/// A trainer with the CPU-adapter kernels (src/gpu/lavapipe.rs), on whatever adapter there is.
fn cpu_adapter(test: &str) -> Option<&'static GpuTrainer> {
    static TRAINER: OnceLock<Result<GpuTrainer, String>> = OnceLock::new();
    trainer(test, &TRAINER, KernelFamily::CpuAdapter)
}

fn trainer(
    test: &str,
    cell: &'static OnceLock<Result<GpuTrainer, String>>,
    family: KernelFamily,
) -> Option<&'static GpuTrainer> {
    static ENV: OnceLock<()> = OnceLock::new();
    // Every test that opens Vulkan calls this first, so the variable is set before any does.
    ENV.get_or_init(errmap::gpu::quiet_headless_vulkan);
    match cell.get_or_init(|| {
        GpuTrainer::new()
            // No pipeline cache files from these tests (tests/gpu_pipeline_cache.rs has its own).
            .map(|t| t.with_kernels(family).with_pipeline_cache_dir(None))
            .map_err(|e| e.to_string())
    }) {
        Ok(trainer) => Some(trainer),
        Err(reason) => {
            if std::env::var("ERRMAP_REQUIRE_GPU").as_deref() == Ok("1") {
                panic!("{test}: ERRMAP_REQUIRE_GPU=1 but no GPU trainer: {reason}");
            }
            eprintln!("SKIPPED {test}: no GPU adapter ({reason})");
            None
        }
    }
}

fn grid_inputs(norm: &Normalisation, step_mm: f64) -> Vec<[f32; 2]> {
    let (nu, nv) = (
        (600.0 / step_mm) as usize + 1,
        (300.0 / step_mm) as usize + 1,
    );
    (0..nv)
        .flat_map(|j| (0..nu).map(move |i| (i, j)))
        .map(|(i, j)| norm.scale_input(i as f64 * step_mm, j as f64 * step_mm))
        .collect()
}

#[test]
fn training_matches_cpu_after_200_adam_steps() {
    let Some(gpu) = gpu("training_matches_cpu_after_200_adam_steps") else {
        return;
    };
    // Four networks of 40 to 273 samples (none a multiple of the 64 gradient lanes).
    let (sets, norms) = sets(&[(8, 5), (13, 10), (15, 9), (21, 13)]);
    let config = ModelConfig {
        hidden: vec![24, 16],
        epochs: 200,
        loss_every: 50,
        ..Default::default()
    };
    let initial = initial_networks(sets.len(), &config);
    let cpu = CpuTrainer::with_lanes(GRAD_LANES)
        .unwrap()
        .train_from(initial.clone(), &sets, &config)
        .unwrap();
    let on_gpu = gpu.train_from(initial.clone(), &sets, &config).unwrap();
    assert_eq!(on_gpu.len(), 4);
    for (k, ((c, g), start)) in cpu.iter().zip(&on_gpu).zip(&initial).enumerate() {
        assert_eq!(g.layer_sizes, c.layer_sizes);
        // Training moved the parameters well beyond the tolerance.
        let moved = c
            .params
            .iter()
            .zip(&start.params)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0f32, f32::max);
        assert!(moved > 0.1, "network {k} barely trained ({moved})");
        // Relative on the parameter vector: the largest difference against the largest
        // parameter (∞-norm), and the Euclidean norms. A single parameter near zero has no
        // meaningful relative error of its own.
        let largest = c.params.iter().fold(0.0f32, |m, p| m.max(p.abs()));
        let worst = c
            .params
            .iter()
            .zip(&g.params)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0f32, f32::max);
        let norm =
            |v: &mut dyn Iterator<Item = f32>| v.map(|x| (x as f64).powi(2)).sum::<f64>().sqrt();
        let diff_norm = norm(&mut c.params.iter().zip(&g.params).map(|(a, b)| a - b));
        let param_norm = norm(&mut c.params.iter().copied());
        eprintln!(
            "network {k} ({} samples): max |Δp| / max |p| = {:.2e}, ‖Δp‖ / ‖p‖ = {:.2e}",
            sets[k].len(),
            worst / largest,
            diff_norm / param_norm
        );
        assert!(
            worst <= 1e-3 * largest,
            "network {k}: max |Δp| {worst} vs max |p| {largest}"
        );
        assert!(
            diff_norm <= 1e-3 * param_norm,
            "network {k}: ‖Δp‖ {diff_norm} vs ‖p‖ {param_norm}"
        );
        // Final maps, unscaled to µm on a 600 × 300 mm grid at 5 mm.
        let inputs = grid_inputs(&norms[k], 5.0);
        let map = |net: &Mlp| -> Vec<f64> {
            inputs
                .iter()
                .map(|&x| norms[k].unscale_output(net.forward(x)))
                .collect()
        };
        let (mc, mg) = (map(c), map(g));
        let rms = (mc
            .iter()
            .zip(&mg)
            .map(|(a, b)| (a - b).powi(2))
            .sum::<f64>()
            / mc.len() as f64)
            .sqrt();
        eprintln!("network {k}: maps differ by {rms:.2e} µm RMS");
        assert!(rms <= 0.05, "network {k}: maps differ by {rms} µm RMS");
    }
}

/// Both kernel families: narrow layers train with the kernels generated per architecture
/// (src/gpu/fixed.rs, tanh and relu), wider ones with the generic kernels of
/// shaders/train.wgsl, and mixes. Each must follow the CPU reference within 1e-3 (∞-norm relative).
#[test]
fn generated_and_generic_kernels_match_cpu() {
    let Some(gpu) = gpu("generated_and_generic_kernels_match_cpu") else {
        return;
    };
    let (sets, _) = sets(&[(9, 7), (12, 11)]);
    for (hidden, activation) in [
        (vec![12, 8], Activation::Relu),
        (vec![70], Activation::Tanh),
        (vec![5, 66], Activation::Tanh),
        // Generated forward kernel (64 wide), generic gradient kernel (64 inputs).
        (vec![64], Activation::Tanh),
    ] {
        let config = ModelConfig {
            hidden: hidden.clone(),
            activation,
            epochs: 60,
            loss_every: 30,
            ..Default::default()
        };
        let initial = initial_networks(sets.len(), &config);
        let cpu = CpuTrainer::with_lanes(GRAD_LANES)
            .unwrap()
            .train_from(initial.clone(), &sets, &config)
            .unwrap();
        let on_gpu = gpu.train_from(initial.clone(), &sets, &config).unwrap();
        for (k, ((c, g), start)) in cpu.iter().zip(&on_gpu).zip(&initial).enumerate() {
            let largest = c.params.iter().fold(0.0f32, |m, p| m.max(p.abs()));
            let max_diff = |a: &[f32], b: &[f32]| {
                a.iter()
                    .zip(b)
                    .map(|(x, y)| (x - y).abs())
                    .fold(0.0f32, f32::max)
            };
            let moved = max_diff(&c.params, &start.params);
            let worst = max_diff(&c.params, &g.params);
            assert!(
                moved > 0.05,
                "{hidden:?} network {k} barely trained ({moved})"
            );
            assert!(
                worst <= 1e-3 * largest,
                "{hidden:?} {activation:?} network {k}: max |Δp| {worst} vs max |p| {largest}"
            );
        }
    }
}

#[test]
fn gpu_training_is_bitwise_repeatable_and_split_invariant() {
    let Some(gpu) = gpu("gpu_training_is_bitwise_repeatable_and_split_invariant") else {
        return;
    };
    let (sets, _) = sets(&[(9, 7), (12, 6), (10, 10)]);
    let config = ModelConfig {
        hidden: vec![16, 8],
        epochs: 30,
        loss_every: 7,
        ..Default::default()
    };
    let bits = |nets: &[Mlp]| -> Vec<u32> {
        nets.iter()
            .flat_map(|n| n.params.iter().map(|p| p.to_bits()))
            .collect()
    };
    let a = gpu.train_batch(&sets, &config).unwrap();
    let b = gpu.train_batch(&sets, &config).unwrap();
    assert_eq!(bits(&a), bits(&b));
    // A buffer limit that admits one network at a time forces three groups.
    let units = 16 + 8 + 1;
    let tiny = GpuTrainer::new()
        .unwrap()
        .with_kernels(KernelFamily::Hardware)
        .with_buffer_limit(120 * units as u64 * 4);
    let split = tiny.train_batch(&sets, &config).unwrap();
    assert_eq!(bits(&split), bits(&a));
}

#[test]
fn evaluation_matches_cpu_within_1e_4_um() {
    let Some(gpu) = gpu("evaluation_matches_cpu_within_1e_4_um") else {
        return;
    };
    let (sets, norms) = sets(&[(12, 8), (10, 6)]);
    let config = ModelConfig {
        epochs: 150,
        ..Default::default()
    };
    let nets = CpuTrainer::with_lanes(GRAD_LANES)
        .unwrap()
        .train_batch(&sets, &config)
        .unwrap();
    // A mixed batch: two trained tanh networks, then a relu network of another shape.
    let mut all = nets.clone();
    all.push(Mlp::init(&[2, 7, 5, 1], Activation::Relu, 9));
    let inputs = grid_inputs(&norms[0], 2.0);
    let cpu = CpuTrainer::with_lanes(GRAD_LANES)
        .unwrap()
        .evaluate_batch(&all, &inputs)
        .unwrap();
    let on_gpu = gpu.evaluate_batch(&all, &inputs).unwrap();
    assert_eq!(on_gpu.len(), 3);
    for (k, (c, g)) in cpu.iter().zip(&on_gpu).enumerate() {
        assert_eq!(g.len(), inputs.len());
        let norm = &norms[k.min(1)];
        let worst = c
            .iter()
            .zip(g)
            .map(|(&a, &b)| (norm.unscale_output(a) - norm.unscale_output(b)).abs())
            .fold(0.0f64, f64::max);
        assert!(
            worst <= 1e-4,
            "network {k}: GPU and CPU maps differ by {worst} µm"
        );
    }
    assert!(gpu
        .evaluate_batch(&all, &[])
        .unwrap()
        .iter()
        .all(|v| v.is_empty()));
}

#[test]
fn gpu_rejects_shapes_it_cannot_hold() {
    let Some(gpu) = gpu("gpu_rejects_shapes_it_cannot_hold") else {
        return;
    };
    let wide = Mlp::init(&[2, 300, 1], Activation::Tanh, 1);
    let err = gpu.evaluate_batch(&[wide], &[[0.0, 0.0]]).unwrap_err();
    assert!(err.to_string().contains("width"), "{err}");
    let mut broken = Mlp::init(&[2, 4, 1], Activation::Tanh, 1);
    broken.params.pop();
    let err = gpu.evaluate_batch(&[broken], &[[0.0, 0.0]]).unwrap_err();
    assert_eq!(err.kind(), "input", "{err}");
    assert!(err.to_string().contains("parameters, it has"), "{err}");
}

/// Struct layouts of the host mirrors against the WGSL declarations, as naga lays them out.
#[test]
fn host_structs_match_wgsl_layouts() {
    use std::mem::{offset_of, size_of};
    use wgpu::naga;
    let mut checked = 0;
    for source in [
        errmap::gpu::train::TRAIN_WGSL,
        errmap::gpu::evaluate::EVALUATE_WGSL,
    ] {
        let module = naga::front::wgsl::parse_str(source).expect("shader parses");
        for (_, ty) in module.types.iter() {
            let naga::TypeInner::Struct { members, span } = &ty.inner else {
                continue;
            };
            let fields: Vec<(String, u32)> = members
                .iter()
                .map(|m| (m.name.clone().unwrap_or_default(), m.offset))
                .collect();
            let expected: (usize, Vec<(&str, usize)>) = match ty.name.as_deref() {
                Some("LayerInfo") => (
                    size_of::<LayerInfo>(),
                    vec![
                        ("inputs", offset_of!(LayerInfo, inputs)),
                        ("outputs", offset_of!(LayerInfo, outputs)),
                        ("weight_offset", offset_of!(LayerInfo, weight_offset)),
                        ("unit_offset", offset_of!(LayerInfo, unit_offset)),
                    ],
                ),
                Some("Dims") => (
                    size_of::<Dims>(),
                    vec![
                        ("net_count", offset_of!(Dims, net_count)),
                        ("param_count", offset_of!(Dims, param_count)),
                        ("layer_count", offset_of!(Dims, layer_count)),
                        ("unit_count", offset_of!(Dims, unit_count)),
                        ("sample_count", offset_of!(Dims, sample_count)),
                        ("activation", offset_of!(Dims, activation)),
                        ("_pad0", offset_of!(Dims, _pad0)),
                        ("_pad1", offset_of!(Dims, _pad1)),
                        ("layers", offset_of!(Dims, layers)),
                    ],
                ),
                Some("NetInfo") => (
                    size_of::<NetInfo>(),
                    vec![
                        ("sample_offset", offset_of!(NetInfo, sample_offset)),
                        ("sample_count", offset_of!(NetInfo, sample_count)),
                        ("act_offset", offset_of!(NetInfo, act_offset)),
                        ("grad_scale", offset_of!(NetInfo, grad_scale)),
                    ],
                ),
                Some("Sample") => (
                    size_of::<Sample>(),
                    vec![
                        ("x", offset_of!(Sample, x)),
                        ("y", offset_of!(Sample, y)),
                        ("target_value", offset_of!(Sample, target_value)),
                        ("net", offset_of!(Sample, net)),
                    ],
                ),
                Some("Step") => (
                    size_of::<Step>(),
                    vec![
                        ("learning_rate", offset_of!(Step, learning_rate)),
                        ("correction1", offset_of!(Step, correction1)),
                        ("correction2", offset_of!(Step, correction2)),
                        ("_pad", offset_of!(Step, _pad)),
                    ],
                ),
                other => panic!("WGSL struct {other:?} has no host mirror in this test"),
            };
            assert_eq!(*span as usize, expected.0, "size of {:?}", ty.name);
            let expected: Vec<(String, u32)> = expected
                .1
                .into_iter()
                .map(|(n, o)| (n.to_string(), o as u32))
                .collect();
            assert_eq!(fields, expected, "fields of {:?}", ty.name);
            checked += 1;
        }
    }
    // LayerInfo and Dims in both shaders, NetInfo, Sample, Step in train.wgsl.
    assert_eq!(checked, 7);
}

#[test]
fn backend_selection_follows_the_documented_order() {
    use errmap::backend::probe::{probe_key, Measure, Verdict};
    use errmap::backend::{select_trainer_cached_in, silent};
    let config = ModelConfig::default();
    let select = |backend, cache: Option<std::path::PathBuf>| {
        select_trainer_cached_in(backend, &config, silent(), cache)
    };
    let cpu = select(Backend::Cpu, None).unwrap();
    assert_eq!(cpu.backend, Backend::Cpu);
    assert!(
        cpu.trainer.name().starts_with("cpu ("),
        "{}",
        cpu.trainer.name()
    );
    let reference = select(Backend::CpuReference, None).unwrap();
    assert_eq!(reference.trainer.name(), "cpu-reference");
    let Some(gpu) = gpu("backend_selection_follows_the_documented_order") else {
        // Without any adapter, auto takes the fast CPU trainer and gpu is a device error.
        assert_eq!(select(Backend::Auto, None).unwrap().backend, Backend::Cpu);
        let err = select(Backend::Gpu, None).err().unwrap();
        assert_eq!(err.kind(), "device", "{err}");
        return;
    };
    let forced = select(Backend::Gpu, None).unwrap();
    assert_eq!(forced.trainer.name(), gpu.name());
    // auto follows the probe's figures: planted in its cache, either way round.
    let dir = tempfile::tempdir().unwrap();
    let cache = dir.path().join("backend-probe.json");
    let measure = |backend: &str, rate: f64| Measure {
        backend: backend.into(),
        device: "planted".into(),
        sample_epochs_per_s: rate,
        pipeline_build_s: 0.0,
    };
    for (cpu_rate, gpu_rate, expected) in [(1e6, 2e6, Backend::Gpu), (2e6, 1e6, Backend::Cpu)] {
        let verdict = Verdict {
            cpu: measure("cpu", cpu_rate),
            gpu: measure("gpu", gpu_rate),
            cached: false,
        };
        let planted = std::collections::BTreeMap::from([(probe_key(gpu, &config), verdict)]);
        std::fs::write(&cache, serde_json::to_string(&planted).unwrap()).unwrap();
        let auto = select(Backend::Auto, Some(cache.clone())).unwrap();
        assert_eq!(auto.backend, expected, "{}", auto.reason);
        assert!(auto.reason.contains("measured earlier"), "{}", auto.reason);
    }
    // With no cache entry, a software adapter is not waited for (its first kernel build takes
    // tens of seconds): auto trains on the CPU and says why. A hardware adapter is measured.
    std::fs::remove_file(&cache).unwrap();
    let auto = select(Backend::Auto, Some(cache.clone())).unwrap();
    if gpu.context().adapter.software {
        assert_eq!(auto.backend, Backend::Cpu, "{}", auto.reason);
        assert!(auto.reason.contains("not measured yet"), "{}", auto.reason);
    } else {
        assert!(auto.reason.contains("measured now"), "{}", auto.reason);
    }
    // The probe (what `errmap gpu-info` runs) measures both and records its figures.
    let _ = std::fs::remove_file(&cache);
    let verdict =
        errmap::backend::probe::compare_cached_in(gpu, &config, Some(cache.clone())).unwrap();
    assert!(!verdict.cached);
    let recorded: std::collections::BTreeMap<String, Verdict> =
        serde_json::from_str(&std::fs::read_to_string(&cache).unwrap()).unwrap();
    let stored = &recorded[&probe_key(gpu, &config)];
    assert!(stored.cpu.sample_epochs_per_s > 0.0 && stored.gpu.sample_epochs_per_s > 0.0);
    assert_eq!(stored.cpu, verdict.cpu);
    let auto = select(Backend::Auto, Some(cache.clone())).unwrap();
    assert_eq!(
        auto.backend == Backend::Gpu,
        verdict.gpu_is_faster(),
        "{}",
        auto.reason
    );
}

/// Batch splitting is planned from the limits alone (no device needed).
#[test]
fn batches_split_under_buffer_and_dispatch_limits() {
    use errmap::gpu::train::plan_groups;
    let set = |n: usize| TrainingSet {
        inputs: vec![[0.0, 0.0]; n],
        targets: vec![0.0; n],
    };
    let sets = vec![set(100), set(100), set(50), set(200)];
    let units = 10u64;
    // 9 000 bytes hold the activations of 225 samples (10 units × 4 bytes each):
    // 100 + 100 fit, + 50 does not; 50 + 200 does not; 200 alone does.
    let groups = plan_groups(9_000, 65_535, &sets, units, 20).unwrap();
    assert_eq!(groups, vec![0..2, 2..3, 3..4]);
    // Everything fits in one group when the limit allows it.
    assert_eq!(
        plan_groups(1 << 30, 65_535, &sets, units, 20).unwrap(),
        vec![0..4]
    );
    // At most two networks per dispatch.
    assert_eq!(
        plan_groups(1 << 30, 2, &sets, units, 20).unwrap(),
        vec![0..2, 2..4]
    );
    // A network that cannot fit alone is a device error naming it.
    let err = plan_groups(3_999, 65_535, &sets, units, 20).unwrap_err();
    assert_eq!(err.kind(), "device");
    assert!(
        err.to_string().contains("training set 0 (100 samples)"),
        "{err}"
    );
}

fn bits(nets: &[Mlp]) -> Vec<u32> {
    nets.iter()
        .flat_map(|n| n.params.iter().map(|p| p.to_bits()))
        .collect()
}

/// The CPU-adapter kernels do the reference's f32 operations in the reference's order
/// (8 lanes, tree +4 +2 +1), so after 200 Adam steps every parameter has the same bits as
/// `CpuTrainer::reference()`, for networks of different training-set sizes (none a multiple
/// of 8), the default architecture and a relu one.
#[test]
fn cpu_adapter_kernels_match_the_reference_bit_for_bit() {
    let Some(gpu) = cpu_adapter("cpu_adapter_kernels_match_the_reference_bit_for_bit") else {
        return;
    };
    // 40, 130, 135 and 273 samples.
    let (sets, norms) = sets(&[(8, 5), (13, 10), (15, 9), (21, 13)]);
    for (hidden, activation) in [
        (vec![32, 32], Activation::Tanh),
        (vec![12, 8], Activation::Relu),
    ] {
        let config = ModelConfig {
            hidden: hidden.clone(),
            activation,
            epochs: 200,
            loss_every: 50,
            ..Default::default()
        };
        let initial = initial_networks(sets.len(), &config);
        let reference = CpuTrainer::reference()
            .train_from(initial.clone(), &sets, &config)
            .unwrap();
        let on_gpu = gpu.train_from(initial.clone(), &sets, &config).unwrap();
        assert_eq!(on_gpu.len(), sets.len());
        for (k, ((c, g), start)) in reference.iter().zip(&on_gpu).zip(&initial).enumerate() {
            assert_eq!(g.layer_sizes, c.layer_sizes);
            let moved = c
                .params
                .iter()
                .zip(&start.params)
                .map(|(a, b)| (a - b).abs())
                .fold(0.0f32, f32::max);
            assert!(
                moved > 0.1,
                "{hidden:?} network {k} barely trained ({moved})"
            );
            for (i, (a, b)) in c.params.iter().zip(&g.params).enumerate() {
                assert_eq!(
                    a.to_bits(),
                    b.to_bits(),
                    "{hidden:?} {activation:?} network {k} parameter {i}: reference {a:e}, kernel {b:e}"
                );
            }
            // The maps (µm on a 5 mm grid), compared independently of the bits.
            let inputs = grid_inputs(&norms[k], 5.0);
            let map = |net: &Mlp| -> Vec<f64> {
                inputs
                    .iter()
                    .map(|&x| norms[k].unscale_output(net.forward(x)))
                    .collect()
            };
            let (mc, mg) = (map(c), map(g));
            let rms = (mc
                .iter()
                .zip(&mg)
                .map(|(a, b)| (a - b).powi(2))
                .sum::<f64>()
                / mc.len() as f64)
                .sqrt();
            assert!(rms <= 0.05, "network {k}: maps differ by {rms} µm RMS");
        }
    }
}

/// Run to run the same bits; a batch larger than one uniform binding holds (15 networks of
/// 1185 parameters: 13 fit 64 KiB) and a batch split by the buffer limit give the bits of
/// the reference too.
#[test]
fn cpu_adapter_kernels_are_repeatable_and_split_invariant() {
    let Some(gpu) = cpu_adapter("cpu_adapter_kernels_are_repeatable_and_split_invariant") else {
        return;
    };
    let sizes: Vec<(usize, usize)> = (0..15).map(|k| (4 + k % 3, 3 + k % 4)).collect();
    let (sets, _) = sets(&sizes);
    let config = ModelConfig {
        epochs: 25,
        loss_every: 7,
        ..Default::default()
    };
    let a = gpu.train_batch(&sets, &config).unwrap();
    let b = gpu.train_batch(&sets, &config).unwrap();
    assert_eq!(bits(&a), bits(&b));
    let reference = CpuTrainer::reference().train_batch(&sets, &config).unwrap();
    assert_eq!(bits(&a), bits(&reference));
    // A buffer limit that admits about one network's moments at a time forces 15 groups.
    let tiny = GpuTrainer::new()
        .unwrap()
        .with_kernels(KernelFamily::CpuAdapter)
        .with_buffer_limit(2 * 1200 * 4)
        .with_pipeline_cache_dir(None);
    let split = tiny.train_batch(&sets[..3], &config).unwrap();
    assert_eq!(bits(&split), bits(&a[..3]));
}

/// Architectures the CPU-adapter family does not take (here 5 251 parameters) train with the
/// hardware kernels: the same bits as a trainer that asks for those.
#[test]
fn cpu_adapter_family_falls_back_to_the_hardware_kernels() {
    let Some(gpu) = cpu_adapter("cpu_adapter_family_falls_back_to_the_hardware_kernels") else {
        return;
    };
    let hardware = self::gpu("cpu_adapter_family_falls_back_to_the_hardware_kernels").unwrap();
    let (sets, _) = sets(&[(6, 5), (7, 4)]);
    let config = ModelConfig {
        hidden: vec![70, 70],
        epochs: 10,
        loss_every: 5,
        ..Default::default()
    };
    assert!(errmap::nn::param_count(&config.layer_sizes()) > errmap::gpu::lavapipe::MAX_CPU_PARAMS);
    let a = gpu.train_batch(&sets, &config).unwrap();
    let b = hardware.train_batch(&sets, &config).unwrap();
    assert_eq!(bits(&a), bits(&b));
}

/// The host mirrors of the CPU-adapter kernels' own structs against their generated WGSL
/// (the one-epoch kernel with and without subgroups, and the many-epoch kernel).
#[test]
fn cpu_adapter_structs_match_the_generated_wgsl() {
    use errmap::gpu::lavapipe::many_epochs::{epochs_source, RunInfo};
    use errmap::gpu::lavapipe::{epoch_source, AdamConstants, BatchInfo};
    use std::mem::size_of;
    use wgpu::naga;
    let sources = [
        epoch_source(&[2, 3, 1], Activation::Tanh, 16, 2, false).unwrap(),
        epoch_source(&[2, 3, 1], Activation::Tanh, 16, 2, true).unwrap(),
        epochs_source(&[2, 3, 1], Activation::Tanh).unwrap(),
    ];
    for (i, source) in sources.iter().enumerate() {
        let module = naga::front::wgsl::parse_str(source).expect("generated WGSL parses");
        let mut seen = 0;
        for (_, ty) in module.types.iter() {
            let naga::TypeInner::Struct { members, span } = &ty.inner else {
                continue;
            };
            let offsets: Vec<u32> = members.iter().map(|m| m.offset).collect();
            let (size, count) = match ty.name.as_deref() {
                Some("AdamConstants") => (size_of::<AdamConstants>(), 8),
                Some("BatchInfo") => (size_of::<BatchInfo>(), 4),
                Some("RunInfo") => (size_of::<RunInfo>(), 4),
                Some("NetInfo") => (size_of::<NetInfo>(), 4),
                Some("Sample") => (size_of::<Sample>(), 4),
                Some("Step") => (size_of::<Step>(), 4),
                _ => continue,
            };
            // Every field a 4-byte scalar, in order, no padding.
            assert_eq!(*span as usize, size, "{:?}", ty.name);
            assert_eq!(offsets, (0..count).map(|i| 4 * i).collect::<Vec<u32>>());
            seen += 1;
        }
        assert_eq!(seen, 5, "kernel {i}");
    }
}

/// Without subgroup operations the lanes meet in workgroup memory (two chunks of at most
/// 512 parameters for 2-32-16-1's 641): the same bits as the reference.
#[test]
fn cpu_adapter_workgroup_memory_reduction_matches_the_reference() {
    if cpu_adapter("cpu_adapter_workgroup_memory_reduction_matches_the_reference").is_none() {
        return;
    }
    let gpu = GpuTrainer::new()
        .unwrap()
        .with_kernels(KernelFamily::CpuAdapter)
        .without_subgroups()
        .with_pipeline_cache_dir(None);
    let (sets, _) = sets(&[(7, 5), (9, 6), (5, 5), (11, 4)]);
    let config = ModelConfig {
        hidden: vec![32, 16],
        epochs: 40,
        loss_every: 20,
        ..Default::default()
    };
    let reference = CpuTrainer::reference().train_batch(&sets, &config).unwrap();
    let on_gpu = gpu.train_batch(&sets, &config).unwrap();
    assert_eq!(bits(&on_gpu), bits(&reference));
}
