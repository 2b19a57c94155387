//! Air refractive index against NIST and IAPWS published values; air and material corrections, pitch fit and error budget against hand arithmetic.

use errmap_metrology::linear::{
    compute_budget, correct_air, fit_pitch, normalise_material, parse_runs, refractive_index,
    saturation_vapour_pressure_pa, sensitivities, AirConditions, AirCorrection, AirFormula,
    BudgetSetup,
};
use std::f64::consts::PI;
use std::path::Path;

/// NIST Engineering Metrology Toolbox, "Index of Refraction of Air" calculator
/// (https://emtoolbox.nist.gov/Wavelength/Documentation.asp), values quoted in issue 4:
/// 20 °C, 101.325 kPa, 633 nm, 450 µmol/mol CO2.
#[test]
fn reproduces_nist_calculator_values_to_1e_8() {
    let cases = [
        (0.0, AirFormula::Ciddor, 1.000_271_800),
        (0.0, AirFormula::Edlen, 1.000_271_799),
        (50.0, AirFormula::Ciddor, 1.000_271_373),
    ];
    for (rh, formula, nist) in cases {
        let n = refractive_index(&AirConditions::new(20.0, 101.325, rh, 633.0), formula).unwrap();
        // NIST prints 9 decimals: agreement to half a unit in the last place (5e-10) is far inside 1e-8.
        assert!(
            (n - nist).abs() < 1e-8,
            "{formula:?} RH {rh}: {n:.10} vs NIST {nist}"
        );
        assert!(
            (n - nist).abs() <= 5.1e-10,
            "{formula:?} RH {rh}: {n:.10} vs NIST {nist}"
        );
    }
}

/// The saturation vapour pressure over water is the IAPWS-IF97 region-4 equation; IAPWS-IF97
/// (revised release 2007), Table 35 gives its verification values.
#[test]
fn saturation_pressure_matches_iapws_if97_table_35() {
    for (t_k, p_mpa) in [
        (300.0, 0.353_658_941e-2),
        (500.0, 0.263_889_776e1),
        (600.0, 0.123_443_146e2),
    ] {
        let p = saturation_vapour_pressure_pa(t_k - 273.15) * 1e-6;
        assert!(
            ((p - p_mpa) / p_mpa).abs() < 1e-8,
            "{t_k} K: {p} MPa vs {p_mpa}"
        );
    }
    // The water branch gives 611.657 Pa at the triple point 273.16 K (IF97); the ice branch
    // (NIST A-I, IAPWS 1993 sublimation) takes over below 0 °C: 611.15 Pa just below 0 °C
    // against 611.21 Pa over water at 0 °C.
    assert!((saturation_vapour_pressure_pa(0.01) - 611.657).abs() < 0.01);
    let ice0 = saturation_vapour_pressure_pa(-1e-9);
    let water0 = saturation_vapour_pressure_pa(0.0);
    assert!(
        (ice0 - 611.15).abs() < 0.02 && (water0 - 611.21).abs() < 0.02,
        "{ice0} {water0}"
    );
    let ice = saturation_vapour_pressure_pa(-20.0);
    // Ice at −20 °C: 103.26 Pa (Wagner, Saul & Pruss 1994; CRC handbook 103.3 Pa).
    assert!((ice - 103.26).abs() < 0.05, "{ice}");
}

/// Cross-check against an independent implementation of the same NIST documentation:
/// the `ref-index` Python package (https://pypi.org/project/ref-index/, README examples),
/// 633 nm, 101 325 Pa, 450 µmol/mol CO2. Agreement to 1e-12 shows the same constants and
/// the same saturation-pressure and enhancement-factor formulas.
#[test]
fn agrees_with_ref_index_package_examples() {
    let cases = [
        (20.0, 20.0, AirFormula::Ciddor, 1.000_271_628_534_057_8),
        (20.0, 20.0, AirFormula::Edlen, 1.000_271_629_169_165),
        (20.0, 80.0, AirFormula::Edlen, 1.000_271_119_763_522_6),
        (20.0, 80.0, AirFormula::Ciddor, 1.000_271_118_347_262_6),
        (60.0, 80.0, AirFormula::Edlen, 1.000_233_974_854_282_3),
        (60.0, 80.0, AirFormula::Ciddor, 1.000_234_024_175_405_5),
    ];
    for (t, rh, formula, expected) in cases {
        let n = refractive_index(&AirConditions::new(t, 101.325, rh, 633.0), formula).unwrap();
        assert!(
            (n - expected).abs() < 1e-12,
            "{formula:?} {t} °C {rh} %: {n:.16} vs {expected}"
        );
    }
}

