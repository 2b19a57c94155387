//! Keeps Mesa's "XDG_RUNTIME_DIR is invalid or not set" off the output of tests and benches that open Vulkan in-process (the binary does the same in `src/main.rs`).

/// Point XDG_RUNTIME_DIR at a private 0700 folder of ours when it is unset. Call it before the
/// process first opens Vulkan; the callers do so from one `OnceLock` initialiser that every
/// Vulkan-opening test passes through first, so no Vulkan thread exists yet, and the other test
/// threads read the environment only through std's lock.
pub fn quiet_headless_vulkan() {
    #[cfg(unix)]
    {
        use std::os::unix::fs::{DirBuilderExt, MetadataExt, PermissionsExt};
        if std::env::var_os("XDG_RUNTIME_DIR").is_some() {
            return;
        }
        let Ok(uid) = std::fs::metadata("/proc/self").map(|m| m.uid()) else {
            return;
        };
        let dir = std::env::temp_dir().join(format!("errmap-runtime-{uid}"));
        let _ = std::fs::DirBuilder::new().mode(0o700).create(&dir);
        // Use it only if it is ours and private, as the XDG spec requires.
        match std::fs::symlink_metadata(&dir) {
            Ok(m) if m.is_dir() && m.uid() == uid && m.permissions().mode() & 0o777 == 0o700 => {
                std::env::set_var("XDG_RUNTIME_DIR", &dir);
            }
            _ => {}
        }
    }
}
