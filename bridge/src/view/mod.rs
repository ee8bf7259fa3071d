//! The live view (`[view]`): a Foxglove WebSocket server in the bridge, made with the Foxglove
//! SDK, that shows the operator what the ADS is being shown while it drives
//! (`docs/live-view.md`):
//!
//! - per stream, raw beside perturbed: camera frames as JPEG (`/<stream>/raw/image`,
//!   `/<stream>/perturbed/image`, `foxglove.CompressedImage`, at `rate_hz`, shrunk to at most
//!   `max_width`), clouds as `foxglove.PointCloud` (`/<stream>/raw/points`, `.../perturbed/points`,
//!   at `cloud_rate_hz`, thinned to `max_points`), the stream's `camera_info` when its ingress
//!   relays one (`/<stream>/camera_info`, `foxglove.CameraCalibration`, scaled to the JPEG);
//! - the events records (`/perturb/events`, JSON, `docs/events.schema.json`), the daemon's state
//!   (`/perturb/status`) and per-stream statistics (`/<stream>/stats`: rates, latency per hop,
//!   frames lost by cause; [`stats`]), JSON with their schemas;
//! - the daemon's controls as services ([`control`]).
//!
//! The view never holds the pipeline up: its readers are extra subscribers of each stream side
//! in shared memory, on threads of their own at a lower scheduling priority; each keeps only the
//! newest frame it received and converts one at the view's rate, while iceoryx2 overwrites what
//! a busy reader has not taken (counted as `missed`); a viewer slower than the stream loses the
//! oldest view messages in its own queue on the server (`backlog`). A side that finds no reader
//! slot left (`max_subscribers`) says so and tries again every few seconds; a view that cannot
//! listen says so and the bridge carries on without it.

pub mod control;
pub mod frames;
pub mod stats;

use crate::adapter::{Adapter, Control};
use crate::bus::{Bus, Side};
use crate::camera_info::CameraInfoLink;
use crate::config::ViewSection;
use crate::daemon_link::DaemonLink;
use crate::events::EventsHub;
use crate::frame::{StreamKind, monotonic_ns};
use crate::stats::AdapterReport;
use anyhow::{Context as _, Result};
use crossbeam::channel::Receiver;
use foxglove::schemas::{CameraCalibration, CompressedImage, PointCloud};
use foxglove::{Channel, RawChannel, Schema};
use perturb_bag::events::EventRecord;
use perturb_wire::TransportOptions;
use perturb_wire::control::ControlRequest;
use stats::{SideCounters, StatsBook};
use std::collections::BTreeMap;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

/// The events schema the view advertises with `/perturb/events` (the events topic's own).
const EVENTS_SCHEMA: &str = include_str!("../../../docs/events.schema.json");

/// How long a side waits before it first subscribes (the egress and the recorder of the same
/// bridge, started at the same moment, take their reader slots first), and between two tries
/// when the stream had no slot left.
const FIRST_TRY: Duration = Duration::from_secs(1);
const RETRY: Duration = Duration::from_secs(3);

/// Gives `events` (the events topic's hub, if the bridge has one) a second reader for the view
/// when `view` runs, making a hub for the view alone when there is none; returns the hub every
/// adapter reports to and the view's reader.
pub fn tap_events(
    view: bool,
    events: Option<Arc<EventsHub>>,
) -> (Option<Arc<EventsHub>>, Option<Receiver<EventRecord>>) {
    if !view {
        return (events, None);
    }
    let hub = events.unwrap_or_else(|| EventsHub::new().0);
    let rx = hub.tap();
    (Some(hub), rx)
}

/// The live view adapter.
pub struct View {
    /// Its settings.
    pub cfg: ViewSection,
    /// The streams shown, with what they carry.
    pub streams: Vec<(String, StreamKind)>,
    /// The streams' camera_info, where an ingress relays one.
    pub calibrations: BTreeMap<String, Arc<CameraInfoLink>>,
    /// Every events record of the bridge.
    pub events: Option<Receiver<EventRecord>>,
    /// The events hub (kill and arm from the view are recorded there).
    pub hub: Option<Arc<EventsHub>>,
    /// The daemon's namespace.
    pub iox2: TransportOptions,
    /// The bridge's name (the server's name).
    pub bridge: String,
}

