//! errmap command line: parse the arguments, call the library, print, and turn the result into an exit code.

mod cli;

use clap::Parser;
use errmap::error::{Diagnose, Diagnostic};

fn main() {
    // Library hints name settings; the binary words them as its flags.
    errmap::setting::install_wording(cli::words::flag);
    errmap::gpu::quiet_headless_vulkan();
    let args = cli::Cli::parse();
    let code = match cli::run(args) {
        Ok(code) => code,
        Err(err) => {
            // A closed pipe (`errmap … | head`) is not an error worth reporting.
            if let Diagnostic::Io { source, .. } = err.diagnostic() {
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
            cli::exit::code(&err)
        }
    };
    std::process::exit(code);
}
