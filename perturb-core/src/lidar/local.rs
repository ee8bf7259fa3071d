//! Local family (L-D): 3D-Corruptions-AD's `*_bbox` corruptions of the points inside object boxes.
//!
//! The boxes come from the caller or from the clustering detector run on the unperturbed cloud
//! ([`crate::detector`]). A point belongs to a box if [`Box3::contains`] says so (the reference's
//! `check_point_in_box`: |dz| <= h/2 and the rotated offset within half length and half width).
//!
//! Deviations shared by the whole family (and by the affine and motion families, which use the
//! same in-box sets):
//! - The reference's `pick_bbox` calls these functions with three arguments while they take two
//!   (issue #6), so it raises a `TypeError`; here they run.
//! - A point inside several boxes belongs to the first one only and is corrupted once (the
//!   reference would run the boxes in turn over the already corrupted points).
//! - Output order: the reference moves each box's points to the front of the array; here every
//!   point keeps its place (the layout's other fields travel with it).
//! - Noise and distances are on x, y, z only; the reference's arrays include intensity (and the
//!   other columns), which it also jitters and uses in its distances.

use super::{Box3, LidarBuilder, LidarFrame, LidarPerturbation, Needs, Plan, Points};
use crate::math::Portable;
use crate::rng::Rng;

/// No box.
pub const NO_BOX: u32 = u32::MAX;

/// The points of each box: `box_of[i]` is the box point `i` belongs to (the first that contains
/// it) or [`NO_BOX`], and `members(b)` lists box `b`'s points in input order.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct InBox {
    /// Box index per point, or [`NO_BOX`].
    pub box_of: Vec<u32>,
    start: Vec<u32>,
    items: Vec<u32>,
}

impl InBox {
    /// Assigns every point of `points` to the first of `boxes` that contains it. A uniform 2-D grid
    /// over the boxes' footprints keeps this O(N + boxes) (a few candidate boxes per point at
    /// most), whatever the number of boxes.
    pub fn new(points: &Points, boxes: &[Box3]) -> Self {
        let mut box_of = vec![NO_BOX; points.len()];
        if let Some(grid) = BoxGrid::new(boxes) {
            for (i, slot) in box_of.iter_mut().enumerate() {
                let p = points.xyz(i);
                if let Some(b) = grid
                    .candidates(p)
                    .iter()
                    .find(|&&b| boxes[b as usize].contains(p))
                {
                    *slot = *b;
                }
            }
        }
        let members = box_of
            .iter()
            .enumerate()
            .filter(|&(_, &b)| b != NO_BOX)
            .map(|(i, &b)| (b as usize, i as u32));
        let (start, items) = compressed_rows(boxes.len(), members);
        InBox {
            box_of,
            start,
            items,
        }
    }

    /// Number of boxes.
    pub fn boxes(&self) -> usize {
        self.start.len().saturating_sub(1)
    }

    /// The points of box `b`, in input order.
    pub fn members(&self, b: usize) -> &[u32] {
        &self.items[self.start[b] as usize..self.start[b + 1] as usize]
    }

    /// Points inside any box.
    pub fn total(&self) -> usize {
        self.items.len()
    }
}

/// A uniform 2-D grid over the boxes' footprints (at most 256 x 256 cells, none smaller than
/// 0.5 m) listing, per cell, the boxes whose footprint bounds touch it, in box order.
struct BoxGrid {
    lo: [f32; 2],
    hi: [f32; 2],
    inv: f32,
    gx: usize,
    gy: usize,
    start: Vec<u32>,
    list: Vec<u32>,
}

