//! Clustering of the points above the ground: voxel downsampling and DBSCAN on a uniform grid.
//!
//! 1. **Voxel downsampling** of the object points: one point per occupied voxel of
//!    [`DetectorConfig::voxel_size`], at the centroid of its points (PCL `VoxelGrid`).
//! 2. **DBSCAN** on the voxel centroids (`eps`, `min_samples`, the point itself counted, distance
//!    `<= eps`, as scikit-learn), with a uniform grid index of cell size `eps` over x, y, so the
//!    search is O(N) for the few thousand to few tens of thousands of centroids of a scan.
//!
//! The result is, per cluster, the raw points of its voxels (counting sort), so the boxes are
//! fitted on the points themselves rather than on the centroids.

use super::DetectorConfig;
use super::beams::BeamGaps;
use crate::lidar::Points;

/// Voxels and clusters of one cloud; the arrays are kept between clouds.
#[derive(Clone, Debug, Default)]
pub(crate) struct Clusterer {
    /// (voxel key << 32 | point index) of the object points, sorted.
    voxel_keys: Vec<u64>,
    radix_tmp: Vec<u64>,
    centroids: Vec<[f32; 3]>,
    /// Per centroid, the factor its z is scaled by for the neighbour search (see
    /// [`BeamGaps::vertical_reach`]): 1, or less where beams are far apart.
    zscale: Vec<f32>,
    /// First sorted entry of each voxel (len = voxels + 1).
    voxel_start: Vec<u32>,
    /// DBSCAN grid.
    dcols: usize,
    drows: usize,
    dcell: f32,
    dorigin: [f32; 2],
    col_start: Vec<u32>,
    col_items: Vec<u32>,
    col_of: Vec<u32>,
    /// Centroids in column order (z zeroed for 2-D clustering).
    sorted: Vec<[f32; 3]>,
    /// Per column, positions in `sorted` ordered by z, and their z.
    zorder: Vec<u32>,
    zval: Vec<f32>,
    /// `sorted[zorder[k]]` for every k: the neighbour scan reads the coordinates in the order
    /// it visits them.
    zpts: Vec<[f32; 3]>,
    lists: NeighbourLists,
    label: Vec<i32>,
    queue: Vec<u32>,
    /// Cluster label per voxel (-1: noise).
    voxel_label: Vec<i32>,
    /// Centroids per cluster.
    pub voxels: Vec<u32>,
    /// Raw points per cluster: `members[members_start[k]..members_start[k + 1]]`.
    pub members_start: Vec<u32>,
    pub members: Vec<u32>,
}

impl Clusterer {
    /// A clusterer for `config`'s region of interest and neighbourhood radius `eps`.
    pub fn new(config: &DetectorConfig, eps: f32) -> Self {
        let mut c = Clusterer::default();
        c.size_grid(
            [config.min_x, config.min_y],
            [config.max_x, config.max_y],
            eps,
        );
        c
    }

    fn size_grid(&mut self, lo: [f32; 2], hi: [f32; 2], eps: f32) {
        let span_x = (hi[0] - lo[0]).max(0.0);
        let span_y = (hi[1] - lo[1]).max(0.0);
        // Columns of at least eps (larger if the grid would exceed 4M columns).
        let mut dcell = eps;
        while (span_x / dcell).ceil() * (span_y / dcell).ceil() > 4.0e6 {
            dcell *= 2.0;
        }
        self.dcols = ((span_x / dcell).ceil() as usize).max(1);
        self.drows = ((span_y / dcell).ceil() as usize).max(1);
        self.dcell = dcell;
        self.dorigin = lo;
    }

    /// Clusters the points `idx` of `points` (voxels of `voxel_size`, then DBSCAN with `eps`,
    /// `min_samples`): afterwards [`Clusterer::members`] lists each cluster's raw points. With
    /// `gaps`, two centroids are neighbours within `eps` horizontally and within the vertical
    /// reach of the sensor's beam spacing at their range ([`BeamGaps::vertical_reach`]): their z
    /// is scaled by `eps / reach` for the search.
    pub fn run(
        &mut self,
        points: &Points,
        idx: impl Iterator<Item = u32>,
        c: &DetectorConfig,
        (voxel_size, eps): (f32, f32),
        gaps: Option<&BeamGaps>,
    ) {
        self.downsample(points, idx, c, voxel_size);
        self.zscale.clear();
        match gaps {
            Some(g) if !c.cluster_2d && eps > 0.0 => self.zscale.extend(
                self.centroids
                    .iter()
                    .map(|&p| eps / g.vertical_reach(p, eps)),
            ),
            _ => self.zscale.resize(self.centroids.len(), 1.0),
        }
        self.dbscan(c, eps);
        self.collect_members();
    }

