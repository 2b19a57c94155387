//! Criterion benches of the toolpath rewrite: straight cuts and arcs of synthetic programs, sizes swept.

use criterion::{BenchmarkId, Criterion, Throughput};
use errmap::geom::{Axis, ErrorField};
use errmap::toolpath::{compensate_gcode, CompensationSettings};
use std::hint::black_box;
use std::path::Path;

/// E = 0.01 + 1e-4·x + 5e-5·y mm over x, y ∈ [0, 600] × [0, 300] mm (a web-plate-sized map).
struct Plane;

impl ErrorField for Plane {
    fn normal(&self) -> Axis {
        Axis::Z
    }
    fn error_mm(&self, u_mm: f64, v_mm: f64) -> Option<f64> {
        ((0.0..=600.0).contains(&u_mm) && (0.0..=300.0).contains(&v_mm))
            .then_some(0.01 + 1e-4 * u_mm + 5e-5 * v_mm)
    }
}

/// A zig-zag finishing pass of `rows` rows over the plate (each row a 600 mm G1), deterministic.
fn zigzag(rows: usize) -> String {
    let mut s = String::from("G21 G90 G17\nG0 X0 Y0 Z5\nG1 Z-1 F800\n");
    for r in 0..rows {
        let y = 300.0 * r as f64 / rows as f64;
        let x = if r % 2 == 0 { 600.0 } else { 0.0 };
        s.push_str(&format!("G1 Y{y:.3}\nG1 X{x:.1}\n"));
    }
    s.push_str("G0 Z5\nM2\n");
    s
}

/// `n` full circles of radius 20 mm (I/J form) across the plate.
fn circles(n: usize) -> String {
    let mut s = String::from("G21 G90 G17\nG0 X40 Y30 Z5\nG1 Z-1 F800\n");
    for k in 0..n {
        let x = 40.0 + (k % 10) as f64 * 55.0;
        let y = 30.0 + (k / 10 % 5) as f64 * 55.0;
        s.push_str(&format!("G1 X{x:.1} Y{y:.1}\nG2 X{x:.1} Y{y:.1} I-20 J0\n"));
    }
    s.push_str("G0 Z5\nM2\n");
    s
}

/// A CAM-style finishing raster of `lines` short G1 moves (1.5 mm steps, 400 per row, Z varying
/// a little as on a 3D surface): the shape of the 100k-line programs users compensate.
fn raster(lines: usize) -> String {
    let mut s = String::from("G21 G90 G17\nG0 X0 Y0 Z5\nG1 Z-1 F1200\n");
    for k in 0..lines {
        let row = k / 400;
        let step = k % 400;
        let x = if row % 2 == 0 {
            step as f64 * 1.5
        } else {
            600.0 - step as f64 * 1.5
        };
        let y = (row as f64 * 0.5) % 300.0;
        let z = -1.0 + 0.01 * ((k % 37) as f64);
        s.push_str(&format!("G1 X{x:.3} Y{y:.3} Z{z:.3}\n"));
    }
    s.push_str("G0 Z5\nM2\n");
    s
}

pub fn toolpath_compensate(c: &mut Criterion) {
    let settings = CompensationSettings {
        everywhere: true,
        dialect: Some(errmap::toolpath::Dialect::Linuxcnc),
        ..CompensationSettings::default()
    };
    let mut group = c.benchmark_group("toolpath/compensate");
    for rows in [10usize, 100, 1000] {
        let text = zigzag(rows);
        group.throughput(Throughput::Bytes(text.len() as u64));
        group.bench_with_input(BenchmarkId::new("zigzag_rows", rows), &text, |b, t| {
            b.iter(|| {
                compensate_gcode(black_box(t), Path::new("bench.ngc"), &Plane, &settings).unwrap()
            })
        });
    }
    for n in [10usize, 100] {
        let text = circles(n);
        group.throughput(Throughput::Bytes(text.len() as u64));
        group.bench_with_input(BenchmarkId::new("full_circles", n), &text, |b, t| {
            b.iter(|| {
                compensate_gcode(black_box(t), Path::new("bench.ngc"), &Plane, &settings).unwrap()
            })
        });
    }
    group.finish();

    // Issue 3's size: a 100k-line program, every move in the map and the zone.
    let mut large = c.benchmark_group("toolpath/compensate_large");
    large.sample_size(10);
    let text = raster(100_000);
    large.throughput(Throughput::Elements(100_000));
    large.bench_with_input(BenchmarkId::new("raster_lines", 100_000), &text, |b, t| {
        b.iter(|| {
            compensate_gcode(black_box(t), Path::new("bench.ngc"), &Plane, &settings).unwrap()
        })
    });
    large.finish();
}
