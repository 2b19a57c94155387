//! The users file of `errmap serve` (`users.toml`): names, roles and argon2id password hashes (PHC strings), rewritten atomically and readable by its owner only.
//!
//! ```toml
//! [[user]]
//! name = "ada"
//! role = "operator"          # or "viewer"
//! password_hash = "$argon2id$v=19$m=19456,t=2,p=1$…"
//! ```
//!
//! Names are case-insensitive (kept in lower case); hashes use argon2id with the argon2
//! crate's defaults (19 MiB, 2 passes, 1 lane), the OWASP Password Storage Cheat Sheet's
//! minimum for argon2id.

use crate::error::UsersError;
use crate::Setting;
use argon2::password_hash::phc::PasswordHash;
use argon2::password_hash::{PasswordHasher, PasswordVerifier};
use argon2::Argon2;
use errmap_core::error::{Error, Location, Result};
use errmap_core::setting::words;
use serde::{Deserialize, Serialize};
use std::io::Write;
use std::path::Path;

/// Fewest characters a password may have (OWASP Authentication Cheat Sheet, password length).
pub const MIN_PASSWORD_CHARS: usize = 8;
/// Most bytes a password may have: long enough for any passphrase, short enough that hashing
/// a submitted one cannot be used to load the server.
pub const MAX_PASSWORD_BYTES: usize = 1024;
/// Most characters of a user name.
pub const MAX_NAME_CHARS: usize = 64;

/// What a user may do.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Role {
    /// Reads every page.
    Viewer,
    /// Reads, and pauses, resumes and acknowledges alarms of the live loop.
    Operator,
}

impl Role {
    /// The role as the users file, the log and the audit log spell it.
    pub fn as_str(self) -> &'static str {
        match self {
            Role::Viewer => "viewer",
            Role::Operator => "operator",
        }
    }
}

/// One user of the users file.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct User {
    /// The user name as stored: lower case, 1 to 64 of letters, digits, `.`, `_`, `-`, `@`.
    pub name: String,
    /// What the user may do; read afresh from the file on every request.
    pub role: Role,
    /// The password's argon2id hash as a PHC string (algorithm, parameters, salt, hash).
    pub password_hash: String,
}

/// The users file's content.
#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Users {
    /// The users, the file's `[[user]]` tables (sorted by name when written by [`Users::add`]).
    #[serde(default, rename = "user")]
    pub users: Vec<User>,
}

/// A user name as stored: trimmed, lower case; `None` unless it is 1 to 64 of the characters
/// letters, digits, `.`, `_`, `-`, `@`.
pub fn normalise_name(name: &str) -> Option<String> {
    let name = name.trim();
    let ok = !name.is_empty()
        && name.chars().count() <= MAX_NAME_CHARS
        && name
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || matches!(c, '.' | '_' | '-' | '@'));
    ok.then(|| name.to_ascii_lowercase())
}