    /// Step 1: voxel centroids of the points `idx`.
    fn downsample(
        &mut self,
        points: &Points,
        idx: impl Iterator<Item = u32>,
        c: &DetectorConfig,
        v: f32,
    ) {
        self.voxel_keys.clear();
        self.centroids.clear();
        self.voxel_start.clear();
        // The vertical extent of object points: the heights are at most max_height above a
        // ground that lies within the region; 64 m covers any real scene (keys are clamped).
        let span = [c.max_x - c.min_x, c.max_y - c.min_y, 64.0].map(|s| s.max(0.0) as f64);
        let (inv, nvy, nvz) = if v.is_finite() && v > 0.0 {
            // Voxel keys must fit in 32 bits: a voxel so small that the region holds more than
            // 2^32 of them is enlarged (never the case for the reference sizes).
            let mut v = v as f64;
            while span
                .iter()
                .map(|s| (s / v).ceil().max(1.0))
                .product::<f64>()
                >= 4.0e9
            {
                v *= 1.25;
            }
            let nvy = ((span[1] / v).ceil() as u64).max(1);
            let nvz = ((span[2] / v).ceil() as u64).max(1);
            (1.0 / v as f32, nvy, nvz)
        } else {
            (0.0, 1, 1)
        };
        let z0 = -32.0f32;
        for i in idx {
            let i = i as usize;
            let key = if inv > 0.0 {
                let vx = (((points.x[i] - c.min_x) * inv).max(0.0)) as u64;
                let vy = ((((points.y[i] - c.min_y) * inv).max(0.0)) as u64).min(nvy - 1);
                let vz = ((((points.z[i] - z0) * inv).max(0.0)) as u64).min(nvz - 1);
                (vx * nvy + vy) * nvz + vz
            } else {
                i as u64 // no downsampling: every point is its own voxel
            };
            self.voxel_keys.push((key << 32) | i as u64);
        }
        radix_sort_high(&mut self.voxel_keys, &mut self.radix_tmp);
        let keys = &self.voxel_keys;
        let mut k = 0;
        while k < keys.len() {
            let key = keys[k] >> 32;
            let start = k;
            let mut s = [0f64; 3];
            while k < keys.len() && keys[k] >> 32 == key {
                let i = (keys[k] & 0xffff_ffff) as usize;
                s[0] += points.x[i] as f64;
                s[1] += points.y[i] as f64;
                s[2] += points.z[i] as f64;
                k += 1;
            }
            let m = (k - start) as f64;
            self.voxel_start.push(start as u32);
            self.centroids
                .push([(s[0] / m) as f32, (s[1] / m) as f32, (s[2] / m) as f32]);
        }
        self.voxel_start.push(keys.len() as u32);
    }

    /// Step 2: DBSCAN over the centroids with a column grid of cell >= eps.
    fn dbscan(&mut self, c: &DetectorConfig, eps: f32) {
        let (cols, rows) = self.sort_into_columns(c, eps);
        let zw = if c.cluster_2d { 0.0 } else { 1.0 };
        self.order_by_height(cols * rows, zw);
        let search = Neighbours {
            sorted: &self.sorted,
            col_start: &self.col_start,
            zorder: &self.zorder,
            zval: &self.zval,
            zpts: &self.zpts,
            cols,
            rows,
            eps2: eps * eps,
            zwin: eps * 1.001 + 1e-4,
        };
        let min_samples = c.min_samples.max(1) as u32;
        search.find_neighbours(min_samples, &mut self.lists);
        Neighbours::grow_clusters(&self.lists, &mut self.label, &mut self.queue);
        // Back to voxel order.
        self.voxel_label.clear();
        self.voxel_label.resize(self.centroids.len(), -1);
        for (s, &v) in self.col_items.iter().enumerate() {
            self.voxel_label[v as usize] = self.label[s];
        }
    }

