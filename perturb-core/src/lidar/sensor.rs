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
