//! One stream's two threads: a receiver that wakes on the input's event (WaitSet), takes every
//! queued sample and hands it to a bounded queue, and a processing thread that perturbs each
//! frame straight from the input sample into a loaned output sample and publishes it.
//!
//! The sensor path never blocks: the receiver never waits for the processing thread. When the
//! queue (capacity `queue_depth`, 1 or 2) is full, the oldest waiting frame is dropped and counted
//! (`dropped_queue`). Frames that never reached the receiver (overwritten in the iceoryx2 input
//! queue, or lost before the daemon) show up as gaps in the sequence numbers and are counted too
//! (`dropped_upstream`), so every sequence number is either published, invalid, or counted as
//! dropped.

use crate::config::StreamConfig;
use crate::perturbation::Active;
use crate::state::CounterCell;
use crate::stats::{Counters, StreamStats};
use crossbeam::channel::{Receiver, RecvTimeoutError, Sender, TrySendError};
use perturb_core::image::ImageGeometry;
use perturb_core::perturber::Spec;
use perturb_core::registry::Modality;
use perturb_wire::control::StreamReport;
use perturb_wire::header::MAGIC;
use perturb_wire::iceoryx2::prelude::*;
use perturb_wire::{
    Frame, FramePublisher, FrameSubscriber, Ipc, LayoutCache, Origin, WireError, WireModality,
    monotonic_ns,
};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::Duration;
use tracing::{debug, error, info, warn};

/// How often blocked threads look at the shutdown flag.
const TICK: Duration = Duration::from_millis(200);

/// The control side of a stream: what is configured, and a change waiting for the next frame.
#[derive(Default)]
struct ControlState {
    /// What `status` reports: the configuration the next frame uses.
    current: Option<Spec>,
    /// The seed a `set` without a seed keeps.
    seed: u64,
    /// A change the processing thread has not picked up yet (`Some(None)`: switch off).
    pending: Option<Option<Active>>,
}

/// Everything the threads of a stream and the control handler share.
pub struct StreamRuntime {
    /// The stream's configuration.
    pub config: StreamConfig,
    /// Counters and latencies.
    pub stats: StreamStats,
    control: Mutex<ControlState>,
    has_pending: AtomicBool,
    geometry: Mutex<Option<ImageGeometry>>,
    /// The stream's own worker threads (`threads` in its configuration); `None`: the global pool.
    pool: Option<rayon::ThreadPool>,
}

impl StreamRuntime {
    /// A stream with its initial perturbation (already built), its counters (see
    /// [`crate::state::CountersFile`]; `CounterCell::default()` keeps them in memory) and its own
    /// pool of worker threads when its configuration asks for one.
    pub fn new(
        config: StreamConfig,
        initial: Option<Spec>,
        counters: CounterCell,
    ) -> Result<Self, rayon::ThreadPoolBuildError> {
        let seed = initial.map_or(config.initial_seed(), |s| s.seed);
        let pool = match config.threads {
            Some(n) => {
                let name = config.name.clone();
                Some(
                    rayon::ThreadPoolBuilder::new()
                        .num_threads(n)
                        .thread_name(move |i| format!("w{i}-{name}"))
                        .build()?,
                )
            }
            None => None,
        };
        Ok(StreamRuntime {
            config,
            stats: StreamStats {
                counters,
                latencies: Default::default(),
            },
            control: Mutex::new(ControlState {
                current: initial,
                seed,
                pending: None,
            }),
            has_pending: AtomicBool::new(false),
            geometry: Mutex::new(None),
            pool,
        })
    }

    /// Runs a perturbation's frame work on the stream's worker threads: its own pool when it has
    /// one, the global pool otherwise.
    fn on_workers<R: Send>(&self, work: impl FnOnce() -> R + Send) -> R {
        match &self.pool {
            Some(pool) => pool.install(work),
            None => work(),
        }
    }

    /// Worker threads the stream's frame work runs on.
    pub fn worker_threads(&self) -> usize {
        self.pool.as_ref().map_or_else(
            rayon::current_num_threads,
            rayon::ThreadPool::current_num_threads,
        )
    }

