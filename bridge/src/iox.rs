//! The iceoryx2 bus: frames go through shared memory with `perturbd` in between, over the
//! [`perturb_wire`] frame format.
//!
//! - A publisher copies the ROS message's pixel or point bytes once, into a loaned sample, with
//!   the header (sequence number, stamp, frame_id, geometry or full point layout, source hop
//!   stamp) in the sample's user header.
//! - A subscriber hands each sample to the adapter in place (no copy): the [`Payload`] borrows
//!   the shared memory. A frame whose header and payload disagree is logged, counted and
//!   skipped.

use crate::bus::{Bus, BusPublisher, BusSubscriber, Held, HeldFrame, Side};
use crate::config::BridgeSection;
use crate::frame::{Applied, FrameMeta, Hops, Payload, StreamKind};
use anyhow::{Context, Result};
use perturb_core::cloud::PointLayout;
use perturb_core::formats::ros::{Header, ImageMsg, PointCloud2Msg};
use perturb_wire::{
    FrameHeader, FramePublisher, FrameSubscriber, Hop, LayoutCache, Stamp, StreamQos, Transport,
    TransportOptions, WireModality,
};
use std::sync::{Arc, Mutex};
use std::time::Duration;
use tracing::{info, warn};

/// The iceoryx2 bus of the bridge `section` (its namespace and QoS).
pub fn bus(section: &BridgeSection) -> Result<Arc<dyn Bus>> {
    let options = section.iox2.clone().with_env_overrides();
    let transport = Transport::open(&section.name, &options)
        .with_context(|| format!("joining the iceoryx2 namespace {}", options.describe()))?;
    Ok(Arc::new(IoxBus {
        transport: Mutex::new(transport),
        retired: Arc::default(),
        options,
        qos: section.qos,
    }))
}

/// Frames through iceoryx2 shared memory.
pub struct IoxBus {
    transport: Mutex<Transport>,
    /// Publishers of finished sources, kept until the bus goes: iceoryx2 takes a publisher's
    /// undelivered samples away with it, so a source that ends (a replayed bag) would take its
    /// last frames from a slower reader (the recorder) that has not received them yet.
    retired: Arc<Mutex<Vec<FramePublisher>>>,
    options: TransportOptions,
    qos: StreamQos,
}

impl IoxBus {
    fn service(stream: &str, side: Side) -> String {
        match side {
            Side::Raw => perturb_wire::names::raw(stream),
            Side::Perturbed => perturb_wire::names::perturbed(stream),
        }
    }

    fn transport(&self) -> Result<std::sync::MutexGuard<'_, Transport>> {
        self.transport
            .lock()
            .map_err(|_| anyhow::anyhow!("iceoryx2 transport poisoned"))
    }
}

impl Bus for IoxBus {
    fn name(&self) -> &'static str {
        "iceoryx2"
    }

    fn sweep_dead(&self) {
        match self.transport().map(|t| t.sweep_dead_nodes()) {
            Ok(Ok(r)) if r.removed > 0 => info!(
                removed = r.removed,
                "removed the shared memory of dead processes"
            ),
            Ok(Err(e)) => warn!("sweeping dead processes: {e}"),
            _ => {}
        }
    }

    fn publisher(
        &self,
        stream: &str,
        kind: StreamKind,
        side: Side,
    ) -> Result<Box<dyn BusPublisher>> {
        let service = Self::service(stream, side);
        let initial = match kind {
            StreamKind::Image => 1920 * 1208 * 3,
            StreamKind::Cloud => 130_000 * 32,
        };
        let publisher = self
            .transport()?
            .publisher(&service, &self.qos, Hop::Keep, initial)
            .with_context(|| {
                format!(
                    "publisher on `{service}` (iceoryx2 {})",
                    self.options.describe()
                )
            })?;
        Ok(Box::new(IoxPublisher {
            publisher: Some(publisher),
            retired: self.retired.clone(),
            undelivered: 0,
        }))
    }

    fn subscriber(
        &self,
        stream: &str,
        _kind: StreamKind,
        side: Side,
    ) -> Result<Box<dyn BusSubscriber>> {
        let service = Self::service(stream, side);
        let subscriber = self
            .transport()?
            .subscriber(&service, &self.qos, None)
            .with_context(|| {
                format!(
                    "subscriber on `{service}` (iceoryx2 {})",
                    self.options.describe()
                )
            })?;
        Ok(Box::new(IoxSubscriber {
            subscriber,
            layouts: LayoutCache::default(),
            invalid: 0,
        }))
    }
}

