//! The two traits an ingress and an egress see of a topic, whatever the transport (ROS 2 over DDS
//! or ROS 1 over TCPROS): a bridge can therefore mix them (ROS 1 sensors in, ROS 2 out, or the
//! other way round). [`crate::endpoint`] opens them.

use crate::bus::Held;
use crate::dds::Received;
use crate::frame::Payload;
use std::time::Duration;

/// A ROS 1 message's place in its publisher's stream.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Ros1Seq {
    /// The header's `seq`.
    pub seq: u32,
    /// Messages of the same publisher missing just before this one (a gap in `seq`): lost
    /// before the bridge, or dropped by the bridge's own queue (see [`TopicReader::dropped`]).
    pub lost_before: u32,
}

/// What a [`TopicReader`] calls for each message: where a ROS 1 message stands in its
/// publisher's `seq` (if it is one) and the message, or why it does not decode.
pub type OnMessage<'f> = dyn FnMut(Option<Ros1Seq>, Result<Received<'_>, perturb_core::Error>) + 'f;

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

    /// Publishes a held frame (see [`crate::bus::HeldFrame`]), which the writer may keep until
    /// its subscribers have it instead of copying it (ROS 1 does); the others write its payload.
    fn write_held(&mut self, seq: u64, frame: Held) -> anyhow::Result<()> {
        self.write(seq, &frame.payload())
    }

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
