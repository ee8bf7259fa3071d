//! LiDAR sensor models: beams, elevation table, range, beam divergence and intensity scale.
//!
//! The physics-based weather models take their beam divergence, beam count and range from here,
//! ring indices are derived from the elevation table when a cloud has no ring field, and the
//! intensity scale (0..1 or 0..255) is stated here instead of guessed from the data.
//!
//! A model also says how the sensor's frame is oriented ([`Axes`]): which of its axes points
//! forward and which up. ROS (REP 103), KITTI and Velodyne drivers use x forward, z up, the
//! default; nuScenes' `LIDAR_TOP` uses y forward (x to the right). Every direction-dependent
//! perturbation and the detector work in the canonical frame (x forward, y left, z up):
//! [`crate::lidar::Points`] reads a cloud into it and the output is written back into the
//! sensor's own frame, so a cloud's axes never change, whatever the convention.
//!
//! ```
//! use perturb_core::sensor_model::SensorModel;
//! let vlp = SensorModel::vlp32c();
//! assert_eq!(vlp.beams(), 32);
//! assert_eq!(vlp.ring_of_elevation(-25.0f32.to_radians()), 0);
//! assert_eq!(vlp.ring_of_elevation(15.0f32.to_radians()), 31);
//! ```

use crate::error::{Error, Result};

/// VLP-32C elevations in degrees, ring 0 (lowest) to 31 (VeloView calibration).
pub const VLP32C_ELEVATIONS: [f32; 32] = [
    -25.0, -15.639, -11.31, -8.843, -7.254, -6.148, -5.333, -4.667, -4.0, -3.667, -3.333, -3.0,
    -2.667, -2.333, -2.0, -1.667, -1.333, -1.0, -0.667, -0.333, 0.0, 0.333, 0.667, 1.0, 1.333,
    1.667, 2.333, 3.333, 4.667, 7.0, 10.333, 15.0,
];

/// One axis of a sensor frame with its direction: `+x`, `-y`, ...
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Axis {
    /// +x
    PosX,
    /// -x
    NegX,
    /// +y
    PosY,
    /// -y
    NegY,
    /// +z
    PosZ,
    /// -z
    NegZ,
}

impl Axis {
    /// Index of the coordinate (0 = x, 1 = y, 2 = z) and its sign.
    pub fn index_sign(self) -> (usize, f32) {
        match self {
            Axis::PosX => (0, 1.0),
            Axis::NegX => (0, -1.0),
            Axis::PosY => (1, 1.0),
            Axis::NegY => (1, -1.0),
            Axis::PosZ => (2, 1.0),
            Axis::NegZ => (2, -1.0),
        }
    }

    /// The unit vector.
    pub fn vector(self) -> [i8; 3] {
        let (k, s) = self.index_sign();
        let mut v = [0; 3];
        v[k] = s as i8;
        v
    }

    fn from_vector(v: [i8; 3]) -> Self {
        match v {
            [1, 0, 0] => Axis::PosX,
            [-1, 0, 0] => Axis::NegX,
            [0, 1, 0] => Axis::PosY,
            [0, -1, 0] => Axis::NegY,
            [0, 0, 1] => Axis::PosZ,
            _ => Axis::NegZ,
        }
    }

    /// Parses `+x`, `x`, `-y`, ... (case-insensitive).
    pub fn parse(s: &str) -> Result<Self> {
        let t = s.trim().to_ascii_lowercase();
        Ok(match t.as_str() {
            "+x" | "x" => Axis::PosX,
            "-x" => Axis::NegX,
            "+y" | "y" => Axis::PosY,
            "-y" => Axis::NegY,
            "+z" | "z" => Axis::PosZ,
            "-z" => Axis::NegZ,
            _ => {
                return Err(Error::InvalidConfig {
                    reason: format!("`{s}` is not an axis (one of +x -x +y -y +z -z)"),
                });
            }
        })
    }
}

impl std::fmt::Display for Axis {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let (k, s) = self.index_sign();
        write!(
            f,
            "{}{}",
            if s > 0.0 { '+' } else { '-' },
            ['x', 'y', 'z'][k]
        )
    }
}

