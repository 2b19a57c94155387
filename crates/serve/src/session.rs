//! Sessions of `errmap serve`: random ids kept server-side (by their SHA-256), idle and absolute expiry, one CSRF token per session, the pre-session token of the login form, and the cookies that carry them.
//!
//! Ids and tokens are 256 random bits from the operating system's generator (session ids must
//! be unpredictable, so they are the one random choice in errmap not drawn from a seed).

use base64::Engine as _;
use hmac::{Hmac, KeyInit, Mac};
use rand::TryRngCore as _;
use sha2::{Digest, Sha256};
use std::collections::HashMap;
use std::sync::Mutex;
use std::time::{Duration, Instant};

use super::users::Role;

/// 32 random bytes as unpadded base64url (43 characters).
pub fn random_token() -> String {
    let mut bytes = [0u8; 32];
    // The operating system's generator; failing it, no token can be trusted: stop serving.
    if rand::rngs::OsRng.try_fill_bytes(&mut bytes).is_err() {
        eprintln!("errmap serve: the operating system's random generator failed; stopping");
        std::process::exit(3);
    }
    base64::engine::general_purpose::URL_SAFE_NO_PAD.encode(bytes)
}

/// Equality of two secrets in time independent of where they differ (for session ids and CSRF
/// tokens). Strings of different lengths return `false` at once, so the length is not hidden:
/// use it on fixed-length values such as [`random_token`]'s.
pub fn same_secret(a: &str, b: &str) -> bool {
    let (a, b) = (a.as_bytes(), b.as_bytes());
    if a.len() != b.len() {
        return false;
    }
    a.iter().zip(b).fold(0u8, |acc, (x, y)| acc | (x ^ y)) == 0
}

fn key_of(id: &str) -> [u8; 32] {
    Sha256::digest(id.as_bytes()).into()
}

/// One logged-in user's session.
#[derive(Debug, Clone)]
pub struct Session {
    /// The user name, lower case as in the users file.
    pub user: String,
    /// The role at login; every request also checks the users file as it is now.
    pub role: Role,
    /// The synchronizer token every state-changing request of this session must carry.
    pub csrf: String,
    /// When the session was created (the login); the absolute lifetime counts from it.
    pub created: Instant,
    /// The last request that used the session ([`Sessions::touch`]); the idle timeout counts
    /// from it.
    pub last_seen: Instant,
}

/// Expiry rules.
#[derive(Debug, Clone, Copy)]
pub struct Timeouts {
    /// A session unused this long ends.
    pub idle: Duration,
    /// A session ends this long after its login, used or not.
    pub absolute: Duration,
}

/// Most sessions held at once; a login beyond it first drops expired ones, then is refused.
pub const MAX_SESSIONS: usize = 10_000;

/// The server's sessions, by SHA-256 of their id.
pub struct Sessions {
    map: Mutex<HashMap<[u8; 32], Session>>,
    /// The idle and absolute expiry every session of this server follows.
    pub timeouts: Timeouts,
}

