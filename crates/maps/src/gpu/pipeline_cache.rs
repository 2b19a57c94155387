//! wgpu pipeline caches in errmap's cache folder, one file per adapter, driver, errmap version and architecture: handed to wgpu when intact and current, rebuilt with a note when stale or corrupt, written atomically after a build.

use std::path::{Path, PathBuf};

use errmap_pipeline_cache::{create, Saved};
use sha2::{Digest, Sha256};

use super::context::GpuContext;

/// Sub-folder of the cache folder that holds pipeline caches.
const FOLDER: &str = "pipelines";

/// What the pipeline cache did for one kernel build (for tests, notes and `bench`).
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct CacheUse {
    /// The cache file of this adapter, driver, errmap version and architecture (`None`: no
    /// cache folder, or the device has no pipeline caches).
    pub file: Option<PathBuf>,
    /// Bytes read from the file and accepted by wgpu and the driver (0 on a miss).
    pub loaded_bytes: usize,
    /// The saved cache was used.
    pub hit: bool,
    /// Bytes written back after the build (0 when nothing was written).
    pub saved_bytes: usize,
    /// Why a file that was there was not used, or could not be written.
    pub note: Option<String>,
}

/// The key of one architecture's cache: adapter, driver, errmap version and architecture.
pub fn cache_key(ctx: &GpuContext, architecture: &str) -> Option<String> {
    let base = ctx.pipeline_cache_key.as_ref()?;
    let a = &ctx.adapter;
    Some(format!(
        "{base} | {} | {} | {} | errmap {} | {architecture}",
        a.name,
        a.driver,
        a.driver_info,
        env!("CARGO_PKG_VERSION")
    ))
}

/// The file of `key` in `dir`: wgpu's adapter key and a digest of the whole key.
fn file_of(dir: &Path, ctx: &GpuContext, key: &str) -> Option<PathBuf> {
    let base = ctx.pipeline_cache_key.as_ref()?;
    let digest = Sha256::digest(key.as_bytes());
    let short: String = digest[..8].iter().map(|b| format!("{b:02x}")).collect();
    Some(dir.join(FOLDER).join(format!("{base}-{short}.bin")))
}

/// Opens the pipeline cache of `architecture` (from its file in `dir` when there is one
/// and wgpu takes it), or `None` when the device keeps no pipeline caches.
pub fn open(
    ctx: &GpuContext,
    dir: Option<&Path>,
    architecture: &str,
) -> (Option<wgpu::PipelineCache>, CacheUse) {
    let mut found = CacheUse::default();
    let Some(key) = cache_key(ctx, architecture) else {
        return (None, found);
    };
    let label = "errmap cpu-adapter kernels";
    let Some(file) = dir.and_then(|d| file_of(d, ctx, &key)) else {
        return (Some(create(&ctx.device, label, None, true)), found);
    };
    found.file = Some(file.clone());
    let saved = match std::fs::read(&file) {
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => None,
        Err(e) => {
            found.note = Some(format!("could not read {} ({e})", file.display()));
            None
        }
        Ok(bytes) => match Saved::decode(&bytes, &key) {
            Ok(saved) => Some(saved),
            Err(why) => {
                found.note = Some(rejected(&file, &why.to_string()));
                None
            }
        },
    };
    if let Some(saved) = saved {
        // Without fallback, wgpu reports data it will not use (another driver or wgpu).
        let scope = ctx.device.push_error_scope(wgpu::ErrorFilter::Validation);
        let cache = create(&ctx.device, label, Some(&saved), false);
        match pollster::block_on(scope.pop()) {
            None => {
                found.hit = true;
                found.loaded_bytes = saved.len();
                return (Some(cache), found);
            }
            Some(e) => found.note = Some(rejected(&file, &format!("stale: {e}"))),
        }
    }
    (Some(create(&ctx.device, label, None, true)), found)
}

fn rejected(file: &Path, why: &str) -> String {
    format!(
        "the pipeline cache {} was not used ({}); the kernel is built anew and the cache rewritten",
        file.display(),
        why.lines().next().unwrap_or(why)
    )
}

/// Writes `cache`'s data to its file (atomically) unless the file was used as it is.
pub fn save(
    ctx: &GpuContext,
    cache: &wgpu::PipelineCache,
    architecture: &str,
    found: &mut CacheUse,
) {
    let (Some(file), Some(key)) = (found.file.clone(), cache_key(ctx, architecture)) else {
        return;
    };
    let Some(saved) = Saved::of(cache, &key) else {
        return;
    };
    if found.hit && saved.len() == found.loaded_bytes {
        return;
    }
    match errmap_core::io::write_atomic_bytes(&file, &saved.encode()) {
        Ok(()) => found.saved_bytes = saved.len(),
        Err(e) => {
            found.note = Some(format!(
                "the pipeline cache {} could not be written ({e}); the next run builds the kernel again",
                file.display()
            ))
        }
    }
}
