//! Recording: streams into a rosbag2 MCAP bag (the directory with `metadata.yaml` that `ros2 bag`
//! and `rosbags` read) or, with `format = "bag1"`, a ROS 1 `.bag` (`rosbag info`, `rosbag play`,
//! Python `rosbag`; `out` ending in `.bag` is the file, otherwise a directory holding
//! `NAME.bag`), plus the `/perturb/events` channel (`std_msgs/String`) saying, for every
//! perturbed frame, which perturbation, severity and seed was active. In a ROS 1 bag the frame's
//! sequence number is the header `seq`.
//!
//! Topics: `<stream>/raw` is recorded as `/<stream>/raw`, `<stream>/perturbed` as
//! `/<stream>/perturbed` (characters that ROS topic names do not allow become `_`). A message's
//! log time is when the recorder received it (rosbag2's convention); its publish time is when
//! the frame entered the middleware (for a replayed bag: the original log time).

use crate::adapter::{Adapter, Control, POLL};
use crate::bus::{Bus, Side};
use crate::config::RecordSection;
use crate::frame::{FrameMeta, Payload, StreamKind, monotonic_ns, wall_ns};
use crate::stats::{AdapterReport, HopLatency, Latency, log_bad};
use anyhow::{Context, Result};
use crossbeam::channel::{Receiver, Sender, bounded};
use perturb_bag::events::{EVENTS_TOPIC, EVENTS_TYPE, PerturbationEvent, encode_string_for};
use perturb_bag::{AnyWriter, BagFormat};
use std::collections::BTreeMap;
use std::sync::atomic::{AtomicU64, Ordering};

/// The bag topic a stream side is recorded on.
pub fn record_topic(stream: &str, side: Side) -> String {
    let clean: String = stream
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || c == '_' || c == '/' {
                c
            } else {
                '_'
            }
        })
        .collect();
    format!("/{}/{}", clean.trim_matches('/'), side.as_str())
}

/// What one recorded stream side saw: key, frames, bad frames, latency, per-hop latency.
type SideResult = (String, u64, u64, Latency, HopLatency);

/// How long a stopped side waits for more frames once its queue is empty.
const DRAIN_WAIT: std::time::Duration = std::time::Duration::from_millis(1);

/// What one stream side has recorded so far.
#[derive(Default)]
struct Tally {
    got: u64,
    bad: u64,
    lat: Latency,
    hops: HopLatency,
}

struct Msg {
    channel: u16,
    log_time: u64,
    publish_time: u64,
    /// The message in the bag's encoding.
    bytes: Vec<u8>,
    event: Option<Vec<u8>>,
}

/// The recorder.
pub struct Record {
    /// Settings.
    pub cfg: RecordSection,
    /// Stream kinds.
    pub kinds: BTreeMap<String, StreamKind>,
}

impl Adapter for Record {
    fn name(&self) -> String {
        format!("record -> {}", self.cfg.out.display())
    }

    fn is_sink(&self) -> bool {
        true
    }

