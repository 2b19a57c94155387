//! The server settings that hints name; the front end words them (the binary as its flags).

/// A setting of `serve` or its users file that a hint can tell the user to give.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Setting {
    /// The PEM certificate chain served over TLS.
    TlsCert,
    /// The PEM private key of the TLS certificate.
    TlsKey,
    /// The address of a TLS reverse proxy whose forwarded client address is trusted.
    TrustedProxy,
    /// Serving plain HTTP on a non-loopback address, risk accepted.
    InsecureHttp,
    /// The role a user is given: `viewer` or `operator`.
    Role,
    /// The users file.
    Users,
    /// The new user's password read from standard input.
    PasswordStdin,
    /// Replacing an existing user's password or role.
    Replace,
    /// The live state file shown on the live page.
    Live,
    /// The folder of batch runs served.
    Runs,
    /// The store of the thermal commands.
    Db,
}

impl errmap_core::Setting for Setting {
    fn key(self) -> &'static str {
        match self {
            Setting::TlsCert => "tls_cert",
            Setting::TlsKey => "tls_key",
            Setting::TrustedProxy => "trusted_proxy",
            Setting::InsecureHttp => "insecure_http",
            Setting::Role => "role",
            Setting::Users => "users",
            Setting::PasswordStdin => "password_stdin",
            Setting::Replace => "replace",
            Setting::Live => "live",
            Setting::Runs => "runs",
            Setting::Db => "db",
        }
    }
}
