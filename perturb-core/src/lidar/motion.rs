//! Motion and alignment family (L-F): ego-motion blur, moving objects, ghost points, misalignment.

use super::local::{BOXES, InBox, write_plan};
use super::{LidarBuilder, LidarFrame, LidarPerturbation, Needs, Plan, Points};
use crate::math::Portable;
use crate::rng::{Rng, for_each_normal_triple};

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
        for_each_normal_triple(&mut rng, points.len(), |i, d| {
            let p = points.xyz(i);
            let mut q = [0f32; 3];
            for a in 0..3 {
                let jitter = (d[a] * sd[a]).clamp(-3.0 * s, 3.0 * s);
                q[a] = p[a] + (t[a] + jitter) as f32;
            }
            plan.moved(i, q);
        });
    }
}

/// L-F4 spatial_misalignment: (probability that a cloud is misaligned, rotation angle in degrees),
/// MultiCorrupt levels 1..3 (`transform_points`).
pub const MISALIGNMENT_LEVELS: [(f64, f64); 3] = [(0.2, 1.0), (0.4, 2.0), (0.6, 3.0)];

/// Translation MultiCorrupt adds to a misaligned cloud, in metres.
pub const MISALIGNMENT_SHIFT_M: [f32; 3] = [2.0, 0.0, 0.0];

/// L-F4 spatial_misalignment: an extrinsic calibration error. With probability p, decided per cloud
/// from (seed, sequence number), every point is rotated by MultiCorrupt's matrix
/// `M = Rx' Ry' Rz'` (see [`multicorrupt_rotation`]), `p' = M p` (the reference's row-vector
/// `p M^T`), and then shifted by (2, 0, 0) m, the reference's fixed translation; otherwise the
/// cloud passes unchanged, byte for byte. The rotation is in x, y, z only; the other fields pass
/// through (the reference keeps its other columns too).
pub struct SpatialMisalignment {
    seed: u64,
    probability: f64,
    rotation: [[f32; 3]; 3],
}

