//! Bag replay: the sensor messages of a rosbag2 MCAP bag, a ROS 1 `.bag` or a ROS 1 profile MCAP
//! file, in log-time order, paced by their original timing, into `<stream>/raw` (the
//! hardware-in-the-loop source).
//!
//! Pacing: message `i` is published at `start + (log_time_i - log_time_0) / rate`; `rate = 0`
//! publishes as fast as the sinks take them. Looping starts the bag again right after its last
//! message (header stamps are the bag's, unchanged). A damaged bag is replayed up to the damage,
//! which is reported. With `[ros1] clock = true` the bag's log time is published on the ROS 1
//! topic `/clock` before each message and every 10 ms in between (`rosbag play --clock`).
//!
//! Reading runs ahead of the clock: a reader thread decompresses the bag's chunks and queues the
//! next messages (up to [`AHEAD_BYTES`] or [`AHEAD_MESSAGES`]), so the pacing thread only waits
//! and publishes. Where the machine cannot decompress as fast as the bag plays (a `rosbag record
//! --bz2` bag of camera frames: bz2 is slow), messages go out late; the largest lag is measured,
//! logged once it passes 100 ms, and reported.

use crate::adapter::{Adapter, Control};
use crate::bus::{Bus, BusPublisher, Side};
use crate::config::ReplaySection;
use crate::frame::{FrameMeta, Hops, OwnedPayload, Payload, StreamKind, monotonic_ns};
use crate::stats::{AdapterReport, log_bad};
use anyhow::{Context, Result};
use perturb_bag::{Bag, Filter, SensorMessage, SensorType};
use std::collections::BTreeMap;
use std::ops::ControlFlow;
use std::time::{Duration, Instant};

/// The replay engine.
pub struct Replay {
    /// Settings.
    pub cfg: ReplaySection,
    bag: Bag,
    /// Bag topic -> (stream, kind).
    pub routes: BTreeMap<String, (String, StreamKind)>,
}

/// The stream a topic goes to when the config does not say: the topic without its leading `/`.
pub fn default_stream(topic: &str) -> String {
    topic.trim_start_matches('/').to_string()
}

impl Replay {
    /// Opens the bag and resolves the topic selection (errors name the bag and the topic).
    pub fn open(cfg: ReplaySection) -> Result<Self> {
        let bag = Bag::open(&cfg.bag)?;
        let topics = bag.topics()?;
        let kind_of = |type_name: &str| match SensorType::of(type_name)? {
            SensorType::Image | SensorType::CompressedImage => Some(StreamKind::Image),
            SensorType::PointCloud2 => Some(StreamKind::Cloud),
        };
        let mut routes = BTreeMap::new();
        if cfg.topics.is_empty() {
            for t in &topics {
                if let Some(k) = kind_of(&t.type_name) {
                    routes.insert(t.topic.clone(), (default_stream(&t.topic), k));
                }
            }
            if routes.is_empty() {
                anyhow::bail!(
                    "{}: no Image, CompressedImage or PointCloud2 topic to replay (topics: {})",
                    cfg.bag.display(),
                    topics
                        .iter()
                        .map(|t| format!("{} [{}]", t.topic, t.type_name))
                        .collect::<Vec<_>>()
                        .join(", ")
                );
            }
        } else {
            for (topic, stream) in &cfg.topics {
                let t = topics.iter().find(|t| &t.topic == topic).with_context(|| {
                    format!(
                        "replay.topics: the bag {} has no topic `{topic}` (it has: {})",
                        cfg.bag.display(),
                        topics
                            .iter()
                            .map(|t| t.topic.as_str())
                            .collect::<Vec<_>>()
                            .join(", ")
                    )
                })?;
                let k = kind_of(&t.type_name).with_context(|| {
                    format!(
                        "replay.topics: `{topic}` is a {} (the bridge replays Image, CompressedImage and PointCloud2)",
                        t.type_name
                    )
                })?;
                routes.insert(topic.clone(), (stream.clone(), k));
            }
        }
        Ok(Replay { cfg, bag, routes })
    }

