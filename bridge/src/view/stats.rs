//! The live view's statistics: what its readers counted per stream side, the latency of each hop
//! of the frames they received, what the daemon says of the stream (`perturb ctl stats`) and what
//! the egress reported on the events channel; one JSON message per stream and interval on
//! `/<stream>/stats`, whose schema is `stats.schema.json` (advertised with the channel).

use crate::frame::{Hops, StreamKind, monotonic_ns};
use crate::guard::FallbackCounts;
use crate::stats::{HopLatency, HopSummary, Summary, summarize};
use perturb_bag::events::{EventKind, EventRecord};
use perturb_wire::control::{LostByCause, StreamReport};
use serde::Serialize;
use std::collections::BTreeMap;
use std::sync::Mutex;
use std::sync::atomic::{AtomicU64, Ordering};

/// The JSON schema of the statistics messages.
pub const STATS_SCHEMA: &str = include_str!("stats.schema.json");
/// The JSON schema of the status messages (`/perturb/status`).
pub const STATUS_SCHEMA: &str = include_str!("status.schema.json");
/// The version of the statistics and status messages.
pub const VERSION: u32 = 1;

/// What the reader of one stream side counted (shared with the statistics thread).
#[derive(Debug, Default)]
pub struct SideCounters {
    /// Frames taken from shared memory.
    pub received: AtomicU64,
    /// Frames sent to the viewers.
    pub shown: AtomicU64,
    /// Frames not sent, by design: beyond the view's rate, a newer one came in the same read,
    /// or no viewer subscribed.
    pub skipped: AtomicU64,
    /// Frames the view never saw: gaps in the sequence numbers it received (its queue
    /// overflowed while it was encoding, or they were lost before).
    pub missed: AtomicU64,
    /// Frames that could not be converted (invalid, unsupported).
    pub failed: AtomicU64,
    window: Mutex<Window>,
}

/// Samples of the current interval.
#[derive(Debug, Default)]
struct Window {
    hops: HopLatency,
    encode_ns: Vec<u64>,
}

impl SideCounters {
    /// Counts a received frame: its hop times (the view's receive as the sink hop) and the gap
    /// before it given the last sequence number seen.
    pub fn received(&self, hops: &Hops, seq: u64, last: &mut Option<u64>) {
        self.received.fetch_add(1, Ordering::Relaxed);
        if let Some(l) = *last
            && seq > l + 1
        {
            self.missed.fetch_add(seq - l - 1, Ordering::Relaxed);
        }
        *last = Some(seq);
        let mut h = *hops;
        if h.sink == 0 {
            h.sink = monotonic_ns();
        }
        self.lock().hops.add(&h);
    }

