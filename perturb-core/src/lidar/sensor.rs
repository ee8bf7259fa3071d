//! Sensor family (L-B): points lost or filtered by the sensor itself.

use super::{LidarBuilder, LidarFrame, LidarPerturbation, Plan, Points};
use crate::rng::Rng;

/// L-B1 density_decrease: fraction of the points deleted, 3D-Corruptions-AD levels 1..5
/// (`density_dec_global`); severities 1, 2, 3 use levels 1, 3, 5.
pub const DENSITY_FRACTION: [f64; 5] = [0.06, 0.12, 0.18, 0.24, 0.30];

/// L-B1 density_decrease: deletes exactly `floor(c N)` points chosen uniformly without replacement;
/// the others keep their order and bytes.
pub struct DensityDecrease {
    seed: u64,
    fraction: f64,
}

/// Registry constructor of L-B1.
pub const DENSITY_DECREASE: LidarBuilder = |s| {
    Ok(Box::new(DensityDecrease {
        seed: s.seed,
        fraction: DENSITY_FRACTION[s.level_of_five()],
    }))
};

impl LidarPerturbation for DensityDecrease {
    fn plan(&self, points: &Points, frame: &LidarFrame<'_>, plan: &mut Plan) {
        let n = points.len();
        let k = (n as f64 * self.fraction) as usize;
        let mut rng = Rng::for_frame(self.seed, frame.seq, 0xB1);
        let drop = rng.choose_mask(n, k);
        for (i, d) in drop.iter().enumerate() {
            if !d {
                plan.keep(i);
            }
        }
    }
}

/// L-B6 fov_filter: half-angle of the kept horizontal field of view in degrees, 3D-Corruptions-AD
/// levels 1..5 (`fov_filter`); severities 1, 2, 3 use levels 1, 3, 5.
pub const FOV_HALF_ANGLE_DEG: [f64; 5] = [105.0, 90.0, 75.0, 60.0, 45.0];

/// L-B6 fov_filter: keeps the points whose azimuth from the sensor's forward axis (+x, as in ROS
/// and KITTI) is within ±a. The reference measures azimuth from +y because nuScenes' LiDAR frame
/// looks along +y; in an x-forward frame that is |atan2(y, x)| <= a, which is what is done here.
/// Deterministic: no random draw.
pub struct FovFilter {
    half_angle: f32,
}

/// Registry constructor of L-B6.
pub const FOV_FILTER: LidarBuilder = |s| {
    Ok(Box::new(FovFilter {
        half_angle: FOV_HALF_ANGLE_DEG[s.level_of_five()].to_radians() as f32,
    }))
};

impl LidarPerturbation for FovFilter {
    fn plan(&self, points: &Points, _frame: &LidarFrame<'_>, plan: &mut Plan) {
        for i in 0..points.len() {
            if points.y[i].atan2(points.x[i]).abs() <= self.half_angle {
                plan.keep(i);
            }
        }
    }
}

/// L-B2 points_reducing: percentage of the points removed, MultiCorrupt levels 1..3
/// (`pointsreducing`, current values; earlier releases used 20/40/60 and 60/75/90).
pub const POINTS_REDUCING_PERCENT: [f64; 3] = [70.0, 80.0, 90.0];

/// L-B2 points_reducing: keeps `round(N (100 - s) / 100)` points chosen uniformly (MultiCorrupt
/// takes the first ones of a random permutation); the kept points keep their order.
pub struct PointsReducing {
    seed: u64,
    percent: f64,
}

/// Registry constructor of L-B2.
pub const POINTS_REDUCING: LidarBuilder = |s| {
    Ok(Box::new(PointsReducing {
        seed: s.seed,
        percent: POINTS_REDUCING_PERCENT[s.level()],
    }))
};

impl LidarPerturbation for PointsReducing {
    fn plan(&self, points: &Points, frame: &LidarFrame<'_>, plan: &mut Plan) {
        let n = points.len();
        let keep = (n as f64 * (100.0 - self.percent) / 100.0).round() as usize;
        let mut rng = Rng::for_frame(self.seed, frame.seq, 0xB2);
        let kept = rng.choose_mask(n, keep);
        for (i, k) in kept.iter().enumerate() {
            if *k {
                plan.keep(i);
            }
        }
    }
}

/// L-B3 beam_reduction: one ring in `step` is kept, severities 1..3. MultiCorrupt keeps 16, 8 and
/// 4 of a 32-beam sensor (rings {1,3,..,31}, {1,5,..,29}, {1,9,17,25}); expressed as a fraction of the
/// beams it applies to any sensor: 1/2, 1/4, 1/8 (HDL-64E: 32, 16, 8 rings; VLP-16: 8, 4, 2).
pub const BEAM_STEP: [u16; 3] = [2, 4, 8];

/// L-B3 beam_reduction: keeps the points whose ring `r` satisfies `r % step == 1`, as MultiCorrupt's
/// lists do for 32 beams. Rings come from the cloud's ring field, or are derived from each point's
/// elevation with the sensor model when the cloud has none (KITTI). Deterministic.
pub struct BeamReduction {
    step: u16,
}