    /// The log time of the first selected message, if any.
    fn first_log_time(&self, filter: &Filter) -> Result<Option<u64>> {
        let mut first = None;
        self.bag.for_each(filter, |m| {
            first = Some(m.log_time);
            Ok(ControlFlow::Break(()))
        })?;
        Ok(first)
    }

    /// Replays, calling `emit(stream, meta, payload)` for every frame at its time. Returns the
    /// report (damage, bad messages, skipped types).
    pub fn run(
        &self,
        ctl: &Control,
        name: &str,
        emit: &mut dyn FnMut(&str, &FrameMeta, &Payload<'_>) -> Result<()>,
    ) -> Result<AdapterReport> {
        self.run_with_clock(ctl, name, emit, None)
    }

    /// [`Self::run`], also calling `clock(log_time)` with the bag's time before each message and
    /// every 10 ms while waiting for the next one (only when paced, `rate > 0`).
    pub fn run_with_clock(
        &self,
        ctl: &Control,
        name: &str,
        emit: &mut dyn FnMut(&str, &FrameMeta, &Payload<'_>) -> Result<()>,
        mut clock: Option<&mut dyn FnMut(u64)>,
    ) -> Result<AdapterReport> {
        let mut rep = AdapterReport {
            name: name.to_string(),
            ..Default::default()
        };
        let mut filter = Filter {
            topics: self.routes.keys().cloned().collect(),
            ..Default::default()
        };
        let Some(bag_start) = self.first_log_time(&filter)? else {
            rep.notes.push("no message to replay".into());
            return Ok(rep);
        };
        filter.start = Some(bag_start + (self.cfg.start_offset * 1e9) as u64);
        let mut seqs: BTreeMap<&str, u64> = BTreeMap::new();
        let mut passes = PassLog::default();
        let mut lag = Lag::default();
        let mut next_pass_at: Option<Instant> = None;
        loop {
            if let Some(at) = next_pass_at {
                let now = Instant::now();
                if at > now && !ctl.sleep(at - now) {
                    break;
                }
            }
            let mut t0: Option<(Instant, u64)> = None;
            let mut span = (u64::MAX, 0u64, 0u64); // first, last log time, messages
            let report = self.read_ahead(ctl, &filter, &mut |m| {
                if ctl.stopped() {
                    return ControlFlow::Break(());
                }
                let Some((stream, _kind)) = self.routes.get(m.topic) else {
                    return ControlFlow::Continue(());
                };
                rep.received += 1;
                span = (span.0.min(m.log_time), span.1.max(m.log_time), span.2 + 1);
                match self.pace(ctl, &mut t0, m.log_time, clock.as_deref_mut()) {
                    None => return ControlFlow::Break(()),
                    Some(late) => lag.observe(late, name),
                }
                let mut owned = None;
                let payload = match payload_of(m, &mut owned) {
                    Ok(Some(p)) => p,
                    Ok(None) => {
                        rep.skipped += 1;
                        return ControlFlow::Continue(());
                    }
                    Err(e) => {
                        rep.bad += 1;
                        log_bad(name, rep.bad, &e);
                        return ControlFlow::Continue(());
                    }
                };
                let seq = seqs.entry(stream.as_str()).or_insert(0);
                let meta = FrameMeta {
                    seq: *seq,
                    log_time: m.log_time,
                    applied: None,
                    lost_before: 0,
                    step: 0,
                    hops: Hops {
                        source: monotonic_ns(),
                        ..Default::default()
                    },
                };
                match emit(stream, &meta, &payload) {
                    Ok(()) => {
                        *seq += 1;
                        rep.forwarded += 1;
                    }
                    Err(e) => {
                        rep.failed += 1;
                        log_bad(name, rep.failed, &e);
                    }
                }
                ControlFlow::Continue(())
            })?;
            if let Some(d) = report.damage {
                tracing::warn!("{name}: the bag is damaged: {d} (replayed what could be read)");
                if !rep.damage.contains(&d) {
                    rep.damage.push(d);
                }
            }
            for n in report.notes {
                if !rep.notes.contains(&n) {
                    rep.notes.push(n);
                }
            }
            if !self.cfg.looped || ctl.stopped() || rep.forwarded == 0 {
                break;
            }
            passes.done(name);
            next_pass_at = self.next_pass_at(span);
        }
        if let Some(note) = lag.note() {
            rep.notes.push(note);
        }
        Ok(rep)
    }

    /// Reads the messages passing `filter` on a thread of its own, ahead of `f` (which paces
    /// and publishes them): at most [`AHEAD_MESSAGES`] messages or [`AHEAD_BYTES`] bytes wait.
    fn read_ahead(
        &self,
        ctl: &Control,
        filter: &Filter,
        f: &mut dyn FnMut(&perturb_bag::BagMessage<'_>) -> ControlFlow<()>,
    ) -> Result<perturb_bag::ReadReport> {
        let (tx, rx) = crossbeam::channel::bounded::<Ahead>(AHEAD_MESSAGES);
        let queued = std::sync::atomic::AtomicUsize::new(0);
        std::thread::scope(|scope| {
            let reader = std::thread::Builder::new()
                .name("replay-read".into())
                .spawn_scoped(scope, || {
                    let tx = tx;
                    self.bag.for_each(filter, |m| {
                        if ctl.stopped() || !self.routes.contains_key(m.topic) {
                            return Ok(if ctl.stopped() {
                                ControlFlow::Break(())
                            } else {
                                ControlFlow::Continue(())
                            });
                        }
                        // The byte bound: wait while the queue holds too much.
                        while queued.load(std::sync::atomic::Ordering::Acquire) > AHEAD_BYTES {
                            if ctl.stopped() {
                                return Ok(ControlFlow::Break(()));
                            }
                            std::thread::sleep(Duration::from_millis(2));
                        }
                        queued.fetch_add(m.data.len(), std::sync::atomic::Ordering::AcqRel);
                        if tx.send(Ahead::of(&m)).is_err() {
                            return Ok(ControlFlow::Break(()));
                        }
                        Ok(ControlFlow::Continue(()))
                    })
                })?;
            for a in rx.iter() {
                queued.fetch_sub(a.data.len(), std::sync::atomic::Ordering::AcqRel);
                if f(&a.view()).is_break() {
                    break;
                }
            }
            drop(rx);
            reader
                .join()
                .map_err(|_| anyhow::anyhow!("the replay's reader thread panicked"))?
                .map_err(anyhow::Error::from)
        })
    }

    /// Waits until the message logged at `log_time` is due at the replay rate (`t0`: the wall
    /// and log time of the pass's first message), ticking `clock` with the bag's time meanwhile;
    /// without pacing (rate 0) only ticks. False when the replay was stopped while waiting.
    fn pace<'c>(
        &self,
        ctl: &Control,
        t0: &mut Option<(Instant, u64)>,
        log_time: u64,
        clock: Option<&mut (dyn FnMut(u64) + 'c)>,
    ) -> Option<Duration> {
        if self.cfg.rate <= 0.0 {
            if let Some(tick) = clock {
                tick(log_time);
            }
            return Some(Duration::ZERO);
        }
        let (wall0, log0) = *t0.get_or_insert((Instant::now(), log_time));
        let due = wall0
            + Duration::from_secs_f64(log_time.saturating_sub(log0) as f64 / 1e9 / self.cfg.rate);
        match clock {
            None => {
                let now = Instant::now();
                if due <= now {
                    Some(now - due)
                } else {
                    ctl.sleep(due - now).then_some(Duration::ZERO)
                }
            }
            Some(tick) => loop {
                let now = Instant::now();
                // The bag's time now, between the last message and this one.
                let behind = due.saturating_duration_since(now).as_secs_f64() * self.cfg.rate;
                tick(log_time.saturating_sub((behind * 1e9) as u64));
                if due <= now {
                    return Some(now - due);
                }
                if !ctl.sleep((due - now).min(Duration::from_millis(10))) {
                    return None;
                }
            },
        }
    }

    /// When a looping replay starts its next pass: one mean message interval of the last pass
    /// (`span`: first and last log time, messages) after now (at least 50 ms, so a bag of one
    /// instant does not flood the sinks), at the replay rate; None (at once) without pacing.
    fn next_pass_at(&self, span: (u64, u64, u64)) -> Option<Instant> {
        if self.cfg.rate <= 0.0 {
            return None;
        }
        let gap_ns = if span.2 > 1 && span.1 > span.0 {
            ((span.1 - span.0) / (span.2 - 1)).max(50_000_000)
        } else {
            100_000_000
        };
        Some(Instant::now() + Duration::from_secs_f64(gap_ns as f64 / 1e9 / self.cfg.rate))
    }
}

/// Messages the replay's reader thread keeps ready at most.
pub const AHEAD_MESSAGES: usize = 256;
/// Bytes of messages the reader thread keeps ready at most.
pub const AHEAD_BYTES: usize = 256 << 20;

/// A message read ahead, owned.
struct Ahead {
    topic: String,
    type_name: String,
    encoding: String,
    schema_encoding: String,
    schema: Vec<u8>,
    log_time: u64,
    publish_time: u64,
    sequence: u32,
    data: Vec<u8>,
    path: std::path::PathBuf,
}

impl Ahead {
    fn of(m: &perturb_bag::BagMessage<'_>) -> Self {
        Ahead {
            topic: m.topic.to_string(),
            type_name: m.type_name.to_string(),
            encoding: m.encoding.to_string(),
            schema_encoding: m.schema_encoding.to_string(),
            // Sensor messages decode by type name: their schema is not needed here.
            schema: Vec::new(),
            log_time: m.log_time,
            publish_time: m.publish_time,
            sequence: m.sequence,
            data: m.data.to_vec(),
            path: m.path.to_path_buf(),
        }
    }

    fn view(&self) -> perturb_bag::BagMessage<'_> {
        perturb_bag::BagMessage {
            topic: &self.topic,
            type_name: &self.type_name,
            encoding: &self.encoding,
            schema_encoding: &self.schema_encoding,
            schema: &self.schema,
            log_time: self.log_time,
            publish_time: self.publish_time,
            sequence: self.sequence,
            data: &self.data,
            path: &self.path,
        }
    }
}

/// How late the replay published its messages against the bag's timing.
#[derive(Default)]
struct Lag {
    max: Duration,
    late: u64,
    messages: u64,
    warned: bool,
}

/// A message this much after its time counts as late.
const LATE: Duration = Duration::from_millis(100);

impl Lag {
    fn observe(&mut self, late: Duration, name: &str) {
        self.messages += 1;
        self.max = self.max.max(late);
        if late >= LATE {
            self.late += 1;
            if !self.warned {
                self.warned = true;
                tracing::warn!(
                    "{name}: the replay is {:.0} ms behind the bag's timing (reading or decompressing the bag is slower than real time here, e.g. bz2 chunks); timing does not hold",
                    late.as_secs_f64() * 1e3
                );
            }
        }
    }

    fn note(&self) -> Option<String> {
        (self.late > 0).then(|| {
            format!(
                "{} of {} messages went out {} ms or more after their time (largest lag {:.0} ms): reading the bag is slower than real time on this machine",
                self.late,
                self.messages,
                LATE.as_millis(),
                self.max.as_secs_f64() * 1e3
            )
        })
    }
}

/// The payload of a bag message: borrowed for raw images and clouds, decoded into `owned` for a
/// compressed image; None for a message that is not a sensor message; an error naming the
/// message for one that does not decode or validate.
fn payload_of<'a>(
    m: &'a perturb_bag::BagMessage<'a>,
    owned: &'a mut Option<OwnedPayload>,
) -> std::result::Result<Option<Payload<'a>>, String> {
    let payload = match m.decode() {
        None => return Ok(None),
        Some(Err(e)) => return Err(e.to_string()),
        Some(Ok(SensorMessage::Image(i))) => Payload::Image(i),
        Some(Ok(SensorMessage::Cloud(c))) => Payload::Cloud(c),
        Some(Ok(SensorMessage::Compressed(c))) => {
            let image = perturb_core::formats::picture::decode(c.data)
                .map_err(|e| format!("{} at {}: {e}", m.topic, m.log_time))?;
            owned
                .insert(OwnedPayload::Image {
                    sec: c.header.stamp_sec,
                    nanosec: c.header.stamp_nanosec,
                    frame_id: c.header.frame_id.to_string(),
                    image,
                })
                .payload()
        }
    };
    payload
        .validate()
        .map_err(|e| format!("{} at {}: {e}", m.topic, m.log_time))?;
    Ok(Some(payload))
}

