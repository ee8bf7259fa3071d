//! The ROS 2 message types as serde structs, fields in `.msg` order (plain XCDR1 needs nothing
//! else). `Time` keeps `sec`/`nanosec` as on the wire, so stamps pass through bit-exact.
//!
//! The bridge's data path does not need them (it reads and writes CDR straight from and into the
//! frame bytes, see [`perturb_core::formats::ros`]); they are the typed face of the same messages
//! for programs built on ros2-client (`node.create_publisher::<Image>(..)`), and the tests use
//! them as an independent serialiser to check the bridge's bytes.

use serde::{Deserialize, Serialize};

/// `builtin_interfaces/msg/Time`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct Time {
    /// Seconds.
    pub sec: i32,
    /// Nanoseconds.
    pub nanosec: u32,
}

/// `std_msgs/msg/Header`.
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct Header {
    /// Stamp.
    pub stamp: Time,
    /// Frame.
    pub frame_id: String,
}

/// `sensor_msgs/msg/Image`.
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct Image {
    /// Header.
    pub header: Header,
    /// Rows.
    pub height: u32,
    /// Columns.
    pub width: u32,
    /// Encoding (`rgb8`).
    pub encoding: String,
    /// Big-endian pixels.
    pub is_bigendian: u8,
    /// Row length in bytes.
    pub step: u32,
    /// Pixels.
    #[serde(with = "serde_bytes")]
    pub data: Vec<u8>,
}

/// `sensor_msgs/msg/CompressedImage`.
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct CompressedImage {
    /// Header.
    pub header: Header,
    /// `jpeg` or `png`.
    pub format: String,
    /// The file bytes.
    #[serde(with = "serde_bytes")]
    pub data: Vec<u8>,
}

/// `sensor_msgs/msg/PointField`.
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct PointField {
    /// Name.
    pub name: String,
    /// Byte offset in the point.
    pub offset: u32,
    /// Datatype code (1 = INT8 ... 8 = FLOAT64).
    pub datatype: u8,
    /// Elements.
    pub count: u32,
}

/// `sensor_msgs/msg/PointCloud2`.
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct PointCloud2 {
    /// Header.
    pub header: Header,
    /// Rows.
    pub height: u32,
    /// Points per row.
    pub width: u32,
    /// Layout.
    pub fields: Vec<PointField>,
    /// Big-endian data.
    pub is_bigendian: bool,
    /// Bytes per point.
    pub point_step: u32,
    /// Bytes per row.
    pub row_step: u32,
    /// Points.
    #[serde(with = "serde_bytes")]
    pub data: Vec<u8>,
    /// No invalid points.
    pub is_dense: bool,
}

impl From<&perturb_core::formats::ros::Header<'_>> for Header {
    fn from(h: &perturb_core::formats::ros::Header<'_>) -> Self {
        Header {
            stamp: Time {
                sec: h.stamp_sec,
                nanosec: h.stamp_nanosec,
            },
            frame_id: h.frame_id.to_string(),
        }
    }
}

impl From<&perturb_core::formats::ros::ImageMsg<'_>> for Image {
    fn from(m: &perturb_core::formats::ros::ImageMsg<'_>) -> Self {
        Image {
            header: (&m.header).into(),
            height: m.height,
            width: m.width,
            encoding: m.encoding.to_string(),
            is_bigendian: m.is_bigendian,
            step: m.step,
            data: m.data.to_vec(),
        }
    }
}

impl From<&perturb_core::formats::ros::PointCloud2Msg<'_>> for PointCloud2 {
    fn from(m: &perturb_core::formats::ros::PointCloud2Msg<'_>) -> Self {
        PointCloud2 {
            header: (&m.header).into(),
            height: m.height,
            width: m.width,
            fields: m
                .fields
                .iter()
                .map(|f| PointField {
                    name: f.name.clone(),
                    offset: f.offset,
                    datatype: f.datatype.code(),
                    count: f.count,
                })
                .collect(),
            is_bigendian: m.is_bigendian,
            point_step: m.point_step,
            row_step: m.row_step,
            data: m.data.to_vec(),
            is_dense: m.is_dense,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::frame::OwnedPayload;
    use crate::frame::Payload;
    use ros2_client::dds::rustdds::cdr_encoding;

    fn serde_cdr<T: Serialize>(v: &T) -> Vec<u8> {
        let mut out = vec![0, 1, 0, 0];
        out.extend(cdr_encoding::to_vec::<T, byteorder::LittleEndian>(v).unwrap());
        out
    }

    #[test]
    fn serde_types_serialise_to_the_bridge_s_bytes() {
        let img = OwnedPayload::Image {
            sec: -3,
            nanosec: 999_999_999,
            frame_id: "camera_front".into(),
            image: perturb_core::synthetic::street_image(17, 5, 1),
        };
        let Payload::Image(m) = img.payload() else {
            unreachable!()
        };
        assert_eq!(serde_cdr(&Image::from(&m)), m.encode());
        let back: Image =
            cdr_encoding::from_bytes::<Image, byteorder::LittleEndian>(&m.encode()[4..])
                .unwrap()
                .0;
        assert_eq!(
            back.header.stamp,
            Time {
                sec: -3,
                nanosec: 999_999_999
            }
        );
        let cloud = OwnedPayload::Cloud {
            sec: 1,
            nanosec: 2,
            frame_id: "velodyne".into(),
            cloud: perturb_core::synthetic::vlp32c_scan(0),
        };
        let Payload::Cloud(m) = cloud.payload() else {
            unreachable!()
        };
        assert_eq!(serde_cdr(&PointCloud2::from(&m)), m.encode());
    }
}
