//! Positioning figures of every standard against hand arithmetic, and the run-file reader's validation.

use errmap_metrology::linear::{evaluate, parse_runs, Direction, Sample, Standard};
use std::path::Path;

const TOL: f64 = 1e-12;

fn close(a: f64, b: f64, what: &str) {
    assert!((a - b).abs() < TOL, "{what}: got {a}, expected {b}");
}

fn some(a: Option<f64>, b: f64, what: &str) {
    match a {
        Some(a) => close(a, b, what),
        None => panic!("{what}: got None, expected {b}"),
    }
}

/// 3 targets × 2 directions × 3 runs, chosen so every mean and s is exact:
///
/// | target | ↑ readings | x̄↑ | s↑ | ↓ readings | x̄↓ | s↓ | B_i = x̄↑ − x̄↓ | x̄_i |
/// |---|---|---|---|---|---|---|---|---|
/// | 0   | 1, 2, 3    | 2  | √((1+0+1)/2) = 1 | −1, 0, 1  | 0  | 1 | 2 | 1   |
/// | 100 | 4, 6, 8    | 6  | √((4+0+4)/2) = 2 | 2, 3, 4   | 3  | 1 | 3 | 4.5 |
/// | 200 | −1, −1, −1 | −1 | 0                | −7, −5, −3 | −5 | 2 | 4 | −3  |
fn data() -> Vec<Sample> {
    let table: [(f64, [f64; 3], [f64; 3]); 3] = [
        (0.0, [1.0, 2.0, 3.0], [-1.0, 0.0, 1.0]),
        (100.0, [4.0, 6.0, 8.0], [2.0, 3.0, 4.0]),
        (200.0, [-1.0, -1.0, -1.0], [-7.0, -5.0, -3.0]),
    ];
    let mut out = Vec::new();
    for (target, up, down) in table {
        for run in 0..3 {
            out.push(Sample {
                run: run as u32 + 1,
                direction: Direction::Forward,
                target,
                deviation: up[run],
            });
            out.push(Sample {
                run: run as u32 + 1,
                direction: Direction::Reverse,
                target,
                deviation: down[run],
            });
        }
    }
    out
}

#[test]
fn per_target_means_std_and_reversal() {
    let ev = evaluate(&data(), Standard::Iso230_2_2014).unwrap();
    assert_eq!(ev.targets.len(), 3);
    let expect = [
        (0.0, 2.0, 0.0, 1.0, 1.0, 2.0, 1.0),
        (100.0, 6.0, 3.0, 2.0, 1.0, 3.0, 4.5),
        (200.0, -1.0, -5.0, 0.0, 2.0, 4.0, -3.0),
    ];
    for (f, (t, mu, md, su, sd, b, m)) in ev.targets.iter().zip(expect) {
        close(f.target, t, "target");
        some(f.mean_up, mu, "mean_up");
        some(f.mean_down, md, "mean_down");
        some(f.s_up, su, "s_up");
        some(f.s_down, sd, "s_down");
        some(f.reversal, b, "reversal");
        some(f.mean, m, "mean bidirectional");
        assert_eq!((f.n_up, f.n_down), (3, 3));
    }
}