impl BoxGrid {
    /// The grid over `boxes`; `None` when no box has finite bounds.
    fn new(boxes: &[Box3]) -> Option<BoxGrid> {
        let fp: Vec<Option<[f32; 4]>> = boxes.iter().map(footprint).collect();
        let mut lo = [f32::INFINITY; 2];
        let mut hi = [f32::NEG_INFINITY; 2];
        for r in fp.iter().flatten() {
            lo = [lo[0].min(r[0]), lo[1].min(r[1])];
            hi = [hi[0].max(r[2]), hi[1].max(r[3])];
        }
        if !(lo[0] <= hi[0] && lo[1] <= hi[1]) {
            return None;
        }
        let cell = ((hi[0] - lo[0]).max(hi[1] - lo[1]) / 256.0).max(0.5);
        let inv = 1.0 / cell;
        let gx = (((hi[0] - lo[0]) * inv) as usize + 1).min(257);
        let gy = (((hi[1] - lo[1]) * inv) as usize + 1).min(257);
        let mut grid = BoxGrid {
            lo,
            hi,
            inv,
            gx,
            gy,
            start: Vec::new(),
            list: Vec::new(),
        };
        let ranges: Vec<Option<[usize; 4]>> = fp
            .iter()
            .map(|r| r.map(|r| [grid.cx(r[0]), grid.cy(r[1]), grid.cx(r[2]), grid.cy(r[3])]))
            .collect();
        let cells = ranges.iter().enumerate().flat_map(|(b, g)| {
            g.iter().flat_map(move |g| {
                (g[0]..=g[2])
                    .flat_map(move |cx| (g[1]..=g[3]).map(move |cy| (cx * gy + cy, b as u32)))
            })
        });
        (grid.start, grid.list) = compressed_rows(gx * gy, cells);
        Some(grid)
    }

    fn cx(&self, x: f32) -> usize {
        (((x - self.lo[0]) * self.inv).max(0.0) as usize).min(self.gx - 1)
    }

    fn cy(&self, y: f32) -> usize {
        (((y - self.lo[1]) * self.inv).max(0.0) as usize).min(self.gy - 1)
    }

    /// The boxes whose footprint bounds touch the cell of `p`, in box order (none outside the grid).
    fn candidates(&self, p: [f32; 3]) -> &[u32] {
        let (lo, hi) = (self.lo, self.hi);
        if !(p[0] >= lo[0] && p[0] <= hi[0] && p[1] >= lo[1] && p[1] <= hi[1]) {
            return &[];
        }
        let c = self.cx(p[0]) * self.gy + self.cy(p[1]);
        &self.list[self.start[c] as usize..self.start[c + 1] as usize]
    }
}

/// The bounds `[x0, y0, x1, y1]` of a box's footprint (axis-aligned around the rotated rectangle,
/// a hair larger so rounding never drops a point that [`Box3::contains`] accepts); `None` for a
/// box with a non-finite size or position.
fn footprint(b: &Box3) -> Option<[f32; 4]> {
    let (s, c) = b.yaw.psin_cos();
    let hx = 0.5 * (b.size[0] * c.abs() + b.size[1] * s.abs()) * 1.0001 + 1e-4;
    let hy = 0.5 * (b.size[0] * s.abs() + b.size[1] * c.abs()) * 1.0001 + 1e-4;
    let r = [
        b.center[0] - hx,
        b.center[1] - hy,
        b.center[0] + hx,
        b.center[1] + hy,
    ];
    (r.iter().all(|v| v.is_finite()) && b.size[2].is_finite() && b.center[2].is_finite())
        .then_some(r)
}

/// Groups `(group, value)` pairs into compressed rows over `groups` groups: group g's values are
/// `list[start[g]..start[g + 1]]`, in the order given.
fn compressed_rows(
    groups: usize,
    pairs: impl Iterator<Item = (usize, u32)> + Clone,
) -> (Vec<u32>, Vec<u32>) {
    let mut start = vec![0u32; groups + 1];
    for (g, _) in pairs.clone() {
        start[g + 1] += 1;
    }
    for k in 1..start.len() {
        start[k] += start[k - 1];
    }
    let mut cursor = start.clone();
    let mut list = vec![0u32; start[groups] as usize];
    for (g, v) in pairs {
        list[cursor[g] as usize] = v;
        cursor[g] += 1;
    }
    (start, list)
}

