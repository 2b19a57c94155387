//! The typed errors of `errmap live`: what a caller can act on when the config, a model, a
//! source, a target or the run's record is refused. Each variant carries the located
//! diagnostic errmap prints.

use errmap_core::error::Diagnostic;

/// Why a live config was refused ([`crate::LiveConfig::read`], [`crate::LiveConfig::parse`]).
#[derive(Debug)]
#[non_exhaustive]
pub enum ConfigError {
    /// The config file cannot be read.
    Read(Diagnostic),
    /// A key or value is refused: not TOML there, an unknown key, a value out of its range, a
    /// combination that means nothing (the diagnostic names the line and the key).
    Key(Diagnostic),
    /// A bug in errmap.
    Internal(Diagnostic),
}
errmap_core::typed_error!(ConfigError {
    Read,
    Key,
    Internal
});

impl From<Diagnostic> for ConfigError {
    /// A diagnostic of the config check by its kind.
    fn from(d: Diagnostic) -> Self {
        match d {
            Diagnostic::Io { .. } if d.is_read() => ConfigError::Read(d),
            Diagnostic::Input { .. } | Diagnostic::Usage { .. } | Diagnostic::Numeric { .. } => {
                ConfigError::Key(d)
            }
            Diagnostic::Io { .. } | Diagnostic::Device { .. } | Diagnostic::Internal(_) => {
                ConfigError::Internal(d)
            }
        }
    }
}

/// Why a source or a target could not be used: its keys, the machine it names, or its login
/// (the `connect` of each source and target kind).
#[derive(Debug)]
#[non_exhaustive]
pub enum LinkError {
    /// A key of its config table is refused (a channel layout, a node id, a pin name, a
    /// security policy errmap does not build in, an axis it has no layout for).
    Config(Diagnostic),
    /// It cannot be opened, reached or read: a server that does not answer, a LinuxCNC that is
    /// not running, a CSV source that does not open, no reading within its timeout at start.
    Unreachable(Diagnostic),
    /// The server refused the login (the configured user and password, or an anonymous
    /// session); the diagnostic names the `user` key.
    Refused(Diagnostic),
    /// A bug in errmap.
    Internal(Diagnostic),
}
errmap_core::typed_error!(LinkError {
    Config,
    Unreachable,
    Refused,
    Internal
});

impl From<Diagnostic> for LinkError {
    /// A diagnostic of a connect, a read or a write by its kind: a key's (input), the link's
    /// (I/O) or errmap's. A login refusal is built where it is detected.
    fn from(d: Diagnostic) -> Self {
        match d {
            Diagnostic::Input { .. } | Diagnostic::Usage { .. } | Diagnostic::Numeric { .. } => {
                LinkError::Config(d)
            }
            // A file the source names that cannot be read is the config's to fix.
            Diagnostic::Io { .. } if d.is_read() => LinkError::Config(d),
            Diagnostic::Io { .. } => LinkError::Unreachable(d),
            Diagnostic::Device { .. } | Diagnostic::Internal(_) => LinkError::Internal(d),
        }
    }
}

/// Why `errmap live` stopped with an error ([`crate::run`], [`crate::cycle::Live::prepare`],
/// [`crate::cycle::Live::run`], [`crate::StopFlags::register_signals`]).
#[derive(Debug)]
#[non_exhaustive]
pub enum LiveError {
    /// A key of the config does not fit the models or sources it names (an axis's model of
    /// another axis, a sensor no model has, a channel no source delivers, no `[coolant]` for a
    /// model with coolant gains), or an option contradicts it (`--once` with a replay).
    Config(Diagnostic),
    /// An axis's model file cannot be read or is refused.
    Model(Diagnostic),
    /// A source could not be used.
    Source(LinkError),
    /// A target could not be used.
    Target(LinkError),
    /// The store is refused: not an errmap store, a sensor stored with another role or unit,
    /// a store SQLite cannot open or write.
    Store(Diagnostic),
    /// The run's record cannot be written: the store's writer, the state file.
    Record(Diagnostic),
    /// A bug in errmap.
    Internal(Diagnostic),
}
errmap_core::typed_error!(LiveError {
    Config,
    Model,
    Source,
    Target,
    Store,
    Record,
    Internal
});

impl From<Diagnostic> for LiveError {
    /// A diagnostic of the config check by its kind: a key's (input, or a file the config
    /// names that cannot be read), the record's (any other I/O) or errmap's.
    fn from(d: Diagnostic) -> Self {
        match d {
            Diagnostic::Input { .. } | Diagnostic::Usage { .. } | Diagnostic::Numeric { .. } => {
                LiveError::Config(d)
            }
            Diagnostic::Io { .. } if d.is_read() => LiveError::Config(d),
            Diagnostic::Io { .. } => LiveError::Record(d),
            Diagnostic::Device { .. } | Diagnostic::Internal(_) => LiveError::Internal(d),
        }
    }
}

impl LiveError {
    /// A model file's diagnostic: refused or unreadable (the model's), or errmap's.
    pub(crate) fn model(d: Diagnostic) -> Self {
        match d {
            Diagnostic::Device { .. } | Diagnostic::Internal(_) => LiveError::Internal(d),
            Diagnostic::Io { .. } if !d.is_read() => LiveError::Internal(d),
            _ => LiveError::Model(d),
        }
    }

    /// A diagnostic of the run's record: the store refused (input, or a store that cannot be
    /// read), an output that cannot be written, or errmap's.
    pub(crate) fn record(d: Diagnostic) -> Self {
        match d {
            Diagnostic::Input { .. } | Diagnostic::Usage { .. } | Diagnostic::Numeric { .. } => {
                LiveError::Store(d)
            }
            Diagnostic::Io { .. } if d.is_read() => LiveError::Store(d),
            Diagnostic::Io { .. } => LiveError::Record(d),
            Diagnostic::Device { .. } | Diagnostic::Internal(_) => LiveError::Internal(d),
        }
    }

    /// A source's diagnostic.
    pub(crate) fn source(d: Diagnostic) -> Self {
        LiveError::Source(LinkError::from(d))
    }

    /// A target's diagnostic.
    pub(crate) fn target(d: Diagnostic) -> Self {
        LiveError::Target(LinkError::from(d))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use errmap_core::error::Location;

    #[test]
    fn a_diagnostic_is_filed_by_its_kind() {
        let key = Diagnostic::input(Location::cell("live.toml", 7, "3"), "bad key", "");
        let unreadable = Diagnostic::read("live.toml", std::io::ErrorKind::NotFound.into());
        let unreachable = Diagnostic::io(
            "reach",
            "Modbus source 'rack'",
            std::io::ErrorKind::ConnectionRefused.into(),
        );
        let bug = Diagnostic::Internal("x".into());
        assert!(matches!(ConfigError::from(key), ConfigError::Key(_)));
        assert!(matches!(
            ConfigError::from(Diagnostic::read(
                "live.toml",
                std::io::ErrorKind::NotFound.into()
            )),
            ConfigError::Read(_)
        ));
        assert!(matches!(
            LinkError::from(unreachable),
            LinkError::Unreachable(_)
        ));
        assert!(matches!(LiveError::model(unreadable), LiveError::Model(_)));
        assert!(matches!(LiveError::from(bug), LiveError::Internal(_)));
        let write = Diagnostic::write("state.json", std::io::ErrorKind::PermissionDenied.into());
        assert!(matches!(LiveError::record(write), LiveError::Record(_)));
    }
}
