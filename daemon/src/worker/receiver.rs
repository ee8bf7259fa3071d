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

    /// Counts a received frame and the frames lost before it (a gap in its publisher's sequence
    /// numbers). Magic, version and seq keep their place in every wire version, so even a frame
    /// this build cannot read is accounted for.
    fn account(&mut self, frame: &Frame) {
        let c = &self.rt.stats.counters;
        let name = self.rt.config.name.as_str();
        Counters::add(&c.frames_in, 1);
        let h = frame.header();
        if h.magic != MAGIC {
            return;
        }
        let origin = frame.origin();
        let gap = self.gaps.observe(name, origin, h.seq);
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
