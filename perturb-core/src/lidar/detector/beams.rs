//! What the detector takes from the sensor: the vertical spacing of its beams, and how smooth a
//! cluster's surface looks along its scanlines.
//!
//! **Beam spacing.** A sensor's beams leave at the elevations of its model
//! ([`SensorModel::elevations_deg`]); two neighbouring beams hit a vertical face at horizontal
//! range `r` about `r * gap` apart in height (`gap` the angle between them). On a 64-beam sensor
//! that is a few centimetres at 10 m; on a 16-beam one (2 degrees) 0.35 m at 10 m and 1.4 m at
//! 40 m, more than any fixed clustering radius. The detector therefore reads the gap at each
//! point's elevation from the sensor model and (a) lets clustering reach that far vertically
//! ([`BeamGaps::vertical_reach`]), and (b) allows a box's measured top and bottom to miss the
//! object's real ones by up to one gap at its range ([`BeamGaps::uncertainty`]).
//!
//! **Scanline roughness** ([`scanline_roughness`]): along one beam's scanline, consecutive returns
//! from a car's panels (or a wall) lie on a smooth curve, while returns from leaves scatter in
//! depth by decimetres. The roughness of a cluster is the median, over its points, of the distance
//! of a point's range from the straight line through its two azimuth neighbours on the same beam
//! (the nearest returns on either side within a few azimuth steps whose elevation is within
//! [`SAME_BEAM`]). On a smooth surface it is the sensor's range noise (about 1 cm on KITTI's
//! HDL-64E, 2-3 cm on a VLP-16); on hedges and bushes 5 to 15 cm. The beam of a point is told by
//! its elevation rather than a ring index, because a ring derived from a nominal elevation table
//! can merge two real lasers (KITTI's HDL-64E), and a ring field may be absent.

use crate::lidar::Points;
use crate::math::Portable;
use crate::sensor_model::SensorModel;

/// How far (as a multiple of the beam gap at its range) a point may reach vertically to a
/// neighbour in the clustering: consecutive beams on one face are one gap apart, and voxel
/// centroids sit on the beams; 1.5 leaves room for a horizontal offset between them.
pub const VERTICAL_REACH: f32 = 1.5;

/// Two returns belong to the same beam when their elevations differ by less than this (radians,
/// 0.1 degree): less than half the finest spacing of any supported sensor's beams (VLP-32C: 1/3
/// degree near the horizon), and far more than one beam's spread over a few azimuth steps.
pub const SAME_BEAM: f32 = 1.745e-3;

/// Azimuth neighbours are looked for within this many azimuth steps of the sensor.
pub const NEIGHBOUR_STEPS: f32 = 3.5;

/// Fewer residuals than this: the roughness is unknown (too few points to tell).
pub const MIN_RESIDUALS: usize = 6;

/// The angle between neighbouring beams of a sensor model, by elevation.
#[derive(Clone, Debug, PartialEq)]
pub struct BeamGaps {
    /// Beam elevations, radians, ascending.
    elevation: Vec<f32>,
    /// Per beam, the larger of the angles to its neighbours, radians.
    gap: Vec<f32>,
    /// The largest of `gap`.
    max_gap: f32,
    /// The azimuth step, radians.
    azimuth_step: f32,
}

impl BeamGaps {
    /// The gaps of `sensor`, or `None` for a model with fewer than two beams or an unordered or
    /// non-finite elevation table.
    pub fn new(sensor: &SensorModel) -> Option<Self> {
        let e: Vec<f32> = sensor
            .elevations_deg
            .iter()
            .map(|d| d.to_radians())
            .collect();
        if e.len() < 2 || !e.windows(2).all(|w| w[0] < w[1]) || !e.iter().all(|v| v.is_finite()) {
            return None;
        }
        let gap: Vec<f32> = (0..e.len())
            .map(|k| {
                let below = if k > 0 { e[k] - e[k - 1] } else { 0.0 };
                let above = if k + 1 < e.len() {
                    e[k + 1] - e[k]
                } else {
                    0.0
                };
                below.max(above)
            })
            .collect();
        let step = sensor.azimuth_resolution_deg.to_radians();
        let max_gap = gap.iter().copied().fold(0.0, f32::max);
        Some(BeamGaps {
            elevation: e,
            gap,
            max_gap,
            azimuth_step: if step.is_finite() && step > 0.0 {
                step
            } else {
                0.2f32.to_radians()
            },
        })
    }

