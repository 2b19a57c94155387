//! Tests of the circular test (ISO 230-4): closed forms of G, F and the centre, the exact minimum zone against brute force, recovery of planted terms from `synth circular`, and rejections of bad runs by the real binary.

mod common;

use common::{errmap, json, ok};
use errmap::circular::{analyze, evaluate, min_zone, parse_run, read_run, Plane, ReadOptions};
use errmap::synth::circular::{write_set, CircularSynthConfig};
use rand::{Rng, SeedableRng};
use std::f64::consts::TAU;
use std::fmt::Write as _;
use std::path::Path;

fn opts(radius_mm: f64) -> ReadOptions {
    ReadOptions {
        radius_mm,
        centre_mm: [0.0, 0.0],
    }
}

/// A two-axis file from a function of (direction sense, angle) giving the point (mm).
fn two_axis_text(n: usize, dirs: &[&str], point: impl Fn(f64, f64) -> [f64; 2]) -> String {
    let mut s = String::from("direction,x_mm,y_mm\n");
    for d in dirs {
        let sigma = if *d == "ccw" { 1.0 } else { -1.0 };
        for k in 0..n {
            let t = TAU * k as f64 / n as f64;
            let p = point(sigma, t);
            let _ = writeln!(s, "{d},{:.12},{:.12}", p[0], p[1]);
        }
    }
    s
}

// ---------------------------------------------------------------- closed forms

#[test]
fn a_pure_centre_offset_gives_g_zero_and_is_reported_as_the_offset() {
    let (r, e) = (100.0, [0.012, -0.008]);
    let text = two_axis_text(720, &["ccw", "cw"], |_, t| {
        [e[0] + r * t.cos(), e[1] + r * t.sin()]
    });
    let run = parse_run(Path::new("offset.csv"), &text, &opts(r)).unwrap();
    let (f, _) = evaluate(&run).unwrap();
    for g in [f.g_um.ccw, f.g_um.cw, f.g_um.bidirectional] {
        assert!(g.unwrap().abs() < 1e-6, "G {g:?}");
    }
    assert!(
        (f.centre_offset_um[0] - 12.0).abs() < 1e-6,
        "{:?}",
        f.centre_offset_um
    );
    assert!(
        (f.centre_offset_um[1] + 8.0).abs() < 1e-6,
        "{:?}",
        f.centre_offset_um
    );
    assert!(f.f_max_um.bidirectional.unwrap().abs() < 1e-6);
    assert!(f.f_min_um.bidirectional.unwrap().abs() < 1e-6);
    assert!(f.h_um.unwrap() < 1e-6);
}

/// Squareness S: the second axis moves along (−sin α, cos α), α = S·1e-6 rad, so a point
/// (x, y) of the nominal circle is reached at (x − α·y, y). Its radial deviation is
/// −α·R·sin θ·cos θ = −(S·R·1e-3/2)·sin 2θ µm: peak to peak S·R·1e-3 µm, and no centre shift
/// can lower it (sin 2θ has the same value at θ and θ + π, where cos θ and sin θ change sign).
#[test]
fn planted_squareness_gives_the_ellipse_whose_g_is_s_times_r() {
    let (r, s_um_per_m) = (150.0, 40.0);
    let alpha = s_um_per_m * 1e-6;
    let text = two_axis_text(1440, &["ccw", "cw"], |_, t| {
        let (x, y) = (r * t.cos(), r * t.sin());
        [x - alpha * y, y]
    });
    let run = parse_run(Path::new("sq.csv"), &text, &opts(r)).unwrap();
    let (e, _, _) = analyze(&run, Plane::Xy, Some(1000.0)).unwrap();
    let expected = s_um_per_m * r * 1e-3; // 6 µm
    for g in [
        e.figures.g_um.ccw,
        e.figures.g_um.cw,
        e.figures.g_um.bidirectional,
    ] {
        let g = g.unwrap();
        assert!(
            (g - expected).abs() < 0.01 * expected,
            "G {g} vs {expected}"
        );
    }
    let s = e.terms.squareness_um_per_m.value.unwrap();
    assert!((s - s_um_per_m).abs() < 0.01 * s_um_per_m, "squareness {s}");
    // The sign: the ellipse is short along 45° and long along 135°.
    assert!(s > 0.0);
}

