//! A stream's runtime state: the perturbation it applies (set by control requests, taken up at the
//! next frame), its worker pool and its counters.

use crate::config::StreamConfig;
use crate::perturbation::Active;
use crate::state::CounterCell;
use crate::stats::{Counters, StreamStats};
use perturb_core::image::ImageGeometry;
use perturb_core::perturber::Spec;
use perturb_wire::control::StreamReport;
use std::collections::HashSet;
use std::sync::Mutex;
use std::sync::atomic::{AtomicBool, Ordering};

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
    pub(super) geometry: Mutex<Option<ImageGeometry>>,
    /// Image encodings this stream received that the encoding table does not have, each logged
    /// once (the frames are counted as invalid).
    pub(super) unsupported: Mutex<HashSet<String>>,
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
            unsupported: Mutex::new(HashSet::new()),
            pool,
        })
    }

    /// Runs a perturbation's frame work on the stream's worker threads: its own pool when it has
    /// one, the global pool otherwise.
    pub(super) fn on_workers<R: Send>(&self, work: impl FnOnce() -> R + Send) -> R {
        match &self.pool {
            Some(pool) => pool.install(work),
            None => work(),
        }
    }

    /// `view` with the stream's `bit_depth` for 16-bit encodings (8-bit frames as they are).
    pub(super) fn with_bit_depth<'a>(
        &self,
        view: perturb_core::encoding::EncodedView<'a>,
    ) -> Result<perturb_core::encoding::EncodedView<'a>, perturb_wire::WireError> {
        match self.config.bit_depth {
            Some(bits) if view.encoding.bits == 16 => Ok(view.with_bit_depth(bits)?),
            _ => Ok(view),
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

    pub(super) fn take_pending(&self) -> Option<Option<Active>> {
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
