//! One beam through the snow: the disks in its wedge occlude parts of it, each reflector adds a
//! pulse, the strongest 10 cm bin is what the sensor detects.

use super::TAU;
use super::flakes::FlakeSet;
use crate::lidar::weather::C_LIGHT;
use crate::math::Portable;

/// Buffers [`beam`] reuses from point to point.
#[derive(Default)]
pub struct BeamScratch {
    /// (range, lo, hi, scan order) of the disks in the wedge.
    cand: Vec<(f32, f32, f32, u64)>,
    covered: Vec<(f32, f32)>,
    pieces: Vec<(f32, f32)>,
    next: Vec<(f32, f32)>,
    reflectors: Vec<(f64, f64)>,
}

fn xi(r: f64) -> f64 {
    ((r - 0.9) / 0.1).clamp(0.0, 1.0)
}

/// The result for one point.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum SnowOutcome {
    /// No flake in the beam.
    Clear,
    /// Flakes in the beam, the target still detected at its range, with this intensity (0..255).
    Dimmed(f64),
    /// No return: nothing in the beam sends back any power (the target wholly hidden by flakes
    /// within the sensor's 0.9 m blind zone, which return nothing themselves); the sensor
    /// reports no point for this beam.
    Lost,
    /// A flake detected instead, at this range with this intensity (0..255).
    Flake {
        /// Range in metres.
        range: f64,
        /// Intensity on 0..255.
        intensity: f64,
    },
}

/// The occlusion and pulse computation for one beam: the target at range `r0` with intensity `i`
/// (0..255), azimuth `az`, wedge half-width `half`, flakes `set`.
pub fn beam(set: &FlakeSet, az: f32, half: f32, r0: f64, i: f64) -> SnowOutcome {
    beam_with(&mut BeamScratch::default(), set, az, half, r0, i)
}

/// [`beam`] with buffers kept between calls.
pub fn beam_with(
    sc: &mut BeamScratch,
    set: &FlakeSet,
    az: f32,
    half: f32,
    r0: f64,
    i: f64,
) -> SnowOutcome {
    let f = &set.flakes;
    if f.is_empty() || r0 <= 0.0 {
        return SnowOutcome::Clear;
    }
    wedge_disks(sc, set, az, half, r0);
    let cand = &mut sc.cand;
    if cand.is_empty() {
        return SnowOutcome::Clear;
    }
    // Nearest first (equal ranges in scan order): each disk takes the part of the wedge not yet
    // covered.
    cand.sort_unstable_by(|a, b| a.0.total_cmp(&b.0).then(a.3.cmp(&b.3)));
    let width = 2.0 * half as f64;
    sc.covered.clear();
    sc.reflectors.clear();
    let mut total = 0.0;
    for &(range, lo, hi, _) in cand.iter() {
        // Length of [lo, hi] not yet covered.
        sc.pieces.clear();
        sc.pieces.push((lo, hi));
        for &(cl, ch) in &sc.covered {
            sc.next.clear();
            for &(a, b) in &sc.pieces {
                if cl >= b || ch <= a {
                    sc.next.push((a, b));
                } else {
                    if a < cl {
                        sc.next.push((a, cl));
                    }
                    if ch < b {
                        sc.next.push((ch, b));
                    }
                }
            }
            std::mem::swap(&mut sc.pieces, &mut sc.next);
        }
        let new: f64 = sc.pieces.iter().map(|(a, b)| (b - a) as f64).sum();
        if new <= 0.0 {
            continue;
        }
        sc.covered.push((lo, hi));
        let ratio = new / width;
        total += ratio;
        let r = range as f64;
        sc.reflectors
            .push((r, 0.9 * 255.0 * ratio * xi(r) / (r * r)));
    }
    if sc.reflectors.is_empty() {
        return SnowOutcome::Clear;
    }
    let rest = (1.0 - total).max(0.0);
    sc.reflectors.push((r0, i * rest * xi(r0)));
    let span = C_LIGHT * TAU;
    let (best_bin, best_p) = strongest_bin(&sc.reflectors, span);
    let d_max = best_bin as f64 / 10.0 - span / 2.0;
    if best_p <= 0.0 || d_max <= 0.0 {
        SnowOutcome::Lost
    } else if (d_max - r0).abs() < 0.2 {
        SnowOutcome::Dimmed(best_p)
    } else {
        SnowOutcome::Flake {
            range: d_max,
            intensity: best_p,
        }
    }
}

