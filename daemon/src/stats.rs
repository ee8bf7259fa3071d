//! Per-stream counters and latency histograms.
//!
//! Counters are atomics (the receiver and processing threads bump them, the control thread reads
//! them). Latencies go into log-linear histograms (64 sub-buckets per power of two: any
//! percentile is within 1.6 % of the true value; the maximum is exact), so memory stays fixed
//! however long the daemon runs.

use perturb_wire::control::{LatencySummary, StreamLatency};
use std::sync::Mutex;

const SUB_BITS: u32 = 6;
const SUB: u64 = 1 << SUB_BITS;
const BUCKETS: usize = ((64 - SUB_BITS as usize) + 1) * SUB as usize;

/// A log-linear histogram of nanosecond values.
#[derive(Clone, Debug)]
pub struct Histogram {
    counts: Vec<u64>,
    count: u64,
    sum: u128,
    max: u64,
}

impl Default for Histogram {
    fn default() -> Self {
        Histogram {
            counts: vec![0; BUCKETS],
            count: 0,
            sum: 0,
            max: 0,
        }
    }
}

fn bucket(v: u64) -> usize {
    if v < SUB {
        v as usize
    } else {
        let e = 63 - v.leading_zeros(); // >= SUB_BITS
        let shift = e - SUB_BITS;
        let sub = (v >> shift) & (SUB - 1);
        ((shift as u64 + 1) * SUB + sub) as usize
    }
}

/// The middle of bucket `i`'s value range.
fn bucket_value(i: usize) -> u64 {
    let i = i as u64;
    if i < SUB {
        i
    } else {
        let shift = i / SUB - 1;
        let sub = i % SUB;
        let lo = (SUB + sub) << shift;
        lo + ((1u64 << shift) >> 1)
    }
}

impl Histogram {
    /// Records one value (ns).
    pub fn record(&mut self, ns: u64) {
        self.counts[bucket(ns)] += 1;
        self.count += 1;
        self.sum += ns as u128;
        self.max = self.max.max(ns);
    }

    /// Values recorded.
    pub fn count(&self) -> u64 {
        self.count
    }

    /// The `q` quantile (0..=1) in ns, 0 when empty.
    pub fn quantile(&self, q: f64) -> u64 {
        if self.count == 0 {
            return 0;
        }
        // the bucket of the sample of nearest rank (perturb_core::percentile)
        let rank = perturb_core::percentile::rank(self.count as usize, q) as u64;
        let mut seen = 0;
        for (i, &c) in self.counts.iter().enumerate() {
            seen += c;
            if seen >= rank {
                return bucket_value(i).min(self.max);
            }
        }
        self.max
    }

    /// p50, p99, max and mean in microseconds.
    pub fn summary(&self) -> LatencySummary {
        let us = |ns: u64| ns as f64 / 1000.0;
        LatencySummary {
            count: self.count,
            p50_us: us(self.quantile(0.5)),
            p99_us: us(self.quantile(0.99)),
            max_us: us(self.max),
            mean_us: if self.count == 0 {
                0.0
            } else {
                self.sum as f64 / self.count as f64 / 1000.0
            },
        }
    }
}

/// The four latencies of a stream.
#[derive(Clone, Debug, Default)]
pub struct Latencies {
    /// Perturbation (or copy) into the output sample.
    pub perturb: Histogram,
    /// Ingress publish to daemon receive.
    pub ingress_to_rx: Histogram,
    /// Daemon receive to daemon publish.
    pub rx_to_tx: Histogram,
    /// Ingress publish to daemon publish.
    pub ingress_to_tx: Histogram,
}

impl Latencies {
    /// The summaries.
    pub fn summary(&self) -> StreamLatency {
        StreamLatency {
            perturb: self.perturb.summary(),
            ingress_to_rx: self.ingress_to_rx.summary(),
            rx_to_tx: self.rx_to_tx.summary(),
            ingress_to_tx: self.ingress_to_tx.summary(),
        }
    }
}

use crate::state::CounterCell;
pub use crate::state::Counters;

/// Counters and latencies of one stream.
#[derive(Debug, Default)]
pub struct StreamStats {
    /// The counters (in the daemon: in the memory-mapped counters file, see [`crate::state`]).
    pub counters: CounterCell,
    /// The latency histograms.
    pub latencies: Mutex<Latencies>,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quantiles_are_within_two_percent() {
        let mut h = Histogram::default();
        for v in 1..=100_000u64 {
            h.record(v * 1000);
        }
        let p50 = h.quantile(0.5) as f64;
        let p99 = h.quantile(0.99) as f64;
        assert!((p50 / 50_000_000.0 - 1.0).abs() < 0.02, "{p50}");
        assert!((p99 / 99_000_000.0 - 1.0).abs() < 0.02, "{p99}");
        assert_eq!(h.summary().max_us, 100_000.0);
        assert_eq!(Histogram::default().quantile(0.5), 0);
        let mut one = Histogram::default();
        one.record(7);
        assert_eq!(one.quantile(0.99), 7);
        for v in [0u64, 1, 63, 64, 65, 1 << 20, u64::MAX] {
            assert!(bucket(v) < BUCKETS, "{v}");
        }
    }
}
