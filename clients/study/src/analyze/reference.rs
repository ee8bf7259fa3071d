//! The paper's reference region (RQ3): the cross-track error is the lateral distance between the
//! driven trajectory and a region built from N nominal drives of the route, not the distance to
//! one line.
//!
//! Construction: the nominal drives are projected on the route (tracked, as every run is); at
//! every `bin` metres of arc length each drive's signed lateral offset is interpolated where the
//! drive passes that arc length, and the region there is the band from the smallest to the
//! largest of those offsets (the band the nominal trajectories span). Between grid points the
//! band's edges are linear; an arc length not every nominal drive passed (before the latest
//! start, after the earliest end) takes the band of the nearest one they all passed. The CTE of a pose is 0 inside the band and its signed distance to the nearer
//! edge outside (positive to the left of the direction of travel).
//!
//! Without a route the nominal drives give one: their centre line (the mean offset of the drives,
//! per arc length, around the longest drive), so the paper's setup (three nominal drives, no
//! drawn route) needs nothing else.

use super::load::PoseSample;
use crate::route::{Projection, Route};
use serde::Serialize;

/// A band around a route, per arc length.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct ReferenceRegion {
    /// Grid spacing, metres: grid point k lies at arc length `k * bin_m`.
    pub bin_m: f64,
    /// Lower (right) edge of the band at each grid point, metres (signed, left positive).
    pub lo: Vec<f64>,
    /// Upper (left) edge.
    pub hi: Vec<f64>,
    /// How many nominal drives passed each grid point.
    pub drives: Vec<usize>,
    /// Names of the nominal drives it was built from.
    pub runs: Vec<String>,
}

/// Where each pose projects on the route, tracked along it so that a route passing near itself
/// is followed in order (the first pose takes the globally nearest point).
pub fn tracked_projections(route: &Route, poses: &[[f64; 2]]) -> Vec<Projection> {
    let mut out: Vec<Projection> = Vec::with_capacity(poses.len());
    for p in poses {
        let pr = match out.last() {
            None => route.project(*p),
            Some(prev) => route.project_near(*p, prev.s),
        };
        out.push(pr);
    }
    out
}

/// The offsets at the grid points a drive passes: for every pair of consecutive samples, every
/// grid arc length between theirs gets the linearly interpolated offset.
fn crossings(proj: &[Projection], bin: f64, n: usize, mut f: impl FnMut(usize, f64)) {
    for w in proj.windows(2) {
        let (a, b) = (w[0], w[1]);
        let (s0, s1) = if a.s <= b.s { (a.s, b.s) } else { (b.s, a.s) };
        let first = (s0 / bin).ceil().max(0.0) as usize;
        let mut k = first;
        while k < n && (k as f64) * bin <= s1 {
            let s = k as f64 * bin;
            let o = if (b.s - a.s).abs() < 1e-12 {
                a.offset
            } else {
                a.offset + (s - a.s) / (b.s - a.s) * (b.offset - a.offset)
            };
            f(k, o);
            k += 1;
        }
    }
    if let [only] = proj {
        let k = (only.s / bin).round() as usize;
        if k < n {
            f(k, only.offset);
        }
    }
}

impl ReferenceRegion {
    /// The band the `drives` (name, poses) span around `route`, every `bin_m` metres. None when
    /// no drive has a pose.
    pub fn build(route: &Route, drives: &[(String, Vec<[f64; 2]>)], bin_m: f64) -> Option<Self> {
        let bin = if bin_m > 0.0 { bin_m } else { 1.0 };
        let n = (route.length() / bin).floor() as usize + 1;
        let mut lo = vec![f64::INFINITY; n];
        let mut hi = vec![f64::NEG_INFINITY; n];
        let mut drives_at = vec![0usize; n];
        let mut any = false;
        for (_, poses) in drives {
            if poses.is_empty() {
                continue;
            }
            any = true;
            let proj = tracked_projections(route, poses);
            let mut seen = vec![false; n];
            crossings(&proj, bin, n, |k, o| {
                lo[k] = lo[k].min(o);
                hi[k] = hi[k].max(o);
                seen[k] = true;
            });
            for (d, s) in drives_at.iter_mut().zip(seen) {
                *d += s as usize;
            }
        }
        if !any || drives_at.iter().all(|&d| d == 0) {
            return None;
        }
        // Grid points not every drive passed (before the latest start, after the earliest
        // end): the band of the nearest one they all passed.
        let full = *drives_at.iter().max().expect("a grid point");
        let reached: Vec<usize> = (0..n).filter(|&k| drives_at[k] == full).collect();
        for k in 0..n {
            if drives_at[k] < full {
                let j = reached
                    .iter()
                    .copied()
                    .min_by_key(|&j| j.abs_diff(k))
                    .expect("one reached");
                lo[k] = lo[j];
                hi[k] = hi[j];
            }
        }
        Some(ReferenceRegion {
            bin_m: bin,
            lo,
            hi,
            drives: drives_at,
            runs: drives.iter().map(|d| d.0.clone()).collect(),
        })
    }