    /// Notes how long a frame took to convert and encode.
    pub fn encoded(&self, ns: u64) {
        self.shown.fetch_add(1, Ordering::Relaxed);
        self.lock().encode_ns.push(ns);
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, Window> {
        self.window.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// Ends the interval: its per-hop latency and encoding times, and the counts so far.
    fn take(&self, received_before: &mut u64, interval_s: f64) -> SideStats {
        let w = std::mem::take(&mut *self.lock());
        let received = self.received.load(Ordering::Relaxed);
        let rate_hz = (received - *received_before) as f64 / interval_s.max(1e-3);
        *received_before = received;
        SideStats {
            rate_hz,
            received,
            shown: self.shown.load(Ordering::Relaxed),
            skipped: self.skipped.load(Ordering::Relaxed),
            missed: self.missed.load(Ordering::Relaxed),
            failed: self.failed.load(Ordering::Relaxed),
            latency_ms: w.hops.summary(),
            encode_ms: summarize(&w.encode_ns),
        }
    }
}

/// One side of a stream in a statistics message.
#[derive(Clone, Debug, Serialize)]
pub struct SideStats {
    /// Frames per second received in the interval.
    pub rate_hz: f64,
    /// Frames received since the view started.
    pub received: u64,
    /// Frames sent to the viewers.
    pub shown: u64,
    /// Frames not sent by design (rate, newer frame, no viewer).
    pub skipped: u64,
    /// Frames the view's reader never saw (sequence gaps).
    pub missed: u64,
    /// Frames that could not be converted.
    pub failed: u64,
    /// Latency of the interval's frames per hop: source -> daemon, daemon, daemon -> view
    /// (`to_sink`), source -> view (`total`); on the raw side only `total` has samples.
    pub latency_ms: HopSummary,
    /// Time to convert, shrink and encode a frame sent in the interval.
    pub encode_ms: Summary,
}

/// What the egress of a stream reported on the events channel since the view started.
#[derive(Clone, Debug, Default, Serialize)]
pub struct EgressTally {
    /// Frames published (frame records).
    pub frames: u64,
    /// Of which the perturbed frame went out.
    pub applied: u64,
    /// Raw frames published in place of perturbed ones, by reason.
    pub fallback_raw: FallbackCounts,
    /// Frames lost, by cause (gap records).
    pub lost: LostByCause,
}

impl EgressTally {
    /// Counts an events record of this stream.
    pub fn add(&mut self, r: &EventRecord) {
        match r.kind {
            EventKind::Frame => {
                self.frames += 1;
                if r.applied {
                    self.applied += 1;
                }
                match r.reason.as_deref() {
                    Some("late") => self.fallback_raw.late += 1,
                    Some("daemon_down") => self.fallback_raw.daemon_down += 1,
                    Some("killed") => self.fallback_raw.killed += 1,
                    _ => {}
                }
            }
            EventKind::Gap => {
                let n = r.count.unwrap_or(0);
                let l = &mut self.lost;
                match r.cause.as_deref() {
                    Some("upstream") => l.upstream += n,
                    Some("daemon_down") => l.daemon_down += n,
                    Some("daemon_late") => l.daemon_late += n,
                    Some("daemon_output") => l.daemon_output += n,
                    Some("egress") => l.egress += n,
                    Some("recorder") => l.recorder += n,
                    _ => {}
                }
            }
            _ => {}
        }
    }
}

/// One statistics message (`/<stream>/stats`).
#[derive(Clone, Debug, Serialize)]
pub struct StatsMsg {
    /// [`VERSION`].
    pub version: u32,
    /// The stream.
    pub stream: String,
    /// `image` or `cloud`.
    pub kind: StreamKind,
    /// Wall-clock time of the message, ns since the Unix epoch.
    pub t_wall_ns: u64,
    /// Seconds the interval lasted.
    pub interval_s: f64,
    /// The raw side as the view read it.
    pub raw: SideStats,
    /// The perturbed side as the view read it.
    pub perturbed: SideStats,
    /// What the daemon reports of the stream (`perturb ctl stats`), null while it does not
    /// answer.
    pub daemon: Option<StreamReport>,
    /// What this bridge's egress of the stream reported on the events channel.
    pub egress: EgressTally,
    /// Viewers connected.
    pub clients: usize,
}

/// The statistics of every shown stream, built once per interval.
pub struct StatsBook {
    received_before: BTreeMap<(String, bool), u64>,
    /// Per stream, what its egress reported.
    pub egress: BTreeMap<String, EgressTally>,
    last: std::time::Instant,
}

impl StatsBook {
    /// An empty book.
    pub fn new() -> Self {
        StatsBook {
            received_before: BTreeMap::new(),
            egress: BTreeMap::new(),
            last: std::time::Instant::now(),
        }
    }

    /// Counts an events record.
    pub fn event(&mut self, r: &EventRecord) {
        if let Some(s) = &r.stream {
            self.egress.entry(s.clone()).or_default().add(r);
        }
    }

    /// Ends the interval: one message per stream of `sides` (stream, kind, raw, perturbed),
    /// with the daemon's `reports` when it answered.
    pub fn messages<'a>(
        &mut self,
        sides: impl Iterator<Item = (&'a str, StreamKind, &'a SideCounters, &'a SideCounters)>,
        reports: Option<&[StreamReport]>,
        clients: usize,
    ) -> Vec<StatsMsg> {
        let now = std::time::Instant::now();
        let interval_s = now.duration_since(self.last).as_secs_f64();
        self.last = now;
        let t_wall_ns = crate::frame::wall_ns();
        sides
            .map(|(stream, kind, raw, perturbed)| {
                let mut take = |c: &SideCounters, p: bool| {
                    let before = self
                        .received_before
                        .entry((stream.to_string(), p))
                        .or_default();
                    c.take(before, interval_s)
                };
                let (raw, perturbed) = (take(raw, false), take(perturbed, true));
                StatsMsg {
                    version: VERSION,
                    stream: stream.to_string(),
                    kind,
                    t_wall_ns,
                    interval_s,
                    raw,
                    perturbed,
                    daemon: reports.and_then(|r| r.iter().find(|s| s.name == stream).cloned()),
                    egress: self.egress.get(stream).cloned().unwrap_or_default(),
                    clients,
                }
            })
            .collect()
    }
}

impl Default for StatsBook {
    fn default() -> Self {
        Self::new()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn gaps_hops_and_events_are_counted() {
        let c = SideCounters::default();
        let mut last = None;
        let h = Hops {
            source: 1_000_000,
            daemon_in: 2_000_000,
            daemon_out: 4_000_000,
            sink: 5_000_000,
        };
        for seq in [3, 4, 7, 8] {
            c.received(&h, seq, &mut last);
        }
        c.encoded(2_000_000);
        let mut book = StatsBook::new();
        let gap = EventRecord::gap("cam", "/cam", 9, "egress", 2, 0);
        let late = EventRecord::frame("cam", "/cam", 9, (0, 0), "cam", None, Some("late"), 0);
        for r in [&gap, &late] {
            book.event(r);
        }
        let other = SideCounters::default();
        let msgs = book.messages(
            std::iter::once(("cam", StreamKind::Image, &other, &c)),
            None,
            1,
        );
        let p = &msgs[0].perturbed;
        assert_eq!((p.received, p.missed, p.shown), (4, 2, 1));
        assert_eq!(p.latency_ms.daemon.p50_ms, 2.0);
        assert_eq!(p.latency_ms.to_sink.p99_ms, 1.0);
        assert_eq!(p.latency_ms.total.n, 4);
        assert_eq!(p.encode_ms.p50_ms, 2.0);
        let e = &msgs[0].egress;
        assert_eq!((e.frames, e.fallback_raw.late, e.lost.egress), (1, 1, 2));
        // The next interval starts empty.
        let msgs = book.messages(
            std::iter::once(("cam", StreamKind::Image, &other, &c)),
            None,
            1,
        );
        assert_eq!(msgs[0].perturbed.latency_ms.total.n, 0);
        assert_eq!(msgs[0].perturbed.received, 4);
        let json = serde_json::to_value(&msgs[0]).unwrap();
        assert_eq!(json["kind"], "image");
        assert!(json["daemon"].is_null());
    }
}
