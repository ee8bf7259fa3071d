//! ROS 1 over TCPROS, natively (no ROS installation needed to build or run the bridge): a node
//! that registers with the ROS master over XML-RPC, serves the node API, publishes and
//! subscribes sensor topics over TCPROS, and behind [`crate::endpoint`] carries ingress and
//! egress like the DDS backends do.
//!
//! - [`xmlrpc`]: XML-RPC values, client and server; [`tcpros`]: connection headers and framing.
//! - [`node`]: the node, its API, its TCPROS server and its registration supervisor (waits for a
//!   master that is not up yet, registers again when the master restarts).
//! - [`publisher`] and [`subscriber`]: one thread per connected peer; a slow or vanished peer
//!   only affects itself.
//!
//! Messages are `sensor_msgs/Image`, `sensor_msgs/CompressedImage` (ingress, decoded) and
//! `sensor_msgs/PointCloud2` with the md5sums the ROS 1 tools expect; the header `seq`, stamp
//! and frame_id pass through exactly (the ingress uses a ROS 1 message's `seq` as the frame's
//! sequence number, and the egress writes the frame's sequence number as `seq`).
//!
//! Why not the `roslibrust` crate: see the README (ROS 1 section): it needs a tokio runtime and
//! an HTTP stack the bridge does not otherwise build, does not report a publisher's `error`
//! header, and hands messages over as owned buffers; this client is small, synchronous like the
//! rest of the bridge, and writes a message from shared memory with one copy.

pub mod node;
pub mod publisher;
pub mod subscriber;
pub mod tcpros;
pub mod xmlrpc;

pub use node::Node;
pub use publisher::{Publisher, SHARED_IN_FLIGHT, SharedData};
pub use subscriber::Subscriber;

use crate::bus::Held;
use crate::dds::{Received, RosType, TopicSpec};
use crate::frame::Payload;
use crate::topic::{OnMessage, Ros1Seq, TopicReader, TopicWriter};
use perturb_core::formats::ros::{CompressedImageMsg, ImageMsg, PointCloud2Msg};
use perturb_core::formats::ros1::{self, MsgType};
use std::collections::HashMap;
use std::sync::Arc;
use std::time::Duration;

/// A ROS 1 error, naming what failed.
#[derive(Debug, thiserror::Error)]
pub enum Ros1Error {
    /// Starting the node or opening a topic failed.
    #[error("ROS 1 setup of {what}: {reason}")]
    Setup {
        /// What (`the TCPROS server`, a topic).
        what: String,
        /// Why.
        reason: String,
    },
}

/// How the node reaches the master and presents itself.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Ros1Settings {
    /// The master's XML-RPC URI (`http://127.0.0.1:11311/`).
    pub master_uri: String,
    /// The host name or address other nodes use to reach this node.
    pub host: String,
    /// The node's global name (`/perturb_bridge`).
    pub node_name: String,
}

impl Ros1Settings {
    /// Settings from explicit values, falling back like the ROS 1 client libraries:
    /// `ROS_MASTER_URI` (else `http://localhost:11311/`), `ROS_HOSTNAME`, then `ROS_IP` (else
    /// this machine's host name), and the node name made global.
    pub fn resolve(
        master_uri: Option<&str>,
        hostname: Option<&str>,
        node_name: &str,
    ) -> Result<Self, String> {
        let env = |k: &str| std::env::var(k).ok().filter(|v| !v.trim().is_empty());
        let master_uri = master_uri
            .map(str::to_string)
            .or_else(|| env("ROS_MASTER_URI"))
            .unwrap_or_else(|| "http://localhost:11311/".into());
        xmlrpc::split_uri(&master_uri).map_err(|e| format!("master_uri: {e}"))?;
        let host = hostname
            .map(str::to_string)
            .or_else(|| env("ROS_HOSTNAME"))
            .or_else(|| env("ROS_IP"))
            .unwrap_or_else(machine_hostname);
        if host.is_empty() || host.contains('/') || host.contains(char::is_whitespace) {
            return Err(format!("hostname: `{host}` is not a host name or address"));
        }
        let name = node_name.trim();
        let ok = !name.is_empty()
            && name
                .trim_start_matches('/')
                .split('/')
                .all(|p| !p.is_empty() && p.chars().all(|c| c.is_ascii_alphanumeric() || c == '_'))
            && !name
                .trim_start_matches('/')
                .starts_with(|c: char| c.is_ascii_digit());
        if !ok {
            return Err(format!(
                "node_name: `{name}` is not a ROS name (letters, digits, `_`, `/` separators)"
            ));
        }
        Ok(Ros1Settings {
            master_uri,
            host,
            node_name: format!("/{}", name.trim_start_matches('/')),
        })
    }
}

