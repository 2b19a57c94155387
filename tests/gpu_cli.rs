//! `errmap gpu-info` through the real binary: text and one JSON document.

use std::process::Command;

fn errmap(args: &[&str]) -> (i32, String, String) {
    let dir = tempfile::tempdir().unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_errmap"))
        .args(args)
        .current_dir(dir.path())
        .output()
        .unwrap();
    let (stdout, stderr) = (
        String::from_utf8_lossy(&out.stdout).to_string(),
        String::from_utf8_lossy(&out.stderr).to_string(),
    );
    (out.status.code().unwrap_or(-1), stdout, stderr)
}

#[test]
fn gpu_info_json_is_one_document_naming_the_choice() {
    let (code, stdout, stderr) = errmap(&["gpu-info", "--json"]);
    assert_eq!(
        code, 0,
        "errmap gpu-info --json\nstdout:\n{stdout}\nstderr:\n{stderr}"
    );
    let doc: serde_json::Value = serde_json::from_str(&stdout)
        .unwrap_or_else(|e| panic!("not one JSON document ({e}):\n{stdout}"));
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
    let (code, stdout, stderr) = errmap(&["gpu-info"]);
    assert_eq!(
        code, 0,
        "errmap gpu-info\nstdout:\n{stdout}\nstderr:\n{stderr}"
    );
    assert!(stdout.contains("adapters"), "{stdout}");
    assert!(stdout.contains("--backend auto trains on the"), "{stdout}");
}
