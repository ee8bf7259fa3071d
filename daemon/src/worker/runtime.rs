//! A stream's runtime state: the perturbation it applies (set by control requests, taken up at the
//! next frame), its worker pool (or the deadline gate in front of the daemon's) and its counters.

use super::gate::Gate;
use crate::config::StreamConfig;
use crate::perturbation::Active;
use crate::safety::KillSwitch;
use crate::state::CounterCell;
use crate::stats::{Counters, StreamStats};
use perturb_core::image::ImageGeometry;
use perturb_core::perturber::Spec;
use perturb_wire::control::LostByCause;
use perturb_wire::control::StreamReport;
use std::collections::HashSet;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};

/// The control side of a stream: what is configured, and a change waiting for the next frame.
#[derive(Default)]
struct ControlState {
    /// What `status` reports: the configuration the next frame uses.
    current: Option<Spec>,
    /// The seed a `set` without a seed keeps.
    seed: u64,
    /// A change the processing thread has not picked up yet (`Some(None)`: switch off), with
    /// the campaign step that made it (0: none).
    pending: Option<(Option<Active>, u16)>,
    /// The campaign step of `current` (0: set by hand or by the configuration).
    step: u16,
    /// True while a campaign drives the stream (`perturb ctl set`/`off` are refused).
    campaign: bool,
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
    /// The deadline gate its frames enter (`[daemon] dispatch = "deadline"`), for a stream
    /// without a pool of its own.
    gate: Option<Arc<Gate>>,
    /// The daemon's kill switch (shared by every stream).
    pub kill: Arc<KillSwitch>,
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
                step: 0,
                campaign: false,
            }),
            has_pending: AtomicBool::new(false),
            geometry: Mutex::new(None),
            unsupported: Mutex::new(HashSet::new()),
            pool,
            gate: None,
            kill: Arc::default(),
        })
    }

    /// The stream, its frames dispatched through `gate` (`[daemon] dispatch = "deadline"`)
    /// unless it has its own pool (`threads`), which it keeps.
    pub fn with_gate(mut self, gate: Option<Arc<Gate>>) -> Self {
        if self.pool.is_none() {
            self.gate = gate;
        }
        self
    }

    /// The stream, under the daemon's kill switch `kill`.
    pub fn with_kill(mut self, kill: Arc<KillSwitch>) -> Self {
        self.kill = kill;
        self
    }

    /// Runs a perturbation's frame work, due at `deadline_ns` (CLOCK_MONOTONIC), on the
    /// stream's worker threads: its own pool when it has one, else a slot of the deadline gate
    /// once the frame's turn comes, else the global pool.
    pub(super) fn on_workers<R: Send>(
        &self,
        deadline_ns: u64,
        work: impl FnOnce() -> R + Send,
    ) -> R {
        match (&self.pool, &self.gate) {
            (Some(pool), _) => pool.install(work),
            (None, Some(gate)) => gate.enter(deadline_ns).run(work),
            (None, None) => work(),
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

    /// Worker threads a frame's work of this stream runs on.
    pub fn worker_threads(&self) -> usize {
        match (&self.pool, &self.gate) {
            (Some(pool), _) => pool.current_num_threads(),
            (None, Some(gate)) => gate.threads_per_slot(),
            (None, None) => rayon::current_num_threads(),
        }
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
        self.set_step(Some(active), 0);
    }

    /// Runs `active` (`None`: off) from the next frame on, chosen by campaign step `step`
    /// (1-based; 0: by hand or by the configuration).
    pub fn set_step(&self, active: Option<Active>, step: u16) {
        let mut c = self.lock_control();
        let spec = active.as_ref().map(Active::spec);
        c.current = spec;
        if let Some(spec) = spec {
            c.seed = spec.seed;
        }
        c.step = step;
        c.pending = Some((active, step));
        self.has_pending.store(true, Ordering::Release);
    }

    /// What the stream runs from the next frame on (`None`: off).
    pub fn current(&self) -> Option<Spec> {
        self.lock_control().current
    }

    /// The campaign step of what the stream runs (0: none).
    pub fn step(&self) -> u16 {
        self.lock_control().step
    }

    /// Forwards frames unchanged from the next frame on.
    pub fn off(&self) {
        self.set_step(None, 0);
    }

    /// Marks the stream as driven by a campaign (or not any more).
    pub fn set_campaign(&self, on: bool) {
        self.lock_control().campaign = on;
    }

    /// True while a campaign drives the stream.
    pub fn in_campaign(&self) -> bool {
        self.lock_control().campaign
    }

    pub(super) fn take_pending(&self) -> Option<(Option<Active>, u16)> {
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
        let (dq, du, dout, dr, di, dd) = (
            g(&c.dropped_queue),
            g(&c.dropped_upstream),
            g(&c.dropped_output),
            g(&c.dropped_restart),
            g(&c.dropped_input),
            g(&c.dropped_down),
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
            dropped: dq + du + dout + dr + di + dd,
            dropped_queue: dq,
            dropped_upstream: du,
            dropped_input: di,
            dropped_down: dd,
            dropped_output: dout,
            dropped_restart: dr,
            lost: LostByCause {
                upstream: du,
                daemon_down: dd + dr,
                daemon_late: dq + di,
                daemon_output: dout,
                ..LostByCause::default()
            },
            killed: self.kill.engaged(),
            step: self.lock_control().step,
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
