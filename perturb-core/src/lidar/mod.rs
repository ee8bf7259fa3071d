//! LiDAR perturbations: the contract, the point extraction and the output plan, and one module per
//! family.
//!
//! A LiDAR perturbation is built once for a (severity, seed, [`SensorModel`]): that is when it
//! computes its tables and particle sets. Per cloud it reads the fields it needs from a [`Points`]
//! extraction and fills a [`Plan`]: for every output point, the input point it comes from and the
//! new position and intensity where they change. [`Plan::write`] then writes the output in the
//! input's own layout, so every field the perturbation does not touch (ring, time, anything a
//! driver adds) passes through byte for byte, whatever the point_step, offsets or byte order.
//! Output is a pure function of (input, perturbation, severity, seed, sequence number).

use crate::math::Portable;
pub mod affine;
pub mod detector;
pub mod local;
pub mod motion;
pub mod noise;
pub mod points;
pub mod sensor;
pub mod weather;

pub use points::{Plan, Points};

use crate::error::Result;
use crate::sensor_model::SensorModel;

/// What a LiDAR perturbation is configured with.
#[derive(Clone, Debug, PartialEq)]
pub struct LidarSetup {
    /// Severity, 1..=3 (already validated).
    pub severity: u8,
    /// Seed of every random draw.
    pub seed: u64,
    /// The sensor the clouds come from.
    pub sensor: SensorModel,
}

impl LidarSetup {
    /// Index 0..=2 into a three-level severity table.
    pub fn level(&self) -> usize {
        (self.severity.clamp(1, 3) - 1) as usize
    }

    /// For references with five levels (3D-Corruptions-AD): severities 1, 2, 3 use levels 1, 3, 5,
    /// returned as indices 0, 2, 4.
    pub fn level_of_five(&self) -> usize {
        self.level() * 2
    }
}

/// An oriented 3-D box in the sensor frame: centre, size (length along the heading, width, height)
/// and heading (yaw about +z, radians).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Box3 {
    /// Centre [x, y, z] in metres.
    pub center: [f32; 3],
    /// [length, width, height] in metres.
    pub size: [f32; 3],
    /// Heading in radians.
    pub yaw: f32,
}

impl Box3 {
    /// True if `p` lies inside the box (the reference's `check_point_in_box`: |dz| <= h/2 and the
    /// point, rotated into the box frame, within half length and half width).
    pub fn contains(&self, p: [f32; 3]) -> bool {
        let dz = p[2] - self.center[2];
        if dz.abs() > self.size[2] * 0.5 {
            return false;
        }
        let (dx, dy) = (p[0] - self.center[0], p[1] - self.center[1]);
        let (s, c) = self.yaw.psin_cos();
        let lx = dx * c + dy * s;
        let ly = dy * c - dx * s;
        lx.abs() <= self.size[0] * 0.5 && ly.abs() <= self.size[1] * 0.5
    }

    /// This box (in the canonical frame of `axes`: x forward, z up) in the sensor's frame.
    pub fn to_sensor(&self, axes: &crate::sensor_model::Axes) -> Box3 {
        if axes.is_canonical() {
            return *self;
        }
        Box3 {
            center: axes.to_sensor(self.center),
            size: self.size,
            yaw: axes.yaw_to_sensor(self.yaw),
        }
    }

    /// This box (in the sensor's frame) in the canonical frame of `axes`.
    pub fn to_canonical(&self, axes: &crate::sensor_model::Axes) -> Box3 {
        if axes.is_canonical() {
            return *self;
        }
        Box3 {
            center: axes.to_canonical(self.center),
            size: self.size,
            yaw: axes.yaw_to_canonical(self.yaw),
        }
    }
}

/// Per-frame inputs besides the points.
#[derive(Clone, Copy, Debug)]
pub struct LidarFrame<'a> {
    /// Frame sequence number.
    pub seq: u64,
    /// Object boxes (from the detector on the unperturbed cloud, or from the caller).
    pub boxes: &'a [Box3],
}

/// What a perturbation needs beyond x, y, z.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Needs {
    /// A ring per point (derived from elevation with the sensor model if the cloud has none).
    pub ring: bool,
    /// Object boxes.
    pub boxes: bool,
}

/// A configured LiDAR perturbation.
pub trait LidarPerturbation: Send + Sync {
    /// What the perturbation needs beyond x, y, z and the intensity.
    fn needs(&self) -> Needs {
        Needs::default()
    }

    /// An upper bound of the output point count for an input of `n` points.
    fn max_output_points(&self, n: usize) -> usize {
        n
    }

    /// Fills `plan` (already cleared) with the output points for this cloud.
    fn plan(&self, points: &Points, frame: &LidarFrame<'_>, plan: &mut Plan);
}

/// A LiDAR constructor as stored in the registry.
pub type LidarBuilder = fn(&LidarSetup) -> Result<Box<dyn LidarPerturbation>>;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn box_contains_respects_heading() {
        let b = Box3 {
            center: [10.0, 0.0, 0.0],
            size: [4.0, 2.0, 1.5],
            yaw: std::f32::consts::FRAC_PI_2,
        };
        // Rotated 90 degrees: the 4 m length now runs along y.
        assert!(b.contains([10.0, 1.9, 0.0]));
        assert!(!b.contains([11.9, 0.0, 0.0]));
        assert!(!b.contains([10.0, 0.0, 0.8]));
    }
}
