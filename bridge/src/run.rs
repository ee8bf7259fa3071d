//! Builds the adapters a configuration asks for and runs them, one thread each: sinks first
//! (so no early frame is missed), then sources. It stops on SIGINT/SIGTERM; when this process has
//! sources, all finite, and they are done (after `linger`, for the last frames to come through the
//! daemon); when every sink is done (a recorder's `max_frames` or `seconds`); or when an adapter
//! fails. A bridge without sources of its own (record or egress only) runs until one of the
//! others: it never stops because nothing arrives. It always says why it stopped.

use crate::adapter::{Adapter, Control};
use crate::bus::{Bus, Side};
use crate::camera_info::{CameraInfoLink, CameraInfoSink};
use crate::config::{BusKind, Config, Transport};
use crate::dds::rustdds_backend::RustddsBackend;
use crate::dds::{self, DdsBackend, TopicSpec};
use crate::egress::Egress;
use crate::endpoint::Endpoint;
use crate::events::{Events, EventsHub};
use crate::frame::{StreamKind, monotonic_ns};
use crate::guard::{GuardSettings, LocalKill};
use crate::ingress::Ingress;
use crate::kill::KillWatch;
use crate::msgs::SmallEndpoint;
use crate::pose::PoseFeed;
use crate::record::Record;
use crate::replay::{Replay, ReplayAdapter};
use crate::stats::AdapterReport;
use crate::synthetic::Synthetic;
use anyhow::{Context, Result};
use std::collections::BTreeMap;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

/// The adapters of a configuration, ready to run.
pub struct Plan {
    /// Sinks (egress, record).
    pub sinks: Vec<Box<dyn Adapter>>,
    /// Sources (ingress, replay, synthetic).
    pub sources: Vec<Box<dyn Adapter>>,
    /// True if a source runs until stopped (ingress, looped replay, endless synthetic).
    pub endless: bool,
    /// `[bridge] stop_after_publishers_gone`: stop once the streams the sinks read have had no
    /// publisher for this long (after one was seen).
    pub publishers_gone: Option<Duration>,
}

/// What a configuration resolves to before anything runs: the replay (its bag opened and its
/// topics matched) and the kind of every stream. `--check` stops here; [`plan`] goes on.
pub struct Resolved {
    /// The opened replay.
    pub replay: Option<Replay>,
    /// Stream -> kind, from every source, `[streams]` and explicit egress kinds.
    pub kinds: BTreeMap<String, StreamKind>,
}

/// Opens the replay bag and works out every stream's kind; errors name the key: a bag that is
/// missing, unreadable or lacks the named topics, an egress `kind` that contradicts what the
/// stream carries, a recorded stream nothing says the kind of.
pub fn resolve(cfg: &Config) -> Result<Resolved> {
    let mut kinds: BTreeMap<String, StreamKind> = cfg.source_kinds();
    let replay = match &cfg.replay {
        Some(r) => {
            let replay = Replay::open(r.clone())
                .with_context(|| format!("replay.bag `{}`", r.bag.display()))?;
            for (stream, kind) in replay.routes.values() {
                kinds.insert(stream.clone(), *kind);
            }
            Some(replay)
        }
        None => None,
    };
    for (i, e) in cfg.egress.iter().enumerate() {
        let Some(k) = e.kind else { continue };
        match kinds.get(&e.stream) {
            Some(&have) if have != k => anyhow::bail!(
                "egress[{i}].kind: `{}` says stream `{}` carries {}, but its source publishes {}",
                match k {
                    StreamKind::Image => "image",
                    StreamKind::Cloud => "cloud",
                },
                e.stream,
                k.ros_type(),
                have.ros_type()
            ),
            Some(_) => {}
            None => {
                kinds.insert(e.stream.clone(), k);
            }
        }
    }
    if let Some(r) = &cfg.record {
        for (i, s) in r.streams.iter().enumerate() {
            if !kinds.contains_key(s) {
                anyhow::bail!(
                    "record.streams[{i}]: nothing says what stream `{s}` carries: add it to [streams] (`{s} = \"image\"` or `\"cloud\"`)"
                );
            }
        }
    }
    if let Some(v) = &cfg.view {
        crate::view::streams(v, &kinds)?;
    }
    Ok(Resolved { replay, kinds })
}

