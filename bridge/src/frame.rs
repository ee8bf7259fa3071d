//! The frames that flow through the bridge: a ROS sensor message (borrowed, so a frame can live
//! in shared memory, in a bag's chunk or in a DDS buffer) plus the middleware's metadata.

use perturb_core::cloud::Cloud;
use perturb_core::formats::ros::{Header, ImageMsg, PointCloud2Msg};
use perturb_core::image::Image;

/// What a stream carries.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum StreamKind {
    /// Camera frames (`sensor_msgs/msg/Image`).
    Image,
    /// Point clouds (`sensor_msgs/msg/PointCloud2`).
    Cloud,
}

impl StreamKind {
    /// The ROS 2 type of the stream's messages.
    pub fn ros_type(self) -> &'static str {
        match self {
            StreamKind::Image => "sensor_msgs/msg/Image",
            StreamKind::Cloud => "sensor_msgs/msg/PointCloud2",
        }
    }
}

/// A sensor message borrowing its bytes.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Payload<'a> {
    /// A raw image.
    Image(ImageMsg<'a>),
    /// A point cloud.
    Cloud(PointCloud2Msg<'a>),
}

impl<'a> Payload<'a> {
    /// The ROS header.
    pub fn header(&self) -> &Header<'a> {
        match self {
            Payload::Image(m) => &m.header,
            Payload::Cloud(m) => &m.header,
        }
    }

    /// What kind of stream it belongs on.
    pub fn kind(&self) -> StreamKind {
        match self {
            Payload::Image(_) => StreamKind::Image,
            Payload::Cloud(_) => StreamKind::Cloud,
        }
    }

    /// The pixel or point bytes.
    pub fn data(&self) -> &'a [u8] {
        match self {
            Payload::Image(m) => m.data,
            Payload::Cloud(m) => m.data,
        }
    }

    /// Little-endian CDR with the 4-byte encapsulation header (what rosbag2 stores).
    pub fn encode(&self) -> Vec<u8> {
        match self {
            Payload::Image(m) => m.encode(),
            Payload::Cloud(m) => m.encode(),
        }
    }

    /// The message in a bag format's encoding: CDR, or ROS 1 with `seq` as the header's `seq`.
    pub fn encode_for(&self, format: perturb_bag::BagFormat, seq: u64) -> Vec<u8> {
        match (format, self) {
            (perturb_bag::BagFormat::Rosbag2, _) => self.encode(),
            (perturb_bag::BagFormat::Ros1, Payload::Image(m)) => m.encode_ros1(seq as u32),
            (perturb_bag::BagFormat::Ros1, Payload::Cloud(m)) => m.encode_ros1(seq as u32),
        }
    }

    /// Checks that the message is internally consistent (image size, step and data length agree;
    /// the point layout is valid and the data holds the points), so a bad message is refused
    /// where it enters instead of failing further down the pipeline.
    pub fn validate(&self) -> perturb_core::Result<()> {
        match self {
            Payload::Image(m) => m.view().map(|_| ()),
            Payload::Cloud(m) => m.view().map(|_| ()),
        }
    }
}

/// Which perturbation was applied to a frame.
#[derive(Clone, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct Applied {
    /// Perturbation ID (`C-A1`).
    pub id: String,
    /// Severity.
    pub severity: u8,
    /// Seed.
    pub seed: u64,
}

/// Per-hop monotonic timestamps (`CLOCK_MONOTONIC`, ns; 0 = not stamped).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Hops {
    /// When the source (ingress, replay, synthetic) handed the frame to the middleware.
    pub source: u64,
    /// When the daemon took the raw frame.
    pub daemon_in: u64,
    /// When the daemon published the perturbed frame.
    pub daemon_out: u64,
    /// When the egress or recorder received the frame.
    pub sink: u64,
}