    fn lock_control(&self) -> std::sync::MutexGuard<'_, ControlState> {
        self.control.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// The seed a `set` without one uses.
    pub fn current_seed(&self) -> u64 {
        self.lock_control().seed
    }

    /// The last camera frame geometry seen (to build a new perturbation ahead of the frame).
    pub fn last_geometry(&self) -> Option<ImageGeometry> {
        *self.geometry.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// Activates `active` from the next frame on.
    pub fn set(&self, active: Active) {
        let mut c = self.lock_control();
        let spec = active.spec();
        c.current = Some(spec);
        c.seed = spec.seed;
        c.pending = Some(Some(active));
        self.has_pending.store(true, Ordering::Release);
    }

    /// What the stream runs from the next frame on (`None`: off).
    pub fn current(&self) -> Option<Spec> {
        self.lock_control().current
    }

    /// Forwards frames unchanged from the next frame on.
    pub fn off(&self) {
        let mut c = self.lock_control();
        c.current = None;
        c.pending = Some(None);
        self.has_pending.store(true, Ordering::Release);
    }

    fn take_pending(&self) -> Option<Option<Active>> {
        if !self.has_pending.swap(false, Ordering::Acquire) {
            return None;
        }
        self.lock_control().pending.take()
    }

    /// The stream's report (latencies only when asked for).
    pub fn report(&self, latency: bool) -> StreamReport {
        let c = &self.stats.counters;
        let g = Counters::get;
        let current = self.lock_control().current;
        let (dq, du, dout, dr) = (
            g(&c.dropped_queue),
            g(&c.dropped_upstream),
            g(&c.dropped_output),
            g(&c.dropped_restart),
        );
        let last = g(&c.last_seq_plus_one);
        StreamReport {
            name: self.config.name.clone(),
            modality: self.config.modality.as_str().to_string(),
            input: self.config.input_service(),
            output: self.config.output_service(),
            id: current.map(|s| s.entry.id.to_string()),
            perturbation: current.map(|s| s.entry.name.to_string()),
            severity: current.map(|s| s.severity),
            seed: current.map_or(self.current_seed(), |s| s.seed),
            frames_in: g(&c.frames_in),
            frames_out: g(&c.frames_out),
            dropped: dq + du + dout + dr,
            dropped_queue: dq,
            dropped_upstream: du,
            dropped_output: dout,
            dropped_restart: dr,
            invalid: g(&c.invalid),
            perturb_failed: g(&c.perturb_failed),
            over_budget: g(&c.over_budget),
            budget_ms: self.config.budget(),
            last_seq: last.checked_sub(1),
            latency: latency.then(|| {
                self.stats
                    .latencies
                    .lock()
                    .unwrap_or_else(|p| p.into_inner())
                    .summary()
            }),
        }
    }
}

/// A received frame on its way to the processing thread.
struct Item {
    frame: Frame,
    t_rx: u64,
}

/// Logs the first occurrences of a recurring problem, then every 100th.
fn should_log(n: u64) -> bool {
    n <= 10 || n.is_multiple_of(100)
}

/// Sequence-number bookkeeping per publisher: a jump forward is a count of lost frames. It starts
/// from where the counters file says the stream was, so a restarted daemon counts the frames its
/// publisher sent while no daemon was there.
struct GapTracker {
    last: Option<(Origin, u64)>,
}

impl GapTracker {
    /// Starts from the publisher and sequence number recorded in `c`.
    fn resume(c: &Counters) -> Self {
        GapTracker {
            last: c.last_origin().map(|(o, seq)| (Origin::from_raw(o), seq)),
        }
    }