    fn run(self: Box<Self>, bus: &dyn Bus, mut ctl: Control) -> Result<AdapterReport> {
        let name = self.name();
        let format = match &self.cfg.format {
            Some(f) => f.parse::<BagFormat>().map_err(anyhow::Error::msg)?,
            None => BagFormat::Rosbag2,
        };
        let mut writer = AnyWriter::create(&self.cfg.out, format, self.cfg.compression.as_deref())?;
        let sides = self.add_topics(&mut writer)?;
        let events = if self.cfg.perturbed {
            Some(writer.add_topic(EVENTS_TOPIC, EVENTS_TYPE)?)
        } else {
            None
        };
        // The side whose count `max_frames` limits.
        let counted = if self.cfg.perturbed {
            Side::Perturbed
        } else {
            Side::Raw
        };
        let (tx, rx) = bounded::<Msg>(64);
        let mut rep = AdapterReport {
            name: name.clone(),
            ..Default::default()
        };
        let (ready_tx, ready_rx) = bounded::<Result<()>>(sides.len());
        let shared = Shared {
            name: name.clone(),
            format,
            bus,
            ctl: ctl.clone(),
            done_streams: AtomicU64::new(0),
            n_counted: sides.iter().filter(|s| s.side == counted).count() as u64,
            deadline: self
                .cfg
                .seconds
                .map(|t| std::time::Instant::now() + std::time::Duration::from_secs_f64(t)),
            seconds: self.cfg.seconds,
        };
        let results = std::thread::scope(|scope| -> Result<Vec<SideResult>> {
            let mut handles = Vec::new();
            for spec in sides.iter().cloned() {
                let max = self.cfg.max_frames.filter(|_| spec.side == counted);
                let (tx, ready_tx, shared) = (tx.clone(), ready_tx.clone(), &shared);
                handles.push(scope.spawn(move || shared.record_side(spec, max, tx, ready_tx)));
            }
            drop(tx);
            drop(ready_tx);
            for _ in 0..sides.len() {
                let started = ready_rx
                    .recv()
                    .map_err(|_| anyhow::anyhow!("a recorder thread ended before it was ready"))
                    .and_then(|r| r);
                if let Err(e) = started {
                    // The sides that did start must stop too, or this scope never ends.
                    let e = explain_full(e);
                    shared.ctl.stop_because(format!("{name}: {e:#}"));
                    return Err(e);
                }
            }
            ctl.ready();
            // Write until every stream thread has finished and the queue is empty.
            rep.forwarded = write_all(&mut writer, &rx, events, &name, &mut rep.failed);
            Ok(handles
                .into_iter()
                .map(|h| {
                    h.join().unwrap_or_else(|_| {
                        ("?".into(), 0, 0, Latency::default(), HopLatency::default())
                    })
                })
                .collect())
        })?;
        let mut all = Latency::default();
        for (key, got, bad, lat, hops) in results {
            rep.received += got;
            rep.bad += bad;
            rep.hops.insert(key, hops.summary());
            for s in lat.samples() {
                all.add(*s);
            }
        }
        rep.latency = Some(all.summary());
        rep.lost_by_cause.recorder = rep.failed;
        let dir = writer.finish()?;
        rep.notes.push(format!("bag written to {}", dir.display()));
        Ok(rep)
    }
}

/// A subscriber refused because the stream side has as many readers as it allows: says so.
fn explain_full(e: anyhow::Error) -> anyhow::Error {
    if format!("{e:#}").contains("ExceedsMax") {
        e.context(
            "the stream already has as many readers as its QoS allows (`max_subscribers`): another recorder, egress or monitor reads it; stop one, or give every process of the stream a larger [bridge] qos / [[streams]] qos max_subscribers",
        )
    } else {
        e
    }
}

/// One recorded stream side: its stream, kind, side, bag topic and channel.
#[derive(Clone)]
struct SideSpec {
    stream: String,
    kind: StreamKind,
    side: Side,
    topic: String,
    channel: u16,
}

impl Record {
    /// Adds a bag topic per recorded stream side (raw and/or perturbed, as configured).
    fn add_topics(&self, writer: &mut AnyWriter) -> Result<Vec<SideSpec>> {
        let mut sides = Vec::new();
        for stream in &self.cfg.streams {
            let kind = *self.kinds.get(stream).with_context(|| {
                format!("record.streams: no source says what stream `{stream}` carries")
            })?;
            for (on, side) in [
                (self.cfg.raw, Side::Raw),
                (self.cfg.perturbed, Side::Perturbed),
            ] {
                if on {
                    let topic = record_topic(stream, side);
                    let channel = writer.add_topic(&topic, kind.ros_type())?;
                    sides.push(SideSpec {
                        stream: stream.clone(),
                        kind,
                        side,
                        topic,
                        channel,
                    });
                }
            }
        }
        Ok(sides)
    }
}

/// What the recording threads share.
struct Shared<'b> {
    name: String,
    format: BagFormat,
    bus: &'b dyn Bus,
    ctl: Control,
    /// Counted sides that reached `max_frames`.
    done_streams: AtomicU64,
    /// Sides `max_frames` counts.
    n_counted: u64,
    deadline: Option<std::time::Instant>,
    seconds: Option<f64>,
}

