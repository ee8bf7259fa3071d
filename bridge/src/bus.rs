//! The bus between the bridge's adapters and the daemon.
//!
//! Sources (DDS ingress, bag replay, synthetic sensors) publish frames into `<stream>/raw`;
//! sinks (DDS egress, the recorder) read `<stream>/perturbed` (and `<stream>/raw` for raw
//! recording). The real bus is iceoryx2 shared memory with `perturbd` in between (see
//! [`crate::iox`]); [`LocalBus`] is an in-process stand-in without a daemon, where the perturbed
//! side of a stream is its raw side (a bag player, a DDS relay, a recorder).

use crate::frame::{FrameMeta, OwnedPayload, Payload, StreamKind};
use anyhow::Result;
use crossbeam::channel::{Receiver, Sender, bounded};
use std::collections::HashMap;
use std::sync::{Arc, Mutex};
use std::time::Duration;

/// Which side of a stream.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Side {
    /// `<stream>/raw`: what the sources publish.
    Raw,
    /// `<stream>/perturbed`: what the daemon publishes.
    Perturbed,
}

impl Side {
    /// `raw` or `perturbed`.
    pub fn as_str(self) -> &'static str {
        match self {
            Side::Raw => "raw",
            Side::Perturbed => "perturbed",
        }
    }
}

