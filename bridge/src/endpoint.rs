//! Opening the topic side of an ingress or egress over either transport: ROS 2 over DDS
//! ([`crate::dds`]) or ROS 1 over TCPROS ([`crate::ros1`]), as the traits of [`crate::topic`].

use crate::dds::{DdsBackend, DdsReader, DdsWriter, TopicSpec};
use crate::frame::Payload;
use crate::topic::{OnMessage, TopicReader, TopicWriter};
use std::sync::Arc;
use std::time::Duration;

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
