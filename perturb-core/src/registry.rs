//! The catalogue: the single list of every perturbation that exists.
//!
//! Each [`Entry`] carries the stable ID, the name, modality, family, severity range, a one-line
//! description, the reference it follows and the constructor. Everything that lists, validates or
//! builds perturbations (the CLI, the daemon, the benches, the tests) goes through [`find`] and
//! [`CATALOGUE`].
//!
//! ```
//! use perturb_core::registry::{find, Modality};
//! let e = find("C-A1").unwrap();
//! assert_eq!(e.name, "gaussian_noise");
//! assert_eq!(e.modality, Modality::Camera);
//! assert!(e.check_severity(6).is_err());
//! assert!(find("gaussian_blur").is_ok()); // names are accepted too
//! ```

use crate::camera::{self, CameraBuilder};
use crate::error::{Error, Result};
use crate::lidar::{self, LidarBuilder};

/// Which sensor a perturbation acts on.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Modality {
    /// Images (severities 1..=5).
    Camera,
    /// Point clouds (severities 1..=3).
    Lidar,
}

impl Modality {
    /// "camera" or "lidar".
    pub fn as_str(self) -> &'static str {
        match self {
            Modality::Camera => "camera",
            Modality::Lidar => "lidar",
        }
    }

    /// The highest severity of this modality.
    pub fn max_severity(self) -> u8 {
        match self {
            Modality::Camera => 5,
            Modality::Lidar => 3,
        }
    }
}

impl std::fmt::Display for Modality {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.as_str())
    }
}

impl std::str::FromStr for Modality {
    type Err = Error;
    fn from_str(s: &str) -> Result<Self> {
        match s.to_ascii_lowercase().as_str() {
            "camera" | "image" => Ok(Modality::Camera),
            "lidar" | "cloud" | "pointcloud" => Ok(Modality::Lidar),
            other => Err(Error::InvalidConfig {
                reason: format!("unknown modality `{other}` (expected camera or lidar)"),
            }),
        }
    }
}

/// How an entry is constructed.
#[derive(Clone, Copy)]
pub enum Builder {
    /// A camera perturbation.
    Camera(CameraBuilder),
    /// A LiDAR perturbation.
    Lidar(LidarBuilder),
}

/// One perturbation of the catalogue.
#[derive(Clone, Copy)]
pub struct Entry {
    /// Stable ID (`C-A1`, `L-B6`).
    pub id: &'static str,
    /// snake_case name.
    pub name: &'static str,
    /// Camera or LiDAR.
    pub modality: Modality,
    /// Family (noise, blur, weather, ...).
    pub family: &'static str,
    /// What it simulates, in one line.
    pub description: &'static str,
    /// The reference implementation it follows.
    pub reference: &'static str,
    /// The constructor.
    pub build: Builder,
}

impl std::fmt::Debug for Entry {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Entry")
            .field("id", &self.id)
            .field("name", &self.name)
            .field("modality", &self.modality)
            .finish()
    }
}

impl Entry {
    /// The highest severity.
    pub fn max_severity(&self) -> u8 {
        self.modality.max_severity()
    }

    /// The valid severities, 1..=max.
    pub fn severities(&self) -> std::ops::RangeInclusive<u8> {
        1..=self.max_severity()
    }

    /// Fails with a clear error if `severity` is out of range.
    pub fn check_severity(&self, severity: u8) -> Result<()> {
        if self.severities().contains(&severity) {
            Ok(())
        } else {
            Err(Error::SeverityOutOfRange {
                id: self.id,
                severity,
                max: self.max_severity(),
            })
        }
    }
}

/// Finds an entry by ID (`C-A1`, case-insensitive) or by name (`gaussian_noise`; names shared by
/// both modalities resolve to the camera one, use the ID for the LiDAR one).
pub fn find(id_or_name: &str) -> Result<&'static Entry> {
    let key = id_or_name.trim();
    CATALOGUE
        .iter()
        .find(|e| e.id.eq_ignore_ascii_case(key))
        .or_else(|| CATALOGUE.iter().find(|e| e.name.eq_ignore_ascii_case(key)))
        .ok_or_else(|| Error::UnknownPerturbation {
            id: id_or_name.to_string(),
        })
}

