//! errmap's criterion benchmarks, one harness: each area adds a module beside this file and a group to `criterion_main!`.

mod family_bench;
mod interp_bench;

use criterion::{criterion_group, criterion_main, Criterion};

mod toolpath_bench;
mod training_bench;

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

criterion_group!(io_benches, csv_table_parse);
criterion_group! {
    name = interp_benches;
    // No plots: criterion's plotters backend looks for system fonts, which CI machines lack.
    config = Criterion::default().without_plots();
    targets = interp_bench::interp_benches
}
criterion_group! {
    name = family_benches;
    config = Criterion::default().without_plots();
    targets = family_bench::family_benches
}
criterion_group!(toolpath_benches, toolpath_bench::toolpath_compensate);
criterion_main!(
    io_benches,
    interp_benches,
    training_bench::benches,
    toolpath_benches,
    family_benches
);