/// Rx(a) Ry(a) Rz(a) for one angle `a` in radians, with the usual right-handed matrices
/// (`Rz(a) = [[cos a, -sin a, 0], [sin a, cos a, 0], [0, 0, 1]]`).
pub fn rotation_xyz(a: f64) -> [[f32; 3]; 3] {
    let (s, c) = a.psin_cos();
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

/// MultiCorrupt's `transform_points` matrix for an angle of `deg` degrees. Its three matrices are
/// written with the signs of the sine terms swapped (`Rx' = [[1,0,0],[0,c,s],[0,-s,c]]`,
/// `Ry' = [[c,0,-s],[0,1,0],[s,0,c]]`, `Rz' = [[c,s,0],[-s,c,0],[0,0,1]]`), that is the usual
/// matrices of `-theta`, so the product is `Rx(-t) Ry(-t) Rz(-t)` = [`rotation_xyz`]`(-t)`.
pub fn multicorrupt_rotation(deg: f64) -> [[f32; 3]; 3] {
    rotation_xyz(-deg.to_radians())
}

/// Registry constructor of L-F4.
pub const MISALIGNMENT: LidarBuilder = |s| {
    let (p, deg) = MISALIGNMENT_LEVELS[s.level()];
    Ok(Box::new(SpatialMisalignment {
        seed: s.seed,
        probability: p,
        rotation: multicorrupt_rotation(deg),
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

/// L-F2 moving_object: the largest shift c in metres, 3D-Corruptions-AD levels 1..5
/// (`moving_noise_bbox`); severities 1, 2, 3 use levels 1, 3, 5.
pub const MOVING_SHIFT_M: [f64; 5] = [0.2, 0.4, 0.6, 0.8, 1.0];

/// L-F2 moving_object: an object that moves while the sensor sweeps over it is smeared along its
/// direction of travel. Per box, with u the coordinate of each of its points along the box heading
/// (`(cos yaw, sin yaw)`) and L = (u_max - u_min) / 3: points with `u_min < u <= u_min + L` move
/// by c / 2 along the heading, points with `u > u_min + L` by c, and the point(s) at u_min stay.
/// Deterministic (no random draw).
///
/// Deviation: the reference shifts along the LiDAR's x axis whatever the object's orientation
/// (its comment: "for kitti: the x is forward"), which smears a crossing car sideways; here the
/// shift follows the box heading, the object's direction of travel. The detector cannot tell an
/// object's front from its back, so its headings lie in (-90, 90] degrees (the shift then has a
/// forward component); boxes from the caller carry their true heading. As in the reference the
/// shifted points may leave the box by up to c.
pub struct MovingObject {
    c: f64,
}

/// Registry constructor of L-F2.
pub const MOVING_OBJECT: LidarBuilder = |s| {
    Ok(Box::new(MovingObject {
        c: MOVING_SHIFT_M[s.level_of_five()],
    }))
};

impl LidarPerturbation for MovingObject {
    fn needs(&self) -> Needs {
        BOXES
    }

    fn plan(&self, points: &Points, frame: &LidarFrame<'_>, plan: &mut Plan) {
        let inbox = InBox::new(points, frame.boxes);
        let mut moved: Vec<Option<[f32; 3]>> = vec![None; points.len()];
        for (b, bx) in frame.boxes.iter().enumerate() {
            let m = inbox.members(b);
            if m.is_empty() {
                continue;
            }
            let (s, c) = (bx.yaw as f64).psin_cos();
            let u = |i: u32| points.x[i as usize] as f64 * c + points.y[i as usize] as f64 * s;
            let (lo, hi) = m
                .iter()
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &i| {
                    (lo.min(u(i)), hi.max(u(i)))
                });
            let third = (hi - lo) / 3.0;
            for &i in m {
                let ui = u(i);
                let shift = if ui > lo + third {
                    self.c
                } else if ui > lo {
                    self.c / 2.0
                } else {
                    continue;
                };
                let p = points.xyz(i as usize);
                moved[i as usize] = Some([
                    (p[0] as f64 + shift * c) as f32,
                    (p[1] as f64 + shift * s) as f32,
                    p[2],
                ]);
            }
        }
        write_plan(points, &[], &moved, plan);
    }
}

/// L-F3 ghost_points: (ghost copies per object point, spacing between successive copies in metres,
/// intensity factor per copy), severities 1..3. The project's own perturbation (no reference).
pub const GHOSTS: [(usize, f32, f32); 3] = [(1, 0.5, 0.5), (2, 0.75, 0.5), (3, 1.0, 0.5)];

/// L-F3 ghost_points: false returns trailing detected objects, as left by a moving object in an
/// aggregated sweep, by multi-echo mismatches or by a misregistered second sensor: every point
/// inside a box gets `k` copies (k = 1, 2, 3 by severity), copy j (1..=k) displaced by
/// `-j * spacing` along the box heading (behind the object; 0.5, 0.75, 1.0 m spacing) and dimmed to
/// `intensity * f^j` (f = 0.5: 50 %, 25 %, 12.5 %). The original points are unchanged and keep
/// their order; the copies follow them, box by box, carrying their source point's other fields
/// (ring, time). The intensity is scaled in the cloud's own units, so the sensor model's scale
/// (`intensity_max`) does not matter; a cloud without intensity gets position-only copies.
/// Deterministic. The output has at most `(1 + k) N` points ([`LidarPerturbation::max_output_points`]).
pub struct GhostPoints {
    copies: usize,
    spacing: f32,
    dim: f32,
}

/// Registry constructor of L-F3.
pub const GHOST_POINTS: LidarBuilder = |s| {
    let (copies, spacing, dim) = GHOSTS[s.level()];
    Ok(Box::new(GhostPoints {
        copies,
        spacing,
        dim,
    }))
};

impl LidarPerturbation for GhostPoints {
    fn needs(&self) -> Needs {
        BOXES
    }

    fn max_output_points(&self, n: usize) -> usize {
        n.saturating_mul(1 + self.copies)
    }

    fn plan(&self, points: &Points, frame: &LidarFrame<'_>, plan: &mut Plan) {
        plan.keep_all(points.len());
        let inbox = InBox::new(points, frame.boxes);
        for (b, bx) in frame.boxes.iter().enumerate() {
            let (s, c) = bx.yaw.psin_cos();
            for j in 1..=self.copies {
                let d = j as f32 * self.spacing;
                let f = self.dim.powi(j as i32);
                for &i in inbox.members(b) {
                    let p = points.xyz(i as usize);
                    plan.emit(
                        i as usize,
                        [p[0] - d * c, p[1] - d * s, p[2]],
                        points.intensity(i as usize) * f,
                    );
                }
            }
        }
    }
}