#[test]
fn iso230_2_2014_and_1997_figures() {
    for std in [Standard::Iso230_2_2014, Standard::Iso230_2_1997] {
        let ev = evaluate(&data(), std).unwrap();
        close(ev.k, 2.0, "k");
        // R_i↑ = 4s↑: 4, 8, 0; R_i↓ = 4s↓: 4, 4, 8.
        // R_i = max(2s↑ + 2s↓ + |B_i|, R_i↑, R_i↓):
        //   0: max(2+2+2, 4, 4) = 6;  100: max(4+2+3, 8, 4) = 9;  200: max(0+4+4, 0, 8) = 8.
        let t = &ev.targets;
        for (f, (ru, rd, r)) in t
            .iter()
            .zip([(4.0, 4.0, 6.0), (8.0, 4.0, 9.0), (0.0, 8.0, 8.0)])
        {
            some(f.repeatability_up, ru, "R_i up");
            some(f.repeatability_down, rd, "R_i down");
            some(f.repeatability, r, "R_i");
        }
        let a = &ev.axis;
        some(a.B, 4.0, "B = max|B_i| = max(2,3,4)");
        some(a.B_mean, 3.0, "B̄ = (2+3+4)/3");
        some(a.R_up, 8.0, "R↑ = max(4,8,0)");
        some(a.R_down, 8.0, "R↓ = max(4,4,8)");
        some(a.R, 9.0, "R = max(6,9,8)");
        some(a.E_up, 7.0, "E↑ = 6 − (−1)");
        some(a.E_down, 8.0, "E↓ = 3 − (−5)");
        some(a.E, 11.0, "E = max(2,0,6,3,−1,−5) − min(…) = 6 − (−5)");
        some(a.M, 7.5, "M = 4.5 − (−3)");
        // A↑: x̄↑ + 2s↑ = 4, 10, −1 → 10; x̄↑ − 2s↑ = 0, 2, −1 → −1; A↑ = 11.
        some(a.A_up, 11.0, "A↑");
        // A↓: x̄↓ + 2s↓ = 2, 5, −1 → 5; x̄↓ − 2s↓ = −2, 1, −9 → −9; A↓ = 14.
        some(a.A_down, 14.0, "A↓");
        // A = max(10, 5) − min(−1, −9) = 19.
        some(a.A, 19.0, "A");
    }
}

#[test]
fn gb10931_1989_figures() {
    let ev = evaluate(&data(), Standard::Gb10931_1989).unwrap();
    close(ev.k, 3.0, "k");
    // R_j = 6S: ↑ 6, 12, 0; ↓ 6, 6, 12; at the target the larger: 6, 12, 12.
    let t = &ev.targets;
    for (f, (ru, rd, r)) in t
        .iter()
        .zip([(6.0, 6.0, 6.0), (12.0, 6.0, 12.0), (0.0, 12.0, 12.0)])
    {
        some(f.repeatability_up, ru, "R_j up");
        some(f.repeatability_down, rd, "R_j down");
        some(f.repeatability, r, "R_j");
    }
    let a = &ev.axis;
    some(a.R_up, 12.0, "R↑");
    some(a.R_down, 12.0, "R↓");
    some(a.R, 12.0, "R");
    some(a.B, 4.0, "B");
    // A↑ = (x̄ + 3S)max − (x̄ − 3S)min: 2+3, 6+6, −1+0 → 12; 2−3, 6−6, −1−0 → −1; 13.
    some(a.A_up, 13.0, "A↑");
    // A↓: 0+3, 3+3, −5+6 → 6; 0−3, 3−3, −5−6 → −11; 17.
    some(a.A_down, 17.0, "A↓");
    // A: 12 − (−11) = 23.
    some(a.A, 23.0, "A");
    some(a.M, 7.5, "M");
    some(a.E, 11.0, "E");
}

#[test]
fn vdi3441_figures() {
    let ev = evaluate(&data(), Standard::Vdi3441).unwrap();
    // s̄_j = (s↑ + s↓)/2 = 1, 1.5, 1; Ps_j = 6 s̄_j = 6, 9, 6.
    let t = &ev.targets;
    for (f, ps) in t.iter().zip([6.0, 9.0, 6.0]) {
        some(f.repeatability, ps, "Ps_j");
    }
    let a = &ev.axis;
    some(a.R, 9.0, "Ps = max Ps_j");
    some(a.B, 4.0, "U = max|U_j|");
    some(a.M, 7.5, "Pa = max x̄_j − min x̄_j");
    // P: x̄_j + ½(|U_j| + Ps_j) = 1 + 4, 4.5 + 6, −3 + 5 = 5, 10.5, 2 → 10.5;
    //    x̄_j − ½(|U_j| + Ps_j) = −3, −1.5, −8 → −8;  P = 18.5.
    some(a.A, 18.5, "P");
    // Unidirectional with 3s (as GB): 13 and 17.
    some(a.A_up, 13.0, "A↑");
    some(a.A_down, 17.0, "A↓");
    some(a.R_up, 12.0, "6s↑ max");
}

