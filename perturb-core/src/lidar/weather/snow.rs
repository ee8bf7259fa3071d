//! Hahner et al.'s LiDAR snowfall simulation (CVPR 2022), as 3D-Corruptions-AD (L-A2, with wet
//! ground) and MultiCorrupt (L-A3) use it.
//!
//! Each beam sees a horizontal slice of falling snow: flakes are spheres whose diameters follow the
//! Gunn-Marshall distribution; cut by the beam's plane they are 2-D disks scattered over an 80 m
//! disc until they cover the occupancy `occ` of its area. A beam is a wedge of the beam divergence
//! around its azimuth; the disks closer than the target that intersect the wedge occlude parts of
//! it (each angular part goes to the nearest disk). Every reflector j (the flakes and the target's
//! visible part) adds a pulse `A_j ratio_j xi(r_j) / r_j^2 sin^2(pi (R - r_j) / (c tau))` to the
//! received power over R in [r_j, r_j + c tau] (tau = 10 ns, 10 cm bins). The strongest bin gives
//! the detected range: within 0.2 m of the target the point keeps its place with the new intensity;
//! otherwise it moves to the flake. Finally the returns at or below the sensor's noise floor (0.7
//! of a quadratic fit to the weakest ground returns by distance) are dropped, as the reference does.
//! L-A2 also wets the ground first: a water film reflects part of the beam away, dimming ground
//! returns.
//!
//! Real-time form: the disk sets (one per beam, reused across frames; the beam-to-set assignment is
//! reshuffled per frame from (seed, sequence number), as the reference shuffles its files) are
//! generated at configuration time and sorted by azimuth; a point binary-searches its wedge and only
//! tests the few disks there; pulses are evaluated only where reflectors overlap. The reference
//! tests every disk for every point (hours per dataset).
//!
//! Deviations, all documented here: the target's pulse amplitude is `i r0^2` as the paper's
//! equations give (both references overwrite it with the flake's 0.9 x 255 when any flake is in the
//! beam, which drops most partially occluded returns under the noise floor); no per-laser HDL-64
//! intensity calibration (focal slope 0, as for any non-HDL-64 sensor); overlapping flakes are not
//! rejected when the sets are generated (at these occupancies overlaps are negligible); the ground
//! for the noise floor and the wet ground is the grid ground mask of [`crate::detector`]; the wet
//! ground is a simplified Fresnel model (below).

use super::super::{LidarBuilder, LidarFrame, LidarPerturbation, LidarSetup, Needs, Plan, Points};
use super::C_LIGHT;
use crate::rng::Rng;

/// 3D-Corruptions-AD's snowfall settings at its levels 1..5: (rain rate rr in mm/h, occupancy);
/// severities 1, 2, 3 use levels 1, 3, 5. From (snowfall mm/h, terminal velocity m/s) =
/// (0.5, 1.8), (2.5, 1.4), (1.0, 0.2), (1.5, 0.2), (2.5, 0.2).
pub const HAHNER_SNOW: [(f64, f64); 5] = [
    (2.62, 7.7e-7),
    (42.7, 4.96e-6),
    (200.2, 1.39e-5),
    (367.8, 2.08e-5),
    (791.4, 3.47e-5),
];
/// MultiCorrupt's settings at its levels 1..3 (from (0.5, 1.2), (2.5, 1.6), (1.5, 0.4)).
pub const MULTICORRUPT_SNOW: [(f64, f64); 3] =
    [(4.82, 1.16e-6), (34.97, 4.34e-6), (130.0, 1.04e-5)];

/// Radius of the disc the flakes are scattered in, metres.
pub const R0: f64 = 80.0;
/// Pulse half-power width, seconds.
pub const TAU: f64 = 10e-9;

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
    tiers: Vec<Tier>,
}

/// A flake as the wedge search reads it.
#[derive(Clone, Copy, Debug)]
struct Entry {
    azimuth: f32,
    range: f32,
    /// Angular half-width, `asin(min(radius / range, 1))`.
    half: f32,
    /// Position in [`FlakeSet::flakes`].
    k: u32,
}