struct IoxPublisher {
    publisher: Option<FramePublisher>,
    retired: Arc<Mutex<Vec<FramePublisher>>>,
    undelivered: u64,
}

impl Drop for IoxPublisher {
    fn drop(&mut self) {
        if let (Some(p), Ok(mut r)) = (self.publisher.take(), self.retired.lock()) {
            r.push(p);
        }
    }
}

/// The wire header of a ROS message.
pub fn header_of(meta: &FrameMeta, payload: &Payload<'_>) -> Result<FrameHeader> {
    let h = payload.header();
    let stamp = Stamp {
        sec: h.stamp_sec,
        nanosec: h.stamp_nanosec,
    };
    let mut header = match payload {
        Payload::Image(m) => {
            let mut w = FrameHeader::image(
                meta.seq, stamp, h.frame_id, m.width, m.height, m.step, m.encoding,
            )?;
            w.is_bigendian = m.is_bigendian;
            w
        }
        Payload::Cloud(m) => FrameHeader::cloud(
            meta.seq,
            stamp,
            h.frame_id,
            &m.layout()?,
            m.width,
            m.height,
            m.row_step,
            m.is_dense,
        )?,
    };
    header.data_len = payload.data().len() as u64;
    header.t_ingress_ns = if meta.hops.source != 0 {
        meta.hops.source
    } else {
        perturb_wire::monotonic_ns()
    };
    header.lost_before = meta.lost_before;
    header.t_daemon_rx_ns = meta.hops.daemon_in;
    header.t_daemon_tx_ns = meta.hops.daemon_out;
    if let Some(a) = &meta.applied {
        let entry = perturb_core::registry::find_with_severity(&a.id, a.severity)?;
        let spec = perturb_core::perturber::Spec {
            entry,
            severity: a.severity,
            seed: a.seed,
        };
        header.set_applied(Some(&spec));
    }
    Ok(header)
}

impl BusPublisher for IoxPublisher {
    fn publish(&mut self, meta: &FrameMeta, payload: &Payload<'_>) -> Result<()> {
        let header = header_of(meta, payload)?;
        let Some(publisher) = self.publisher.as_mut() else {
            anyhow::bail!("publisher already retired");
        };
        let reached = publisher
            .publish_raw(header, payload.data())
            .with_context(|| format!("publishing frame {}", meta.seq))?;
        if reached == 0 {
            self.undelivered += 1;
            if self.undelivered == 1 || self.undelivered.is_multiple_of(100) {
                warn!(
                    service = publisher.service(),
                    seq = meta.seq,
                    undelivered = self.undelivered,
                    "no reader (perturbd) on the stream: frame lost"
                );
            }
        }
        Ok(())
    }

    fn undelivered(&self) -> u64 {
        self.undelivered
    }
}

struct IoxSubscriber {
    subscriber: FrameSubscriber,
    layouts: LayoutCache,
    invalid: u64,
}

/// The message a frame holds, borrowing its shared memory (`layout`: the parsed point layout of
/// a cloud, `None` for an image).
fn payload_of<'a>(
    frame: &'a perturb_wire::Frame,
    layout: Option<&Arc<PointLayout>>,
) -> perturb_wire::WireResult<Payload<'a>> {
    let h = frame.header();
    let data = frame.data()?;
    let header = Header {
        stamp_sec: h.stamp_sec,
        stamp_nanosec: h.stamp_nanosec,
        frame_id: h.frame_id()?,
    };
    Ok(match layout {
        None => Payload::Image(ImageMsg {
            header,
            height: h.height,
            width: h.width,
            encoding: h.encoding()?,
            is_bigendian: h.is_bigendian,
            step: h.step,
            data,
        }),
        Some(layout) => Payload::Cloud(PointCloud2Msg {
            header,
            height: h.height,
            width: h.width,
            fields: layout.fields.clone(),
            is_bigendian: layout.big_endian,
            point_step: layout.point_step,
            row_step: h.row_step,
            data,
            is_dense: h.is_dense != 0,
        }),
    })
}

/// The middleware's metadata of a frame, stamped as received now.
fn meta_of(h: &FrameHeader) -> FrameMeta {
    FrameMeta {
        seq: h.seq,
        log_time: crate::frame::wall_ns(),
        applied: h.applied().map(|a| Applied {
            id: a.id,
            severity: a.severity,
            seed: a.seed,
        }),
        lost_before: h.lost_before,
        step: h.campaign_step,
        hops: Hops {
            source: h.t_ingress_ns,
            daemon_in: h.t_daemon_rx_ns,
            daemon_out: h.t_daemon_tx_ns,
            sink: perturb_wire::monotonic_ns(),
        },
    }
}