/// The strongest 10 cm bin of the summed pulses `a_k sin^2(pi (R - r_k) / span)` of `reflectors`
/// `(r_k, a_k)` (in range order) over the bins any pulse covers, and its power; the lowest bin wins
/// a tie. Each reflector's peak bin is evaluated first; a bin is then evaluated only when an upper
/// bound of its power (below) reaches the best power so far, and a pulse that no other overlaps is
/// scanned outwards from its peak until the bound rules a bin out: most bins cost nothing instead of
/// a `sin` per reflector. The result is that of evaluating every bin.
fn strongest_bin(reflectors: &[(f64, f64)], span: f64) -> (i64, f64) {
    let pi = std::f64::consts::PI;
    let bins = |rj: f64| {
        (
            (rj * 10.0).ceil() as i64,
            ((rj + span) * 10.0).floor() as i64,
        )
    };
    let power = |b: i64| -> f64 {
        let rb = b as f64 / 10.0;
        reflectors
            .iter()
            .filter(|(rk, _)| rb >= *rk && rb <= rk + span)
            .map(|(rk, ak)| ak * (pi * (rb - rk) / span).psin().powi(2))
            .sum()
    };
    // An upper bound of `power(b)`: sin^2 t <= t^2, <= (pi - t)^2, and, with d = |t - pi/2|,
    // sin^2 t = 1 - sin^2 d <= 1 - (d - d^3/6)^2; widened by far more than the rounding of both.
    let bound = |b: i64| -> f64 {
        let rb = b as f64 / 10.0;
        let sum: f64 = reflectors
            .iter()
            .filter(|(rk, _)| rb >= *rk && rb <= rk + span)
            .map(|(rk, ak)| {
                let t = pi * (rb - rk) / span;
                let d = (t - 0.5 * pi).abs();
                let c = d - d * d * d / 6.0;
                ak.abs() * (t * t).min((pi - t) * (pi - t)).min(1.0 - c * c)
            })
            .sum();
        sum * (1.0 + 1e-9) + 1e-300
    };
    let peak_of = |rj: f64| ((rj + 0.5 * span) * 10.0).round() as i64;
    let mut best = (0, -1.0);
    let consider = |best: &mut (i64, f64), b: i64, p: f64| {
        if p > best.1 || (p == best.1 && b < best.0) {
            *best = (b, p);
        }
    };
    for &(rj, _) in reflectors {
        let (first, last) = bins(rj);
        let peak = peak_of(rj).clamp(first, last.max(first));
        consider(&mut best, peak, power(peak));
    }
    let mut done = i64::MIN;
    for (k, &(rk, _)) in reflectors.iter().enumerate() {
        let (first, last) = bins(rk);
        let first = first.max(done.saturating_add(1));
        done = done.max(last);
        if first > last {
            continue;
        }
        // Alone: no other pulse within 5 cm of these bins, so the bound falls monotonically away
        // from the pulse's peak and the scan can stop at the first bin it rules out.
        // Every pulse within 5 cm of these bins at its full height cannot reach the best: skip.
        let (lo, hi) = (first as f64 / 10.0 - 0.05, last as f64 / 10.0 + 0.05);
        let reach: f64 = reflectors
            .iter()
            .filter(|(rj, _)| *rj <= hi && rj + span >= lo)
            .map(|(_, aj)| aj.abs())
            .sum();
        if reach * (1.0 + 1e-9) + 1e-300 < best.1 {
            continue;
        }
        let alone = (k == 0 || reflectors[k - 1].0 + span < first as f64 / 10.0 - 0.05)
            && reflectors
                .get(k + 1)
                .is_none_or(|next| next.0 > last as f64 / 10.0 + 0.05);
        if alone {
            let peak = peak_of(rk).clamp(first, last);
            consider(&mut best, peak, power(peak));
            for b in (first..peak).rev() {
                if bound(b) < best.1 {
                    break;
                }
                consider(&mut best, b, power(b));
            }
            for b in peak + 1..=last {
                if bound(b) < best.1 {
                    break;
                }
                consider(&mut best, b, power(b));
            }
        } else {
            for b in first..=last {
                if bound(b) >= best.1 {
                    consider(&mut best, b, power(b));
                }
            }
        }
    }
    best
}