impl Shared<'_> {
    /// Records one stream side until stopped, `max` frames or the deadline: every frame goes to
    /// `tx` in the bag's encoding (with its perturbation event on the perturbed side). Says on
    /// `ready_tx` once subscribed.
    fn record_side(
        &self,
        spec: SideSpec,
        max: Option<u64>,
        tx: Sender<Msg>,
        ready_tx: Sender<Result<()>>,
    ) -> SideResult {
        let name = &self.name;
        let SideSpec {
            stream, kind, side, ..
        } = &spec;
        let key = format!("{stream}/{}", side.as_str());
        let mut sub = match self.bus.subscriber(stream, *kind, *side) {
            Ok(s) => {
                let _ = ready_tx.send(Ok(()));
                s
            }
            Err(e) => {
                let _ = ready_tx.send(Err(e));
                return (key, 0, 0, Latency::default(), HopLatency::default());
            }
        };
        let mut t = Tally::default();
        let deadline = self.deadline;
        // One frame to the bag's writer (counted), or counted as bad.
        let take = |t: &mut Tally, meta: &FrameMeta, payload: &Payload<'_>| {
            if max.is_some_and(|m| t.got >= m) {
                return;
            }
            if payload.kind() != *kind {
                t.bad += 1;
                log_bad(name, t.bad, &format!("{stream}: frame of the wrong kind"));
                return;
            }
            t.got += 1;
            if meta.hops.source != 0 {
                t.lat.add(monotonic_ns().saturating_sub(meta.hops.source));
            }
            t.hops.add(&meta.hops);
            let _ = tx.send(self.message(&spec, meta, payload));
        };
        while !self.ctl.stopped()
            && max.is_none_or(|m| t.got < m)
            && deadline.is_none_or(|d| std::time::Instant::now() < d)
        {
            if let Err(e) = sub.recv(POLL, &mut |meta, payload| take(&mut t, meta, payload)) {
                t.bad += 1;
                log_bad(name, t.bad, &e);
            }
            self.ctl.watch_publishers(sub.as_ref());
        }
        // Frames that had arrived when the stop came are recorded too: one side's reader
        // falling behind the other's must not cost it the frames waiting in its queue. (A
        // short wait, not zero: with a zero timeout the iceoryx2 wait did not return, and the
        // bridge's stop hung in the demo's test.)
        if self.ctl.stopped() {
            let _ = sub.recv(DRAIN_WAIT, &mut |meta, payload| take(&mut t, meta, payload));
        }
        let Tally {
            got,
            bad,
            lat,
            hops,
        } = t;
        if max.is_some_and(|m| got >= m)
            && self.done_streams.fetch_add(1, Ordering::SeqCst) + 1 == self.n_counted
        {
            self.ctl.stop_because(format!(
                "{name}: every stream reached max_frames ({})",
                max.unwrap_or(0)
            ));
        }
        if deadline.is_some_and(|d| std::time::Instant::now() >= d) {
            self.ctl.stop_because(format!(
                "{name}: recorded for the {} s asked for",
                self.seconds.unwrap_or(0.0)
            ));
        }
        (key, got, bad, lat, hops)
    }

    /// A frame of `spec`'s side in the bag's encoding, with its perturbation event (JSON in a
    /// `std_msgs/String`) on the perturbed side.
    fn message(&self, spec: &SideSpec, meta: &FrameMeta, payload: &Payload<'_>) -> Msg {
        let h = payload.header();
        let event = (spec.side == Side::Perturbed).then(|| {
            let ev = PerturbationEvent {
                topic: spec.topic.clone(),
                stream: Some(spec.stream.clone()),
                seq: meta.seq,
                stamp_sec: h.stamp_sec,
                stamp_nanosec: h.stamp_nanosec,
                frame_id: h.frame_id.to_string(),
                id: meta.applied.as_ref().map(|a| a.id.clone()),
                severity: meta.applied.as_ref().map(|a| a.severity),
                seed: meta.applied.as_ref().map(|a| a.seed),
            };
            encode_string_for(
                self.format,
                &serde_json::to_string(&ev).unwrap_or_else(|_| "{}".into()),
            )
        });
        Msg {
            channel: spec.channel,
            log_time: wall_ns(),
            publish_time: meta.log_time,
            bytes: payload.encode_for(self.format, meta.seq),
            event,
        }
    }
}

/// Writes every queued message (and its event on `events`) until the senders are gone; a
/// failed write is counted in `failed` and logged. Returns the frames written.
fn write_all(
    writer: &mut AnyWriter,
    rx: &Receiver<Msg>,
    events: Option<u16>,
    name: &str,
    failed: &mut u64,
) -> u64 {
    let mut written = 0u64;
    for m in rx.iter() {
        if let Err(e) = writer.write(m.channel, m.log_time, m.publish_time, &m.bytes) {
            *failed += 1;
            log_bad(name, *failed, &e);
            continue;
        }
        written += 1;
        if let (Some(ev), Some(ch)) = (m.event, events)
            && let Err(e) = writer.write(ch, m.log_time, m.publish_time, &ev)
        {
            *failed += 1;
            log_bad(name, *failed, &e);
        }
    }
    written
}