/// Backlash b on the first axis, ideal lost motion: the axis is b/2 behind its command in the
/// direction of motion, x = R cos θ − (b/2)·sgn(vₓ). At each reversal of X (θ = 0°, 180°) the
/// radius steps by +b (larger after the reversal), in both directions.
#[test]
fn backlash_on_one_axis_gives_the_step_b_at_the_reversal_angles() {
    let (r, b_mm) = (100.0, 0.004);
    let n = 3600;
    let text = two_axis_text(n, &["ccw", "cw"], |sigma, t| {
        let vx = -sigma * t.sin();
        let lost = if vx > 0.0 {
            -b_mm / 2.0
        } else if vx < 0.0 {
            b_mm / 2.0
        } else {
            0.0
        };
        [r * t.cos() + lost, r * t.sin()]
    });
    let run = parse_run(Path::new("bl.csv"), &text, &opts(r)).unwrap();
    let (e, c, _) = analyze(&run, Plane::Xy, None).unwrap();
    // Deviation at the readings 0.3° after and before each reversal, in travel order.
    let dev_at = |dir: errmap::circular::Rotation, deg: f64| {
        let target = deg.to_radians().rem_euclid(TAU);
        let i = c
            .of(dir)
            .into_iter()
            .min_by(|&a, &b| {
                let da = (c.angle_rad[a] - target).abs();
                let db = (c.angle_rad[b] - target).abs();
                da.total_cmp(&db)
            })
            .unwrap();
        c.dev_um[i]
    };
    use errmap::circular::Rotation::{Ccw, Cw};
    for (dir, sigma) in [(Ccw, 1.0), (Cw, -1.0)] {
        for rev in [0.0, 180.0] {
            let after = dev_at(dir, rev + sigma * 0.3);
            let before = dev_at(dir, rev - sigma * 0.3);
            let step = after - before;
            assert!(
                (step - 4.0).abs() < 0.02 * 4.0,
                "{dir:?} at {rev}°: step {step}"
            );
        }
    }
    let b1 = e.terms.backlash_first_um.value.unwrap();
    let b2 = e.terms.backlash_second_um.value.unwrap();
    assert!((b1 - 4.0).abs() < 0.04, "backlash first {b1}");
    assert!(b2.abs() < 0.04, "backlash second {b2}");
}

/// One spike of h µm at θ₀ on a perfect circle read every 1° (N = 360). The least-squares
/// circle of d = c + a·cos θ + b·sin θ over equally spaced angles has, by orthogonality,
/// a = (2/N)·Σ dᵢ cos θᵢ = 2h·cos θ₀/N, b = 2h·sin θ₀/N and c = h/N.
#[test]
fn the_least_squares_centre_moves_by_two_h_over_n_toward_one_spike() {
    let (r, h, n, spike_deg) = (100.0, 5.0, 360, 30.0_f64);
    let mut text = String::from("direction,angle_deg,deviation_um\n");
    for k in 0..n {
        let d = if k == spike_deg as usize { h } else { 0.0 };
        let _ = writeln!(text, "ccw,{k},{d}");
    }
    let run = parse_run(Path::new("spike.csv"), &text, &opts(r)).unwrap();
    let (f, _) = evaluate(&run).unwrap();
    let t0 = spike_deg.to_radians();
    let (a, b) = (2.0 * h * t0.cos() / n as f64, 2.0 * h * t0.sin() / n as f64);
    assert!(
        (f.centre_offset_um[0] - a).abs() < 1e-4,
        "{:?} vs {a}",
        f.centre_offset_um
    );
    assert!(
        (f.centre_offset_um[1] - b).abs() < 1e-4,
        "{:?} vs {b}",
        f.centre_offset_um
    );
    assert!((f.mean_radius_deviation_um - h / n as f64).abs() < 1e-4);
    // F about that centre (against the nominal radius): the spike minus what the centre
    // shift took of it, h − (a·cos θ₀ + b·sin θ₀) = h − 2h/N.
    let f_max = h - (a * t0.cos() + b * t0.sin());
    assert!((f.f_max_um.ccw.unwrap() - f_max).abs() < 1e-4);
}

