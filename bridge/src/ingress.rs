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
use crate::camera_info::{Calibration, CameraInfoLink, ROS2_TYPE, stamp_of};
use crate::dds::{Received, RosType, TopicSpec};
use crate::endpoint::Endpoint;
use crate::frame::{FrameMeta, OwnedPayload, Payload, StreamKind, monotonic_ns, wall_ns};
use crate::msgs::SmallEndpoint;
use crate::stats::{AdapterReport, log_bad};
use crate::topic::Ros1Seq;
use anyhow::Result;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

/// One ingress mapping.
pub struct Ingress {
    /// The topic.
    pub spec: TopicSpec,
    /// The stream.
    pub stream: String,
    /// The DDS participant of the ingress direction, or the ROS 1 node.
    pub endpoint: Endpoint,
    /// The stream's camera_info source topic, where it is read, and what the egress of the
    /// stream takes it from.
    pub camera_info: Option<(String, SmallEndpoint, Arc<CameraInfoLink>)>,
}

/// Reads the camera_info topic into `link` until `stop` (a thread beside the ingress).
fn relay_camera_info(
    topic: &str,
    endpoint: &SmallEndpoint,
    link: &CameraInfoLink,
    stop: &AtomicBool,
    ready: crossbeam::channel::Sender<Result<()>>,
) -> u64 {
    let mut reader = match endpoint.reader(topic, ROS2_TYPE, crate::dds::Qos::default(), 16) {
        Ok(r) => {
            let _ = ready.send(Ok(()));
            r
        }
        Err(e) => {
            let _ = ready.send(Err(e));
            return 0;
        }
    };
    let name = format!("camera_info <- {topic}");
    let (mut got, mut bad) = (0u64, 0u64);
    while !stop.load(Ordering::Relaxed) {
        let r = reader.take(POLL, &mut |m| match stamp_of(m.data, m.wire) {
            Some(stamp) => {
                got += 1;
                link.push(Calibration {
                    stamp,
                    data: m.data.to_vec(),
                    wire: m.wire,
                    arrived: std::time::Instant::now(),
                });
            }
            None => {
                bad += 1;
                log_bad(&name, bad, &"a message too short to hold a header");
            }
        });
        if let Err(e) = r {
            bad += 1;
            log_bad(&name, bad, &e);
        }
    }
    got
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
        let stop_info = AtomicBool::new(false);
        std::thread::scope(|scope| -> Result<AdapterReport> {
            let info = match &self.camera_info {
                Some((topic, endpoint, link)) => {
                    let (tx, rx) = crossbeam::channel::bounded(1);
                    let stop = &stop_info;
                    let h = std::thread::Builder::new()
                        .name("camera-info".into())
                        .spawn_scoped(scope, move || {
                            relay_camera_info(topic, endpoint, link, stop, tx)
                        })?;
                    rx.recv()
                        .map_err(|_| anyhow::anyhow!("the camera_info reader ended at start"))??;
                    Some(h)
                }
                None => None,
            };
            let r = self.pump(&mut publisher, reader.as_mut(), &mut ctl, &name);
            stop_info.store(true, Ordering::Relaxed);
            let mut rep = r?;
            if let (Some(h), Some((topic, _, _))) = (info, &self.camera_info) {
                let n = h.join().unwrap_or(0);
                rep.notes
                    .push(format!("camera_info <- {topic}: {n} received"));
            }
            Ok(rep)
        })
    }
}

impl Ingress {
    /// Reads the topic into the stream until stopped.
    fn pump(
        &self,
        publisher: &mut Box<dyn crate::bus::BusPublisher>,
        reader: &mut dyn crate::topic::TopicReader,
        ctl: &mut Control,
        name: &str,
    ) -> Result<AdapterReport> {
        let name = name.to_string();
        ctl.ready();
        let mut rep = AdapterReport {
            name: name.clone(),
            ..Default::default()
        };
        let mut seq = 0u64;
        let mut lost_before = 0u32;
        while !ctl.stopped() {
            let mut handle =
                |ros1: Option<Ros1Seq>, r: Result<Received<'_>, perturb_core::Error>| {
                    rep.received += 1;
                    let t_source = monotonic_ns();
                    // Lost upstream since the last frame published: this one says so.
                    lost_before = lost_before.saturating_add(ros1.map_or(0, |s| s.lost_before));
                    let meta = FrameMeta {
                        seq: ros1.map_or(seq, |s| u64::from(s.seq)),
                        lost_before,
                        step: 0,
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
                            lost_before = 0;
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
        rep.lost_by_cause.upstream = rep.lost + rep.dropped;
        Ok(rep)
    }
}