impl View {
    /// The view of a configuration: `[view] streams`, or every stream of `kinds`; errors name
    /// the key.
    pub fn new(
        cfg: &crate::config::Config,
        kinds: &BTreeMap<String, StreamKind>,
        calibrations: &BTreeMap<String, Arc<CameraInfoLink>>,
        events: Option<Receiver<EventRecord>>,
        hub: Option<Arc<EventsHub>>,
    ) -> Result<Option<View>> {
        let Some(v) = &cfg.view else {
            return Ok(None);
        };
        Ok(Some(View {
            cfg: v.clone(),
            streams: streams(v, kinds)?,
            calibrations: calibrations.clone(),
            events,
            hub,
            iox2: cfg.bridge.iox2.clone(),
            bridge: cfg.bridge.name.clone(),
        }))
    }
}

/// The streams `v` shows: its `streams`, or every stream of `kinds`; an error names a listed
/// stream nothing says the kind of.
pub fn streams(
    v: &ViewSection,
    kinds: &BTreeMap<String, StreamKind>,
) -> Result<Vec<(String, StreamKind)>> {
    if v.streams.is_empty() {
        return Ok(kinds.iter().map(|(s, k)| (s.clone(), *k)).collect());
    }
    v.streams
        .iter()
        .enumerate()
        .map(|(i, s)| {
            let k = kinds.get(s).with_context(|| {
                format!(
                    "view.streams[{i}]: nothing says what stream `{s}` carries: add it to [streams] (`{s} = \"image\"` or `\"cloud\"`)"
                )
            })?;
            Ok((s.clone(), *k))
        })
        .collect()
}

/// The view's topics of a stream (`side`: a frame side; `None`: the stream's own topics).
pub fn topic(stream: &str, side: Option<Side>, kind: StreamKind) -> String {
    match (side, kind) {
        (Some(side), StreamKind::Image) => format!("/{stream}/{}/image", side.as_str()),
        (Some(side), StreamKind::Cloud) => format!("/{stream}/{}/points", side.as_str()),
        (None, _) => format!("/{stream}/stats"),
    }
}

/// The topic of a camera stream's calibration.
pub fn calibration_topic(stream: &str) -> String {
    format!("/{stream}/camera_info")
}

/// What one stream side sends its frames on.
enum Out {
    Image {
        channel: Channel<CompressedImage>,
        calibration: Option<(Arc<CameraInfoLink>, Channel<CameraCalibration>)>,
    },
    Cloud(Channel<PointCloud>),
}

impl Out {
    fn has_sinks(&self) -> bool {
        match self {
            Out::Image { channel, .. } => channel.has_sinks(),
            Out::Cloud(c) => c.has_sinks(),
        }
    }
}

/// One stream side and what the view does with it.
struct SideJob<'a> {
    stream: &'a str,
    kind: StreamKind,
    side: Side,
    out: Out,
    counters: &'a SideCounters,
    period: Duration,
}

/// A JSON channel with its schema.
fn json_channel(
    ctx: &Arc<foxglove::Context>,
    topic: &str,
    schema_name: &str,
    schema: &'static str,
) -> Result<Arc<RawChannel>> {
    ctx.channel_builder(topic)
        .message_encoding("json")
        .schema(Schema::new(schema_name, "jsonschema", schema.as_bytes()))
        .build_raw()
        .with_context(|| format!("view channel {topic}"))
}

/// Lowers the calling thread's scheduling priority (nice 10): the view's threads give way to
/// the pipeline's whenever both want a core.
// libc's setpriority.
#[allow(unsafe_code)]
fn give_way() {
    // SAFETY: setpriority with PRIO_PROCESS and who = 0 changes the nice value of the calling
    // thread only (Linux keeps one per thread); it touches no memory of ours.
    unsafe {
        libc::setpriority(libc::PRIO_PROCESS, 0, 10);
    }
}