#[test]
fn single_approach_gives_not_applicable_not_zero() {
    // n = 1: targets 0 and 500; ↑ 3, 1; ↓ −1, −4.
    let s = |direction, target, deviation| Sample {
        run: 1,
        direction,
        target,
        deviation,
    };
    let samples = [
        s(Direction::Forward, 0.0, 3.0),
        s(Direction::Forward, 500.0, 1.0),
        s(Direction::Reverse, 0.0, -1.0),
        s(Direction::Reverse, 500.0, -4.0),
    ];
    for std in Standard::ALL {
        let ev = evaluate(&samples, std).unwrap();
        for f in &ev.targets {
            assert_eq!(f.s_up, None);
            assert_eq!(f.repeatability, None);
            assert_eq!(f.repeatability_up, None);
        }
        let a = &ev.axis;
        assert_eq!((a.R_up, a.R_down, a.R), (None, None, None), "{std}");
        assert_eq!((a.A_up, a.A_down, a.A), (None, None, None), "{std}");
        // B_i = 4, 5 → B = 5, B̄ = 4.5; E↑ = 3 − 1 = 2; E↓ = −1 − (−4) = 3; E = 3 − (−4) = 7;
        // x̄_i = 1, −1.5 → M = 2.5.
        some(a.B, 5.0, "B");
        some(a.B_mean, 4.5, "B̄");
        some(a.E_up, 2.0, "E↑");
        some(a.E_down, 3.0, "E↓");
        some(a.E, 7.0, "E");
        some(a.M, 2.5, "M");
    }
}

#[test]
fn figures_are_unit_agnostic_and_scale_linearly() {
    // Rotary use: deviations in arcsec scale every figure by the same factor.
    let scaled: Vec<Sample> = data()
        .into_iter()
        .map(|s| Sample {
            deviation: s.deviation * 3.6,
            ..s
        })
        .collect();
    let ev = evaluate(&scaled, Standard::Iso230_2_2014).unwrap();
    close(ev.axis.A.unwrap(), 19.0 * 3.6, "A scaled");
    some(ev.axis.B, 4.0 * 3.6, "B scaled");
}

#[test]
fn mixed_uni_and_bidirectional_targets_are_an_error() {
    // Target 0 from both directions, target 10 from + only: neither test kind.
    let sample = |direction, target| Sample {
        run: 1,
        direction,
        target,
        deviation: 1.0,
    };
    let samples = [
        sample(Direction::Forward, 0.0),
        sample(Direction::Reverse, 0.0),
        sample(Direction::Forward, 10.0),
    ];
    let err = evaluate(&samples, Standard::Vdi3441)
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("target 10") && err.contains("direction -"),
        "{err}"
    );
    // Targets each from a different single direction are mixed too.
    let samples = [
        sample(Direction::Forward, 0.0),
        sample(Direction::Reverse, 10.0),
    ];
    let err = evaluate(&samples, Standard::Iso230_2_2014).unwrap_err();
    assert_eq!(err.kind(), "input", "{err}");
    assert!(
        err.to_string().contains("mixed uni/bidirectional samples"),
        "{err}"
    );
    let err = evaluate(&[], Standard::Vdi3441).unwrap_err();
    assert_eq!(err.kind(), "input", "{err}");
    assert!(err.to_string().contains("no samples to evaluate"), "{err}");
}

/// Unidirectional hand data: 3 targets × 3 runs, one direction only.
///
/// target 0:  1, 2, 3  → x̄ = 2, s = √((1 + 0 + 1)/2) = 1
/// target 10: 4, 6, 8  → x̄ = 6, s = √((4 + 0 + 4)/2) = 2
/// target 20: −1, 0, 1 → x̄ = 0, s = √((1 + 0 + 1)/2) = 1
fn unidirectional(direction: Direction) -> Vec<Sample> {
    let data = [
        (0.0, [1.0, 2.0, 3.0]),
        (10.0, [4.0, 6.0, 8.0]),
        (20.0, [-1.0, 0.0, 1.0]),
    ];
    let mut out = Vec::new();
    for (target, devs) in data {
        for (j, deviation) in devs.into_iter().enumerate() {
            out.push(Sample {
                run: j as u32 + 1,
                direction,
                target,
                deviation,
            });
        }
    }
    out
}