    /// Sorts the centroids into the columns of the region's grid (cell >= eps), restricted to the
    /// sub-grid of the cells they occupy (same cells, same column order): a split of one cluster
    /// costs in proportion to that cluster, not to the whole region of interest. Fills `col_of`,
    /// `col_start` and `col_items` (a counting sort); returns the sub-grid's (columns, rows).
    fn sort_into_columns(&mut self, c: &DetectorConfig, eps: f32) -> (usize, usize) {
        if self.dcell < eps || self.dcell > 2.0 * eps {
            self.size_grid([c.min_x, c.min_y], [c.max_x, c.max_y], eps);
        }
        let m = self.centroids.len();
        let (gcols, grows, inv) = (self.dcols, self.drows, 1.0 / self.dcell);
        let o = self.dorigin;
        let cell = |p: &[f32; 3]| {
            (
                (((p[0] - o[0]) * inv).max(0.0) as usize).min(gcols - 1),
                (((p[1] - o[1]) * inv).max(0.0) as usize).min(grows - 1),
            )
        };
        let (mut x0, mut x1, mut y0, mut y1) = (usize::MAX, 0, usize::MAX, 0);
        for p in &self.centroids {
            let (cx, cy) = cell(p);
            (x0, x1, y0, y1) = (x0.min(cx), x1.max(cx), y0.min(cy), y1.max(cy));
        }
        if m == 0 {
            (x0, x1, y0, y1) = (0, 0, 0, 0);
        }
        let (cols, rows) = (x1 - x0 + 1, y1 - y0 + 1);
        self.col_of.clear();
        self.col_of.extend(self.centroids.iter().map(|p| {
            let (cx, cy) = cell(p);
            ((cx - x0) * rows + (cy - y0)) as u32
        }));
        self.col_start.clear();
        self.col_start.resize(cols * rows + 1, 0);
        for &col in &self.col_of {
            self.col_start[col as usize + 1] += 1;
        }
        for k in 1..self.col_start.len() {
            self.col_start[k] += self.col_start[k - 1];
        }
        self.col_items.clear();
        self.col_items.resize(m, 0);
        for (i, &col) in self.col_of.iter().enumerate() {
            let slot = &mut self.col_start[col as usize];
            self.col_items[*slot as usize] = i as u32;
            *slot += 1;
        }
        // Each start now points at the next column's start: shift back by one.
        for k in (1..self.col_start.len()).rev() {
            self.col_start[k] = self.col_start[k - 1];
        }
        self.col_start[0] = 0;
        (cols, rows)
    }

    /// The centroids in column order (`sorted`, z scaled by `zw` and the centroid's `zscale`), so that every neighbour scan
    /// reads contiguous memory; and per column, the positions of its centroids ordered by height
    /// (`zorder`, `zval`), so that a neighbour query reads only the slice of each column within
    /// eps in z (the columns span the whole height of the scene). Only the search uses the height
    /// order: the seeds are visited in column order, so the clusters and their labels do not
    /// depend on it.
    fn order_by_height(&mut self, columns: usize, zw: f32) {
        self.sorted.clear();
        self.sorted.extend(self.col_items.iter().map(|&v| {
            let p = self.centroids[v as usize];
            [p[0], p[1], p[2] * zw * self.zscale[v as usize]]
        }));
        self.zorder.clear();
        self.zorder.extend(0..self.sorted.len() as u32);
        for col in 0..columns {
            let (a, b) = (
                self.col_start[col] as usize,
                self.col_start[col + 1] as usize,
            );
            if b - a > 1 {
                let sorted = &self.sorted;
                self.zorder[a..b].sort_unstable_by(|&i, &j| {
                    sorted[i as usize][2]
                        .total_cmp(&sorted[j as usize][2])
                        .then(i.cmp(&j))
                });
            }
        }
        self.zpts.clear();
        self.zpts
            .extend(self.zorder.iter().map(|&i| self.sorted[i as usize]));
        self.zval.clear();
        self.zval.extend(self.zpts.iter().map(|p| p[2]));
    }