// ---------------------------------------------------------------- minimum zone

/// Brute force: the optimum of the zone LP is a vertex where four readings touch (at least
/// one outer, one inner). Solve every such 4×4 system for (a, b, u, l) and keep the smallest
/// width max − min of rᵢ − a·cos θᵢ − b·sin θᵢ found at any of them.
fn brute_force_width(r: &[f64], ang: &[f64]) -> f64 {
    let n = r.len();
    let width = |a: f64, b: f64| {
        let v: Vec<f64> = (0..n)
            .map(|i| r[i] - a * ang[i].cos() - b * ang[i].sin())
            .collect();
        v.iter().cloned().fold(f64::MIN, f64::max) - v.iter().cloned().fold(f64::MAX, f64::min)
    };
    let mut best = f64::INFINITY;
    for i in 0..n {
        for j in 0..n {
            for k in 0..n {
                for l in 0..n {
                    let idx = [i, j, k, l];
                    if idx
                        .iter()
                        .enumerate()
                        .any(|(p, x)| idx[p + 1..].contains(x))
                    {
                        continue;
                    }
                    for outer_mask in 1..15u8 {
                        let m = nalgebra::Matrix4::from_fn(|row, col| {
                            let p = idx[row];
                            let outer = outer_mask & (1 << row) != 0;
                            match col {
                                0 => ang[p].cos(),
                                1 => ang[p].sin(),
                                2 => f64::from(u8::from(outer)),
                                _ => f64::from(u8::from(!outer)),
                            }
                        });
                        let rhs = nalgebra::Vector4::from_fn(|row, _| r[idx[row]]);
                        if let Some(sol) = m.lu().solve(&rhs) {
                            if sol.iter().all(|v| v.is_finite()) {
                                best = best.min(width(sol[0], sol[1]));
                            }
                        }
                    }
                }
            }
        }
    }
    best
}

#[test]
fn minimum_zone_equals_brute_force_on_small_data() {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
    for case in 0..12 {
        let n = 7 + case % 3;
        let ang: Vec<f64> = (0..n)
            .map(|k| (k as f64 + rng.random_range(-0.3..0.3)) * TAU / n as f64)
            .collect();
        let r: Vec<f64> = (0..n).map(|_| rng.random_range(-5.0..5.0)).collect();
        let z = min_zone(&r, &ang);
        let brute = brute_force_width(&r, &ang);
        assert!(
            (z.width_um - brute).abs() < 1e-9,
            "case {case}: LP {} vs brute {brute}",
            z.width_um
        );
        // And no point of a fine grid around the LP centre does better.
        for da in -20..=20 {
            for db in -20..=20 {
                let (a, b) = (
                    z.shift_um[0] + 0.05 * da as f64,
                    z.shift_um[1] + 0.05 * db as f64,
                );
                let v: Vec<f64> = (0..n)
                    .map(|i| r[i] - a * ang[i].cos() - b * ang[i].sin())
                    .collect();
                let w = v.iter().cloned().fold(f64::MIN, f64::max)
                    - v.iter().cloned().fold(f64::MAX, f64::min);
                assert!(w >= z.width_um - 1e-12);
            }
        }
        assert!(z.contacts.iter().any(|c| c.1) && z.contacts.iter().any(|c| !c.1));
    }
}

// ---------------------------------------------------------------- recovery

/// |value − truth| within 5 % of the truth, or 0.1 µm for the terms in µm.
fn assert_recovered(name: &str, value: f64, truth: f64, unit_um: bool) {
    let tol = if unit_um {
        (0.05 * truth.abs()).max(0.1)
    } else {
        0.05 * truth.abs()
    };
    assert!(
        (value - truth).abs() <= tol,
        "{name}: {value} vs planted {truth} (tolerance {tol})"
    );
}

