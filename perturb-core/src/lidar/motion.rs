//! Motion and alignment family (L-F): ego-motion blur, moving objects, ghost points, misalignment.

use super::{LidarBuilder, LidarFrame, LidarPerturbation, Plan, Points};
use crate::rng::Rng;

/// L-F1 motion_blur: the motion scale s in metres, MultiCorrupt levels 1..3 (`pts_motion`).
pub const MOTION_SCALE_M: [f64; 3] = [0.06, 0.10, 0.13];

/// L-F1 motion_blur: MultiCorrupt's ego-motion approximation: one translation t ~ N(0, s^2) per axis
/// for the whole cloud, plus per-point jitter with standard deviations 0.15 s, 0.2 s and 0.12 s on x,
/// y and z, each jitter clipped to ±3 s. Like the reference it uses no timestamps or ego velocity.
pub struct MotionBlur {
    seed: u64,
    s: f64,
}

/// Registry constructor of L-F1.
pub const MOTION_BLUR: LidarBuilder = |s| {
    Ok(Box::new(MotionBlur {
        seed: s.seed,
        s: MOTION_SCALE_M[s.level()],
    }))
};

impl LidarPerturbation for MotionBlur {
    fn plan(&self, points: &Points, frame: &LidarFrame<'_>, plan: &mut Plan) {
        let mut rng = Rng::for_frame(self.seed, frame.seq, 0xF1);
        let s = self.s;
        let t = [rng.normal() * s, rng.normal() * s, rng.normal() * s];
        let sd = [0.15 * s, 0.2 * s, 0.12 * s];
        for i in 0..points.len() {
            let p = points.xyz(i);
            let mut q = [0f32; 3];
            for a in 0..3 {
                let jitter = (rng.normal() * sd[a]).clamp(-3.0 * s, 3.0 * s);
                q[a] = p[a] + (t[a] + jitter) as f32;
            }
            plan.moved(i, q);
        }
    }
}

/// L-F4 spatial_misalignment: (probability that a cloud is misaligned, rotation angle in degrees),
/// MultiCorrupt levels 1..3 (`transform_points`).
pub const MISALIGNMENT: [(f64, f64); 3] = [(0.2, 1.0), (0.4, 2.0), (0.6, 3.0)];

/// Translation MultiCorrupt adds to a misaligned cloud, in metres.
pub const MISALIGNMENT_SHIFT_M: [f32; 3] = [2.0, 0.0, 0.0];

/// L-F4 spatial_misalignment: an extrinsic calibration error. With probability p, decided per cloud
/// from (seed, sequence number), every point is rotated by theta about x, y and z (R = Rx Ry Rz,
/// applied as MultiCorrupt does, `p R^T` for row vectors) and then shifted by (2, 0, 0) m, the
/// reference's fixed translation; otherwise the cloud passes unchanged.
pub struct SpatialMisalignment {
    seed: u64,
    probability: f64,
    rotation: [[f32; 3]; 3],
}

/// Rx(a) Ry(a) Rz(a) for one angle `a` in radians.
pub fn rotation_xyz(a: f64) -> [[f32; 3]; 3] {
    let (s, c) = a.sin_cos();
    let rx = [[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]];
    let ry = [[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]];
    let rz = [[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]];
    let mul = |a: [[f64; 3]; 3], b: [[f64; 3]; 3]| {
        let mut o = [[0.0; 3]; 3];
        for i in 0..3 {
            for j in 0..3 {
                o[i][j] = (0..3).map(|k| a[i][k] * b[k][j]).sum();
            }
        }
        o
    };
    mul(mul(rx, ry), rz).map(|r| r.map(|v| v as f32))
}

/// Registry constructor of L-F4.
pub const MISALIGNMENT_BUILDER: LidarBuilder = |s| {
    let (p, deg) = MISALIGNMENT[s.level()];
    Ok(Box::new(SpatialMisalignment {
        seed: s.seed,
        probability: p,
        rotation: rotation_xyz(deg.to_radians()),
    }))
};

impl SpatialMisalignment {
    /// True if the cloud of frame `seq` is misaligned.
    pub fn misaligned(&self, seq: u64) -> bool {
        Rng::for_frame(self.seed, seq, 0xF4).chance(self.probability)
    }
}

impl LidarPerturbation for SpatialMisalignment {
    fn plan(&self, points: &Points, frame: &LidarFrame<'_>, plan: &mut Plan) {
        if !self.misaligned(frame.seq) {
            plan.keep_all(points.len());
            return;
        }
        let r = &self.rotation;
        for i in 0..points.len() {
            let p = points.xyz(i);
            // Row vector times R^T = R times column vector.
            let q = [0, 1, 2].map(|k| {
                r[k][0] * p[0] + r[k][1] * p[1] + r[k][2] * p[2] + MISALIGNMENT_SHIFT_M[k]
            });
            plan.moved(i, q);
        }
    }
}