/// Finds an entry and checks the severity in one step.
pub fn find_with_severity(id_or_name: &str, severity: u8) -> Result<&'static Entry> {
    let e = find(id_or_name)?;
    e.check_severity(severity)?;
    Ok(e)
}

/// The entries of one modality, in catalogue order.
pub fn of_modality(m: Modality) -> impl Iterator<Item = &'static Entry> {
    CATALOGUE.iter().filter(move |e| e.modality == m)
}

/// What a perturbation does to the camera model that a stream's `camera_info` describes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Calibration {
    /// Every pixel stays where it was: the forwarded calibration describes the output exactly
    /// (every LiDAR perturbation too: `camera_info` belongs to cameras).
    Kept,
    /// Pixels move by a bounded amount or part of the image is another view of the scene; the
    /// note says how far the forwarded calibration still holds.
    Approximate(&'static str),
}

/// The camera perturbations that move pixels. No camera perturbation changes the image's size,
/// its principal point or its focal length, so the bridge forwards `camera_info` unchanged.
const MOVES_PIXELS: &[(&str, &str)] = &[
    (
        "C-B2",
        "each pixel taken from a random neighbour up to 2, 5, 6, 9, 12 px away (s1-s5): the calibration holds to that error",
    ),
    (
        "C-B4",
        "an average of copies zoomed about the image centre by up to 1.0, 1.10, 1.14, 1.20, 1.30x (s1-s5): the centre holds, edges smear radially",
    ),
    (
        "C-D1",
        "each pixel displaced by a smoothed field of at most 2, 3, 5, 7, 10 px (s1-s5): the calibration holds to that error",
    ),
    (
        "C-D3",
        "a 2x enlargement of a random quarter blended in with weight 0.1-0.9 (s1-s5): that ghost image is not described by the calibration, the frame itself is",
    ),
];

impl Entry {
    /// Whether the forwarded `camera_info` still describes this perturbation's output.
    pub fn calibration(&self) -> Calibration {
        MOVES_PIXELS
            .iter()
            .find(|(id, _)| *id == self.id)
            .map_or(Calibration::Kept, |(_, note)| {
                Calibration::Approximate(note)
            })
    }
}

macro_rules! entry {
    ($id:literal, $name:literal, $m:ident, $family:literal, $build:expr, $reference:literal, $desc:literal) => {
        Entry {
            id: $id,
            name: $name,
            modality: Modality::$m,
            family: $family,
            description: $desc,
            reference: $reference,
            build: $build,
        }
    };
}

