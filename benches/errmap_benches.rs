//! errmap's criterion benchmarks, one harness: each area adds a module beside this file and a group to `criterion_main!`.

mod family_bench;
mod interp_bench;
mod linear_bench;
mod reader_bench;
mod rotary_bench;
mod thermal_bench;
mod toolpath_bench;
mod training_bench;

use criterion::{criterion_group, criterion_main, Criterion};

fn csv_table_parse(c: &mut Criterion) {
    let mut text = String::from("x_mm,y_mm,z_mm\n");
    for i in 0..10_000 {
        text.push_str(&format!(
            "{},{},{}\n",
            i as f64 * 0.5,
            i as f64 * 0.25,
            0.001 * i as f64
        ));
    }
    c.bench_function("io/csv_table_parse_10k_rows", |b| {
        b.iter(|| errmap::io::CsvTable::parse(std::path::Path::new("bench.csv"), &text).unwrap())
    });
}

criterion_group!(io_benches, csv_table_parse, reader_bench::reader_benches);
criterion_group!(interp_benches, interp_bench::interp_benches);
criterion_group!(family_benches, family_bench::family_benches);
criterion_group!(
    rotary_benches,
    rotary_bench::sphere_fit,
    rotary_bench::analyze_campaign
);
criterion_group!(thermal_benches, thermal_bench::compensate_throughput);
criterion_group!(toolpath_benches, toolpath_bench::toolpath_compensate);
criterion_main!(
    io_benches,
    interp_benches,
    training_bench::benches,
    family_benches,
    toolpath_benches,
    linear_bench::linear_benches,
    thermal_benches,
    rotary_benches
);