    /// The gap (radians) of the beam nearest to `elevation` (radians).
    pub fn at(&self, elevation: f32) -> f32 {
        let e = &self.elevation;
        let i = e.partition_point(|&v| v < elevation);
        let k = if i == 0 {
            0
        } else if i >= e.len() {
            e.len() - 1
        } else if elevation - e[i - 1] <= e[i] - elevation {
            i - 1
        } else {
            i
        };
        self.gap[k]
    }

    /// How far apart in height neighbouring beams hit a vertical face through `p` (sensor at
    /// the origin, metres): horizontal range times the gap at `p`'s elevation.
    pub fn uncertainty(&self, p: [f32; 3]) -> f32 {
        let r = p[0].phypot(p[1]);
        if !(r.is_finite() && p[2].is_finite()) {
            return 0.0;
        }
        r * self.at(p[2].patan2(r))
    }

    /// The vertical distance within which a point at `p` has clustering neighbours: `eps`, or
    /// [`VERTICAL_REACH`] beam gaps at its range if that is more.
    pub fn vertical_reach(&self, p: [f32; 3], eps: f32) -> f32 {
        // Where even the widest gap reaches no further than eps (most points of a dense
        // sensor), the elevation need not be looked up: the same eps.
        if VERTICAL_REACH * (p[0].phypot(p[1]) * self.max_gap) <= eps {
            return eps;
        }
        (VERTICAL_REACH * self.uncertainty(p)).max(eps)
    }

    /// True if `p` lies on the sensor's highest beam (within half its gap): an object whose
    /// highest return is there may reach higher than the sensor sees.
    pub fn on_highest_beam(&self, p: [f32; 3]) -> bool {
        let r = p[0].phypot(p[1]);
        let (top, gap) = (
            self.elevation[self.elevation.len() - 1],
            self.gap[self.gap.len() - 1],
        );
        p[2].patan2(r) >= top - 0.5 * gap
    }

    /// The sensor's azimuth step, radians.
    pub fn azimuth_step(&self) -> f32 {
        self.azimuth_step
    }
}

/// Scratch of [`scanline_roughness`]: (azimuth, elevation, range) per point, and the residuals.
#[derive(Clone, Debug, Default)]
pub struct RoughScratch {
    polar: Vec<(f32, f32, f32)>,
    residuals: Vec<f32>,
}