#[test]
fn index_trends_and_range_checks() {
    let base = AirConditions::new(20.0, 101.325, 50.0, 632.991);
    for f in [AirFormula::Ciddor, AirFormula::Edlen] {
        let n0 = refractive_index(&base, f).unwrap();
        let warm = refractive_index(
            &AirConditions {
                temp_c: 21.0,
                ..base
            },
            f,
        )
        .unwrap();
        let high = refractive_index(
            &AirConditions {
                pressure_kpa: 102.325,
                ..base
            },
            f,
        )
        .unwrap();
        // (n − 1) ∝ density: −(n−1)/T ≈ −9.3e-7 per K, +(n−1)/p ≈ +2.7e-6 per kPa (±3 %).
        let d_t = warm - n0;
        let d_p = high - n0;
        assert!(
            (d_t / (-(n0 - 1.0) / 293.15) - 1.0).abs() < 0.03,
            "{f:?} dT {d_t}"
        );
        assert!(
            (d_p / ((n0 - 1.0) / 101.325) - 1.0).abs() < 0.03,
            "{f:?} dp {d_p}"
        );
        // Ciddor and Edlén agree within 2e-8 near standard conditions (NIST, section VII).
    }
    let c = refractive_index(&base, AirFormula::Ciddor).unwrap();
    let e = refractive_index(&base, AirFormula::Edlen).unwrap();
    assert!((c - e).abs() < 2e-8, "{c} {e}");
    assert_refused(
        refractive_index(
            &AirConditions {
                humidity_pct: 120.0,
                ..base
            },
            AirFormula::Ciddor,
        ),
        "input",
        "relative humidity 120 % is outside 0…100 %",
    );
    assert_refused(
        refractive_index(
            &AirConditions {
                wavelength_nm: 200.0,
                ..base
            },
            AirFormula::Edlen,
        ),
        "input",
        "wavelength 200 nm is outside 300…1700 nm",
    );
    let co2 = AirConditions {
        co2_ppm: 600.0,
        ..base
    };
    assert_refused(
        refractive_index(&co2, AirFormula::Edlen),
        "input",
        "Edlén equation assumes 450 µmol/mol CO2",
    );
    // More CO2 raises Ciddor's index: raxs·(1 + 5.34e-7·150) and a heavier Ma.
    assert!(refractive_index(&co2, AirFormula::Ciddor).unwrap() > c);
}

