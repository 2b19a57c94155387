//! Throughput of `errmap thermal compensate`: a synthetic machine log streamed through a model
//! fitted to synthetic campaigns, on one core, into a sink.

use criterion::{BenchmarkId, Criterion, Throughput};
use errmap::synth::thermal::{write_campaigns, SynthThermalOptions};
use errmap::thermal::compensate::compensate_stream;
use errmap::thermal::{fit, Campaign, FitOptions, ThermalModel};
use rand::{Rng, SeedableRng};
use std::path::Path;

fn model() -> ThermalModel {
    let dir = tempfile::tempdir().expect("temp dir");
    let options = SynthThermalOptions {
        campaigns: 2,
        repeats: 1,
        every_s: 1800.0,
        ..Default::default()
    };
    let truth = write_campaigns(dir.path(), &options).expect("synth");
    let campaigns: Vec<Campaign> = truth
        .campaigns
        .iter()
        .map(|c| Campaign::read(&dir.path().join(&c.name)).expect("campaign"))
        .collect();
    fit(
        &campaigns,
        &FitOptions {
            order: Some(3),
            leave_one_out: false,
            ..Default::default()
        },
    )
    .expect("fit")
}

/// A machine log of `rows` rows: nut in Ω (Pt100), bearing and room in °C, two coolant states.
fn log(rows: usize) -> Vec<u8> {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(42);
    let mut text = String::with_capacity(rows * 60);
    text.push_str("time_s,position_mm,direction,nut,bearing,ambient_c,coolant\n");
    for i in 0..rows {
        let x: f64 = rng.random_range(0.0..500.0);
        let warm = (i as f64 / rows as f64) * 6.0;
        let nut_c = 20.0 + warm;
        let nut_ohm = 100.0 * (1.0 + 3.9083e-3 * nut_c - 5.775e-7 * nut_c * nut_c);
        text.push_str(&format!(
            "{:.3},{:.3},{},{:.3},{:.3},{:.3},{}\n",
            i as f64 * 0.004,
            x,
            if i % 2 == 0 { '+' } else { '-' },
            nut_ohm,
            20.0 + warm * 0.5,
            20.0 + warm * 0.05,
            if (i / 1000) % 2 == 0 { "off" } else { "on" }
        ));
    }
    text.into_bytes()
}

pub fn compensate_throughput(c: &mut Criterion) {
    let model = model();
    let mut group = c.benchmark_group("thermal/compensate");
    for rows in [10_000usize, 200_000] {
        let input = log(rows);
        group.throughput(Throughput::Elements(rows as u64));
        group.bench_with_input(BenchmarkId::from_parameter(rows), &input, |b, input| {
            b.iter(|| {
                compensate_stream(
                    &model,
                    input.as_slice(),
                    Path::new("bench.csv"),
                    std::io::sink(),
                )
                .expect("compensate")
            })
        });
    }
    group.finish();
}