/// Builds the adapters (opens bags, DDS participants and the ROS 1 node; errors name what
/// failed).
pub fn plan(cfg: &Config) -> Result<Plan> {
    let Resolved { replay, kinds } = resolve(cfg)?;
    let mut sources: Vec<Box<dyn Adapter>> = Vec::new();
    let mut sinks: Vec<Box<dyn Adapter>> = Vec::new();
    let mut endless = false;
    // One ROS 1 node for both directions: the configuration refuses a topic read and written
    // on the same transport, so it never subscribes to its own output.
    let ros1 = if cfg.uses_ros1() {
        let settings = cfg.ros1_settings().map_err(anyhow::Error::msg)?;
        Some(Arc::new(
            crate::ros1::Node::start(&settings).context("ros1 (the bridge's ROS 1 node)")?,
        ))
    } else {
        None
    };
    if let Some(replay) = replay {
        endless |= replay.cfg.looped;
        let clock = if cfg.ros1.clock { ros1.clone() } else { None };
        sources.push(Box::new(ReplayAdapter { replay, clock }));
    }
    let mut small = SmallEndpoints::new(cfg, ros1.clone());
    let kill = Arc::new(LocalKill::default());
    let events = match &cfg.events {
        Some(e) => {
            let (hub, rx) = EventsHub::new();
            let transport = cfg.events_transport().unwrap_or_default();
            sinks.push(Box::new(Events {
                topic: e.topic.clone(),
                mode: e.mode,
                endpoint: small.of(transport)?,
                rx,
                hub: hub.clone(),
            }));
            Some(hub)
        }
        None => None,
    };
    // The live view reads every events record too (a hub of its own without [events]).
    let (events, view_events) = crate::view::tap_events(cfg.view.is_some(), events);
    if let (Some(k), Some(transport)) = (&cfg.kill, cfg.kill_transport()) {
        sinks.push(Box::new(KillWatch {
            topic: k.topic.clone(),
            ros2_type: k.ros2_type.clone(),
            field: k.field.clone(),
            definition: k.definition.clone(),
            rule: k.rule(),
            deadman: k.deadman_s.map(Duration::from_secs_f64),
            endpoint: small.of(transport)?,
            latch: kill.clone(),
            events: events.clone(),
            iox2: cfg.bridge.iox2.clone(),
            control_service: k.control_service.clone(),
        }));
    }
    if let (Some(p), Some(transport)) = (&cfg.pose, cfg.pose_transport()) {
        sinks.push(Box::new(PoseFeed {
            topic: p.topic.clone(),
            ros2_type: p.ros2_type.clone(),
            field: p.field.clone(),
            definition: p.definition.clone(),
            max_rate_hz: p.max_rate_hz,
            endpoint: small.of(transport)?,
            iox2: cfg.bridge.iox2.clone(),
            control_service: p.control_service.clone(),
        }));
    }
    let mut calibrations: BTreeMap<String, Arc<CameraInfoLink>> = BTreeMap::new();
    if !cfg.ingress.is_empty() {
        let transports: Vec<Transport> = cfg.ingress.iter().map(|i| i.transport).collect();
        let ends = Endpoints::open(cfg, &transports, "ingress", &ros1)?;
        endless = true;
        for i in &cfg.ingress {
            let camera_info = match &i.camera_info {
                Some(topic) => {
                    let link = calibrations.entry(i.stream.clone()).or_default().clone();
                    Some((topic.clone(), small.of(i.transport)?, link))
                }
                None => None,
            };
            sources.push(Box::new(Ingress {
                spec: TopicSpec {
                    topic: i.topic.clone(),
                    ros_type: i.ros_type,
                    qos: i.qos,
                },
                stream: i.stream.clone(),
                endpoint: ends.of(i.transport)?,
                camera_info,
            }));
        }
    }
    for c in &cfg.synthetic.camera {
        endless |= c.count.is_none();
        sources.push(Box::new(Synthetic::camera(c.clone())));
    }
    for l in &cfg.synthetic.lidar {
        endless |= l.count.is_none();
        sources.push(Box::new(Synthetic::lidar(l.clone())));
    }
    if !cfg.egress.is_empty() {
        let transports: Vec<Transport> = cfg.egress.iter().map(|e| e.transport).collect();
        let ends = Endpoints::open(cfg, &transports, "egress", &ros1)?;
        for (i, e) in cfg.egress.iter().enumerate() {
            let camera_info = match (&e.camera_info, calibrations.get(&e.stream)) {
                (Some(topic), Some(link)) => Some((
                    link.clone(),
                    CameraInfoSink::new(topic.clone(), &small.of(e.transport)?)
                        .with_context(|| format!("egress[{i}].camera_info"))?,
                )),
                _ => None,
            };
            let mut sink = egress_sink(i, e, &kinds, &ends)?;
            sink.kill = kill.clone();
            sink.events = events.clone();
            sink.camera_info = camera_info;
            sinks.push(sink);
        }
    }
    if let Some(r) = &cfg.record {
        sinks.push(Box::new(Record {
            cfg: r.clone(),
            kinds: kinds.clone(),
        }));
    }
    if let Some(v) = crate::view::View::new(cfg, &kinds, &calibrations, view_events, events)? {
        sinks.push(Box::new(v));
    }
    Ok(Plan {
        sinks,
        sources,
        endless,
        publishers_gone: cfg
            .bridge
            .stop_after_publishers_gone
            .map(Duration::from_secs_f64),
    })
}