#[test]
fn forward_only_runs_give_the_forward_figures_by_hand() {
    let ev = evaluate(&unidirectional(Direction::Forward), Standard::Iso230_2_2014).unwrap();
    assert_eq!(ev.unidirectional, Some(Direction::Forward));
    let means = [2.0, 6.0, 0.0];
    let sds = [1.0, 2.0, 1.0];
    for (i, t) in ev.targets.iter().enumerate() {
        assert_eq!((t.n_up, t.n_down), (3, 0));
        some(t.mean_up, means[i], "x̄_i↑");
        some(t.s_up, sds[i], "s_i↑");
        // ISO 230-2:2014 3.14: R_i↑ = 4 s_i↑ → 4, 8, 4.
        some(t.repeatability_up, 4.0 * sds[i], "R_i↑");
        // The other direction and every bidirectional figure: not applicable, never 0.
        assert_eq!(t.mean_down, None);
        assert_eq!(t.s_down, None);
        assert_eq!(t.repeatability_down, None);
        assert_eq!(t.mean, None);
        assert_eq!(t.reversal, None);
        assert_eq!(t.repeatability, None);
    }
    let a = &ev.axis;
    // R↑ = max(4, 8, 4) = 8.
    some(a.R_up, 8.0, "R↑");
    // E↑ = max x̄↑ − min x̄↑ = 6 − 0 = 6.
    some(a.E_up, 6.0, "E↑");
    // A↑ = max(x̄ + 2s) − min(x̄ − 2s) = max(4, 10, 2) − min(0, 2, −2) = 10 + 2 = 12.
    some(a.A_up, 12.0, "A↑");
    for (name, v) in [
        ("R↓", a.R_down),
        ("E↓", a.E_down),
        ("A↓", a.A_down),
        ("B", a.B),
        ("B̄", a.B_mean),
        ("R", a.R),
        ("E", a.E),
        ("M", a.M),
        ("A", a.A),
    ] {
        assert_eq!(v, None, "{name} must be None in a forward-only test");
    }
}

#[test]
fn reverse_only_runs_by_gb10931_and_vdi3441() {
    // GB 10931 (k = 3) on the same numbers from − only:
    // R_i↓ = 6S → 6, 12, 6 → R↓ = 12; E↓ = 6;
    // A↓ = max(x̄ + 3S) − min(x̄ − 3S) = max(5, 12, 3) − min(−1, 0, −3) = 12 + 3 = 15.
    let ev = evaluate(&unidirectional(Direction::Reverse), Standard::Gb10931_1989).unwrap();
    assert_eq!(ev.unidirectional, Some(Direction::Reverse));
    some(ev.targets[1].mean_down, 6.0, "x̄_2↓");
    some(ev.targets[1].repeatability_down, 12.0, "R_2↓ = 6·2");
    assert_eq!(ev.targets[1].mean_up, None);
    let a = &ev.axis;
    some(a.R_down, 12.0, "R↓");
    some(a.E_down, 6.0, "E↓");
    some(a.A_down, 15.0, "A↓");
    assert_eq!((a.R_up, a.E_up, a.A_up), (None, None, None));
    assert_eq!(
        (a.B, a.B_mean, a.R, a.E, a.M, a.A),
        (None, None, None, None, None, None)
    );
    // VDI 3441: the one-direction scatter 6s gives the same R↓ = 12; Ps, U, P are bidirectional.
    let ev = evaluate(&unidirectional(Direction::Reverse), Standard::Vdi3441).unwrap();
    some(ev.axis.R_down, 12.0, "VDI R↓");
    assert_eq!((ev.axis.R, ev.axis.A, ev.axis.B), (None, None, None));
}

