//! The perturbation log on the vehicle's bus: the bridge publishes `/perturb/events` (name
//! configurable) as `std_msgs/String` holding one JSON [`EventRecord`] per frame an egress
//! published (which perturbation the ADS got, or why it got the raw frame), per gap (frames lost,
//! with their cause) and per kill/arm, so a run recorded the usual way (`rosbag record`, `ros2 bag
//! record` of the ADS's topics plus this one) says which perturbation was active when, and
//! `perturb analyze` reads it from that single bag.
//!
//! `mode = "frames"` (the default) writes every frame record; `mode = "changes"` writes a frame
//! record only when what a stream delivers changes (perturbation, severity, seed, applied or not,
//! the fallback reason, the campaign step) and otherwise a heartbeat per stream once a second;
//! gap, kill and arm records always go out. The adapters hand records over without waiting (a
//! full queue drops the record and counts it); the events writer runs on a thread of its own.

use crate::adapter::{Adapter, Control, POLL};
use crate::bus::Bus;
use crate::dds::Qos;
use crate::msgs::{STRING, SmallEndpoint, encode_string};
use crate::stats::{AdapterReport, log_bad};
use anyhow::Result;
use crossbeam::channel::{Receiver, Sender, bounded};
use perturb_bag::events::{EventKind, EventRecord};
use std::collections::BTreeMap;
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::{Duration, Instant};

/// Which records go out.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum EventsMode {
    /// One record per frame published.
    #[default]
    Frames,
    /// One record per change of a stream's state, plus a heartbeat per stream once a second.
    Changes,
}

/// Where the adapters hand their records over.
#[derive(Debug)]
pub struct EventsHub {
    tx: Sender<EventRecord>,
    dropped: AtomicU64,
    /// The live view's copy of every record ([`EventsHub::tap`]), when the view runs.
    view: std::sync::OnceLock<Sender<EventRecord>>,
}

/// Records the hub holds before it drops new ones.
const QUEUE: usize = 4096;

impl EventsHub {
    /// A hub and the receiving end for the events adapter.
    pub fn new() -> (Arc<EventsHub>, Receiver<EventRecord>) {
        let (tx, rx) = bounded(QUEUE);
        (
            Arc::new(EventsHub {
                tx,
                dropped: AtomicU64::new(0),
                view: std::sync::OnceLock::new(),
            }),
            rx,
        )
    }

    /// A second receiver of every record, for the live view (its own queue: a full one drops
    /// the view's copy only). The first call makes it; later calls get `None`.
    pub fn tap(&self) -> Option<Receiver<EventRecord>> {
        let (tx, rx) = bounded(QUEUE);
        self.view.set(tx).ok().map(|()| rx)
    }

    /// Hands a record over without waiting (a full queue drops it, counted).
    pub fn send(&self, r: EventRecord) {
        if let Some(v) = self.view.get() {
            let _ = v.try_send(r.clone());
        }
        if self.tx.try_send(r).is_err() {
            self.dropped.fetch_add(1, Ordering::Relaxed);
        }
    }

    /// Records dropped because the queue was full.
    pub fn dropped(&self) -> u64 {
        self.dropped.load(Ordering::Relaxed)
    }
}

/// The state a `changes`-mode record compares.
type StreamState = (
    Option<String>,
    Option<u8>,
    Option<u64>,
    bool,
    Option<String>,
    Option<u16>,
);

fn state_of(r: &EventRecord) -> StreamState {
    (
        r.id.clone(),
        r.severity,
        r.seed,
        r.applied,
        r.reason.clone(),
        r.step,
    )
}

/// The `changes` filter: what to write of each record.
#[derive(Default)]
struct Changes {
    last: BTreeMap<String, (StreamState, Instant, EventRecord)>,
}

impl Changes {
    /// The records to write for `r` (none, the record itself).
    fn admit(&mut self, r: EventRecord, now: Instant) -> Option<EventRecord> {
        if r.kind != EventKind::Frame {
            return Some(r);
        }
        let key = r.stream.clone().unwrap_or_else(|| r.topic.clone());
        let st = state_of(&r);
        match self.last.get_mut(&key) {
            Some((s, _, last)) if *s == st => {
                *last = r;
                None
            }
            _ => {
                self.last.insert(key, (st, now, r.clone()));
                Some(r)
            }
        }
    }

