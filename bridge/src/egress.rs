//! Egress: `<stream>/perturbed` out to a ROS 2 (DDS) or ROS 1 (TCPROS) topic, header stamp and
//! frame_id bit-exact (and, over ROS 1, the frame's sequence number as header `seq`).
//!
//! On the iceoryx2 bus an egress is guarded ([`crate::guard`]): it also reads `<stream>/raw` and
//! publishes the raw frame when the perturbed one misses its deadline, when `perturbd` is down or
//! while the kill switch holds, so the ADS keeps receiving frames at the sensor's rate. Every
//! frame published is reported on the events channel ([`crate::events`]) with what it carries;
//! the stream's `camera_info` follows its image ([`crate::camera_info`]).

use crate::adapter::{Adapter, Control, POLL};
use crate::bus::{Bus, Held, Side};
use crate::camera_info::{CameraInfoLink, CameraInfoSink};
use crate::dds::TopicSpec;
use crate::endpoint::Endpoint;
use crate::events::EventsHub;
use crate::frame::{StreamKind, monotonic_ns, wall_ns};
use crate::guard::{Decision, Fallback, Guard, GuardSettings, LocalKill, reader_thread};
use crate::stats::{AdapterReport, HopLatency, Latency, log_bad};
use crate::topic::TopicWriter;
use anyhow::Result;
use perturb_bag::events::EventRecord;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::time::{Duration, Instant};

/// How often an egress asks its writer about readers with an incompatible QoS.
const QOS_CHECK: Duration = Duration::from_millis(500);

/// How long the perturbed side may stay silent, with a publisher listed, before the egress asks
/// iceoryx2 to remove the ports of dead processes (a `perturbd` killed with `kill -9` stays
/// listed until someone does).
const SWEEP_AFTER: Duration = Duration::from_secs(1);

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
    /// The deadline and late-frame policy; `None`: not guarded (publishes what the daemon
    /// publishes, when it does).
    pub guard: Option<GuardSettings>,
    /// The bridge's kill switch.
    pub kill: Arc<LocalKill>,
    /// Where the events records go, if the bridge publishes them.
    pub events: Option<Arc<EventsHub>>,
    /// The stream's camera_info: what the ingress received, and where it goes.
    pub camera_info: Option<(Arc<CameraInfoLink>, CameraInfoSink)>,
}

/// What an egress keeps while it runs: the writer, the counts, the latencies.
struct Out {
    name: String,
    stream: String,
    topic: String,
    writer: Box<dyn TopicWriter>,
    rep: AdapterReport,
    total: Latency,
    hops: HopLatency,
    events: Option<Arc<EventsHub>>,
    camera_info: Option<(Arc<CameraInfoLink>, CameraInfoSink)>,
    qos_checked: Instant,
    qos_warned: bool,
}

impl Out {
    /// Publishes a frame, handing it to the writer (a ROS 1 writer sends its data from shared
    /// memory without a copy); `fallback`: it is the raw frame, published for this reason.
    fn publish_held(&mut self, frame: Held, fallback: Option<Fallback>) {
        let meta = frame.meta().clone();
        let (stamp, frame_id) = {
            let p = frame.payload();
            let h = p.header();
            ((h.stamp_sec, h.stamp_nanosec), h.frame_id.to_string())
        };
        match self.writer.write_held(meta.seq, frame) {
            Ok(()) => {
                self.rep.forwarded += 1;
                // The egress hop ends when the write returns (DDS: written; ROS 1: serialized
                // and queued for every subscriber).
                let mut h = meta.hops;
                h.sink = monotonic_ns();
                if h.source != 0 {
                    self.total.add(h.sink.saturating_sub(h.source));
                }
                if fallback.is_none() {
                    self.hops.add(&h);
                }
                if let Some(ev) = &self.events {
                    let applied = match fallback {
                        None => meta
                            .applied
                            .as_ref()
                            .map(|a| (a.id.as_str(), a.severity, a.seed)),
                        Some(_) => None,
                    };
                    let mut rec = EventRecord::frame(
                        &self.stream,
                        &self.topic,
                        meta.seq,
                        stamp,
                        &frame_id,
                        applied,
                        fallback.map(Fallback::as_str),
                        wall_ns(),
                    );
                    if fallback.is_none() && meta.step > 0 {
                        rec.step = Some(meta.step);
                    }
                    ev.send(rec);
                }
                if let Some((link, sink)) = &mut self.camera_info {
                    sink.after_image(link, stamp);
                }
            }
            Err(e) => {
                self.rep.failed += 1;
                self.rep.lost_by_cause.egress += 1;
                log_bad(&self.name, self.rep.failed, &e);
            }
        }
    }

    /// Reports `count` frames lost to `cause` before frame `seq`.
    fn gap(&self, seq: u64, cause: &str, count: u64) {
        if let Some(ev) = &self.events {
            ev.send(EventRecord::gap(
                &self.stream,
                &self.topic,
                seq,
                cause,
                count,
                wall_ns(),
            ));
        }
    }

