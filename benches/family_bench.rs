//! Benches of the family pipeline: a heatmap of the seed-001 web (117 × 57 nodes) and a whole 2-part batch on the CPU trainer.

use criterion::Criterion;
use errmap::batch::{self, BatchOptions, Job};
use errmap::nn::CpuTrainer;
use errmap::report::heatmap::{save_heatmap, Heatmap, Scale};
use errmap::synth::web_plate::{generate, WebPlateSpec};
use std::hint::black_box;

pub fn family_benches(c: &mut Criterion) {
    let dir = tempfile::tempdir().expect("temp dir");
    // A smooth bump over the web floor, 5 mm grid.
    let (nu, nv) = (117usize, 57usize);
    let values: Vec<Option<f64>> = (0..nu * nv)
        .map(|k| {
            let (i, j) = (
                (k % nu) as f64 / (nu - 1) as f64,
                (k / nu) as f64 / (nv - 1) as f64,
            );
            Some(30.0 * (std::f64::consts::PI * i).sin() * (std::f64::consts::PI * j).sin())
        })
        .collect();
    let probes: Vec<(f64, f64)> = (0..144)
        .map(|k| (25.0 + 50.0 * (k % 12) as f64, 25.0 + 22.7 * (k / 12) as f64))
        .collect();
    let png = dir.path().join("map.png");
    c.bench_function("family/heatmap_117x57_nodes_144_probes", |b| {
        b.iter(|| {
            save_heatmap(
                &png,
                &Heatmap {
                    title: "bench".into(),
                    u_name: "x",
                    v_name: "y",
                    value_label: "E (µm)",
                    u0_mm: 10.0,
                    v0_mm: 10.0,
                    step_mm: 5.0,
                    nu,
                    nv,
                    values: &values,
                    probes: &probes,
                    rejected: &probes[..3],
                    hull: &[[25.0, 25.0], [575.0, 25.0], [575.0, 275.0], [25.0, 275.0]],
                    scale: Scale::Diverging,
                    extrapolated: &[],
                },
            )
            .expect("heatmap")
        })
    });

    let data = dir.path().join("data");
    let spec = WebPlateSpec {
        parts: 2,
        epochs: 50,
        ..WebPlateSpec::default()
    };
    generate(&spec, &data, "bench").expect("synth");
    let job = Job::read(&data.join("job.toml")).expect("job");
    let plan =
        batch::plan_job(&job, &BatchOptions::default(), &dir.path().join("out")).expect("plan");
    let mut group = c.benchmark_group("family");
    group.sample_size(10);
    group.bench_function("batch_2_parts_144_probes_50_epochs_cpu", |b| {
        b.iter(|| {
            black_box(
                batch::execute(&plan, &CpuTrainer::reference(), &errmap::progress::Silent)
                    .expect("batch"),
            )
        })
    });
    group.finish();
}
