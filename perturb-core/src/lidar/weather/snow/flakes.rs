//! The flake disks of one beam's slice of snow: generated once per set, sorted by azimuth and
//! indexed in range tiers for the wedge search.

use super::R0;
use crate::math::Portable;
use crate::rng::Rng;

/// One flake disk of a beam's set.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Flake {
    /// Azimuth, radians in [-pi, pi).
    pub azimuth: f32,
    /// Range of the centre, metres.
    pub range: f32,
    /// Radius, metres.
    pub radius: f32,
}

/// The flakes of one beam, sorted by azimuth, with an index for the beam test: flakes are
/// grouped into tiers by range (the nearer, the fewer and the wider), so that finding the flakes
/// in front of a target within a beam's wedge reads only the tiers nearer than the target, and
/// in each only the azimuth window its widest flake could reach from, in contiguous memory.
#[derive(Clone, Debug, Default)]
pub struct FlakeSet {
    /// Flakes in azimuth order.
    pub flakes: Vec<Flake>,
    /// Largest angular half-width of any flake.
    pub max_half_angle: f32,
    /// The tiers of [`FlakeSet::TIER_RANGES`], nearest first.
    pub(super) tiers: Vec<Tier>,
}

/// A flake as the wedge search reads it.
#[derive(Clone, Copy, Debug)]
pub(super) struct Entry {
    pub(super) azimuth: f32,
    pub(super) range: f32,
    /// Angular half-width, `asin(min(radius / range, 1))`.
    pub(super) half: f32,
    /// Position in [`FlakeSet::flakes`].
    pub(super) k: u32,
}

/// The flakes of one range class, in azimuth order, with a bucket table of their azimuths.
#[derive(Clone, Debug, Default)]
pub(super) struct Tier {
    /// The class's lower range bound: no flake of the tier is nearer.
    pub(super) min_range: f32,
    /// Widest half-width in the tier.
    pub(super) max_half: f32,
    pub(super) entries: Vec<Entry>,
    /// `bucket[b]`: how many entries have an azimuth below the lower edge of bucket `b - 1` (of
    /// `bucket.len()` over [-pi, pi)); a lower bound of the search's answer for any azimuth in
    /// bucket `b`, from which a short forward step finds it.
    bucket: Vec<u32>,
}

impl Tier {
    fn new(min_range: f32, entries: Vec<Entry>) -> Self {
        let max_half = entries.iter().map(|e| e.half).fold(0.0, f32::max);
        let n = entries.len().next_power_of_two().clamp(16, 16384);
        // The edges ascend, so one walk through the (sorted) entries finds every count.
        let mut below = 0;
        let bucket = (0..n)
            .map(|b| {
                let edge = bucket_edge(b.saturating_sub(1), n);
                while below < entries.len() && entries[below].azimuth < edge {
                    below += 1;
                }
                below as u32
            })
            .collect();
        Tier {
            min_range,
            max_half,
            entries,
            bucket,
        }
    }

    /// The first entry with an azimuth at or above `lo` (`partition_point(azimuth < lo)`).
    #[inline]
    pub(super) fn start(&self, lo: f32) -> usize {
        let e = &self.entries;
        let n = self.bucket.len();
        let scaled = (lo + std::f32::consts::PI) * (n as f32 / (2.0 * std::f32::consts::PI));
        let mut k = if scaled >= 0.0 {
            // (NaN and negatives start at 0.)
            match self.bucket.get(scaled as usize) {
                Some(&s) => s as usize,
                None => return e.partition_point(|x| x.azimuth < lo),
            }
        } else {
            0
        };
        while k < e.len() && e[k].azimuth < lo {
            k += 1;
        }
        k
    }
}

/// The lower edge of bucket `b` of `n` over [-pi, pi).
fn bucket_edge(b: usize, n: usize) -> f32 {
    -std::f32::consts::PI + b as f32 * (2.0 * std::f32::consts::PI / n as f32)
}