impl Sessions {
    /// No sessions yet, with these expiry rules.
    pub fn new(timeouts: Timeouts) -> Sessions {
        Sessions {
            map: Mutex::new(HashMap::new()),
            timeouts,
        }
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, HashMap<[u8; 32], Session>> {
        self.map.lock().unwrap_or_else(|p| p.into_inner())
    }

    fn expired(&self, s: &Session, now: Instant) -> bool {
        now.duration_since(s.last_seen) >= self.timeouts.idle
            || now.duration_since(s.created) >= self.timeouts.absolute
    }

    /// A new session for a user with a new random id and CSRF token (never an id the client
    /// offered); returns the id (for the cookie; only its SHA-256 is kept) and the session.
    /// `None` when [`MAX_SESSIONS`] live sessions exist. The caller must end the session the
    /// browser carried before (no fixation) and check the password first.
    pub fn create(&self, user: &str, role: Role) -> Option<(String, Session)> {
        let now = Instant::now();
        let mut map = self.lock();
        if map.len() >= MAX_SESSIONS {
            map.retain(|_, s| !self.expired(s, now));
            if map.len() >= MAX_SESSIONS {
                return None;
            }
        }
        let id = random_token();
        let session = Session {
            user: user.to_string(),
            role,
            csrf: random_token(),
            created: now,
            last_seen: now,
        };
        map.insert(key_of(&id), session.clone());
        Some((id, session))
    }

    /// The session of an id if neither its idle nor its absolute timeout has passed, with its
    /// idle clock restarted; an expired one is removed and `None` returned, as for an unknown id.
    /// It does not look at the users file: the caller must check the user still exists.
    pub fn touch(&self, id: &str) -> Option<Session> {
        let now = Instant::now();
        let key = key_of(id);
        let mut map = self.lock();
        let s = map.get_mut(&key)?;
        if self.expired(s, now) {
            map.remove(&key);
            return None;
        }
        s.last_seen = now;
        Some(s.clone())
    }

    /// Whether an id is a session that has not been removed and is within its absolute
    /// lifetime. The idle timeout is not checked and the idle clock not restarted: a live
    /// stream checks this, so an open live page lives on past the idle timeout but not past the
    /// absolute lifetime, logout or the user's removal.
    pub fn alive(&self, id: &str) -> bool {
        let now = Instant::now();
        self.lock()
            .get(&key_of(id))
            .is_some_and(|s| now.duration_since(s.created) < self.timeouts.absolute)
    }

    /// End a session (logout, or a new login replacing it); an unknown id is ignored.
    pub fn remove(&self, id: &str) {
        self.lock().remove(&key_of(id));
    }

    /// Keep only the sessions whose user `keep` accepts: after a users file reload, every
    /// session of a removed user ends.
    pub fn retain_users(&self, keep: impl Fn(&str) -> bool) {
        self.lock().retain(|_, s| keep(&s.user));
    }

    /// Sessions held, expired ones not yet removed included.
    pub fn len(&self) -> usize {
        self.lock().len()
    }

    /// Whether no session is held.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

/// The login form's CSRF token: an HMAC of the pre-session cookie under the server's key, so
/// the form can only be posted by the browser that fetched it (OWASP CSRF Prevention Cheat
/// Sheet, login CSRF with a pre-session; HMAC based token pattern).
pub struct LoginTokens {
    key: [u8; 32],
}

/// How long a login form stays valid, seconds.
pub const LOGIN_FORM_LIFETIME_S: i64 = 3600;

impl LoginTokens {
    /// A new 256-bit HMAC key from the operating system's generator (the process exits with
    /// code 3 if the generator fails); forms issued by another process do not check.
    pub fn new() -> LoginTokens {
        let mut key = [0u8; 32];
        if rand::rngs::OsRng.try_fill_bytes(&mut key).is_err() {
            eprintln!("errmap serve: the operating system's random generator failed; stopping");
            std::process::exit(3);
        }
        LoginTokens { key }
    }

    fn mac(&self, pre: &str) -> String {
        let mut mac = <Hmac<Sha256> as KeyInit>::new_from_slice(&self.key)
            .expect("HMAC takes a key of any length");
        mac.update(b"errmap-login:");
        mac.update(pre.as_bytes());
        base64::engine::general_purpose::URL_SAFE_NO_PAD.encode(mac.finalize().into_bytes())
    }

    /// A new pre-session value (`<unix seconds>.<random>`) and the form token tied to it.
    pub fn issue(&self, now_s: i64) -> (String, String) {
        let pre = format!("{now_s}.{}", random_token());
        let token = self.mac(&pre);
        (pre, token)
    }

    /// Whether a form token is the HMAC of this pre-session value under this server's key
    /// (compared in constant time) and the value was issued at most [`LOGIN_FORM_LIFETIME_S`]
    /// before `now_s` (and not after it). It does not check the password or the throttle; the
    /// caller must take `pre` from the request's login cookie, not from the form.
    pub fn check(&self, pre: &str, token: &str, now_s: i64) -> bool {
        let Some((issued, _)) = pre.split_once('.') else {
            return false;
        };
        let Ok(issued) = issued.parse::<i64>() else {
            return false;
        };
        if now_s < issued || now_s - issued > LOGIN_FORM_LIFETIME_S {
            return false;
        }
        same_secret(&self.mac(pre), token)
    }
}

impl Default for LoginTokens {
    fn default() -> Self {
        Self::new()
    }
}

/// Cookie names and attributes: `__Host-` names and `Secure` under TLS.
#[derive(Debug, Clone, Copy)]
pub struct CookieStyle {
    /// Serving TLS: cookies get `Secure` and the `__Host-` name prefix.
    pub secure: bool,
}

impl CookieStyle {
    /// The session cookie's name.
    pub fn session_name(self) -> &'static str {
        if self.secure {
            "__Host-errmap_session"
        } else {
            "errmap_session"
        }
    }
    /// The name of the login form's pre-session cookie.
    pub fn login_name(self) -> &'static str {
        if self.secure {
            "__Host-errmap_login"
        } else {
            "errmap_login"
        }
    }
    fn attributes(self) -> &'static str {
        // No Max-Age or Expires: a session cookie goes when the browser closes; no Domain:
        // the cookie goes to this host only.
        if self.secure {
            "Path=/; HttpOnly; SameSite=Strict; Secure"
        } else {
            "Path=/; HttpOnly; SameSite=Strict"
        }
    }
    /// `Set-Cookie` value setting a cookie: `Path=/`, `HttpOnly`, `SameSite=Strict`, `Secure`
    /// under TLS, no `Domain`, no expiry (gone when the browser closes). `value` is not escaped:
    /// pass tokens only.
    pub fn set(self, name: &str, value: &str) -> String {
        format!("{name}={value}; {}", self.attributes())
    }
    /// `Set-Cookie` value deleting a cookie (empty value, `Max-Age=0`, the same attributes).
    pub fn clear(self, name: &str) -> String {
        format!("{name}=; Max-Age=0; {}", self.attributes())
    }
}