    /// The band's edges at arc length `s` (linear between grid points, clamped at the ends).
    pub fn band_at(&self, s: f64) -> (f64, f64) {
        let n = self.lo.len();
        let x = (s / self.bin_m).clamp(0.0, (n - 1) as f64);
        let k = (x.floor() as usize).min(n - 1);
        if k + 1 >= n {
            return (self.lo[k], self.hi[k]);
        }
        let f = x - k as f64;
        (
            self.lo[k] + f * (self.lo[k + 1] - self.lo[k]),
            self.hi[k] + f * (self.hi[k + 1] - self.hi[k]),
        )
    }

    /// The signed cross-track error of a projection: 0 inside the band, the distance to the
    /// nearer edge outside (positive on the left).
    pub fn cte(&self, p: &Projection) -> f64 {
        let (lo, hi) = self.band_at(p.s);
        if p.offset > hi {
            p.offset - hi
        } else if p.offset < lo {
            p.offset - lo
        } else {
            0.0
        }
    }

    /// The band's two edges as polylines in the pose frame (for maps): (left edge, right edge).
    pub fn edges(&self, route: &Route) -> (Vec<[f64; 2]>, Vec<[f64; 2]>) {
        let mut left = Vec::with_capacity(self.lo.len());
        let mut right = Vec::with_capacity(self.lo.len());
        for k in 0..self.lo.len() {
            let s = (k as f64 * self.bin_m).min(route.length());
            let p = route.point_at(s);
            let h = route.heading_at(s);
            let n = [-h.sin(), h.cos()];
            left.push([p[0] + self.hi[k] * n[0], p[1] + self.hi[k] * n[1]]);
            right.push([p[0] + self.lo[k] * n[0], p[1] + self.lo[k] * n[1]]);
        }
        (left, right)
    }
}

/// The centre line of nominal drives: the longest drive (thinned to a point every `bin_m`
/// metres) is the first guess; every drive is projected on it, and the line is moved sideways at
/// every grid point by the mean of the drives' offsets there. None with fewer than two distinct
/// points.
pub fn centre_line(drives: &[(String, Vec<[f64; 2]>)], bin_m: f64) -> Option<Route> {
    let bin = if bin_m > 0.0 { bin_m } else { 1.0 };
    let longest = drives
        .iter()
        .map(|(_, p)| p)
        .max_by(|a, b| path_length(a).total_cmp(&path_length(b)))?;
    let mut thin: Vec<[f64; 2]> = Vec::new();
    for p in longest {
        if thin
            .last()
            .is_none_or(|q| (p[0] - q[0]).hypot(p[1] - q[1]) >= bin)
        {
            thin.push(*p);
        }
    }
    if let (Some(last), Some(end)) = (thin.last(), longest.last())
        && last != end
    {
        thin.push(*end);
    }
    let guess = Route::new(thin).ok()?;
    let n = (guess.length() / bin).floor() as usize + 1;
    let mut sum = vec![0.0; n];
    let mut count = vec![0usize; n];
    for (_, poses) in drives {
        let proj = tracked_projections(&guess, poses);
        crossings(&proj, bin, n, |k, o| {
            sum[k] += o;
            count[k] += 1;
        });
    }
    let pts: Vec<[f64; 2]> = (0..n)
        .filter(|&k| count[k] > 0)
        .map(|k| {
            let s = (k as f64 * bin).min(guess.length());
            let p = guess.point_at(s);
            let h = guess.heading_at(s);
            let o = sum[k] / count[k] as f64;
            [p[0] - o * h.sin(), p[1] + o * h.cos()]
        })
        .collect();
    Route::new(pts).ok()
}

fn path_length(p: &[[f64; 2]]) -> f64 {
    p.windows(2)
        .map(|w| (w[1][0] - w[0][0]).hypot(w[1][1] - w[0][1]))
        .sum()
}

/// The positions of pose samples.
pub(crate) fn positions(poses: &[PoseSample]) -> Vec<[f64; 2]> {
    poses.iter().map(|p| p.p).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn band_of_three_parallel_drives_and_cte_outside_it() {
        let route = Route::new(vec![[0.0, 0.0], [100.0, 0.0]]).unwrap();
        let drive = |y: f64| -> Vec<[f64; 2]> { (0..=50).map(|k| [2.0 * k as f64, y]).collect() };
        let drives = vec![
            ("a".to_string(), drive(-0.5)),
            ("b".to_string(), drive(0.1)),
            ("c".to_string(), drive(0.4)),
        ];
        let r = ReferenceRegion::build(&route, &drives, 1.0).unwrap();
        assert_eq!(r.band_at(37.3), (-0.5, 0.4));
        assert!(r.drives.iter().all(|&d| d == 3));
        let at = |offset: f64| Projection {
            s: 50.0,
            offset,
            segment: 0,
        };
        assert_eq!(r.cte(&at(0.2)), 0.0);
        assert!((r.cte(&at(1.0)) - 0.6).abs() < 1e-12);
        assert!((r.cte(&at(-1.0)) + 0.5).abs() < 1e-12);
        // The centre line of the drives is y = mean offset.
        let c = centre_line(&drives, 1.0).unwrap();
        let y = (-0.5 + 0.1 + 0.4) / 3.0;
        assert!(c.points.iter().all(|p| (p[1] - y).abs() < 1e-9), "{c:?}");
        assert!((c.length() - 100.0).abs() < 1e-9);
    }
}
