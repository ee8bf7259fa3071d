//! The pure-Rust backend: ros2-client 0.12 (ROS naming, the ROS graph) on RustDDS 0.15 (the
//! wire).
//!
//! The data path uses RustDDS writers and readers with raw-CDR adapters: a message is serialised
//! once from the frame bytes into a buffer that RustDDS fragments onto the wire, and a received
//! sample is decoded in place from RustDDS's reassembly buffer (no owned message is built).

use super::interfaces::Interface;
use super::{
    DdsBackend, DdsError, DdsReader, DdsWriter, IncompatibleReaders, Received, RosType, TopicSpec,
};
use crate::frame::Payload;
use ros2_client::dds::rustdds::{
    self, QosPolicies, RepresentationIdentifier, TopicKind, bytes::Bytes, mio1, no_key,
};
use ros2_client::{Context, ContextOptions, NodeName, NodeOptions, QosProfile};
use std::cell::RefCell;
use std::time::Duration;

/// A CDR body (little-endian, without the encapsulation header).
pub struct RawCdr(Bytes);

/// Serialises [`RawCdr`] by handing RustDDS the bytes (reference counted, no copy).
pub struct RawWriteAdapter;

impl no_key::SerializerAdapter<RawCdr> for RawWriteAdapter {
    type Error = std::io::Error;
    fn output_encoding() -> RepresentationIdentifier {
        RepresentationIdentifier::CDR_LE
    }
    fn to_bytes(value: &RawCdr) -> Result<Bytes, Self::Error> {
        Ok(value.0.clone())
    }
}

/// What the reader produces: nothing; the decoder passes the bytes to a callback.
pub struct Taken;

/// Reads samples by calling back with their body and byte order.
pub struct RawReadAdapter;

/// An error of the raw decoder (never produced; the callback reports decode errors itself).
#[derive(Debug, thiserror::Error)]
#[error("raw CDR decode")]
pub struct RawDecodeError;

impl no_key::DeserializerAdapter<Taken> for RawReadAdapter {
    type Error = RawDecodeError;
    type Decoded = Taken;
    fn supported_encodings() -> &'static [RepresentationIdentifier] {
        &[
            RepresentationIdentifier::CDR_LE,
            RepresentationIdentifier::CDR_BE,
        ]
    }
    fn transform_decoded(decoded: Taken) -> Taken {
        decoded
    }
}

type Callback<'f> = RefCell<&'f mut dyn FnMut(&[u8], bool)>;

/// A decoder that hands each sample's bytes to a callback.
#[derive(Clone, Copy)]
struct CallbackDecoder<'f, 'g>(&'g Callback<'f>);

impl<'de> no_key::Decode<'de, Taken> for CallbackDecoder<'_, '_> {
    type Error = RawDecodeError;
    fn decode_bytes(
        self,
        input_bytes: &'de [u8],
        encoding: RepresentationIdentifier,
    ) -> Result<Taken, RawDecodeError> {
        (self.0.borrow_mut())(input_bytes, encoding == RepresentationIdentifier::CDR_LE);
        Ok(Taken)
    }
}

/// ros2-client / RustDDS: one DDS participant (a ROS 2 context with one node).
pub struct RustddsBackend {
    context: Context,
    node: std::sync::Mutex<ros2_client::Node>,
    publisher: rustdds::Publisher,
    subscriber: rustdds::Subscriber,
}

fn setup(topic: &str, e: impl std::fmt::Display) -> DdsError {
    DdsError::Setup {
        topic: topic.to_string(),
        reason: e.to_string(),
    }
}