/// The median scanline residual (metres) of the points `idx` of `points` (see the module
/// documentation), or `None` with fewer than [`MIN_RESIDUALS`] points that have a neighbour on
/// their beam on both sides. `azimuth_step` is the sensor's (radians).
pub fn scanline_roughness(
    points: &Points,
    idx: &[u32],
    azimuth_step: f32,
    sc: &mut RoughScratch,
) -> Option<f32> {
    let polar = &mut sc.polar;
    polar.clear();
    polar.extend(idx.iter().map(|&i| {
        let i = i as usize;
        let (x, y, z) = (points.x[i], points.y[i], points.z[i]);
        let h = x.phypot(y);
        (y.patan2(x), z.patan2(h), (h * h + z * z).sqrt())
    }));
    // A cluster never spans the +-pi seam in a way that matters here: one that does (behind
    // the sensor) loses the neighbours across the seam only.
    polar.sort_unstable_by(|a, b| a.0.total_cmp(&b.0).then(a.1.total_cmp(&b.1)));
    let window = NEIGHBOUR_STEPS * azimuth_step;
    let res = &mut sc.residuals;
    res.clear();
    for b in 0..polar.len() {
        let (az, el, r) = polar[b];
        let same = |q: &(f32, f32, f32)| (q.1 - el).abs() < SAME_BEAM && q.0 != az;
        let before = polar[..b]
            .iter()
            .rev()
            .take_while(|q| az - q.0 <= window)
            .find(|q| same(q));
        let after = polar[b + 1..]
            .iter()
            .take_while(|q| q.0 - az <= window)
            .find(|q| same(q));
        if let (Some(a), Some(c)) = (before, after) {
            let t = (az - a.0) / (c.0 - a.0);
            res.push((r - (a.2 + t * (c.2 - a.2))).abs());
        }
    }
    if res.len() < MIN_RESIDUALS {
        return None;
    }
    let mid = res.len() / 3;
    Some(*res.select_nth_unstable_by(mid, f32::total_cmp).1)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn gaps_follow_the_elevation_table() {
        let g = BeamGaps::new(&SensorModel::vlp16()).unwrap();
        let two = 2f32.to_radians();
        assert!((g.at(0.0) - two).abs() < 1e-6);
        assert!((g.at(-1.0) - two).abs() < 1e-6);
        // 10 m away, beams 2 degrees apart are 0.35 m apart in height.
        assert!((g.uncertainty([10.0, 0.0, 0.0]) - 0.349).abs() < 1e-3);
        assert_eq!(g.vertical_reach([1.0, 0.0, 0.0], 0.5), 0.5);
        let v = BeamGaps::new(&SensorModel::vlp32c()).unwrap();
        assert!(v.at(0.0) < 0.4f32.to_radians() && v.at(-0.44) > 4f32.to_radians());
        let mut one = SensorModel::vlp16();
        one.elevations_deg.truncate(1);
        assert!(BeamGaps::new(&one).is_none());
    }

    #[test]
    fn vertical_reach_near_the_sensor_is_the_full_formula() {
        let mut rng = crate::rng::Rng::for_setup(5, 35);
        for sensor in [
            SensorModel::hdl64e(),
            SensorModel::vlp16(),
            SensorModel::vlp32c(),
        ] {
            let g = BeamGaps::new(&sensor).unwrap();
            let mut near = 0;
            for k in 0..20_000 {
                let r = if k % 2 == 0 { 80.0 } else { 8.0 };
                let p = [
                    rng.uniform(-r, r) as f32,
                    rng.uniform(-r, r) as f32,
                    rng.uniform(-10.0, 5.0) as f32,
                ];
                for eps in [0.35f32, 0.5] {
                    let full = (VERTICAL_REACH * g.uncertainty(p)).max(eps);
                    assert_eq!(g.vertical_reach(p, eps).to_bits(), full.to_bits(), "{p:?}");
                    near += (full == eps) as usize;
                }
            }
            assert!(near > 1000, "{}: {near}", sensor.name);
        }
    }

    /// Two beams, 1/3 degree apart, scanning a face at 10 m: flat, or with depth noise.
    fn face(noise: f32) -> Points {
        let mut p = Points::default();
        let mut rng = crate::rng::Rng::for_setup(1, 2);
        for el in [-1.0f32, -1.0 + 1.0 / 3.0] {
            for k in 0..100 {
                let az = (k as f32 * 0.1 - 5.0).to_radians();
                // A flat wall at x = 10.
                let mut r = 10.0 / az.pcos() / el.to_radians().pcos();
                r += noise * (rng.f32() * 2.0 - 1.0);
                let (h, z) = (r * el.to_radians().pcos(), r * el.to_radians().psin());
                p.x.push(h * az.pcos());
                p.y.push(h * az.psin());
                p.z.push(z);
            }
        }
        p
    }

    #[test]
    fn a_flat_face_is_smooth_and_foliage_is_rough() {
        let step = 0.1f32.to_radians();
        let mut sc = RoughScratch::default();
        let flat = face(0.0);
        let all: Vec<u32> = (0..flat.len() as u32).collect();
        let r = scanline_roughness(&flat, &all, step, &mut sc).unwrap();
        assert!(r < 1e-3, "{r}");
        let leaves = face(0.3);
        let r = scanline_roughness(&leaves, &all, step, &mut sc).unwrap();
        assert!(r > 0.05, "{r}");
        assert_eq!(scanline_roughness(&flat, &all[..3], step, &mut sc), None);
    }
}