#[test]
fn air_correction_divides_the_reading_by_n() {
    // 20 °C, 101.325 kPa, 0 %, 633 nm: n = 1.000271800 (NIST). A laser showing
    // 1000.2718 mm on the vacuum scale measured 1000.2718 / 1.0002718 = 1000.0000 mm.
    // Second row: datum 100 mm, reading 600.1359 → 100 + 500.1359 / 1.0002718 = 600.0000.
    let text = "run,direction,target_mm,actual_mm,air_temp_c,pressure_kpa,humidity_pct\n\
                1,+,1000,1000.2718,20,101.325,0\n\
                1,-,1000,1000.2718,20,101.325,0\n";
    let file = parse_runs(Path::new("a.csv"), text).unwrap();
    let settings = AirCorrection {
        formula: AirFormula::Ciddor,
        wavelength_nm: 633.0,
        co2_ppm: 450.0,
        datum_mm: 0.0,
    };
    let (out, n) = correct_air(&file, &settings).unwrap();
    assert!((n[0] - 1.000_271_800).abs() < 1e-9);
    // Uncorrected deviation +271.8 µm; corrected ≈ 0 (n known to 1e-9 → ±0.001 µm).
    assert!((file.rows[0].deviation_um - 271.8).abs() < 1e-6);
    assert!(
        out.rows[0].deviation_um.abs() < 2e-3,
        "{}",
        out.rows[0].deviation_um
    );
    let text = "run,direction,target_mm,actual_mm,air_temp_c,pressure_kpa,humidity_pct\n\
                1,+,600,600.1359,20,101.325,0\n1,-,600,600.1359,20,101.325,0\n";
    let file = parse_runs(Path::new("a.csv"), text).unwrap();
    let (out, _) = correct_air(
        &file,
        &AirCorrection {
            datum_mm: 100.0,
            ..settings
        },
    )
    .unwrap();
    assert!(
        out.rows[0].deviation_um.abs() < 2e-3,
        "{}",
        out.rows[0].deviation_um
    );
    // Missing environment is an error naming file:line and column.
    let text = "run,direction,target_mm,deviation_um,air_temp_c,pressure_kpa,humidity_pct\n1,+,0,0,20,,50\n";
    let file = parse_runs(Path::new("a.csv"), text).unwrap();
    let err = correct_air(&file, &settings).unwrap_err().to_string();
    assert!(err.contains("a.csv:2, column pressure_kpa"), "{err}");
}

#[test]
fn material_normalisation_to_20_c() {
    // α = 10 µm/(m·K), material at 25 °C: L20 = 500.025 / (1 + 10e-6 · 5) = 500.025 / 1.00005
    // = 500.000 mm, so a +25 µm deviation at 500 mm is pure expansion and becomes 0.
    // At 15 °C: 499.975 / (1 − 50e-6) = 499.975 / 0.99995 = 500.000: −25 µm becomes 0.
    let text = "run,direction,target_mm,actual_mm,material_temp_c\n\
                1,+,500,500.025,25\n1,-,500,499.975,15\n";
    let file = parse_runs(Path::new("m.csv"), text).unwrap();
    assert!((file.rows[0].deviation_um - 25.0).abs() < 1e-6);
    let out = normalise_material(&file, 10.0, 0.0).unwrap();
    assert!(
        out.rows[0].deviation_um.abs() < 1e-6,
        "{}",
        out.rows[0].deviation_um
    );
    assert!(
        out.rows[1].deviation_um.abs() < 1e-6,
        "{}",
        out.rows[1].deviation_um
    );
    let text = "run,direction,target_mm,deviation_um,material_temp_c\n1,+,500,3,\n";
    let file = parse_runs(Path::new("m.csv"), text).unwrap();
    let err = normalise_material(&file, 10.0, 0.0)
        .unwrap_err()
        .to_string();
    assert!(err.contains("m.csv:2, column material_temp_c"), "{err}");
}

#[test]
fn pitch_fit_recovers_planted_values_exactly() {
    // e(x) = a + k·x + d·sin(2πx/P + φ) with a = 2 µm, k = 15 µm/m, d = 1.2 µm, φ = −2.0 rad,
    // P = 5 mm, at irregular targets (noise-free).
    let (a, k, d, phi, lead) = (2.0, 15.0, 1.2, -2.0, 5.0);
    let xs: Vec<f64> = (0..25)
        .map(|i| i as f64 * 41.3 + (i * i % 7) as f64 * 0.37)
        .collect();
    let es: Vec<f64> = xs
        .iter()
        .map(|x| a + k * x * 1e-3 + d * (2.0 * PI * x / lead + phi).sin())
        .collect();
    let fit = fit_pitch(&xs, &es, lead).unwrap();
    assert!((fit.a_um - a).abs() < 1e-9, "{fit:?}");
    assert!((fit.k_um_per_m - k).abs() < 1e-9, "{fit:?}");
    assert!((fit.d_um - d).abs() < 1e-9, "{fit:?}");
    assert!((fit.phi_rad - phi).abs() < 1e-9, "{fit:?}");
    assert!(fit.residual_rms_um < 1e-9, "{fit:?}");
    assert!(
        (fit.eval(123.4) - (a + k * 0.1234 + d * (2.0 * PI * 123.4 / lead + phi).sin())).abs()
            < 1e-9
    );
    // Targets at whole multiples of the lead cannot see the periodic term.
    let xs: Vec<f64> = (0..10).map(|i| i as f64 * 50.0).collect();
    let es: Vec<f64> = xs.iter().map(|x| 1.0 + x * 0.01).collect();
    let err = fit_pitch(&xs, &es, 5.0).unwrap_err().to_string();
    assert!(err.contains("multiples of the lead"), "{err}");
    assert_refused(
        fit_pitch(&xs[..4], &es[..4], 7.0),
        "input",
        "needs at least 5 targets, got 4",
    );
}

