//! Sensor family (L-B): points lost or filtered by the sensor itself.

use super::{LidarBuilder, LidarFrame, LidarPerturbation, Plan, Points};
use crate::math::Portable;
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
            if points.y[i].patan2(points.x[i]).abs() <= self.half_angle {
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

/// L-B3 beam_reduction: one ring in `step` is kept, severities 1..3. MultiCorrupt
/// (`reduce_LiDAR_beamsV2`, on nuScenes' 32-beam HDL-32E) keeps 16, 8 and 4 rings: {1, 3, .., 31},
/// {1, 5, .., 29} and {1, 9, 17, 25}, which is `ring % step == 1` with step 2, 4, 8.
pub const BEAM_STEP: [u16; 3] = [2, 4, 8];

/// L-B3 beam_reduction: a sensor with fewer beams. Keeps exactly the points whose ring `r`
/// satisfies `r % step == 1` (step 2, 4, 8), every other field untouched. Deterministic.
///
/// How MultiCorrupt's 32-beam lists map to the sensor models (rings numbered by elevation from
/// the lowest beam, 0, as the ROS Velodyne driver numbers them):
/// - 32 beams (VLP-32C, HDL-32E): exactly MultiCorrupt's lists, 16 / 8 / 4 rings. The VLP-32C's
///   beams are not evenly spaced (dense around the horizon), so the kept rows are every second /
///   fourth / eighth row in elevation order, not evenly spaced angles.
/// - 64 beams (HDL-64E, KITTI): the same fraction of the beams, 32 / 16 / 8 rings ({1, 3, .., 63},
///   {1, 5, .., 61}, {1, 9, .., 57}), i.e. a sensor with a half, a quarter, an eighth of the beams;
///   keeping MultiCorrupt's absolute counts (16 / 8 / 4 of 64) would be a far stronger corruption.
/// - 16 beams (VLP-16): 8 / 4 / 2 rings.
///
/// Rings come from the cloud's ring field, or, when the cloud has none (KITTI), are derived from
/// each point's elevation with the sensor model's elevation table (nearest beam); derived rings
/// are as good as the table (the HDL-64E table is the nominal one, so a point between two
/// beams can be given its neighbour's ring).
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
/// remaining points (itself included), N the original count: occluded patches. Exactly `k m`
/// points go (fewer only if fewer remain).
///
/// The nearest points are found exactly (ties broken by index) with a uniform x, y grid: rings of
/// cells around the seed are gathered until the m-th nearest candidate is closer than the ring
/// radius, so only the points around each hole are visited, not the whole cloud per hole.
/// Seeds are drawn uniformly among the remaining points with a finite position; points without
/// one (NaN) are never nearer than a finite point and go last.
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

/// Finite points of a cloud bucketed into a uniform x, y grid (counting sort).
struct XyGrid {
    lo: [f32; 2],
    inv: f32,
    cell: f32,
    nx: usize,
    ny: usize,
    start: Vec<u32>,
    items: Vec<u32>,
}

impl XyGrid {
    fn new(points: &Points) -> Self {
        let finite = |i: usize| {
            points.x[i].is_finite() && points.y[i].is_finite() && points.z[i].is_finite()
        };
        let mut lo = [f32::INFINITY; 2];
        let mut hi = [f32::NEG_INFINITY; 2];
        for i in (0..points.len()).filter(|&i| finite(i)) {
            lo = [lo[0].min(points.x[i]), lo[1].min(points.y[i])];
            hi = [hi[0].max(points.x[i]), hi[1].max(points.y[i])];
        }
        if lo[0] > hi[0] {
            lo = [0.0; 2];
            hi = [0.0; 2];
        }
        // 1 m cells, at most 512 x 512 of them.
        let ext = (hi[0] - lo[0]).max(hi[1] - lo[1]);
        let cell = (ext / 512.0).max(1.0);
        let inv = 1.0 / cell;
        let nx = ((hi[0] - lo[0]) * inv) as usize + 1;
        let ny = ((hi[1] - lo[1]) * inv) as usize + 1;
        let mut g = XyGrid {
            lo,
            inv,
            cell,
            nx,
            ny,
            start: vec![0; nx * ny + 1],
            items: Vec::new(),
        };
        let cells: Vec<u32> = (0..points.len())
            .map(|i| {
                if finite(i) {
                    let (cx, cy) = g.cell_of(points.x[i], points.y[i]);
                    (cx * ny + cy) as u32
                } else {
                    u32::MAX
                }
            })
            .collect();
        for &c in cells.iter().filter(|c| **c != u32::MAX) {
            g.start[c as usize + 1] += 1;
        }
        for k in 1..g.start.len() {
            g.start[k] += g.start[k - 1];
        }
        let mut cursor = g.start.clone();
        g.items = vec![0; g.start[nx * ny] as usize];
        for (i, &c) in cells.iter().enumerate() {
            if c != u32::MAX {
                g.items[cursor[c as usize] as usize] = i as u32;
                cursor[c as usize] += 1;
            }
        }
        g
    }

    fn cell_of(&self, x: f32, y: f32) -> (usize, usize) {
        (
            (((x - self.lo[0]) * self.inv).max(0.0) as usize).min(self.nx - 1),
            (((y - self.lo[1]) * self.inv).max(0.0) as usize).min(self.ny - 1),
        )
    }

    fn cell(&self, cx: usize, cy: usize) -> &[u32] {
        let c = cx * self.ny + cy;
        &self.items[self.start[c] as usize..self.start[c + 1] as usize]
    }

    /// Adds the remaining points of the cells at Chebyshev ring `r` around (cx, cy) to `cand`.
    fn add_ring(&self, (cx, cy): (usize, usize), r: usize, mut add: impl FnMut(u32)) {
        let (x0, x1) = (cx as isize - r as isize, cx as isize + r as isize);
        let (y0, y1) = (cy as isize - r as isize, cy as isize + r as isize);
        let inx = |x: isize| x >= 0 && (x as usize) < self.nx;
        let iny = |y: isize| y >= 0 && (y as usize) < self.ny;
        for x in x0..=x1 {
            if !inx(x) {
                continue;
            }
            let edge_x = x == x0 || x == x1;
            let mut y = y0;
            while y <= y1 {
                if iny(y) {
                    self.cell(x as usize, y as usize)
                        .iter()
                        .for_each(|&i| add(i));
                }
                // Interior columns only touch the ring's top and bottom cells.
                y = if edge_x || y == y1 { y + 1 } else { y1 };
            }
        }
    }
}

impl LidarPerturbation for Cutout {
    fn plan(&self, points: &Points, frame: &LidarFrame<'_>, plan: &mut Plan) {
        let n = points.len();
        let m = (0.02 * n as f64) as usize;
        let mut removed = vec![false; n];
        if m > 0 && self.holes > 0 {
            let grid = XyGrid::new(points);
            let finite = &grid.items; // every finite point, in grid order
            let mut finite_left = finite.len();
            let nan: Vec<u32> = (0..n as u32)
                .filter(|&i| {
                    !points.x[i as usize].is_finite()
                        || !points.y[i as usize].is_finite()
                        || !points.z[i as usize].is_finite()
                })
                .collect();
            let mut nan_next = 0;
            let mut rng = Rng::for_frame(self.seed, frame.seq, 0xB4);
            let mut cand: Vec<(f32, u32)> = Vec::new();
            let max_ring = grid.nx.max(grid.ny);
            for _ in 0..self.holes {
                if finite_left == 0 {
                    break;
                }
                // A uniformly drawn remaining finite point (rejection: at most 20 % are gone).
                let s = loop {
                    let i = finite[rng.below(finite.len() as u64) as usize] as usize;
                    if !removed[i] {
                        break points.xyz(i);
                    }
                };
                let home = grid.cell_of(s[0], s[1]);
                cand.clear();
                let dist = |i: u32| {
                    let p = points.xyz(i as usize);
                    (p[0] - s[0]).powi(2) + (p[1] - s[1]).powi(2) + (p[2] - s[2]).powi(2)
                };
                let mut ring = 0;
                let mut need = 0; // ring up to which candidates must be gathered
                loop {
                    while ring <= need.min(max_ring) {
                        grid.add_ring(home, ring, |i| {
                            if !removed[i as usize] {
                                cand.push((dist(i), i));
                            }
                        });
                        ring += 1;
                    }
                    if ring > max_ring {
                        break; // every cell gathered
                    }
                    if cand.len() < m {
                        need = ring;
                        continue;
                    }
                    // Every point within (ring - 1) cells of the seed's cell is gathered.
                    let covered = (ring - 1) as f32 * grid.cell;
                    let (_, kth, _) = cand.select_nth_unstable_by(m - 1, |a, b| {
                        a.0.total_cmp(&b.0).then(a.1.cmp(&b.1))
                    });
                    let r = kth.0.sqrt();
                    if r <= covered {
                        break;
                    }
                    need = (r / grid.cell).ceil() as usize + 1;
                }
                let take = m.min(cand.len());
                if take > 0 && take < cand.len() {
                    cand.select_nth_unstable_by(take - 1, |a, b| {
                        a.0.total_cmp(&b.0).then(a.1.cmp(&b.1))
                    });
                }
                for &(_, i) in &cand[..take] {
                    removed[i as usize] = true;
                }
                finite_left -= take;
                // Points without a position are the farthest of all.
                for _ in take..m {
                    if nan_next < nan.len() {
                        removed[nan[nan_next] as usize] = true;
                        nan_next += 1;
                    }
                }
            }
        }
        for (i, r) in removed.iter().enumerate() {
            if !r {
                plan.keep(i);
            }
        }
    }
}

/// L-B5 crosstalk: fraction of the points hit, 3D-Corruptions-AD levels 1..5
/// (`lidar_crosstalk_noise`); severities 1, 2, 3 use levels 1, 3, 5.
pub const CROSSTALK_FRACTION: [f64; 5] = [0.004, 0.008, 0.012, 0.016, 0.020];

/// L-B5 crosstalk: `floor(c N)` points chosen without replacement get N(0, (3 m)^2) added to x, y
/// and z: the far-off false returns another LiDAR's pulses cause.
///
/// Deviation: the reference adds the noise to every column of its array (intensity and ring too);
/// here to x, y, z only, and the other fields pass through unchanged.
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

#[cfg(test)]
mod tests {
    use super::*;

    /// The reference's selection: the m nearest remaining points of each seed, by brute force.
    fn brute(points: &Points, seeds: &[[f32; 3]], m: usize) -> Vec<bool> {
        let mut removed = vec![false; points.len()];
        for s in seeds {
            let mut d: Vec<(f32, u32)> = (0..points.len())
                .filter(|&i| !removed[i])
                .map(|i| {
                    let p = points.xyz(i);
                    let d = (p[0] - s[0]).powi(2) + (p[1] - s[1]).powi(2) + (p[2] - s[2]).powi(2);
                    (if d.is_nan() { f32::INFINITY } else { d }, i as u32)
                })
                .collect();
            d.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
            for v in d.iter().take(m) {
                removed[v.1 as usize] = true;
            }
        }
        removed
    }

    #[test]
    fn cutout_grid_search_equals_brute_force() {
        let mut rng = Rng::for_setup(3, 4);
        let mut p = Points::default();
        // Dense near the origin, sparse far away, a few NaN.
        for i in 0..6000 {
            let r = if i % 3 == 0 {
                rng.uniform(30.0, 90.0)
            } else {
                rng.uniform(2.0, 15.0)
            };
            let a = rng.uniform(0.0, std::f64::consts::TAU);
            p.x.push((r * a.pcos()) as f32);
            p.y.push((r * a.psin()) as f32);
            p.z.push(rng.uniform(-2.0, 1.0) as f32);
        }
        p.x[17] = f32::NAN;
        p.z[99] = f32::NAN;
        for seq in 0..6 {
            let cut = Cutout { seed: 9, holes: 10 };
            let mut plan = Plan::default();
            cut.plan(&p, &LidarFrame { seq, boxes: &[] }, &mut plan);
            let kept: std::collections::HashSet<u32> = plan.src.iter().copied().collect();
            assert_eq!(plan.len(), 6000 - 10 * 120);
            // Rebuild the seeds the same way and compare with brute force.
            let grid = XyGrid::new(&p);
            let mut rng = Rng::for_frame(9, seq, 0xB4);
            let mut removed = vec![false; p.len()];
            let mut seeds = Vec::new();
            for _ in 0..10 {
                let s = loop {
                    let i = grid.items[rng.below(grid.items.len() as u64) as usize] as usize;
                    if !removed[i] {
                        break p.xyz(i);
                    }
                };
                seeds.push(s);
                removed = brute(&p, &seeds, 120);
            }
            for (i, r) in removed.iter().enumerate() {
                assert_eq!(!kept.contains(&(i as u32)), *r, "seq {seq} point {i}");
            }
        }
    }
}