impl Adapter for View {
    fn name(&self) -> String {
        format!("view -> ws://{}:{}", self.cfg.bind, self.cfg.port)
    }

    fn is_sink(&self) -> bool {
        true
    }

    fn run(self: Box<Self>, bus: &dyn Bus, mut ctl: Control) -> Result<AdapterReport> {
        let name = self.name();
        let mut rep = AdapterReport {
            name: name.clone(),
            ..Default::default()
        };
        let ctx = foxglove::Context::new();
        // The channels exist before the server starts, so a viewer sees them all at once.
        let counters: Vec<(SideCounters, SideCounters)> =
            self.streams.iter().map(|_| Default::default()).collect();
        let mut jobs = Vec::new();
        let mut stats_channels = Vec::new();
        for ((stream, kind), (raw_c, pert_c)) in self.streams.iter().zip(&counters) {
            for (side, c) in [(Side::Raw, raw_c), (Side::Perturbed, pert_c)] {
                let frames = topic(stream, Some(side), *kind);
                let (out, hz) = match kind {
                    StreamKind::Image => (
                        Out::Image {
                            channel: ctx.channel_builder(&frames).build::<CompressedImage>(),
                            calibration: match (side, self.calibrations.get(stream)) {
                                (Side::Raw, Some(link)) => Some((
                                    link.clone(),
                                    ctx.channel_builder(calibration_topic(stream))
                                        .build::<CameraCalibration>(),
                                )),
                                _ => None,
                            },
                        },
                        self.cfg.rate_hz,
                    ),
                    StreamKind::Cloud => (
                        Out::Cloud(ctx.channel_builder(&frames).build::<PointCloud>()),
                        self.cfg.cloud_rate_hz,
                    ),
                };
                jobs.push(SideJob {
                    stream,
                    kind: *kind,
                    side,
                    out,
                    counters: c,
                    period: Duration::from_secs_f64(1.0 / hz),
                });
            }
            stats_channels.push(json_channel(
                &ctx,
                &topic(stream, None, *kind),
                "perturb.ViewStats",
                stats::STATS_SCHEMA,
            )?);
        }
        let events_channel = json_channel(
            &ctx,
            "/perturb/events",
            "perturb.EventRecord",
            EVENTS_SCHEMA,
        )?;
        let status_channel = json_channel(
            &ctx,
            "/perturb/status",
            "perturb.ViewStatus",
            stats::STATUS_SCHEMA,
        )?;
        let (port, calls) = control::port();
        let runtime = tokio::runtime::Builder::new_multi_thread()
            .worker_threads(1)
            .thread_name("view-ws")
            .on_thread_start(give_way)
            .enable_all()
            .build()
            .context("the view's runtime")?;
        let mut server = ctx
            .websocket_server()
            .name(format!("perturb-bridge {}", self.bridge))
            .bind(self.cfg.bind.clone(), self.cfg.port)
            .supported_encodings(["json"])
            .message_backlog_size(self.cfg.backlog);
        if self.cfg.control {
            server = server.services(control::services(port.clone(), self.hub.clone()));
        }
        let server = match runtime.block_on(server.start()) {
            Ok(s) => s,
            Err(e) => {
                // The view is for the operator: the sensor path carries on without it.
                let why = format!(
                    "the live view could not listen on {}:{}: {e}; the bridge runs without it",
                    self.cfg.bind, self.cfg.port
                );
                tracing::error!("{why}");
                rep.notes.push(why);
                ctl.ready();
                return Ok(rep);
            }
        };
        let url = format!("ws://{}:{}", self.cfg.bind, server.port());
        tracing::info!(
            "live view: {url} ({} stream(s); open it in Foxglove or Lichtblick, layout config/foxglove-view-layout.json)",
            self.streams.len()
        );
        ctl.ready();
        let stop = AtomicBool::new(false);
        let view = &*self;
        let max_clients = std::sync::atomic::AtomicUsize::new(0);
        std::thread::scope(|scope| -> Result<()> {
            for job in &jobs {
                let (stop, ctl) = (&stop, &ctl);
                std::thread::Builder::new()
                    .name(format!("view-{}", job.side.as_str()))
                    .spawn_scoped(scope, move || {
                        give_way();
                        view.run_side(bus, job, stop, ctl)
                    })?;
            }
            let link = DaemonLink::new(&view.iox2, &view.cfg.control_service, "view");
            let stop_ref = &stop;
            std::thread::Builder::new()
                .name("view-control".into())
                .spawn_scoped(scope, move || serve_control(link, calls, stop_ref))?;
            let (server, max_clients) = (&server, &max_clients);
            let (stats_channels, events_channel, status_channel, counters, port) = (
                &stats_channels,
                &events_channel,
                &status_channel,
                &counters,
                &port,
            );
            std::thread::Builder::new()
                .name("view-state".into())
                .spawn_scoped(scope, move || {
                    give_way();
                    let mut book = StatsBook::new();
                    let interval = Duration::from_secs_f64(view.cfg.stats_interval_s);
                    let mut next = Instant::now() + interval;
                    while !stop_ref.load(Ordering::Relaxed) {
                        let wait = next
                            .saturating_duration_since(Instant::now())
                            .min(Duration::from_millis(100));
                        match &view.events {
                            Some(rx) => {
                                if let Ok(r) = rx.recv_timeout(wait) {
                                    book.event(&r);
                                    if events_channel.has_sinks()
                                        && let Ok(json) = serde_json::to_vec(&r)
                                    {
                                        events_channel.log(&json);
                                    }
                                }
                            }
                            None => std::thread::sleep(wait),
                        }
                        if Instant::now() < next {
                            continue;
                        }
                        next = Instant::now() + interval;
                        let clients = server.client_count();
                        max_clients.fetch_max(clients, Ordering::Relaxed);
                        let answer = port.request(ControlRequest::Stats);
                        status_channel.log(&status_json(&answer));
                        let reports = answer.as_ref().ok().and_then(|a| a.streams.as_deref());
                        let sides = view
                            .streams
                            .iter()
                            .zip(counters.iter())
                            .map(|((s, k), (r, p))| (s.as_str(), *k, r, p));
                        for (msg, ch) in book
                            .messages(sides, reports, clients)
                            .iter()
                            .zip(stats_channels.iter())
                        {
                            if let Ok(json) = serde_json::to_vec(msg) {
                                ch.log(&json);
                            }
                        }
                    }
                })?;
            while !ctl.stopped() {
                std::thread::sleep(crate::adapter::POLL);
            }
            stop.store(true, Ordering::Relaxed);
            Ok(())
        })?;
        // A viewer that stopped reading keeps its connection's tasks waiting on a full socket:
        // the server gets two seconds to close, then its tasks are dropped with the runtime.
        let closed = runtime.block_on(async {
            tokio::time::timeout(Duration::from_secs(2), server.stop().wait())
                .await
                .is_ok()
        });
        if !closed {
            rep.notes
                .push("the view's server did not close within 2 s (a viewer not reading)".into());
        }
        runtime.shutdown_timeout(Duration::from_secs(2));
        for ((stream, _), (raw, pert)) in self.streams.iter().zip(&counters) {
            let n = |c: &SideCounters, f: fn(&SideCounters) -> &std::sync::atomic::AtomicU64| {
                f(c).load(Ordering::Relaxed)
            };
            rep.received += n(raw, |c| &c.received) + n(pert, |c| &c.received);
            rep.forwarded += n(raw, |c| &c.shown) + n(pert, |c| &c.shown);
            rep.bad += n(raw, |c| &c.failed) + n(pert, |c| &c.failed);
            rep.notes.push(format!(
                "{stream}: {} raw and {} perturbed frames shown, {} and {} missed (view only)",
                n(raw, |c| &c.shown),
                n(pert, |c| &c.shown),
                n(raw, |c| &c.missed),
                n(pert, |c| &c.missed),
            ));
        }
        rep.notes.push(format!(
            "{url}: at most {} viewer(s) at once",
            max_clients.load(Ordering::Relaxed)
        ));
        Ok(rep)
    }
}