/// Every perturbation, camera first, in ID order.
#[rustfmt::skip]
pub static CATALOGUE: &[Entry] = &[
    // ---- Camera: noise
    entry!("C-A1", "gaussian_noise", Camera, "noise", Builder::Camera(camera::noise::GAUSSIAN), "PerturbationDrive gaussian_noise", "Additive zero-mean Gaussian sensor noise on every channel"),
    entry!("C-A2", "poisson_noise", Camera, "noise", Builder::Camera(camera::noise::POISSON), "PerturbationDrive poisson_noise", "Photon shot noise: each value drawn from a Poisson law around itself"),
    entry!("C-A3", "impulse_noise", Camera, "noise", Builder::Camera(camera::noise::IMPULSE), "PerturbationDrive impulse_noise", "Salt-and-pepper specks on random pixel channels"),
    entry!("C-A4", "jpeg_compression", Camera, "noise", Builder::Camera(camera::noise::JPEG), "PerturbationDrive jpeg_filter", "JPEG block and ringing artefacts at low quality"),
    entry!("C-A5", "speckle_noise", Camera, "noise", Builder::Camera(camera::noise::SPECKLE), "PerturbationDrive speckle_noise_filter", "Multiplicative Gaussian speckle noise"),
    // ---- Camera: blur
    entry!("C-B1", "defocus_blur", Camera, "blur", Builder::Camera(camera::blur::DEFOCUS), "PerturbationDrive defocus_blur", "Out-of-focus lens: convolution with a disk"),
    entry!("C-B2", "glass_blur", Camera, "blur", Builder::Camera(camera::blur::GLASS), "PerturbationDrive glass_blur", "Frosted-glass look: each pixel taken from a random neighbour"),
    entry!("C-B3", "motion_blur", Camera, "blur", Builder::Camera(camera::blur::MOTION_BLUR), "PerturbationDrive motion_blur", "Camera shake: convolution with a slanted line kernel"),
    entry!("C-B4", "zoom_blur", Camera, "blur", Builder::Camera(camera::blur::ZOOM_BLUR), "PerturbationDrive zoom_blur", "Radial blur of a fast forward motion: average of zoomed copies"),
    entry!("C-B5", "gaussian_blur", Camera, "blur", Builder::Camera(camera::blur::GAUSSIAN), "PerturbationDrive gaussian_blur", "Soft focus: Gaussian blur with a growing kernel"),
    entry!("C-B6", "low_pass", Camera, "blur", Builder::Camera(camera::blur::LOW_PASS), "PerturbationDrive low_pass_filter", "Gaussian low-pass on the brightness channel only"),
    entry!("C-B7", "high_pass", Camera, "blur", Builder::Camera(camera::blur::HIGH_PASS), "PerturbationDrive high_pass_filter", "Unsharp-mask high-pass emphasis of edges and noise"),
    // ---- Camera: weather and illumination
    entry!("C-C1", "frost", Camera, "weather", Builder::Camera(camera::weather::FROST), "PerturbationDrive frost_filter", "Ice crystals on the lens (procedural frost texture)"),
    entry!("C-C2", "snow", Camera, "weather", Builder::Camera(camera::weather::SNOW), "PerturbationDrive snow_filter", "Snow layer over the scene (procedural snow texture)"),
    entry!("C-C3", "fog", Camera, "weather", Builder::Camera(camera::weather::FOG), "PerturbationDrive fog_mapping", "Fog: blend with a fractal (diamond-square) haze"),
    entry!("C-C4", "brightness_increase", Camera, "weather", Builder::Camera(camera::weather::BRIGHTNESS_UP), "PerturbationDrive increase_brightness", "Over-exposure: HSV value scaled up"),
    entry!("C-C5", "brightness_decrease", Camera, "weather", Builder::Camera(camera::weather::BRIGHTNESS_DOWN), "mirror of increase_brightness", "Under-exposure: HSV value scaled down"),
    entry!("C-C6", "contrast", Camera, "weather", Builder::Camera(camera::weather::CONTRAST), "PerturbationDrive contrast", "Contrast stretched around mid-grey"),
    entry!("C-C7", "rain", Camera, "weather", Builder::Camera(camera::weather::RAIN), "PerturbationDrive dynamic_rain_filter", "Falling rain streaks (procedural, animated)"),
    entry!("C-C8", "raindrops", Camera, "weather", Builder::Camera(camera::weather::RAINDROPS), "PerturbationDrive effects_rain_dynamic", "Refracting water drops on the windshield (animated)"),
    entry!("C-C9", "lightning", Camera, "weather", Builder::Camera(camera::weather::LIGHTNING), "PerturbationDrive dynamic_lightning_filter", "Lightning bolts and flashes (procedural, animated)"),
    entry!("C-C10", "smoke", Camera, "weather", Builder::Camera(camera::weather::SMOKE), "PerturbationDrive dynamic_smoke_filter", "Drifting smoke clouds (procedural, animated)"),
    entry!("C-C11", "sun_glare", Camera, "weather", Builder::Camera(camera::weather::SUN_GLARE), "PerturbationDrive dynamic_sun_filter", "Sun glare with streak and lens ghosts (procedural, animated)"),
    entry!("C-C12", "snowflakes", Camera, "weather", Builder::Camera(camera::weather::SNOWFLAKES), "PerturbationDrive effects_snowflake_dynamic", "Snowflakes rushing past while driving (particles, animated)"),
    // ---- Camera: distortion
    entry!("C-D1", "elastic", Camera, "distortion", Builder::Camera(camera::distortion::ELASTIC), "PerturbationDrive elastic", "Elastic pixel jitter from a smoothed random displacement field"),
    entry!("C-D2", "pixelate", Camera, "distortion", Builder::Camera(camera::distortion::PIXELATE), "PerturbationDrive pixelate", "Low-resolution blocks: downscale then nearest upscale"),
    entry!("C-D3", "sample_pairing", Camera, "distortion", Builder::Camera(camera::distortion::SAMPLE_PAIRING), "PerturbationDrive sample_pairing_filter", "Blend with an enlarged random crop of the same frame"),
    entry!("C-D4", "sharpen", Camera, "distortion", Builder::Camera(camera::distortion::SHARPEN), "PerturbationDrive sharpen_filter", "Over-sharpening with an unnormalised Laplacian kernel"),
    // ---- Camera: patterns
    entry!("C-E1", "splatter", Camera, "pattern", Builder::Camera(camera::pattern::SPLATTER), "PerturbationDrive splatter_mapping", "Black blobs of dirt on the lens"),
    entry!("C-E2", "dotted_lines", Camera, "pattern", Builder::Camera(camera::pattern::DOTTED_LINES), "PerturbationDrive dotted_lines_mapping", "Dotted black lines across the image"),
    entry!("C-E3", "zigzag", Camera, "pattern", Builder::Camera(camera::pattern::ZIGZAG), "PerturbationDrive zigzag_mapping", "Zig-zag black scratches"),
    entry!("C-E4", "canny_edges", Camera, "pattern", Builder::Camera(camera::pattern::CANNY), "PerturbationDrive canny_edges_mapping", "Canny edge overlay on a dimmed image"),
    entry!("C-E5", "cutout", Camera, "pattern", Builder::Camera(camera::pattern::CUTOUT), "PerturbationDrive cutout_filter", "Black rectangles occluding parts of the image"),
    entry!("C-E6", "object_overlay", Camera, "pattern", Builder::Camera(camera::pattern::OBJECT_OVERLAY), "PerturbationDrive object_overlay", "An opaque object (sticker, sign) covering the centre"),
    // ---- Camera: colour and tone
    entry!("C-F1", "false_color", Camera, "color", Builder::Camera(camera::color::FALSE_COLOR), "PerturbationDrive false_color_filter", "Channel swaps, inversion and channel mixing"),
    entry!("C-F2", "phase_scrambling", Camera, "color", Builder::Camera(camera::color::PHASE_SCRAMBLING), "PerturbationDrive phase_scrambling", "Fourier phase noise that keeps the power spectrum"),
    entry!("C-F3", "histogram_equalization", Camera, "color", Builder::Camera(camera::color::HISTOGRAM_EQUALIZATION), "PerturbationDrive histogram_equalisation", "CLAHE on brightness: local contrast boost"),
    entry!("C-F4", "white_balance", Camera, "color", Builder::Camera(camera::color::WHITE_BALANCE), "PerturbationDrive white_balance_filter", "Gray-world white balance shift"),
    entry!("C-F5", "grayscale", Camera, "color", Builder::Camera(camera::color::GRAYSCALE), "PerturbationDrive grayscale_filter", "Colour loss: blend towards the BT.601 luma"),
    entry!("C-F6", "saturation_increase", Camera, "color", Builder::Camera(camera::color::SATURATION_UP), "PerturbationDrive saturation_filter", "Over-saturated colours: HSV saturation scaled up"),
    entry!("C-F7", "posterize", Camera, "color", Builder::Camera(camera::color::POSTERIZE), "PerturbationDrive posterize_filter", "Fewer intensity levels per channel"),
    entry!("C-F8", "saturation_decrease", Camera, "color", Builder::Camera(camera::color::SATURATION_DOWN), "PerturbationDrive saturation_decrease_filter", "Washed-out colours: HSV saturation scaled down"),
    // ---- LiDAR: weather
    entry!("L-A1", "snow_lisa", Lidar, "weather", Builder::Lidar(lidar::weather::lisa::SNOW_LISA), "3D-Corruptions-AD snow_sim (LISA, Marshall-Gunn)", "Snowfall by Monte-Carlo scattering of each beam on ice particles (LISA)"),
    entry!("L-A2", "snow_hahner", Lidar, "weather", Builder::Lidar(lidar::weather::snow::SNOW_HAHNER), "3D-Corruptions-AD snow_sim_nus (Hahner + wet ground)", "Physics snowfall: per-beam snowflake occlusion and wet ground"),
    entry!("L-A3", "snow_multicorrupt", Lidar, "weather", Builder::Lidar(lidar::weather::snow::SNOW_MULTICORRUPT), "MultiCorrupt simulate_snow", "Hahner snowfall with MultiCorrupt's parameters, no wet ground"),
    entry!("L-A4", "snow_fast", Lidar, "weather", Builder::Lidar(lidar::weather::fast::SNOW_FAST), "lightweight approximation (paper)", "Constant-time snow: distance and intensity attenuation, point removal, near-field flakes"),
    entry!("L-A5", "rain_lisa", Lidar, "weather", Builder::Lidar(lidar::weather::lisa::RAIN_LISA), "3D-Corruptions-AD rain_sim (LISA, Marshall-Palmer)", "Rainfall by Monte-Carlo scattering of each beam on water drops (LISA)"),
    entry!("L-A6", "rain_fast", Lidar, "weather", Builder::Lidar(lidar::weather::fast::RAIN_FAST), "lightweight approximation (paper)", "Constant-time rain: intensity attenuation and sparsification of distant points"),
    entry!("L-A7", "fog_hahner", Lidar, "weather", Builder::Lidar(lidar::weather::fog::FOG_HAHNER), "3D-Corruptions-AD fog_sim (Hahner)", "Physics fog: attenuation and soft-target fog returns"),
    entry!("L-A8", "fog_multicorrupt", Lidar, "weather", Builder::Lidar(lidar::weather::fog::FOG_MULTICORRUPT), "MultiCorrupt simulate_fog", "Hahner fog with MultiCorrupt's parameters"),
    entry!("L-A9", "fog_fast", Lidar, "weather", Builder::Lidar(lidar::weather::fast::FOG_FAST), "lightweight approximation (paper)", "Constant-time fog: survival exp(-alpha d) and near-field backscatter"),
    entry!("L-A10", "strong_sunlight", Lidar, "weather", Builder::Lidar(lidar::noise::SUNLIGHT), "3D-Corruptions-AD scene_glare_noise", "Sunlight saturating the receiver: strong noise on random points"),
    // ---- LiDAR: sensor
    entry!("L-B1", "density_decrease", Lidar, "sensor", Builder::Lidar(lidar::sensor::DENSITY_DECREASE), "3D-Corruptions-AD density_dec_global", "Random points lost uniformly over the cloud"),
    entry!("L-B2", "points_reducing", Lidar, "sensor", Builder::Lidar(lidar::sensor::POINTS_REDUCING), "MultiCorrupt pointsreducing", "A large random fraction of the points removed"),
    entry!("L-B3", "beam_reduction", Lidar, "sensor", Builder::Lidar(lidar::sensor::BEAM_REDUCTION), "MultiCorrupt reduce_LiDAR_beamsV2", "A sensor with fewer beams: only some rings kept"),
    entry!("L-B4", "cutout", Lidar, "sensor", Builder::Lidar(lidar::sensor::CUTOUT), "3D-Corruptions-AD cutout_local", "Occluded patches: clusters of nearby points removed"),
    entry!("L-B5", "crosstalk", Lidar, "sensor", Builder::Lidar(lidar::sensor::CROSSTALK), "3D-Corruptions-AD lidar_crosstalk_noise", "Interference from other LiDARs: strong noise on a few points"),
    entry!("L-B6", "fov_filter", Lidar, "sensor", Builder::Lidar(lidar::sensor::FOV_FILTER), "3D-Corruptions-AD fov_filter", "Narrower horizontal field of view around the forward axis"),
    // ---- LiDAR: noise
    entry!("L-C1", "gaussian_noise", Lidar, "noise", Builder::Lidar(lidar::noise::GAUSSIAN), "3D-Corruptions-AD gaussian_noise", "Gaussian range jitter on every point"),
    entry!("L-C2", "uniform_noise", Lidar, "noise", Builder::Lidar(lidar::noise::UNIFORM), "3D-Corruptions-AD uniform_noise", "Uniform jitter on every point"),
    entry!("L-C3", "impulse_noise", Lidar, "noise", Builder::Lidar(lidar::noise::IMPULSE), "3D-Corruptions-AD impulse_noise", "A fraction of points displaced by a fixed step"),
    // ---- LiDAR: local (object-level)
    entry!("L-D1", "local_density_decrease", Lidar, "local", Builder::Lidar(lidar::local::LOCAL_DENSITY), "3D-Corruptions-AD density_dec_bbox", "Points of detected objects thinned"),
    entry!("L-D2", "local_cutout", Lidar, "local", Builder::Lidar(lidar::local::LOCAL_CUTOUT), "3D-Corruptions-AD cutout_bbox", "A part of each detected object cut away"),
    entry!("L-D3", "local_gaussian_noise", Lidar, "local", Builder::Lidar(lidar::local::LOCAL_GAUSSIAN), "3D-Corruptions-AD gaussian_noise_bbox", "Gaussian jitter on the points of detected objects"),
    entry!("L-D4", "local_uniform_noise", Lidar, "local", Builder::Lidar(lidar::local::LOCAL_UNIFORM), "3D-Corruptions-AD uniform_noise_bbox", "Uniform jitter on the points of detected objects"),
    entry!("L-D5", "local_impulse_noise", Lidar, "local", Builder::Lidar(lidar::local::LOCAL_IMPULSE), "3D-Corruptions-AD impulse_noise_bbox", "Impulse displacement of points of detected objects"),
    // ---- LiDAR: affine (object-level)
    entry!("L-E1", "shear", Lidar, "affine", Builder::Lidar(lidar::affine::SHEAR), "3D-Corruptions-AD shear_bbox", "Detected objects sheared inside their boxes"),
    entry!("L-E2", "scale", Lidar, "affine", Builder::Lidar(lidar::affine::SCALE), "3D-Corruptions-AD scale_bbox", "Detected objects stretched or squeezed along one axis"),
    entry!("L-E3", "rotation", Lidar, "affine", Builder::Lidar(lidar::affine::ROTATION), "3D-Corruptions-AD rotation_bbox", "Detected objects rotated about their vertical axis"),
    // ---- LiDAR: motion and alignment
    entry!("L-F1", "motion_blur", Lidar, "motion", Builder::Lidar(lidar::motion::MOTION_BLUR), "MultiCorrupt pts_motion", "Ego-motion smear: a global shift plus per-point jitter"),
    entry!("L-F2", "moving_object", Lidar, "motion", Builder::Lidar(lidar::motion::MOVING_OBJECT), "3D-Corruptions-AD moving_noise_bbox", "Detected objects smeared as if moving during the sweep"),
    entry!("L-F3", "ghost_points", Lidar, "motion", Builder::Lidar(lidar::motion::GHOST_POINTS), "project's own", "Displaced, dimmer copies of the points of detected objects"),
    entry!("L-F4", "spatial_misalignment", Lidar, "motion", Builder::Lidar(lidar::motion::MISALIGNMENT), "MultiCorrupt transform_points", "Extrinsic calibration error: a rigid rotation and shift"),
];