/// A frame held in shared memory (see [`crate::bus::HeldFrame`]), checked when received.
struct IoxHeld {
    frame: perturb_wire::Frame,
    meta: FrameMeta,
    layout: Option<Arc<PointLayout>>,
}

impl HeldFrame for IoxHeld {
    fn meta(&self) -> &FrameMeta {
        &self.meta
    }

    fn payload(&self) -> Payload<'_> {
        payload_of(&self.frame, self.layout.as_ref())
            .expect("checked by IoxSubscriber::hold when received")
    }

    fn lost_before(&self) -> u32 {
        self.frame.header().lost_before
    }

    fn killed(&self) -> bool {
        self.frame.header().flags & perturb_wire::header::FLAG_KILLED != 0
    }
}

impl IoxSubscriber {
    /// The point layout of a frame (`None` for an image), after checking header and payload.
    fn layout(
        &mut self,
        frame: &perturb_wire::Frame,
    ) -> perturb_wire::WireResult<Option<Arc<PointLayout>>> {
        Ok(match frame.validate()? {
            WireModality::Camera => None,
            WireModality::Lidar => Some(self.layouts.layout_for(frame.header())?),
        })
    }

    /// Passes one received frame to `f`, in place (an error says why the frame is invalid).
    fn deliver(
        &mut self,
        frame: &perturb_wire::Frame,
        f: &mut dyn FnMut(&FrameMeta, &Payload<'_>),
    ) -> perturb_wire::WireResult<()> {
        let layout = self.layout(frame)?;
        let payload = payload_of(frame, layout.as_ref())?;
        f(&meta_of(frame.header()), &payload);
        Ok(())
    }

    /// Checks a received frame and keeps it (an error says why the frame is invalid).
    fn hold(&mut self, frame: perturb_wire::Frame) -> perturb_wire::WireResult<Held> {
        let layout = self.layout(&frame)?;
        payload_of(&frame, layout.as_ref())?;
        let meta = meta_of(frame.header());
        Ok(Box::new(IoxHeld {
            frame,
            meta,
            layout,
        }))
    }

    /// Waits up to `timeout` for the first frame; a broken connection is reopened (no frame).
    fn first(&mut self, timeout: Duration) -> Result<Option<perturb_wire::Frame>> {
        match self.subscriber.wait(timeout) {
            Ok(x) => Ok(x),
            Err(e) if e.is_borrow_limit() => Ok(None),
            Err(e) => {
                // A broken connection is reconnected, not counted as a bad message.
                self.subscriber.reopen()?;
                info!(
                    service = self.subscriber.service(),
                    reconnects = self.subscriber.reconnects(),
                    "reconnected after: {e}"
                );
                Ok(None)
            }
        }
    }

    fn invalid(&mut self, seq: u64, e: &dyn std::fmt::Display) {
        self.invalid += 1;
        warn!(
            service = self.subscriber.service(),
            seq,
            invalid = self.invalid,
            "skipping an invalid frame: {e}"
        );
    }
}

impl BusSubscriber for IoxSubscriber {
    fn publishers(&self) -> Option<usize> {
        Some(self.subscriber.publisher_count())
    }

    fn recv(
        &mut self,
        timeout: Duration,
        f: &mut dyn FnMut(&FrameMeta, &Payload<'_>),
    ) -> Result<usize> {
        let mut n = 0;
        let mut next = self.first(timeout)?;
        while let Some(frame) = next {
            match self.deliver(&frame, f) {
                Ok(()) => n += 1,
                Err(e) => self.invalid(frame.header().seq, &e),
            }
            drop(frame);
            next = match self.subscriber.receive() {
                Err(e) if e.is_borrow_limit() => None,
                other => other?,
            };
        }
        Ok(n)
    }

    fn recv_held(&mut self, timeout: Duration) -> Result<Vec<Held>> {
        let mut out = Vec::new();
        let mut next = self.first(timeout)?;
        while let Some(frame) = next {
            let seq = frame.header().seq;
            match self.hold(frame) {
                Ok(h) => out.push(h),
                Err(e) => self.invalid(seq, &e),
            }
            // At the borrow limit the frames held elsewhere must be handed back first.
            next = match self.subscriber.receive() {
                Err(e) if e.is_borrow_limit() => None,
                other => other?,
            };
        }
        Ok(out)
    }
}
