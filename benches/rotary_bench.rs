//! Rotary benches: one sphere fit from touch points, and a whole `analyze` of a synthetic campaign.

use criterion::{BenchmarkId, Criterion};
use errmap::rotary::{analyze, fit_sphere, sphere::cap_directions, AnalyzeOptions};

pub fn sphere_fit(c: &mut Criterion) {
    let mut group = c.benchmark_group("rotary/sphere_fit");
    for n in [9usize, 25, 100] {
        let pts: Vec<[f64; 3]> = cap_directions(n, 90.0, [0.0, 0.0, 1.0])
            .iter()
            .map(|d| [10.0 + 14.0 * d[0], -5.0 + 14.0 * d[1], 60.0 + 14.0 * d[2]])
            .collect();
        group.bench_with_input(BenchmarkId::from_parameter(n), &pts, |b, pts| {
            b.iter(|| fit_sphere(pts, None).unwrap())
        });
    }
    group.finish();
}

pub fn analyze_campaign(c: &mut Criterion) {
    let dir = tempfile::tempdir().unwrap();
    let config = errmap::synth::rotary::RotarySynthConfig {
        seed: 5,
        ..Default::default()
    };
    errmap::synth::rotary::write_set(dir.path(), &config).unwrap();
    let m = errmap::rotary::read_measurement(&dir.path().join("touch_points.csv")).unwrap();
    let opts = AnalyzeOptions {
        fit_axis: true,
        ..Default::default()
    };
    c.bench_function("rotary/analyze_288_sphere_fits", |b| {
        b.iter(|| analyze(&m, &opts).unwrap())
    });
}