/// How a sensor's frame is oriented on the vehicle: the axis that points forward (`+x`, `-x`,
/// `+y` or `-y`) and the one that points up (`+z`, or `-z` for a sensor mounted upside down).
///
/// The canonical frame is x forward, y left, z up (ROS REP 103). [`Axes::to_canonical`] and
/// [`Axes::to_sensor`] only permute coordinates and flip signs, so they are exact: a point read
/// into the canonical frame and written back has the same bytes.
///
/// ```
/// use perturb_core::sensor_model::{Axes, Axis};
/// let nuscenes = Axes::new(Axis::PosY, Axis::PosZ).unwrap(); // LIDAR_TOP: x right, y forward
/// assert_eq!(nuscenes.to_canonical([1.0, 10.0, -1.5]), [10.0, -1.0, -1.5]); // 10 m ahead, 1 m right
/// assert_eq!(nuscenes.to_sensor([10.0, -1.0, -1.5]), [1.0, 10.0, -1.5]);
/// ```
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct Axes {
    /// The sensor axis that points forward.
    pub forward: Axis,
    /// The sensor axis that points up.
    pub up: Axis,
    /// Canonical axes (forward, left, up) as sensor axes.
    rows: [Axis; 3],
}

impl Default for Axes {
    fn default() -> Self {
        Axes::new(Axis::PosX, Axis::PosZ).expect("orthogonal")
    }
}

impl Axes {
    /// The convention with `forward` (`+x`, `-x`, `+y` or `-y`) and `up` (`+z` or `-z`); other
    /// combinations are refused (boxes turn about the sensor's z axis).
    pub fn new(forward: Axis, up: Axis) -> Result<Self> {
        if forward.index_sign().0 == 2 {
            return Err(Error::InvalidConfig {
                reason: format!("forward axis {forward}: must be +x, -x, +y or -y"),
            });
        }
        if up.index_sign().0 != 2 {
            return Err(Error::InvalidConfig {
                reason: format!("up axis {up}: must be +z or -z"),
            });
        }
        let (f, u) = (forward.vector(), up.vector());
        // left = up x forward
        let left = [
            u[1] * f[2] - u[2] * f[1],
            u[2] * f[0] - u[0] * f[2],
            u[0] * f[1] - u[1] * f[0],
        ];
        Ok(Axes {
            forward,
            up,
            rows: [forward, Axis::from_vector(left), up],
        })
    }

    /// Parses the forward and up axes (`"+y"`, `"+z"`).
    pub fn parse(forward: &str, up: &str) -> Result<Self> {
        Axes::new(Axis::parse(forward)?, Axis::parse(up)?)
    }

    /// True for the canonical convention (x forward, z up), where nothing is converted.
    pub fn is_canonical(&self) -> bool {
        self.forward == Axis::PosX && self.up == Axis::PosZ
    }

    /// A sensor-frame point in the canonical frame (x forward, y left, z up).
    #[inline]
    pub fn to_canonical(&self, p: [f32; 3]) -> [f32; 3] {
        self.rows.map(|a| {
            let (k, s) = a.index_sign();
            if s > 0.0 { p[k] } else { -p[k] }
        })
    }

    /// A canonical-frame point in the sensor frame (the inverse of [`Axes::to_canonical`]).
    #[inline]
    pub fn to_sensor(&self, q: [f32; 3]) -> [f32; 3] {
        let mut p = [0f32; 3];
        for (r, a) in self.rows.iter().enumerate() {
            let (k, s) = a.index_sign();
            p[k] = if s > 0.0 { q[r] } else { -q[r] };
        }
        p
    }

    /// A heading (about the up axis, radians, in the canonical frame) as a heading about the
    /// sensor's +z axis.
    pub fn yaw_to_sensor(&self, yaw: f32) -> f32 {
        let (s, c) = crate::math::sincosf(yaw);
        let d = self.to_sensor([c, s, 0.0]);
        crate::math::atan2f(d[1], d[0])
    }

    /// A heading about the sensor's +z axis as a heading in the canonical frame.
    pub fn yaw_to_canonical(&self, yaw: f32) -> f32 {
        let (s, c) = crate::math::sincosf(yaw);
        let d = self.to_canonical([c, s, 0.0]);
        crate::math::atan2f(d[1], d[0])
    }
}

impl std::fmt::Display for Axes {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "forward {}, up {}", self.forward, self.up)
    }
}

/// A LiDAR model.
#[derive(Clone, Debug, PartialEq)]
pub struct SensorModel {
    /// Model name (`VLP-32C`).
    pub name: &'static str,
    /// Beam elevations in degrees, ascending: index = ring.
    pub elevations_deg: Vec<f32>,
    /// Maximum range in metres.
    pub max_range: f32,
    /// Full-angle beam divergence in radians.
    pub beam_divergence: f32,
    /// Full-scale intensity: 255 for Velodyne drivers, 1 for KITTI's reflectance.
    pub intensity_max: f32,
    /// Horizontal angular resolution in degrees at the nominal rotation rate.
    pub azimuth_resolution_deg: f32,
    /// Height of the sensor above the ground in metres, for ground-plane fallbacks.
    pub mount_height: f32,
    /// Which sensor axes point forward and up (default x forward, z up).
    pub axes: Axes,
}

