//! The typed errors of `errmap serve`: what a caller can act on when the users file, the
//! address, the TLS certificate or the store is refused. Each variant carries the located
//! diagnostic errmap prints.

use errmap_core::error::Diagnostic;

/// Why the users file or a change to it was refused ([`crate::users::Users::load`],
/// [`crate::users::Users::save`], [`crate::users::Users::add`],
/// [`crate::users::Users::remove`]).
#[derive(Debug)]
#[non_exhaustive]
pub enum UsersError {
    /// There is no users file where the server looks for one (add a user first).
    Missing(Diagnostic),
    /// The file cannot be read.
    Read(Diagnostic),
    /// The file is not a users file: not TOML there, an unknown key, a name not in stored
    /// form or twice, a hash that is not an argon2id PHC string.
    File(Diagnostic),
    /// A user name is refused: not a user name, a user that exists already (without
    /// `replace`), no user of that name to remove.
    Name(Diagnostic),
    /// A new password is too short or too long.
    Password(Diagnostic),
    /// The file may not be written there (it would overwrite an input).
    Output(Diagnostic),
    /// The file cannot be written.
    Write(Diagnostic),
    /// A bug in errmap (hashing, the file as TOML).
    Internal(Diagnostic),
}
errmap_core::typed_error!(UsersError {
    Missing,
    Read,
    File,
    Name,
    Password,
    Output,
    Write,
    Internal
});

impl UsersError {
    /// A diagnostic of writing the file, by its kind.
    pub(crate) fn save(d: Diagnostic) -> Self {
        match d {
            Diagnostic::Io { .. } if d.is_read() => UsersError::Read(d),
            Diagnostic::Io { .. } => UsersError::Write(d),
            Diagnostic::Input { .. } | Diagnostic::Usage { .. } | Diagnostic::Numeric { .. } => {
                UsersError::Output(d)
            }
            Diagnostic::Device { .. } | Diagnostic::Internal(_) => UsersError::Internal(d),
        }
    }
}

/// Why `errmap serve` did not start or stopped with an error ([`crate::run`],
/// [`crate::check_transport`]).
#[derive(Debug)]
#[non_exhaustive]
pub enum ServeError {
    /// Plain HTTP on an address other than loopback without `insecure_http`.
    Transport(Diagnostic),
    /// The users file was refused.
    Users(UsersError),
    /// The runs folder does not exist or is not a folder.
    Runs(Diagnostic),
    /// The store is refused: no file there, not an errmap store, not in WAL mode.
    Store(Diagnostic),
    /// The TLS certificate or key cannot be read or is not a usable PEM pair.
    Tls(Diagnostic),
    /// The address cannot be listened on (in use, not this machine's, no permission), or
    /// serving on it failed.
    Bind(Diagnostic),
    /// A bug in errmap (the async runtime, hashing).
    Internal(Diagnostic),
}
errmap_core::typed_error!(ServeError {
    Transport,
    Users,
    Runs,
    Store,
    Tls,
    Bind,
    Internal
});

impl From<UsersError> for ServeError {
    fn from(e: UsersError) -> Self {
        ServeError::Users(e)
    }
}

impl ServeError {
    /// A diagnostic of opening the store, by its kind: the store's (input, unreadable) or
    /// errmap's.
    pub(crate) fn store(d: Diagnostic) -> Self {
        match d {
            Diagnostic::Io { .. } if !d.is_read() => ServeError::Internal(d),
            Diagnostic::Device { .. } | Diagnostic::Internal(_) => ServeError::Internal(d),
            _ => ServeError::Store(d),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use errmap_core::error::Location;

    #[test]
    fn a_diagnostic_is_filed_by_its_kind() {
        let over_input = Diagnostic::input(Location::file("users.toml"), "would overwrite", "");
        let write = Diagnostic::write("users.toml", std::io::ErrorKind::PermissionDenied.into());
        let not_a_store = Diagnostic::input(Location::file("s.sqlite"), "store: not a db", "");
        assert!(matches!(
            UsersError::save(over_input),
            UsersError::Output(_)
        ));
        assert!(matches!(UsersError::save(write), UsersError::Write(_)));
        assert!(matches!(
            ServeError::store(not_a_store),
            ServeError::Store(_)
        ));
        assert!(matches!(
            ServeError::store(Diagnostic::Internal("x".into())),
            ServeError::Internal(_)
        ));
    }
}
