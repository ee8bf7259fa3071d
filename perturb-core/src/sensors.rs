//! LiDAR sensor models: beams, elevation table, range, beam divergence and intensity scale.
//!
//! The physics-based weather models take their beam divergence, beam count and range from here,
//! ring indices are derived from the elevation table when a cloud has no ring field, and the
//! intensity scale (0..1 or 0..255) is stated here instead of guessed from the data.
//!
//! ```
//! use perturb_core::sensors::SensorModel;
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
    fn ring_of_elevation_picks_nearest() {
        let m = SensorModel::vlp16();
        assert_eq!(m.ring_of_elevation((-14.2f32).to_radians()), 0);
        assert_eq!(m.ring_of_elevation((-13.8f32).to_radians()), 1);
        assert_eq!(m.ring_of_elevation(0.9f32.to_radians()), 8);
        assert_eq!(m.ring_of_elevation(80f32.to_radians()), 15);
    }
}