/// Where the topics of one direction (ingress or egress) are opened: a DDS participant of its
/// own when any topic of that direction is on DDS, and the bridge's ROS 1 node.
struct Endpoints {
    dds: Option<Arc<dyn DdsBackend>>,
    ros1: Option<Arc<crate::ros1::Node>>,
}

impl Endpoints {
    /// The endpoints for `transports` (the direction's topics), the participant named after
    /// the bridge and `role`.
    fn open(
        cfg: &Config,
        transports: &[Transport],
        role: &str,
        ros1: &Option<Arc<crate::ros1::Node>>,
    ) -> Result<Endpoints> {
        let dds: Option<Arc<dyn DdsBackend>> = if transports.contains(&Transport::Dds) {
            Some(Arc::from(
                dds::backend(
                    &cfg.dds.participant(),
                    &format!("{}_{role}", cfg.bridge.name),
                )
                .with_context(|| format!("dds ({role} participant)"))?,
            ))
        } else {
            None
        };
        Ok(Endpoints {
            dds,
            ros1: ros1.clone(),
        })
    }

    /// The endpoint of a topic on `transport`.
    fn of(&self, transport: Transport) -> Result<Endpoint> {
        match (transport, &self.dds) {
            (Transport::Dds, Some(d)) => Ok(Endpoint::Dds(d.clone())),
            _ => Ok(Endpoint::Ros1(
                self.ros1
                    .clone()
                    .context("the ROS 1 node was not started")?,
            )),
        }
    }
}

/// Where the small topics (events, camera_info, kill switch, pose) are opened: the ROS 1 node,
/// and for ROS 2 one RustDDS participant of their own (opened when first needed).
struct SmallEndpoints {
    ros1: Option<Arc<crate::ros1::Node>>,
    dds: Option<Arc<RustddsBackend>>,
    participant: crate::dds::ParticipantConfig,
    name: String,
}

impl SmallEndpoints {
    fn new(cfg: &Config, ros1: Option<Arc<crate::ros1::Node>>) -> Self {
        SmallEndpoints {
            ros1,
            dds: None,
            participant: cfg.dds.participant(),
            name: format!("{}_small", cfg.bridge.name),
        }
    }