/// Fills `plan` with every point in input order: points with `moved[i]` set at their new position,
/// points with `removed[i]` set left out, the rest kept unchanged.
pub(crate) fn write_plan(
    points: &Points,
    removed: &[bool],
    moved: &[Option<[f32; 3]>],
    plan: &mut Plan,
) {
    for i in 0..points.len() {
        if removed.get(i).copied().unwrap_or(false) {
            continue;
        }
        match moved.get(i).copied().flatten() {
            Some(p) => plan.moved(i, p),
            None => plan.keep(i),
        }
    }
}

/// The needs of every object-level perturbation.
pub(crate) const BOXES: Needs = Needs {
    ring: false,
    boxes: true,
};

/// L-D1 local_density_decrease: fraction of each box's points deleted, 3D-Corruptions-AD levels
/// 1..5 (`density_dec_bbox`); severities 1, 2, 3 use levels 1, 3, 5.
pub const LOCAL_DENSITY_FRACTION: [f64; 5] = [0.1, 0.2, 0.3, 0.4, 0.5];

/// L-D1 local_density_decrease: in every box, `int(c n)` of its n points, chosen uniformly without
/// replacement, are deleted (objects look sparser, as with a dark or distant target).
pub struct LocalDensity {
    seed: u64,
    fraction: f64,
}

/// Registry constructor of L-D1.
pub const LOCAL_DENSITY: LidarBuilder = |s| {
    Ok(Box::new(LocalDensity {
        seed: s.seed,
        fraction: LOCAL_DENSITY_FRACTION[s.level_of_five()],
    }))
};

impl LidarPerturbation for LocalDensity {
    fn needs(&self) -> Needs {
        BOXES
    }

    fn plan(&self, points: &Points, frame: &LidarFrame<'_>, plan: &mut Plan) {
        let inbox = InBox::new(points, frame.boxes);
        let mut removed = vec![false; points.len()];
        let rng = Rng::for_frame(self.seed, frame.seq, 0xD1);
        for b in 0..inbox.boxes() {
            let m = inbox.members(b);
            let k = (self.fraction * m.len() as f64) as usize;
            for j in rng.fork(b as u64).sample_indices(m.len(), k) {
                removed[m[j as usize] as usize] = true;
            }
        }
        write_plan(points, &removed, &[], plan);
    }
}

/// L-D2 local_cutout: fraction of each box's points cut away around one seed, 3D-Corruptions-AD
/// levels 1..5 (`cutout_bbox`); severities 1, 2, 3 use levels 1, 3, 5.
pub const LOCAL_CUTOUT_FRACTION: [f64; 5] = [0.3, 0.4, 0.5, 0.6, 0.7];

/// L-D2 local_cutout: in every box, one of its points is picked at random and its `int(c n)`
/// nearest points of the box (itself included; x, y, z distance) are deleted: a part of the object
/// is missing, as if occluded. Partial selection, O(n) per box.
pub struct LocalCutout {
    seed: u64,
    fraction: f64,
}

/// Registry constructor of L-D2.
pub const LOCAL_CUTOUT: LidarBuilder = |s| {
    Ok(Box::new(LocalCutout {
        seed: s.seed,
        fraction: LOCAL_CUTOUT_FRACTION[s.level_of_five()],
    }))
};