const TERMS: [(&str, bool); 9] = [
    ("squareness_um_per_m", false),
    ("scale_mismatch_um_per_m", false),
    ("backlash_first_um", true),
    ("backlash_second_um", true),
    ("reversal_spike_first_um", true),
    ("reversal_spike_second_um", true),
    ("servo_mismatch_ms", false),
    ("cyclic_first_um", true),
    ("cyclic_second_um", true),
];

#[test]
fn synth_circular_terms_are_recovered_within_5_percent_with_0_2_um_noise() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    ok(
        d,
        &["synth", "circular", "--out-dir", "set", "--seed", "7", "-q"],
    );
    let truth: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(d.join("set/truth.json")).unwrap()).unwrap();
    assert_eq!(truth["config"]["noise_um"], 0.2);
    let run = ok(
        d,
        &[
            "circular",
            "set/run.csv",
            "--radius",
            "100",
            "--feed",
            "1000",
            "--json",
        ],
    );
    let doc = json(&run);
    for (key, unit_um) in TERMS {
        let planted = truth[key].as_f64().unwrap();
        assert!(planted != 0.0, "{key} must be planted");
        let got = doc["terms"][key]["value"]
            .as_f64()
            .unwrap_or_else(|| panic!("{key}: {}", doc["terms"][key]));
        assert_recovered(key, got, planted, unit_um);
        assert!(doc["terms"][key]["stderr"].as_f64().unwrap() > 0.0);
    }
    for (key, axis) in [("cyclic_first_um", 0), ("cyclic_second_um", 1)] {
        let p = doc["terms"][key]["period_mm"].as_f64().unwrap();
        let planted = truth["cyclic_period_mm"][axis].as_f64().unwrap();
        assert!((p - planted).abs() < 0.01 * planted, "{key} period {p}");
    }
    for (key, axis) in [
        ("reversal_spike_first_um", 0),
        ("reversal_spike_second_um", 1),
    ] {
        let dm = doc["terms"][key]["decay_mm"].as_f64().unwrap();
        let planted = truth["spike_decay_mm"][axis].as_f64().unwrap();
        assert!((dm - planted).abs() < 0.15 * planted, "{key} decay {dm}");
    }
    let rms = doc["residual_rms_um"].as_f64().unwrap();
    assert!(
        rms > 0.18 && rms < 0.25,
        "residual RMS {rms} should be near the 0.2 µm noise"
    );
    // The set-up offset of the synthetic run.
    let c = &doc["centre_offset_um"];
    assert!(
        (c[0].as_f64().unwrap() - 12.0).abs() < 0.3 && (c[1].as_f64().unwrap() + 8.0).abs() < 0.3,
        "{c}"
    );
}

/// Every sign flipped (and backlash of the other kind on each axis): the conventions hold.
#[test]
fn flipped_signs_are_recovered_with_their_signs() {
    let dir = tempfile::tempdir().unwrap();
    let config = CircularSynthConfig {
        seed: 3,
        squareness_um_per_m: -25.0,
        scale_um_per_m: [-10.0, 8.0],
        backlash_um: [-2.0, 2.5],
        spike_um: [3.0, 3.5],
        spike_decay_mm: [2.0, 1.2],
        lag_ms: [0.6, 1.0],
        cyclic_um: [0.7, 1.2],
        cyclic_period_mm: [12.0, 8.0],
        radius_mm: 150.0,
        feed_mm_per_min: 2000.0,
        ..Default::default()
    };
    write_set(dir.path(), &config).unwrap();
    let run = read_run(&dir.path().join("run.csv"), &opts(150.0)).unwrap();
    let (e, _, _) = analyze(&run, Plane::Xy, Some(2000.0)).unwrap();
    let t = config.truth();
    let terms = &e.terms;
    let pairs = [
        (
            "squareness",
            terms.squareness_um_per_m.value,
            t.squareness_um_per_m,
            false,
        ),
        (
            "scale",
            terms.scale_mismatch_um_per_m.value,
            t.scale_mismatch_um_per_m,
            false,
        ),
        (
            "backlash 1",
            terms.backlash_first_um.value,
            t.backlash_first_um,
            true,
        ),
        (
            "backlash 2",
            terms.backlash_second_um.value,
            t.backlash_second_um,
            true,
        ),
        (
            "spike 1",
            terms.reversal_spike_first_um.value,
            t.reversal_spike_first_um,
            true,
        ),
        (
            "spike 2",
            terms.reversal_spike_second_um.value,
            t.reversal_spike_second_um,
            true,
        ),
        (
            "servo",
            terms.servo_mismatch_ms.value,
            t.servo_mismatch_ms,
            false,
        ),
        (
            "cyclic 1",
            terms.cyclic_first_um.value,
            t.cyclic_first_um,
            true,
        ),
        (
            "cyclic 2",
            terms.cyclic_second_um.value,
            t.cyclic_second_um,
            true,
        ),
    ];
    for (name, got, planted, unit_um) in pairs {
        assert_recovered(name, got.unwrap(), planted, unit_um);
    }
}

