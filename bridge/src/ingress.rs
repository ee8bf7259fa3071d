//! Ingress: a ROS 2 (DDS) or ROS 1 (TCPROS) sensor topic into `<stream>/raw`.
//!
//! Images and point clouds are checked (geometry, step, data length, point layout) and published
//! from the receive buffer straight into the bus. Compressed images (jpeg, png) are decoded
//! first. A message that does not decode or does not check is logged, counted and skipped. A
//! ROS 1 message's header `seq` becomes the frame's sequence number (so the egress writes it
//! back and the daemon counts gaps as frames lost upstream); over ROS 2 the ingress numbers the
//! frames itself.

use crate::adapter::{Adapter, Control, POLL};
use crate::bus::{Bus, Side};
use crate::dds::{Received, RosType, TopicSpec};
use crate::endpoint::Endpoint;
use crate::frame::{FrameMeta, OwnedPayload, Payload, StreamKind, monotonic_ns, wall_ns};
use crate::stats::{AdapterReport, log_bad};
use anyhow::Result;

/// One ingress mapping.
pub struct Ingress {
    /// The topic.
    pub spec: TopicSpec,
    /// The stream.
    pub stream: String,
    /// The DDS participant of the ingress direction, or the ROS 1 node.
    pub endpoint: Endpoint,
}

impl Adapter for Ingress {
    fn name(&self) -> String {
        let ros1 = matches!(self.endpoint, Endpoint::Ros1(_));
        format!(
            "ingress {}{} -> {}/raw",
            if ros1 { "ros1:" } else { "" },
            self.spec.topic,
            self.stream
        )
    }

    fn is_sink(&self) -> bool {
        false
    }

    fn run(self: Box<Self>, bus: &dyn Bus, mut ctl: Control) -> Result<AdapterReport> {
        let name = self.name();
        let kind = match self.spec.ros_type {
            RosType::PointCloud2 => StreamKind::Cloud,
            _ => StreamKind::Image,
        };
        let mut publisher = bus.publisher(&self.stream, kind, Side::Raw)?;
        let mut reader = self.endpoint.reader(&self.spec)?;
        ctl.ready();
        let mut rep = AdapterReport {
            name: name.clone(),
            ..Default::default()
        };
        let mut seq = 0u64;
        while !ctl.stopped() {
            let mut handle =
                |ros1_seq: Option<u32>, r: Result<Received<'_>, perturb_core::Error>| {
                    rep.received += 1;
                    let t_source = monotonic_ns();
                    let meta = FrameMeta {
                        seq: ros1_seq.map_or(seq, u64::from),
                        log_time: wall_ns(),
                        applied: None,
                        hops: crate::frame::Hops {
                            source: t_source,
                            ..Default::default()
                        },
                    };
                    let owned;
                    let payload = match r {
                        Ok(Received::Image(m)) => Payload::Image(m),
                        Ok(Received::Cloud(m)) => Payload::Cloud(m),
                        Ok(Received::Compressed(c)) => {
                            match perturb_core::formats::picture::decode(c.data) {
                                Ok(image) => {
                                    owned = OwnedPayload::Image {
                                        sec: c.header.stamp_sec,
                                        nanosec: c.header.stamp_nanosec,
                                        frame_id: c.header.frame_id.to_string(),
                                        image,
                                    };
                                    owned.payload()
                                }
                                Err(e) => {
                                    rep.bad += 1;
                                    log_bad(
                                        &name,
                                        rep.bad,
                                        &format!("compressed image ({}): {e}", c.format),
                                    );
                                    return;
                                }
                            }
                        }
                        Err(e) => {
                            rep.bad += 1;
                            log_bad(&name, rep.bad, &e);
                            return;
                        }
                    };
                    if let Err(e) = payload.validate() {
                        rep.bad += 1;
                        log_bad(&name, rep.bad, &e);
                        return;
                    }
                    match publisher.publish(&meta, &payload) {
                        Ok(()) => {
                            rep.forwarded += 1;
                            seq += 1;
                        }
                        Err(e) => {
                            rep.failed += 1;
                            log_bad(&name, rep.failed, &e);
                        }
                    }
                };
            if let Err(e) = reader.take(POLL, &mut handle) {
                rep.failed += 1;
                log_bad(&name, rep.failed, &e);
            }
        }
        rep.undelivered = publisher.undelivered();
        rep.lost = reader.lost();
        rep.dropped = reader.dropped();
        Ok(rep)
    }
}
