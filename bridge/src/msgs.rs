//! Small messages beside the sensor streams: the events record (`std_msgs/String`), the kill
//! switch's topic (`std_msgs/Bool` or any message read by field path), the vehicle's pose for
//! campaigns, and `camera_info` relayed with its image. They are written and read as bytes in
//! the transport's own serialization (ROS 1, or CDR with its 4-byte encapsulation header), and
//! decoded by field path with the message's definition ([`perturb_bag::dynamic`]): a type the
//! project has never seen works as long as its definition is known (ROS 1 publishers send it
//! with every connection; for ROS 2 the built-in types below, or a `definition` in the
//! configuration).
//!
//! Over ROS 2 these topics always use a RustDDS participant (small messages need no fragment
//! reassembly, where RustDDS is slow), also in a bridge whose sensor topics use Cyclone DDS.

use crate::dds::Qos;
use crate::dds::rustdds_backend::RustddsBackend;
use crate::ros1::{Node, Publisher, Subscriber};
use anyhow::{Context, Result};
use perturb_bag::dynamic::{FieldPath, MessageCodec, Value};
use perturb_core::formats::kinds::Kind;
use perturb_core::formats::ros1::MsgType;
use std::sync::Arc;
use std::time::Duration;

/// How the bytes of a message are serialized.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Wire {
    /// ROS 1 (TCPROS, `.bag`).
    Ros1,
    /// ROS 2 CDR with the 4-byte encapsulation header.
    Cdr,
}

/// A small message type: its row of the message-kind table, and the ROS 2 definition the
/// bridge decodes it by (empty for a type it only relays).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SmallType {
    /// The kind.
    pub kind: Kind,
    /// The ROS 2 definition (`ros2msg`, with its dependencies).
    pub ros2_definition: &'static str,
}

impl SmallType {
    /// The ROS 1 type.
    pub fn ros1(&self) -> MsgType {
        self.kind.info().ros1
    }

    /// The DDS type name (`std_msgs::msg::dds_::Bool_`).
    pub fn dds_name(&self) -> &'static str {
        self.kind.info().dds_name
    }
}

/// The DDS type name of a ROS 2 type (`pkg/msg/Type` -> `pkg::msg::dds_::Type_`), for types
/// outside the message-kind table.
pub fn dds_name(ros2: &str) -> String {
    if let Some(k) = Kind::parse(ros2) {
        return k.info().dds_name.to_string();
    }
    let parts: Vec<&str> = ros2.split('/').collect();
    match parts.as_slice() {
        [pkg, sub, ty] => format!("{pkg}::{sub}::dds_::{ty}_"),
        [pkg, ty] => format!("{pkg}::msg::dds_::{ty}_"),
        _ => ros2.to_string(),
    }
}

const SEP: &str =
    "================================================================================\n";

/// `std_msgs/String`.
pub const STRING: SmallType = SmallType {
    kind: Kind::String,
    ros2_definition: "string data\n",
};

/// `std_msgs/Bool`.
pub const BOOL: SmallType = SmallType {
    kind: Kind::Bool,
    ros2_definition: "bool data\n",
};

/// `sensor_msgs/CameraInfo` (relayed as bytes, never decoded: no ROS 2 definition needed).
pub const CAMERA_INFO: SmallType = SmallType {
    kind: Kind::CameraInfo,
    ros2_definition: "",
};

const ROS2_HEADER: &str = "MSG: std_msgs/Header\nbuiltin_interfaces/Time stamp\nstring frame_id\n";
const ROS2_POSE: &str = "MSG: geometry_msgs/Pose\nPoint position\nQuaternion orientation\n";
const ROS2_POINT: &str = "MSG: geometry_msgs/Point\nfloat64 x\nfloat64 y\nfloat64 z\n";
const ROS2_QUAT: &str =
    "MSG: geometry_msgs/Quaternion\nfloat64 x 0\nfloat64 y 0\nfloat64 z 0\nfloat64 w 1\n";