/// The flakes of one range class, in azimuth order, with a bucket table of their azimuths.
#[derive(Clone, Debug, Default)]
struct Tier {
    /// The class's lower range bound: no flake of the tier is nearer.
    min_range: f32,
    /// Widest half-width in the tier.
    max_half: f32,
    entries: Vec<Entry>,
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
    fn start(&self, lo: f32) -> usize {
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
                half: (f.radius / f.range).min(1.0).asin(),
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

/// Generates one beam's disk set: flakes uniform over the 80 m disc, diameters exponential with
/// mean 10 / Lambda mm (Lambda = 25.5 rr^-0.48 per cm), capped at 20 mm, cut at a height uniform
/// in the sphere, until their area reaches `occ` of the disc; disks covering the sensor are
/// rejected.
pub fn flake_set(rng: &mut Rng, rr: f64, occ: f64) -> FlakeSet {
    let lambda = 25.5 * rr.powf(-0.48);
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
    let reflectors = &sc.reflectors;
    // Strongest 10 cm bin of the summed pulses, evaluated where any pulse is: each bin once, in
    // ascending order (the reflectors are in range order), the lowest bin winning a tie.
    let span = C_LIGHT * TAU;
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
                .map(|(rk, ak)| ak * (std::f64::consts::PI * (rb - rk) / span).sin().powi(2))
                .sum();
            if p > best_p {
                best_p = p;
                best_bin = b;
            }
        }
        done = done.max(last);
    }
    let d_max = best_bin as f64 / 10.0 - span / 2.0;
    if (d_max - r0).abs() < 0.2 {
        SnowOutcome::Dimmed(best_p)
    } else {
        SnowOutcome::Flake {
            range: d_max.max(0.1),
            intensity: best_p,
        }
    }
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

/// The noise floor: 0.7 of a quadratic fit, over distance, of the weakest ground returns (the 5th
/// percentile of each 2 m distance bin), on 0..255. Without enough ground it is 0.
pub fn noise_floor(points: &Points, ground: &[bool], to255: f64) -> [f64; 3] {
    let mut bins: Vec<Vec<f64>> = vec![Vec::new(); 50];
    for (i, g) in ground.iter().enumerate() {
        if !g {
            continue;
        }
        let d = points.range(i) as f64;
        let b = (d / 2.0) as usize;
        if b < bins.len() {
            bins[b].push(points.intensity(i) as f64 * to255);
        }
    }
    let samples: Vec<(f64, f64)> = bins
        .iter_mut()
        .enumerate()
        .filter(|(_, v)| v.len() >= 20)
        .map(|(b, v)| {
            v.sort_by(f64::total_cmp);
            (b as f64 * 2.0 + 1.0, v[v.len() / 20])
        })
        .collect();
    if samples.len() < 3 {
        return [0.0; 3];
    }
    // Least squares for a + b d + c d^2.
    let mut m = [[0f64; 4]; 3];
    for &(d, y) in &samples {
        let row = [1.0, d, d * d];
        for r in 0..3 {
            for c in 0..3 {
                m[r][c] += row[r] * row[c];
            }
            m[r][3] += row[r] * y;
        }
    }
    for col in 0..3 {
        let piv = (col..3)
            .max_by(|&a, &b| m[a][col].abs().total_cmp(&m[b][col].abs()))
            .unwrap_or(col);
        m.swap(col, piv);
        if m[col][col].abs() < 1e-12 {
            return [0.0; 3];
        }
        for r in 0..3 {
            if r != col {
                let f = m[r][col] / m[col][col];
                let pivot_row = m[col];
                for (v, p) in m[r].iter_mut().zip(pivot_row).skip(col) {
                    *v -= f * p;
                }
            }
        }
    }
    [
        0.7 * m[0][3] / m[0][0],
        0.7 * m[1][3] / m[1][1],
        0.7 * m[2][3] / m[2][2],
    ]
}

/// Intensity factor of a wet road at incidence angle `theta` (radians from the surface normal):
/// the beam crosses the 1 mm water film twice; the share the water surface reflects away
/// (unpolarised Fresnel, n = 1.33) is lost to the sensor, so the diffuse return of the pavement
/// is scaled by the two-way transmittance (1 - R(theta))^2.
pub fn wet_ground_factor(theta: f64) -> f64 {
    let n = 1.33f64;
    let ci = theta.cos().clamp(0.0, 1.0);
    let st = theta.sin() / n;
    let ct = (1.0 - st * st).max(0.0).sqrt();
    let rs = ((ci - n * ct) / (ci + n * ct)).powi(2);
    let rp = ((ct - n * ci) / (ct + n * ci)).powi(2);
    let r = 0.5 * (rs + rp);
    (1.0 - r).powi(2)
}

/// L-A2 snow_hahner / L-A3 snow_multicorrupt.
pub struct HahnerSnow {
    seed: u64,
    salt: u64,
    sets: Vec<FlakeSet>,
    half_divergence: f32,
    wet_ground: bool,
}

fn build(s: &LidarSetup, rr: f64, occ: f64, wet: bool, salt: u64) -> HahnerSnow {
    let beams = s.sensor.beams().max(1);
    let base = Rng::for_setup(s.seed, salt);
    let sets = (0..beams)
        .map(|b| flake_set(&mut base.fork(b as u64), rr, occ))
        .collect();
    HahnerSnow {
        seed: s.seed,
        salt,
        sets,
        half_divergence: s.sensor.beam_divergence / 2.0,
        wet_ground: wet,
    }
}

/// Registry constructor of L-A2.
pub const SNOW_HAHNER: LidarBuilder = |s| {
    let (rr, occ) = HAHNER_SNOW[s.level_of_five()];
    Ok(Box::new(build(s, rr, occ, true, 0xA2)))
};

/// Registry constructor of L-A3.
pub const SNOW_MULTICORRUPT: LidarBuilder = |s| {
    let (rr, occ) = MULTICORRUPT_SNOW[s.level()];
    Ok(Box::new(build(s, rr, occ, false, 0xA3)))
};

impl HahnerSnow {
    /// The disk sets, one per beam.
    pub fn sets(&self) -> &[FlakeSet] {
        &self.sets
    }
}

impl LidarPerturbation for HahnerSnow {
    fn needs(&self) -> Needs {
        Needs {
            ring: true,
            ..Default::default()
        }
    }