/// The middleware's metadata of a frame.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct FrameMeta {
    /// Sequence number within the stream (the one perturbations are seeded with).
    pub seq: u64,
    /// Wall-clock time (ns since the Unix epoch) at which the frame entered the middleware; for
    /// replayed frames the bag's original log time.
    pub log_time: u64,
    /// The perturbation applied, if any.
    pub applied: Option<Applied>,
    /// Per-hop timestamps.
    pub hops: Hops,
    /// Frames the source knows were lost just before this one (a ROS 1 publisher's `seq`
    /// gap), carried to the daemon (`lost_before` in the wire header).
    pub lost_before: u32,
    /// The campaign step that chose the applied perturbation (1-based; 0: none).
    pub step: u16,
}

/// An owned sensor message (synthetic frames, decoded compressed images, frames copied between
/// threads).
#[derive(Clone, Debug, PartialEq)]
pub enum OwnedPayload {
    /// An image with its header.
    Image {
        /// Stamp seconds.
        sec: i32,
        /// Stamp nanoseconds.
        nanosec: u32,
        /// frame_id.
        frame_id: String,
        /// The pixels.
        image: Image,
    },
    /// A point cloud with its header.
    Cloud {
        /// Stamp seconds.
        sec: i32,
        /// Stamp nanoseconds.
        nanosec: u32,
        /// frame_id.
        frame_id: String,
        /// The points.
        cloud: Cloud,
    },
    /// An exact copy of a message (keeps every field, including padding and odd steps).
    Copied {
        /// The message in CDR (little-endian, with the encapsulation header).
        cdr: Vec<u8>,
        /// What it is.
        kind: StreamKind,
    },
}

impl OwnedPayload {
    /// Copies a borrowed payload, field for field.
    pub fn copy_of(p: &Payload<'_>) -> Self {
        OwnedPayload::Copied {
            cdr: p.encode(),
            kind: p.kind(),
        }
    }

    /// Borrows it as a [`Payload`].
    pub fn payload(&self) -> Payload<'_> {
        match self {
            OwnedPayload::Image {
                sec,
                nanosec,
                frame_id,
                image,
            } => Payload::Image(ImageMsg::from_view(
                Header {
                    stamp_sec: *sec,
                    stamp_nanosec: *nanosec,
                    frame_id,
                },
                &image.view(),
            )),
            OwnedPayload::Cloud {
                sec,
                nanosec,
                frame_id,
                cloud,
            } => Payload::Cloud(PointCloud2Msg::from_view(
                Header {
                    stamp_sec: *sec,
                    stamp_nanosec: *nanosec,
                    frame_id,
                },
                &cloud.view(),
            )),
            OwnedPayload::Copied { cdr, kind } => match kind {
                StreamKind::Image => {
                    Payload::Image(ImageMsg::decode(cdr).expect("encoded by copy_of"))
                }
                StreamKind::Cloud => {
                    Payload::Cloud(PointCloud2Msg::decode(cdr).expect("encoded by copy_of"))
                }
            },
        }
    }
}

/// `CLOCK_MONOTONIC` in ns, the clock of the per-hop timestamps (shared by all processes): the
/// wire crate's, so bridge and daemon stamp hops with one function.
pub use perturb_wire::monotonic_ns;

/// Wall-clock time in ns since the Unix epoch.
pub fn wall_ns() -> u64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| d.as_nanos() as u64)
        .unwrap_or(0)
}

#[cfg(test)]
mod tests {
    use super::*;
    use perturb_core::synthetic::{street_image, vlp32c_scan};

    #[test]
    fn owned_payloads_borrow_and_copy_exactly() {
        let img = OwnedPayload::Image {
            sec: 5,
            nanosec: 7,
            frame_id: "cam".into(),
            image: street_image(32, 20, 0),
        };
        let p = img.payload();
        p.validate().unwrap();
        assert_eq!(p.header().stamp_nanosec, 7);
        let copy = OwnedPayload::copy_of(&p);
        assert_eq!(copy.payload(), p);
        let cloud = OwnedPayload::Cloud {
            sec: 1,
            nanosec: 2,
            frame_id: "velodyne".into(),
            cloud: vlp32c_scan(0),
        };
        let p = cloud.payload();
        p.validate().unwrap();
        assert_eq!(OwnedPayload::copy_of(&p).payload(), p);
    }
}