    /// The endpoint of a small topic on `transport`.
    fn of(&mut self, transport: Transport) -> Result<SmallEndpoint> {
        match transport {
            Transport::Ros1 => Ok(SmallEndpoint::Ros1(
                self.ros1
                    .clone()
                    .context("the ROS 1 node was not started")?,
            )),
            Transport::Dds => {
                if self.dds.is_none() {
                    let nets = crate::dds::interfaces::resolve(&self.participant.interfaces)?;
                    self.dds = Some(Arc::new(
                        RustddsBackend::new(self.participant.domain_id, &self.name, nets.as_deref())
                            .context("dds (the participant of the small topics: events, camera_info, kill switch, pose)")?,
                    ));
                }
                Ok(SmallEndpoint::Dds(self.dds.clone().expect("opened above")))
            }
        }
    }
}

/// The sink of `[[egress]]` entry `i`: the perturbed side of its stream, on its topic, guarded
/// (see [`crate::guard`]).
fn egress_sink(
    i: usize,
    e: &crate::config::EgressEntry,
    kinds: &BTreeMap<String, StreamKind>,
    ends: &Endpoints,
) -> Result<Box<Egress>> {
    let kind = *kinds.get(&e.stream).with_context(|| {
        format!(
            "egress[{i}].kind: nothing says what stream `{}` carries: add `kind = \"image\"` or `\"cloud\"`",
            e.stream
        )
    })?;
    let ros_type = match kind {
        StreamKind::Image => dds::RosType::Image,
        StreamKind::Cloud => dds::RosType::PointCloud2,
    };
    Ok(Box::new(Egress {
        stream: e.stream.clone(),
        kind,
        spec: TopicSpec {
            topic: e.topic.clone(),
            ros_type,
            qos: e.qos,
        },
        side: Side::Perturbed,
        endpoint: ends.of(e.transport)?,
        guard: Some(GuardSettings {
            deadline: e.deadline_ms.map(|ms| Duration::from_secs_f64(ms / 1000.0)),
            rate_hz: e.rate_hz,
            on_late: e.on_late,
        }),
        kill: Arc::default(),
        events: None,
        camera_info: None,
    }))
}

static SIGNALLED: AtomicBool = AtomicBool::new(false);

/// What [`on_stopping`] registered.
static STOPPING_HOOK: std::sync::OnceLock<Box<dyn Fn() + Send + Sync>> = std::sync::OnceLock::new();

/// Registers `f` to run once the bridge decides to stop, before its adapters are told to (the
/// binary quiets the DDS libraries' log there: tearing a RustDDS participant down logs a dozen
/// harmless ERROR lines). Only the first registration counts.
pub fn on_stopping(f: Box<dyn Fn() + Send + Sync>) {
    let _ = STOPPING_HOOK.set(f);
}

fn stopping() {
    if let Some(f) = STOPPING_HOOK.get() {
        f();
    }
}

extern "C" fn on_signal(_: libc::c_int) {
    SIGNALLED.store(true, Ordering::SeqCst);
}

/// Makes SIGINT and SIGTERM set the stop flag instead of killing the process.
// libc's signal.
#[allow(unsafe_code)]
pub fn install_signal_handlers() {
    // SAFETY: the handler only stores to an atomic, which is async-signal-safe.
    unsafe {
        libc::signal(libc::SIGINT, on_signal as *const () as libc::sighandler_t);
        libc::signal(libc::SIGTERM, on_signal as *const () as libc::sighandler_t);
    }
}

/// What a run did and why it ended.
#[derive(Debug)]
pub struct Outcome {
    /// Every adapter's report.
    pub reports: Vec<AdapterReport>,
    /// Why the bridge stopped.
    pub stopped_by: String,
}

/// Runs a plan on `bus` until stopped; returns every adapter's report and why it stopped.
pub fn run(plan: Plan, bus: Arc<dyn Bus>, linger: Duration) -> Result<Outcome> {
    let mut r = Runner {
        stop: Arc::new(AtomicBool::new(false)),
        why: Arc::default(),
        upstream: Arc::new(std::sync::atomic::AtomicU64::new(0)),
        bus,
        handles: Vec::new(),
    };
    let has_sources = !plan.sources.is_empty();
    // The sinks first, so the sources' first frames find them ready.
    r.start(plan.sinks, false)?;
    r.start(plan.sources, true)?;
    tracing::info!("bridge running on the {} bus", r.bus.name());
    r.supervise(has_sources && !plan.endless, plan.publishers_gone, linger);
    // Also when an adapter stopped the run (a recorder's max_frames, a failure).
    stopping();
    r.finish()
}