    /// Voxel counts and raw point lists per cluster (counting sort).
    fn collect_members(&mut self) {
        let clusters = self.voxel_label.iter().copied().max().map_or(0, |l| l + 1) as usize;
        self.voxels.clear();
        self.voxels.resize(clusters, 0);
        self.members_start.clear();
        self.members_start.resize(clusters + 1, 0);
        for (v, &l) in self.voxel_label.iter().enumerate() {
            if l >= 0 {
                self.voxels[l as usize] += 1;
                let n = self.voxel_start[v + 1] - self.voxel_start[v];
                self.members_start[l as usize + 1] += n;
            }
        }
        for k in 1..=clusters {
            self.members_start[k] += self.members_start[k - 1];
        }
        self.members.clear();
        self.members
            .resize(self.members_start[clusters] as usize, 0);
        let mut cursor: Vec<u32> = self.members_start[..clusters].to_vec();
        for (v, &l) in self.voxel_label.iter().enumerate() {
            if l < 0 {
                continue;
            }
            let (a, b) = (
                self.voxel_start[v] as usize,
                self.voxel_start[v + 1] as usize,
            );
            for &key in &self.voxel_keys[a..b] {
                let slot = &mut cursor[l as usize];
                self.members[*slot as usize] = (key & 0xffff_ffff) as u32;
                *slot += 1;
            }
        }
    }

    /// Number of clusters of the last run.
    pub fn len(&self) -> usize {
        self.voxels.len()
    }

    /// The raw points of cluster `k`.
    pub fn cluster(&self, k: usize) -> &[u32] {
        &self.members[self.members_start[k] as usize..self.members_start[k + 1] as usize]
    }
}

/// Sorts `keys` by their upper 32 bits, stably (LSD radix, 11-bit digits, only as many passes as
/// the largest key needs); the lower 32 bits ride along.
pub(crate) fn radix_sort_high(keys: &mut Vec<u64>, tmp: &mut Vec<u64>) {
    let max = keys.iter().map(|k| k >> 32).max().unwrap_or(0);
    let bits = 64 - max.leading_zeros();
    tmp.clear();
    tmp.resize(keys.len(), 0);
    let mut shift = 32;
    while shift < 32 + bits {
        let mut count = [0u32; 2049];
        for &k in keys.iter() {
            count[((k >> shift) & 2047) as usize + 1] += 1;
        }
        for d in 1..2049 {
            count[d] += count[d - 1];
        }
        for &k in keys.iter() {
            let d = ((k >> shift) & 2047) as usize;
            tmp[count[d] as usize] = k;
            count[d] += 1;
        }
        std::mem::swap(keys, tmp);
        shift += 11;
    }
}

/// The neighbour search of DBSCAN over centroids sorted into grid columns (see
/// [`Clusterer::sort_into_columns`] and [`Clusterer::order_by_height`]).
struct Neighbours<'a> {
    sorted: &'a [[f32; 3]],
    col_start: &'a [u32],
    zorder: &'a [u32],
    zval: &'a [f32],
    zpts: &'a [[f32; 3]],
    cols: usize,
    rows: usize,
    eps2: f32,
    /// Half the height window read per column: a little wider than eps, so the distance test
    /// decides, with the same rounding as a scan of the whole column.
    zwin: f32,
}