#[test]
fn two_axis_form_with_a_centre_and_sorted_rows_gives_the_same_terms() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    ok(
        d,
        &[
            "synth",
            "circular",
            "--out-dir",
            "t",
            "--form",
            "two-axis",
            "--step-deg",
            "0.2",
            "-q",
        ],
    );
    // Shift to machine coordinates and shuffle the rows: errmap sorts them by angle.
    let text = std::fs::read_to_string(d.join("t/run.csv")).unwrap();
    let mut lines: Vec<String> = text
        .lines()
        .skip(1)
        .map(|l| {
            let f: Vec<&str> = l.split(',').collect();
            let x: f64 = f[1].parse().unwrap();
            let y: f64 = f[2].parse().unwrap();
            format!("{},{:.8},{:.8}", f[0], x + 250.0, y - 120.0)
        })
        .collect();
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(9);
    for i in (1..lines.len()).rev() {
        lines.swap(i, rng.random_range(0..=i));
    }
    std::fs::write(
        d.join("machine.csv"),
        format!("direction,x_mm,y_mm\n{}\n", lines.join("\n")),
    )
    .unwrap();
    let a = json(&ok(
        d,
        &[
            "circular",
            "t/run.csv",
            "--radius",
            "100",
            "--feed",
            "1000",
            "--json",
        ],
    ));
    let b = json(&ok(
        d,
        &[
            "circular",
            "machine.csv",
            "--radius",
            "100",
            "--feed",
            "1000",
            "--centre",
            "250,-120",
            "--json",
        ],
    ));
    let truth: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(d.join("t/truth.json")).unwrap()).unwrap();
    for (key, unit_um) in TERMS {
        let va = a["terms"][key]["value"].as_f64().unwrap();
        let vb = b["terms"][key]["value"].as_f64().unwrap();
        assert!(
            (va - vb).abs() < 1e-3 * (1.0 + va.abs()),
            "{key}: {va} vs {vb}"
        );
        assert_recovered(key, va, truth[key].as_f64().unwrap(), unit_um);
    }
    assert!(
        (a["g_um"]["bidirectional"].as_f64().unwrap()
            - b["g_um"]["bidirectional"].as_f64().unwrap())
        .abs()
            < 1e-4
    );
}

// ---------------------------------------------------------------- CLI output

