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

mod gate;
mod processor;
mod receiver;
mod runtime;

pub use gate::{Gate, Permit};
pub use runtime::StreamRuntime;

use processor::process_loop;
use receiver::receive_loop;

use crate::perturbation::Active;
use perturb_wire::{Frame, FramePublisher, FrameSubscriber};
use std::sync::Arc;
use std::sync::atomic::AtomicBool;
use std::thread::JoinHandle;
use std::time::Duration;

/// How often blocked threads look at the shutdown flag.
const TICK: Duration = Duration::from_millis(200);

/// A received frame on its way to the processing thread.
struct Item {
    frame: Frame,
    t_rx: u64,
}

/// Logs the first occurrences of a recurring problem, then every 100th.
fn should_log(n: u64) -> bool {
    n <= 10 || n.is_multiple_of(100)
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::Config;
    use crate::state::CounterCell;
    use crate::stream::StreamConfig;

    fn stream(extra: &str) -> StreamConfig {
        let text = format!("[[streams]]\nname = \"cam\"\nmodality = \"camera\"\n{extra}");
        Config::parse(&text).unwrap().streams.remove(0)
    }

    #[test]
    fn a_stream_with_threads_runs_its_frame_work_on_a_pool_of_that_size() {
        let rt = StreamRuntime::new(stream("threads = 3\n"), None, CounterCell::default()).unwrap();
        assert_eq!(rt.worker_threads(), 3);
        let (n, name) = rt.on_workers(0, || {
            let inner = rayon::join(|| std::thread::current().name().map(str::to_owned), || ());
            (rayon::current_num_threads(), inner.0)
        });
        assert_eq!(n, 3);
        assert!(name.is_some_and(|n| n.ends_with("-cam")));
        // Without `threads` the work stays on the caller's (global) pool.
        let rt = StreamRuntime::new(stream(""), None, CounterCell::default()).unwrap();
        assert_eq!(
            rt.on_workers(0, rayon::current_num_threads),
            rayon::current_num_threads()
        );
        assert_eq!(rt.worker_threads(), rayon::current_num_threads());
    }

    #[test]
    fn with_the_deadline_gate_a_stream_runs_on_a_slot_unless_it_has_its_own_pool() {
        let gate = Some(Arc::new(Gate::new(2, 1, Duration::ZERO).unwrap()));
        let rt = StreamRuntime::new(stream(""), None, CounterCell::default())
            .unwrap()
            .with_gate(gate.clone());
        assert_eq!(rt.worker_threads(), 1);
        let (n, name) = rt.on_workers(0, || {
            let inner = rayon::join(|| std::thread::current().name().map(str::to_owned), || ());
            (rayon::current_num_threads(), inner.0)
        });
        assert_eq!(n, 1);
        assert!(name.is_some_and(|n| n.starts_with('g')), "not on a slot");
        // `threads` keeps the stream's own pool: its frames do not enter the gate.
        let rt = StreamRuntime::new(stream("threads = 3\n"), None, CounterCell::default())
            .unwrap()
            .with_gate(gate);
        assert_eq!(rt.worker_threads(), 3);
        let name = rt.on_workers(0, || std::thread::current().name().map(str::to_owned));
        assert!(name.is_some_and(|n| n.ends_with("-cam")));
    }
}
