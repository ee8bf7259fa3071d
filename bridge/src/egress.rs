//! Egress: `<stream>/perturbed` out to a ROS 2 (DDS) or ROS 1 (TCPROS) topic, header stamp and
//! frame_id bit-exact (and, over ROS 1, the frame's sequence number as header `seq`).

use crate::adapter::{Adapter, Control, POLL};
use crate::bus::{Bus, Side};
use crate::dds::TopicSpec;
use crate::endpoint::Endpoint;
use crate::frame::{StreamKind, monotonic_ns};
use crate::stats::{AdapterReport, HopLatency, Latency, log_bad};
use anyhow::Result;
use std::time::Duration;

/// How often an egress asks its writer about readers with an incompatible QoS.
const QOS_CHECK: Duration = Duration::from_millis(500);

/// One egress mapping.
pub struct Egress {
    /// The stream.
    pub stream: String,
    /// What it carries.
    pub kind: StreamKind,
    /// The topic.
    pub spec: TopicSpec,
    /// Which side of the stream (perturbed, or raw in passthrough setups).
    pub side: Side,
    /// The DDS participant of the egress direction, or the ROS 1 node.
    pub endpoint: Endpoint,
}

impl Adapter for Egress {
    fn name(&self) -> String {
        let ros1 = matches!(self.endpoint, Endpoint::Ros1(_));
        format!(
            "egress {}/{} -> {}{}",
            self.stream,
            self.side.as_str(),
            if ros1 { "ros1:" } else { "" },
            self.spec.topic
        )
    }

    fn is_sink(&self) -> bool {
        true
    }

    fn run(self: Box<Self>, bus: &dyn Bus, mut ctl: Control) -> Result<AdapterReport> {
        let name = self.name();
        let mut writer = self.endpoint.writer(&self.spec)?;
        let mut sub = bus.subscriber(&self.stream, self.kind, self.side)?;
        ctl.ready();
        let mut rep = AdapterReport {
            name: name.clone(),
            ..Default::default()
        };
        let mut total = Latency::default();
        let mut hops = HopLatency::default();
        let mut qos_checked = std::time::Instant::now();
        let mut qos_warned = false;
        while !ctl.stopped() {
            // A reader whose QoS does not match gets nothing and DDS says nothing: say it once.
            if !qos_warned && qos_checked.elapsed() >= QOS_CHECK {
                qos_checked = std::time::Instant::now();
                if let Some(why) = writer.incompatible_readers() {
                    tracing::warn!("{name}: {why}");
                    rep.notes.push(why);
                    qos_warned = true;
                }
            }
            let r = sub.recv(POLL, &mut |meta, payload| {
                rep.received += 1;
                if payload.kind() != self.kind {
                    rep.bad += 1;
                    log_bad(&name, rep.bad, &"frame of the wrong kind for this topic");
                    return;
                }
                match writer.write(meta.seq, payload) {
                    Ok(()) => {
                        rep.forwarded += 1;
                        // The egress hop ends when the write returns (DDS: written; ROS 1:
                        // serialized and queued for every subscriber).
                        let mut h = meta.hops;
                        h.sink = monotonic_ns();
                        if h.source != 0 {
                            total.add(h.sink.saturating_sub(h.source));
                        }
                        hops.add(&h);
                    }
                    Err(e) => {
                        rep.failed += 1;
                        log_bad(&name, rep.failed, &e);
                    }
                }
            });
            if let Err(e) = r {
                rep.failed += 1;
                log_bad(&name, rep.failed, &e);
            }
            ctl.watch_publishers(sub.as_ref());
        }
        rep.dropped = writer.dropped();
        rep.latency = Some(total.summary());
        rep.hops.insert(
            format!("{}/{}", self.stream, self.side.as_str()),
            hops.summary(),
        );
        Ok(rep)
    }
}
