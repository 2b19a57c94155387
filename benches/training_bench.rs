//! Training and map-evaluation throughput: the CPU reference, the fast CPU trainer and wgpu (lavapipe or a hardware GPU), families of 1, 8 and 32 parts.
//!
//! Workload (mirrored by benches/peers/peers.py): each part is a 48 × 32 grid (1536 samples)
//! of a ±40 µm web-plate deflection field over 600 × 300 mm, standardised; MLP 2-32-32-1 tanh,
//! full-batch Adam, `EPOCHS` epochs per iteration. Throughput unit: sample·epochs.

use std::hint::black_box;

use criterion::{BenchmarkId, Criterion, Throughput};
use errmap::gpu::GpuTrainer;
use errmap::nn::{CpuTrainer, FastCpuTrainer, ModelConfig, Normalisation, Trainer, TrainingSet};

#[path = "../tests/common/plate_sets.rs"]
mod plate_sets;
use plate_sets::{domain, sets};

pub const EPOCHS: u32 = 10;
pub const GRID_U: usize = 48;
pub const GRID_V: usize = 32;

/// Part k of the family is a GRID_U × GRID_V grid of the shared plate field.
pub fn family(parts: usize) -> Vec<TrainingSet> {
    sets(&vec![(GRID_U, GRID_V); parts]).0
}

fn gpu_or_note() -> Option<GpuTrainer> {
    // Benchmarks run one at a time on the main thread: no Vulkan thread exists yet.
    errmap::gpu::quiet_headless_vulkan();
    match GpuTrainer::new() {
        Ok(gpu) => {
            eprintln!("training bench on {}", gpu.name());
            Some(gpu)
        }
        Err(e) => {
            eprintln!("training bench: GPU benchmarks skipped ({e})");
            None
        }
    }
}

pub fn training(c: &mut Criterion) {
    let gpu = gpu_or_note();
    let config = ModelConfig {
        epochs: EPOCHS,
        loss_every: EPOCHS,
        ..Default::default()
    };
    let mut group = c.benchmark_group("training");
    group.sample_size(10);
    group.warm_up_time(std::time::Duration::from_secs(1));
    group.measurement_time(std::time::Duration::from_secs(10));
    for parts in [1usize, 8, 32] {
        let sets = family(parts);
        let samples: usize = sets.iter().map(|s| s.len()).sum();
        group.throughput(Throughput::Elements(samples as u64 * EPOCHS as u64));
        group.bench_with_input(BenchmarkId::new("cpu", parts), &sets, |b, sets| {
            b.iter(|| black_box(CpuTrainer::reference().train_batch(sets, &config).unwrap()))
        });
        group.bench_with_input(BenchmarkId::new("cpu-fast", parts), &sets, |b, sets| {
            b.iter(|| black_box(FastCpuTrainer.train_batch(sets, &config).unwrap()))
        });
        if let Some(gpu) = &gpu {
            group.bench_with_input(BenchmarkId::new("gpu", parts), &sets, |b, sets| {
                b.iter(|| black_box(gpu.train_batch(sets, &config).unwrap()))
            });
        }
    }
    group.finish();
}

/// One trained-shape network evaluated on a 600 × 300 mm grid at 0.5 mm (721 801 nodes).
pub fn grid_evaluation(c: &mut Criterion) {
    let gpu = gpu_or_note();
    let config = ModelConfig::default();
    let nets = errmap::nn::initial_networks(1, &config);
    let norm = Normalisation::new(&domain(), &[0.0, 1.0]);
    let step_mm = 0.5;
    let (nu, nv) = (1201usize, 601usize);
    let inputs: Vec<[f32; 2]> = (0..nv)
        .flat_map(|j| (0..nu).map(move |i| (i, j)))
        .map(|(i, j)| norm.scale_input(i as f64 * step_mm, j as f64 * step_mm))
        .collect();
    let mut group = c.benchmark_group("grid_evaluation_600x300mm_0.5mm");
    group.sample_size(10);
    group.throughput(Throughput::Elements(inputs.len() as u64));
    group.bench_function("cpu", |b| {
        b.iter(|| {
            black_box(
                CpuTrainer::reference()
                    .evaluate_batch(&nets, &inputs)
                    .unwrap(),
            )
        })
    });
    if let Some(gpu) = &gpu {
        group.bench_function("gpu", |b| {
            b.iter(|| black_box(gpu.evaluate_batch(&nets, &inputs).unwrap()))
        });
    }
    group.finish();
}

criterion::criterion_group!(benches, training, grid_evaluation);