#[test]
fn budget_terms_by_hand() {
    // L = 1000 mm; Edlén at 20 °C, 101.325 kPa, 0 % RH, 632.991 nm.
    let setup: BudgetSetup = toml::from_str(
        r#"
        length_mm = 1000.0
        laser_stability_ppm = 0.1
        [air]
        formula = "edlen"
        temp_c = 20.0
        pressure_kpa = 101.325
        humidity_pct = 0.0
        temp_uncertainty_c = 0.1
        pressure_uncertainty_kpa = 0.1
        humidity_uncertainty_pct = 5.0
        [abbe]
        offset_mm = 10.0
        angle_arcsec = 2.0
        [alignment]
        angle_arcsec = 30.0
        [thermal]
        expansion_ppm_per_k = 11.5
        temp_uncertainty_c = 0.2
        "#,
    )
    .unwrap();
    let b = compute_budget(&setup).unwrap();
    let term = |name: &str| b.terms.iter().find(|t| t.name == name).unwrap().value_um;
    let arcsec = PI / 648_000.0;
    // δ1 = 0.1e-6 × 1e6 µm = 0.1 µm.
    assert!((term("laser_stability") - 0.1).abs() < 1e-12);
    // δ3 = 10 000 µm × tan(2″) = 10 000 × 9.6963e-6 = 0.096963 µm.
    assert!((term("abbe") - 1e4 * (2.0 * arcsec).tan()).abs() < 1e-12);
    assert!((term("abbe") - 0.096_963).abs() < 1e-6);
    // δ4 = 1e6 µm × (1 − cos 30″) ≈ 1e6 × θ²/2 = 1e6 × (1.45444e-4)²/2 = 0.0105770 µm.
    assert!((term("cosine_misalignment") - 0.010_577).abs() < 1e-6);
    // δ5 = 11.5e-6 × 0.2 × 1e6 µm = 2.3 µm.
    assert!((term("thermal_expansion") - 2.3).abs() < 1e-12);
    // δ2 from the Edlén partials in closed form (dry air, so the water term only enters ∂n/∂RH):
    // n − 1 = p(ns−1)/D · X, X = (1 + 1e-8(E − F t)p)/(1 + G t), p in Pa.
    let (e_, f_, g_, d_) = (0.601, 0.009_72, 0.003_661, 96_095.43);
    let s = 1.0 / (0.632_991f64 * 0.632_991);
    let ns1 = 1e-8 * (8342.54 + 2_406_147.0 / (130.0 - s) + 15_998.0 / (38.9 - s));
    let (t, p) = (20.0, 101_325.0);
    let q = 1.0 + 1e-8 * (e_ - f_ * t) * p;
    let dn_dp_pa = ns1 / d_ * (q + 1e-8 * (e_ - f_ * t) * p) / (1.0 + g_ * t);
    let dn_dt =
        p * ns1 / d_ * ((-1e-8 * f_ * p) * (1.0 + g_ * t) - g_ * q) / (1.0 + g_ * t).powi(2);
    let psv = saturation_vapour_pressure_pa(20.0);
    let dn_drh = -1e-10 * (292.75 / 293.15) * (3.7345 - 0.0401 * s) * psv / 100.0;
    let cond = AirConditions::new(20.0, 101.325, 0.0, 632.991);
    let [st, sp, sh] = sensitivities(&cond, AirFormula::Edlen).unwrap();
    assert!((st / dn_dt - 1.0).abs() < 1e-6, "{st} vs {dn_dt}");
    assert!(
        (sp / (dn_dp_pa * 1e3) - 1.0).abs() < 1e-6,
        "{sp} vs {}",
        dn_dp_pa * 1e3
    );
    assert!((sh / dn_drh - 1.0).abs() < 1e-6, "{sh} vs {dn_drh}");
    let delta2 =
        1e6 * ((dn_dt * 0.1).powi(2) + (dn_dp_pa * 100.0).powi(2) + (dn_drh * 5.0).powi(2)).sqrt();
    assert!((term("wavelength_correction") / delta2 - 1.0).abs() < 1e-6);
    // About 0.28 µm: pressure dominates (2.68e-6/kPa × 0.1 kPa × 1 m).
    assert!((delta2 - 0.28).abs() < 0.02, "{delta2}");
    let total = [
        0.1,
        term("abbe"),
        term("cosine_misalignment"),
        2.3,
        term("wavelength_correction"),
    ]
    .iter()
    .map(|v| v * v)
    .sum::<f64>()
    .sqrt();
    assert!((b.total_um - total).abs() < 1e-12);
}