/// The ROS 2 definitions the bridge knows by type name (the kill switch's and the pose's usual
/// types); any other type needs its definition in the configuration.
pub fn ros2_definition(type_name: &str) -> Option<String> {
    let t = perturb_bag::dynamic::normalize_type_name(type_name);
    let with = |root: &str, deps: &[&str]| {
        let mut s = root.to_string();
        for d in deps {
            s.push_str(SEP);
            s.push_str(d);
        }
        s
    };
    Some(match t.as_str() {
        "std_msgs/Bool" => BOOL.ros2_definition.to_string(),
        "std_msgs/String" => STRING.ros2_definition.to_string(),
        "geometry_msgs/PoseStamped" => with(
            "std_msgs/Header header\ngeometry_msgs/Pose pose\n",
            &[ROS2_HEADER, ROS2_POSE, ROS2_POINT, ROS2_QUAT],
        ),
        "geometry_msgs/PoseWithCovarianceStamped" => with(
            "std_msgs/Header header\ngeometry_msgs/PoseWithCovariance pose\n",
            &[
                ROS2_HEADER,
                "MSG: geometry_msgs/PoseWithCovariance\nPose pose\nfloat64[36] covariance\n",
                ROS2_POSE,
                ROS2_POINT,
                ROS2_QUAT,
            ],
        ),
        "nav_msgs/Odometry" => with(
            "std_msgs/Header header\nstring child_frame_id\n\
             geometry_msgs/PoseWithCovariance pose\ngeometry_msgs/TwistWithCovariance twist\n",
            &[
                ROS2_HEADER,
                "MSG: geometry_msgs/PoseWithCovariance\nPose pose\nfloat64[36] covariance\n",
                ROS2_POSE,
                ROS2_POINT,
                ROS2_QUAT,
                "MSG: geometry_msgs/TwistWithCovariance\nTwist twist\nfloat64[36] covariance\n",
                "MSG: geometry_msgs/Twist\nVector3 linear\nVector3 angular\n",
                "MSG: geometry_msgs/Vector3\nfloat64 x\nfloat64 y\nfloat64 z\n",
            ],
        ),
        _ => return None,
    })
}

/// One received small message.
pub struct SmallMsg<'a> {
    /// Its bytes.
    pub data: &'a [u8],
    /// How they are serialized.
    pub wire: Wire,
    /// The type's name as the publisher gave it (ROS 1) or as configured (ROS 2).
    pub type_name: &'a str,
    /// Its full definition, when known.
    pub definition: Option<&'a str>,
}

/// Writes small messages on one topic.
pub trait SmallWriter: Send {
    /// The serialization this writer takes.
    fn wire(&self) -> Wire;
    /// Publishes one message (bytes in [`SmallWriter::wire`]).
    fn write(&mut self, bytes: &[u8]) -> Result<()>;
}

