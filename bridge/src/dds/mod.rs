//! ROS 2 over DDS: the backend interface and its implementations.
//!
//! A backend creates writers and readers of ROS 2 sensor topics. Topic and type names follow the
//! ROS 2 DDS mapping (`/sensing/camera/image_raw` is the DDS topic `rt/sensing/camera/image_raw`
//! of type `sensor_msgs::msg::dds_::Image_`), and messages are plain XCDR1, so any ROS 2 node
//! (rmw_cyclonedds, rmw_fastrtps, rmw_connextdds) talks to them.
//!
//! Backends:
//! - [`rustdds_backend`] (`rustdds`, the default): ros2-client 0.12 on RustDDS 0.15, pure Rust.
//!   Slow for multi-megabyte messages (see the README's latency table).
//! - [`cyclone`] (`cyclone`): Eclipse Cyclone DDS through its C library, loaded at run time
//!   (`libddsc.so.0`, Debian package `libddsc0`/`cyclonedds-dev`), so the bridge builds without it.
//!
//! A process never reads the topics it writes: each direction gets its own DDS participant, and
//! the configuration refuses an egress topic that is also an ingress topic.

pub mod cyclone;
mod cyclone_types;
pub mod interfaces;
pub mod msgs;
pub mod rustdds_backend;

use crate::frame::Payload;
use perturb_core::formats::kinds::Kind;
use perturb_core::formats::ros::{CompressedImageMsg, ImageMsg, PointCloud2Msg};
use std::time::Duration;

/// A ROS 2 message type the bridge handles.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum RosType {
    /// `sensor_msgs/msg/Image`.
    Image,
    /// `sensor_msgs/msg/CompressedImage` (jpeg or png; ingress only: decoded to an Image).
    CompressedImage,
    /// `sensor_msgs/msg/PointCloud2`.
    #[serde(alias = "pointcloud2")]
    PointCloud2,
}

impl RosType {
    /// Its row of the message-kind table ([`perturb_core::formats::kinds`]).
    pub fn kind(self) -> Kind {
        match self {
            RosType::Image => Kind::Image,
            RosType::CompressedImage => Kind::CompressedImage,
            RosType::PointCloud2 => Kind::PointCloud2,
        }
    }

    /// The ROS 2 type name (`sensor_msgs/msg/Image`).
    pub fn ros_name(self) -> &'static str {
        self.kind().ros2_name()
    }

    /// The DDS type name (`sensor_msgs::msg::dds_::Image_`).
    pub fn dds_name(self) -> &'static str {
        self.kind().info().dds_name
    }

    /// The type's last name (`Image`).
    pub fn short_name(self) -> &'static str {
        self.kind().short_name()
    }

    /// Parses a sensor type as written in a config or a bag (`image`, `sensor_msgs/msg/Image`,
    /// any spelling the message-kind table knows).
    pub fn parse(s: &str) -> Option<Self> {
        Some(match Kind::parse(s)? {
            Kind::Image => RosType::Image,
            Kind::CompressedImage => RosType::CompressedImage,
            Kind::PointCloud2 => RosType::PointCloud2,
            _ => return None,
        })
    }
}

/// DDS reliability.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Reliability {
    /// Best effort: lost fragments lose the sample; never blocks the writer.
    BestEffort,
    /// Reliable: retransmits; a reliable reader does not match a best-effort writer.
    Reliable,
}

/// DDS durability.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Durability {
    /// Late joiners get nothing old.
    Volatile,
    /// Late joiners get the last `depth` samples.
    TransientLocal,
}

/// The QoS of a topic.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Qos {
    /// Reliability.
    pub reliability: Reliability,
    /// Durability.
    pub durability: Durability,
    /// History depth (KEEP_LAST).
    pub depth: u32,
}

impl Qos {
    /// ROS 2 `SensorDataQoS` (`rmw_qos_profile_sensor_data`): best effort, keep last 5, volatile.
    pub const SENSOR_DATA: Qos = Qos {
        reliability: Reliability::BestEffort,
        durability: Durability::Volatile,
        depth: 5,
    };
}

impl Default for Qos {
    fn default() -> Self {
        Qos::SENSOR_DATA
    }
}

/// A topic to read or write.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct TopicSpec {
    /// ROS 2 topic name (`/sensing/camera/image_raw`).
    pub topic: String,
    /// Message type.
    pub ros_type: RosType,
    /// QoS.
    pub qos: Qos,
}