/// Each condition is refused just outside the range the air-index equations are valid for
/// (−40…100 °C, 10…140 kPa, 0…100 %, 300…1700 nm, 0…2000 µmol/mol) and accepted at its edge,
/// with the quantity and its range named.
#[test]
fn air_index_refuses_conditions_outside_the_valid_range() {
    let standard = AirConditions {
        temp_c: 20.0,
        pressure_kpa: 101.325,
        humidity_pct: 50.0,
        wavelength_nm: 633.0,
        co2_ppm: 450.0,
    };
    type Field = fn(&mut AirConditions) -> &mut f64;
    let cases: [(Field, f64, f64, &str); 10] = [
        (
            |c| &mut c.temp_c,
            -40.0,
            -40.01,
            "air temperature -40.01 °C is outside −40…100 °C",
        ),
        (
            |c| &mut c.temp_c,
            100.0,
            100.01,
            "air temperature 100.01 °C is outside",
        ),
        (
            |c| &mut c.pressure_kpa,
            10.0,
            9.99,
            "pressure 9.99 kPa is outside 10…140 kPa",
        ),
        (
            |c| &mut c.pressure_kpa,
            140.0,
            140.01,
            "pressure 140.01 kPa is outside",
        ),
        (
            |c| &mut c.humidity_pct,
            0.0,
            -0.01,
            "relative humidity -0.01 % is outside 0…100 %",
        ),
        (
            |c| &mut c.humidity_pct,
            100.0,
            100.01,
            "relative humidity 100.01 % is outside",
        ),
        (
            |c| &mut c.wavelength_nm,
            300.0,
            299.99,
            "wavelength 299.99 nm is outside 300…1700 nm",
        ),
        (
            |c| &mut c.wavelength_nm,
            1700.0,
            1700.01,
            "wavelength 1700.01 nm is outside",
        ),
        (
            |c| &mut c.co2_ppm,
            0.0,
            -0.01,
            "CO2 content -0.01 µmol/mol is outside 0…2000",
        ),
        (
            |c| &mut c.co2_ppm,
            2000.0,
            2000.01,
            "CO2 content 2000.01 µmol/mol is outside",
        ),
    ];
    for (field, edge, outside, message) in cases {
        let mut at_edge = standard;
        *field(&mut at_edge) = edge;
        assert!(
            refractive_index(&at_edge, AirFormula::Ciddor).is_ok(),
            "{message}: the edge value {edge} must be accepted"
        );
        let mut beyond = standard;
        *field(&mut beyond) = outside;
        let err = refractive_index(&beyond, AirFormula::Ciddor)
            .unwrap_err()
            .to_string();
        assert!(err.contains(message), "expected '{message}' in: {err}");
    }
}

/// Assert that `result` is refused with an error of `kind` whose message holds `words`.
fn assert_refused<T: std::fmt::Debug>(result: errmap_core::Result<T>, kind: &str, words: &str) {
    let err = result.expect_err(words);
    assert_eq!(err.kind(), kind, "{err}");
    assert!(err.to_string().contains(words), "{err}");
}