/// The log lines of a looping replay's passes: a short bag loops many times a second, so the
/// first pass is said, then at most one line a minute (the rest at debug level).
struct PassLog {
    pass: u32,
    logged: u32,
    last: Instant,
}

impl Default for PassLog {
    fn default() -> Self {
        PassLog {
            pass: 0,
            logged: 0,
            last: Instant::now(),
        }
    }
}

impl PassLog {
    /// A pass of replay `name` finished and the replay loops on.
    fn done(&mut self, name: &str) {
        self.pass += 1;
        let pass = self.pass;
        if pass == 1 || self.last.elapsed() >= PASS_LOG_EVERY {
            tracing::info!(
                "{name}: pass {pass} done, looping ({} passes since the last such line)",
                pass - self.logged
            );
            self.last = Instant::now();
            self.logged = pass;
        } else {
            tracing::debug!("{name}: pass {pass} done, looping");
        }
    }
}

/// How often a looping replay logs a finished pass at info level.
const PASS_LOG_EVERY: Duration = Duration::from_secs(60);

/// The replay adapter: the engine publishing into the bus (and, optionally, `/clock` on ROS 1).
pub struct ReplayAdapter {
    /// The engine.
    pub replay: Replay,
    /// The ROS 1 node to publish `/clock` on, if `[ros1] clock` is set.
    pub clock: Option<std::sync::Arc<crate::ros1::Node>>,
}