/// The `k` points of `members` nearest to `seed` (ties by index), by partial selection.
pub(crate) fn nearest_k(points: &Points, members: &[u32], seed: [f32; 3], k: usize) -> Vec<u32> {
    let k = k.min(members.len());
    if k == 0 {
        return Vec::new();
    }
    let mut d: Vec<(f32, u32)> = members
        .iter()
        .map(|&i| {
            let p = points.xyz(i as usize);
            let d = (p[0] - seed[0]).powi(2) + (p[1] - seed[1]).powi(2) + (p[2] - seed[2]).powi(2);
            (if d.is_nan() { f32::INFINITY } else { d }, i)
        })
        .collect();
    d.select_nth_unstable_by(k - 1, |a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
    d[..k].iter().map(|v| v.1).collect()
}

impl LidarPerturbation for LocalCutout {
    fn needs(&self) -> Needs {
        BOXES
    }

    fn plan(&self, points: &Points, frame: &LidarFrame<'_>, plan: &mut Plan) {
        let inbox = InBox::new(points, frame.boxes);
        let mut removed = vec![false; points.len()];
        let rng = Rng::for_frame(self.seed, frame.seq, 0xD2);
        for b in 0..inbox.boxes() {
            let m = inbox.members(b);
            if m.is_empty() {
                continue;
            }
            let mut r = rng.fork(b as u64);
            let seed = points.xyz(m[r.below(m.len() as u64) as usize] as usize);
            let k = (self.fraction * m.len() as f64) as usize;
            for i in nearest_k(points, m, seed, k) {
                removed[i as usize] = true;
            }
        }
        write_plan(points, &removed, &[], plan);
    }
}

/// L-D3 local_gaussian_noise: standard deviation in metres, 3D-Corruptions-AD levels 1..5
/// (`gaussian_noise_bbox`, the same constants as L-C1); severities 1, 2, 3 use levels 1, 3, 5.
pub const LOCAL_GAUSSIAN_SIGMA_M: [f64; 5] = [0.02, 0.04, 0.06, 0.08, 0.10];

/// L-D4 local_uniform_noise: half-width in metres, 3D-Corruptions-AD levels 1..5
/// (`uniform_noise_bbox`, as L-C2); severities 1, 2, 3 use levels 1, 3, 5.
pub const LOCAL_UNIFORM_HALF_WIDTH_M: [f64; 5] = [0.02, 0.04, 0.06, 0.08, 0.10];

/// L-D5 local_impulse_noise: divisor d of the number of points hit in each box (`n / d`),
/// 3D-Corruptions-AD levels 1..5 (`impulse_noise_bbox`, as L-C3); severities 1, 2, 3 use levels
/// 1, 3, 5.
pub const LOCAL_IMPULSE_DIVISOR: [usize; 5] = [30, 25, 20, 15, 10];

/// Which jitter a [`LocalNoise`] adds.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum LocalNoiseKind {
    /// N(0, sigma^2) on x, y and z of every point of a box (L-D3).
    Gaussian(f64),
    /// U(-c, c) on x, y and z of every point of a box (L-D4).
    Uniform(f64),
    /// `n / d` points of a box (without replacement) move by exactly ±0.1 m on x, y and z,
    /// independent signs (L-D5).
    Impulse(usize),
}

/// L-D3 / L-D4 / L-D5: the global noises of the L-C family on the points inside boxes only; every
/// point outside a box is byte-identical in the output. x, y, z only (the reference also jitters
/// the other columns).
pub struct LocalNoise {
    seed: u64,
    salt: u64,
    kind: LocalNoiseKind,
}

/// Registry constructor of L-D3.
pub const LOCAL_GAUSSIAN: LidarBuilder = |s| {
    Ok(Box::new(LocalNoise {
        seed: s.seed,
        salt: 0xD3,
        kind: LocalNoiseKind::Gaussian(LOCAL_GAUSSIAN_SIGMA_M[s.level_of_five()]),
    }))
};

/// Registry constructor of L-D4.
pub const LOCAL_UNIFORM: LidarBuilder = |s| {
    Ok(Box::new(LocalNoise {
        seed: s.seed,
        salt: 0xD4,
        kind: LocalNoiseKind::Uniform(LOCAL_UNIFORM_HALF_WIDTH_M[s.level_of_five()]),
    }))
};