/// The control thread: the line to the daemon, at the view's priority.
fn serve_control(
    link: DaemonLink,
    calls: Receiver<(
        ControlRequest,
        crossbeam::channel::Sender<Result<perturb_wire::control::ControlResponse, String>>,
    )>,
    stop: &AtomicBool,
) {
    give_way();
    control::serve(link, calls, stop);
}

/// The `/perturb/status` message of the daemon's answer to `stats` (or of its silence).
fn status_json(
    answer: &Result<perturb_wire::control::ControlResponse, control::ControlError>,
) -> Vec<u8> {
    let mut v = serde_json::json!({
        "version": stats::VERSION,
        "t_wall_ns": crate::frame::wall_ns(),
        "daemon": "down",
        "killed": null,
        "campaign": null,
        "streams": [],
    });
    match answer {
        Ok(a) => {
            v["daemon"] = "up".into();
            v["killed"] = serde_json::to_value(&a.killed).unwrap_or_default();
            v["campaign"] = serde_json::to_value(&a.campaign).unwrap_or_default();
            v["streams"] = a
                .streams
                .iter()
                .flatten()
                .map(|s| {
                    serde_json::json!({
                        "name": s.name, "id": s.id, "perturbation": s.perturbation,
                        "severity": s.severity, "seed": s.seed, "step": s.step,
                    })
                })
                .collect();
        }
        Err(e) => v["error"] = e.to_string().into(),
    }
    serde_json::to_vec(&v).unwrap_or_default()
}