impl FlakeSet {
    /// Range bounds (metres) between the tiers: flakes nearer than the first, between two
    /// bounds, beyond the last.
    pub const TIER_RANGES: [f32; 6] = [1.25, 2.5, 5.0, 10.0, 20.0, 40.0];

    /// A set of `flakes` (sorted here by azimuth) and its index. Flakes must lie off the
    /// sensor (`range > radius > 0`), as [`flake_set`] makes them.
    pub fn new(mut flakes: Vec<Flake>) -> Self {
        flakes.sort_by(|a, b| a.azimuth.total_cmp(&b.azimuth));
        let entries: Vec<Entry> = flakes
            .iter()
            .enumerate()
            .map(|(k, f)| Entry {
                azimuth: f.azimuth,
                range: f.range,
                half: (f.radius / f.range).min(1.0).pasin(),
                k: k as u32,
            })
            .collect();
        let max_half_angle = entries.iter().map(|e| e.half).fold(0.0, f32::max);
        let mut lo = 0.0;
        let mut tiers = Vec::new();
        for &hi in Self::TIER_RANGES.iter().chain([f32::INFINITY].iter()) {
            let mine: Vec<Entry> = entries
                .iter()
                .filter(|e| e.range >= lo && e.range < hi)
                .copied()
                .collect();
            tiers.push(Tier::new(lo, mine));
            lo = hi;
        }
        FlakeSet {
            flakes,
            max_half_angle,
            tiers,
        }
    }
}

/// Generates one beam's disk set: flakes uniform over the 80 m disc, diameters exponential with
/// mean 10 / Lambda mm (Lambda = 25.5 rr^-0.48 per cm), capped at 20 mm, cut at a height uniform
/// in the sphere, until their area reaches `occ` of the disc; disks covering the sensor are
/// rejected.
pub fn flake_set(rng: &mut Rng, rr: f64, occ: f64) -> FlakeSet {
    let lambda = 25.5 * rr.ppowf(-0.48);
    let mean_mm = 10.0 / lambda;
    let target = occ * std::f64::consts::PI * R0 * R0;
    let mut area = 0.0;
    let mut flakes = Vec::new();
    while area < target {
        let d_mm = rng.exponential(mean_mm).min(20.0);
        let h = (rng.f64() - 0.5) * d_mm;
        let r = (((d_mm / 2.0).powi(2) - h * h).max(0.0)).sqrt() * 1e-3;
        let rho = R0 * rng.f64().sqrt();
        if rho <= r {
            continue;
        }
        let az = rng.uniform(-std::f64::consts::PI, std::f64::consts::PI);
        area += std::f64::consts::PI * r * r;
        flakes.push(Flake {
            azimuth: az as f32,
            range: rho as f32,
            radius: r as f32,
        });
    }
    FlakeSet::new(flakes)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::lidar::weather::snow::HAHNER_SNOW;

    #[test]
    fn the_bucket_table_finds_what_a_binary_search_finds() {
        let mut rng = Rng::for_setup(3, 7);
        let set = flake_set(&mut rng, HAHNER_SNOW[2].0, HAHNER_SNOW[2].1);
        let tier = set.tiers.last().unwrap();
        assert!(tier.entries.len() > 1000 && set.tiers.iter().all(|t| !t.entries.is_empty()));
        let mut probes: Vec<f32> = (0..20_000).map(|_| rng.uniform(-3.2, 3.2) as f32).collect();
        for e in tier.entries.iter().step_by(97) {
            let x = e.azimuth;
            probes.extend([x, x.next_up(), x.next_down()]);
        }
        for b in 0..tier.bucket.len() {
            let e = bucket_edge(b, tier.bucket.len());
            probes.extend([e, e.next_up(), e.next_down()]);
        }
        probes.extend([f32::NAN, f32::INFINITY, f32::NEG_INFINITY, -7.0, 7.0]);
        for t in &set.tiers {
            for &lo in &probes {
                assert_eq!(
                    t.start(lo),
                    t.entries.partition_point(|e| e.azimuth < lo),
                    "{lo}"
                );
            }
        }
    }
}