impl Users {
    /// Read a users file; a missing file is an empty list when `missing_ok`. Refused (with the
    /// file and line): TOML that is not a users file, unknown keys, a name not in stored form
    /// (lower case), a name twice, a hash that is not an argon2id PHC string. The hashes' parameters
    /// are not checked.
    pub fn load(path: &Path, missing_ok: bool) -> Result<Users, UsersError> {
        let text = match std::fs::read_to_string(path) {
            Ok(t) => t,
            Err(e) if missing_ok && e.kind() == std::io::ErrorKind::NotFound => {
                return Ok(Users::default())
            }
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
                return Err(UsersError::Missing(Error::read(path, e)))
            }
            Err(e) => return Err(UsersError::Read(Error::read(path, e))),
        };
        let users: Users = toml::from_str(&text).map_err(|e| {
            let line = e
                .span()
                .map(|s| text[..s.start.min(text.len())].matches('\n').count() as u64 + 1);
            UsersError::File(Error::input(
                Location {
                    file: path.to_path_buf(),
                    line,
                    column: None,
                },
                format!("not a users file: {}", e.message()),
                format!(
                    "write it with `errmap serve user add NAME {} viewer|operator {} FILE {}`",
                    words(Setting::Role),
                    words(Setting::Users),
                    words(Setting::PasswordStdin)
                ),
            ))
        })?;
        let mut seen = std::collections::BTreeSet::new();
        for u in &users.users {
            let at = |msg: String| {
                UsersError::File(Error::input(
                    Location::file(path),
                    msg,
                    "remove the entry and add it again with `errmap serve user add`",
                ))
            };
            match normalise_name(&u.name) {
                Some(n) if n == u.name => {}
                _ => return Err(at(format!("user name {:?} is not a stored name (lower case letters, digits, . _ - @; at most {MAX_NAME_CHARS})", u.name))),
            }
            if !seen.insert(u.name.clone()) {
                return Err(at(format!("user {:?} appears twice", u.name)));
            }
            let parsed = PasswordHash::new(&u.password_hash).map_err(|e| {
                at(format!(
                    "the password hash of {:?} is not a PHC string: {e}",
                    u.name
                ))
            })?;
            if parsed.algorithm.as_str() != "argon2id" {
                return Err(at(format!(
                    "the password hash of {:?} is {}, not argon2id",
                    u.name,
                    parsed.algorithm.as_str()
                )));
            }
        }
        Ok(users)
    }

    /// Write the file atomically (a temporary file beside it, renamed), mode 0600: it holds
    /// password hashes.
    pub fn save(&self, path: &Path) -> Result<(), UsersError> {
        self.write(path).map_err(UsersError::save)
    }

    fn write(&self, path: &Path) -> Result<()> {
        let mut text = String::from(
            "# errmap serve users: argon2id password hashes (PHC strings).\n# Edit with `errmap serve user add|remove|list`.\n\n",
        );
        text.push_str(
            &toml::to_string(self)
                .map_err(|e| Error::Internal(format!("users file as TOML: {e}")))?,
        );
        errmap_core::io::safety::check_output(path)?;
        let dir = match path.parent() {
            Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
            _ => std::path::PathBuf::from("."),
        };
        std::fs::create_dir_all(&dir).map_err(|e| Error::io("create folder", &dir, e))?;
        // tempfile creates the file 0600, which is what a file of hashes should stay.
        let mut tmp = tempfile::Builder::new()
            .prefix(".errmap-users-")
            .suffix(".tmp")
            .tempfile_in(&dir)
            .map_err(|e| Error::io("create a temporary file in", &dir, e))?;
        tmp.write_all(text.as_bytes())
            .and_then(|()| tmp.as_file().sync_all())
            .map_err(|e| Error::write(path, e))?;
        tmp.persist(path)
            .map_err(|e| Error::io("rename the finished file to", path, e.error))?;
        Ok(())
    }

    /// The user of a stored name (exact match: normalise a typed name first with
    /// [`normalise_name`]); `None` when there is none.
    pub fn get(&self, name: &str) -> Option<&User> {
        self.users.iter().find(|u| u.name == name)
    }

    /// Add a user (name normalised, password checked by [`check_password`] and hashed with
    /// [`hash_password`]), or replace one of that name when `replace`; an error for a bad name,
    /// a bad password, or an existing user without `replace`. The file is written by [`Users::save`].
    pub fn add(
        &mut self,
        name: &str,
        role: Role,
        password: &str,
        replace: bool,
    ) -> Result<(), UsersError> {
        let name = normalise_name(name).ok_or_else(|| {
            UsersError::Name(Error::usage(
                format!("{name:?} is not a user name"),
                format!("use 1 to {MAX_NAME_CHARS} letters, digits, '.', '_', '-' or '@'"),
            ))
        })?;
        check_password(password).map_err(UsersError::Password)?;
        if self.get(&name).is_some() && !replace {
            return Err(UsersError::Name(Error::usage(
                format!("user {name:?} exists already"),
                format!(
                    "give {} to set a new password or role",
                    words(Setting::Replace)
                ),
            )));
        }
        let password_hash = hash_password(password).map_err(UsersError::Internal)?;
        self.users.retain(|u| u.name != name);
        self.users.push(User {
            name,
            role,
            password_hash,
        });
        self.users.sort_by(|a, b| a.name.cmp(&b.name));
        Ok(())
    }

    /// Remove a user; an error when there is none of that name.
    pub fn remove(&mut self, name: &str) -> Result<(), UsersError> {
        let key = normalise_name(name).unwrap_or_default();
        let before = self.users.len();
        self.users.retain(|u| u.name != key);
        if self.users.len() == before {
            return Err(UsersError::Name(Error::usage(
                format!("no user {name:?}"),
                format!(
                    "`errmap serve user list {} FILE` lists them",
                    words(Setting::Users)
                ),
            )));
        }
        Ok(())
    }
}

/// A new password's length rules: at least [`MIN_PASSWORD_CHARS`] characters, at most
/// [`MAX_PASSWORD_BYTES`] bytes, any characters, no composition rules.
pub fn check_password(password: &str) -> Result<()> {
    if password.chars().count() < MIN_PASSWORD_CHARS {
        return Err(Error::usage(
            format!("the password has fewer than {MIN_PASSWORD_CHARS} characters"),
            "choose a longer password or a passphrase",
        ));
    }
    if password.len() > MAX_PASSWORD_BYTES {
        return Err(Error::usage(
            format!("the password is longer than {MAX_PASSWORD_BYTES} bytes"),
            "choose a shorter passphrase",
        ));
    }
    Ok(())
}

/// An argon2id PHC string of a password with a random 16-byte salt and the argon2 crate's
/// default parameters (19 MiB, 2 passes, 1 lane); takes 19 MiB and tens of ms. It does not
/// check the length: call [`check_password`] first for a new password.
pub fn hash_password(password: &str) -> Result<String> {
    Argon2::default()
        .hash_password(password.as_bytes())
        .map(|h| h.to_string())
        .map_err(|e| Error::Internal(format!("argon2 hashing failed: {e}")))
}

/// Whether a password matches a PHC string (argon2 compares in constant time, with the
/// parameters the string names). A password over [`MAX_PASSWORD_BYTES`] or a string that does
/// not parse is `false` without hashing.
pub fn verify_password(password: &str, phc: &str) -> bool {
    if password.len() > MAX_PASSWORD_BYTES {
        return false;
    }
    match PasswordHash::new(phc) {
        Ok(parsed) => Argon2::default()
            .verify_password(password.as_bytes(), &parsed)
            .is_ok(),
        Err(_) => false,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_are_case_insensitive_and_bounded() {
        assert_eq!(normalise_name(" Ada "), Some("ada".into()));
        assert_eq!(normalise_name("a.b_c-d@e"), Some("a.b_c-d@e".into()));
        assert_eq!(normalise_name(""), None);
        assert_eq!(normalise_name("a b"), None);
        assert_eq!(normalise_name("ä"), None);
        assert_eq!(normalise_name(&"x".repeat(65)), None);
    }

    #[test]
    fn hashes_are_argon2id_and_verify_only_their_password() {
        let h = hash_password("correct horse").unwrap();
        assert!(h.starts_with("$argon2id$v=19$m=19456,t=2,p=1$"), "{h}");
        assert!(verify_password("correct horse", &h));
        assert!(!verify_password("correct horsf", &h));
        assert!(!verify_password("correct horse", "not a hash"));
        // Two hashes of one password differ (random salt).
        assert_ne!(h, hash_password("correct horse").unwrap());
    }
}
