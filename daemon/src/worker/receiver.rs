//! The receiver thread: wakes on the input's event, takes every queued sample, counts the gaps in
//! the sequence numbers and hands frames to the bounded queue.

use super::processor::{check, invalid};
use super::runtime::StreamRuntime;
use super::{Item, TICK, should_log};
use crate::stats::Counters;
use crossbeam::channel::{Receiver, Sender, TrySendError};
use perturb_wire::header::MAGIC;
use perturb_wire::iceoryx2::prelude::*;
use perturb_wire::{Frame, FrameSubscriber, Ipc, LayoutCache, Origin, monotonic_ns};
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;
use tracing::{debug, error, info, warn};

/// What a jump in a publisher's `publish_index` means: frames it sent that this daemon never
/// received.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Missed {
    /// None.
    Nothing,
    /// While this daemon ran: its input queue overflowed (it was stalled or overloaded).
    WhileRunning(u64),
    /// While no daemon ran (the first frame after a start): killed, crashed, restarting, or not
    /// started yet.
    WhileDown(u64),
}

/// `publish_index` bookkeeping per publisher. It starts from where the counters file says the
/// stream was, so a restarted daemon counts the frames its publisher sent while no daemon was
/// there. Frames lost before the source (sensor, driver, network) are not gaps here: the source
/// counts them itself and says so in each frame's `lost_before`.
struct GapTracker {
    last: Option<(Origin, u64)>,
    /// True until the first frame after the daemon started.
    starting: bool,
}

impl GapTracker {
    /// Starts from the publisher and `publish_index` recorded in `c`.
    fn resume(c: &Counters) -> Self {
        GapTracker {
            last: c.last_index().map(|(o, i)| (Origin::from_raw(o), i)),
            starting: true,
        }
    }

    /// What was missed before the frame `index` of `origin`.
    fn observe(&mut self, stream: &str, origin: Origin, index: u64) -> Missed {
        let starting = std::mem::replace(&mut self.starting, false);
        // (frames missed, whether no daemon was reading then)
        let (gap, down) = match self.last {
            Some((o, last)) if o == origin => {
                if index <= last {
                    warn!(
                        stream,
                        last, index, "input publish index went backwards; counting restarts"
                    );
                }
                (index.saturating_sub(last + 1), starting)
            }
            // A publisher this daemon has not heard from numbers its samples from 0: those
            // before `index` were sent before this daemon subscribed (or while none ran).
            Some(_) => {
                info!(stream, index, "a new publisher feeds the input");
                (index, true)
            }
            None => (index, true),
        };
        self.last = Some((origin, index));
        match (gap, down) {
            (0, _) => Missed::Nothing,
            (n, true) => Missed::WhileDown(n),
            (n, false) => Missed::WhileRunning(n),
        }
    }
}

pub(super) fn receive_loop(
    rt: &StreamRuntime,
    mut sub: FrameSubscriber,
    tx: Sender<Item>,
    evict: Receiver<Item>,
    shutdown: &AtomicBool,
) {
    let name = rt.config.name.as_str();
    let mut intake = Intake {
        rt,
        tx,
        evict,
        gaps: GapTracker::resume(&rt.stats.counters),
        layouts: LayoutCache::default(),
    };
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
                broken = !intake.take_all(&sub);
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

/// What the receiver keeps between wake-ups: where frames go, and what it knows of the input.
struct Intake<'a> {
    rt: &'a StreamRuntime,
    tx: Sender<Item>,
    evict: Receiver<Item>,
    gaps: GapTracker,
    layouts: LayoutCache,
}

impl Intake<'_> {
    /// Takes every queued sample of `sub`: counted, checked, queued. False when the input broke
    /// (to be reopened).
    fn take_all(&mut self, sub: &FrameSubscriber) -> bool {
        let name = self.rt.config.name.as_str();
        loop {
            match sub.receive() {
                Ok(Some(frame)) => {
                    let t_rx = monotonic_ns();
                    self.account(&frame);
                    // An invalid frame is counted and released here, so it never takes a good
                    // frame's place in the queue.
                    if let Err(e) = check(self.rt.config.modality, &frame, &mut self.layouts) {
                        invalid(self.rt, frame.header().seq, &e);
                        continue;
                    }
                    enqueue(self.rt, &self.tx, &self.evict, Item { frame, t_rx });
                }
                Ok(None) => return true,
                Err(e) if e.is_borrow_limit() => {
                    warn!(stream = name, "{e}");
                    return true;
                }
                Err(e) => {
                    error!(stream = name, "{e}; reopening the input");
                    return false;
                }
            }
        }
    }

    /// Counts a received frame, the frames lost upstream that its source reports
    /// (`lost_before`), and the frames its publisher sent that this daemon missed (a gap in
    /// `publish_index`: while stalled, or while no daemon ran). Magic, version and seq keep their
    /// place in every wire version, so even a frame this build cannot read is counted in.
    fn account(&mut self, frame: &Frame) {
        let c = &self.rt.stats.counters;
        let name = self.rt.config.name.as_str();
        Counters::add(&c.frames_in, 1);
        let h = frame.header();
        if h.magic != MAGIC || h.version != perturb_wire::WIRE_VERSION {
            return;
        }
        if h.lost_before > 0 {
            let n = c
                .dropped_upstream
                .fetch_add(u64::from(h.lost_before), Ordering::Relaxed);
            if should_log(n + 1) {
                warn!(
                    stream = name,
                    seq = h.seq,
                    missing = h.lost_before,
                    "frames lost before the middleware (the source saw gaps in the sensor's sequence numbers)"
                );
            }
        }
        let origin = frame.origin();
        match self.gaps.observe(name, origin, h.publish_index) {
            Missed::Nothing => {}
            Missed::WhileRunning(gap) => {
                let n = c.dropped_input.fetch_add(gap, Ordering::Relaxed);
                if should_log(n + 1) {
                    warn!(
                        stream = name,
                        seq = h.seq,
                        missing = gap,
                        "frames lost on the daemon's input: it did not keep up (stalled or overloaded)"
                    );
                }
            }
            Missed::WhileDown(gap) => {
                Counters::add(&c.dropped_down, gap);
                info!(
                    stream = name,
                    seq = h.seq,
                    missing = gap,
                    "frames published while no daemon read the stream"
                );
            }
        }
        c.set_origin(origin.raw());
        c.last_seq_plus_one.store(h.seq + 1, Ordering::Relaxed);
        c.last_index_plus_one
            .store(h.publish_index + 1, Ordering::Relaxed);
    }
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