impl Adapter for ReplayAdapter {
    fn name(&self) -> String {
        format!("replay {}", self.replay.cfg.bag.display())
    }

    fn is_sink(&self) -> bool {
        false
    }

    fn run(self: Box<Self>, bus: &dyn Bus, mut ctl: Control) -> Result<AdapterReport> {
        let name = self.name();
        let mut pubs: BTreeMap<String, Box<dyn BusPublisher>> = BTreeMap::new();
        for (stream, kind) in self.replay.routes.values() {
            pubs.insert(stream.clone(), bus.publisher(stream, *kind, Side::Raw)?);
        }
        let mut clock = match &self.clock {
            Some(node) => Some(crate::ros1::ClockPublisher::new(node)?),
            None => None,
        };
        let mut tick = |ns: u64| {
            if let Some(c) = clock.as_mut() {
                c.publish(ns);
            }
        };
        ctl.ready();
        let mut rep = self.replay.run_with_clock(
            &ctl,
            &name,
            &mut |stream, meta, payload| {
                let p = pubs
                    .get_mut(stream)
                    .context("replay route without publisher")?;
                p.publish(meta, payload)
            },
            self.clock
                .is_some()
                .then_some(&mut tick as &mut dyn FnMut(u64)),
        )?;
        rep.undelivered = pubs.values().map(|p| p.undelivered()).sum();
        Ok(rep)
    }
}