/// An adapter's thread: its name, whether it is a sink, and its report.
type AdapterThread = (String, bool, std::thread::JoinHandle<Result<AdapterReport>>);

/// The running adapters and what they share: the stop flag, the first reason to stop, and when a
/// sink last saw a publisher.
struct Runner {
    stop: Arc<AtomicBool>,
    why: Arc<std::sync::Mutex<Option<String>>>,
    upstream: Arc<std::sync::atomic::AtomicU64>,
    bus: Arc<dyn Bus>,
    handles: Vec<AdapterThread>,
}

impl Runner {
    /// Starts `adapters` (each on its thread) and waits until they are ready; sources are not
    /// started once the run is stopping.
    fn start(&mut self, adapters: Vec<Box<dyn Adapter>>, sources: bool) -> Result<()> {
        let (tx, rx) = crossbeam::channel::unbounded();
        let n = adapters.len();
        for a in adapters {
            if sources && self.stop.load(Ordering::SeqCst) {
                break;
            }
            self.spawn(a, tx.clone())?;
        }
        drop(tx);
        self.wait_ready(rx, n);
        Ok(())
    }

    /// Runs `a` on a thread of its own; a failure stops the whole run, saying why.
    fn spawn(&mut self, a: Box<dyn Adapter>, ready: crossbeam::channel::Sender<()>) -> Result<()> {
        let name = a.name();
        let sink = a.is_sink();
        let ctl = Control::new(self.stop.clone(), Some(ready))
            .with_reason(self.why.clone())
            .with_upstream(self.upstream.clone());
        let bus = self.bus.clone();
        let h = std::thread::Builder::new()
            .name(name.chars().take(15).collect())
            .spawn(move || {
                let stopper = ctl.clone();
                let r = a.run(bus.as_ref(), ctl);
                if let Err(e) = &r {
                    tracing::error!("{e:#}");
                    stopper.stop_because(format!("an adapter failed: {e:#}"));
                }
                r
            })?;
        self.handles.push((name, sink, h));
        Ok(())
    }

    /// Waits until `n` adapters are ready; an adapter that fails first drops its sender and
    /// stops the others, which ends the wait.
    fn wait_ready(&self, rx: crossbeam::channel::Receiver<()>, n: usize) {
        let deadline = Instant::now() + Duration::from_secs(120);
        let mut got = 0;
        while got < n && Instant::now() < deadline && !self.stop.load(Ordering::SeqCst) {
            // A signal while the adapters start (e.g. a long pre-render) stops them too.
            if SIGNALLED.load(Ordering::SeqCst) {
                self.set_why("SIGINT/SIGTERM".into());
                self.stop.store(true, Ordering::SeqCst);
                break;
            }
            match rx.recv_timeout(Duration::from_millis(50)) {
                Ok(()) => got += 1,
                Err(crossbeam::channel::RecvTimeoutError::Timeout) => {}
                Err(crossbeam::channel::RecvTimeoutError::Disconnected) => break,
            }
        }
    }

    /// Keeps the first reason given to stop.
    fn set_why(&self, w: String) {
        if let Ok(mut g) = self.why.lock() {
            g.get_or_insert(w);
        }
    }

    /// Stops the run for `why`.
    fn stop_for(&self, why: String) {
        self.set_why(why);
        stopping();
        self.stop.store(true, Ordering::SeqCst);
    }