impl Neighbours<'_> {
    /// The neighbour lists of every centroid: the positions `t` within eps of the centroid at
    /// position `s` (itself included), in `nb[nb_start[pos_of[s]]..nb_start[pos_of[s] + 1]]`,
    /// and the core flags (at least `min_samples` neighbours). The centroids are visited column
    /// by column in height order, so both ends of each neighbouring column's height window
    /// only move up (no search per query); the window, and the distance test, are those of a
    /// scan of the whole column.
    fn find_neighbours(&self, min_samples: u32, lists: &mut NeighbourLists) {
        let NeighbourLists {
            core,
            nb_start,
            nb,
            pos_of,
        } = lists;
        let m = self.sorted.len();
        core.clear();
        core.resize(m, false);
        pos_of.clear();
        pos_of.resize(m, 0);
        nb_start.clear();
        nb_start.reserve(m + 1);
        nb.clear();
        let (cols, rows) = (self.cols, self.rows);
        // Per neighbouring column: its height window [lo, end) for the current centroid, and
        // the column's end.
        let mut near: Vec<(usize, usize, usize)> = Vec::with_capacity(9);
        for col in 0..cols * rows {
            let (a, b) = (
                self.col_start[col] as usize,
                self.col_start[col + 1] as usize,
            );
            if a == b {
                continue;
            }
            let (cx, cy) = (col / rows, col % rows);
            near.clear();
            for nx in cx.saturating_sub(1)..=(cx + 1).min(cols - 1) {
                for ny in cy.saturating_sub(1)..=(cy + 1).min(rows - 1) {
                    let c = nx * rows + ny;
                    let (lo, hi) = (self.col_start[c] as usize, self.col_start[c + 1] as usize);
                    if lo < hi {
                        near.push((lo, lo, hi));
                    }
                }
            }
            for k in a..b {
                let p = &self.zpts[k];
                let s = self.zorder[k] as usize;
                pos_of[s] = nb_start.len() as u32;
                nb_start.push(nb.len() as u32);
                let (below, above) = (p[2] - self.zwin, p[2] + self.zwin);
                for (lo, end, hi) in near.iter_mut() {
                    // Both ends only move up: the heights are ascending in the column and in
                    // the window's centre.
                    while *lo < *hi && self.zval[*lo] < below {
                        *lo += 1;
                    }
                    *end = (*end).max(*lo);
                    while *end < *hi && self.zval[*end] <= above {
                        *end += 1;
                    }
                    let window = self.zpts[*lo..*end].iter().zip(&self.zorder[*lo..*end]);
                    for (q, &t) in window {
                        let (dx, dy, dz) = (q[0] - p[0], q[1] - p[1], q[2] - p[2]);
                        if dx * dx + dy * dy + dz * dz <= self.eps2 {
                            nb.push(t);
                        }
                    }
                }
                core[s] = (nb.len() as u32 - nb_start[nb_start.len() - 1]) >= min_samples;
            }
        }
        nb_start.push(nb.len() as u32);
    }

    /// Clusters: connected core points plus the border points they reach (the first one), labelled
    /// 0, 1, ... in seed order; -1 is noise. A cluster is every point reachable from its seed
    /// through core points, less what an earlier cluster took: the labels do not depend on the
    /// order in which the neighbours are listed.
    fn grow_clusters(lists: &NeighbourLists, label: &mut Vec<i32>, queue: &mut Vec<u32>) {
        let core = &lists.core;
        let m = core.len();
        label.clear();
        label.resize(m, -1);
        let mut next = 0i32;
        for seed in 0..m {
            if !core[seed] || label[seed] >= 0 {
                continue;
            }
            label[seed] = next;
            queue.clear();
            queue.push(seed as u32);
            while let Some(s) = queue.pop() {
                for &t in lists.of(s as usize) {
                    let t = t as usize;
                    if label[t] < 0 {
                        label[t] = next;
                        if core[t] {
                            queue.push(t as u32);
                        }
                    }
                }
            }
            next += 1;
        }
    }
}

/// The neighbour lists of the centroids and their core flags (see
/// [`Neighbours::find_neighbours`]); kept between clouds.
#[derive(Clone, Debug, Default)]
struct NeighbourLists {
    /// Core flag per position in `sorted`.
    core: Vec<bool>,
    /// Start of each visited centroid's list in `nb` (len = centroids + 1).
    nb_start: Vec<u32>,
    /// The lists: positions in `sorted`.
    nb: Vec<u32>,
    /// Per position in `sorted`, its index into `nb_start`.
    pos_of: Vec<u32>,
}