#[test]
fn json_has_the_keys_the_issue_lists_and_the_chart_has_both_directions() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    ok(
        d,
        &[
            "synth",
            "circular",
            "--out-dir",
            "s",
            "--step-deg",
            "0.5",
            "-q",
        ],
    );
    let doc = json(&ok(
        d,
        &[
            "circular",
            "s/run.csv",
            "--radius",
            "100",
            "--feed",
            "1000",
            "--json",
            "-o",
            "c.png",
        ],
    ));
    for k in ["cw", "ccw", "bidirectional"] {
        assert!(doc["g_um"][k].as_f64().unwrap() > 0.0, "g_um.{k}");
        assert!(doc["f_max_um"][k].as_f64().unwrap() > 0.0);
        assert!(doc["f_min_um"][k].as_f64().unwrap() < 0.0);
    }
    // G bidirectional encloses both paths: at least each direction's G.
    let gb = doc["g_um"]["bidirectional"].as_f64().unwrap();
    assert!(
        gb >= doc["g_um"]["cw"].as_f64().unwrap() - 1e-9
            && gb >= doc["g_um"]["ccw"].as_f64().unwrap() - 1e-9
    );
    assert!(doc["h_um"].as_f64().unwrap() > 0.0);
    assert_eq!(doc["centre_offset_um"].as_array().unwrap().len(), 2);
    assert!(doc["residual_rms_um"].as_f64().is_some());
    let terms = doc["terms"].as_object().unwrap();
    assert_eq!(terms.len(), TERMS.len());
    for (key, _) in TERMS {
        assert!(
            terms[key]["value"].is_number() && terms[key]["stderr"].is_number(),
            "{key}"
        );
    }
    let img = image::open(d.join("c.png")).unwrap().to_rgb8();
    let blue = img
        .pixels()
        .filter(|p| p.0[2] > 200 && p.0[0] < 60 && p.0[1] < 60)
        .count();
    let red = img
        .pixels()
        .filter(|p| p.0[0] > 200 && p.0[1] < 60 && p.0[2] < 60)
        .count();
    assert!(blue > 500 && red > 500, "blue {blue}, red {red} pixels");
    // The text report names the figures.
    let text = ok(d, &["circular", "s/run.csv", "--radius", "100"]);
    assert!(
        text.stdout.contains("G circular deviation") && text.stdout.contains("squareness_um_per_m")
    );
}

#[test]
fn one_direction_or_no_feed_leaves_servo_mismatch_empty_with_a_note() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    ok(
        d,
        &[
            "synth",
            "circular",
            "--out-dir",
            "one",
            "--only",
            "ccw",
            "--step-deg",
            "0.5",
            "-q",
        ],
    );
    let doc = json(&ok(
        d,
        &[
            "circular",
            "one/run.csv",
            "--radius",
            "100",
            "--feed",
            "1000",
            "--json",
        ],
    ));
    assert!(doc["g_um"]["ccw"].as_f64().is_some());
    assert!(
        doc["g_um"]["cw"].is_null()
            && doc["g_um"]["bidirectional"].is_null()
            && doc["h_um"].is_null()
    );
    assert!(doc["terms"]["servo_mismatch_ms"]["value"].is_null());
    assert!(doc["terms"]["servo_mismatch_ms"]["note"]
        .as_str()
        .unwrap()
        .contains("both directions"));
    ok(
        d,
        &[
            "synth",
            "circular",
            "--out-dir",
            "two",
            "--step-deg",
            "0.5",
            "-q",
        ],
    );
    let doc = json(&ok(
        d,
        &["circular", "two/run.csv", "--radius", "100", "--json"],
    ));
    assert!(doc["terms"]["servo_mismatch_ms"]["value"].is_null());
    assert!(doc["terms"]["servo_mismatch_ms"]["note"]
        .as_str()
        .unwrap()
        .contains("--feed"));
    // 0.5 ms at 1000 mm/min is a radial amplitude of 1000·0.5/120 µm.
    let k = doc["model"]["servo_amplitude_um"].as_f64().unwrap();
    assert!((k - 1000.0 * 0.5 / 120.0).abs() < 0.05 * 4.17, "{k}");
}

// ---------------------------------------------------------------- bad input

/// Run `errmap circular FILE --radius R` on `text` and return stderr, requiring exit 2.
fn rejected(text: &str, radius: &str) -> String {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("run.csv"), text).unwrap();
    let run = errmap(dir.path(), &["circular", "run.csv", "--radius", radius]);
    run.expect_code(2);
    run.stderr
}

fn radial(rows: impl Iterator<Item = (String, f64, f64)>) -> String {
    let mut s = String::from("direction,angle_deg,deviation_um\n");
    for (d, a, v) in rows {
        let _ = writeln!(s, "{d},{a},{v}");
    }
    s
}

fn turn(step: f64) -> impl Iterator<Item = (String, f64, f64)> {
    let n = (360.0 / step).round() as usize;
    (0..n).map(move |k| ("ccw".to_string(), k as f64 * step, 0.5 * (k as f64).sin()))
}