impl SensorModel {
    /// Velodyne VLP-32C (Ultra Puck), the default: 32 beams, -25..+15 deg, 200 m, 0..255 intensity.
    pub fn vlp32c() -> Self {
        SensorModel {
            name: "VLP-32C",
            elevations_deg: VLP32C_ELEVATIONS.to_vec(),
            max_range: 200.0,
            beam_divergence: 3e-3,
            intensity_max: 255.0,
            azimuth_resolution_deg: 0.2,
            mount_height: 1.9,
            axes: Axes::default(),
        }
    }

    /// Velodyne VLP-16 (Puck): 16 beams, -15..+15 deg in 2 deg steps, 100 m, 0..255 intensity.
    pub fn vlp16() -> Self {
        SensorModel {
            name: "VLP-16",
            elevations_deg: (0..16).map(|i| -15.0 + 2.0 * i as f32).collect(),
            max_range: 100.0,
            beam_divergence: 3e-3,
            intensity_max: 255.0,
            azimuth_resolution_deg: 0.2,
            mount_height: 1.9,
            axes: Axes::default(),
        }
    }

    /// Velodyne HDL-32E: 32 beams, -30.67..+10.67 deg in 4/3 deg steps, 100 m, 0..255 intensity.
    pub fn hdl32e() -> Self {
        SensorModel {
            name: "HDL-32E",
            elevations_deg: (0..32).map(|i| -30.67 + i as f32 * (4.0 / 3.0)).collect(),
            max_range: 100.0,
            beam_divergence: 2.79e-3,
            intensity_max: 255.0,
            azimuth_resolution_deg: 0.16,
            mount_height: 1.9,
            axes: Axes::default(),
        }
    }

    /// Velodyne HDL-64E (KITTI): 64 beams, +2..-24.33 deg (upper block in 1/3 deg, lower in 1/2
    /// deg steps), 120 m, intensity as KITTI stores it (reflectance 0..1).
    pub fn hdl64e() -> Self {
        let mut e: Vec<f32> = (0..32).map(|i| 2.0 - i as f32 / 3.0).collect();
        e.extend((0..32).map(|i| -8.83 - i as f32 * 0.5));
        e.sort_by(f32::total_cmp);
        SensorModel {
            name: "HDL-64E",
            elevations_deg: e,
            max_range: 120.0,
            beam_divergence: 3e-3,
            intensity_max: 1.0,
            azimuth_resolution_deg: 0.08,
            mount_height: 1.73,
            axes: Axes::default(),
        }
    }

    /// The models by name (case-insensitive, dash optional): vlp32c, vlp16, hdl32e, hdl64e.
    pub fn by_name(name: &str) -> Result<Self> {
        let key: String = name
            .chars()
            .filter(|c| c.is_ascii_alphanumeric())
            .collect::<String>()
            .to_ascii_lowercase();
        Ok(match key.as_str() {
            "vlp32c" | "vlp32" | "ultrapuck" => Self::vlp32c(),
            "vlp16" | "puck" => Self::vlp16(),
            "hdl32e" | "hdl32" => Self::hdl32e(),
            "hdl64e" | "hdl64" | "kitti" => Self::hdl64e(),
            _ => {
                return Err(Error::InvalidConfig {
                    reason: format!(
                        "unknown sensor model `{name}` (known: VLP-32C, VLP-16, HDL-32E, HDL-64E)"
                    ),
                });
            }
        })
    }

    /// nuScenes' `LIDAR_TOP`: an HDL-32E whose frame has y forward, x to the right, z up (the
    /// convention of nuScenes `.pcd.bin` files).
    pub fn nuscenes() -> Self {
        Self::hdl32e().with_axes(Axes::new(Axis::PosY, Axis::PosZ).expect("orthogonal"))
    }

    /// The same model with another frame convention.
    pub fn with_axes(mut self, axes: Axes) -> Self {
        self.axes = axes;
        self
    }

    /// One line saying which model and convention: `HDL-32E, forward +y, up +z, intensity 0..255`.
    pub fn describe(&self) -> String {
        format!(
            "{}, {}, intensity 0..{}",
            self.name, self.axes, self.intensity_max
        )
    }