impl View {
    /// Reads one stream side until `stop`: subscribes (again every [`RETRY`] while the
    /// stream has no reader slot left), keeps the newest frame of each read and sends one
    /// per period while a viewer subscribes.
    fn run_side(&self, bus: &dyn Bus, job: &SideJob<'_>, stop: &AtomicBool, ctl: &Control) {
        let what = format!("live view {}/{}", job.stream, job.side.as_str());
        let wait = |d: Duration| {
            let end = Instant::now() + d;
            while Instant::now() < end && !stop.load(Ordering::Relaxed) && !ctl.stopped() {
                std::thread::sleep(Duration::from_millis(50));
            }
        };
        wait(FIRST_TRY);
        let mut said = false;
        let mut sub = loop {
            if stop.load(Ordering::Relaxed) {
                return;
            }
            match bus.subscriber(job.stream, job.kind, job.side) {
                Ok(s) => break s,
                Err(e) => {
                    if !said {
                        tracing::warn!(
                            "{what}: cannot read the stream ({e:#}); trying again every {} s (a reader slot frees when another reader leaves; [bridge] qos.max_subscribers)",
                            RETRY.as_secs()
                        );
                        said = true;
                    }
                    wait(RETRY);
                }
            }
        };
        let mut last_seq = None;
        // When the next frame is due: one period after the last one was due (not after it was
        // sent), so a 30 Hz stream shown at 10 Hz gets every third frame, not every fourth.
        let mut next_due = Instant::now();
        let mut scratch = perturb_core::encoding::Scratch::new();
        let mut decoder: Option<frames::CalibrationDecoder> = None;
        let mut bad = 0u64;
        while !stop.load(Ordering::Relaxed) {
            let mut frames = match sub.recv_held(Duration::from_millis(50)) {
                Ok(f) => f,
                Err(e) => {
                    tracing::warn!("{what}: {e:#}");
                    wait(Duration::from_millis(200));
                    continue;
                }
            };
            for f in &frames {
                let m = f.meta();
                job.counters.received(&m.hops, m.seq, &mut last_seq);
            }
            let Some(newest) = frames.pop() else {
                continue;
            };
            let superseded = frames.len() as u64;
            // The older ones go back to shared memory at once.
            drop(frames);
            job.counters
                .skipped
                .fetch_add(superseded, Ordering::Relaxed);
            let now = Instant::now();
            // A quarter of a period early still counts (frames come on the sensor's grid).
            if now + job.period / 4 < next_due || !job.out.has_sinks() {
                job.counters.skipped.fetch_add(1, Ordering::Relaxed);
                continue;
            }
            // After a pause (or from a source slower than the view) the schedule starts anew.
            next_due = (next_due + job.period).max(now);
            let t0 = monotonic_ns();
            let sent = match &job.out {
                Out::Image {
                    channel,
                    calibration,
                } => {
                    let shrunk =
                        frames::shrink(&newest.payload(), self.cfg.max_width, &mut scratch);
                    drop(newest);
                    shrunk.and_then(|s| {
                        let msg = frames::jpeg(&s, self.cfg.jpeg_quality)?;
                        channel.log(&msg);
                        if let Some((link, ch)) = calibration
                            && let Some(c) = link.latest()
                        {
                            if decoder.is_none() {
                                decoder = Some(frames::CalibrationDecoder::new()?);
                            }
                            let d = decoder.as_ref().expect("made above");
                            ch.log(&d.calibration(&c, s.factor)?);
                        }
                        Ok(())
                    })
                }
                Out::Cloud(channel) => {
                    let msg = frames::cloud(&newest.payload(), self.cfg.max_points);
                    drop(newest);
                    msg.map(|m| channel.log(&m))
                }
            };
            match sent {
                Ok(()) => job.counters.encoded(monotonic_ns().saturating_sub(t0)),
                Err(e) => {
                    job.counters.failed.fetch_add(1, Ordering::Relaxed);
                    bad += 1;
                    crate::stats::log_bad(&what, bad, &e);
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::Value;

    /// The schema node a dotted field path leads to in `schema` (following `$ref`s to `$defs`).
    fn field<'a>(schema: &'a Value, path: &str) -> Option<&'a Value> {
        let mut node = schema;
        for part in path.split('.') {
            while let Some(r) = node["$ref"].as_str() {
                node = &schema["$defs"][r.strip_prefix("#/$defs/")?];
            }
            node = node["properties"].get(part)?;
        }
        Some(node)
    }

    #[test]
    fn the_layout_shows_topics_and_fields_the_view_sends() {
        let layout: Value =
            serde_json::from_str(include_str!("../../../config/foxglove-view-layout.json"))
                .unwrap();
        // config/bridge-synthetic.toml's streams, which `perturb demo` runs.
        let mut topics = vec![
            "/perturb/events".to_string(),
            "/perturb/status".to_string(),
            calibration_topic("camera_front"),
        ];
        for (stream, kind) in [
            ("camera_front", StreamKind::Image),
            ("lidar_top", StreamKind::Cloud),
        ] {
            topics.push(topic(stream, None, kind));
            for side in [Side::Raw, Side::Perturbed] {
                topics.push(topic(stream, Some(side), kind));
            }
        }
        let stats: Value = serde_json::from_str(stats::STATS_SCHEMA).unwrap();
        let mut seen = 0;
        for (id, panel) in layout["configById"].as_object().unwrap() {
            let mut named: Vec<&str> = ["imageTopic", "calibrationTopic"]
                .iter()
                .filter_map(|k| panel["imageMode"][*k].as_str())
                .chain(panel["topicPath"].as_str())
                .collect();
            named.extend(
                panel["topics"]
                    .as_object()
                    .into_iter()
                    .flatten()
                    .map(|(t, _)| t.as_str()),
            );
            for p in panel["paths"].as_array().into_iter().flatten() {
                let path = p["value"].as_str().unwrap();
                let (t, fields) = path.split_once('.').unwrap();
                assert!(t.ends_with("/stats"), "{id}: {path}");
                assert!(
                    field(&stats, fields).is_some(),
                    "{id}: {path}: no such field"
                );
                named.push(t);
            }
            for t in named {
                assert!(topics.iter().any(|x| x == t), "{id}: the view sends no {t}");
                seen += 1;
            }
        }
        assert!(seen >= 10, "{seen} topics named");
        let ids: Vec<String> = layout["configById"]
            .as_object()
            .unwrap()
            .keys()
            .cloned()
            .collect();
        let tree = layout["layout"].to_string();
        for id in ids {
            assert!(
                tree.contains(&format!("\"{id}\"")),
                "{id} is not in the layout tree"
            );
        }
    }
}