    /// Watches the run until it stops: a signal, an adapter's stop, every source finished (when
    /// `sources_end`; the sinks get `linger` for the last frames), no publisher for
    /// `publishers_gone`, or every adapter finished.
    fn supervise(&self, sources_end: bool, publishers_gone: Option<Duration>, linger: Duration) {
        let mut sources_done_at: Option<Instant> = None;
        loop {
            if SIGNALLED.load(Ordering::SeqCst) {
                self.stop_for("SIGINT/SIGTERM".into());
            }
            if self.stop.load(Ordering::SeqCst) {
                break;
            }
            let left = |sinks: bool| {
                self.handles
                    .iter()
                    .any(|(_, sink, h)| *sink == sinks && !h.is_finished())
            };
            let (sources_left, sinks_left) = (left(false), left(true));
            if sources_end && !sources_left {
                let t = *sources_done_at.get_or_insert_with(Instant::now);
                if !sinks_left || t.elapsed() >= linger {
                    self.stop_for(format!(
                        "every source finished (the sinks had {:.1} s for the last frames)",
                        linger.as_secs_f64()
                    ));
                    break;
                }
            }
            if let Some(gone) = publishers_gone {
                let seen = self.upstream.load(Ordering::Relaxed);
                if seen != 0 && monotonic_ns().saturating_sub(seen) >= gone.as_nanos() as u64 {
                    self.stop_for(format!(
                        "the streams this bridge reads have had no publisher for {:.1} s \
                         (stop_after_publishers_gone)",
                        gone.as_secs_f64()
                    ));
                    break;
                }
            }
            if !sinks_left && !sources_left {
                self.stop_for("every adapter finished".into());
                break;
            }
            std::thread::sleep(Duration::from_millis(20));
        }
    }

    /// Joins every adapter: their reports, or the first error.
    fn finish(self) -> Result<Outcome> {
        let stopped_by = self
            .why
            .lock()
            .ok()
            .and_then(|g| g.clone())
            .unwrap_or_else(|| "stopped".into());
        tracing::info!("stopping: {stopped_by}");
        let mut reports = Vec::new();
        let mut first_err = None;
        for (name, _, h) in self.handles {
            match h.join() {
                Ok(Ok(r)) => reports.push(r),
                Ok(Err(e)) => {
                    first_err.get_or_insert(e.context(name));
                }
                Err(_) => {
                    first_err.get_or_insert(anyhow::anyhow!("{name}: the adapter thread panicked"));
                }
            }
        }
        match first_err {
            Some(e) => Err(e),
            None => Ok(Outcome {
                reports,
                stopped_by,
            }),
        }
    }
}

/// The bus of a configuration.
pub fn make_bus(cfg: &Config) -> Result<Arc<dyn Bus>> {
    match cfg.bridge.bus {
        BusKind::Local => Ok(Arc::new(crate::bus::SharedLocalBus::default())),
        BusKind::Iceoryx2 => crate::iox::bus(&cfg.bridge),
    }
}

/// Prints the reports as a table.
pub fn print_reports(reports: &[AdapterReport]) {
    println!(
        "{:<60} {:>8} {:>8} {:>5} {:>7} {:>6} {:>9} {:>9}",
        "adapter", "in", "out", "bad", "skipped", "failed", "p50 ms", "p99 ms"
    );
    for r in reports {
        let (p50, p99) = r
            .latency
            .filter(|l| l.n > 0)
            .map(|l| (format!("{:.2}", l.p50_ms), format!("{:.2}", l.p99_ms)))
            .unwrap_or_else(|| ("-".into(), "-".into()));
        println!(
            "{:<60} {:>8} {:>8} {:>5} {:>7} {:>6} {:>9} {:>9}",
            r.name, r.received, r.forwarded, r.bad, r.skipped, r.failed, p50, p99
        );
        for d in &r.damage {
            println!("    damage: {d}");
        }
        if r.undelivered > 0 {
            println!(
                "    note: {} frame(s) published while no reader (perturbd) was connected: lost",
                r.undelivered
            );
        }
        if r.dropped > 0 {
            println!(
                "    dropped from full queues (ROS 1 subscribers slower than the stream, or the ingress's own queue): {}",
                r.dropped
            );
        }
        if r.lost > 0 {
            println!(
                "    lost before the bridge (gaps in the ROS 1 header seq): {}",
                r.lost
            );
        }
        for n in &r.notes {
            println!("    note: {n}");
        }
    }
}
