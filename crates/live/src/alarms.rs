//! Alarms of the live loop: raised once per episode of a cause (a silent source, an implausible
//! sensor, a bound, a failed write), listed until they are both acknowledged by an operator and
//! no longer active.

use super::state::AlarmState;

#[derive(Debug, Clone)]
struct Alarm {
    id: u64,
    key: String,
    raised_utc: String,
    source: String,
    message: String,
    acknowledged: bool,
    active: bool,
}

/// At most this many alarms are listed; the oldest finished ones go first.
const MAX_LISTED: usize = 100;

/// The alarms of one run: the listed alarms (at most 100), the next id to give and how many
/// were raised in all.
#[derive(Debug, Clone)]
pub struct Alarms {
    list: Vec<Alarm>,
    next_id: u64,
    raised: u64,
}

impl Default for Alarms {
    fn default() -> Self {
        Alarms {
            list: Vec::new(),
            next_id: 1,
            raised: 0,
        }
    }
}

impl Alarms {
    /// Raise an alarm for `key` unless one is active for it; the new alarm's id.
    pub fn raise(&mut self, key: &str, source: &str, message: String, utc: &str) -> Option<u64> {
        if self.list.iter().any(|a| a.active && a.key == key) {
            return None;
        }
        let id = self.next_id;
        self.next_id += 1;
        self.raised += 1;
        self.list.push(Alarm {
            id,
            key: key.to_string(),
            raised_utc: utc.to_string(),
            source: source.to_string(),
            message,
            acknowledged: false,
            active: true,
        });
        if self.list.len() > MAX_LISTED {
            if let Some(i) = self.list.iter().position(|a| !a.active || a.acknowledged) {
                self.list.remove(i);
            } else {
                self.list.remove(0);
            }
        }
        Some(id)
    }

    /// The cause of `key` is gone.
    pub fn clear(&mut self, key: &str) {
        for a in self.list.iter_mut().filter(|a| a.key == key) {
            a.active = false;
        }
        self.list.retain(|a| a.active || !a.acknowledged);
    }

    /// Acknowledge an alarm; its key, or None for an unknown id.
    pub fn acknowledge(&mut self, id: u64) -> Option<String> {
        let a = self.list.iter_mut().find(|a| a.id == id)?;
        a.acknowledged = true;
        let key = a.key.clone();
        self.list.retain(|a| a.active || !a.acknowledged);
        Some(key)
    }

    /// Whether every listed alarm is acknowledged (true with none listed): after a ramp to zero the
    /// loop stays at zero until this holds and the cause is gone.
    pub fn all_acknowledged(&self) -> bool {
        self.list.iter().all(|a| a.acknowledged)
    }

    /// How many were raised in this run.
    pub fn raised(&self) -> u64 {
        self.raised
    }

    /// The listed alarms as the state file shows them, oldest first.
    pub fn states(&self) -> Vec<AlarmState> {
        self.list
            .iter()
            .map(|a| AlarmState {
                id: a.id,
                raised_utc: a.raised_utc.clone(),
                source: a.source.clone(),
                message: a.message.clone(),
                acknowledged: a.acknowledged,
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn one_alarm_per_episode_listed_until_acknowledged_and_cleared() {
        let mut a = Alarms::default();
        assert_eq!(a.raise("s", "rack", "silent".into(), "t"), Some(1));
        assert_eq!(a.raise("s", "rack", "silent".into(), "t"), None);
        a.clear("s");
        assert_eq!(a.states().len(), 1, "listed until acknowledged");
        assert!(!a.all_acknowledged());
        assert_eq!(a.acknowledge(1).as_deref(), Some("s"));
        assert!(a.states().is_empty());
        assert_eq!(a.acknowledge(7), None);
        assert_eq!(a.raise("s", "rack", "silent again".into(), "t"), Some(2));
        assert_eq!(a.raised(), 2);
    }
}
