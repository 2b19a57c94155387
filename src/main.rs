//! errmap command line: parse the arguments, call the library, print, and turn the result into an exit code.

mod cli;

use clap::Parser;

fn main() {
    quiet_headless_vulkan();
    let args = cli::Cli::parse();
    let code = match cli::run(args) {
        Ok(code) => code,
        Err(err) => {
            // A closed pipe (`errmap … | head`) is not an error worth reporting.
            if let errmap::Error::Io { source, .. } = &err {
                if source.kind() == std::io::ErrorKind::BrokenPipe {
                    std::process::exit(0);
                }
            }
            eprintln!("errmap: {err}");
            let mut cause = std::error::Error::source(&err);
            while let Some(c) = cause {
                eprintln!("  caused by: {c}");
                cause = c.source();
            }
            err.exit_code()
        }
    };
    std::process::exit(code);
}

/// Mesa's Vulkan drivers print "XDG_RUNTIME_DIR is invalid or not set" on headless machines
/// (batch nodes, CI) where no login session sets it. Point it at a private folder of ours
/// before any thread starts, so a batch's output carries no false alarm.
fn quiet_headless_vulkan() {
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
