//! Terrain-following ground estimation: per-cell lowest points, isolated pits removed, and a
//! slope-limited lower envelope that carries the ground under objects and across empty cells.
//!
//! 1. Every point inside the region of interest (and outside the ego box) falls into a cell of a
//!    regular x, y grid; each cell keeps its lowest z.
//!    A cell with three points or more takes its second-lowest, so that one stray return below
//!    the road (a reflection, a multipath return) does not set its ground.
//! 2. **Pits**: a cell more than [`DetectorConfig::pit_depth`] below the median of the occupied
//!    cells within 3 cells around it (groups of below-ground returns, a ditch next to the road)
//!    seeds nothing: its ground comes from the cells around it, and its own points, below that,
//!    count as ground.
//! 3. **Envelope**: the ground height of a cell is the lowest, over every seeding cell n, of
//!    `min(n) + max_slope * distance`, computed exactly on the grid's chamfer distance (two
//!    passes, 8 neighbours, diagonal steps weighted by sqrt 2). Terrain rising or falling at less
//!    than `max_slope` keeps its own lowest points; a cell holding only the side of a car or a
//!    wall gets the ground of its neighbours plus at most `max_slope` per metre; cells without
//!    points inherit the estimate too.
//! 4. Each point's height above the ground of its cell: ground if at most
//!    [`DetectorConfig::tolerance`], an object point up to [`DetectorConfig::max_height`], above
//!    that ignored (tree canopies, building fronts above the street).
//!
//! Unlike a fixed height window (Autoware Mini crops z to [-2.5, 0.1) m around the sensor), the
//! envelope follows roads that climb or fall and keeps the objects on them.

use super::DetectorConfig;
use crate::lidar::Points;

/// Not in the region of interest.
pub(crate) const OUT: u32 = u32::MAX;

/// Pits are judged against the cells within this many cells (a 7 x 7 window).
const PIT_WINDOW: usize = 3;

/// The ground grid and the per-point heights; its arrays are kept between clouds.
#[derive(Clone, Debug, Default)]
pub(crate) struct Ground {
    /// Grid size (cells along x, along y).
    pub gx: usize,
    pub gy: usize,
    /// Cell of each point, or [`OUT`].
    pub cell_of: Vec<u32>,
    /// Lowest z per cell (+inf when empty); the second lowest where the cell has three points
    /// or more (one stray return below the road does not set its ground).
    pub cell_min: Vec<f32>,
    /// Second-lowest z and point count per cell.
    cell_second: Vec<f32>,
    cell_count: Vec<u32>,
    /// Ground height per cell (+inf when nothing reaches it).
    pub level: Vec<f32>,
    /// Height of each point above its cell's ground (NaN outside the region).
    pub height: Vec<f32>,
}

impl Ground {
    /// A grid covering `config`'s region of interest.
    pub fn new(config: &DetectorConfig) -> Self {
        let span_x = (config.max_x - config.min_x).max(0.0);
        let span_y = (config.max_y - config.min_y).max(0.0);
        let gx = ((span_x / config.cell_size).ceil() as usize).max(1);
        let gy = ((span_y / config.cell_size).ceil() as usize).max(1);
        Ground {
            gx,
            gy,
            cell_min: vec![f32::INFINITY; gx * gy],
            cell_second: vec![f32::INFINITY; gx * gy],
            cell_count: vec![0; gx * gy],
            level: vec![f32::INFINITY; gx * gy],
            ..Ground::default()
        }
    }

