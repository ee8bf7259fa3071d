//! Reading and writing the file formats, with the file name in every error.

use crate::error::{Result, StudyError};
use perturb_core::cloud::{Cloud, CloudView};
use perturb_core::formats::{FileKind, kitti, pcd, picture};
use perturb_core::image::{Image, ImageView};
use perturb_core::sensor_model::{Axes, Axis, SensorModel};
use std::path::Path;

/// A decoded input file.
pub enum Loaded {
    /// An image and whether it was a JPEG.
    Image(Image, FileKind),
    /// A cloud, its file kind, and for PCD the data encoding and viewpoint.
    Cloud(Cloud, FileKind, Option<(pcd::PcdData, [f64; 7])>),
}

/// The kind of file `path` is, from its name.
pub fn kind_of(path: &Path) -> Result<FileKind> {
    Ok(FileKind::from_path(path)?)
}

/// Reads and decodes an image or point-cloud file. Doubts about a KITTI `.bin` and bytes a PCD
/// file's reader ignored are printed as warnings on stderr (never silent).
pub fn load(path: &Path) -> Result<Loaded> {
    let kind = kind_of(path)?;
    if kind == FileKind::Mcap {
        return Err(StudyError::input(
            path,
            "is a bag; this operation needs an image or point-cloud file",
        ));
    }
    let bytes = std::fs::read(path).map_err(StudyError::io(path))?;
    let bad = |e: perturb_core::Error| StudyError::input(path, e.to_string());
    Ok(match kind {
        FileKind::Png | FileKind::Jpeg => {
            Loaded::Image(picture::decode(&bytes).map_err(bad)?, kind)
        }
        FileKind::KittiBin => {
            let cloud = kitti::decode_kitti(&bytes).map_err(bad)?;
            for doubt in kitti::kitti_doubts(&bytes) {
                eprintln!("warning: {}: {doubt}", path.display());
            }
            Loaded::Cloud(cloud, kind, None)
        }
        FileKind::NuscenesBin => {
            Loaded::Cloud(kitti::decode_nuscenes(&bytes).map_err(bad)?, kind, None)
        }
        FileKind::Pcd => {
            let f = pcd::decode(&bytes).map_err(bad)?;
            for w in &f.warnings {
                eprintln!("warning: {}: {w}", path.display());
            }
            Loaded::Cloud(f.cloud, kind, Some((f.data, f.viewpoint)))
        }
        FileKind::Mcap => unreachable!("handled above"),
    })
}

/// Encodes and writes an image in `kind`'s format.
pub fn save_image(path: &Path, img: &ImageView<'_>, kind: FileKind) -> Result<()> {
    let bytes = match kind {
        FileKind::Jpeg => picture::encode_jpeg(img, 95),
        _ => picture::encode_png(img),
    }
    .map_err(StudyError::perturb(format!("encoding {}", path.display())))?;
    std::fs::write(path, bytes).map_err(StudyError::io(path))
}

/// Encodes and writes a cloud in `kind`'s format (PCD keeps its data encoding and viewpoint).
pub fn save_cloud(
    path: &Path,
    cloud: &CloudView<'_>,
    kind: FileKind,
    pcd_meta: Option<(pcd::PcdData, [f64; 7])>,
) -> Result<()> {
    let bytes = match kind {
        FileKind::KittiBin => kitti::encode_kitti(cloud),
        FileKind::NuscenesBin => kitti::encode_nuscenes(cloud),
        _ => {
            let (data, vp) =
                pcd_meta.unwrap_or((pcd::PcdData::Binary, [0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0]));
            pcd::encode(cloud, data, vp)
        }
    }
    .map_err(StudyError::perturb(format!("encoding {}", path.display())))?;
    std::fs::write(path, bytes).map_err(StudyError::io(path))
}

/// The sensor model for a cloud file: `sensor` if given, else HDL-64E for KITTI `.bin` files
/// (KITTI's sensor, reflectance 0..1), HDL-32E for nuScenes `.pcd.bin` files and VLP-32C
/// (intensity 0..255) for everything else; the forward axis from `forward` (`--forward`) if
/// given, else +y for nuScenes `.pcd.bin` files (nuScenes' `LIDAR_TOP` looks along +y) and +x
/// otherwise (ROS, KITTI, Velodyne drivers); `intensity_max` overrides the intensity scale.
/// [`describe_sensor`] says which one it is, for the user.
pub fn sensor_for(
    kind: Option<FileKind>,
    sensor: Option<&str>,
    forward: Option<&str>,
    intensity_max: Option<f32>,
) -> Result<SensorModel> {
    let mut m = match sensor {
        Some(name) => SensorModel::by_name(name)?,
        None if kind == Some(FileKind::KittiBin) => SensorModel::hdl64e(),
        None if kind == Some(FileKind::NuscenesBin) => SensorModel::hdl32e(),
        None => SensorModel::vlp32c(),
    };
    let axes = match forward {
        Some(f) => Axis::parse(f)
            .and_then(|f| Axes::new(f, m.axes.up))
            .map_err(|e| StudyError::Config(format!("--forward: {e}")))?,
        None if kind == Some(FileKind::NuscenesBin) => SensorModel::nuscenes().axes,
        None => m.axes,
    };
    m = m.with_axes(axes);
    if let Some(max) = intensity_max {
        if max != 1.0 && max != 255.0 {
            return Err(StudyError::Config(format!(
                "--intensity-max must be 1 or 255, not {max}"
            )));
        }
        m = m.with_intensity_max(max);
    }
    Ok(m)
}

/// The line telling the user which sensor model reads the clouds.
pub fn describe_sensor(m: &SensorModel) -> String {
    format!(
        "sensor model {}; change with --sensor / --forward / --intensity-max",
        m.describe()
    )
}
