//! Decoders and encoders for the file and message formats the project reads and writes.
//!
//! Everything here works on bytes in memory; reading and writing files is the caller's job, and
//! the caller adds the file name to the error. Malformed input returns [`crate::Error::Malformed`]
//! saying what is wrong and where, never a panic.
//!
//! | format | module |
//! |---|---|
//! | PNG, JPEG | [`picture`] |
//! | KITTI velodyne `.bin` (float32 x, y, z, reflectance) | [`kitti`] |
//! | nuScenes `.pcd.bin` (float32 x, y, z, intensity, ring) | [`kitti`] |
//! | KITTI object labels and calibration (`label_2`, `calib`) | [`kitti_labels`] |
//! | PCD v0.7 (ascii, binary, binary_compressed; any fields) | [`pcd`] |
//! | `sensor_msgs/Image`, `CompressedImage`, `PointCloud2` in CDR | [`ros`] |
//! | the same, `std_msgs/String` and `rosgraph_msgs/Clock` in ROS 1 serialization | [`ros1`] |
//!
//! [`kinds`] is the one table of the message kinds (names in every spelling, md5sums,
//! definitions) that the bridge and the bag crate read.

pub mod kinds;
pub mod kitti;
pub mod kitti_labels;
pub mod pcd;
pub mod picture;
pub mod ros;
pub mod ros1;

use crate::error::{Error, Result};

/// The file formats recognised by extension.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FileKind {
    /// `.png`
    Png,
    /// `.jpg` / `.jpeg`
    Jpeg,
    /// KITTI `.bin`
    KittiBin,
    /// nuScenes `.pcd.bin`
    NuscenesBin,
    /// `.pcd`
    Pcd,
    /// A bag, handled by the bag crate: `.mcap` (rosbag2, or the ROS 1 profile) or a ROS 1
    /// `.bag` (format 2.0).
    Mcap,
}

impl FileKind {
    /// The kind of a file from its name, or a clear error naming the extension.
    pub fn from_path(path: &std::path::Path) -> Result<Self> {
        let name = path
            .file_name()
            .and_then(|n| n.to_str())
            .unwrap_or_default()
            .to_ascii_lowercase();
        Ok(if name.ends_with(".pcd.bin") {
            FileKind::NuscenesBin
        } else if name.ends_with(".bin") {
            FileKind::KittiBin
        } else if name.ends_with(".pcd") {
            FileKind::Pcd
        } else if name.ends_with(".png") {
            FileKind::Png
        } else if name.ends_with(".jpg") || name.ends_with(".jpeg") {
            FileKind::Jpeg
        } else if name.ends_with(".mcap") || name.ends_with(".bag") {
            FileKind::Mcap
        } else {
            return Err(Error::InvalidConfig {
                reason: format!(
                    "cannot tell the format of `{}` from its extension (known: .png .jpg .jpeg .bin .pcd.bin .pcd .mcap .bag)",
                    path.display()
                ),
            });
        })
    }

    /// True for the image formats.
    pub fn is_image(self) -> bool {
        matches!(self, FileKind::Png | FileKind::Jpeg)
    }

    /// True for the point-cloud formats.
    pub fn is_cloud(self) -> bool {
        matches!(
            self,
            FileKind::KittiBin | FileKind::NuscenesBin | FileKind::Pcd
        )
    }
}
