//! The message kinds the project reads and writes, in one table: every place that names a
//! message type (the bridge's configuration and its ROS 1 and ROS 2 sides, the bag reader and
//! writer, `perturb info`) asks this table, so a new kind is one row here plus its codec.
//!
//! ```
//! use perturb_core::formats::kinds::Kind;
//! let k = Kind::parse("sensor_msgs/msg/CompressedImage").unwrap();
//! assert_eq!(k, Kind::parse("compressed_image").unwrap());
//! assert_eq!(k.info().ros1.name, "sensor_msgs/CompressedImage");
//! assert_eq!(k.info().dds_name, "sensor_msgs::msg::dds_::CompressedImage_");
//! assert!(k.is_sensor());
//! ```

use super::ros1::{self, MsgType};

/// A message kind.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Kind {
    /// `sensor_msgs/Image`: camera frames.
    Image,
    /// `sensor_msgs/CompressedImage` (jpeg or png): camera frames, decoded on the way in.
    CompressedImage,
    /// `sensor_msgs/PointCloud2`: LiDAR clouds.
    PointCloud2,
    /// `sensor_msgs/CameraInfo`: a camera's calibration, relayed with its images.
    CameraInfo,
    /// `std_msgs/String`: the events records.
    String,
    /// `std_msgs/Bool`: the usual kill switch topic.
    Bool,
    /// `rosgraph_msgs/Clock`: `/clock` of a replay under `use_sim_time`.
    Clock,
}

/// What the project knows of a kind.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct KindInfo {
    /// The kind.
    pub kind: Kind,
    /// Its name in the configuration (`compressed_image`).
    pub key: &'static str,
    /// Other names a configuration may use (`CompressedImage`).
    pub aliases: &'static [&'static str],
    /// The ROS 1 type (name, md5sum, definition); its `ros2_name` is the ROS 2 name.
    pub ros1: MsgType,
    /// The DDS type name of the ROS 2 type (`sensor_msgs::msg::dds_::CompressedImage_`).
    pub dds_name: &'static str,
    /// True for the sensor messages the streams carry (images, clouds).
    pub sensor: bool,
}

/// `sensor_msgs/CameraInfo`.
pub const CAMERA_INFO: MsgType = MsgType {
    name: "sensor_msgs/CameraInfo",
    ros2_name: "sensor_msgs/msg/CameraInfo",
    md5sum: "c9a58c1b0b154e0e6da7578cb991d214",
    definition: include_str!("ros1_msg/sensor_msgs-CameraInfo.txt"),
};

/// `std_msgs/Bool`.
pub const BOOL: MsgType = MsgType {
    name: "std_msgs/Bool",
    ros2_name: "std_msgs/msg/Bool",
    md5sum: "8b94c1b53db61fb6aed406028ad6332a",
    definition: include_str!("ros1_msg/std_msgs-Bool.txt"),
};

/// The table.
pub const KINDS: [KindInfo; 7] = [
    KindInfo {
        kind: Kind::Image,
        key: "image",
        aliases: &["Image"],
        ros1: ros1::IMAGE,
        dds_name: "sensor_msgs::msg::dds_::Image_",
        sensor: true,
    },
    KindInfo {
        kind: Kind::CompressedImage,
        key: "compressed_image",
        aliases: &["CompressedImage"],
        ros1: ros1::COMPRESSED_IMAGE,
        dds_name: "sensor_msgs::msg::dds_::CompressedImage_",
        sensor: true,
    },
    KindInfo {
        kind: Kind::PointCloud2,
        key: "pointcloud2",
        aliases: &["point_cloud2", "PointCloud2"],
        ros1: ros1::POINT_CLOUD2,
        dds_name: "sensor_msgs::msg::dds_::PointCloud2_",
        sensor: true,
    },
    KindInfo {
        kind: Kind::CameraInfo,
        key: "camera_info",
        aliases: &["CameraInfo"],
        ros1: CAMERA_INFO,
        dds_name: "sensor_msgs::msg::dds_::CameraInfo_",
        sensor: false,
    },
    KindInfo {
        kind: Kind::String,
        key: "string",
        aliases: &["String"],
        ros1: ros1::STRING,
        dds_name: "std_msgs::msg::dds_::String_",
        sensor: false,
    },
    KindInfo {
        kind: Kind::Bool,
        key: "bool",
        aliases: &["Bool"],
        ros1: BOOL,
        dds_name: "std_msgs::msg::dds_::Bool_",
        sensor: false,
    },
    KindInfo {
        kind: Kind::Clock,
        key: "clock",
        aliases: &["Clock"],
        ros1: ros1::CLOCK,
        dds_name: "rosgraph_msgs::msg::dds_::Clock_",
        sensor: false,
    },
];

impl Kind {
    /// Its row of the table.
    pub fn info(self) -> &'static KindInfo {
        KINDS
            .iter()
            .find(|k| k.kind == self)
            .expect("every kind has a row")
    }

    /// The kind named `name` in any spelling: the configuration's key or an alias, the ROS 1
    /// name (`sensor_msgs/Image`), the ROS 2 name (`sensor_msgs/msg/Image`) or the DDS name.
    pub fn parse(name: &str) -> Option<Kind> {
        KINDS
            .iter()
            .find(|k| {
                k.key == name
                    || k.aliases.contains(&name)
                    || k.ros1.name == name
                    || k.ros1.ros2_name == name
                    || k.dds_name == name
            })
            .map(|k| k.kind)
    }

    /// The ROS 2 type name (`sensor_msgs/msg/Image`).
    pub fn ros2_name(self) -> &'static str {
        self.info().ros1.ros2_name
    }

    /// The type's last name (`Image`).
    pub fn short_name(self) -> &'static str {
        let n = self.info().ros1.name;
        n.rsplit('/').next().unwrap_or(n)
    }

    /// True for the sensor messages the streams carry.
    pub fn is_sensor(self) -> bool {
        self.info().sensor
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_spelling_names_one_kind_and_every_kind_has_one_row() {
        for k in KINDS {
            assert_eq!(k.kind.info(), &k);
            for name in [k.key, k.ros1.name, k.ros1.ros2_name, k.dds_name]
                .into_iter()
                .chain(k.aliases.iter().copied())
            {
                assert_eq!(Kind::parse(name), Some(k.kind), "{name}");
            }
            assert!(k.dds_name.ends_with(&format!("{}_", k.kind.short_name())));
        }
        assert_eq!(Kind::parse("sensor_msgs/msg/Imu"), None);
    }
}
