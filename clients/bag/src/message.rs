//! What reading a bag yields, whatever its format: the filter of what to read, each topic's
//! description, each message with its data, the report of what was read.

use crate::BagError;
use perturb_core::formats::ros::{CompressedImageMsg, ImageMsg, PointCloud2Msg};
use std::collections::BTreeMap;
use std::path::Path;

/// Which messages to read.
#[derive(Clone, Debug, Default)]
pub struct Filter {
    /// Only these topics (all when empty).
    pub topics: Vec<String>,
    /// Only messages with log time >= this (ns).
    pub start: Option<u64>,
    /// Only messages with log time < this (ns).
    pub end: Option<u64>,
}

impl Filter {
    pub(crate) fn accepts(&self, topic: &str, log_time: u64) -> bool {
        (self.topics.is_empty() || self.topics.iter().any(|t| t == topic))
            && self.accepts_time(log_time)
    }

    pub(crate) fn accepts_time(&self, log_time: u64) -> bool {
        self.start.is_none_or(|s| log_time >= s) && self.end.is_none_or(|e| log_time < e)
    }
}

/// The sensor message types the project decodes, whatever their spelling in the bag.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum SensorType {
    /// `sensor_msgs/msg/Image` (ROS 2) or `sensor_msgs/Image` (ROS 1).
    Image,
    /// `sensor_msgs/msg/CompressedImage` or `sensor_msgs/CompressedImage`.
    CompressedImage,
    /// `sensor_msgs/msg/PointCloud2` or `sensor_msgs/PointCloud2`.
    PointCloud2,
}

impl SensorType {
    /// The sensor type of a type name in its ROS 2 or ROS 1 spelling (the message-kind table,
    /// [`perturb_core::formats::kinds`]).
    pub fn of(type_name: &str) -> Option<Self> {
        use perturb_core::formats::kinds::Kind;
        match Kind::parse(type_name)? {
            Kind::Image => Some(SensorType::Image),
            Kind::CompressedImage => Some(SensorType::CompressedImage),
            Kind::PointCloud2 => Some(SensorType::PointCloud2),
            _ => None,
        }
    }
}

/// One topic of a bag.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct TopicInfo {
    /// Topic name.
    pub topic: String,
    /// Message type as the bag spells it (`sensor_msgs/msg/Image` in ROS 2 bags,
    /// `sensor_msgs/Image` in ROS 1 ones; see [`SensorType::of`]).
    pub type_name: String,
    /// Schema encoding (`ros2msg`, `ros2idl`; `ros1msg` for ROS 1).
    pub schema_encoding: String,
    /// Schema text.
    pub schema: Vec<u8>,
    /// Message encoding (`cdr`; `ros1` for ROS 1).
    pub message_encoding: String,
    /// Channel metadata (rosbag2 stores `offered_qos_profiles` here; for a ROS 1 bag: `md5sum`,
    /// `callerid`, `latching`).
    pub metadata: BTreeMap<String, String>,
    /// Messages on the topic, when the bag has statistics.
    pub message_count: Option<u64>,
}

/// A message, borrowed from the bag while the callback runs.
#[derive(Clone, Copy, Debug)]
pub struct BagMessage<'a> {
    /// Topic name.
    pub topic: &'a str,
    /// Message type, as the bag spells it.
    pub type_name: &'a str,
    /// Message encoding: `cdr` (ROS 2) or `ros1`.
    pub encoding: &'a str,
    /// Schema encoding: `ros2msg`, `ros2idl`, `ros1msg`, or empty when the bag has no schema.
    pub schema_encoding: &'a str,
    /// The schema (message definition) text.
    pub schema: &'a [u8],
    /// Receive time in ns.
    pub log_time: u64,
    /// Publish time in ns.
    pub publish_time: u64,
    /// Per-channel sequence number.
    pub sequence: u32,
    /// The serialized message, in `encoding`.
    pub data: &'a [u8],
    /// The file the message comes from.
    pub path: &'a Path,
}

/// A decoded sensor message.
#[derive(Clone, Debug)]
pub enum SensorMessage<'a> {
    /// `sensor_msgs/Image`.
    Image(ImageMsg<'a>),
    /// `sensor_msgs/CompressedImage`.
    Compressed(CompressedImageMsg<'a>),
    /// `sensor_msgs/PointCloud2`.
    Cloud(PointCloud2Msg<'a>),
}

impl<'a> BagMessage<'a> {
    /// True if the message is in ROS 1 serialization (a `.bag`, or ROS 1 profile MCAP).
    pub fn is_ros1(&self) -> bool {
        self.encoding == "ros1" || self.encoding == "ros"
    }

    /// Decodes an Image, CompressedImage or PointCloud2 in either encoding; `None` for other
    /// types.
    pub fn decode(&self) -> Option<Result<SensorMessage<'a>, BagError>> {
        let wrap = |e| BagError::Message {
            path: self.path.to_path_buf(),
            topic: self.topic.to_string(),
            log_time: self.log_time,
            source: e,
        };
        let ty = SensorType::of(self.type_name)?;
        let d = self.data;
        Some(
            match (ty, self.is_ros1()) {
                (SensorType::Image, false) => ImageMsg::decode(d).map(SensorMessage::Image),
                (SensorType::Image, true) => {
                    ImageMsg::decode_ros1(d).map(|m| SensorMessage::Image(m.1))
                }
                (SensorType::CompressedImage, false) => {
                    CompressedImageMsg::decode(d).map(SensorMessage::Compressed)
                }
                (SensorType::CompressedImage, true) => {
                    CompressedImageMsg::decode_ros1(d).map(|m| SensorMessage::Compressed(m.1))
                }
                (SensorType::PointCloud2, false) => {
                    PointCloud2Msg::decode(d).map(SensorMessage::Cloud)
                }
                (SensorType::PointCloud2, true) => {
                    PointCloud2Msg::decode_ros1(d).map(|m| SensorMessage::Cloud(m.1))
                }
            }
            .map_err(wrap),
        )
    }

    /// The header's `seq` of a ROS 1 sensor message (ROS 2 headers have none).
    pub fn header_seq(&self) -> Option<u32> {
        if self.is_ros1() && SensorType::of(self.type_name).is_some() {
            perturb_core::formats::ros1::header_seq(self.data)
        } else {
            None
        }
    }
}

/// The order in which messages were delivered.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ReadOrder {
    /// Log-time order, through the bag's index.
    LogTime,
    /// File order: the bag has no usable index (for example a recording that was killed).
    FileOrder,
}

/// What a read delivered.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ReadReport {
    /// Messages passed to the callback.
    pub delivered: u64,
    /// How they were ordered.
    pub order: ReadOrder,
    /// Damage found (the messages before it were delivered), e.g. a truncated last chunk.
    pub damage: Option<String>,
    /// Remarks that are not damage, e.g. a file without index read in file order.
    pub notes: Vec<String>,
}

/// A file's bytes: memory-mapped, or in memory ([`Bag::from_bytes`]).
pub(crate) enum Bytes {
    Map(memmap2::Mmap),
    Owned(Vec<u8>),
}

impl std::ops::Deref for Bytes {
    type Target = [u8];
    fn deref(&self) -> &[u8] {
        match self {
            Bytes::Map(m) => m,
            Bytes::Owned(v) => v,
        }
    }
}