/// Registry constructor of L-D5.
pub const LOCAL_IMPULSE: LidarBuilder = |s| {
    Ok(Box::new(LocalNoise {
        seed: s.seed,
        salt: 0xD5,
        kind: LocalNoiseKind::Impulse(LOCAL_IMPULSE_DIVISOR[s.level_of_five()]),
    }))
};

impl LidarPerturbation for LocalNoise {
    fn needs(&self) -> Needs {
        BOXES
    }

    fn plan(&self, points: &Points, frame: &LidarFrame<'_>, plan: &mut Plan) {
        let inbox = InBox::new(points, frame.boxes);
        let mut moved: Vec<Option<[f32; 3]>> = vec![None; points.len()];
        let rng = Rng::for_frame(self.seed, frame.seq, self.salt);
        for b in 0..inbox.boxes() {
            let m = inbox.members(b);
            let mut r = rng.fork(b as u64);
            let mut jitter = |i: u32, d: [f64; 3]| {
                let p = points.xyz(i as usize);
                moved[i as usize] =
                    Some([p[0] + d[0] as f32, p[1] + d[1] as f32, p[2] + d[2] as f32]);
            };
            match self.kind {
                LocalNoiseKind::Gaussian(s) => {
                    for &i in m {
                        let d = [r.normal() * s, r.normal() * s, r.normal() * s];
                        jitter(i, d);
                    }
                }
                LocalNoiseKind::Uniform(c) => {
                    for &i in m {
                        let d = [r.uniform(-c, c), r.uniform(-c, c), r.uniform(-c, c)];
                        jitter(i, d);
                    }
                }
                LocalNoiseKind::Impulse(div) => {
                    for j in r.sample_indices(m.len(), m.len() / div) {
                        let bits = r.next_u32();
                        let s = |k: u32| if bits >> k & 1 == 1 { 0.1 } else { -0.1 };
                        jitter(m[j as usize], [s(0), s(1), s(2)]);
                    }
                }
            }
        }
        write_plan(points, &[], &moved, plan);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn in_box_assignment_matches_brute_force() {
        let mut rng = Rng::for_setup(1, 2);
        let mut p = Points::default();
        for _ in 0..5000 {
            p.x.push(rng.uniform(-30.0, 30.0) as f32);
            p.y.push(rng.uniform(-30.0, 30.0) as f32);
            p.z.push(rng.uniform(-2.0, 1.0) as f32);
        }
        p.x.push(f32::NAN);
        p.y.push(0.0);
        p.z.push(0.0);
        let boxes: Vec<Box3> = (0..40)
            .map(|_| Box3 {
                center: [
                    rng.uniform(-30.0, 30.0) as f32,
                    rng.uniform(-30.0, 30.0) as f32,
                    rng.uniform(-1.5, 0.0) as f32,
                ],
                size: [
                    rng.uniform(0.5, 8.0) as f32,
                    rng.uniform(0.5, 3.0) as f32,
                    rng.uniform(0.5, 3.0) as f32,
                ],
                yaw: rng.uniform(-3.2, 3.2) as f32,
            })
            .collect();
        let inbox = InBox::new(&p, &boxes);
        for i in 0..p.len() {
            let want = boxes
                .iter()
                .position(|b| b.contains(p.xyz(i)))
                .map_or(NO_BOX, |b| b as u32);
            assert_eq!(inbox.box_of[i], want, "point {i}");
        }
        let total: usize = (0..inbox.boxes()).map(|b| inbox.members(b).len()).sum();
        assert_eq!(total, inbox.box_of.iter().filter(|b| **b != NO_BOX).count());
        assert!(total > 100);
        // No boxes, or boxes with NaN: nothing inside.
        assert_eq!(InBox::new(&p, &[]).total(), 0);
        let nan = Box3 {
            center: [f32::NAN; 3],
            size: [1.0; 3],
            yaw: 0.0,
        };
        assert_eq!(InBox::new(&p, &[nan]).total(), 0);
    }
}
