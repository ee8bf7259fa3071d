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
//! ground is a simplified Fresnel model (below); a beam whose light no reflector returns (the
//! target hidden by flakes in the sensor's blind zone) gives no point, never one at a minimum
//! range.
//!
//! Severity: Gunn-Marshall's size scale grows with the rate (`Lambda = 25.5 R^-0.48` per cm), so
//! an occupancy is covered by fewer, larger flakes as the rate rises: MultiCorrupt's levels (L-A3,
//! occupancy x9 from s1 to s3, rate x27) hold about 2.5 times fewer flakes at s3 than at s1, and a
//! beam meets a flake about as often at every severity (the reference's users noticed the count
//! falling with the rate: SysCV/LiDAR_snow_sim issue 26). L-A3's retention is flat within 0.01
//! (docs/lidar.md, "Weather and severity").

use crate::math::Portable;
mod beam;
mod flakes;
mod ground;

pub use beam::*;
pub use flakes::*;
pub use ground::*;

use super::super::{LidarBuilder, LidarFrame, LidarPerturbation, LidarSetup, Needs, Plan, Points};
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
                    .patan2(-p[2] as f64)
                    .abs();
                inten *= wet_ground_factor(theta.min(std::f64::consts::FRAC_PI_2));
                changed = true;
            }
            let ring = rings.map_or(0, |r| r[i] as usize) % self.sets.len();
            let set = &self.sets[order[ring]];
            let az = p[1].patan2(p[0]);
            match beam_with(&mut scratch, set, az, self.half_divergence, r0, inten) {
                // No return: the beam gives no point (never one at a minimum range).
                SnowOutcome::Lost => continue,
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
    fn a_beam_hidden_by_a_flake_in_the_blind_zone_returns_nothing() {
        // A flake 5 cm from the sensor covers the whole 3 mrad wedge; closer than 0.9 m it
        // returns nothing itself, and the target behind it gets no light: no return at all.
        let set = FlakeSet::new(vec![Flake {
            azimuth: 0.0,
            range: 0.05,
            radius: 0.004,
        }]);
        assert_eq!(beam(&set, 0.0, 1.5e-3, 30.0, 200.0), SnowOutcome::Lost);
    }

    #[test]
    fn wet_ground_dims_grazing_returns_more() {
        let (steep, grazing) = (wet_ground_factor(0.2), wet_ground_factor(1.4));
        assert!(steep > 0.9 && grazing < steep, "{steep} {grazing}");
    }
}
