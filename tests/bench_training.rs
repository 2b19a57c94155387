//! `errmap bench training --json`: the report's work, wall-clock and CPU-time figures agree with each other and with the work asked for.

mod common;

#[test]
fn training_bench_reports_work_per_wall_and_per_cpu_second() {
    let dir = tempfile::tempdir().unwrap();
    let (parts, samples, epochs) = (2u64, 200u64, 40u64);
    let run = common::errmap(
        dir.path(),
        &[
            "bench",
            "training",
            "--backend",
            "cpu",
            "--parts",
            &parts.to_string(),
            "--samples",
            &samples.to_string(),
            "--epochs",
            &epochs.to_string(),
            "--json",
        ],
    );
    run.expect_code(0);
    let doc = common::json(&run);
    let num = |key: &str| {
        doc[key]
            .as_f64()
            .unwrap_or_else(|| panic!("{key} missing:\n{}", run.report()))
    };
    // The work asked for: 2 networks × 200 samples × 40 epochs = 16 000 sample·epochs.
    let work = (parts * samples * epochs) as f64;
    assert_eq!(work, 16_000.0);
    let (wall_s, cpu_s) = (num("train_s"), num("train_cpu_s"));
    assert!(wall_s > 0.0 && cpu_s > 0.0, "{}", run.report());
    assert!(
        (num("sample_epochs_per_s") * wall_s - work).abs() <= 1e-6 * work,
        "{}",
        run.report()
    );
    assert!(
        (num("sample_epochs_per_cpu_s") * cpu_s - work).abs() <= 1e-6 * work,
        "{}",
        run.report()
    );
    // The CPU time is that of the timed epochs only: the process's threads cannot have
    // spent more than wall time × cores in them (plus the clocks' granularity).
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get()) as f64;
    assert!(
        cpu_s <= wall_s * cores + 0.05,
        "{cpu_s} CPU s in {wall_s} s on {cores} cores:\n{}",
        run.report()
    );
}