#[test]
fn a_run_shorter_than_one_turn_is_refused_with_file_and_line() {
    let text = radial(turn(1.0).filter(|r| r.1 < 270.0));
    let err = rejected(&text, "100");
    assert!(
        err.contains("run.csv:271") && err.contains("covers only 269.0°"),
        "{err}"
    );
}

#[test]
fn a_direction_with_too_few_readings_is_refused() {
    let text = radial(turn(15.0));
    let err = rejected(&text, "100");
    assert!(
        err.contains("run.csv:") && err.contains("only 24 readings"),
        "{err}"
    );
}

#[test]
fn a_repeated_angle_is_refused_naming_both_lines() {
    // A second reading at 180° inside the turn (line 182 repeats line 182's angle at 183).
    let mut rows: Vec<_> = turn(1.0).collect();
    rows.insert(181, ("ccw".to_string(), 180.0, 0.1));
    let err = rejected(&radial(rows.into_iter()), "100");
    assert!(
        err.contains("run.csv:183") && err.contains("repeated") && err.contains("line 182"),
        "{err}"
    );
}

#[test]
fn readings_past_one_turn_are_overshoot_and_counted() {
    // A ballbar records on: ccw 0°..359° then 360°..400° (the overrun), and cw 359°..0°
    // then on to −30°. The turn is one turn from each direction's first reading.
    let mut rows: Vec<(String, f64, f64)> = turn(1.0).collect();
    for a in 0..=40 {
        rows.push(("ccw".to_string(), 360.0 + a as f64, 99.0));
    }
    for a in (0..360).rev() {
        rows.push((
            "cw".to_string(),
            a as f64,
            0.5 * (a as f64).to_radians().sin(),
        ));
    }
    for a in 1..=30 {
        rows.push(("cw".to_string(), -(a as f64), 99.0));
    }
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("run.csv"), radial(rows.into_iter())).unwrap();
    let doc = json(&ok(
        dir.path(),
        &["circular", "run.csv", "--radius", "100", "--json"],
    ));
    assert_eq!(doc["readings"]["ccw"], 360, "{doc}");
    assert_eq!(doc["readings"]["cw"], 360, "{doc}");
    assert_eq!(doc["readings"]["overshoot"], 41 + 30, "{doc}");
    assert_eq!(doc["readings"]["overrun"], 41 + 30, "{doc}");
    // The overrun's 99 µm readings are not evaluated: F stays that of the turn.
    let f_max = doc["f_max_um"]["ccw"].as_f64().unwrap();
    assert!(f_max < 5.0, "{doc}");
    let text = ok(dir.path(), &["circular", "run.csv", "--radius", "100"]).stdout;
    assert!(
        text.contains("(71 overshoot rows ignored, 71 of them readings past one turn)"),
        "{text}"
    );
}

#[test]
fn a_gap_over_10_degrees_is_refused() {
    let text = radial(turn(1.0).filter(|r| !(100.0..=111.0).contains(&r.1)));
    let err = rejected(&text, "100");
    assert!(
        err.contains("run.csv:101") && err.contains("gap of 13.00°"),
        "{err}"
    );
}

#[test]
fn a_radius_that_does_not_match_the_data_is_refused() {
    // Deviations of 12 mm on a 100 mm radius: the radius (or the unit) is wrong.
    let text = radial(turn(1.0).map(|(d, a, v)| (d, a, if a == 45.0 { 12000.0 } else { v })));
    let err = rejected(&text, "100");
    assert!(
        err.contains("run.csv:47") && err.contains("radius does not match"),
        "{err}"
    );
    // Two-axis points on an 80 mm circle read with --radius 100.
    let text = two_axis_text(360, &["ccw"], |_, t| [80.0 * t.cos(), 80.0 * t.sin()]);
    let err = rejected(&text, "100");
    assert!(
        err.contains("run.csv:2") && err.contains("radius does not match"),
        "{err}"
    );
}

