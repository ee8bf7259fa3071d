//! The topic side of an ingress or egress, over either transport: ROS 2 over DDS
//! ([`crate::dds`]) or ROS 1 over TCPROS ([`crate::ros1`]). Ingress and egress see only these
//! two traits, so a bridge can mix them (ROS 1 sensors in, ROS 2 out, or the other way round).

use crate::dds::{DdsBackend, DdsReader, DdsWriter, Received, TopicSpec};
use crate::frame::Payload;
use std::sync::Arc;
use std::time::Duration;

/// What a [`TopicReader`] calls for each message: the ROS 1 header `seq` (if any) and the
/// message, or why it does not decode.
pub type OnMessage<'f> = dyn FnMut(Option<u32>, Result<Received<'_>, perturb_core::Error>) + 'f;

/// Reads sensor messages from one topic.
pub trait TopicReader: Send {
    /// Waits up to `timeout` and passes every available message to `f` with the ROS 1 header
    /// `seq` (`None` over ROS 2, whose headers have none); a message that does not decode is
    /// passed as an error. Returns how many were passed.
    fn take(&mut self, timeout: Duration, f: &mut OnMessage<'_>) -> anyhow::Result<usize>;

    /// Messages known to be lost before they reached the reader (gaps in a ROS 1 publisher's
    /// header `seq`, which include messages dropped from a full queue).
    fn lost(&self) -> u64 {
        0
    }

    /// Messages the reader received and dropped itself because its queue was full.
    fn dropped(&self) -> u64 {
        0
    }
}

/// Writes sensor messages on one topic.
pub trait TopicWriter: Send {
    /// Publishes one message; `seq` is the frame's sequence number, written into the header
    /// where the message format has one (ROS 1).
    fn write(&mut self, seq: u64, msg: &Payload<'_>) -> anyhow::Result<()>;

    /// Messages written but dropped before they reached a subscriber (a ROS 1 subscriber slower
    /// than the stream); summed over subscribers, including those that left.
    fn dropped(&self) -> u64 {
        0
    }

    /// Readers that asked for a QoS this writer does not offer and therefore receive nothing
    /// (DDS; ROS 1 has no QoS), with what to change.
    fn incompatible_readers(&mut self) -> Option<String> {
        None
    }
}

/// Where an ingress or egress opens its topic.
#[derive(Clone)]
pub enum Endpoint {
    /// A ROS 2 DDS participant.
    Dds(Arc<dyn DdsBackend>),
    /// A ROS 1 node.
    Ros1(Arc<crate::ros1::Node>),
}

impl Endpoint {
    /// `dds (rustdds)` or `ros1`.
    pub fn describe(&self) -> String {
        match self {
            Endpoint::Dds(d) => format!("dds ({})", d.name()),
            Endpoint::Ros1(_) => "ros1".into(),
        }
    }

    /// A reader of `spec`.
    pub fn reader(&self, spec: &TopicSpec) -> anyhow::Result<Box<dyn TopicReader>> {
        Ok(match self {
            Endpoint::Dds(d) => Box::new(DdsTopicReader(d.reader(spec)?)),
            Endpoint::Ros1(n) => Box::new(crate::ros1::TopicReader1::new(n, spec)?),
        })
    }

    /// A writer of `spec`.
    pub fn writer(&self, spec: &TopicSpec) -> anyhow::Result<Box<dyn TopicWriter>> {
        Ok(match self {
            Endpoint::Dds(d) => Box::new(DdsTopicWriter(d.writer(spec)?, spec.clone())),
            Endpoint::Ros1(n) => Box::new(crate::ros1::TopicWriter1::new(n, spec)?),
        })
    }
}

struct DdsTopicReader(Box<dyn DdsReader>);

impl TopicReader for DdsTopicReader {
    fn take(&mut self, timeout: Duration, f: &mut OnMessage<'_>) -> anyhow::Result<usize> {
        Ok(self.0.take(timeout, &mut |r| f(None, r))?)
    }
}

struct DdsTopicWriter(Box<dyn DdsWriter>, TopicSpec);

impl TopicWriter for DdsTopicWriter {
    fn write(&mut self, _seq: u64, msg: &Payload<'_>) -> anyhow::Result<()> {
        Ok(self.0.write(msg)?)
    }

    fn incompatible_readers(&mut self) -> Option<String> {
        self.0.incompatible_readers().map(|r| r.explain(&self.1))
    }
}
