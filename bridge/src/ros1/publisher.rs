//! Publications: each connected subscriber has its own writer thread and a queue of two
//! messages, so a slow subscriber (a rospy node whose callback takes long stops reading its
//! socket) delays only itself; when its queue is full the oldest message is dropped and counted,
//! as roscpp does. A message is serialized once and shared by every queue: small messages into a
//! recycled buffer, a sensor frame as its header and tail around a reference to its data where
//! they lie ([`Publisher::publish_shared`]: shared memory), written with one vectored write.

use super::node::Shared;
use super::xmlrpc::Value;
use perturb_core::formats::ros1::MsgType;
use std::collections::VecDeque;
use std::io::{IoSlice, Write};
use std::net::TcpStream;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Condvar, Mutex, Weak};
use tracing::{debug, info};

/// Messages a subscriber's queue holds before the oldest is dropped.
const LINK_QUEUE: usize = 2;

/// Shared messages (references to data held elsewhere) a publication keeps in its queues at
/// once; past this the next message is copied, so that a stalled subscriber never holds more
/// than this many of the bus's frames (an iceoryx2 subscriber may hold only a few).
pub const SHARED_IN_FLIGHT: usize = 2;

/// Bytes kept where they lie until every subscriber has written them (a frame's data in shared
/// memory): [`Publisher::publish_shared`] writes them without copying.
pub trait SharedData: Send + Sync {
    /// The bytes.
    fn data(&self) -> &[u8];
}

/// A message as the subscribers' queues hold it.
enum Msg {
    /// Serialized into one buffer, its length prefix included.
    Flat(Vec<u8>),
    /// The length prefix and the fields before the data, the data where it lies, the fields
    /// after it.
    Shared {
        head: Vec<u8>,
        data: Box<dyn SharedData>,
        tail: Vec<u8>,
    },
}

impl Msg {
    /// Writes the whole message (a vectored write for a shared one: no copy of its data).
    fn write_to(&self, w: &mut impl Write) -> std::io::Result<()> {
        match self {
            Msg::Flat(v) => w.write_all(v),
            Msg::Shared { head, data, tail } => {
                let mut parts = [
                    IoSlice::new(head),
                    IoSlice::new(data.data()),
                    IoSlice::new(tail),
                ];
                let mut bufs = &mut parts[..];
                while !bufs.is_empty() {
                    match w.write_vectored(bufs) {
                        Ok(0) => return Err(std::io::ErrorKind::WriteZero.into()),
                        Ok(n) => IoSlice::advance_slices(&mut bufs, n),
                        Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
                        Err(e) => return Err(e),
                    }
                }
                Ok(())
            }
        }
    }
}

/// One connected subscriber.
struct Link {
    id: u32,
    caller: String,
    queue: Mutex<VecDeque<Arc<Msg>>>,
    wake: Condvar,
    alive: AtomicBool,
    dropped: AtomicU64,
    stream: TcpStream,
}

impl Link {
    fn kill(&self) {
        self.alive.store(false, Ordering::Relaxed);
        let _ = self.stream.shutdown(std::net::Shutdown::Both);
        self.wake.notify_all();
    }
}

/// A publication's state, shared by the node (which connects subscribers) and the [`Publisher`].
pub(crate) struct PubShared {
    pub(crate) topic: String,
    pub(crate) ty: MsgType,
    pub(crate) registered: AtomicBool,
    links: Mutex<Vec<Arc<Link>>>,
    closed: AtomicBool,
    /// Messages dropped for subscribers that have left.
    dropped_gone: AtomicU64,
}

impl PubShared {
    pub(crate) fn new(topic: &str, ty: MsgType) -> Self {
        PubShared {
            topic: topic.to_string(),
            ty,
            registered: AtomicBool::new(false),
            links: Mutex::default(),
            closed: AtomicBool::new(false),
            dropped_gone: AtomicU64::new(0),
        }
    }