    /// A reader whose QoS does not match gets nothing and DDS says nothing: say it once.
    fn check_qos(&mut self) {
        if !self.qos_warned && self.qos_checked.elapsed() >= QOS_CHECK {
            self.qos_checked = Instant::now();
            if let Some(why) = self.writer.incompatible_readers() {
                tracing::warn!("{}: {why}", self.name);
                self.rep.notes.push(why);
                self.qos_warned = true;
            }
        }
    }

    /// Publishes the camera_info messages that are due (those that came after their image).
    fn poll_camera_info(&mut self) {
        if let Some((link, sink)) = &mut self.camera_info {
            sink.poll(link);
        }
    }

    /// Frames the writer dropped since last asked (slow ROS 1 subscribers): counted, reported.
    fn egress_drops(&mut self, seen: &mut u64, seq: u64) {
        let now = self.writer.dropped();
        if now > *seen {
            self.gap(seq, "egress", now - *seen);
            *seen = now;
        }
    }

    fn finish(mut self, key: String) -> AdapterReport {
        self.rep.dropped = self.writer.dropped();
        self.rep.lost_by_cause.egress += self.rep.dropped;
        self.rep.latency = Some(self.total.summary());
        self.rep.hops.insert(key, self.hops.summary());
        if let Some((_, sink)) = &self.camera_info {
            self.rep.notes.push(format!(
                "camera_info -> {}: {} published, {} failed",
                sink.topic, sink.published, sink.failed
            ));
        }
        self.rep
    }
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

    fn run(self: Box<Self>, bus: &dyn Bus, ctl: Control) -> Result<AdapterReport> {
        let name = self.name();
        let writer = self.endpoint.writer(&self.spec)?;
        let key = format!("{}/{}", self.stream, self.side.as_str());
        let mut out = Out {
            name: name.clone(),
            stream: self.stream.clone(),
            topic: self.spec.topic.clone(),
            writer,
            rep: AdapterReport {
                name,
                ..Default::default()
            },
            total: Latency::default(),
            hops: HopLatency::default(),
            events: self.events.clone(),
            camera_info: None,
            qos_checked: Instant::now(),
            qos_warned: false,
        };
        let Egress {
            stream,
            kind,
            side,
            guard,
            kill,
            camera_info,
            ..
        } = *self;
        out.camera_info = camera_info;
        match guard {
            Some(g)
                if side == Side::Perturbed
                    && bus.name() == "iceoryx2"
                    && g.on_late != crate::guard::OnLate::Wait =>
            {
                run_guarded(bus, &stream, kind, g, &kill, ctl, &mut out)?
            }
            _ => run_plain(bus, &stream, kind, side, ctl, &mut out)?,
        }
        Ok(out.finish(key))
    }
}

/// Publishes what the stream side carries, as it comes.
fn run_plain(
    bus: &dyn Bus,
    stream: &str,
    kind: StreamKind,
    side: Side,
    mut ctl: Control,
    out: &mut Out,
) -> Result<()> {
    let mut sub = bus.subscriber(stream, kind, side)?;
    ctl.ready();
    let mut seen_drops = 0;
    let mut last_seq = 0;
    while !ctl.stopped() {
        out.check_qos();
        match sub.recv_held(POLL) {
            Ok(frames) => {
                for h in frames {
                    out.rep.received += 1;
                    if h.payload().kind() != kind {
                        out.rep.bad += 1;
                        log_bad(
                            &out.name,
                            out.rep.bad,
                            &"frame of the wrong kind for this topic",
                        );
                        continue;
                    }
                    let lost = h.meta().lost_before;
                    if lost > 0 {
                        out.rep.lost_by_cause.upstream += u64::from(lost);
                        out.gap(h.meta().seq, "upstream", u64::from(lost));
                    }
                    last_seq = h.meta().seq;
                    out.publish_held(h, None);
                }
            }
            Err(e) => {
                out.rep.failed += 1;
                log_bad(&out.name, out.rep.failed, &e);
            }
        }
        out.egress_drops(&mut seen_drops, last_seq);
        out.poll_camera_info();
        ctl.watch_publishers(sub.as_ref());
    }
    Ok(())
}

