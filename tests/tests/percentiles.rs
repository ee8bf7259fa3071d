//! Every latency report computes its percentiles the same way (`perturb_core::percentile`): the
//! core bench (`perturb bench`, the HiL sweep), the bridge's reports (`perturb demo`, the sink
//! table), the daemon's histogram (`perturb ctl stats`, its report; exact up to its bucket width).

use perturb_bridge::stats::summarize as bridge_summary;
use perturb_core::bench::summarize as bench_summary;
use perturb_core::percentile::of_sorted;
use perturbd::stats::Histogram;
use std::time::Duration;

/// Latency-like samples (ns): a body around 2 ms and a tail to 40 ms, from a fixed generator.
fn samples(n: usize, seed: u64) -> Vec<u64> {
    let mut rng = perturb_core::rng::Rng::for_frame(seed, n as u64, 0x5EED);
    (0..n)
        .map(|_| {
            let body = 1_500_000 + rng.below(1_000_000);
            if rng.below(20) == 0 {
                body + rng.below(38_000_000)
            } else {
                body
            }
        })
        .collect()
}

#[test]
fn the_reports_agree_on_the_same_samples() {
    for (n, seed) in [
        (1, 1),
        (2, 2),
        (7, 3),
        (100, 4),
        (101, 5),
        (999, 6),
        (5000, 7),
    ] {
        let ns = samples(n, seed);
        let mut sorted = ns.clone();
        sorted.sort_unstable();
        let want = |q: f64| of_sorted(&sorted, q).unwrap() as f64 / 1e6;

        let bridge = bridge_summary(&ns);
        let mut durations: Vec<Duration> = ns.iter().map(|&v| Duration::from_nanos(v)).collect();
        let bench = bench_summary("X", "x", 1, Duration::ZERO, &mut durations);
        let mut hist = Histogram::default();
        ns.iter().for_each(|&v| hist.record(v));

        for (q, b, c) in [
            (0.5, bridge.p50_ms, bench.median_ms),
            (0.99, bridge.p99_ms, bench.p99_ms),
        ] {
            let w = want(q);
            assert!((b - w).abs() < 1e-9, "bridge q{q} n{n}: {b} vs {w}");
            assert!((c - w).abs() < 1e-9, "bench q{q} n{n}: {c} vs {w}");
            let h = hist.quantile(q) as f64 / 1e6;
            assert!(
                (h - w).abs() <= w * 0.02,
                "daemon histogram q{q} n{n}: {h} vs {w} (beyond its 2% bucket width)"
            );
        }
        assert_eq!(bridge.max_ms, bench.max_ms);
    }
}
