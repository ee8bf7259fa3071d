//! The kill switch: one latch for the whole daemon. Engaged (`perturb ctl off --all`, the
//! bridge's kill topic, a dead-man timeout), every stream passes its raw frames from the next
//! frame on, whatever it is configured to run; it stays engaged, across restarts of the daemon
//! too (the runtime state keeps it), until someone arms it again (`perturb ctl arm`). Arming
//! does not choose perturbations: each stream goes back to what it was set to run (by the
//! configuration, `perturb ctl set` or a campaign), which a person can change first while the
//! latch holds.
//!
//! The processing threads read the latch once per frame (one atomic load).

pub use perturb_wire::control::KillRecord;
use std::sync::Mutex;
use std::sync::atomic::{AtomicBool, Ordering};

/// The daemon-wide kill latch.
#[derive(Debug, Default)]
pub struct KillSwitch {
    engaged: AtomicBool,
    record: Mutex<Option<KillRecord>>,
}

impl KillSwitch {
    /// A latch that starts engaged when `restored` says the last run left it so.
    pub fn restored(restored: Option<KillRecord>) -> Self {
        KillSwitch {
            engaged: AtomicBool::new(restored.is_some()),
            record: Mutex::new(restored),
        }
    }

    /// True while engaged (read per frame by the processing threads).
    pub fn engaged(&self) -> bool {
        self.engaged.load(Ordering::Acquire)
    }

    /// Engages the latch; returns false if it already was (the first reason is kept).
    pub fn engage(&self, reason: &str) -> bool {
        let mut r = self.record.lock().unwrap_or_else(|p| p.into_inner());
        if r.is_some() {
            return false;
        }
        *r = Some(KillRecord {
            reason: reason.to_string(),
            since_unix_s: unix_now(),
        });
        self.engaged.store(true, Ordering::Release);
        true
    }

    /// Releases the latch; returns what had engaged it (None if it was not engaged).
    pub fn arm(&self) -> Option<KillRecord> {
        let mut r = self.record.lock().unwrap_or_else(|p| p.into_inner());
        self.engaged.store(false, Ordering::Release);
        r.take()
    }

    /// Why it is engaged, if it is.
    pub fn record(&self) -> Option<KillRecord> {
        self.record
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .clone()
    }
}

/// Seconds since the Unix epoch.
pub fn unix_now() -> f64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| d.as_secs_f64())
        .unwrap_or(0.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_latch_keeps_its_first_reason_until_armed() {
        let k = KillSwitch::default();
        assert!(!k.engaged());
        assert!(k.engage("takeover"));
        assert!(!k.engage("button"), "already engaged");
        assert!(k.engaged());
        assert_eq!(k.record().unwrap().reason, "takeover");
        assert_eq!(k.arm().unwrap().reason, "takeover");
        assert!(!k.engaged());
        assert!(k.arm().is_none());
        let r = KillSwitch::restored(Some(KillRecord {
            reason: "before the restart".into(),
            since_unix_s: 1.0,
        }));
        assert!(r.engaged(), "a restarted daemon keeps the latch");
    }
}
