//! The deadline gate (`[daemon] dispatch = "deadline"`): a stream's processing thread enters it
//! with its frame's deadline before the frame's work, waits until its frame has the earliest
//! deadline of those waiting and a slot is free, runs the work on that slot's worker threads and
//! leaves when the work is done.
//!
//! Frames are admitted earliest deadline first (equal deadlines in the order they came); a frame
//! already past its deadline is still admitted, first. Admission never preempts: a frame that
//! holds a slot keeps it until its work is done. Each slot has its own rayon pool, so frames in
//! different slots never share worker threads, and the work of a frame runs on the same number
//! of threads whatever the other streams do.
//!
//! Because a slot is not taken back, a long frame with a distant deadline (a LiDAR's object-level
//! perturbation, due in 200 ms) could fill the last free slot just before a burst of camera
//! frames due in 33 ms. So the last free slot, while another slot is busy, is kept for urgent
//! frames: those due within `reserve` (the shortest budget of the streams behind the gate). A
//! frame that is not urgent waits for a second free slot, or until it becomes urgent itself.
//!
//! Waiting is a `Mutex` + `Condvar`: every change (a frame admitted while slots are left, a slot
//! freed) wakes every waiter, and each checks its turn under the lock, so no wake-up is lost; a
//! frame kept from the last slot also wakes when it becomes urgent. There are as many waiters as
//! streams, so waking them all costs little.

use perturb_wire::monotonic_ns;
use std::cmp::Reverse;
use std::collections::BinaryHeap;
use std::sync::{Condvar, Mutex, MutexGuard};
use std::time::Duration;

/// Admits frames to a fixed number of slots, earliest deadline first.
pub struct Gate {
    state: Mutex<State>,
    turn: Condvar,
    /// One pool per slot.
    pools: Vec<rayon::ThreadPool>,
    /// Frames due within this many ns (CLOCK_MONOTONIC) may take the last free slot.
    reserve_ns: u64,
}

#[derive(Default)]
struct State {
    /// Frames waiting as (deadline, ticket): the earliest on top, ties in arrival order.
    waiting: BinaryHeap<Reverse<(u64, u64)>>,
    /// Slots no frame holds.
    free: Vec<usize>,
    /// The next frame's ticket.
    next_ticket: u64,
}

/// A frame's slot, from its admission to its drop (which frees the slot).
pub struct Permit<'a> {
    gate: &'a Gate,
    slot: usize,
}

impl Gate {
    /// A gate of `slots` slots (at least 1), each with a pool of `threads_per_slot` worker
    /// threads (at least 1), named `g<slot>.<thread>`; the last free slot is kept for frames due
    /// within `reserve`.
    pub fn new(
        slots: usize,
        threads_per_slot: usize,
        reserve: Duration,
    ) -> Result<Self, rayon::ThreadPoolBuildError> {
        let pools = (0..slots.max(1))
            .map(|slot| {
                rayon::ThreadPoolBuilder::new()
                    .num_threads(threads_per_slot.max(1))
                    .thread_name(move |i| format!("g{slot}.{i}"))
                    .build()
            })
            .collect::<Result<Vec<_>, _>>()?;
        Ok(Gate {
            state: Mutex::new(State {
                free: (0..pools.len()).rev().collect(),
                ..State::default()
            }),
            turn: Condvar::new(),
            pools,
            reserve_ns: u64::try_from(reserve.as_nanos()).unwrap_or(u64::MAX),
        })
    }

    /// Frames admitted at a time.
    pub fn slots(&self) -> usize {
        self.pools.len()
    }

    /// Worker threads of each slot.
    pub fn threads_per_slot(&self) -> usize {
        self.pools[0].current_num_threads()
    }

    /// Frames waiting for a slot now.
    pub fn waiting(&self) -> usize {
        self.lock().waiting.len()
    }