    /// Missing sequence numbers before `seq`.
    fn observe(&mut self, stream: &str, origin: Origin, seq: u64) -> u64 {
        let gap = match self.last {
            Some((o, last)) if o == origin => {
                if seq > last {
                    seq - last - 1
                } else {
                    warn!(
                        stream,
                        last, seq, "input sequence number went backwards; counting restarts"
                    );
                    0
                }
            }
            Some(_) => {
                info!(stream, seq, "a new publisher feeds the input");
                0
            }
            None => 0,
        };
        self.last = Some((origin, seq));
        gap
    }
}

/// Starts the receiver and processing threads of a stream.
pub fn spawn(
    rt: Arc<StreamRuntime>,
    subscriber: FrameSubscriber,
    publisher: FramePublisher,
    initial: Option<Active>,
    shutdown: Arc<AtomicBool>,
) -> std::io::Result<[JoinHandle<()>; 2]> {
    let (tx, rx) = crossbeam::channel::bounded::<Item>(rt.config.queue_depth);
    let evict = rx.clone();
    let name = rt.config.name.clone();
    let rt2 = rt.clone();
    let receiver = std::thread::Builder::new()
        .name(format!("rx-{name}"))
        .spawn(move || receive_loop(&rt2, subscriber, tx, evict, &shutdown))?;
    let processor = std::thread::Builder::new()
        .name(format!("px-{name}"))
        .spawn(move || process_loop(&rt, publisher, rx, initial))?;
    Ok([receiver, processor])
}

fn receive_loop(
    rt: &StreamRuntime,
    mut sub: FrameSubscriber,
    tx: Sender<Item>,
    evict: Receiver<Item>,
    shutdown: &AtomicBool,
) {
    let name = rt.config.name.as_str();
    let c = &rt.stats.counters;
    let mut gaps = GapTracker::resume(c);
    let mut layouts = LayoutCache::default();
    while !shutdown.load(Ordering::Relaxed) {
        let mut broken = false;
        // A reopen that failed left no ports: try again before waiting on them.
        if !sub.has_ports() {
            if let Err(e) = sub.reopen() {
                error!(
                    stream = name,
                    "cannot reopen the input: {e}; retrying in 1 s"
                );
                std::thread::sleep(Duration::from_secs(1));
            }
            continue;
        }
        {
            let waitset = match WaitSetBuilder::new()
                .signal_handling_mode(SignalHandlingMode::Disabled)
                .create::<Ipc>()
            {
                Ok(w) => w,
                Err(e) => {
                    error!(stream = name, "cannot create a WaitSet: {e:?}; retrying");
                    std::thread::sleep(Duration::from_secs(1));
                    continue;
                }
            };
            let _guard = match waitset.attach_notification(sub.listener()) {
                Ok(g) => g,
                Err(e) => {
                    error!(
                        stream = name,
                        "cannot attach the input listener: {e:?}; retrying"
                    );
                    std::thread::sleep(Duration::from_secs(1));
                    continue;
                }
            };
            while !shutdown.load(Ordering::Relaxed) && !broken {
                // Wakes on the input's event, or after TICK to look at the shutdown flag.
                let _ = waitset
                    .wait_and_process_once_with_timeout(|_| CallbackProgression::Continue, TICK);
                sub.drain_notifications();
                loop {
                    match sub.receive() {
                        Ok(Some(frame)) => {
                            let t_rx = monotonic_ns();
                            Counters::add(&c.frames_in, 1);
                            let h = frame.header();
                            // Magic, version and seq keep their place in every wire version, so
                            // even a frame this build cannot read is accounted for.
                            if h.magic == MAGIC {
                                let origin = frame.origin();
                                let gap = gaps.observe(name, origin, h.seq);
                                if gap > 0 {
                                    let n = c.dropped_upstream.fetch_add(gap, Ordering::Relaxed);
                                    if should_log(n + 1) {
                                        warn!(
                                            stream = name,
                                            seq = h.seq,
                                            missing = gap,
                                            "frames lost before the daemon received them"
                                        );
                                    }
                                }
                                c.set_origin(origin.raw());
                                c.last_seq_plus_one.store(h.seq + 1, Ordering::Relaxed);
                            }
                            // An invalid frame is counted and released here, so it never takes
                            // a good frame's place in the queue.
                            if let Err(e) = check(rt.config.modality, &frame, &mut layouts) {
                                invalid(rt, frame.header().seq, &e);
                                continue;
                            }
                            enqueue(rt, &tx, &evict, Item { frame, t_rx });
                        }
                        Ok(None) => break,
                        Err(e) if e.is_borrow_limit() => {
                            warn!(stream = name, "{e}");
                            break;
                        }
                        Err(e) => {
                            error!(stream = name, "{e}; reopening the input");
                            broken = true;
                            break;
                        }
                    }
                }
            }
        }
        if broken && let Err(e) = sub.reopen() {
            error!(
                stream = name,
                "cannot reopen the input: {e}; retrying in 1 s"
            );
            std::thread::sleep(Duration::from_secs(1));
        }
    }
    debug!(stream = name, "receiver stopped");
}

/// Puts a frame in the queue; when it is full, drops the oldest waiting frame (counted).
fn enqueue(rt: &StreamRuntime, tx: &Sender<Item>, evict: &Receiver<Item>, mut item: Item) {
    let c = &rt.stats.counters;
    loop {
        match tx.try_send(item) {
            Ok(()) => return,
            Err(TrySendError::Full(back)) => {
                item = back;
                if let Ok(old) = evict.try_recv() {
                    let n = c.dropped_queue.fetch_add(1, Ordering::Relaxed) + 1;
                    if should_log(n) {
                        warn!(
                            stream = rt.config.name.as_str(),
                            seq = old.frame.header().seq,
                            dropped = n,
                            "worker behind: oldest waiting frame dropped"
                        );
                    }
                }
            }
            Err(TrySendError::Disconnected(_)) => return,
        }
    }
}

fn process_loop(
    rt: &StreamRuntime,
    mut publisher: FramePublisher,
    rx: Receiver<Item>,
    mut active: Option<Active>,
) {
    let name = rt.config.name.as_str();
    let mut cache = LayoutCache::default();
    loop {
        let item = match rx.recv_timeout(TICK) {
            Ok(i) => i,
            // The receiver drops the sender when it stops (shutdown); the queue is drained first.
            Err(RecvTimeoutError::Timeout) => continue,
            Err(RecvTimeoutError::Disconnected) => break,
        };
        if let Some(change) = rt.take_pending() {
            match &change {
                Some(a) => info!(
                    stream = name,
                    id = a.spec().entry.id,
                    severity = a.spec().severity,
                    seed = a.spec().seed,
                    seq = item.frame.header().seq,
                    "perturbation active from this frame"
                ),
                None => info!(
                    stream = name,
                    seq = item.frame.header().seq,
                    "perturbation off from this frame"
                ),
            }
            active = change;
        }
        process_one(rt, &mut publisher, item, &mut active, &mut cache);
    }
    debug!(stream = name, "processor stopped");
}

/// Checks a received frame is one the stream can process: header and payload agree, the
/// modality is the stream's, the image encoding is supported or the point layout is readable.
fn check(modality: Modality, frame: &Frame, layouts: &mut LayoutCache) -> Result<(), WireError> {
    match modality {
        Modality::Camera => frame.image().map(|_| ()),
        Modality::Lidar => frame.cloud_cached(layouts).map(|_| ()),
    }
}

fn invalid(rt: &StreamRuntime, seq: u64, e: &WireError) {
    let n = rt.stats.counters.invalid.fetch_add(1, Ordering::Relaxed) + 1;
    if should_log(n) {
        warn!(
            stream = rt.config.name.as_str(),
            seq,
            invalid = n,
            "invalid frame skipped: {e}"
        );
    }
}

fn failed(rt: &StreamRuntime, seq: u64, id: &str, e: &dyn std::fmt::Display) {
    let n = rt
        .stats
        .counters
        .perturb_failed
        .fetch_add(1, Ordering::Relaxed)
        + 1;
    if should_log(n) {
        warn!(
            stream = rt.config.name.as_str(),
            seq, id, "perturbation failed, frame forwarded unperturbed: {e}"
        );
    }
}

fn process_one(
    rt: &StreamRuntime,
    publisher: &mut FramePublisher,
    item: Item,
    active: &mut Option<Active>,
    cache: &mut LayoutCache,
) {
    let Item { frame, t_rx } = item;
    let h = *frame.header();
    let want = match rt.config.modality {
        Modality::Camera => WireModality::Camera,
        Modality::Lidar => WireModality::Lidar,
    };
    match frame.validate() {
        Ok(m) if m == want => {}
        Ok(m) => {
            let e = WireError::invalid(format!(
                "a {} frame on a {} stream",
                m.as_str(),
                want.as_str()
            ));
            return invalid(rt, h.seq, &e);
        }
        Err(e) => return invalid(rt, h.seq, &e),
    }
    let t0 = monotonic_ns();
    let loan = match want {
        WireModality::Camera => camera(rt, publisher, &frame, &h, active),
        WireModality::Lidar => lidar(rt, publisher, &frame, &h, active, cache),
    };
    let mut loan = match loan {
        Ok(Some(l)) => l,
        Ok(None) => return,
        Err(e) => {
            let n = rt
                .stats
                .counters
                .dropped_output
                .fetch_add(1, Ordering::Relaxed)
                + 1;
            if should_log(n) {
                error!(
                    stream = rt.config.name.as_str(),
                    seq = h.seq,
                    "frame dropped, no output sample: {e}"
                );
            }
            return;
        }
    };
    let t1 = monotonic_ns();
    {
        let hd = loan.header_mut();
        hd.t_daemon_rx_ns = t_rx;
        hd.t_daemon_tx_ns = monotonic_ns();
    }
    let t_tx = loan.header().t_daemon_tx_ns;
    drop(frame); // hand the input sample back before publishing
    let c = &rt.stats.counters;
    match publisher.send(loan) {
        Ok(_) => Counters::add(&c.frames_out, 1),
        Err(e) => {
            let n = c.dropped_output.fetch_add(1, Ordering::Relaxed) + 1;
            if should_log(n) {
                error!(
                    stream = rt.config.name.as_str(),
                    seq = h.seq,
                    "publishing failed: {e}"
                );
            }
            return;
        }
    }
    let budget_ns = (rt.config.budget() * 1e6) as u64;
    let mut lat = rt.stats.latencies.lock().unwrap_or_else(|p| p.into_inner());
    lat.perturb.record(t1.saturating_sub(t0));
    lat.rx_to_tx.record(t_tx.saturating_sub(t_rx));
    let total = if h.t_ingress_ns != 0 && h.t_ingress_ns <= t_rx {
        lat.ingress_to_rx.record(t_rx - h.t_ingress_ns);
        lat.ingress_to_tx.record(t_tx - h.t_ingress_ns);
        t_tx - h.t_ingress_ns
    } else {
        t_tx.saturating_sub(t_rx)
    };
    drop(lat);
    if total > budget_ns {
        let n = c.over_budget.fetch_add(1, Ordering::Relaxed) + 1;
        if should_log(n) {
            warn!(
                stream = rt.config.name.as_str(),
                seq = h.seq,
                latency_ms = total as f64 / 1e6,
                budget_ms = rt.config.budget(),
                "frame over budget"
            );
        }
    }
}

type Loan = perturb_wire::FrameLoan;

/// Writes the output image into a loan: perturbed, or copied when off (or when the perturbation
/// fails). `Ok(None)`: the frame was invalid and counted.
fn camera(
    rt: &StreamRuntime,
    publisher: &FramePublisher,
    frame: &Frame,
    h: &perturb_wire::FrameHeader,
    active: &mut Option<Active>,
) -> Result<Option<Loan>, WireError> {
    let input = match frame.image() {
        Ok(v) => v,
        Err(e) => {
            invalid(rt, h.seq, &e);
            return Ok(None);
        }
    };
    let g = input.geometry();
    {
        let mut last = rt.geometry.lock().unwrap_or_else(|p| p.into_inner());
        if *last != Some(g) {
            *last = Some(g);
        }
    }
    let len = h.data_len as usize;
    let mut loan = publisher.loan(len.max(1))?;
    *loan.header_mut() = *h;
    loan.header_mut().set_applied(None);
    let data = frame.data()?;
    match active {
        Some(Active::Camera(p)) => {
            let result = {
                let mut out = h.image_view_mut(loan.payload_mut())?;
                rt.on_workers(|| p.apply(&input, &mut out, h.seq))
            };
            match result {
                Ok(()) => {
                    let out = loan.payload_mut();
                    // Row padding is not image data: pass it through.
                    let (step, row) = (h.step as usize, g.row_bytes());
                    if step > row {
                        for y in 0..(h.height as usize).saturating_sub(1) {
                            let r = y * step + row..(y + 1) * step;
                            out[r.clone()].copy_from_slice(&data[r]);
                        }
                    }
                    let spec = p.spec();
                    loan.header_mut().set_applied(Some(&spec));
                }
                Err(e) => {
                    failed(rt, h.seq, p.spec().entry.id, &e);
                    loan.payload_mut()[..len].copy_from_slice(data);
                }
            }
        }
        _ => loan.payload_mut()[..len].copy_from_slice(data),
    }
    Ok(Some(loan))
}

/// Writes the output cloud into a loan sized for the perturbation's worst case and records the
/// size it produced.
fn lidar(
    rt: &StreamRuntime,
    publisher: &FramePublisher,
    frame: &Frame,
    h: &perturb_wire::FrameHeader,
    active: &mut Option<Active>,
    cache: &mut LayoutCache,
) -> Result<Option<Loan>, WireError> {
    let input = match frame.cloud_cached(cache) {
        Ok(v) => v,
        Err(e) => {
            invalid(rt, h.seq, &e);
            return Ok(None);
        }
    };
    let data = frame.data()?;
    let len = data.len();
    if let Some(Active::Lidar(p)) = active {
        let max = p.max_output_bytes(&input);
        let mut loan = publisher.loan(max.max(1))?;
        *loan.header_mut() = *h;
        let payload = loan.payload_mut();
        match rt.on_workers(|| p.apply(&input, payload, h.seq, None)) {
            Ok(shape) => {
                let spec = p.spec();
                let hd = loan.header_mut();
                hd.width = shape.width;
                hd.height = shape.height;
                hd.row_step = shape.row_step as u32;
                hd.data_len = shape.bytes as u64;
                hd.set_applied(Some(&spec));
                return Ok(Some(loan));
            }
            Err(e) => failed(rt, h.seq, p.spec().entry.id, &e),
        }
    }
    let mut loan = publisher.loan(len.max(1))?;
    *loan.header_mut() = *h;
    loan.header_mut().set_applied(None);
    loan.payload_mut()[..len].copy_from_slice(data);
    Ok(Some(loan))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::Config;

    fn stream(extra: &str) -> StreamConfig {
        let text = format!("[[streams]]\nname = \"cam\"\nmodality = \"camera\"\n{extra}");
        Config::parse(&text).unwrap().streams.remove(0)
    }

    #[test]
    fn a_stream_with_threads_runs_its_frame_work_on_a_pool_of_that_size() {
        let rt = StreamRuntime::new(stream("threads = 3\n"), None, CounterCell::default()).unwrap();
        assert_eq!(rt.worker_threads(), 3);
        let (n, name) = rt.on_workers(|| {
            let inner = rayon::join(|| std::thread::current().name().map(str::to_owned), || ());
            (rayon::current_num_threads(), inner.0)
        });
        assert_eq!(n, 3);
        assert!(name.is_some_and(|n| n.ends_with("-cam")));
        // Without `threads` the work stays on the caller's (global) pool.
        let rt = StreamRuntime::new(stream(""), None, CounterCell::default()).unwrap();
        assert_eq!(
            rt.on_workers(rayon::current_num_threads),
            rayon::current_num_threads()
        );
        assert_eq!(rt.worker_threads(), rayon::current_num_threads());
    }
}
