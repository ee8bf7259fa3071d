//! Global noise family (L-C): jitter on every point's position.

use super::{LidarBuilder, LidarFrame, LidarPerturbation, Plan, Points};
use crate::rng::{Rng, for_each_normal_triple};

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
        for_each_normal_triple(&mut rng, points.len(), |i, d| {
            let [x, y, z] = points.xyz(i);
            let d = d.map(|v| v * s);
            plan.moved(i, [x + d[0] as f32, y + d[1] as f32, z + d[2] as f32]);
        });
    }
}

/// L-C2 uniform_noise: half-width of the uniform noise in metres, 3D-Corruptions-AD levels 1..5
/// (`uniform_noise`); severities 1, 2, 3 use levels 1, 3, 5.
pub const UNIFORM_HALF_WIDTH_M: [f64; 5] = [0.02, 0.04, 0.06, 0.08, 0.10];

/// L-C2 uniform_noise: adds independent U(-c, c) to x, y and z of every point.
///
/// Deviation from the reference (as L-C1): 3D-Corruptions-AD adds the noise to every column,
/// intensity and ring included; here only x, y, z move and every other field passes through.
pub struct UniformNoise {
    seed: u64,
    c: f64,
}

/// Registry constructor of L-C2.
pub const UNIFORM: LidarBuilder = |s| {
    Ok(Box::new(UniformNoise {
        seed: s.seed,
        c: UNIFORM_HALF_WIDTH_M[s.level_of_five()],
    }))
};

impl LidarPerturbation for UniformNoise {
    fn plan(&self, points: &Points, frame: &LidarFrame<'_>, plan: &mut Plan) {
        let mut rng = Rng::for_frame(self.seed, frame.seq, 0xC2);
        let c = self.c;
        for i in 0..points.len() {
            let [x, y, z] = points.xyz(i);
            let mut u = || rng.uniform(-c, c) as f32;
            plan.moved(i, [x + u(), y + u(), z + u()]);
        }
    }
}

/// L-C3 impulse_noise: the divisor d of the number of points hit (`N / d`), 3D-Corruptions-AD
/// levels 1..5 (`impulse_noise`); severities 1, 2, 3 use levels 1, 3, 5.
pub const IMPULSE_DIVISOR: [usize; 5] = [30, 25, 20, 15, 10];

/// L-C3 impulse_noise: `N / d` (integer division) points chosen without replacement move by exactly
/// ±0.1 m on each of x, y and z (independent random signs).
///
/// Deviation from the reference (as L-C1): 3D-Corruptions-AD shifts every column by ±0.1,
/// intensity and ring included; here only x, y, z.
pub struct ImpulseNoise {
    seed: u64,
    divisor: usize,
}

/// Registry constructor of L-C3.
pub const IMPULSE: LidarBuilder = |s| {
    Ok(Box::new(ImpulseNoise {
        seed: s.seed,
        divisor: IMPULSE_DIVISOR[s.level_of_five()],
    }))
};

impl LidarPerturbation for ImpulseNoise {
    fn plan(&self, points: &Points, frame: &LidarFrame<'_>, plan: &mut Plan) {
        let n = points.len();
        let mut rng = Rng::for_frame(self.seed, frame.seq, 0xC3);
        let hit = rng.choose_mask(n, n / self.divisor);
        for (i, h) in hit.iter().enumerate() {
            if *h {
                let [x, y, z] = points.xyz(i);
                let bits = rng.next_u32();
                let s = |b: u32| if bits >> b & 1 == 1 { 0.1f32 } else { -0.1 };
                plan.moved(i, [x + s(0), y + s(1), z + s(2)]);
            } else {
                plan.keep(i);
            }
        }
    }
}

/// L-A10 strong_sunlight: fraction of the points hit, 3D-Corruptions-AD levels 1..5
/// (`scene_glare_noise`); severities 1, 2, 3 use levels 1, 3, 5.
pub const SUNLIGHT_FRACTION: [f64; 5] = [0.01, 0.02, 0.03, 0.04, 0.05];

/// L-A10 strong_sunlight: sunlight saturating the receiver makes some returns unreliable:
/// `floor(c N)` points chosen without replacement get N(0, (2 m)^2) added to x, y and z
/// (3D-Corruptions-AD `scene_glare_noise`, the LiDAR-only variant; the camera-and-LiDAR variant
/// `ImagePointAddSun` needs the sun's position in a camera image and is not used).
///
/// Placement: the catalogue lists it in the weather family, but its algorithm is a noise model
/// (it is L-B5 crosstalk with sigma 2 m and other fractions), so it lives here, next to the other
/// noises, and shares its code with L-B5; the weather module holds the physics-based models.
///
/// Deviation: the reference adds the noise to every column (intensity and ring too); here to x,
/// y, z only.
pub struct StrongSunlight {
    seed: u64,
    fraction: f64,
}

/// Registry constructor of L-A10.
pub const SUNLIGHT: LidarBuilder = |s| {
    Ok(Box::new(StrongSunlight {
        seed: s.seed,
        fraction: SUNLIGHT_FRACTION[s.level_of_five()],
    }))
};

impl LidarPerturbation for StrongSunlight {
    fn plan(&self, points: &Points, frame: &LidarFrame<'_>, plan: &mut Plan) {
        super::sensor::scatter_subset(
            points,
            plan,
            Rng::for_frame(self.seed, frame.seq, 0xA10),
            self.fraction,
            2.0,
        );
    }
}