#[test]
fn mixed_run_file_names_the_file_and_the_target_line() {
    // Targets 0 and 10 from both directions; target 20 from + only, first at line 4.
    let text = "run,direction,target_mm,deviation_um\n\
1,+,0,1\n1,+,10,2\n1,+,20,3\n1,-,10,2\n1,-,0,1\n\
2,+,0,1\n2,+,10,2\n2,+,20,3\n2,-,10,2\n2,-,0,1\n";
    let err = parse_runs(Path::new("mixed.csv"), text)
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("mixed.csv:4") && err.contains("target 20") && err.contains("direction +"),
        "{err}"
    );
    // Forward-only and reverse-only files are accepted.
    let fwd = "run,direction,target_mm,deviation_um\n1,+,0,1\n1,+,10,2\n2,+,0,1\n2,+,10,2\n";
    assert!(parse_runs(Path::new("f.csv"), fwd).is_ok());
    let rev = fwd.replace(",+,", ",-,");
    assert!(parse_runs(Path::new("r.csv"), &rev).is_ok());
}

#[test]
fn standard_names_parse() {
    for s in Standard::ALL {
        assert_eq!(s.name().parse::<Standard>().unwrap(), s);
    }
    assert_eq!(
        "GB/T17421.2-2000".parse::<Standard>().unwrap(),
        Standard::Iso230_2_1997
    );
    assert!("iso9000".parse::<Standard>().is_err());
}

#[test]
fn reader_converts_actual_mm_and_keeps_env_and_time() {
    let text = "run,direction,target_mm,actual_mm,air_temp_c,pressure_kpa,humidity_pct,material_temp_c,time_s\n\
                1,+,0,0.0012,20.1,101.3,45,20.5,0\n\
                1,+,100,100.0030,,,,,12.5\n\
                1,-,100,99.9990,20.2,101.2,46,20.6,30\n\
                1,-,0,-0.0005,20.2,101.2,46,20.6,40\n";
    let f = parse_runs(Path::new("r.csv"), text).unwrap();
    assert!(f.had_actual);
    assert_eq!(f.rows.len(), 4);
    // (0.0012 − 0) mm = 1.2 µm; (100.003 − 100) mm = 3 µm; 99.999 − 100 = −1 µm.
    assert!((f.rows[0].deviation_um - 1.2).abs() < 1e-9);
    assert!((f.rows[1].deviation_um - 3.0).abs() < 1e-9);
    assert!((f.rows[2].deviation_um + 1.0).abs() < 1e-9);
    assert_eq!(f.rows[0].env.air_temp_c, Some(20.1));
    assert_eq!(f.rows[0].env.material_temp_c, Some(20.5));
    assert_eq!(f.rows[1].env.pressure_kpa, None);
    assert_eq!(f.rows[1].time_s, Some(12.5));
    assert_eq!(f.rows[3].line, 5);
    assert_eq!(f.rows[2].direction, Direction::Reverse);
    assert_eq!(f.targets_mm(), vec![0.0, 100.0]);
    let samples = f.samples();
    assert_eq!(samples.len(), 4);
    assert!((samples[1].deviation - 3.0).abs() < 1e-9 && samples[1].target == 100.0);
}

#[test]
fn reader_errors_name_file_line_and_what_to_fix() {
    let cases: [(&str, &[&str]); 7] = [
        (
            "run,direction,target_mm,deviation_um\n1,+,0,1\n1,x,100,2\n",
            &["r.csv:3, column direction", "'x' is not a direction"],
        ),
        (
            "run,direction,target_mm,deviation_um\n1,+,0,1\n1,+,100,abc\n",
            &["r.csv:3, column deviation_um", "'abc' is not a number"],
        ),
        (
            "run,direction,target_mm,deviation_um\n1,+,0,1\n1,+,100,2\n2,+,0,1\n",
            &["target 100 mm missing from run 2 direction +", "r.csv:4"],
        ),
        (
            "run,direction,target_mm,deviation_um\n1,+,0,1\n1,+,0,2\n",
            &["r.csv:3", "visits target 0 mm twice (first at line 2)"],
        ),
        (
            "run,direction,target_mm,actual_mm,deviation_um\n1,+,0,0,1\n",
            &["both actual_mm and deviation_um"],
        ),
        (
            "run,direction,target_mm,dev_um\n1,+,0,1\n",
            &["r.csv:1, column dev_um", "unknown column"],
        ),
        (
            "run,direction,target_mm,deviation_um\n-1,+,0,1\n",
            &["r.csv:2, column run", "not a run number"],
        ),
    ];
    for (text, needles) in cases {
        let err = parse_runs(Path::new("r.csv"), text)
            .unwrap_err()
            .to_string();
        for n in needles {
            assert!(err.contains(n), "for {text:?}: '{err}' lacks '{n}'");
        }
    }
    let err = parse_runs(
        Path::new("r.csv"),
        "run,direction,target_mm,deviation_um,humidity_pct\n1,+,0,1,120\n",
    )
    .unwrap_err()
    .to_string();
    assert!(err.contains("r.csv:2, column humidity_pct"), "{err}");
}