#[test]
fn two_axis_points_not_near_a_circle_are_refused() {
    let text = two_axis_text(360, &["ccw"], |_, t| {
        let r = if (t.to_degrees() - 200.0).abs() < 0.1 {
            103.0
        } else {
            100.0
        };
        [r * t.cos(), r * t.sin()]
    });
    let err = rejected(&text, "100");
    assert!(
        err.contains("run.csv:202") && err.contains("not near a circle"),
        "{err}"
    );
}

#[test]
fn bad_labels_headers_and_outputs_are_refused() {
    let text = radial(turn(1.0).map(|(_, a, v)| ("forward".to_string(), a, v)));
    let err = rejected(&text, "100");
    assert!(
        err.contains("run.csv:2, column direction") && err.contains("not cw, ccw or overshoot"),
        "{err}"
    );
    let err = rejected("direction,angle_deg,x_mm\nccw,0,1\n", "100");
    assert!(
        err.contains("run.csv:1") && err.contains("neither the radial nor the two-axis form"),
        "{err}"
    );
    // The chart may not overwrite the run file.
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("run.csv"), radial(turn(1.0))).unwrap();
    let run = errmap(
        dir.path(),
        &["circular", "run.csv", "--radius", "100", "-o", "run.csv"],
    );
    run.expect_code(2);
    assert!(
        run.stderr.contains("would overwrite the run file"),
        "{}",
        run.report()
    );
    assert!(std::fs::read_to_string(dir.path().join("run.csv"))
        .unwrap()
        .starts_with("direction"));
    // Overshoot rows are read but not evaluated.
    let mut rows: Vec<_> = turn(1.0).collect();
    rows.push(("overshoot".to_string(), 5.0, 1.0));
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("run.csv"), radial(rows.into_iter())).unwrap();
    let doc = json(&ok(
        dir.path(),
        &["circular", "run.csv", "--radius", "100", "--json"],
    ));
    assert_eq!(doc["readings"]["overshoot"], 1);
    assert_eq!(doc["readings"]["ccw"], 360);
}

/// The worked example of docs/circular.md: R = 100 mm, 1000 mm/min, squareness 30 µm/m and
/// servo mismatch 0.5 ms. Radial deviation −1.5·sin 2θ (squareness) plus 4.1667·sin 2θ ccw,
/// minus it cw (servo): ccw 2.6667·sin 2θ, cw −5.6667·sin 2θ. By hand: G ccw 5.333, G cw
/// 11.333, G both 11.333, H = 2.6667 + 5.6667 = 8.333 µm; squareness alone 3 µm = 26.5 % of
/// G, servo alone 8.333 µm = 73.5 %.
#[test]
fn the_worked_example_of_the_docs_gives_the_figures_computed_by_hand() {
    let mut text = String::from("direction,angle_deg,deviation_um\n");
    for (d, k) in [("ccw", 2.0 + 2.0 / 3.0), ("cw", -5.0 - 2.0 / 3.0)] {
        for a in 0..360 {
            let t = (a as f64).to_radians();
            let _ = writeln!(text, "{d},{a},{:.12}", k * (2.0 * t).sin());
        }
    }
    let run = parse_run(Path::new("example.csv"), &text, &opts(100.0)).unwrap();
    let (e, _, _) = analyze(&run, Plane::Xy, Some(1000.0)).unwrap();
    let f = &e.figures;
    let close = |got: Option<f64>, want: f64| {
        let got = got.unwrap();
        assert!((got - want).abs() < 2e-3, "{got} vs {want}");
    };
    close(f.g_um.ccw, 16.0 / 3.0);
    close(f.g_um.cw, 34.0 / 3.0);
    close(f.g_um.bidirectional, 34.0 / 3.0);
    close(f.h_um, 25.0 / 3.0);
    close(e.terms.squareness_um_per_m.value, 30.0);
    close(e.terms.servo_mismatch_ms.value, 0.5);
    close(e.terms.squareness_um_per_m.share_of_g, 3.0 / (34.0 / 3.0));
    close(
        e.terms.servo_mismatch_ms.share_of_g,
        (25.0 / 3.0) / (34.0 / 3.0),
    );
}