impl TopicSpec {
    /// The DDS topic name: `rt` + the ROS name (`rt/sensing/camera/image_raw`).
    pub fn dds_topic(&self) -> String {
        let t = self.topic.trim_start_matches('/');
        format!("rt/{t}")
    }
}

/// Which backend to use.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum BackendKind {
    /// ros2-client / RustDDS (pure Rust).
    #[default]
    Rustdds,
    /// Cyclone DDS through libddsc.
    Cyclone,
}

impl std::str::FromStr for BackendKind {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "rustdds" => Ok(BackendKind::Rustdds),
            "cyclone" | "cyclonedds" => Ok(BackendKind::Cyclone),
            o => Err(format!("unknown DDS backend `{o}` (rustdds, cyclone)")),
        }
    }
}

/// A DDS error, naming the topic.
#[derive(Debug, thiserror::Error)]
pub enum DdsError {
    /// Creating a participant, topic, reader or writer failed.
    #[error("DDS setup of `{topic}`: {reason}")]
    Setup {
        /// The topic (or `participant`).
        topic: String,
        /// What failed.
        reason: String,
    },
    /// Writing a sample failed.
    #[error("DDS write on `{topic}`: {reason}")]
    Write {
        /// The topic.
        topic: String,
        /// What failed.
        reason: String,
    },
    /// Reading failed.
    #[error("DDS read on `{topic}`: {reason}")]
    Read {
        /// The topic.
        topic: String,
        /// What failed.
        reason: String,
    },
    /// The backend is not available on this machine.
    #[error("DDS backend `{backend}` is not available: {reason}")]
    Unavailable {
        /// The backend.
        backend: &'static str,
        /// Why.
        reason: String,
    },
}