#[test]
fn malformed_tables_are_errors_not_panics() {
    use errmap_metrology::linear::{read_table, TableFormat, TableOptions};
    let dir = tempfile::tempdir().unwrap();
    let cases: [(&str, Option<TableFormat>); 12] = [
        ("0 1\n", Some(TableFormat::Linuxcnc)),
        ("0 a 1\n", Some(TableFormat::Linuxcnc)),
        ("5 5 5\n1 1 1\n", Some(TableFormat::Linuxcnc)),
        ("$AA_ENC_COMP[0,x,AX1]=1\n", Some(TableFormat::Sinumerik)),
        ("$AA_ENC_COMP[0,0,AX1]=1\n", Some(TableFormat::Sinumerik)),
        ("%\nN3620A1P0\n%\n", Some(TableFormat::Fanuc)),
        ("%\nN3620A1P0\nN3621A1P-5\nN3622A1P99999999\nN3623A1P1\nN3624A1P1\nN3626A1P0\nN3627A1P0\n%\n", Some(TableFormat::Fanuc)),
        ("%\nNxyz\n%\n", Some(TableFormat::Fanuc)),
        ("BEGIN X.COM MM\n", Some(TableFormat::Heidenhain)),
        ("BEGIN X.COM MM\nNR AXISPOS X\n0 1\n[END]\n", Some(TableFormat::Heidenhain)),
        ("position_mm,forward_um\n0,1\n", Some(TableFormat::Csv)),
        ("hello\n", None),
    ];
    for (i, (text, format)) in cases.iter().enumerate() {
        let path = dir.path().join(format!("t{i}.txt"));
        std::fs::write(&path, text).unwrap();
        let result = read_table(&path, *format, &TableOptions::default());
        let Err(err) = result else {
            panic!("case {i} {text:?} was accepted: {result:?}");
        };
        // Refused as bad input, naming the file.
        assert_eq!(
            errmap_core::error::Diagnose::diagnostic(&err).kind(),
            "input",
            "case {i}: {err}"
        );
        assert!(
            err.to_string().contains(&format!("t{i}.txt")),
            "case {i}: {err}"
        );
    }
}

/// The worked example of the VDI/DGQ 3441 and GB 10931 golden tests: positions j = 1…3 at
/// 0, 100, 200 mm, three approaches each way, readings a−d, a, a+d so that x̄ = a and s = d:
///
/// | j | pos | ↑ readings | x̄_j↑ | s_j↑ | ↓ readings | x̄_j↓ | s_j↓ |
/// |---|-----|------------|------|------|------------|------|------|
/// | 1 | 0   | 1, 2, 3    | 2    | 1    | −1, 0, 1   | 0    | 1    |
/// | 2 | 100 | 3, 5, 7    | 5    | 2    | 2, 4, 6    | 4    | 2    |
/// | 3 | 200 | −2, −1, 0  | −1   | 1    | −6, −4, −2 | −4   | 2    |
fn worked_example() -> Vec<Sample> {
    let table: [(f64, [f64; 3], [f64; 3]); 3] = [
        (0.0, [1.0, 2.0, 3.0], [-1.0, 0.0, 1.0]),
        (100.0, [3.0, 5.0, 7.0], [2.0, 4.0, 6.0]),
        (200.0, [-2.0, -1.0, 0.0], [-6.0, -4.0, -2.0]),
    ];
    let mut out = Vec::new();
    for (target, up, down) in table {
        for run in 0..3 {
            for (direction, deviation) in [
                (Direction::Forward, up[run]),
                (Direction::Reverse, down[run]),
            ] {
                out.push(Sample {
                    run: run as u32 + 1,
                    direction,
                    target,
                    deviation,
                });
            }
        }
    }
    out
}