/// Reads small messages from one topic.
pub trait SmallReader: Send {
    /// Waits up to `timeout` and passes every available message to `f`; returns how many.
    fn take(&mut self, timeout: Duration, f: &mut dyn FnMut(SmallMsg<'_>)) -> Result<usize>;
    /// Publishers connected now, when the transport knows.
    fn publishers(&self) -> Option<usize>;
}

/// Where small topics are opened: the bridge's ROS 1 node, or a RustDDS participant.
#[derive(Clone)]
pub enum SmallEndpoint {
    /// ROS 1.
    Ros1(Arc<Node>),
    /// ROS 2 over a RustDDS participant.
    Dds(Arc<RustddsBackend>),
}

/// A ROS 1 subscription of any type (`*`): the publisher's header says what it sends.
pub const ANY: MsgType = MsgType {
    name: "*",
    ros2_name: "*",
    md5sum: "*",
    definition: "",
};

impl SmallEndpoint {
    /// How adapter names mark the transport: `ros1:` before a ROS 1 topic, nothing for ROS 2.
    pub fn prefix(&self) -> &'static str {
        match self {
            SmallEndpoint::Ros1(_) => "ros1:",
            SmallEndpoint::Dds(_) => "",
        }
    }

    /// A writer of `ty` on `topic`.
    pub fn writer(&self, topic: &str, ty: SmallType, qos: Qos) -> Result<Box<dyn SmallWriter>> {
        Ok(match self {
            SmallEndpoint::Ros1(n) => Box::new(Ros1Small {
                publisher: n.advertise(topic, ty.ros1())?,
            }),
            SmallEndpoint::Dds(d) => Box::new(DdsSmall {
                writer: d.raw_writer(topic, ty.dds_name(), qos)?,
            }),
        })
    }

    /// A reader of `topic`: over ROS 1 of any type (the publisher says which), over ROS 2 of
    /// `ros2_type` (its DDS type name must match the publisher's).
    pub fn reader(
        &self,
        topic: &str,
        ros2_type: &str,
        qos: Qos,
        queue: usize,
    ) -> Result<Box<dyn SmallReader>> {
        Ok(match self {
            SmallEndpoint::Ros1(n) => Box::new(Ros1SmallReader {
                sub: n.subscribe(topic, ANY, queue)?,
            }),
            SmallEndpoint::Dds(d) => Box::new(DdsSmallReader {
                reader: d.raw_reader(topic, &dds_name(ros2_type), qos)?,
                type_name: ros2_type.to_string(),
                definition: ros2_definition(ros2_type),
            }),
        })
    }
}

struct Ros1Small {
    publisher: Publisher,
}

impl SmallWriter for Ros1Small {
    fn wire(&self) -> Wire {
        Wire::Ros1
    }
    fn write(&mut self, bytes: &[u8]) -> Result<()> {
        self.publisher.publish(&[bytes]);
        Ok(())
    }
}

struct Ros1SmallReader {
    sub: Subscriber,
}

impl SmallReader for Ros1SmallReader {
    fn take(&mut self, timeout: Duration, f: &mut dyn FnMut(SmallMsg<'_>)) -> Result<usize> {
        let mut n = 0;
        let mut next = self.sub.recv(timeout);
        while let Some(m) = next {
            f(SmallMsg {
                data: &m.data,
                wire: Wire::Ros1,
                type_name: &m.conn.type_name,
                definition: Some(&m.conn.definition),
            });
            n += 1;
            self.sub.recycle(m.data);
            next = self.sub.try_recv();
        }
        Ok(n)
    }

    fn publishers(&self) -> Option<usize> {
        Some(self.sub.publishers())
    }
}

struct DdsSmall {
    writer: crate::dds::rustdds_backend::RawWriter,
}

impl SmallWriter for DdsSmall {
    fn wire(&self) -> Wire {
        Wire::Cdr
    }
    fn write(&mut self, bytes: &[u8]) -> Result<()> {
        Ok(self.writer.write(bytes)?)
    }
}

struct DdsSmallReader {
    reader: crate::dds::rustdds_backend::RawReader,
    type_name: String,
    definition: Option<String>,
}

impl SmallReader for DdsSmallReader {
    fn take(&mut self, timeout: Duration, f: &mut dyn FnMut(SmallMsg<'_>)) -> Result<usize> {
        let (ty, def) = (self.type_name.as_str(), self.definition.as_deref());
        Ok(self.reader.take(timeout, &mut |cdr: &[u8]| {
            f(SmallMsg {
                data: cdr,
                wire: Wire::Cdr,
                type_name: ty,
                definition: def,
            })
        })?)
    }

    fn publishers(&self) -> Option<usize> {
        self.reader.publishers()
    }
}

/// Encodes a `std_msgs/String` for `wire`.
pub fn encode_string(wire: Wire, s: &str) -> Vec<u8> {
    match wire {
        Wire::Ros1 => perturb_core::formats::ros1::encode_string(s),
        Wire::Cdr => perturb_bag::events::encode_string(s),
    }
}

/// Reads one field of small messages by path, whatever their type, with a codec per type
/// (built from the definition the first message of that type brings).
pub struct FieldReader {
    path: String,
    /// (type name, codec, parsed path) of the last type seen.
    codec: Option<(String, MessageCodec, FieldPath)>,
    /// A definition given in the configuration (ROS 2 types the bridge does not know).
    definition: Option<String>,
}

impl FieldReader {
    /// Reads `path` (`data`, `pose.pose.position`); `definition`: the type's definition when
    /// the messages do not bring one.
    pub fn new(path: &str, definition: Option<String>) -> Self {
        FieldReader {
            path: path.to_string(),
            codec: None,
            definition,
        }
    }