/// A received message, borrowed from the backend's buffer while the callback runs.
#[derive(Clone, Debug)]
pub enum Received<'a> {
    /// `sensor_msgs/Image`.
    Image(ImageMsg<'a>),
    /// `sensor_msgs/CompressedImage`.
    Compressed(CompressedImageMsg<'a>),
    /// `sensor_msgs/PointCloud2`.
    Cloud(PointCloud2Msg<'a>),
}

/// Writes sensor messages on one topic.
pub trait DdsWriter: Send {
    /// Publishes one message (serialising it from the borrowed bytes).
    fn write(&mut self, msg: &Payload<'_>) -> Result<(), DdsError>;
    /// How many readers are matched, when the backend knows.
    fn matched(&self) -> Option<usize>;
    /// Readers seen so far that asked for a QoS this writer does not offer (so DDS never
    /// matched them and they receive nothing), when the backend reports it.
    fn incompatible_readers(&mut self) -> Option<IncompatibleReaders>;
}

/// Readers that requested a QoS the writer does not offer: DDS does not match them, silently.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct IncompatibleReaders {
    /// How many such readers were seen since the writer was created.
    pub total: u64,
    /// The QoS policy the last one disagreed on, in DDS spelling (`RELIABILITY`, `DURABILITY`).
    pub policy: String,
}

impl IncompatibleReaders {
    /// What it means for a writer of `spec` and what to change, in one sentence.
    pub fn explain(&self, spec: &TopicSpec) -> String {
        let fix = match (
            self.policy.as_str(),
            spec.qos.reliability,
            spec.qos.durability,
        ) {
            ("RELIABILITY", Reliability::BestEffort, _) => {
                "a reliable reader does not match a best-effort writer: make the reader best effort \
                 (ROS 2 SensorDataQoS) or set qos = { reliability = \"reliable\" } on this [[egress]]"
            }
            ("DURABILITY", _, Durability::Volatile) => {
                "a transient-local reader does not match a volatile writer: make the reader volatile \
                 or set qos = { durability = \"transient_local\" } on this [[egress]]"
            }
            _ => "compare the reader's QoS with this [[egress]]'s qos",
        };
        format!(
            "{} reader(s) of `{}` asked for a QoS this egress does not offer ({}) and receive nothing; {fix}",
            self.total, spec.topic, self.policy
        )
    }
}

/// The DDS name of a QoS policy id (the numbering of the DDS specification, which Cyclone's
/// `dds_qos_policy_id_t` follows).
pub fn policy_name(id: u32) -> String {
    match id {
        1 => "USER_DATA",
        2 => "DURABILITY",
        3 => "PRESENTATION",
        4 => "DEADLINE",
        5 => "LATENCY_BUDGET",
        6 => "OWNERSHIP",
        7 => "OWNERSHIP_STRENGTH",
        8 => "LIVELINESS",
        9 => "TIME_BASED_FILTER",
        10 => "PARTITION",
        11 => "RELIABILITY",
        12 => "DESTINATION_ORDER",
        13 => "HISTORY",
        14 => "RESOURCE_LIMITS",
        21 => "DATA_REPRESENTATION",
        _ => return format!("QoS policy #{id}"),
    }
    .to_string()
}

/// Reads sensor messages from one topic.
pub trait DdsReader: Send {
    /// Waits up to `timeout` for messages and passes every available one to `f` (a message that
    /// does not decode is passed as an error; the reader carries on). Returns how many were
    /// passed.
    fn take(
        &mut self,
        timeout: Duration,
        f: &mut dyn FnMut(Result<Received<'_>, perturb_core::Error>),
    ) -> Result<usize, DdsError>;
}

/// A DDS implementation: one participant, many topics.
pub trait DdsBackend: Send + Sync {
    /// The backend's name.
    fn name(&self) -> &'static str;
    /// Creates a writer.
    fn writer(&self, spec: &TopicSpec) -> Result<Box<dyn DdsWriter>, DdsError>;
    /// Creates a reader.
    fn reader(&self, spec: &TopicSpec) -> Result<Box<dyn DdsReader>, DdsError>;
}

/// Where a participant lives: its backend, domain and network interfaces.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct ParticipantConfig {
    /// The DDS implementation.
    pub backend: BackendKind,
    /// The DDS domain.
    pub domain_id: u16,
    /// The network interfaces DDS may use, by name (`lo`, `eth0`) or IPv4 address; empty means
    /// the implementation's own choice (Cyclone and RustDDS then pick the machine's
    /// multicast-capable interfaces, as ROS 2 nodes do by default).
    pub interfaces: Vec<String>,
}

impl ParticipantConfig {
    /// A participant of `backend` on `domain_id` that only uses the loopback interface: what
    /// tests, benchmarks and single-computer setups use.
    pub fn loopback(backend: BackendKind, domain_id: u16) -> Self {
        ParticipantConfig {
            backend,
            domain_id,
            interfaces: vec!["lo".into()],
        }
    }
}

/// Creates a backend with one participant as `cfg` says; `node` names the ROS node.
pub fn backend(cfg: &ParticipantConfig, node: &str) -> Result<Box<dyn DdsBackend>, DdsError> {
    let nets = interfaces::resolve(&cfg.interfaces)?;
    match cfg.backend {
        BackendKind::Rustdds => Ok(Box::new(rustdds_backend::RustddsBackend::new(
            cfg.domain_id,
            node,
            nets.as_deref(),
        )?)),
        BackendKind::Cyclone => Ok(Box::new(cyclone::CycloneBackend::new(
            cfg.domain_id,
            nets.as_deref(),
        )?)),
    }
}

/// Decodes a CDR body of `ty` in the given byte order.
pub fn decode_body(
    ty: RosType,
    body: &[u8],
    little_endian: bool,
) -> Result<Received<'_>, perturb_core::Error> {
    Ok(match ty {
        RosType::Image => Received::Image(ImageMsg::decode_body(body, little_endian)?),
        RosType::CompressedImage => {
            Received::Compressed(CompressedImageMsg::decode_body(body, little_endian)?)
        }
        RosType::PointCloud2 => Received::Cloud(PointCloud2Msg::decode_body(body, little_endian)?),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_follow_the_ros2_dds_mapping() {
        let s = TopicSpec {
            topic: "/sensing/camera/image_raw".into(),
            ros_type: RosType::Image,
            qos: Qos::default(),
        };
        assert_eq!(s.dds_topic(), "rt/sensing/camera/image_raw");
        assert_eq!(
            RosType::parse("sensor_msgs/msg/PointCloud2"),
            Some(RosType::PointCloud2)
        );
        assert_eq!(
            RosType::PointCloud2.dds_name(),
            "sensor_msgs::msg::dds_::PointCloud2_"
        );
        assert_eq!(Qos::default().depth, 5);
    }
}