    /// Heartbeats of the streams whose last write is a second old.
    fn heartbeats(&mut self, now: Instant) -> Vec<EventRecord> {
        let mut out = Vec::new();
        for (_, at, last) in self.last.values_mut() {
            if now.duration_since(*at) >= Duration::from_secs(1) {
                *at = now;
                let mut h = last.clone();
                h.kind = EventKind::Heartbeat;
                h.t_wall_ns = crate::frame::wall_ns();
                out.push(h);
            }
        }
        out
    }
}

/// The events writer.
pub struct Events {
    /// The topic (`/perturb/events`).
    pub topic: String,
    /// Which records go out.
    pub mode: EventsMode,
    /// Where.
    pub endpoint: SmallEndpoint,
    /// The records.
    pub rx: Receiver<EventRecord>,
    /// The hub (for its drop count).
    pub hub: Arc<EventsHub>,
}

impl Adapter for Events {
    fn name(&self) -> String {
        let t = self.endpoint.prefix();
        format!("events -> {t}{}", self.topic)
    }

    fn is_sink(&self) -> bool {
        true
    }

    fn run(self: Box<Self>, _bus: &dyn Bus, mut ctl: Control) -> Result<AdapterReport> {
        let name = self.name();
        // Reliable with a deep history: a recorder that falls behind a little loses no record.
        let qos = Qos {
            reliability: crate::dds::Reliability::Reliable,
            durability: crate::dds::Durability::Volatile,
            depth: 100,
        };
        let mut writer = self.endpoint.writer(&self.topic, STRING, qos)?;
        ctl.ready();
        let mut rep = AdapterReport {
            name: name.clone(),
            ..Default::default()
        };
        let mut changes = Changes::default();
        let mut write = |r: &EventRecord, rep: &mut AdapterReport| {
            let json = serde_json::to_string(r).unwrap_or_else(|_| "{}".into());
            match writer.write(&encode_string(writer.wire(), &json)) {
                Ok(()) => rep.forwarded += 1,
                Err(e) => {
                    rep.failed += 1;
                    log_bad(&name, rep.failed, &e);
                }
            }
        };
        // After the stop, the records already queued still go out.
        let mut draining = false;
        loop {
            let got = self.rx.recv_timeout(if draining {
                Duration::from_millis(1)
            } else {
                POLL
            });
            let now = Instant::now();
            match got {
                Ok(r) => {
                    rep.received += 1;
                    let keep = match self.mode {
                        EventsMode::Frames => Some(r),
                        EventsMode::Changes => changes.admit(r, now),
                    };
                    if let Some(r) = keep {
                        write(&r, &mut rep);
                    }
                }
                Err(_) if draining => break,
                Err(_) => {}
            }
            if self.mode == EventsMode::Changes {
                for h in changes.heartbeats(now) {
                    write(&h, &mut rep);
                }
            }
            if ctl.stopped() {
                draining = true;
            }
        }
        let dropped = self.hub.dropped();
        if dropped > 0 {
            rep.dropped = dropped;
            rep.notes.push(format!(
                "{dropped} record(s) dropped: the events queue ({QUEUE}) was full"
            ));
        }
        Ok(rep)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn frame(seq: u64, id: Option<&str>, reason: Option<&str>) -> EventRecord {
        EventRecord::frame(
            "cam",
            "/cam",
            seq,
            (0, 0),
            "cam",
            id.map(|i| (i, 2, 1)),
            reason,
            0,
        )
    }

    #[test]
    fn changes_mode_writes_changes_gaps_and_heartbeats() {
        let mut c = Changes::default();
        let t = Instant::now();
        assert!(c.admit(frame(0, Some("C-A1"), None), t).is_some());
        assert!(c.admit(frame(1, Some("C-A1"), None), t).is_none());
        assert!(c.admit(frame(2, None, Some("late")), t).is_some());
        assert!(
            c.admit(EventRecord::gap("cam", "/cam", 3, "egress", 2, 0), t)
                .is_some()
        );
        assert!(c.heartbeats(t + Duration::from_millis(500)).is_empty());
        let hb = c.heartbeats(t + Duration::from_secs(1));
        assert_eq!(hb.len(), 1);
        assert_eq!((hb[0].kind, hb[0].seq), (EventKind::Heartbeat, 2));
    }
}
