//! Kubernetes manifests for a sharded job: an Indexed Job with one completion per shard and a merge Job that waits on the shared volume for every shard, then reduces.
//!
//! Both are `batch/v1` Jobs in JSON (which `kubectl apply -f` reads like YAML); the tests
//! check them against the `k8s-openapi` types.

use crate::ClusterError;
use errmap_core::error::{Diagnostic, Result};
use serde_json::{json, Value};
use std::path::{Path, PathBuf};

/// What the manifests run and where. The errmap command lines are the caller's: the batch
/// knows Kubernetes, the front end knows its own command line.
#[derive(Debug, Clone)]
pub struct K8sPlan {
    /// The job's family; names the Jobs (`errmap-<family>-shards`, `-merge`) and labels them.
    pub family: String,
    /// Number of shards: the Indexed Job's completions and parallelism.
    pub shards: usize,
    /// Container image that holds the errmap binary (run as `errmap` on its PATH).
    pub image: String,
    /// The PersistentVolumeClaim that holds the job, the probe files and the outputs.
    pub pvc: String,
    /// Where the claim is mounted in the containers; also their working directory.
    pub mount: String,
    /// The arguments of each shard's errmap (its index comes from `JOB_COMPLETION_INDEX`).
    pub shard_args: Vec<String>,
    /// The arguments of the merge's errmap (it waits on the volume for the shards).
    pub merge_args: Vec<String>,
    /// Retries of a failed shard (per index).
    pub retries: u32,
}

/// The family as a DNS label: lower case, `[a-z0-9-]`, at most `max` characters.
fn dns_label(family: &str, max: usize) -> String {
    let mut base: String = family
        .to_ascii_lowercase()
        .chars()
        .map(|c| if c.is_ascii_alphanumeric() { c } else { '-' })
        .collect();
    base = base.trim_matches('-').to_string();
    base.truncate(max);
    base.trim_end_matches('-').to_string()
}

/// A Kubernetes object name from the family: `errmap-<family>-<suffix>`, at most 63 characters.
pub fn object_name(family: &str, suffix: &str) -> String {
    let max = 63 - suffix.len() - "errmap--".len();
    format!("errmap-{}-{suffix}", dns_label(family, max))
}

impl K8sPlan {
    fn labels(&self) -> Value {
        json!({
            "app.kubernetes.io/name": "errmap",
            "errmap.family": dns_label(&self.family, 63),
        })
    }

    fn pod_spec(&self, container: &str, args: Vec<String>) -> Value {
        let mut command = vec!["errmap".to_string()];
        command.extend(args);
        json!({
            "restartPolicy": "Never",
            "containers": [{
                "name": container,
                "image": self.image,
                "command": command,
                "workingDir": self.mount,
                "volumeMounts": [{"name": "work", "mountPath": self.mount}],
            }],
            "volumes": [{
                "name": "work",
                "persistentVolumeClaim": {"claimName": self.pvc},
            }],
        })
    }

    /// The Indexed Job: completion I (`JOB_COMPLETION_INDEX`) maps shard I of N.
    pub fn shards_job(&self) -> Value {
        let args = self.shard_args.clone();
        json!({
            "apiVersion": "batch/v1",
            "kind": "Job",
            "metadata": {"name": object_name(&self.family, "shards"), "labels": self.labels()},
            "spec": {
                "completionMode": "Indexed",
                "completions": self.shards,
                "parallelism": self.shards,
                "backoffLimitPerIndex": self.retries,
                "maxFailedIndexes": self.shards,
                "template": {
                    "metadata": {"labels": self.labels()},
                    "spec": self.pod_spec("shard", args),
                },
            },
        })
    }

    /// The merge Job: waits on the volume until every shard has committed, then reduces.
    pub fn merge_job(&self) -> Value {
        let args = self.merge_args.clone();
        json!({
            "apiVersion": "batch/v1",
            "kind": "Job",
            "metadata": {"name": object_name(&self.family, "merge"), "labels": self.labels()},
            "spec": {
                "completions": 1,
                "backoffLimit": self.retries,
                "template": {
                    "metadata": {"labels": self.labels()},
                    "spec": self.pod_spec("merge", args),
                },
            },
        })
    }
}

/// The manifests as files: `(file name, pretty JSON)` of the shards' Job and the merge Job.
pub fn manifest_files(plan: &K8sPlan) -> Result<[(&'static str, String); 2], ClusterError> {
    let text = |v: &Value| {
        serde_json::to_string_pretty(v)
            .map_err(|e| ClusterError::Internal(Diagnostic::Internal(e.to_string())))
    };
    Ok([
        ("shards-job.json", text(&plan.shards_job())?),
        ("merge-job.json", text(&plan.merge_job())?),
    ])
}

/// Write the manifests into `dir` (each ends with a newline); their paths, shards' first.
pub fn write_manifests(plan: &K8sPlan, dir: &Path) -> Result<Vec<PathBuf>, ClusterError> {
    let mut paths = Vec::new();
    for (name, text) in manifest_files(plan)? {
        let path = dir.join(name);
        errmap_core::io::write_atomic_bytes(&path, format!("{text}\n").as_bytes())?;
        paths.push(path);
    }
    Ok(paths)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn object_names_are_dns_labels() {
        assert_eq!(
            object_name("web-plate", "shards"),
            "errmap-web-plate-shards"
        );
        assert_eq!(
            object_name("Web_Plate.2", "merge"),
            "errmap-web-plate-2-merge"
        );
        let long = object_name(&"a".repeat(100), "shards");
        assert!(long.len() <= 63 && long.ends_with("-shards"), "{long}");
    }
}
