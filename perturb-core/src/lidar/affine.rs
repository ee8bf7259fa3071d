//! Affine family (L-E): 3D-Corruptions-AD's shear, scale and rotation of the points inside object
//! boxes, in the normalised box frame.
//!
//! The normalised frame of a box (centre c, size d, heading h) is the reference's `to_Max2`:
//! `p' = R(-h) (p - c) * 2 / max(d)`, so the box spans `±d_i / max(d)` on each axis; `to_Lidar`
//! inverts it. After the transform, the reference's `normalize_gt` divides each axis whose largest
//! |coordinate| exceeds the box's half extent by the excess ratio, which puts the points back
//! inside their box. The reference does that for shear only; here all three do it, so an object
//! never spills out of its box into its neighbours (and the box stays a valid label of the
//! perturbed object). Boxes, in-box sets and the shared deviations are as in [`super::local`];
//! computations are in f64, the output in f32.

use super::local::{BOXES, InBox, write_plan};
use super::{Box3, LidarBuilder, LidarFrame, LidarPerturbation, Needs, Plan, Points};
use crate::math::Portable;
use crate::rng::Rng;

/// A box's normalised frame.
#[derive(Clone, Copy, Debug)]
pub struct BoxFrame {
    c: [f64; 3],
    cos: f64,
    sin: f64,
    scale: f64,
    /// Half extents in the normalised frame: d_i / max(d).
    pub half: [f64; 3],
}

impl BoxFrame {
    /// The normalised frame of `b` (a box with no size gets scale 1).
    pub fn new(b: &Box3) -> Self {
        let m = b.size.iter().fold(0f32, |a, v| a.max(*v)) as f64;
        let m = if m > 0.0 && m.is_finite() { m } else { 1.0 };
        let (sin, cos) = (b.yaw as f64).psin_cos();
        BoxFrame {
            c: b.center.map(|v| v as f64),
            cos,
            sin,
            scale: 2.0 / m,
            half: b.size.map(|v| v as f64 / m),
        }
    }

    /// The reference's `to_Max2`.
    pub fn to_norm(&self, p: [f32; 3]) -> [f64; 3] {
        let d = [
            p[0] as f64 - self.c[0],
            p[1] as f64 - self.c[1],
            p[2] as f64 - self.c[2],
        ];
        [
            (d[0] * self.cos + d[1] * self.sin) * self.scale,
            (-d[0] * self.sin + d[1] * self.cos) * self.scale,
            d[2] * self.scale,
        ]
    }

    /// The reference's `to_Lidar`.
    pub fn to_sensor(&self, q: [f64; 3]) -> [f32; 3] {
        let x = (q[0] * self.cos - q[1] * self.sin) / self.scale;
        let y = (q[0] * self.sin + q[1] * self.cos) / self.scale;
        [
            (x + self.c[0]) as f32,
            (y + self.c[1]) as f32,
            (q[2] / self.scale + self.c[2]) as f32,
        ]
    }

    /// The reference's `normalize_gt`: each axis whose largest |coordinate| exceeds the half
    /// extent is divided by the ratio.
    pub fn normalize(&self, pts: &mut [[f64; 3]]) {
        for a in 0..3 {
            let max = pts.iter().fold(0f64, |m, p| m.max(p[a].abs()));
            let ratio = max / self.half[a];
            if ratio > 1.0 {
                for p in pts.iter_mut() {
                    p[a] /= ratio;
                }
            }
        }
    }
}

/// Runs `transform` over the normalised points of every box (with that box's own random stream),
/// normalises them back into the box and fills the plan.
fn per_box(
    points: &Points,
    boxes: &[Box3],
    rng: Rng,
    plan: &mut Plan,
    transform: impl Fn(&mut Rng, &BoxFrame, &mut [[f64; 3]]),
) {
    let inbox = InBox::new(points, boxes);
    let mut moved: Vec<Option<[f32; 3]>> = vec![None; points.len()];
    let mut buf: Vec<[f64; 3]> = Vec::new();
    for (b, bx) in boxes.iter().enumerate() {
        let m = inbox.members(b);
        if m.is_empty() {
            continue;
        }
        let f = BoxFrame::new(bx);
        buf.clear();
        buf.extend(m.iter().map(|&i| f.to_norm(points.xyz(i as usize))));
        let mut r = rng.fork(b as u64);
        transform(&mut r, &f, &mut buf);
        f.normalize(&mut buf);
        for (&i, q) in m.iter().zip(&buf) {
            moved[i as usize] = Some(f.to_sensor(*q));
        }
    }
    write_plan(points, &[], &moved, plan);
}