#[cfg(test)]
mod tests {
    use super::*;
    use std::collections::HashSet;

    #[test]
    fn catalogue_has_42_camera_and_31_lidar_unique_ids() {
        assert_eq!(of_modality(Modality::Camera).count(), 42);
        assert_eq!(of_modality(Modality::Lidar).count(), 31);
        let ids: HashSet<_> = CATALOGUE.iter().map(|e| e.id).collect();
        assert_eq!(ids.len(), 73);
        for e in CATALOGUE {
            let prefix = if e.modality == Modality::Camera {
                "C-"
            } else {
                "L-"
            };
            assert!(e.id.starts_with(prefix), "{}", e.id);
            assert!(!e.description.is_empty() && !e.name.contains(' '));
            match (e.modality, e.build) {
                (Modality::Camera, Builder::Lidar(_)) | (Modality::Lidar, Builder::Camera(_)) => {
                    panic!("{} has a builder of the other modality", e.id)
                }
                _ => {}
            }
        }
    }

    #[test]
    fn calibration_notes_name_camera_entries_only() {
        for (id, note) in MOVES_PIXELS {
            let e = find(id).unwrap();
            assert_eq!(e.modality, Modality::Camera, "{id}");
            assert_eq!(e.calibration(), Calibration::Approximate(note));
        }
        assert_eq!(find("C-A1").unwrap().calibration(), Calibration::Kept);
        assert_eq!(find("L-F4").unwrap().calibration(), Calibration::Kept);
    }

    #[test]
    fn unknown_ids_and_bad_severities_are_clear_errors() {
        let err = find("C-Z9").unwrap_err();
        assert!(err.to_string().contains("C-Z9"), "{err}");
        let err = find_with_severity("L-B1", 4).unwrap_err();
        assert_eq!(
            err.to_string(),
            "severity 4 is out of range for L-B1: valid severities are 1..=3"
        );
        assert!(find_with_severity("l-b1", 3).is_ok());
        assert!(find_with_severity("C-A1", 0).is_err());
        assert_eq!(find("gaussian_noise").unwrap().id, "C-A1");
    }
}