    /// Serves a subscriber whose header was accepted, in the calling thread, until it goes.
    pub(crate) fn serve(&self, id: u32, caller: String, stream: TcpStream, node: &Shared) {
        let Ok(write_half) = stream.try_clone() else {
            return;
        };
        let link = Arc::new(Link {
            id,
            caller,
            queue: Mutex::new(VecDeque::with_capacity(LINK_QUEUE)),
            wake: Condvar::new(),
            alive: AtomicBool::new(true),
            dropped: AtomicU64::new(0),
            stream,
        });
        match self.links.lock() {
            Ok(mut l) if !self.closed.load(Ordering::Relaxed) => l.push(link.clone()),
            _ => return,
        }
        info!(topic = %self.topic, subscriber = %link.caller, "ROS 1 subscriber connected");
        let mut w = write_half;
        let why = loop {
            let next = {
                let Ok(mut q) = link.queue.lock() else {
                    break "poisoned".to_string();
                };
                loop {
                    if !link.alive.load(Ordering::Relaxed) || node.stopped() {
                        break None;
                    }
                    if let Some(m) = q.pop_front() {
                        break Some(m);
                    }
                    q = match link
                        .wake
                        .wait_timeout(q, std::time::Duration::from_millis(200))
                    {
                        Ok((q, _)) => q,
                        Err(_) => break None,
                    };
                }
            };
            let Some(msg) = next else {
                break "closed".to_string();
            };
            if let Err(e) = msg.write_to(&mut w) {
                break e.to_string();
            }
        };
        link.kill();
        let dropped = match self.links.lock() {
            Ok(mut l) => {
                l.retain(|x| x.id != link.id);
                // Under the lock, so `dropped()` never counts the link twice or not at all.
                let n = link.dropped.load(Ordering::Relaxed);
                self.dropped_gone.fetch_add(n, Ordering::Relaxed);
                n
            }
            Err(_) => link.dropped.load(Ordering::Relaxed),
        };
        info!(
            topic = %self.topic,
            subscriber = %link.caller,
            dropped,
            "ROS 1 subscriber left ({why})"
        );
    }

    /// Queues a framed message on every link; returns how many.
    fn enqueue(&self, msg: &Arc<Msg>) -> usize {
        let Ok(links) = self.links.lock() else {
            return 0;
        };
        for l in links.iter() {
            if let Ok(mut q) = l.queue.lock() {
                if q.len() >= LINK_QUEUE {
                    q.pop_front();
                    let n = l.dropped.fetch_add(1, Ordering::Relaxed) + 1;
                    if n == 1 || n.is_multiple_of(100) {
                        debug!(topic = %self.topic, subscriber = %l.caller, "slow subscriber: {n} message(s) dropped");
                    }
                }
                q.push_back(msg.clone());
            }
            l.wake.notify_one();
        }
        links.len()
    }

    fn subscribers(&self) -> usize {
        self.links.lock().map(|l| l.len()).unwrap_or(0)
    }

    fn dropped(&self) -> u64 {
        self.links
            .lock()
            .map(|l| {
                self.dropped_gone.load(Ordering::Relaxed)
                    + l.iter()
                        .map(|l| l.dropped.load(Ordering::Relaxed))
                        .sum::<u64>()
            })
            .unwrap_or(0)
    }

    /// getBusInfo rows.
    pub(crate) fn bus_info(&self) -> Vec<Value> {
        self.links
            .lock()
            .map(|l| {
                l.iter()
                    .map(|l| {
                        Value::Array(vec![
                            (l.id as i32).into(),
                            l.caller.clone().into(),
                            "o".into(),
                            "TCPROS".into(),
                            self.topic.clone().into(),
                            Value::Bool(true),
                            "".into(),
                        ])
                    })
                    .collect()
            })
            .unwrap_or_default()
    }

    /// Disconnects every subscriber.
    pub(crate) fn close(&self) {
        self.closed.store(true, Ordering::Relaxed);
        if let Ok(l) = self.links.lock() {
            l.iter().for_each(|l| l.kill());
        }
    }
}

/// Publishes one topic; dropping it unregisters the topic and disconnects its subscribers.
pub struct Publisher {
    shared: Arc<PubShared>,
    node: Arc<Shared>,
    /// Message buffers, reused once every link has written them.
    pool: Vec<Arc<Msg>>,
    /// The shared messages still in some queue or being written.
    in_flight: Vec<Weak<Msg>>,
    /// Messages given as shared data and copied because [`SHARED_IN_FLIGHT`] were in flight.
    copied: u64,
}

