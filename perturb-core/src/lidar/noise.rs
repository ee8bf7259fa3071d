//! Global noise family (L-C): jitter on every point's position.

use super::{LidarBuilder, LidarFrame, LidarPerturbation, Plan, Points};
use crate::rng::Rng;

/// L-C1 gaussian_noise: standard deviation in metres, 3D-Corruptions-AD levels 1..5
/// (`gaussian_noise`); severities 1, 2, 3 use levels 1, 3, 5.
pub const GAUSSIAN_SIGMA_M: [f64; 5] = [0.02, 0.04, 0.06, 0.08, 0.10];

/// L-C1 gaussian_noise: adds independent N(0, sigma^2) to x, y and z of every point.
///
/// Deviation from the reference: 3D-Corruptions-AD adds the noise to every column of its array,
/// intensity and ring included; here only the position moves (a ring index or an intensity with
/// centimetre noise is not a physical effect), and every other field passes through unchanged.
pub struct GaussianNoise {
    seed: u64,
    sigma: f64,
}

/// Registry constructor of L-C1.
pub const GAUSSIAN: LidarBuilder = |s| {
    Ok(Box::new(GaussianNoise {
        seed: s.seed,
        sigma: GAUSSIAN_SIGMA_M[s.level_of_five()],
    }))
};

impl LidarPerturbation for GaussianNoise {
    fn plan(&self, points: &Points, frame: &LidarFrame<'_>, plan: &mut Plan) {
        let mut rng = Rng::for_frame(self.seed, frame.seq, 0xC1);
        let s = self.sigma;
        for i in 0..points.len() {
            let [x, y, z] = points.xyz(i);
            let d = [rng.normal() * s, rng.normal() * s, rng.normal() * s];
            plan.moved(i, [x + d[0] as f32, y + d[1] as f32, z + d[2] as f32]);
        }
    }
}