    fn plan(&self, points: &Points, frame: &LidarFrame<'_>, plan: &mut Plan) {
        let to255 = 255.0 / points.intensity_max.max(1e-6) as f64;
        let ground = crate::detector::ground_mask(points);
        let floor = noise_floor(points, &ground, to255);
        let thr = |d: f64| floor[0] + floor[1] * d + floor[2] * d * d;
        // This frame's assignment of disk sets to beams.
        let mut order: Vec<usize> = (0..self.sets.len()).collect();
        Rng::for_frame(self.seed, frame.seq, self.salt).shuffle(&mut order);
        let rings = points.ring.as_deref();
        let mut scratch = BeamScratch::default();
        for i in 0..points.len() {
            let p = points.xyz(i);
            let r0 = points.range(i) as f64;
            if !r0.is_finite() || r0 <= 0.0 {
                plan.keep(i);
                continue;
            }
            let mut inten = points
                .intensity
                .as_ref()
                .map_or(127.5, |v| v[i] as f64 * to255);
            let mut changed = false;
            if self.wet_ground && ground[i] {
                let theta = ((p[0] * p[0] + p[1] * p[1]).sqrt() as f64)
                    .atan2(-p[2] as f64)
                    .abs();
                inten *= wet_ground_factor(theta.min(std::f64::consts::FRAC_PI_2));
                changed = true;
            }
            let ring = rings.map_or(0, |r| r[i] as usize) % self.sets.len();
            let set = &self.sets[order[ring]];
            let az = p[1].atan2(p[0]);
            match beam_with(&mut scratch, set, az, self.half_divergence, r0, inten) {
                SnowOutcome::Flake { range, intensity } => {
                    let k = (range / r0) as f32;
                    plan.emit(
                        i,
                        [p[0] * k, p[1] * k, p[2] * k],
                        (intensity / to255) as f32,
                    );
                }
                outcome => {
                    if let SnowOutcome::Dimmed(v) = outcome {
                        inten = v;
                        changed = true;
                    }
                    // Returns at or below the noise floor are not detected.
                    if inten <= thr(r0) {
                        continue;
                    }
                    if changed {
                        plan.dimmed(i, (inten / to255) as f32);
                    } else {
                        plan.keep(i);
                    }
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

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
                let a = (f.radius / f.range).min(1.0).asin();
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

    #[test]
    fn disk_sets_have_the_configured_occupancy() {
        let mut rng = Rng::for_setup(1, 1);
        for (rr, occ) in [HAHNER_SNOW[0], HAHNER_SNOW[4]] {
            let set = flake_set(&mut rng, rr, occ);
            let area: f64 = set
                .flakes
                .iter()
                .map(|f| std::f64::consts::PI * (f.radius as f64).powi(2))
                .sum();
            let want = occ * std::f64::consts::PI * R0 * R0;
            assert!(area >= want && area < want * 1.05, "{area} vs {want}");
            assert!(set.flakes.windows(2).all(|w| w[0].azimuth <= w[1].azimuth));
            assert!(
                set.flakes
                    .iter()
                    .all(|f| f.range > f.radius && f.range <= R0 as f32)
            );
        }
        // lidar.md: about 3.8e4 disks per beam at the lightest setting; fewer for heavy snow
        // (larger flakes).
        let light = flake_set(&mut rng, HAHNER_SNOW[0].0, HAHNER_SNOW[0].1)
            .flakes
            .len();
        assert!((30_000..48_000).contains(&light), "{light}");
        assert!(
            flake_set(&mut rng, HAHNER_SNOW[4].0, HAHNER_SNOW[4].1)
                .flakes
                .len()
                < light
        );
    }

    #[test]
    fn a_flake_in_front_of_a_dark_far_target_wins() {
        let set = FlakeSet::new(vec![Flake {
            azimuth: 0.0,
            range: 5.0,
            radius: 0.004,
        }]);
        // A 3 mrad wedge at 5 m is 15 mm wide: the flake covers about half of it.
        match beam(&set, 0.0, 1.5e-3, 40.0, 10.0) {
            SnowOutcome::Flake { range, .. } => assert!((range - 5.0).abs() < 0.2, "{range}"),
            o => panic!("{o:?}"),
        }
        // A bright near target is still detected, dimmed by its occluded share.
        match beam(&set, 0.0, 1.5e-3, 6.0, 250.0) {
            SnowOutcome::Dimmed(v) => assert!(v < 250.0 && v > 50.0, "{v}"),
            o => panic!("{o:?}"),
        }
        assert_eq!(
            beam(&set, 1.0, 1.5e-3, 40.0, 10.0),
            SnowOutcome::Clear,
            "no flake in another direction"
        );
    }

    #[test]
    fn wet_ground_dims_grazing_returns_more() {
        let (steep, grazing) = (wet_ground_factor(0.2), wet_ground_factor(1.4));
        assert!(steep > 0.9 && grazing < steep, "{steep} {grazing}");
    }
}