/// Registry constructor of L-B3.
pub const BEAM_REDUCTION: LidarBuilder = |s| {
    Ok(Box::new(BeamReduction {
        step: BEAM_STEP[s.level()],
    }))
};

impl BeamReduction {
    /// True if ring `r` is kept.
    pub fn keeps(&self, r: u16) -> bool {
        r % self.step == 1 % self.step
    }
}

impl LidarPerturbation for BeamReduction {
    fn needs(&self) -> super::Needs {
        super::Needs {
            ring: true,
            ..Default::default()
        }
    }

    fn plan(&self, points: &Points, _frame: &LidarFrame<'_>, plan: &mut Plan) {
        let Some(ring) = &points.ring else { return };
        for (i, r) in ring.iter().enumerate() {
            if self.keeps(*r) {
                plan.keep(i);
            }
        }
    }
}

/// L-B4 cutout: number of holes, 3D-Corruptions-AD levels 1..5 (`cutout_local`); severities 1, 2,
/// 3 use levels 1, 3, 5.
pub const CUTOUT_HOLES: [usize; 5] = [2, 3, 5, 7, 10];

/// L-B4 cutout: `k` times, picks a random remaining point and deletes its `m = int(0.02 N)` nearest
/// remaining neighbours (itself included), N the original count; occluded patches.
///
/// Deviation: the reference measures the distance over every column of its array (intensity
/// included); here over x, y, z only.
pub struct Cutout {
    seed: u64,
    holes: usize,
}

/// Registry constructor of L-B4.
pub const CUTOUT: LidarBuilder = |s| {
    Ok(Box::new(Cutout {
        seed: s.seed,
        holes: CUTOUT_HOLES[s.level_of_five()],
    }))
};

impl LidarPerturbation for Cutout {
    fn plan(&self, points: &Points, frame: &LidarFrame<'_>, plan: &mut Plan) {
        let n = points.len();
        let m = (0.02 * n as f64) as usize;
        let mut alive: Vec<u32> = (0..n as u32).collect();
        let mut rng = Rng::for_frame(self.seed, frame.seq, 0xB4);
        let mut dist: Vec<(f32, u32)> = Vec::with_capacity(n);
        for _ in 0..self.holes {
            if alive.is_empty() || m == 0 {
                break;
            }
            let c = points.xyz(alive[rng.below(alive.len() as u64) as usize] as usize);
            dist.clear();
            dist.extend(alive.iter().map(|&i| {
                let p = points.xyz(i as usize);
                let d = (p[0] - c[0]).powi(2) + (p[1] - c[1]).powi(2) + (p[2] - c[2]).powi(2);
                (if d.is_nan() { f32::INFINITY } else { d }, i)
            }));
            let cut = m.min(dist.len());
            // Partial selection: the `cut` nearest, ties broken by index for determinism.
            dist.select_nth_unstable_by(cut - 1, |a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
            let mut gone: Vec<u32> = dist[..cut].iter().map(|d| d.1).collect();
            gone.sort_unstable();
            alive.retain(|i| gone.binary_search(i).is_err());
        }
        for i in alive {
            plan.keep(i as usize);
        }
    }
}

/// L-B5 crosstalk: fraction of the points hit, 3D-Corruptions-AD levels 1..5
/// (`lidar_crosstalk_noise`); severities 1, 2, 3 use levels 1, 3, 5.
pub const CROSSTALK_FRACTION: [f64; 5] = [0.004, 0.008, 0.012, 0.016, 0.020];

/// L-B5 crosstalk: `c N` points chosen without replacement get N(0, 3 m) added to x, y and z: the
/// far-off false returns another LiDAR's pulses cause.
///
/// Deviation: the reference adds the noise to every column (intensity too); here to x, y, z only.
pub struct Crosstalk {
    seed: u64,
    fraction: f64,
}

/// Registry constructor of L-B5.
pub const CROSSTALK: LidarBuilder = |s| {
    Ok(Box::new(Crosstalk {
        seed: s.seed,
        fraction: CROSSTALK_FRACTION[s.level_of_five()],
    }))
};

impl LidarPerturbation for Crosstalk {
    fn plan(&self, points: &Points, frame: &LidarFrame<'_>, plan: &mut Plan) {
        scatter_subset(
            points,
            plan,
            Rng::for_frame(self.seed, frame.seq, 0xB5),
            self.fraction,
            3.0,
        );
    }
}

/// Adds N(0, sigma) to x, y, z of `floor(fraction N)` points chosen without replacement; the others
/// are kept unchanged, in order.
pub(crate) fn scatter_subset(
    points: &Points,
    plan: &mut Plan,
    mut rng: Rng,
    fraction: f64,
    sigma: f64,
) {
    let n = points.len();
    let hit = rng.choose_mask(n, (fraction * n as f64) as usize);
    for (i, h) in hit.iter().enumerate() {
        if *h {
            let [x, y, z] = points.xyz(i);
            plan.moved(
                i,
                [
                    x + (rng.normal() * sigma) as f32,
                    y + (rng.normal() * sigma) as f32,
                    z + (rng.normal() * sigma) as f32,
                ],
            );
        } else {
            plan.keep(i);
        }
    }
}