// libc's gethostname.
#[allow(unsafe_code)]
fn machine_hostname() -> String {
    let mut buf = [0u8; 256];
    // SAFETY: gethostname writes at most buf.len() bytes into our buffer.
    let r = unsafe { libc::gethostname(buf.as_mut_ptr().cast(), buf.len()) };
    if r != 0 {
        return "localhost".into();
    }
    let n = buf.iter().position(|&b| b == 0).unwrap_or(buf.len());
    String::from_utf8_lossy(&buf[..n]).into_owned()
}

/// The ROS 1 type of a bridge message type.
pub fn msg_type(t: RosType) -> MsgType {
    t.kind().info().ros1
}

/// Decodes a ROS 1 message of `ty`: the header's `seq` and the message.
pub fn decode(ty: RosType, data: &[u8]) -> Result<(u32, Received<'_>), perturb_core::Error> {
    Ok(match ty {
        RosType::Image => {
            let (s, m) = ImageMsg::decode_ros1(data)?;
            (s, Received::Image(m))
        }
        RosType::CompressedImage => {
            let (s, m) = CompressedImageMsg::decode_ros1(data)?;
            (s, Received::Compressed(m))
        }
        RosType::PointCloud2 => {
            let (s, m) = PointCloud2Msg::decode_ros1(data)?;
            (s, Received::Cloud(m))
        }
    })
}

/// Messages an ingress subscription queues before the oldest is dropped.
const INGRESS_QUEUE: usize = 2;

/// The ROS 1 side of an ingress.
pub struct TopicReader1 {
    sub: Subscriber,
    ty: RosType,
    /// Last `seq` per publisher, for counting gaps.
    last: HashMap<Arc<str>, u32>,
    lost: u64,
}

impl TopicReader1 {
    /// Subscribes to `spec` on `node`.
    pub fn new(node: &Node, spec: &TopicSpec) -> Result<Self, Ros1Error> {
        Ok(TopicReader1 {
            sub: node.subscribe(&spec.topic, msg_type(spec.ros_type), INGRESS_QUEUE)?,
            ty: spec.ros_type,
            last: HashMap::new(),
            lost: 0,
        })
    }

    /// Messages of `publisher` missing before `seq` (counted in `lost`).
    fn count_gap(&mut self, publisher: &Arc<str>, seq: u32) -> u32 {
        match self.last.insert(publisher.clone(), seq) {
            Some(prev) if seq > prev => {
                let gap = seq - prev - 1;
                self.lost += u64::from(gap);
                gap
            }
            _ => 0,
        }
    }
}

impl TopicReader for TopicReader1 {
    fn take(&mut self, timeout: Duration, f: &mut OnMessage<'_>) -> anyhow::Result<usize> {
        let mut n = 0;
        let mut next = self.sub.recv(timeout);
        while let Some(m) = next {
            match decode(self.ty, &m.data) {
                Ok((seq, msg)) => {
                    let lost_before = self.count_gap(&m.publisher, seq);
                    f(Some(Ros1Seq { seq, lost_before }), Ok(msg));
                }
                Err(e) => f(None, Err(e)),
            }
            n += 1;
            self.sub.recycle(m.data);
            next = self.sub.try_recv();
        }
        Ok(n)
    }