impl RustddsBackend {
    /// Creates the participant on `domain_id` with a ROS node named `node` (visible in
    /// `ros2 node list` once its spinner runs; the bridge starts it). With `nets`, the
    /// participant joins multicast groups, sends and advertises locators on those interfaces
    /// only (and finds same-host peers by unicast to 127.0.0.1 when multicast is unavailable).
    pub fn new(domain_id: u16, node: &str, nets: Option<&[Interface]>) -> Result<Self, DdsError> {
        let context = match nets {
            None => Context::with_options(ContextOptions::new().domain_id(domain_id)),
            Some(nets) => {
                let dp = rustdds::DomainParticipantBuilder::new(domain_id)
                    .with_only_networks(nets.iter().map(|n| n.addr))
                    .build()
                    .map_err(|e| setup("participant", e))?;
                Context::from_domain_participant(dp)
            }
        }
        .map_err(|e| setup("participant", e))?;
        let name = NodeName::new("/", node).map_err(|e| setup("participant", e))?;
        let mut n = context
            .new_node(name, NodeOptions::new().enable_rosout(false))
            .map_err(|e| setup("participant", e))?;
        let participant = context.domain_participant();
        let qos = QosPolicies::qos_none();
        let publisher = participant
            .create_publisher(&qos)
            .map_err(|e| setup("participant", e))?;
        let subscriber = participant
            .create_subscriber(&qos)
            .map_err(|e| setup("participant", e))?;
        // The spinner answers ROS graph queries (node list, parameters); the data path does not
        // need it.
        if let Ok(spinner) = n.spinner() {
            std::thread::Builder::new()
                .name("ros2-spinner".into())
                .spawn(move || {
                    let _ = futures::executor::block_on(spinner.spin());
                })
                .map_err(|e| setup("participant", e))?;
        }
        Ok(RustddsBackend {
            context,
            node: std::sync::Mutex::new(n),
            publisher,
            subscriber,
        })
    }

    fn topic(&self, spec: &TopicSpec) -> Result<(rustdds::Topic, QosPolicies), DdsError> {
        let qos: QosPolicies = (&profile(spec)).into();
        let topic = self
            .context
            .domain_participant()
            .create_topic(
                spec.dds_topic(),
                spec.ros_type.dds_name().to_string(),
                &qos,
                TopicKind::NoKey,
            )
            .map_err(|e| setup(&spec.topic, e))?;
        Ok((topic, qos))
    }
}

/// The ros2-client QoS profile of a spec.
pub fn profile(spec: &TopicSpec) -> QosProfile {
    use ros2_client::qos::{Durability, History, Reliability, WhenFull};
    let base = QosProfile::subscription_default().history(History::KeepLast {
        depth: spec.qos.depth.max(1) as usize,
    });
    let base = match spec.qos.reliability {
        super::Reliability::BestEffort => base.reliability(Reliability::BestEffort),
        super::Reliability::Reliable => base.reliability(Reliability::Reliable {
            when_full: WhenFull::Wait(Duration::from_millis(100)),
        }),
    };
    match spec.qos.durability {
        super::Durability::Volatile => base.durability(Durability::Volatile),
        super::Durability::TransientLocal => base.durability(Durability::TransientLocal),
    }
}

impl DdsBackend for RustddsBackend {
    fn name(&self) -> &'static str {
        "rustdds"
    }

    fn writer(&self, spec: &TopicSpec) -> Result<Box<dyn DdsWriter>, DdsError> {
        if spec.ros_type == RosType::CompressedImage {
            return Err(setup(
                &spec.topic,
                "the bridge publishes raw images only (sensor_msgs/Image)",
            ));
        }
        let (topic, qos) = self.topic(spec)?;
        let writer = self
            .publisher
            .create_datawriter_no_key::<RawCdr, RawWriteAdapter>(&topic, Some(qos))
            .map_err(|e| setup(&spec.topic, e))?;
        let _ = &self.node;
        Ok(Box::new(RustddsWriter {
            writer,
            topic: spec.topic.clone(),
            incompatible: None,
        }))
    }

    fn reader(&self, spec: &TopicSpec) -> Result<Box<dyn DdsReader>, DdsError> {
        let (topic, qos) = self.topic(spec)?;
        let mut reader = self
            .subscriber
            .create_simple_datareader_no_key::<Taken, RawReadAdapter>(&topic, Some(qos))
            .map_err(|e| setup(&spec.topic, e))?;
        let poll = mio1::Poll::new().map_err(|e| setup(&spec.topic, e))?;
        poll.registry()
            .register(&mut reader, mio1::Token(0), mio1::Interest::READABLE)
            .map_err(|e| setup(&spec.topic, e))?;
        Ok(Box::new(RustddsReader {
            reader,
            poll,
            events: mio1::Events::with_capacity(4),
            spec: spec.clone(),
        }))
    }
}

struct RustddsWriter {
    writer: no_key::DataWriter<RawCdr, RawWriteAdapter>,
    topic: String,
    incompatible: Option<IncompatibleReaders>,
}

