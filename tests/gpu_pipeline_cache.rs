//! The CPU-adapter kernels' pipeline cache on disk: the first open writes it, a second open reads it and wgpu takes it, a corrupt file is rebuilt with a note (lavapipe on CI).
//!
//! Without an adapter that keeps pipeline caches (Vulkan) the test prints why it skips,
//! unless ERRMAP_REQUIRE_GPU=1, where it fails.

use std::sync::{Arc, Mutex};

use errmap::gpu::pipeline_cache::CacheUse;
use errmap::gpu::{GpuTrainer, KernelFamily};
use errmap::nn::{ModelConfig, Trainer, TrainingSet};

/// A small architecture, so that its kernel compiles in a second or two.
fn config() -> ModelConfig {
    ModelConfig {
        hidden: vec![4],
        epochs: 3,
        loss_every: 3,
        ..ModelConfig::default()
    }
}

/// Opens a CPU-adapter trainer whose pipeline caches live in `dir`, builds the kernel of
/// [`config`], and returns what the cache did and the notes it gave; `None` to skip.
fn build_in(dir: &std::path::Path) -> Option<(CacheUse, Vec<String>)> {
    let notes = Arc::new(Mutex::new(Vec::new()));
    let sink = Arc::clone(&notes);
    let trainer = match GpuTrainer::new() {
        Ok(t) => t
            .with_kernels(KernelFamily::CpuAdapter)
            .with_pipeline_cache_dir(Some(dir.to_path_buf()))
            .with_notes(Arc::new(move |n: &str| {
                sink.lock().unwrap().push(n.to_string())
            })),
        Err(e) => return skip(&e.to_string()),
    };
    if trainer.context().pipeline_cache_key.is_none() {
        return skip(&format!(
            "{} keeps no pipeline caches",
            trainer.context().describe()
        ));
    }
    let built = trainer.prepare(&config()).expect("kernel builds");
    assert!(built.is_some(), "the CPU-adapter kernel was asked for");
    // The kernel trains after any cache outcome.
    let set = TrainingSet {
        inputs: vec![[0.1, 0.2], [0.5, -0.3], [-0.7, 0.9]],
        targets: vec![0.3, -0.1, 0.4],
    };
    let nets = trainer.train_batch(&[set], &config()).expect("trains");
    assert!(nets[0].params.iter().all(|p| p.is_finite()));
    let used = trainer.pipeline_cache_use(&config()).expect("kernel built");
    let notes = notes.lock().unwrap().clone();
    Some((used, notes))
}

fn skip(reason: &str) -> Option<(CacheUse, Vec<String>)> {
    if std::env::var("ERRMAP_REQUIRE_GPU").as_deref() == Ok("1") {
        panic!("ERRMAP_REQUIRE_GPU=1 but no pipeline cache: {reason}");
    }
    eprintln!("SKIPPED pipeline cache test: {reason}");
    None
}

#[test]
fn a_second_open_reuses_the_pipeline_cache_and_a_corrupt_one_is_rebuilt() {
    errmap::gpu::quiet_headless_vulkan();
    let dir = tempfile::tempdir().unwrap();
    // First open: nothing to read; the cache is written.
    let Some((first, notes)) = build_in(dir.path()) else {
        return;
    };
    assert!(!first.hit, "{first:?}");
    assert_eq!(first.loaded_bytes, 0);
    assert!(first.saved_bytes > 0, "nothing written: {first:?}");
    let file = first.file.clone().expect("a cache file");
    assert!(
        file.starts_with(dir.path()),
        "{file:?} outside the private folder"
    );
    assert!(file.exists());
    assert!(notes.is_empty(), "{notes:?}");

    // Second open: the file is read and wgpu takes all of its bytes.
    let (second, notes) = build_in(dir.path()).unwrap();
    assert!(
        second.hit,
        "the saved pipeline cache was not reused: {second:?}"
    );
    assert_eq!(second.loaded_bytes, first.saved_bytes);
    assert_eq!(second.file.as_ref(), Some(&file));
    assert!(notes.is_empty(), "{notes:?}");

    // A corrupt file: not handed to the driver, rebuilt with one note, written again.
    let mut bytes = std::fs::read(&file).unwrap();
    let last = bytes.len() - 1;
    bytes[last] ^= 0x5a;
    std::fs::write(&file, &bytes).unwrap();
    let (third, notes) = build_in(dir.path()).unwrap();
    assert!(!third.hit, "{third:?}");
    assert_eq!(third.loaded_bytes, 0);
    assert_eq!(notes.len(), 1, "{notes:?}");
    assert!(notes[0].contains("corrupt"), "{notes:?}");
    assert_eq!(third.saved_bytes, first.saved_bytes);

    // … and the rewritten file is reused again.
    let (fourth, _) = build_in(dir.path()).unwrap();
    assert!(fourth.hit, "{fourth:?}");
}
