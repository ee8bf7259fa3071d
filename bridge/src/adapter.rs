//! What every adapter (a thread of the bridge) gets: the bus, the stop flag and a way to say
//! that its subscriptions exist (sinks start before sources so no early frame is missed).

use crate::bus::{Bus, BusSubscriber};
use crate::stats::AdapterReport;
use anyhow::Result;
use crossbeam::channel::Sender;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;

/// The run-time context of an adapter.
#[derive(Clone)]
pub struct Control {
    stop: Arc<AtomicBool>,
    ready: Option<Sender<()>>,
    why: Arc<Mutex<Option<String>>>,
    upstream: Arc<AtomicU64>,
}

impl Control {
    /// A context with a stop flag and a readiness channel.
    pub fn new(stop: Arc<AtomicBool>, ready: Option<Sender<()>>) -> Self {
        Control {
            stop,
            ready,
            why: Arc::default(),
            upstream: Arc::default(),
        }
    }

    /// A context sharing `upstream`: when (monotonic ns) a sink last saw a publisher on a
    /// stream it reads, 0 if none yet.
    pub fn with_upstream(mut self, upstream: Arc<AtomicU64>) -> Self {
        self.upstream = upstream;
        self
    }

    /// Notes that `sub`'s stream has a publisher now (for `stop_after_publishers_gone`).
    pub fn watch_publishers(&self, sub: &dyn BusSubscriber) {
        if sub.publishers().is_some_and(|n| n > 0) {
            self.upstream
                .store(crate::frame::monotonic_ns(), Ordering::Relaxed);
        }
    }

    /// Notes that a stream this adapter reads has a publisher now.
    pub fn note_publisher(&self) {
        self.upstream
            .store(crate::frame::monotonic_ns(), Ordering::Relaxed);
    }

    /// A context sharing `why` (the first reason given by [`Control::stop_because`]).
    pub fn with_reason(mut self, why: Arc<Mutex<Option<String>>>) -> Self {
        self.why = why;
        self
    }

    /// Asks every adapter to stop, saying why (the first reason given is the one reported).
    pub fn stop_because(&self, why: impl Into<String>) {
        if let Ok(mut w) = self.why.lock() {
            w.get_or_insert_with(|| why.into());
        }
        self.stop_all();
    }

    /// True once the bridge is stopping.
    pub fn stopped(&self) -> bool {
        self.stop.load(Ordering::Relaxed)
    }

    /// Asks every adapter to stop.
    pub fn stop_all(&self) {
        self.stop.store(true, Ordering::Relaxed);
    }

    /// Says the adapter's ports exist.
    pub fn ready(&mut self) {
        if let Some(r) = self.ready.take() {
            let _ = r.send(());
        }
    }

    /// Sleeps `d`, waking early when stopped; false if stopped.
    pub fn sleep(&self, d: Duration) -> bool {
        let end = std::time::Instant::now() + d;
        loop {
            if self.stopped() {
                return false;
            }
            let now = std::time::Instant::now();
            if now >= end {
                return true;
            }
            std::thread::sleep((end - now).min(Duration::from_millis(50)));
        }
    }
}

/// One adapter.
pub trait Adapter: Send {
    /// `ingress /topic -> stream`, ...
    fn name(&self) -> String;
    /// True for sinks (started first).
    fn is_sink(&self) -> bool;
    /// Creates its ports (inside its thread), calls `ctl.ready()`, runs until stopped or done.
    fn run(self: Box<Self>, bus: &dyn Bus, ctl: Control) -> Result<AdapterReport>;
}

/// How long a blocking receive waits before checking the stop flag.
pub const POLL: Duration = Duration::from_millis(100);
