//! Failed-login throttling: after 5 failures within 15 minutes, a user name or a client address gets 429 with Retry-After until its oldest failure leaves the window.
//!
//! Counted per submitted user name (existing or not, so the answer reveals nothing) and per
//! client address, in memory, with a bound on how many names and addresses are remembered.

use std::collections::{HashMap, VecDeque};
use std::net::IpAddr;
use std::sync::Mutex;
use std::time::{Duration, Instant};

/// Failures allowed in the window.
pub const MAX_FAILURES: usize = 5;
/// The window.
pub const WINDOW: Duration = Duration::from_secs(15 * 60);
/// Most names (and, apart, addresses) remembered; past it the ones without recent failures go.
const MAX_KEYS: usize = 100_000;

struct Counts<K> {
    map: HashMap<K, VecDeque<Instant>>,
}

impl<K> Default for Counts<K> {
    fn default() -> Self {
        Counts {
            map: HashMap::new(),
        }
    }
}

impl<K: std::hash::Hash + Eq + Clone> Counts<K> {
    fn prune(q: &mut VecDeque<Instant>, now: Instant) {
        while q.front().is_some_and(|t| now.duration_since(*t) >= WINDOW) {
            q.pop_front();
        }
    }

    /// Seconds until a blocked key may try again, or `None` when it may now.
    fn blocked_for(&mut self, key: &K, now: Instant) -> Option<u64> {
        let q = self.map.get_mut(key)?;
        Self::prune(q, now);
        if q.len() < MAX_FAILURES {
            return None;
        }
        let oldest = q[q.len() - MAX_FAILURES];
        let left = WINDOW.saturating_sub(now.duration_since(oldest));
        Some(left.as_secs() + u64::from(left.subsec_nanos() > 0))
    }

    fn fail(&mut self, key: K, now: Instant) -> usize {
        if self.map.len() >= MAX_KEYS && !self.map.contains_key(&key) {
            self.map.retain(|_, q| {
                Self::prune(q, now);
                !q.is_empty()
            });
        }
        let q = self.map.entry(key).or_default();
        Self::prune(q, now);
        q.push_back(now);
        // Only the last MAX_FAILURES matter.
        while q.len() > MAX_FAILURES {
            q.pop_front();
        }
        q.len()
    }

    fn clear(&mut self, key: &K) {
        self.map.remove(key);
    }
}

/// The failure counts.
#[derive(Default)]
pub struct Throttle {
    inner: Mutex<(Counts<String>, Counts<IpAddr>)>,
}

/// Why a login may not be tried now.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Blocked {
    /// The user name has [`MAX_FAILURES`] failures in the [`WINDOW`].
    User {
        /// Seconds (rounded up) until the oldest of them leaves the window.
        retry_after_s: u64,
    },
    /// The client address has [`MAX_FAILURES`] failures in the [`WINDOW`].
    Address {
        /// Seconds (rounded up) until the oldest of them leaves the window.
        retry_after_s: u64,
    },
}

impl Blocked {
    /// Seconds to wait, for the `Retry-After` header.
    pub fn retry_after_s(self) -> u64 {
        match self {
            Blocked::User { retry_after_s } | Blocked::Address { retry_after_s } => retry_after_s,
        }
    }
}

impl Throttle {
    fn lock(&self) -> std::sync::MutexGuard<'_, (Counts<String>, Counts<IpAddr>)> {
        self.inner.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// Whether a login of `user` from `addr` must wait (the longer wait when both are blocked);
    /// `None`: it may be tried. Call it before checking the password, and refuse a blocked
    /// attempt even when its password would be right; `user` must be the same key later given to
    /// [`Throttle::fail`] (the login uses the normalised name, or the typed one cut and lower-cased).
    pub fn check(&self, user: &str, addr: IpAddr) -> Option<Blocked> {
        self.check_at(user, addr, Instant::now())
    }

    fn check_at(&self, user: &str, addr: IpAddr, now: Instant) -> Option<Blocked> {
        let mut g = self.lock();
        let u = g.0.blocked_for(&user.to_string(), now);
        let a = g.1.blocked_for(&addr, now);
        match (u, a) {
            (Some(u), Some(a)) if a > u => Some(Blocked::Address { retry_after_s: a }),
            (Some(u), _) => Some(Blocked::User { retry_after_s: u }),
            (None, Some(a)) => Some(Blocked::Address { retry_after_s: a }),
            (None, None) => None,
        }
    }

    /// Count a failed login; returns the failures now in the window for the user and for the
    /// address (each at most [`MAX_FAILURES`]: older ones no longer matter).
    pub fn fail(&self, user: &str, addr: IpAddr) -> (usize, usize) {
        self.fail_at(user, addr, Instant::now())
    }

    fn fail_at(&self, user: &str, addr: IpAddr, now: Instant) -> (usize, usize) {
        let mut g = self.lock();
        (g.0.fail(user.to_string(), now), g.1.fail(addr, now))
    }

    /// A successful login forgets the user's failures (not the address's: one good account
    /// must not reset an address that guesses at others).
    pub fn succeed(&self, user: &str) {
        self.lock().0.clear(&user.to_string());
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn five_failures_block_for_the_rest_of_the_window() {
        let t = Throttle::default();
        let a: IpAddr = "10.0.0.1".parse().unwrap();
        let b: IpAddr = "10.0.0.2".parse().unwrap();
        let t0 = Instant::now();
        for i in 0..4 {
            t.fail_at("ada", a, t0 + Duration::from_secs(i));
            assert_eq!(t.check_at("ada", a, t0 + Duration::from_secs(i)), None);
        }
        t.fail_at("ada", a, t0 + Duration::from_secs(10));
        // Blocked until the first failure (t0) is 15 min old: 900 − 10 s from t0 + 10 s.
        assert_eq!(
            t.check_at("ada", b, t0 + Duration::from_secs(10)),
            Some(Blocked::User { retry_after_s: 890 })
        );
        assert_eq!(
            t.check_at("bob", a, t0 + Duration::from_secs(10)),
            Some(Blocked::Address { retry_after_s: 890 })
        );
        assert_eq!(t.check_at("bob", b, t0 + Duration::from_secs(10)), None);
        // The first failure leaves the window at t0 + 900 s.
        // (Checks go forward in time, as the clock does: a check forgets expired failures.)
        assert!(t
            .check_at("ada", b, t0 + Duration::from_secs(899))
            .is_some());
        assert_eq!(t.check_at("ada", b, t0 + Duration::from_secs(900)), None);
        t.fail_at("ada", a, t0 + Duration::from_secs(900));
        assert!(t
            .check_at("ada", b, t0 + Duration::from_secs(900))
            .is_some());
        t.succeed("ada");
        assert_eq!(t.check_at("ada", b, t0 + Duration::from_secs(900)), None);
        assert!(t
            .check_at("bob", a, t0 + Duration::from_secs(900))
            .is_some());
    }
}