    /// Estimates the ground of `points` and every point's height above it.
    pub fn segment(&mut self, points: &Points, c: &DetectorConfig) {
        let n = points.len();
        let inv = 1.0 / c.cell_size;
        let (gx, gy) = (self.gx, self.gy);
        self.cell_of.clear();
        self.cell_of.resize(n, OUT);
        self.cell_min.fill(f32::INFINITY);
        self.cell_second.fill(f32::INFINITY);
        self.cell_count.fill(0);
        for i in 0..n {
            let (x, y, z) = (points.x[i], points.y[i], points.z[i]);
            let inside =
                x >= c.min_x && x < c.max_x && y >= c.min_y && y < c.max_y && z.is_finite();
            if !inside {
                continue;
            }
            if let Some([lo, hi]) = c.ego_box
                && x >= lo[0]
                && x <= hi[0]
                && y >= lo[1]
                && y <= hi[1]
                && z >= lo[2]
                && z <= hi[2]
            {
                continue;
            }
            let ix = (((x - c.min_x) * inv) as usize).min(gx - 1);
            let iy = (((y - c.min_y) * inv) as usize).min(gy - 1);
            let cell = ix * gy + iy;
            self.cell_of[i] = cell as u32;
            self.cell_count[cell] += 1;
            let (m, m2) = (self.cell_min[cell], self.cell_second[cell]);
            if z < m {
                self.cell_min[cell] = z;
                self.cell_second[cell] = m;
            } else if z < m2 {
                self.cell_second[cell] = z;
            }
        }
        for ((m, &m2), &k) in self
            .cell_min
            .iter_mut()
            .zip(&self.cell_second)
            .zip(&self.cell_count)
        {
            if k >= 3 {
                *m = m2;
            }
        }
        self.remove_pits(c);
        self.envelope(c);
        self.height.clear();
        self.height.extend((0..n).map(|i| {
            let cell = self.cell_of[i];
            if cell == OUT {
                f32::NAN
            } else {
                points.z[i] - self.level[cell as usize]
            }
        }));
    }

    /// Step 2: `level` = each cell's value where it is a plausible ground height (+inf where
    /// not: empty cells and pits).
    fn remove_pits(&mut self, c: &DetectorConfig) {
        let (gx, gy) = (self.gx, self.gy);
        self.level.copy_from_slice(&self.cell_min);
        if !(c.pit_depth.is_finite() && c.pit_depth > 0.0) {
            return;
        }
        const R: usize = PIT_WINDOW;
        for ix in 0..gx {
            for iy in 0..gy {
                let own = self.cell_min[ix * gy + iy];
                if own == f32::INFINITY {
                    continue;
                }
                // The cell is a pit when it is more than pit_depth below the median (the element
                // at index n / 2 in ascending order) of its occupied neighbours. `own < v -
                // pit_depth` only grows with v, so that holds exactly when it holds for at least
                // the n - n / 2 largest neighbours: counting them gives the same answer as
                // selecting the median, without the selection.
                // Every occupied cell of the window counts, the cell itself too (it is never
                // more than pit_depth below itself), which is taken off after.
                let (mut n, mut above) = (0usize, 0usize);
                let (y0, y1) = (iy.saturating_sub(R), (iy + R).min(gy - 1));
                for jx in ix.saturating_sub(R)..=(ix + R).min(gx - 1) {
                    for &v in &self.cell_min[jx * gy + y0..=jx * gy + y1] {
                        let occupied = v != f32::INFINITY;
                        n += occupied as usize;
                        above += (occupied && own < v - c.pit_depth) as usize;
                    }
                }
                n -= 1;
                if n >= 3 && above >= n - n / 2 {
                    self.level[ix * gy + iy] = f32::INFINITY;
                }
            }
        }
    }

