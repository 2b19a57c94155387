//! Benches of the streaming readers at scale: a 1 M-row probe file and a 1 M-row temperature log read from disk (line numbers tracked while streaming, so the time is linear in the rows).

use criterion::Criterion;
use errmap::io::CsvTable;
use errmap::probe::{read_probes, ProbeSpec};
use std::hint::black_box;
use std::io::Write;
use std::path::Path;

/// Rows of each file: the 1 M-row goal.
const ROWS: usize = 1_000_000;

/// A 1000 × 1000 probe lattice on a 5 mm plane (µm-scale deviations), with comments and blank
/// lines sprinkled in as real files have them.
fn write_probe_file(path: &Path) {
    let mut w = std::io::BufWriter::new(std::fs::File::create(path).expect("probe file"));
    writeln!(w, "# probe file for the reader bench\nx_mm,y_mm,z_mm").unwrap();
    for k in 0..ROWS {
        let (i, j) = (k % 1000, k / 1000);
        let z = 5.0 + 1e-3 * ((i as f64 * 0.01).sin() + (j as f64 * 0.013).cos());
        writeln!(w, "{:.3},{:.3},{z:.6}", i as f64 * 0.6, j as f64 * 0.3).unwrap();
        if k % 100_000 == 0 {
            writeln!(w, "\n# block {k}").unwrap();
        }
    }
}

/// A day and a half of 1 Hz readings of four sensors.
fn write_log_file(path: &Path) {
    let mut w = std::io::BufWriter::new(std::fs::File::create(path).expect("log file"));
    writeln!(w, "time_s,nut,bearing,room,coolant").unwrap();
    for k in 0..ROWS {
        let t = k as f64;
        writeln!(
            w,
            "{k},{:.4},{:.4},{:.4},{:.4}",
            20.0 + 5.0 * (t / 3600.0).tanh(),
            20.0 + 3.0 * (t / 5400.0).tanh(),
            20.0 + 0.5 * (t / 86400.0).sin(),
            19.0
        )
        .unwrap();
    }
}

pub fn reader_benches(c: &mut Criterion) {
    let dir = tempfile::tempdir().expect("temp dir");
    let probes = dir.path().join("probes_1m.csv");
    let log = dir.path().join("log_1m.csv");
    write_probe_file(&probes);
    write_log_file(&log);

    let mut group = c.benchmark_group("io/read_1m_rows");
    group.sample_size(10);
    group.bench_function("csv_table_probe_file", |b| {
        b.iter(|| black_box(CsvTable::read(&probes).expect("table").rows.len()))
    });
    group.bench_function("csv_table_temperature_log", |b| {
        b.iter(|| black_box(CsvTable::read(&log).expect("table").rows.len()))
    });
    let spec = ProbeSpec {
        nominal_plane_mm: Some(5.0),
        ..ProbeSpec::default()
    };
    group.bench_function("read_probes_validated", |b| {
        b.iter(|| black_box(read_probes(&probes, &spec).expect("probes").points.len()))
    });
    group.finish();
}