/// Fills `sc.cand` with the disks in front of the target that intersect the wedge, as angular
/// intervals relative to `az` clipped to the wedge. The azimuth windows are those of a scan of
/// every flake within `half + max_half_angle` (the window, then its wrapped-around parts below
/// -pi and above pi); each tier reads only the part of them its widest flake can reach from. The
/// scan order is kept in each entry so that equal ranges sort as a scan would list them.
fn wedge_disks(sc: &mut BeamScratch, set: &FlakeSet, az: f32, half: f32, r0: f64) {
    let pi = std::f32::consts::PI;
    let reach = half + set.max_half_angle;
    let cand = &mut sc.cand;
    cand.clear();
    // Windows: (lo, hi, shift, scan order of the window).
    let mut windows = [(az - reach, az + reach, 0.0, 0u64); 3];
    let mut n = 1;
    if az - reach < -pi {
        windows[n] = (az - reach + 2.0 * pi, pi, -2.0 * pi, 1);
        n += 1;
    }
    if az + reach > pi {
        windows[n] = (-pi, az + reach - 2.0 * pi, 2.0 * pi, 2);
        n += 1;
    }
    for tier in &set.tiers {
        if (tier.min_range as f64) >= r0 {
            break; // this tier and the farther ones are behind the target
        }
        if tier.entries.is_empty() {
            continue;
        }
        // Only flakes within this tier's reach of az can touch the wedge (with a margin, so
        // that a rounding never leaves out a flake the test below would take).
        let near = (half + tier.max_half) * (1.0 + 1e-5) + 1e-6;
        for &(wlo, whi, shift, segment) in &windows[..n] {
            let (lo, hi) = match segment {
                0 => (wlo.max(az - near), whi.min(az + near)),
                1 => (wlo.max(az - near + 2.0 * pi), whi),
                _ => (wlo, whi.min(az + near - 2.0 * pi)),
            };
            for e in &tier.entries[tier.start(lo)..] {
                if e.azimuth > hi {
                    break;
                }
                if (e.range as f64) >= r0 {
                    continue;
                }
                let c = e.azimuth + shift - az;
                let (l, h) = ((c - e.half).max(-half), (c + e.half).min(half));
                if l < h {
                    cand.push((e.range, l, h, segment << 32 | e.k as u64));
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::lidar::weather::snow::{HAHNER_SNOW, flake_set};
    use crate::rng::Rng;

    /// Every bin evaluated in ascending order, the lowest winning a tie: what [`strongest_bin`]
    /// must equal.
    fn strongest_bin_by_scan(reflectors: &[(f64, f64)], span: f64) -> (i64, f64) {
        let (mut best_bin, mut best_p) = (0i64, -1.0);
        let mut done = i64::MIN;
        for &(rj, _) in reflectors {
            let first = ((rj * 10.0).ceil() as i64).max(done.saturating_add(1));
            let last = ((rj + span) * 10.0).floor() as i64;
            for b in first..=last {
                let rb = b as f64 / 10.0;
                let p: f64 = reflectors
                    .iter()
                    .filter(|(rk, _)| rb >= *rk && rb <= rk + span)
                    .map(|(rk, ak)| ak * (std::f64::consts::PI * (rb - rk) / span).psin().powi(2))
                    .sum();
                if p > best_p {
                    best_p = p;
                    best_bin = b;
                }
            }
            done = done.max(last);
        }
        (best_bin, best_p)
    }

    #[test]
    fn the_pruned_pulse_search_finds_what_a_scan_of_every_bin_finds() {
        let span = C_LIGHT * TAU;
        let mut rng = Rng::from_key(17);
        for case in 0..20_000 {
            let n = 1 + (case % 12);
            let mut reflectors: Vec<(f64, f64)> = (0..n)
                .map(|_| {
                    // Ranges on a coarse grid half the time (equal ranges, bins on pulse edges),
                    // amplitudes sometimes equal (ties) or zero.
                    let r = if rng.f64() < 0.5 {
                        (rng.below(400) as f64) * 0.05
                    } else {
                        rng.f64() * 20.0
                    };
                    let a = match rng.below(4) {
                        0 => 0.0,
                        1 => 10.0,
                        _ => rng.f64() * 100.0,
                    };
                    (r, a)
                })
                .collect();
            reflectors.sort_by(|a, b| a.0.total_cmp(&b.0));
            let (bin, p) = strongest_bin(&reflectors, span);
            let (want_bin, want_p) = strongest_bin_by_scan(&reflectors, span);
            assert_eq!(
                (bin, p.to_bits()),
                (want_bin, want_p.to_bits()),
                "{reflectors:?}"
            );
        }
    }

    /// The indexed wedge search gives what testing every flake gives.
    #[test]
    fn the_wedge_search_finds_every_flake_a_full_scan_finds() {
        let mut rng = Rng::for_setup(5, 9);
        let set = flake_set(&mut rng, HAHNER_SNOW[4].0, HAHNER_SNOW[4].1);
        let mut sc = BeamScratch::default();
        let pi = std::f32::consts::PI;
        for k in 0..4000 {
            let az = if k < 50 {
                [pi - 1e-4, -pi + 1e-4][k % 2]
            } else {
                rng.uniform(-std::f64::consts::PI, std::f64::consts::PI) as f32
            };
            let (half, r0) = (1.5e-3, rng.uniform(1.0, 80.0));
            wedge_disks(&mut sc, &set, az, half, r0);
            let mut got: Vec<(f32, f32, f32)> = sc.cand.iter().map(|c| (c.0, c.1, c.2)).collect();
            let mut want = Vec::new();
            for f in &set.flakes {
                let a = (f.radius / f.range).min(1.0).pasin();
                if (f.range as f64) >= r0 {
                    continue;
                }
                for shift in [0.0, -2.0 * pi, 2.0 * pi] {
                    let c = f.azimuth + shift - az;
                    let (l, h) = ((c - a).max(-half), (c + a).min(half));
                    if l < h {
                        want.push((f.range, l, h));
                    }
                }
            }
            let key = |a: &(f32, f32, f32), b: &(f32, f32, f32)| {
                a.0.total_cmp(&b.0).then(a.1.total_cmp(&b.1))
            };
            got.sort_by(key);
            want.sort_by(key);
            assert_eq!(got, want, "azimuth {az}");
        }
    }
}