    /// The field's value in `m`.
    pub fn read(&mut self, m: &SmallMsg<'_>) -> Result<Value> {
        if self.codec.as_ref().is_none_or(|(t, _, _)| t != m.type_name) {
            let def = m
                .definition
                .filter(|d| !d.is_empty())
                .map(str::to_string)
                .or_else(|| self.definition.clone())
                .with_context(|| {
                    format!(
                        "no definition of `{}` to read `{}` from (give `definition` in the configuration)",
                        m.type_name, self.path
                    )
                })?;
            let (dialect, encoding) = match m.wire {
                Wire::Ros1 => ("ros1msg", "ros1"),
                Wire::Cdr => ("ros2msg", "cdr"),
            };
            let codec = MessageCodec::new(m.type_name, dialect, def.as_bytes(), encoding)
                .with_context(|| format!("the definition of `{}`", m.type_name))?;
            let path = codec.path(&self.path)?;
            self.codec = Some((m.type_name.to_string(), codec, path));
        }
        let (_, codec, path) = self.codec.as_ref().expect("set above");
        Ok(codec.get(m.data, path)?)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn dds_names_and_known_definitions() {
        assert_eq!(dds_name("std_msgs/msg/Bool"), "std_msgs::msg::dds_::Bool_");
        assert_eq!(BOOL.dds_name(), "std_msgs::msg::dds_::Bool_");
        for t in [
            "geometry_msgs/msg/PoseStamped",
            "nav_msgs/msg/Odometry",
            "geometry_msgs/PoseWithCovarianceStamped",
        ] {
            let def = ros2_definition(t).unwrap();
            let codec = MessageCodec::new(t, "ros2msg", def.as_bytes(), "cdr").unwrap();
            let path = perturb_bag::dynamic::position_path(&codec)
                .unwrap_or_else(|| panic!("{t}: no position"));
            assert!(path.starts_with("pose."), "{t}: {path}");
        }
    }

    #[test]
    fn a_field_reader_reads_a_bool_in_both_serializations() {
        let mut r = FieldReader::new("data", None);
        let ros1 = [1u8];
        let v = r
            .read(&SmallMsg {
                data: &ros1,
                wire: Wire::Ros1,
                type_name: "std_msgs/Bool",
                definition: Some("bool data\n"),
            })
            .unwrap();
        assert_eq!(v.as_bool(), Some(true));
        let cdr = [0u8, 1, 0, 0, 0];
        let v = r
            .read(&SmallMsg {
                data: &cdr,
                wire: Wire::Cdr,
                type_name: "std_msgs/msg/Bool",
                definition: ros2_definition("std_msgs/msg/Bool").as_deref(),
            })
            .unwrap();
        assert_eq!(v.as_bool(), Some(false));
        let e = FieldReader::new("data", None)
            .read(&SmallMsg {
                data: &cdr,
                wire: Wire::Cdr,
                type_name: "my_msgs/msg/Engage",
                definition: None,
            })
            .unwrap_err();
        assert!(
            e.to_string()
                .contains("no definition of `my_msgs/msg/Engage`"),
            "{e}"
        );
    }
}