/// ±1 with equal probability.
fn sign(r: &mut Rng) -> f64 {
    if r.next_u64() >> 63 == 1 { 1.0 } else { -1.0 }
}

/// L-E1 shear: centre c of the shear coefficients, 3D-Corruptions-AD levels 1..5 (`shear_bbox`);
/// severities 1, 2, 3 use levels 1, 3, 5.
pub const SHEAR_COEFFICIENT: [f64; 5] = [0.05, 0.10, 0.15, 0.20, 0.25];

/// L-E1 shear: per box, four coefficients b, d, e, f ~ U(c - 0.05, c + 0.05) with independent
/// random signs; in the normalised frame `x' = x + d y + f z`, `y' = y`, `z' = b x + e y + z` (the
/// reference's row vector times `[[1,0,b],[d,1,e],[f,0,1]]`), then `normalize_gt`. A slanted,
/// skewed object of the same footprint.
pub struct Shear {
    seed: u64,
    c: f64,
}

/// Registry constructor of L-E1.
pub const SHEAR: LidarBuilder = |s| {
    Ok(Box::new(Shear {
        seed: s.seed,
        c: SHEAR_COEFFICIENT[s.level_of_five()],
    }))
};

impl LidarPerturbation for Shear {
    fn needs(&self) -> Needs {
        BOXES
    }

    fn plan(&self, points: &Points, frame: &LidarFrame<'_>, plan: &mut Plan) {
        let c = self.c;
        let rng = Rng::for_frame(self.seed, frame.seq, 0xE1);
        per_box(points, frame.boxes, rng, plan, |r, _, pts| {
            let mut coef = || r.uniform(c - 0.05, c + 0.05) * sign(r);
            let (b, d, e, f) = (coef(), coef(), coef(), coef());
            for p in pts.iter_mut() {
                let [x, y, z] = *p;
                *p = [x + d * y + f * z, y, b * x + e * y + z];
            }
        });
    }
}

/// L-E2 scale: scale change c, 3D-Corruptions-AD levels 1..5 (`scale_bbox`); severities 1, 2, 3
/// use levels 1, 3, 5.
pub const SCALE_CHANGE: [f64; 5] = [0.04, 0.08, 0.12, 0.16, 0.20];

/// L-E2 scale: per box, one axis (x, y or z of the box, uniformly) and a sign t = ±1 are drawn;
/// that axis is multiplied by `1 + c t` in the normalised frame, and when it is z the points are
/// lifted by `(s - 1) d_z / max(d)` so the object keeps standing on the box's bottom. An object
/// stretched or squeezed along one axis.
///
/// Deviation: the reference does not bring the points back into the box. With `normalize_gt` a
/// stretch (t = +1) along an axis the points span is undone exactly, and the detector's boxes are
/// tight around their points, so every stretch would be a no-op. Here a stretched object is then
/// shrunk uniformly by `1 / (1 + c)` about the box's bottom centre: it has exactly the reference's
/// proportions (the chosen axis `1 + c` times longer relative to the two others) and fits its box.
/// A squeeze (t = -1) is the reference's transform unchanged. `normalize_gt` runs last, as for
/// the other two (a no-op here).
pub struct Scale {
    seed: u64,
    c: f64,
}

/// Registry constructor of L-E2.
pub const SCALE: LidarBuilder = |s| {
    Ok(Box::new(Scale {
        seed: s.seed,
        c: SCALE_CHANGE[s.level_of_five()],
    }))
};

impl LidarPerturbation for Scale {
    fn needs(&self) -> Needs {
        BOXES
    }