impl DdsWriter for RustddsWriter {
    fn write(&mut self, msg: &Payload<'_>) -> Result<(), DdsError> {
        // One copy: frame bytes -> CDR buffer; RustDDS slices its fragments out of it.
        let cdr = Bytes::from(msg.encode()).slice(4..);
        self.writer
            .write(RawCdr(cdr), Some(rustdds::Timestamp::now()))
            .map_err(|e| DdsError::Write {
                topic: self.topic.clone(),
                reason: e.to_string(),
            })
    }

    fn matched(&self) -> Option<usize> {
        None
    }

    fn incompatible_readers(&mut self) -> Option<IncompatibleReaders> {
        use rustdds::{DataWriterStatus, StatusEvented};
        while let Some(status) = self.writer.try_recv_status() {
            if let DataWriterStatus::OfferedIncompatibleQos {
                count,
                last_policy_id,
                ..
            } = status
            {
                self.incompatible = Some(IncompatibleReaders {
                    total: count.count().max(0) as u64,
                    policy: rustdds_policy(&format!("{last_policy_id:?}")),
                });
            }
        }
        self.incompatible.clone()
    }
}

/// RustDDS's `QosPolicyId` debug name (`Reliability`, `DestinationOrder`) in DDS spelling
/// (`RELIABILITY`, `DESTINATION_ORDER`).
fn rustdds_policy(debug: &str) -> String {
    let mut out = String::new();
    for (i, c) in debug.chars().enumerate() {
        if c.is_uppercase() && i > 0 {
            out.push('_');
        }
        out.push(c.to_ascii_uppercase());
    }
    out
}

struct RustddsReader {
    reader: no_key::SimpleDataReader<Taken, RawReadAdapter>,
    poll: mio1::Poll,
    events: mio1::Events,
    spec: TopicSpec,
}

// SAFETY: the reader is used from one thread at a time (the DdsReader trait takes `&mut self`);
// RustDDS's SimpleDataReader holds its state behind Arc/Mutex and channels that are Send, and the
// mio Poll is Send. The marker is needed because the adapter type parameters are not Sync.
// A Send marker for RustDDS's reader.
#[allow(unsafe_code)]
unsafe impl Send for RustddsReader {}