impl NeighbourLists {
    /// The neighbours of the centroid at position `s` in `sorted` (itself included).
    fn of(&self, s: usize) -> &[u32] {
        let k = self.pos_of[s] as usize;
        &self.nb[self.nb_start[k] as usize..self.nb_start[k + 1] as usize]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn radix_sort_is_a_stable_sort_by_the_high_word() {
        let mut rng = crate::rng::Rng::for_setup(1, 1);
        for hi in [1u64, 3000, 1 << 31] {
            let mut keys: Vec<u64> = (0..5000u64).map(|i| (rng.below(hi) << 32) | i).collect();
            let mut want = keys.clone();
            want.sort();
            radix_sort_high(&mut keys, &mut Vec::new());
            assert_eq!(keys, want);
        }
    }

    /// DBSCAN by the definition, over every pair: core points have at least `min` points
    /// within eps (the same distance formula), clusters grow from the seeds in order.
    fn dbscan_by_pairs(pts: &[[f32; 3]], eps: f32, min: u32) -> Vec<i32> {
        let eps2 = eps * eps;
        let near = |s: usize, t: usize| {
            let (p, q) = (&pts[s], &pts[t]);
            let (dx, dy, dz) = (q[0] - p[0], q[1] - p[1], q[2] - p[2]);
            dx * dx + dy * dy + dz * dz <= eps2
        };
        let n = pts.len();
        let core: Vec<bool> = (0..n)
            .map(|s| (0..n).filter(|&t| near(s, t)).count() as u32 >= min)
            .collect();
        let mut label = vec![-1i32; n];
        let mut next = 0;
        for seed in 0..n {
            if !core[seed] || label[seed] >= 0 {
                continue;
            }
            label[seed] = next;
            let mut queue = vec![seed];
            while let Some(s) = queue.pop() {
                for t in 0..n {
                    if near(s, t) && label[t] < 0 {
                        label[t] = next;
                        if core[t] {
                            queue.push(t);
                        }
                    }
                }
            }
            next += 1;
        }
        label
    }

    /// The grid search with neighbour lists labels exactly like the definition: points spread
    /// over a few metres with many at the same height (scanlines), clumps, lone points and
    /// distances at eps itself, in 3-D and in 2-D, with and without voxels.
    #[test]
    fn dbscan_labels_equal_the_pairwise_definition() {
        let mut rng = crate::rng::Rng::for_setup(7, 35);
        let (mut noise, mut several) = (false, false);
        for case in 0..12 {
            let mut p = Points::default();
            let n = 300 + 100 * case;
            for i in 0..n {
                let (x, y, z) = match i % 4 {
                    // On a 0.25 m lattice: many pairs exactly 0.5 m apart.
                    0 => (
                        rng.below(16) as f32 * 0.25,
                        rng.below(16) as f32 * 0.25,
                        rng.below(4) as f32 * 0.25 - 1.0,
                    ),
                    // A few shared heights.
                    1 => (
                        rng.uniform(0.0, 4.0) as f32,
                        rng.uniform(-1.0, 3.0) as f32,
                        [-0.0f32, 0.0, 0.5, -1.25][rng.below(4) as usize],
                    ),
                    _ => (
                        rng.uniform(-1.0, 5.0) as f32,
                        rng.uniform(-1.0, 5.0) as f32,
                        rng.uniform(-2.0, 1.0) as f32,
                    ),
                };
                p.x.push(x + 10.0);
                p.y.push(y);
                p.z.push(z);
            }
            let config = DetectorConfig {
                cluster_2d: case % 3 == 2,
                min_samples: 2 + case % 4,
                ..DetectorConfig::default()
            };
            let eps = [0.5f32, 0.35, 0.7][case % 3];
            let voxel = if case % 2 == 0 { 0.0 } else { 0.25 };
            let mut cl = Clusterer::new(&config, eps);
            cl.run(&p, 0..p.len() as u32, &config, (voxel, eps), None);
            let want = dbscan_by_pairs(&cl.sorted, eps, config.min_samples as u32);
            assert_eq!(cl.label, want, "case {case}");
            noise |= want.contains(&-1);
            several |= want.iter().any(|&l| l >= 1);
        }
        assert!(
            noise && several,
            "the cases have noise and several clusters"
        );
    }

    #[test]
    fn dbscan_separates_blobs_and_drops_noise() {
        let mut p = Points::default();
        let mut push = |q: [f32; 3]| {
            p.x.push(q[0]);
            p.y.push(q[1]);
            p.z.push(q[2]);
        };
        // Two blobs 3 m apart and two isolated points.
        for (cx, cy) in [(10.0f32, 0.0f32), (10.0, 3.0)] {
            for i in 0..5 {
                for j in 0..5 {
                    for k in 0..4 {
                        push([
                            cx + i as f32 * 0.25,
                            cy + j as f32 * 0.25,
                            -1.0 + k as f32 * 0.25,
                        ]);
                    }
                }
            }
        }
        push([20.0, 10.0, -1.0]);
        push([25.0, -10.0, -0.5]);
        let c = DetectorConfig::default();
        let mut cl = Clusterer::new(&c, c.eps);
        cl.run(&p, 0..p.len() as u32, &c, (c.voxel_size, c.eps), None);
        assert_eq!(cl.len(), 2);
        assert_eq!(cl.cluster(0).len(), 100);
        assert_eq!(cl.cluster(1).len(), 100);
        // A smaller eps on the same points: the voxel centroids (0.25 m apart) stay connected.
        cl.run(&p, 0..p.len() as u32, &c, (c.voxel_size, 0.3), None);
        assert_eq!(cl.len(), 2);
    }
}