    /// Step 3: the slope-limited lower envelope of `level`, in place (chamfer distance).
    fn envelope(&mut self, c: &DetectorConfig) {
        let (gx, gy) = (self.gx, self.gy);
        let slope = c.max_slope.max(0.0);
        let a = slope * c.cell_size;
        let b = a * std::f32::consts::SQRT_2;
        let l = &mut self.level;
        // Forward pass: neighbours already visited (previous row, and the previous cell).
        for ix in 0..gx {
            for iy in 0..gy {
                let k = ix * gy + iy;
                let mut v = l[k];
                if iy > 0 {
                    v = v.min(l[k - 1] + a);
                }
                if ix > 0 {
                    let p = k - gy;
                    v = v.min(l[p] + a);
                    if iy > 0 {
                        v = v.min(l[p - 1] + b);
                    }
                    if iy + 1 < gy {
                        v = v.min(l[p + 1] + b);
                    }
                }
                l[k] = v;
            }
        }
        // Backward pass.
        for ix in (0..gx).rev() {
            for iy in (0..gy).rev() {
                let k = ix * gy + iy;
                let mut v = l[k];
                if iy + 1 < gy {
                    v = v.min(l[k + 1] + a);
                }
                if ix + 1 < gx {
                    let q = k + gy;
                    v = v.min(l[q] + a);
                    if iy + 1 < gy {
                        v = v.min(l[q + 1] + b);
                    }
                    if iy > 0 {
                        v = v.min(l[q - 1] + b);
                    }
                }
                l[k] = v;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn pts(v: &[[f32; 3]]) -> Points {
        let mut p = Points::default();
        for q in v {
            p.x.push(q[0]);
            p.y.push(q[1]);
            p.z.push(q[2]);
        }
        p
    }

    #[test]
    fn envelope_is_the_slope_limited_minimum() {
        // Brute force over every pair of cells with the chamfer metric.
        let c = DetectorConfig {
            min_x: 0.0,
            max_x: 6.0,
            min_y: 0.0,
            max_y: 4.0,
            ego_box: None,
            pit_depth: f32::INFINITY,
            ..DetectorConfig::default()
        };
        let mut rng = crate::rng::Rng::for_setup(3, 3);
        let mut v = Vec::new();
        for _ in 0..25 {
            v.push([
                rng.uniform(0.0, 6.0) as f32,
                rng.uniform(0.0, 4.0) as f32,
                rng.uniform(-2.0, 1.0) as f32,
            ]);
        }
        let mut g = Ground::new(&c);
        g.segment(&pts(&v), &c);
        let (gx, gy) = (g.gx, g.gy);
        for ix in 0..gx {
            for iy in 0..gy {
                let mut want = f32::INFINITY;
                for jx in 0..gx {
                    for jy in 0..gy {
                        let m = g.cell_min[jx * gy + jy];
                        let (dx, dy) = (ix.abs_diff(jx) as f32, iy.abs_diff(jy) as f32);
                        let d = dx.max(dy) - dx.min(dy) + dx.min(dy) * std::f32::consts::SQRT_2;
                        want = want.min(m + c.max_slope * c.cell_size * d);
                    }
                }
                let got = g.level[ix * gy + iy];
                assert!((got - want).abs() < 1e-4, "cell {ix},{iy}: {got} vs {want}");
            }
        }
    }

    #[test]
    fn follows_a_ramp_and_keeps_a_box_on_it() {
        // A road climbing at 8 % from x = 10 m, with a 1.5 m high object standing on it at 30 m:
        // the ramp is ground all the way up, the object is not (a fixed window around the
        // sensor's height would call the ramp an object and cut the object off).
        let mut v = Vec::new();
        let road = |x: f32| -1.8 + 0.08 * (x - 10.0).max(0.0);
        for i in 0..200 {
            for j in 0..20 {
                let x = 3.5 + i as f32 * 0.25;
                v.push([x, -2.5 + j as f32 * 0.25, road(x)]);
            }
        }
        let first_object = v.len();
        for i in 0..8 {
            for k in 1..=6 {
                v.push([30.0, -1.0 + i as f32 * 0.25, road(30.0) + k as f32 * 0.25]);
            }
        }
        let c = DetectorConfig::default();
        let mut g = Ground::new(&c);
        g.segment(&pts(&v), &c);
        let ground = |i: usize| g.height[i] <= c.tolerance;
        let bad: Vec<_> = (0..first_object)
            .filter(|&i| !ground(i))
            .map(|i| (v[i], g.height[i]))
            .collect();
        assert!(bad.is_empty(), "the whole ramp is ground: {bad:?}");
        assert!(
            (first_object..v.len()).all(|i| !ground(i)),
            "the object is not"
        );
        // Its heights are measured from the ramp, not from the sensor.
        let top = (first_object..v.len())
            .map(|i| g.height[i])
            .fold(0.0, f32::max);
        assert!((top - 1.5).abs() < 0.1, "{top}");
    }

    /// The pits are those of the definition: a cell more than pit_depth below the median (by
    /// selection) of the occupied cells around it, on random grids with empty cells, ties and
    /// deep cells.
    #[test]
    fn pits_are_cells_below_the_median_of_their_neighbours() {
        let c = DetectorConfig {
            min_x: 0.0,
            max_x: 9.0,
            min_y: 0.0,
            max_y: 7.2,
            ..DetectorConfig::default()
        };
        let mut rng = crate::rng::Rng::for_setup(9, 35);
        let mut pits = 0;
        for _ in 0..40 {
            let mut g = Ground::new(&c);
            let (gx, gy) = (g.gx, g.gy);
            for v in g.cell_min.iter_mut() {
                *v = match rng.below(6) {
                    0 => f32::INFINITY,
                    1 => -1.7 - 0.5 - rng.below(3) as f32 * 0.25,
                    2 => -1.7,
                    _ => -1.7 + (rng.f32() - 0.5) * 1.2,
                };
            }
            g.remove_pits(&c);
            for ix in 0..gx {
                for iy in 0..gy {
                    let own = g.cell_min[ix * gy + iy];
                    let mut near = Vec::new();
                    for jx in ix.saturating_sub(PIT_WINDOW)..=(ix + PIT_WINDOW).min(gx - 1) {
                        for jy in iy.saturating_sub(PIT_WINDOW)..=(iy + PIT_WINDOW).min(gy - 1) {
                            let v = g.cell_min[jx * gy + jy];
                            if v != f32::INFINITY && (jx, jy) != (ix, iy) {
                                near.push(v);
                            }
                        }
                    }
                    let pit = own != f32::INFINITY && near.len() >= 3 && {
                        let mid = near.len() / 2;
                        own < *near.select_nth_unstable_by(mid, f32::total_cmp).1 - c.pit_depth
                    };
                    let want = if pit { f32::INFINITY } else { own };
                    assert_eq!(g.level[ix * gy + iy], want, "cell {ix},{iy}");
                    pits += pit as usize;
                }
            }
        }
        assert!(pits > 100, "{pits}");
    }

    #[test]
    fn a_pit_does_not_lift_the_ground_around_it() {
        let mut v = Vec::new();
        for i in 0..40 {
            for j in 0..40 {
                v.push([5.0 + i as f32 * 0.25, -5.0 + j as f32 * 0.25, -1.7]);
            }
        }
        v.push([10.0, 0.0, -4.0]); // a multipath return 2.3 m below the road
        let c = DetectorConfig::default();
        let mut g = Ground::new(&c);
        g.segment(&pts(&v), &c);
        assert!(g.height[..v.len() - 1].iter().all(|h| h.abs() < 1e-6));
    }

    #[test]
    fn outside_the_region_ego_box_and_nan_have_no_height() {
        let p = pts(&[
            [10.0, 0.0, -1.8],
            [70.0, 0.0, -1.8],
            [0.5, 0.0, -1.8],
            [f32::NAN, 0.0, -1.8],
            [10.0, 0.0, f32::NAN],
        ]);
        let c = DetectorConfig::default();
        let mut g = Ground::new(&c);
        g.segment(&p, &c);
        assert_eq!(g.height[0], 0.0);
        assert!(g.height[1..].iter().all(|h| h.is_nan()));
    }
}