fn drain(
    reader: &no_key::SimpleDataReader<Taken, RawReadAdapter>,
    spec: &TopicSpec,
    f: &mut dyn FnMut(Result<Received<'_>, perturb_core::Error>),
) -> Result<usize, DdsError> {
    let ty = spec.ros_type;
    let mut n = 0usize;
    let mut cb = |body: &[u8], le: bool| {
        n += 1;
        f(super::decode_body(ty, body, le));
    };
    {
        let cell: Callback<'_> = RefCell::new(&mut cb);
        loop {
            reader.drain_read_notifications();
            match reader.try_take_one_with(CallbackDecoder(&cell)) {
                Ok(Some(_)) => continue,
                Ok(None) => break,
                Err(e) => {
                    return Err(DdsError::Read {
                        topic: spec.topic.clone(),
                        reason: e.to_string(),
                    });
                }
            }
        }
    }
    Ok(n)
}

impl DdsReader for RustddsReader {
    fn take(
        &mut self,
        timeout: Duration,
        f: &mut dyn FnMut(Result<Received<'_>, perturb_core::Error>),
    ) -> Result<usize, DdsError> {
        let n = drain(&self.reader, &self.spec, f)?;
        if n > 0 {
            return Ok(n);
        }
        // Nothing was there: wait for the reader's notification, then drain again.
        self.poll
            .poll(&mut self.events, Some(timeout))
            .map_err(|e| DdsError::Read {
                topic: self.spec.topic.clone(),
                reason: e.to_string(),
            })?;
        drain(&self.reader, &self.spec, f)
    }
}

/// A writer of CDR messages of any type on one topic (small messages: events, relays).
pub struct RawWriter {
    writer: no_key::DataWriter<RawCdr, RawWriteAdapter>,
    topic: String,
}

impl RawWriter {
    /// Publishes one message: CDR with its 4-byte encapsulation header (little-endian).
    pub fn write(&mut self, cdr: &[u8]) -> Result<(), DdsError> {
        let body = cdr.get(4..).ok_or_else(|| DdsError::Write {
            topic: self.topic.clone(),
            reason: format!(
                "a CDR message of {} bytes has no encapsulation header",
                cdr.len()
            ),
        })?;
        self.writer
            .write(
                RawCdr(Bytes::copy_from_slice(body)),
                Some(rustdds::Timestamp::now()),
            )
            .map_err(|e| DdsError::Write {
                topic: self.topic.clone(),
                reason: e.to_string(),
            })
    }
}

/// A reader of CDR messages of any type on one topic.
pub struct RawReader {
    reader: no_key::SimpleDataReader<Taken, RawReadAdapter>,
    poll: mio1::Poll,
    events: mio1::Events,
    topic: String,
}

// SAFETY: as for `RustddsReader`: used from one thread at a time (`&mut self`), RustDDS keeps its
// state behind Arc/Mutex and channels that are Send, the mio Poll is Send.
// A Send marker for RustDDS's reader.
#[allow(unsafe_code)]
unsafe impl Send for RawReader {}

impl RawReader {
    /// Waits up to `timeout` and passes every available message to `f` as CDR with its
    /// encapsulation header; returns how many.
    pub fn take(&mut self, timeout: Duration, f: &mut dyn FnMut(&[u8])) -> Result<usize, DdsError> {
        let mut n = self.drain(f)?;
        if n == 0 {
            self.poll
                .poll(&mut self.events, Some(timeout))
                .map_err(|e| DdsError::Read {
                    topic: self.topic.clone(),
                    reason: e.to_string(),
                })?;
            n = self.drain(f)?;
        }
        Ok(n)
    }

    fn drain(&self, f: &mut dyn FnMut(&[u8])) -> Result<usize, DdsError> {
        let mut n = 0usize;
        let mut buf = Vec::new();
        let mut cb = |body: &[u8], le: bool| {
            n += 1;
            buf.clear();
            buf.extend_from_slice(&[0, u8::from(le), 0, 0]);
            buf.extend_from_slice(body);
            f(&buf);
        };
        {
            let cell: Callback<'_> = RefCell::new(&mut cb);
            loop {
                self.reader.drain_read_notifications();
                match self.reader.try_take_one_with(CallbackDecoder(&cell)) {
                    Ok(Some(_)) => continue,
                    Ok(None) => break,
                    Err(e) => {
                        return Err(DdsError::Read {
                            topic: self.topic.clone(),
                            reason: e.to_string(),
                        });
                    }
                }
            }
        }
        Ok(n)
    }

    /// Writers matched now (not reported by this backend).
    pub fn publishers(&self) -> Option<usize> {
        None
    }
}

impl RustddsBackend {
    fn raw_topic(
        &self,
        topic: &str,
        dds_type: &str,
        qos: super::Qos,
    ) -> Result<(rustdds::Topic, QosPolicies), DdsError> {
        let spec = TopicSpec {
            topic: topic.to_string(),
            ros_type: RosType::Image,
            qos,
        };
        let qos: QosPolicies = (&profile(&spec)).into();
        let t = self
            .context
            .domain_participant()
            .create_topic(
                spec.dds_topic(),
                dds_type.to_string(),
                &qos,
                TopicKind::NoKey,
            )
            .map_err(|e| setup(topic, e))?;
        Ok((t, qos))
    }

    /// A writer of `dds_type` (`std_msgs::msg::dds_::String_`) on the ROS 2 `topic`.
    pub fn raw_writer(
        &self,
        topic: &str,
        dds_type: &str,
        qos: super::Qos,
    ) -> Result<RawWriter, DdsError> {
        let (t, q) = self.raw_topic(topic, dds_type, qos)?;
        let writer = self
            .publisher
            .create_datawriter_no_key::<RawCdr, RawWriteAdapter>(&t, Some(q))
            .map_err(|e| setup(topic, e))?;
        Ok(RawWriter {
            writer,
            topic: topic.to_string(),
        })
    }

    /// A reader of `dds_type` on the ROS 2 `topic`.
    pub fn raw_reader(
        &self,
        topic: &str,
        dds_type: &str,
        qos: super::Qos,
    ) -> Result<RawReader, DdsError> {
        let (t, q) = self.raw_topic(topic, dds_type, qos)?;
        let mut reader = self
            .subscriber
            .create_simple_datareader_no_key::<Taken, RawReadAdapter>(&t, Some(q))
            .map_err(|e| setup(topic, e))?;
        let poll = mio1::Poll::new().map_err(|e| setup(topic, e))?;
        poll.registry()
            .register(&mut reader, mio1::Token(0), mio1::Interest::READABLE)
            .map_err(|e| setup(topic, e))?;
        Ok(RawReader {
            reader,
            poll,
            events: mio1::Events::with_capacity(4),
            topic: topic.to_string(),
        })
    }
}