    fn plan(&self, points: &Points, frame: &LidarFrame<'_>, plan: &mut Plan) {
        let c = self.c;
        let rng = Rng::for_frame(self.seed, frame.seq, 0xE2);
        per_box(points, frame.boxes, rng, plan, |r, f, pts| {
            let axis = r.below(3) as usize;
            let t = sign(r);
            let s = 1.0 + c * t;
            let h = f.half[2];
            for p in pts.iter_mut() {
                p[axis] *= s;
                if axis == 2 {
                    p[2] += (s - 1.0) * h;
                }
                if t > 0.0 {
                    p[0] /= s;
                    p[1] /= s;
                    p[2] = -h + (p[2] + h) / s;
                }
            }
        });
    }
}

/// L-E3 rotation: centre c of the rotation angle in degrees, 3D-Corruptions-AD levels 1..5
/// (`rotation_bbox`); severities 1, 2, 3 use levels 1, 3, 5.
pub const ROTATION_DEG: [f64; 5] = [1.0, 3.0, 5.0, 7.0, 9.0];

/// L-E3 rotation: per box, an angle beta ~ U(c - 1, c + 1) degrees with a random sign; the points
/// rotate by beta about the box's vertical axis (a heading error of the object's shape).
///
/// Deviation: the reference lets the rotated corners leave the box; here `normalize_gt` follows,
/// as for shear, which narrows the rotated object along the box's axes where it would stick out
/// (for a 4 x 1.8 m car at 5 degrees, about 16 % in width).
pub struct Rotation {
    seed: u64,
    c: f64,
}

/// Registry constructor of L-E3.
pub const ROTATION: LidarBuilder = |s| {
    Ok(Box::new(Rotation {
        seed: s.seed,
        c: ROTATION_DEG[s.level_of_five()],
    }))
};

impl LidarPerturbation for Rotation {
    fn needs(&self) -> Needs {
        BOXES
    }

    fn plan(&self, points: &Points, frame: &LidarFrame<'_>, plan: &mut Plan) {
        let c = self.c;
        let rng = Rng::for_frame(self.seed, frame.seq, 0xE3);
        per_box(points, frame.boxes, rng, plan, |r, _, pts| {
            let beta = (r.uniform(c - 1.0, c + 1.0) * sign(r)).to_radians();
            let (s, co) = beta.psin_cos();
            for p in pts.iter_mut() {
                let [x, y, _] = *p;
                p[0] = x * co - y * s;
                p[1] = x * s + y * co;
            }
        });
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn normalised_frame_round_trips_and_spans_the_box() {
        let b = Box3 {
            center: [12.0, -3.0, -1.0],
            size: [4.0, 2.0, 1.5],
            yaw: 0.7,
        };
        let f = BoxFrame::new(&b);
        assert_eq!(f.half, [1.0, 0.5, 0.375]);
        let p = [13.0, -2.5, -0.6];
        let q = f.to_norm(p);
        let back = f.to_sensor(q);
        for a in 0..3 {
            assert!((back[a] - p[a]).abs() < 1e-5);
        }
        // The box's front-left-top corner maps to (+half_x, +half_y, +half_z).
        let (s, c) = 0.7f32.psin_cos();
        let corner = [12.0 + 2.0 * c - 1.0 * s, -3.0 + 2.0 * s + 1.0 * c, -0.25];
        let q = f.to_norm(corner);
        assert!(
            (q[0] - 1.0).abs() < 1e-5 && (q[1] - 0.5).abs() < 1e-5 && (q[2] - 0.375).abs() < 1e-5
        );
    }

    #[test]
    fn normalize_shrinks_only_the_axes_that_stick_out() {
        let f = BoxFrame::new(&Box3 {
            center: [0.0; 3],
            size: [4.0, 2.0, 2.0],
            yaw: 0.0,
        });
        let mut pts = vec![[1.2, 0.25, -0.1], [-0.6, -0.5, 0.2]];
        f.normalize(&mut pts);
        assert!((pts[0][0] - 1.0).abs() < 1e-12 && (pts[1][0] + 0.5).abs() < 1e-12);
        assert_eq!(pts[0][1], 0.25);
        assert_eq!(pts[1][2], 0.2);
    }
}
