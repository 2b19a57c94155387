//! `errmap k8s` manifests checked against the Kubernetes API's own types (`k8s-openapi`, v1.33): every field known, and the shard count, image, claim and merge step asked for.

mod common;

use k8s_openapi::api::batch::v1::Job;
use serde_json::Value;
use std::path::Path;

/// Deserialise into `batch/v1` Job and require that nothing was dropped: `k8s-openapi` skips
/// unknown fields, so a manifest that does not survive the round trip unchanged has one.
fn strict_job(doc: &Value) -> Result<Job, String> {
    let job: Job = serde_json::from_value(doc.clone()).map_err(|e| e.to_string())?;
    let back = serde_json::to_value(&job).map_err(|e| e.to_string())?;
    if &back != doc {
        return Err(format!(
            "fields unknown to batch/v1 Job were dropped:\n{}\nbecame\n{}",
            serde_json::to_string_pretty(doc).unwrap(),
            serde_json::to_string_pretty(&back).unwrap()
        ));
    }
    Ok(job)
}

fn read(path: &Path) -> Value {
    serde_json::from_slice(&std::fs::read(path).unwrap()).unwrap()
}

#[test]
fn manifests_are_batch_v1_jobs_with_the_shards_image_claim_and_merge_asked_for() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    common::ok(
        d,
        &[
            "synth",
            "web-plate",
            "--parts",
            "3",
            "--out-dir",
            "data",
            "--epochs",
            "20",
        ],
    );
    common::ok(
        d,
        &[
            "k8s",
            "data/job.toml",
            "--shards",
            "5",
            "--image",
            "registry.example/errmap:0.1",
            "--pvc",
            "plant-data",
            "--backend",
            "cpu",
            "--quiet",
        ],
    );
    let shards = strict_job(&read(&d.join("out/web-plate/k8s/shards-job.json"))).unwrap();
    let merge = strict_job(&read(&d.join("out/web-plate/k8s/merge-job.json"))).unwrap();

    let spec = shards.spec.as_ref().unwrap();
    assert_eq!(spec.completion_mode.as_deref(), Some("Indexed"));
    assert_eq!((spec.completions, spec.parallelism), (Some(5), Some(5)));
    let pod = spec.template.spec.as_ref().unwrap();
    let c = &pod.containers[0];
    assert_eq!(c.image.as_deref(), Some("registry.example/errmap:0.1"));
    let cmd = c.command.as_ref().unwrap().join(" ");
    assert_eq!(
        cmd,
        "errmap batch data/job.toml --shards 5 --out-dir out/web-plate --quiet --backend cpu"
    );
    let claim = |p: &k8s_openapi::api::core::v1::PodSpec| {
        p.volumes.as_ref().unwrap()[0]
            .persistent_volume_claim
            .as_ref()
            .unwrap()
            .claim_name
            .clone()
    };
    assert_eq!(claim(pod), "plant-data");
    assert_eq!(pod.restart_policy.as_deref(), Some("Never"));
    let mount = &c.volume_mounts.as_ref().unwrap()[0];
    assert_eq!(
        (mount.name.as_str(), mount.mount_path.as_str()),
        ("work", "/work")
    );
    assert_eq!(c.working_dir.as_deref(), Some("/work"));

    // The merge shares the claim and reduces the same output folder, waiting for the shards.
    let mpod = merge.spec.as_ref().unwrap().template.spec.as_ref().unwrap();
    assert_eq!(claim(mpod), "plant-data");
    let mc = &mpod.containers[0];
    assert_eq!(mc.image.as_deref(), Some("registry.example/errmap:0.1"));
    assert_eq!(
        mc.command.as_ref().unwrap().join(" "),
        "errmap merge out/web-plate --shards 5 --job data/job.toml --wait 86400 --quiet --backend cpu"
    );
    assert_eq!(
        merge.metadata.name.as_deref(),
        Some("errmap-web-plate-merge")
    );
}

#[test]
fn the_strict_check_catches_an_unknown_field() {
    let doc = serde_json::json!({
        "apiVersion": "batch/v1",
        "kind": "Job",
        "metadata": {"name": "x"},
        "spec": {"completions": 2, "template": {"spec": {"containers": [
            {"name": "a", "image": "i", "volumeMount": []}
        ]}}},
    });
    let err = strict_job(&doc).unwrap_err();
    assert!(err.contains("volumeMount"), "{err}");
    let mut fine = doc.clone();
    fine["spec"]["template"]["spec"]["containers"][0]
        .as_object_mut()
        .unwrap()
        .remove("volumeMount");
    assert!(strict_job(&fine).is_ok());
}
