//! End-to-end chart tests on the real binary: the family maps show every part's probes, rejects and the measured hull; `rotary analyze --sign` flips text, JSON and chart together.

mod common;

use common::{json, ok};
use errmap::report::heatmap::{frame, Heatmap, Scale};
use std::path::Path;

/// (x, y) columns of a CSV with a header, as numbers.
fn xy(path: &Path) -> Vec<(f64, f64)> {
    let text = std::fs::read_to_string(path).unwrap();
    text.lines()
        .skip(1)
        .filter(|l| !l.trim().is_empty())
        .map(|l| {
            let mut f = l.split(',').map(|v| v.trim().parse::<f64>().unwrap());
            (f.next().unwrap(), f.next().unwrap())
        })
        .collect()
}

/// The grid of a map CSV (x_mm,y_mm,value on a regular grid): first node, step, counts.
fn grid(nodes: &[(f64, f64)]) -> (f64, f64, f64, usize, usize) {
    let mut xs: Vec<f64> = nodes.iter().map(|p| p.0).collect();
    let mut ys: Vec<f64> = nodes.iter().map(|p| p.1).collect();
    for v in [&mut xs, &mut ys] {
        v.sort_by(f64::total_cmp);
        v.dedup();
    }
    (xs[0], ys[0], xs[1] - xs[0], xs.len(), ys.len())
}

fn dark(img: &image::RgbImage, (x, y): (i32, i32)) -> bool {
    img.get_pixel(x as u32, y as u32).0.iter().all(|&c| c < 60)
}

#[test]
fn family_maps_show_probes_rejects_and_the_hull() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    ok(
        d,
        &[
            "synth",
            "web-plate",
            "--parts",
            "2",
            "--grid",
            "8x5",
            "--outliers",
            "1",
            "--epochs",
            "30",
            "--out",
            "data",
            "--quiet",
        ],
    );
    ok(
        d,
        &[
            "batch",
            "data/job.toml",
            "--backend",
            "cpu",
            "--out",
            "out",
            "--quiet",
        ],
    );
    let (u0, v0, step, nu, nv) = grid(&xy(&d.join("out/family/mean.csv")));
    let map = Heatmap {
        title: String::new(),
        u_name: "x",
        v_name: "y",
        value_label: "",
        u0_mm: u0,
        v0_mm: v0,
        step_mm: step,
        nu,
        nv,
        values: &[],
        probes: &[],
        rejected: &[],
        hull: &[],
        scale: Scale::Diverging,
        extrapolated: &[],
    };
    let f = frame(&map);
    let probes: Vec<(f64, f64)> = ["p01", "p02"]
        .iter()
        .flat_map(|p| xy(&d.join(format!("out/{p}/clean.csv"))))
        .collect();
    let rejected: Vec<(f64, f64)> = ["p01", "p02"]
        .iter()
        .flat_map(|p| xy(&d.join(format!("out/{p}/rejected.csv"))))
        .collect();
    assert!(
        probes.len() > 70 && rejected.len() == 2,
        "{probes:?} {rejected:?}"
    );
    for name in ["mean.png", "std.png"] {
        let img = image::open(d.join("out/family").join(name))
            .unwrap()
            .to_rgb8();
        // The probe dot (black in a white rim) at every part's probe, the crossed circle's
        // centre at every reject.
        for &(x, y) in probes.iter().chain(&rejected) {
            assert!(dark(&img, f.pixel(x, y)), "{name}: no mark at ({x}, {y})");
        }
        // The hull (the probed rectangle 25 … 575 × 25 … 275 mm) between two probes.
        for (x, y) in [(300.0, 25.0), (300.0, 275.0), (25.0, 190.0), (575.0, 190.0)] {
            let (px, py) = f.pixel(x, y);
            assert!(
                (-1..=1).any(|k| dark(&img, (px + k, py + k))),
                "{name}: no hull at ({x}, {y})"
            );
        }
        // Away from every mark the map shows colour, not black.
        assert!(!dark(&img, f.pixel(300.0, 150.0)), "{name}");
    }
}

#[test]
fn rotary_sign_flips_text_json_and_chart_together() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let meas = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/golden/rotary/meas.csv");
    let meas = meas.to_str().unwrap();
    let ours = json(&ok(d, &["rotary", "analyze", meas, "--json"]));
    let theirs = json(&ok(
        d,
        &[
            "rotary",
            "analyze",
            meas,
            "--json",
            "--sign",
            "calibrator",
            "--chart",
            "c.png",
        ],
    ));
    assert_eq!(ours["sign"], "errmap");
    assert_eq!(theirs["sign"], "calibrator");
    let (a, b) = (
        ours["table"].as_array().unwrap(),
        theirs["table"].as_array().unwrap(),
    );
    assert_eq!(a.len(), 8);
    for (a, b) in a.iter().zip(b) {
        let v = |r: &serde_json::Value, k: &str| r[k].as_f64().unwrap();
        assert_eq!(v(b, "error_arcsec"), -v(a, "error_arcsec"));
        assert_eq!(v(b, "min_arcsec"), -v(a, "max_arcsec"));
    }
    // ISO 230-2 keeps its own x = actual − target whatever the sign.
    assert_eq!(ours["iso230_2"], theirs["iso230_2"]);
    assert!(d.join("c.png").is_file());
    let text = ok(d, &["rotary", "analyze", meas, "--sign", "calibrator"]).stdout;
    assert!(
        text.contains("error = β − α = measured − commanded"),
        "{text}"
    );
    assert!(text.contains("counter-clockwise"), "{text}");
    // The planted err(90°, +) = 10″ reads −10 in the calibrator's sign.
    assert!(text.contains("        90    +        -10.00"), "{text}");
    let default = ok(d, &["rotary", "analyze", meas]).stdout;
    assert!(
        default.contains("err = α − β (arcsec), mean over repeats"),
        "{default}"
    );
}
