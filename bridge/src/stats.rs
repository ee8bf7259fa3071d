//! Per-adapter counters and latency summaries, logged and written to the end-of-run report.

use serde::Serialize;

/// Latency samples (ns) with percentiles.
#[derive(Clone, Debug, Default)]
pub struct Latency {
    samples: Vec<u64>,
}

/// p50 / p99 / max of a latency series, in milliseconds.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct Summary {
    /// Samples.
    pub n: usize,
    /// Median.
    pub p50_ms: f64,
    /// 99th percentile.
    pub p99_ms: f64,
    /// Maximum.
    pub max_ms: f64,
}

impl Latency {
    /// Adds one sample.
    pub fn add(&mut self, ns: u64) {
        self.samples.push(ns);
    }

    /// The samples.
    pub fn samples(&self) -> &[u64] {
        &self.samples
    }

    /// The summary (percentiles by [`perturb_core::percentile`]).
    pub fn summary(&self) -> Summary {
        summarize(&self.samples)
    }
}

/// Percentiles of `ns` samples in ms, by the project's one definition ([`perturb_core::percentile`]).
pub fn summarize(ns: &[u64]) -> Summary {
    if ns.is_empty() {
        return Summary::default();
    }
    let mut v = ns.to_vec();
    v.sort_unstable();
    let pct = |p: f64| perturb_core::percentile::of_sorted(&v, p / 100.0).unwrap_or(0) as f64 / 1e6;
    Summary {
        n: v.len(),
        p50_ms: pct(50.0),
        p99_ms: pct(99.0),
        max_ms: *v.last().unwrap_or(&0) as f64 / 1e6,
    }
}

/// Latency per hop of the frames a sink received: source -> daemon (iceoryx2 into the daemon),
/// daemon (perturbation and its output), daemon -> sink (iceoryx2 out), and the total.
#[derive(Clone, Debug, Default)]
pub struct HopLatency {
    to_daemon: Latency,
    daemon: Latency,
    to_sink: Latency,
    total: Latency,
}

/// [`HopLatency`] summarised.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct HopSummary {
    /// Source hop to daemon receive.
    pub to_daemon: Summary,
    /// Daemon receive to daemon send (the perturbation).
    pub daemon: Summary,
    /// Daemon send to sink receive.
    pub to_sink: Summary,
    /// Source hop to sink receive.
    pub total: Summary,
}

impl HopLatency {
    /// Adds a frame's hop timestamps (those that are 0 were not stamped and are skipped).
    pub fn add(&mut self, h: &crate::frame::Hops) {
        if h.source != 0 && h.sink >= h.source {
            self.total.add(h.sink - h.source);
        }
        if h.source != 0 && h.daemon_in >= h.source && h.daemon_in != 0 {
            self.to_daemon.add(h.daemon_in - h.source);
        }
        if h.daemon_in != 0 && h.daemon_out >= h.daemon_in {
            self.daemon.add(h.daemon_out - h.daemon_in);
        }
        if h.daemon_out != 0 && h.sink >= h.daemon_out {
            self.to_sink.add(h.sink - h.daemon_out);
        }
    }

    /// Merges another series into this one.
    pub fn merge(&mut self, o: &HopLatency) {
        for (a, b) in [
            (&mut self.to_daemon, &o.to_daemon),
            (&mut self.daemon, &o.daemon),
            (&mut self.to_sink, &o.to_sink),
            (&mut self.total, &o.total),
        ] {
            a.samples.extend_from_slice(&b.samples);
        }
    }

    /// The summary.
    pub fn summary(&self) -> HopSummary {
        HopSummary {
            to_daemon: self.to_daemon.summary(),
            daemon: self.daemon.summary(),
            to_sink: self.to_sink.summary(),
            total: self.total.summary(),
        }
    }
}

/// What one adapter did.
#[derive(Clone, Debug, Default, Serialize)]
pub struct AdapterReport {
    /// `ingress /topic -> stream`, ...
    pub name: String,
    /// Frames taken in.
    pub received: u64,
    /// Frames passed on.
    pub forwarded: u64,
    /// Messages refused (malformed, unsupported), each logged.
    pub bad: u64,
    /// Messages of types the adapter does not carry (skipped).
    pub skipped: u64,
    /// Frames lost (e.g. a DDS write that failed).
    pub failed: u64,
    /// Sources: frames published while no reader was connected (no `perturbd` on the stream, or
    /// it was restarting); the daemon counts them as `dropped_upstream` once it is back.
    #[serde(default)]
    pub undelivered: u64,
    /// Frames lost before the adapter: gaps in a ROS 1 publisher's header `seq` (ingress), not
    /// counting the frames the bridge itself dropped (`dropped`).
    pub lost: u64,
    /// Frames dropped because a queue of the bridge was full: ROS 1 subscribers slower than the
    /// stream (egress, summed over subscribers: the oldest queued message is dropped, as roscpp
    /// does) or the ROS 1 ingress's own queue when the bus side fell behind.
    #[serde(default)]
    pub dropped: u64,
    /// Frames lost, by cause (the causes `perturb ctl stats` and the events use): for an egress
    /// what the ADS did not receive, for the recorder what the bag lacks.
    #[serde(default)]
    pub lost_by_cause: perturb_wire::control::LostByCause,
    /// Egress: raw frames published in place of perturbed ones, by reason (the ADS received
    /// them: they are not lost).
    #[serde(default)]
    pub fallback_raw: crate::guard::FallbackCounts,
    /// Egress: perturbed frames that came after their raw frame had gone out (discarded).
    #[serde(default)]
    pub late_discarded: u64,
    /// Damage found (bags).
    pub damage: Vec<String>,
    /// Notes.
    pub notes: Vec<String>,
    /// Latency from the source hop to this adapter (sinks), or of the adapter's own work.
    pub latency: Option<Summary>,
    /// Per-hop latency of the frames a sink received, per `<stream>/<side>`.
    pub hops: std::collections::BTreeMap<String, HopSummary>,
}

/// Logs a bad message, at most `limit` times in full per adapter, then every 100th.
pub fn log_bad(name: &str, count: u64, what: &dyn std::fmt::Display) {
    if count <= 10 || count.is_multiple_of(100) {
        tracing::warn!("{name}: {what} (bad message #{count}; carrying on)");
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nearest_rank_percentiles() {
        let v: Vec<u64> = (1..=100).map(|i| i * 1_000_000).collect();
        let s = summarize(&v);
        assert_eq!((s.p50_ms, s.p99_ms, s.max_ms), (50.0, 99.0, 100.0));
        assert_eq!(summarize(&[]).n, 0);
    }
}
