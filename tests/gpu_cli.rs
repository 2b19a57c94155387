//! `errmap gpu-info` through the real binary: text and one JSON document.

mod common;

#[test]
fn gpu_info_json_is_one_document_naming_the_choice() {
    let dir = tempfile::tempdir().unwrap();
    let run = common::ok(dir.path(), &["gpu-info", "--json"]);
    let doc = common::json(&run);
    let stdout = &run.stdout;
    let adapters = doc["adapters"].as_array().expect("adapters array");
    let software = doc["chosen"]["software"].as_bool() == Some(true);
    match doc["auto_backend"].as_str() {
        Some("cpu") if software => {
            // A software adapter serves --backend gpu; auto prefers the CPU trainer.
            assert_eq!(doc["chosen"]["name"], adapters[0]["name"], "{stdout}");
            assert!(
                doc["limits"]["max_storage_buffer_binding_size"]
                    .as_u64()
                    .unwrap()
                    > 0
            );
        }
        Some("gpu") => {
            assert!(!adapters.is_empty());
            let chosen = &doc["chosen"];
            // The chosen adapter is the first listed (best first) and its limits are given.
            assert_eq!(chosen["name"], adapters[0]["name"], "{stdout}");
            assert!(
                doc["limits"]["max_storage_buffer_binding_size"]
                    .as_u64()
                    .unwrap()
                    > 0
            );
        }
        Some("cpu") => {
            if std::env::var("ERRMAP_REQUIRE_GPU").as_deref() == Ok("1") {
                panic!("ERRMAP_REQUIRE_GPU=1 but gpu-info found no usable adapter:\n{stdout}");
            }
            eprintln!("SKIPPED part of gpu_info test: no GPU adapter");
            assert!(
                doc["chosen"].is_null() && doc["error"].is_string(),
                "{stdout}"
            );
        }
        other => panic!("auto_backend {other:?}:\n{stdout}"),
    }
}

#[test]
fn gpu_info_text_lists_adapters_and_the_backend_auto_uses() {
    let dir = tempfile::tempdir().unwrap();
    let stdout = common::ok(dir.path(), &["gpu-info"]).stdout;
    assert!(stdout.contains("adapters"), "{stdout}");
    assert!(stdout.contains("--backend auto trains on the"), "{stdout}");
}

/// Every file under `dir` with its size, relative paths.
fn snapshot(dir: &std::path::Path) -> Vec<(String, u64)> {
    let mut out: Vec<(String, u64)> = common::files(dir)
        .into_iter()
        .map(|p| {
            let size = std::fs::metadata(&p).map(|m| m.len()).unwrap_or(0);
            (p.strip_prefix(dir).unwrap().display().to_string(), size)
        })
        .collect();
    out.sort();
    out
}

/// A kernel built on a CPU adapter is kept in Mesa's on-disk shader cache: a second process
/// that opens the adapter and builds the same kernel reuses it and adds nothing to the cache.
#[test]
fn a_second_open_reuses_the_pipeline_cache() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let mesa = d.join("mesa-cache");
    let args = [
        "bench",
        "training",
        "--backend",
        "gpu",
        "--parts",
        "2",
        "--samples",
        "64",
        "--epochs",
        "2",
        "--hidden",
        "4,4",
        "--json",
    ];
    let run = || {
        common::errmap_with(d, &args, |c| {
            c.env("MESA_SHADER_CACHE_DIR", &mesa);
            c.env_remove("MESA_SHADER_CACHE_DISABLE");
        })
    };
    let first = run();
    if first.code == 3 {
        if std::env::var("ERRMAP_REQUIRE_GPU").as_deref() == Ok("1") {
            panic!("ERRMAP_REQUIRE_GPU=1 but no adapter:\n{}", first.report());
        }
        eprintln!("SKIPPED a_second_open_reuses_the_pipeline_cache: no GPU adapter");
        return;
    }
    first.expect_code(0);
    let doc = common::json(&first);
    let device = doc["device"].as_str().unwrap_or_default().to_string();
    if !device.contains("llvmpipe") {
        eprintln!(
            "SKIPPED a_second_open_reuses_the_pipeline_cache: {device} keeps its own driver cache"
        );
        return;
    }
    let built = snapshot(&mesa);
    assert!(
        !built.is_empty(),
        "the first build stored nothing:\n{}",
        first.report()
    );
    run().expect_code(0);
    assert_eq!(
        snapshot(&mesa),
        built,
        "the second open rebuilt kernels instead of reusing the cache"
    );
}
