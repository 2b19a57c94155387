//! Training and map-evaluation throughput: CPU reference vs wgpu (lavapipe or a hardware GPU), families of 1, 8 and 32 parts.
//!
//! Workload (mirrored by benches/peers/peers.py): each part is a 48 × 32 grid (1536 samples)
//! of a ±40 µm web-plate deflection field over 600 × 300 mm, standardised; MLP 2-32-32-1 tanh,
//! full-batch Adam, `EPOCHS` epochs per iteration. Throughput unit: sample·epochs.

use std::hint::black_box;

use criterion::{BenchmarkId, Criterion, Throughput};
use errmap::geom::Domain;
use errmap::gpu::GpuTrainer;
use errmap::nn::{CpuTrainer, ModelConfig, Normalisation, Trainer, TrainingSet};

pub const EPOCHS: u32 = 10;
pub const GRID_U: usize = 48;
pub const GRID_V: usize = 32;

fn domain() -> Domain {
    Domain {
        u_min_mm: 0.0,
        v_min_mm: 0.0,
        u_max_mm: 600.0,
        v_max_mm: 300.0,
    }
}

/// e(u, v) of part k in µm (the same formula as peers.py).
pub fn field_um(u_mm: f64, v_mm: f64, k: usize) -> f64 {
    use std::f64::consts::PI;
    -40.0 * (PI * u_mm / 600.0).sin() * (PI * v_mm / 300.0).sin()
        + 6.0 * (u_mm / 600.0 - 0.5)
        + 0.5 * k as f64 * (v_mm / 300.0)
}

pub fn family(parts: usize) -> Vec<TrainingSet> {
    (0..parts)
        .map(|k| {
            let points: Vec<(f64, f64, f64)> = (0..GRID_V)
                .flat_map(|j| (0..GRID_U).map(move |i| (i, j)))
                .map(|(i, j)| {
                    let u = 600.0 * i as f64 / (GRID_U - 1) as f64;
                    let v = 300.0 * j as f64 / (GRID_V - 1) as f64;
                    (u, v, field_um(u, v, k))
                })
                .collect();
            let e: Vec<f64> = points.iter().map(|p| p.2).collect();
            let norm = Normalisation::new(&domain(), &e);
            TrainingSet {
                inputs: points.iter().map(|p| norm.scale_input(p.0, p.1)).collect(),
                targets: points.iter().map(|p| norm.scale_target(p.2)).collect(),
            }
        })
        .collect()
}

fn gpu_or_note() -> Option<GpuTrainer> {
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
            b.iter(|| black_box(CpuTrainer.train_batch(sets, &config).unwrap()))
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
        b.iter(|| black_box(CpuTrainer.evaluate_batch(&nets, &inputs).unwrap()))
    });
    if let Some(gpu) = &gpu {
        group.bench_function("gpu", |b| {
            b.iter(|| black_box(gpu.evaluate_batch(&nets, &inputs).unwrap()))
        });
    }
    group.finish();
}

criterion::criterion_group!(benches, training, grid_evaluation);
