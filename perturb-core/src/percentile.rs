//! The one percentile definition of the project: every latency report (`perturb demo`, `perturb
//! bench`, `perturb ctl stats`, the bridge's and the daemon's reports, the end-to-end bench and the
//! HiL sweep) computes its p50 and p99 here, so their figures are comparable.
//!
//! **Nearest rank**: the `q` quantile of `n` samples is the sample of 1-based rank
//! `ceil(q * n)` (at least 1) in ascending order. It is always a value that was observed, the
//! maximum for `q = 1`, and what a histogram can report exactly up to its bucket width (the
//! daemon's histogram uses [`rank`] to pick its bucket). The study's bootstrap confidence
//! intervals are a statistical estimator, not a latency report, and keep numpy's linear
//! interpolation so they match scipy.
//!
//! ```
//! use perturb_core::percentile::{of_sorted, rank};
//! let ms = [1.0, 2.0, 3.0, 4.0, 100.0];
//! assert_eq!(rank(5, 0.5), 3);
//! assert_eq!(of_sorted(&ms, 0.5), Some(3.0));
//! assert_eq!(of_sorted(&ms, 0.99), Some(100.0));
//! assert_eq!(of_sorted::<f64>(&[], 0.5), None);
//! ```

/// The 1-based nearest rank of the `q` quantile (`0..=1`) among `n` samples: `ceil(q * n)`
/// clamped to `1..=n` (0 when `n` is 0).
pub fn rank(n: usize, q: f64) -> usize {
    if n == 0 {
        return 0;
    }
    // q * n is computed in floating point: 0.29 * 100 is 28.999999999999996, whose ceiling
    // would be 29 only by luck; a tolerance far below one rank absorbs that.
    let r = (q.clamp(0.0, 1.0) * n as f64 - 1e-9).ceil();
    (r.max(1.0) as usize).min(n)
}

/// The `q` quantile (`0..=1`) of `sorted` (ascending) by nearest rank; `None` when empty.
pub fn of_sorted<T: Copy>(sorted: &[T], q: f64) -> Option<T> {
    sorted.get(rank(sorted.len(), q).checked_sub(1)?).copied()
}

/// Sorts `v` (floats by total order) and returns its `q` quantile by nearest rank, `NaN` when
/// empty.
pub fn of_f64(v: &mut [f64], q: f64) -> f64 {
    v.sort_by(f64::total_cmp);
    of_sorted(v, q).unwrap_or(f64::NAN)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ranks_of_small_and_round_counts() {
        assert_eq!(rank(0, 0.5), 0);
        assert_eq!(rank(1, 0.0), 1);
        assert_eq!(rank(1, 0.99), 1);
        assert_eq!(rank(2, 0.5), 1);
        assert_eq!(rank(3, 0.5), 2);
        assert_eq!(rank(100, 0.99), 99);
        assert_eq!(rank(100, 0.29), 29);
        assert_eq!(rank(101, 0.99), 100);
        assert_eq!(rank(1000, 0.999), 999);
        assert_eq!(rank(10, 1.0), 10);
    }

    #[test]
    fn rank_is_the_smallest_covering_share_for_every_count() {
        for n in 1..400usize {
            for q in [0.01, 0.1, 0.25, 0.5, 0.75, 0.9, 0.95, 0.99, 0.999, 1.0] {
                let r = rank(n, q);
                // at least q of the samples are at or below rank r, and not so for r - 1
                assert!(r as f64 >= q * n as f64 - 1e-6, "n {n} q {q} r {r}");
                assert!(
                    ((r - 1) as f64) < q * n as f64 - 1e-6 || r == 1,
                    "n {n} q {q} r {r}"
                );
            }
        }
    }

    #[test]
    fn of_f64_sorts_and_picks() {
        let mut v = vec![5.0, 1.0, 4.0, 2.0, 3.0];
        assert_eq!(of_f64(&mut v, 0.5), 3.0);
        assert_eq!(of_f64(&mut v, 0.2), 1.0);
        assert_eq!(of_f64(&mut v, 0.21), 2.0);
        assert!(of_f64(&mut [], 0.5).is_nan());
    }
}