    /// The same model with another intensity full scale (1 or 255).
    pub fn with_intensity_max(mut self, max: f32) -> Self {
        self.intensity_max = max;
        self
    }

    /// Number of beams.
    pub fn beams(&self) -> usize {
        self.elevations_deg.len()
    }

    /// The ring whose elevation is nearest to `elevation` (radians).
    pub fn ring_of_elevation(&self, elevation: f32) -> u16 {
        let deg = elevation.to_degrees();
        let e = &self.elevations_deg;
        let i = e.partition_point(|&v| v < deg);
        if i == 0 {
            return 0;
        }
        if i >= e.len() {
            return (e.len() - 1) as u16;
        }
        if (deg - e[i - 1]).abs() <= (e[i] - deg).abs() {
            (i - 1) as u16
        } else {
            i as u16
        }
    }
}

impl Default for SensorModel {
    fn default() -> Self {
        Self::vlp32c()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tables_are_ascending_and_sized() {
        for m in [
            SensorModel::vlp32c(),
            SensorModel::vlp16(),
            SensorModel::hdl32e(),
            SensorModel::hdl64e(),
        ] {
            assert!(
                m.elevations_deg.windows(2).all(|w| w[0] < w[1]),
                "{}",
                m.name
            );
            assert_eq!(SensorModel::by_name(m.name).unwrap(), m);
        }
        assert_eq!(SensorModel::hdl64e().beams(), 64);
        assert_eq!(SensorModel::vlp16().elevations_deg[15], 15.0);
        assert!(SensorModel::by_name("os1").is_err());
    }

    #[test]
    fn axes_are_exact_rotations_with_their_inverse() {
        let p = [1.5f32, -2.25, 0.75];
        for f in [Axis::PosX, Axis::NegX, Axis::PosY, Axis::NegY] {
            for u in [Axis::PosZ, Axis::NegZ] {
                let a = Axes::new(f, u).unwrap();
                let q = a.to_canonical(p);
                assert_eq!(a.to_sensor(q), p, "{a}");
                // The forward axis maps to canonical +x, up to +z.
                let fv = f.vector().map(|v| v as f32);
                assert_eq!(a.to_canonical(fv), [1.0, 0.0, 0.0], "{a}");
                let uv = u.vector().map(|v| v as f32);
                assert_eq!(a.to_canonical(uv), [0.0, 0.0, 1.0], "{a}");
                // Proper rotation: the canonical frame is right-handed (x cross y = z).
                let x = a.to_sensor([1.0, 0.0, 0.0]);
                let y = a.to_sensor([0.0, 1.0, 0.0]);
                let z = a.to_sensor([0.0, 0.0, 1.0]);
                let cross = [
                    x[1] * y[2] - x[2] * y[1],
                    x[2] * y[0] - x[0] * y[2],
                    x[0] * y[1] - x[1] * y[0],
                ];
                assert_eq!(cross, z, "{a}");
                for yaw in [-3.0f32, -1.0, 0.0, 0.4, 2.0] {
                    let back = a.yaw_to_canonical(a.yaw_to_sensor(yaw));
                    let d = (back - yaw).rem_euclid(std::f32::consts::TAU);
                    assert!(d.min(std::f32::consts::TAU - d) < 1e-5, "{a} {yaw}");
                }
            }
        }
        assert!(Axes::new(Axis::PosZ, Axis::PosZ).is_err());
        assert!(Axes::new(Axis::PosX, Axis::PosY).is_err());
        assert!(Axis::parse("fwd").is_err());
        assert_eq!(
            Axes::parse("-y", "z").unwrap().to_string(),
            "forward -y, up +z"
        );
        assert!(Axes::default().is_canonical());
        // nuScenes: 10 m along +y is 10 m ahead; +x is the right-hand side.
        let n = SensorModel::nuscenes();
        assert_eq!(n.axes.to_canonical([0.0, 10.0, 0.0]), [10.0, 0.0, 0.0]);
        assert_eq!(n.axes.to_canonical([3.0, 0.0, 0.0]), [0.0, -3.0, 0.0]);
        assert_eq!(n.name, "HDL-32E");
    }

    #[test]
    fn ring_of_elevation_picks_nearest() {
        let m = SensorModel::vlp16();
        assert_eq!(m.ring_of_elevation((-14.2f32).to_radians()), 0);
        assert_eq!(m.ring_of_elevation((-13.8f32).to_radians()), 1);
        assert_eq!(m.ring_of_elevation(0.9f32.to_radians()), 8);
        assert_eq!(m.ring_of_elevation(80f32.to_radians()), 15);
    }
}
