//! Benchmarks of the linear-axis code: evaluation by standard, air index, pitch fit, table rendering.

use criterion::{criterion_group, Criterion};
use errmap::linear::{
    evaluate, fit_pitch, refractive_index, render_table, AirConditions, AirFormula, CompTable,
    Direction, Sample, Standard, TableFormat, TableOptions,
};
use std::hint::black_box;

/// 201 targets × 2 directions × 5 runs, deterministic values.
fn samples() -> Vec<Sample> {
    let mut out = Vec::new();
    for run in 1..=5u32 {
        for i in 0..=200 {
            let x = i as f64 * 5.0 + (i % 7) as f64 * 0.3;
            let e = 0.012 * x + (x * 0.6283).sin() + 0.1 * run as f64;
            out.push(Sample {
                run,
                direction: Direction::Forward,
                target: x,
                deviation: e + 2.0,
            });
            out.push(Sample {
                run,
                direction: Direction::Reverse,
                target: x,
                deviation: e - 2.0,
            });
        }
    }
    out
}

fn linear_bench(c: &mut Criterion) {
    let s = samples();
    c.bench_function("linear/evaluate_iso230_2_201_targets_5_runs", |b| {
        b.iter(|| evaluate(black_box(&s), Standard::Iso230_2_2014).unwrap())
    });
    let cond = AirConditions::new(20.3, 101.2, 45.0, 632.991);
    c.bench_function("linear/air_index_ciddor", |b| {
        b.iter(|| refractive_index(black_box(&cond), AirFormula::Ciddor).unwrap())
    });
    let ev = evaluate(&s, Standard::Iso230_2_2014).unwrap();
    let xs: Vec<f64> = ev.targets.iter().map(|t| t.target).collect();
    let es: Vec<f64> = ev.targets.iter().map(|t| t.mean_any()).collect();
    c.bench_function("linear/pitch_fit_201_targets", |b| {
        b.iter(|| fit_pitch(black_box(&xs), black_box(&es), 10.0).unwrap())
    });
    let table = CompTable::from_evaluation(&ev, 10.0).unwrap();
    c.bench_function("linear/render_sinumerik_101_points", |b| {
        b.iter(|| {
            render_table(
                black_box(&table),
                TableFormat::Sinumerik,
                &TableOptions::default(),
                std::path::Path::new("x.ini"),
            )
            .unwrap()
        })
    });
}

criterion_group!(linear_benches, linear_bench);