impl Publisher {
    pub(crate) fn new(shared: Arc<PubShared>, node: Arc<Shared>) -> Self {
        Publisher {
            shared,
            node,
            pool: Vec::new(),
            in_flight: Vec::new(),
            copied: 0,
        }
    }

    /// The topic.
    pub fn topic(&self) -> &str {
        &self.shared.topic
    }

    /// Subscribers connected now.
    pub fn subscribers(&self) -> usize {
        self.shared.subscribers()
    }

    /// Messages dropped for slow subscribers so far (those connected now and those that left).
    pub fn dropped(&self) -> u64 {
        self.shared.dropped()
    }

    /// Messages given to [`Publisher::publish_shared`] that were copied all the same, because
    /// subscribers still held [`SHARED_IN_FLIGHT`] earlier ones.
    pub fn copied(&self) -> u64 {
        self.copied
    }

    /// True once the master knows this publication.
    pub fn is_registered(&self) -> bool {
        self.shared.registered.load(Ordering::Relaxed)
    }

    /// Publishes one message given as consecutive parts (see
    /// [`perturb_core::formats::ros1::Ros1Parts`]), copied into one buffer; returns how many
    /// subscribers it was queued for. Nothing is serialized when nobody subscribes.
    pub fn publish(&mut self, parts: &[&[u8]]) -> usize {
        if self.shared.subscribers() == 0 {
            return 0;
        }
        let len: usize = parts.iter().map(|p| p.len()).sum();
        let mut buf = match self.pool.iter().position(|b| Arc::strong_count(b) == 1) {
            Some(i) => self.pool.swap_remove(i),
            None => Arc::new(Msg::Flat(Vec::with_capacity(len + 4))),
        };
        if let Some(Msg::Flat(v)) = Arc::get_mut(&mut buf) {
            v.clear();
            v.extend_from_slice(&(len as u32).to_le_bytes());
            for p in parts {
                v.extend_from_slice(p);
            }
        }
        let n = self.shared.enqueue(&buf);
        if self.pool.len() < LINK_QUEUE + 2 {
            self.pool.push(buf);
        }
        n
    }

    /// Publishes the message `head ++ data ++ tail` without copying `data`: every subscriber's
    /// writer sends it from where it lies, and `data` is dropped (a shared-memory sample handed
    /// back) once the last one has. While [`SHARED_IN_FLIGHT`] shared messages are still queued
    /// or being written, the message is copied instead (counted in [`Publisher::copied`]).
    pub fn publish_shared(&mut self, head: &[u8], data: Box<dyn SharedData>, tail: &[u8]) -> usize {
        if self.shared.subscribers() == 0 {
            return 0;
        }
        self.in_flight.retain(|m| m.strong_count() > 0);
        if self.in_flight.len() >= SHARED_IN_FLIGHT {
            self.copied += 1;
            return self.publish(&[head, data.data(), tail]);
        }
        let len = head.len() + data.data().len() + tail.len();
        let mut with_len = Vec::with_capacity(head.len() + 4);
        with_len.extend_from_slice(&(len as u32).to_le_bytes());
        with_len.extend_from_slice(head);
        let msg = Arc::new(Msg::Shared {
            head: with_len,
            data,
            tail: tail.to_vec(),
        });
        self.in_flight.push(Arc::downgrade(&msg));
        self.shared.enqueue(&msg)
    }
}

impl Drop for Publisher {
    fn drop(&mut self) {
        if let Ok(mut p) = self.node.pubs.lock() {
            p.remove(&self.shared.topic);
        }
        self.shared.close();
        if self.shared.registered.load(Ordering::Relaxed)
            && let Err(e) = self.node.master(
                "unregisterPublisher",
                &[
                    self.shared.topic.clone().into(),
                    self.node.api_uri.clone().into(),
                ],
            )
        {
            debug!(topic = %self.shared.topic, "unregisterPublisher: {e}");
        }
    }
}