/// Publishes frames into one stream side.
pub trait BusPublisher {
    /// Publishes one frame (the bus stamps `meta.hops.source` if it is 0).
    fn publish(&mut self, meta: &FrameMeta, payload: &Payload<'_>) -> Result<()>;
    /// Frames dropped because a reader was full (the sensor path never blocks).
    fn dropped(&self) -> u64 {
        0
    }
    /// Frames published while no reader was connected (on the iceoryx2 bus: no `perturbd`, or
    /// it was restarting): lost before the daemon, which counts them as `dropped_upstream`.
    fn undelivered(&self) -> u64 {
        0
    }
}

/// A received frame kept for later: on the iceoryx2 bus a reference into shared memory (the
/// sample is handed back when the frame is dropped), no copy. It may be sent to another thread
/// and read from several at once (a ROS 1 egress writes it to every subscriber's socket).
pub trait HeldFrame: Send + Sync {
    /// The middleware's metadata (sequence number, hop stamps, applied perturbation).
    fn meta(&self) -> &FrameMeta;
    /// The message, borrowing the held bytes.
    fn payload(&self) -> Payload<'_>;
    /// Frames the source knew were lost upstream just before this one (gaps in a ROS 1
    /// publisher's `seq`), 0 when it did not say.
    fn lost_before(&self) -> u32 {
        0
    }
    /// True if the daemon published it while its kill switch was engaged (so it is raw).
    fn killed(&self) -> bool {
        false
    }
}

/// A boxed [`HeldFrame`].
pub type Held = Box<dyn HeldFrame>;

/// Receives frames from one stream side.
pub trait BusSubscriber {
    /// Waits up to `timeout` and passes every available frame to `f`; returns how many.
    fn recv(
        &mut self,
        timeout: Duration,
        f: &mut dyn FnMut(&FrameMeta, &Payload<'_>),
    ) -> Result<usize>;

    /// Waits up to `timeout` and returns every available frame, held (see [`HeldFrame`]) so
    /// that the caller decides later whether and when to pass it on.
    fn recv_held(&mut self, timeout: Duration) -> Result<Vec<Held>>;

    /// Publishers currently connected to the stream side, when the bus knows (iceoryx2: the
    /// daemon for a perturbed side, a source bridge for a raw side).
    fn publishers(&self) -> Option<usize> {
        None
    }
}

impl HeldFrame for Item {
    fn meta(&self) -> &FrameMeta {
        &self.0
    }
    fn payload(&self) -> Payload<'_> {
        self.1.payload()
    }
}

/// A bus: a factory of publishers and subscribers. Ports are created inside the thread that
/// uses them (iceoryx2 ports are not `Send`).
pub trait Bus: Send + Sync {
    /// `iceoryx2` or `local`.
    fn name(&self) -> &'static str;
    /// A publisher of `<stream>/<side>`.
    fn publisher(
        &self,
        stream: &str,
        kind: StreamKind,
        side: Side,
    ) -> Result<Box<dyn BusPublisher>>;
    /// A subscriber of `<stream>/<side>`.
    fn subscriber(
        &self,
        stream: &str,
        kind: StreamKind,
        side: Side,
    ) -> Result<Box<dyn BusSubscriber>>;
    /// Removes what dead processes left on the bus (iceoryx2: the ports of a process killed
    /// with `kill -9`, which stay listed until someone sweeps them).
    fn sweep_dead(&self) {}
}

type Item = Arc<(FrameMeta, OwnedPayload)>;

/// In-process bus without a daemon: both sides of a stream are the same channel.
/// Lossless: a publisher waits while a subscriber's queue (16 frames) is full.
#[derive(Default)]
pub struct LocalBus {
    subscribers: Mutex<HashMap<String, Vec<Sender<Item>>>>,
}

impl LocalBus {
    /// An empty bus.
    pub fn new() -> Self {
        Self::default()
    }
}

struct LocalPublisher {
    bus: Arc<LocalBus>,
    stream: String,
}

impl BusPublisher for LocalPublisher {
    fn publish(&mut self, meta: &FrameMeta, payload: &Payload<'_>) -> Result<()> {
        let targets: Vec<Sender<Item>> = self
            .bus
            .subscribers
            .lock()
            .map_err(|_| anyhow::anyhow!("local bus poisoned"))?
            .get(&self.stream)
            .cloned()
            .unwrap_or_default();
        if targets.is_empty() {
            return Ok(());
        }
        let mut meta = meta.clone();
        if meta.hops.source == 0 {
            meta.hops.source = crate::frame::monotonic_ns();
        }
        let item = Arc::new((meta, OwnedPayload::copy_of(payload)));
        for t in targets {
            let _ = t.send(item.clone());
        }
        Ok(())
    }
}

struct LocalSubscriber {
    rx: Receiver<Item>,
}

impl BusSubscriber for LocalSubscriber {
    fn recv(
        &mut self,
        timeout: Duration,
        f: &mut dyn FnMut(&FrameMeta, &Payload<'_>),
    ) -> Result<usize> {
        let mut n = 0;
        let first = match self.rx.recv_timeout(timeout) {
            Ok(i) => i,
            Err(_) => return Ok(0),
        };
        let mut next = Some(first);
        while let Some(item) = next {
            let mut meta = item.0.clone();
            meta.hops.sink = crate::frame::monotonic_ns();
            f(&meta, &item.1.payload());
            n += 1;
            next = self.rx.try_recv().ok();
        }
        Ok(n)
    }

    fn recv_held(&mut self, timeout: Duration) -> Result<Vec<Held>> {
        let Ok(first) = self.rx.recv_timeout(timeout) else {
            return Ok(Vec::new());
        };
        let mut out: Vec<Held> = vec![Box::new(first)];
        while let Ok(i) = self.rx.try_recv() {
            out.push(Box::new(i));
        }
        Ok(out)
    }
}

/// The local bus shared by the adapters of one process.
#[derive(Clone, Default)]
pub struct SharedLocalBus(pub Arc<LocalBus>);

impl Bus for SharedLocalBus {
    fn name(&self) -> &'static str {
        "local"
    }
    fn publisher(
        &self,
        stream: &str,
        _kind: StreamKind,
        _side: Side,
    ) -> Result<Box<dyn BusPublisher>> {
        Ok(Box::new(LocalPublisher {
            bus: self.0.clone(),
            stream: stream.to_string(),
        }))
    }
    fn subscriber(
        &self,
        stream: &str,
        _kind: StreamKind,
        _side: Side,
    ) -> Result<Box<dyn BusSubscriber>> {
        let (tx, rx) = bounded(16);
        self.0
            .subscribers
            .lock()
            .map_err(|_| anyhow::anyhow!("local bus poisoned"))?
            .entry(stream.to_string())
            .or_default()
            .push(tx);
        Ok(Box::new(LocalSubscriber { rx }))
    }
}
