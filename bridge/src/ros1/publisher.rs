//! Publications: each connected subscriber has its own writer thread and a queue of two
//! messages, so a slow subscriber (a rospy node whose callback takes long stops reading its
//! socket) delays only itself; when its queue is full the oldest message is dropped and counted,
//! as roscpp does. A message is serialized once, into a recycled buffer shared by every queue.

use super::node::Shared;
use super::xmlrpc::Value;
use perturb_core::formats::ros1::MsgType;
use std::collections::VecDeque;
use std::io::Write;
use std::net::TcpStream;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Condvar, Mutex};
use tracing::{debug, info};

/// Messages a subscriber's queue holds before the oldest is dropped.
const LINK_QUEUE: usize = 2;

/// One connected subscriber.
struct Link {
    id: u32,
    caller: String,
    queue: Mutex<VecDeque<Arc<Vec<u8>>>>,
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
            if let Err(e) = w.write_all(&msg) {
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
    fn enqueue(&self, msg: &Arc<Vec<u8>>) -> usize {
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
    pool: Vec<Arc<Vec<u8>>>,
}

impl Publisher {
    pub(crate) fn new(shared: Arc<PubShared>, node: Arc<Shared>) -> Self {
        Publisher {
            shared,
            node,
            pool: Vec::new(),
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

    /// True once the master knows this publication.
    pub fn is_registered(&self) -> bool {
        self.shared.registered.load(Ordering::Relaxed)
    }

    /// Publishes one message given as consecutive parts (see
    /// [`perturb_core::formats::ros1::Ros1Parts`]); returns how many subscribers it was queued
    /// for. Nothing is serialized when nobody subscribes.
    pub fn publish(&mut self, parts: &[&[u8]]) -> usize {
        if self.shared.subscribers() == 0 {
            return 0;
        }
        let len: usize = parts.iter().map(|p| p.len()).sum();
        let mut buf = match self.pool.iter().position(|b| Arc::strong_count(b) == 1) {
            Some(i) => self.pool.swap_remove(i),
            None => Arc::new(Vec::with_capacity(len + 4)),
        };
        {
            let v = Arc::get_mut(&mut buf).expect("only the pool held it");
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