/// The value of a cookie in a request's `Cookie` headers (the first of that name); `None` when
/// absent, empty, over 256 bytes or in a header that is not visible ASCII.
pub fn cookie<'a>(headers: &'a axum::http::HeaderMap, name: &str) -> Option<&'a str> {
    headers
        .get_all(axum::http::header::COOKIE)
        .iter()
        .filter_map(|v| v.to_str().ok())
        .flat_map(|v| v.split(';'))
        .filter_map(|pair| pair.trim().split_once('='))
        .find(|(k, _)| *k == name)
        .map(|(_, v)| v)
        .filter(|v| !v.is_empty() && v.len() <= 256)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tokens_are_distinct_and_long() {
        let a = random_token();
        let b = random_token();
        assert_eq!(a.len(), 43);
        assert_ne!(a, b);
        assert!(same_secret(&a, &a.clone()));
        assert!(!same_secret(&a, &b));
        assert!(!same_secret("ab", "abc"));
    }

    #[test]
    fn sessions_expire_when_idle_and_absolutely() {
        let s = Sessions::new(Timeouts {
            idle: Duration::from_millis(0),
            absolute: Duration::from_secs(60),
        });
        let (id, _) = s.create("ada", Role::Viewer).unwrap();
        assert!(s.touch(&id).is_none(), "idle timeout 0 ends it at once");
        let s = Sessions::new(Timeouts {
            idle: Duration::from_secs(60),
            absolute: Duration::from_millis(0),
        });
        let (id, _) = s.create("ada", Role::Viewer).unwrap();
        assert!(s.touch(&id).is_none(), "absolute timeout 0 ends it at once");
        let s = Sessions::new(Timeouts {
            idle: Duration::from_secs(60),
            absolute: Duration::from_secs(60),
        });
        let (id, sess) = s.create("ada", Role::Operator).unwrap();
        assert_eq!(s.touch(&id).unwrap().csrf, sess.csrf);
        assert!(s.touch("not-an-id").is_none());
        s.remove(&id);
        assert!(s.touch(&id).is_none());
    }

    #[test]
    fn login_tokens_belong_to_their_pre_session_and_age() {
        let t = LoginTokens::new();
        let (pre, token) = t.issue(1000);
        assert!(t.check(&pre, &token, 1000));
        assert!(t.check(&pre, &token, 1000 + LOGIN_FORM_LIFETIME_S));
        assert!(!t.check(&pre, &token, 1001 + LOGIN_FORM_LIFETIME_S));
        let (other, _) = t.issue(1000);
        assert!(!t.check(&other, &token, 1000));
        // Another server (another key) does not accept it.
        assert!(!LoginTokens::new().check(&pre, &token, 1000));
        assert!(!t.check("garbage", &token, 1000));
    }

    #[test]
    fn cookies_are_read_by_name() {
        let mut h = axum::http::HeaderMap::new();
        h.append("cookie", "a=1; errmap_session=xyz".parse().unwrap());
        h.append("cookie", "b=2".parse().unwrap());
        assert_eq!(cookie(&h, "errmap_session"), Some("xyz"));
        assert_eq!(cookie(&h, "b"), Some("2"));
        assert_eq!(cookie(&h, "c"), None);
        let style = CookieStyle { secure: true };
        assert_eq!(
            style.set(style.session_name(), "v"),
            "__Host-errmap_session=v; Path=/; HttpOnly; SameSite=Strict; Secure"
        );
    }
}