/// Publishes the perturbed frames, or the raw ones in their place (see [`crate::guard`]).
fn run_guarded(
    bus: &dyn Bus,
    stream: &str,
    kind: StreamKind,
    settings: GuardSettings,
    kill: &LocalKill,
    mut ctl: Control,
    out: &mut Out,
) -> Result<()> {
    let (raw_tx, raw_rx) = crossbeam::channel::bounded::<Held>(64);
    let (pert_tx, pert_rx) = crossbeam::channel::bounded::<Held>(64);
    let (ready_tx, ready_rx) = crossbeam::channel::bounded(2);
    let stop = Arc::new(AtomicBool::new(false));
    let raw_pubs = Arc::new(AtomicUsize::new(0));
    let daemon_pubs = Arc::new(AtomicUsize::new(1));
    std::thread::scope(|scope| -> Result<()> {
        for (side, tx, pubs) in [
            (Side::Raw, raw_tx, raw_pubs.clone()),
            (Side::Perturbed, pert_tx, daemon_pubs.clone()),
        ] {
            let (stop, ready) = (stop.clone(), ready_tx.clone());
            std::thread::Builder::new()
                .name(format!("eg-{}", side.as_str()))
                .spawn_scoped(scope, move || {
                    reader_thread(bus, stream, kind, side, tx, pubs, stop, ready)
                })?;
        }
        drop(ready_tx);
        let started = (0..2).try_for_each(|_| {
            ready_rx
                .recv()
                .map_err(|_| anyhow::anyhow!("a reader of the egress ended before it was ready"))?
        });
        if let Err(e) = started {
            stop.store(true, Ordering::Relaxed);
            return Err(e);
        }
        ctl.ready();
        let mut guard = Guard::new(settings);
        let mut decisions = Vec::new();
        let mut seen_drops = 0;
        let mut last_seq = 0;
        let mut last_perturbed = Instant::now();
        let mut last_sweep = Instant::now();
        let mut was_killed = false;
        while !ctl.stopped() {
            out.check_qos();
            let now = Instant::now();
            let wait = guard
                .next_deadline()
                .map_or(POLL, |d| d.saturating_duration_since(now).min(POLL));
            let daemon_up = || daemon_pubs.load(Ordering::Relaxed) > 0;
            let on_raw =
                |h: Held, guard: &mut Guard, decisions: &mut Vec<Decision>, out: &mut Out| {
                    out.rep.received += 1;
                    if h.payload().kind() != kind {
                        out.rep.bad += 1;
                        log_bad(
                            &out.name,
                            out.rep.bad,
                            &"frame of the wrong kind for this topic",
                        );
                        return;
                    }
                    let lost = u64::from(h.lost_before());
                    if lost > 0 {
                        out.rep.lost_by_cause.upstream += lost;
                        out.gap(h.meta().seq, "upstream", lost);
                    }
                    guard.on_raw(h, Instant::now(), daemon_up(), kill.engaged(), decisions);
                };
            crossbeam::select! {
                recv(raw_rx) -> m => if let Ok(h) = m {
                    on_raw(h, &mut guard, &mut decisions, out);
                },
                recv(pert_rx) -> m => if let Ok(h) = m {
                    last_perturbed = Instant::now();
                    // Its raw frame may still wait in the raw reader's queue: take the raw
                    // frames first, so the perturbed one finds its own.
                    while let Ok(r) = raw_rx.try_recv() {
                        on_raw(r, &mut guard, &mut decisions, out);
                    }
                    guard.on_perturbed(h, &mut decisions);
                },
                default(wait) => {},
            }
            let killed = kill.engaged();
            if killed && !was_killed {
                guard.flush(Fallback::Killed, &mut decisions);
            }
            was_killed = killed;
            guard.expire(Instant::now(), daemon_up(), &mut decisions);
            for d in decisions.drain(..) {
                match d {
                    Decision::Perturbed(h) => {
                        last_seq = h.meta().seq;
                        out.publish_held(h, None);
                    }
                    Decision::Raw(h, why) => {
                        last_seq = h.meta().seq;
                        out.publish_held(h, Some(why));
                    }
                    Decision::Dropped(seq, why) => {
                        let cause = match why {
                            Fallback::DaemonDown => {
                                out.rep.lost_by_cause.daemon_down += 1;
                                "daemon_down"
                            }
                            _ => {
                                out.rep.lost_by_cause.daemon_late += 1;
                                "daemon_late"
                            }
                        };
                        out.gap(seq + 1, cause, 1);
                    }
                }
            }
            out.egress_drops(&mut seen_drops, last_seq);
            out.poll_camera_info();
            // A perturbd killed with kill -9 stays listed as the perturbed side's publisher
            // until its ports are swept: look for dead processes while the side is silent.
            if daemon_up()
                && last_perturbed.elapsed() >= SWEEP_AFTER
                && last_sweep.elapsed() >= SWEEP_AFTER
            {
                last_sweep = Instant::now();
                bus.sweep_dead();
            }
            if raw_pubs.load(Ordering::Relaxed) > 0 || daemon_up() {
                ctl.note_publisher();
            }
        }
        stop.store(true, Ordering::Relaxed);
        // What still waits goes out raw: the ADS must not lose the last frames to a stop.
        guard.flush(Fallback::Late, &mut decisions);
        for d in decisions.drain(..) {
            if let Decision::Raw(h, why) = d {
                out.publish_held(h, Some(why));
            }
        }
        out.rep.fallback_raw = guard.fallback;
        out.rep.late_discarded = guard.late_discarded;

        Ok(())
    })
}