    fn lock(&self) -> MutexGuard<'_, State> {
        self.state.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// Waits until the frame due at `deadline_ns` (CLOCK_MONOTONIC) is the earliest waiting
    /// and a slot is free for it, and takes the slot.
    pub fn enter(&self, deadline_ns: u64) -> Permit<'_> {
        let mut s = self.lock();
        let me = Reverse((deadline_ns, s.next_ticket));
        s.next_ticket += 1;
        s.waiting.push(me);
        loop {
            let mut until_urgent = None;
            if s.waiting.peek() == Some(&me) && !s.free.is_empty() {
                let busy = s.free.len() < self.pools.len();
                let urgent_at = deadline_ns.saturating_sub(self.reserve_ns);
                let now = monotonic_ns();
                if s.free.len() > 1 || !busy || now >= urgent_at {
                    let slot = s.free.pop().unwrap_or_default();
                    s.waiting.pop();
                    if !s.free.is_empty() && !s.waiting.is_empty() {
                        // A slot is left: the next earliest may go too.
                        self.turn.notify_all();
                    }
                    return Permit { gate: self, slot };
                }
                // Only the last slot is free and this frame is not urgent: no frame behind it is
                // (their deadlines are later). Wait for a change, or until it becomes urgent.
                until_urgent = Some(Duration::from_nanos(urgent_at - now));
            }
            s = match until_urgent {
                Some(t) => {
                    self.turn
                        .wait_timeout(s, t)
                        .unwrap_or_else(|p| p.into_inner())
                        .0
                }
                None => self.turn.wait(s).unwrap_or_else(|p| p.into_inner()),
            };
        }
    }
}

impl Permit<'_> {
    /// Runs `work` on the slot's worker threads (rayon calls inside it stay on them).
    pub fn run<R: Send>(&self, work: impl FnOnce() -> R + Send) -> R {
        self.gate.pools[self.slot].install(work)
    }
}