    fn lost(&self) -> u64 {
        // The gaps include the messages this reader's own queue dropped: those are `dropped`.
        self.lost.saturating_sub(self.sub.dropped())
    }

    fn dropped(&self) -> u64 {
        self.sub.dropped()
    }
}

/// The ROS 1 side of an egress.
pub struct TopicWriter1 {
    publisher: Publisher,
}

impl TopicWriter1 {
    /// Advertises `spec` on `node`.
    pub fn new(node: &Node, spec: &TopicSpec) -> Result<Self, Ros1Error> {
        Ok(TopicWriter1 {
            publisher: node.advertise(&spec.topic, msg_type(spec.ros_type))?,
        })
    }
}

impl TopicWriter for TopicWriter1 {
    fn write(&mut self, seq: u64, msg: &Payload<'_>) -> anyhow::Result<()> {
        let parts = ros1_parts(msg, seq);
        self.publisher
            .publish(&[&parts.head, parts.data, &parts.tail]);
        Ok(())
    }

    fn write_held(&mut self, seq: u64, frame: Held) -> anyhow::Result<()> {
        let (head, tail) = {
            let parts = ros1_parts(&frame.payload(), seq);
            (parts.head, parts.tail)
        };
        self.publisher
            .publish_shared(&head, Box::new(HeldData(frame)), &tail);
        Ok(())
    }

    fn dropped(&self) -> u64 {
        self.publisher.dropped()
    }
}

/// The ROS 1 serialization of a frame with header `seq` (ROS 1 sequence numbers are 32 bits; a
/// longer run wraps, as roscpp's counter does).
fn ros1_parts<'a>(msg: &Payload<'a>, seq: u64) -> ros1::Ros1Parts<'a> {
    match msg {
        Payload::Image(m) => m.ros1_parts(seq as u32),
        Payload::Cloud(m) => m.ros1_parts(seq as u32),
    }
}

/// A held frame's data bytes, written to the subscribers from where they lie.
struct HeldData(Held);

impl publisher::SharedData for HeldData {
    fn data(&self) -> &[u8] {
        match self.0.payload() {
            Payload::Image(m) => m.data,
            Payload::Cloud(m) => m.data,
        }
    }
}

/// Publishes `/clock` (`rosgraph_msgs/Clock`) for nodes running with `use_sim_time`, as
/// `rosbag play --clock` does.
pub struct ClockPublisher {
    publisher: Publisher,
    last: Option<u64>,
}

impl ClockPublisher {
    /// Advertises `/clock` on `node`.
    pub fn new(node: &Node) -> Result<Self, Ros1Error> {
        Ok(ClockPublisher {
            publisher: node.advertise("/clock", ros1::CLOCK)?,
            last: None,
        })
    }

    /// Publishes simulated time `ns` (a looping replay goes back to the bag's start, as
    /// `rosbag play --clock --loop` does).
    pub fn publish(&mut self, ns: u64) {
        self.last = Some(ns);
        let msg = ros1::encode_clock(ns);
        self.publisher.publish(&[&msg]);
    }

    /// The last time published.
    pub fn last(&self) -> Option<u64> {
        self.last
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn settings_fall_back_and_check() {
        let s = Ros1Settings::resolve(
            Some("http://127.0.0.1:1/"),
            Some("127.0.0.1"),
            "perturb_bridge",
        )
        .unwrap();
        assert_eq!(s.node_name, "/perturb_bridge");
        assert!(Ros1Settings::resolve(Some("127.0.0.1:1"), Some("h"), "n").is_err());
        assert!(Ros1Settings::resolve(Some("http://h:1/"), Some("h"), "bad name").is_err());
        assert!(Ros1Settings::resolve(Some("http://h:1/"), Some("h"), "/ns/ok_name").is_ok());
    }
}