fn figure(ev: &errmap_metrology::linear::Evaluation, symbol: &str, want: f64) {
    match ev.figure(symbol) {
        Some(Some(v)) => close(v, want, symbol),
        other => panic!("{}: {symbol} is {other:?}, expected {want}", ev.standard),
    }
}

#[test]
fn vdi3441_every_figure_of_the_worked_example_by_hand() {
    // U_j = |x̄_j↑ − x̄_j↓| = 2, 1, 3 → U max = 3, Ū = (2 + 1 + 3)/3 = 2.
    // s̄_j = (s_j↑ + s_j↓)/2 = 1, 2, 1.5 → Ps_j = 6·s̄_j = 6, 12, 9 → Ps max = 12,
    //   P̄s = (6 + 12 + 9)/3 = 9.
    // x̄_j = (x̄_j↑ + x̄_j↓)/2 = 1, 4.5, −2.5 → Pa = 4.5 − (−2.5) = 7.
    // (U_j + Ps_j)/2 = 4, 6.5, 6 → x̄_j + … = 5, 11, 3.5 (max 11), x̄_j − … = −3, −2, −8.5
    //   (min −8.5) → P = 19.5.
    let ev = evaluate(&worked_example(), Standard::Vdi3441).unwrap();
    figure(&ev, "P", 19.5);
    figure(&ev, "Pa", 7.0);
    figure(&ev, "Ps max", 12.0);
    figure(&ev, "P̄s", 9.0);
    figure(&ev, "U max", 3.0);
    figure(&ev, "Ū", 2.0);
    // Only VDI's own figures: no ISO symbols.
    let symbols: Vec<&str> = ev.figures().iter().map(|f| f.symbol).collect();
    assert_eq!(symbols, ["P", "Pa", "Ps max", "P̄s", "U max", "Ū"]);
    assert!(ev.figures().iter().all(|f| !f.definition.is_empty()));
}

#[test]
fn gb10931_every_figure_of_the_worked_example_by_hand() {
    // R_j↑ = 6S_j↑ = 6, 12, 6 → R↑ = 12; R_j↓ = 6S_j↓ = 6, 12, 12 → R↓ = 12; R = 12.
    // B_j = X̄_j↑ − X̄_j↓ = 2, 1, 3 → B = 3.
    // A↑: X̄↑ + 3S↑ = 5, 11, 2 (max 11); X̄↑ − 3S↑ = −1, −1, −4 (min −4) → A↑ = 15.
    // A↓: X̄↓ + 3S↓ = 3, 10, 2 (max 10); X̄↓ − 3S↓ = −3, −2, −10 (min −10) → A↓ = 20.
    // A over both directions: max 11, min −10 → A = 21.
    let ev = evaluate(&worked_example(), Standard::Gb10931_1989).unwrap();
    for (symbol, want) in [
        ("A", 21.0),
        ("A↑", 15.0),
        ("A↓", 20.0),
        ("R", 12.0),
        ("R↑", 12.0),
        ("R↓", 12.0),
        ("B", 3.0),
    ] {
        figure(&ev, symbol, want);
    }
    // GB's own figures only (ISO 230-2's E, M and B̄ are not GB 10931 figures), and GB's
    // per-position symbols (position j, X̄ and S).
    assert_eq!(ev.figure("E"), None);
    assert_eq!(ev.figure("M"), None);
    let names: Vec<&str> = ev.figures().iter().map(|f| f.name).collect();
    assert!(
        names
            .iter()
            .all(|n| n.contains("精度") || n.contains("反向差值")),
        "{names:?}"
    );
    assert_eq!(
        errmap_metrology::linear::target_symbols(Standard::Gb10931_1989)[0],
        "X̄_j↑"
    );
}