impl Drop for Permit<'_> {
    fn drop(&mut self) {
        let mut s = self.gate.lock();
        s.free.push(self.slot);
        drop(s);
        self.gate.turn.notify_all();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::Arc;
    use std::sync::atomic::{AtomicUsize, Ordering};
    use std::time::Duration;

    /// Waits until `n` frames wait in the gate (a state to reach, not a time to meet).
    fn until_waiting(gate: &Gate, n: usize) {
        while gate.waiting() != n {
            std::thread::yield_now();
        }
    }

    #[test]
    fn frames_run_earliest_deadline_first_ties_in_arrival_order_and_late_ones_first() {
        let gate = Arc::new(Gate::new(1, 1, Duration::ZERO).unwrap());
        let order = Arc::new(Mutex::new(Vec::new()));
        // The main thread holds the only slot while the frames line up one by one.
        let held = gate.enter(0);
        // (name, deadline): `late` is already past its deadline when it comes, last.
        let frames = [
            ("c", 300),
            ("a", 100),
            ("d", 300),
            ("b", 200),
            ("e", 900),
            ("late", 0),
        ];
        let mut threads = Vec::new();
        for (i, (name, deadline)) in frames.into_iter().enumerate() {
            let (g, o) = (gate.clone(), order.clone());
            threads.push(std::thread::spawn(move || {
                let permit = g.enter(deadline);
                let tid = permit.run(|| std::thread::current().name().map(str::to_owned));
                o.lock().unwrap().push((name, tid));
            }));
            until_waiting(&gate, i + 1);
        }
        drop(held);
        for t in threads {
            t.join().unwrap();
        }
        let order = order.lock().unwrap();
        let names: Vec<&str> = order.iter().map(|(n, _)| *n).collect();
        assert_eq!(names, ["late", "a", "b", "c", "d", "e"]);
        assert!(order.iter().all(|(_, t)| t.as_deref() == Some("g0.0")));
        assert_eq!(gate.waiting(), 0);
    }

    #[test]
    fn the_last_free_slot_is_kept_for_urgent_frames() {
        let hour = Duration::from_secs(3600).as_nanos() as u64;
        let gate = Arc::new(Gate::new(2, 1, Duration::from_secs(3600)).unwrap());
        let order = Arc::new(Mutex::new(Vec::new()));
        let now = monotonic_ns();
        // An urgent frame holds one slot.
        let held = gate.enter(now);
        // A frame due in two hours may not take the last free slot...
        let (g, o) = (gate.clone(), order.clone());
        let distant = std::thread::spawn(move || {
            let _p = g.enter(now + 2 * hour);
            o.lock().unwrap().push("distant");
        });
        until_waiting(&gate, 1);
        // ...which an urgent frame coming after it gets at once, while the first slot is held.
        let (g, o) = (gate.clone(), order.clone());
        std::thread::spawn(move || {
            let _p = g.enter(now + hour / 2);
            o.lock().unwrap().push("urgent");
        })
        .join()
        .unwrap();
        assert_eq!(*order.lock().unwrap(), ["urgent"]);
        assert_eq!(gate.waiting(), 1);
        // Once no other slot is busy, the distant frame goes.
        drop(held);
        distant.join().unwrap();
        assert_eq!(*order.lock().unwrap(), ["urgent", "distant"]);
        // Alone in an idle gate, a distant frame does not wait.
        drop(gate.enter(now + 2 * hour));
    }

    #[test]
    fn every_slot_is_used_and_never_more_frames_than_slots_run_at_once() {
        let gate = Arc::new(Gate::new(2, 1, Duration::ZERO).unwrap());
        assert_eq!((gate.slots(), gate.threads_per_slot()), (2, 1));
        // One frame holds a slot; another frame still gets the second one at once.
        let held = gate.enter(5);
        let (tx, rx) = std::sync::mpsc::channel();
        let g = gate.clone();
        std::thread::spawn(move || {
            let p = g.enter(10);
            tx.send(p.run(|| std::thread::current().name().map(str::to_owned)))
                .unwrap();
        });
        let other = rx
            .recv_timeout(Duration::from_secs(60))
            .expect("a free slot was not given to a waiting frame");
        let mine = held.run(|| std::thread::current().name().map(str::to_owned));
        assert_ne!(other, mine, "two frames shared a slot's worker");
        drop(held);

        // Many streams, many frames: every frame runs once, at most two at a time, and no
        // wake-up is lost (a lost one leaves a thread waiting for ever).
        let (streams, frames) = (8u64, 300u64);
        let running = Arc::new(AtomicUsize::new(0));
        let most = Arc::new(AtomicUsize::new(0));
        let done = Arc::new(AtomicUsize::new(0));
        let (tx, rx) = std::sync::mpsc::channel();
        for k in 0..streams {
            let (gate, running, most, done, tx) = (
                gate.clone(),
                running.clone(),
                most.clone(),
                done.clone(),
                tx.clone(),
            );
            std::thread::spawn(move || {
                for f in 0..frames {
                    let deadline = (f * 7919 + k * 104_729) % 1000;
                    let p = gate.enter(deadline);
                    let now = running.fetch_add(1, Ordering::SeqCst) + 1;
                    most.fetch_max(now, Ordering::SeqCst);
                    p.run(std::thread::yield_now);
                    running.fetch_sub(1, Ordering::SeqCst);
                    drop(p);
                    done.fetch_add(1, Ordering::SeqCst);
                }
                tx.send(()).unwrap();
            });
        }
        for _ in 0..streams {
            rx.recv_timeout(Duration::from_secs(120))
                .unwrap_or_else(|_| {
                    panic!(
                        "a stream never got its slot: {} of {} frames ran, {} waiting",
                        done.load(Ordering::SeqCst),
                        streams * frames,
                        gate.waiting()
                    )
                });
        }
        assert_eq!(done.load(Ordering::SeqCst), (streams * frames) as usize);
        assert!(most.load(Ordering::SeqCst) <= 2, "{most:?} frames at once");
        assert_eq!(gate.waiting(), 0);
    }
}
