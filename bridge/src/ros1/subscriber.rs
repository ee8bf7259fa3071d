//! Subscriptions: one thread per publisher (`requestTopic`, connect, exchange headers, then read
//! messages into recycled buffers), all feeding one bounded queue that the reader takes from.
//! The publisher list comes from the master (`registerSubscriber`, then `publisherUpdate`): a
//! new publisher is connected, and a link that breaks while its publisher is still listed is
//! retried (every 0.5 s, backing off to 5 s). A publisher the list no longer names is
//! disconnected only if its link is not working: a master that restarted knows none of the
//! nodes that registered with the old one (rospy and roscpp do not register again), so its list
//! is empty or partial while their links still carry messages. Such a link stays until its
//! connection ends (the publisher went away); it is then not retried. This is what ROS 1 itself
//! promises: links outlive the master. A publisher that refuses the connection with an `error`
//! header (another type or md5sum) is reported and not retried.

use super::node::{CALL_TIMEOUT, Shared, ros_value};
use super::tcpros;
use super::xmlrpc::{self, Value};
use crossbeam::channel::{Receiver, Sender, TrySendError, bounded};
use perturb_core::formats::ros1::MsgType;
use std::collections::BTreeMap;
use std::net::{TcpStream, ToSocketAddrs};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;
use tracing::{debug, error, info, warn};

/// What a publisher said of its messages when the link was made (its TCPROS header): what a
/// subscription of any type (`*`) needs to decode them.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct ConnInfo {
    /// The publishing node.
    pub callerid: String,
    /// The message type (`std_msgs/Bool`).
    pub type_name: String,
    /// Its md5sum.
    pub md5sum: String,
    /// Its full definition.
    pub definition: String,
}

/// One received message.
#[derive(Debug)]
pub struct Incoming {
    /// The publisher's XML-RPC URI.
    pub publisher: Arc<str>,
    /// What the publisher said of its messages.
    pub conn: Arc<ConnInfo>,
    /// The serialized message (without its length prefix).
    pub data: Vec<u8>,
}

/// A link to one publisher.
struct Link {
    uri: Arc<str>,
    id: u32,
    stop: AtomicBool,
    connected: AtomicBool,
    /// True while the master's latest list names the publisher; an unlisted link lives on while
    /// it is connected and is not retried once it breaks.
    listed: AtomicBool,
    stream: Mutex<Option<TcpStream>>,
}

impl Link {
    fn kill(&self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Ok(s) = self.stream.lock()
            && let Some(s) = s.as_ref()
        {
            let _ = s.shutdown(std::net::Shutdown::Both);
        }
    }
}

/// A subscription's state, shared by the node (master updates) and the [`Subscriber`].
pub(crate) struct SubShared {
    pub(crate) topic: String,
    pub(crate) ty: MsgType,
    pub(crate) registered: AtomicBool,
    links: Mutex<BTreeMap<Arc<str>, Arc<Link>>>,
    tx: Sender<Incoming>,
    /// A second receiver, to drop the oldest message when the queue is full.
    oldest: Receiver<Incoming>,
    pool: Receiver<Vec<u8>>,
    dropped: AtomicU64,
    closed: AtomicBool,
}

impl SubShared {
    /// Connects new publishers and disconnects those no longer listed.
    pub(crate) fn update_publishers(self: &Arc<Self>, uris: &[String], node: &Arc<Shared>) {
        if self.closed.load(Ordering::Relaxed) {
            return;
        }
        let Ok(mut links) = self.links.lock() else {
            return;
        };
        links.retain(|uri, link| {
            let listed = uris.iter().any(|u| u.as_str() == &**uri);
            link.listed.store(listed, Ordering::Relaxed);
            if listed {
                return true;
            }
            if link.connected.load(Ordering::Relaxed) {
                // A restarted master does not know this publisher, which still sends: keep it.
                debug!(topic = %self.topic, publisher = %uri, "publisher not listed by the master, link kept while it works");
                return true;
            }
            info!(topic = %self.topic, publisher = %uri, "ROS 1 publisher left");
            link.kill();
            false
        });
        for uri in uris {
            if links.contains_key(uri.as_str()) || *uri == node.api_uri {
                continue;
            }
            let link = Arc::new(Link {
                uri: Arc::from(uri.as_str()),
                id: node.next_conn_id.fetch_add(1, Ordering::Relaxed),
                stop: AtomicBool::new(false),
                connected: AtomicBool::new(false),
                listed: AtomicBool::new(true),
                stream: Mutex::new(None),
            });
            links.insert(link.uri.clone(), link.clone());
            let (me, node) = (self.clone(), node.clone());
            let spawned = std::thread::Builder::new()
                .name("ros1-link-in".into())
                .spawn(move || me.run_link(&link, &node));
            if let Err(e) = spawned {
                error!(topic = %self.topic, "cannot start a link thread: {e}");
            }
        }
    }

    /// Keeps one publisher connected until it leaves the list, refuses us, or the node stops.
    fn run_link(&self, link: &Link, node: &Shared) {
        let mut backoff = Duration::from_millis(500);
        let mut failures = 0u32;
        while !link.stop.load(Ordering::Relaxed) && !node.stopped() {
            match self.connect_and_read(link, node) {
                Ok(()) => {
                    if !link.stop.load(Ordering::Relaxed) && !node.stopped() {
                        info!(topic = %self.topic, publisher = %link.uri, "the ROS 1 publisher closed the connection");
                    }
                    backoff = Duration::from_millis(500);
                    failures = 0;
                }
                Err(LinkError::Refused(msg)) => {
                    error!(topic = %self.topic, publisher = %link.uri, "the ROS 1 publisher refused the connection: {msg}");
                    break;
                }
                Err(LinkError::Failed(msg)) => {
                    failures += 1;
                    if failures == 1 {
                        warn!(topic = %self.topic, publisher = %link.uri, "cannot reach the ROS 1 publisher ({msg}); retrying while the master lists it");
                    } else {
                        debug!(topic = %self.topic, publisher = %link.uri, "still cannot reach the publisher: {msg}");
                    }
                }
            }
            link.connected.store(false, Ordering::Relaxed);
            if !link.listed.load(Ordering::Relaxed) {
                // Kept only because it worked while the master did not list it: it ended.
                info!(topic = %self.topic, publisher = %link.uri, "ROS 1 publisher left (its link ended; the master does not list it)");
                self.forget(link);
                break;
            }
            let end = std::time::Instant::now() + backoff;
            while std::time::Instant::now() < end
                && !link.stop.load(Ordering::Relaxed)
                && !node.stopped()
            {
                std::thread::sleep(Duration::from_millis(20));
            }
            backoff = (backoff * 2).min(Duration::from_secs(5));
        }
        link.connected.store(false, Ordering::Relaxed);
    }

    /// Removes `link` from the links (if it is still the one kept for its publisher).
    fn forget(&self, link: &Link) {
        if let Ok(mut links) = self.links.lock()
            && links
                .get(&link.uri)
                .is_some_and(|l| std::ptr::eq(Arc::as_ptr(l), link))
        {
            links.remove(&link.uri);
        }
    }

    fn connect_and_read(&self, link: &Link, node: &Shared) -> Result<(), LinkError> {
        let failed =
            |what: &str, e: &dyn std::fmt::Display| LinkError::Failed(format!("{what}: {e}"));
        let reply = xmlrpc::call(
            &link.uri,
            "requestTopic",
            &[
                node.name.clone().into(),
                self.topic.clone().into(),
                Value::Array(vec![Value::Array(vec!["TCPROS".into()])]),
            ],
            CALL_TIMEOUT,
        )
        .map_err(|e| failed("requestTopic", &e))?;
        let proto = ros_value(reply).map_err(|e| failed("requestTopic", &e))?;
        let p = proto.as_array().unwrap_or_default();
        let (host, port) = match (
            p.first().and_then(Value::as_str),
            p.get(1).and_then(Value::as_str),
            p.get(2).and_then(Value::as_i32),
        ) {
            (Some("TCPROS"), Some(h), Some(port)) => (h.to_string(), port as u16),
            _ => {
                return Err(LinkError::Refused(format!(
                    "requestTopic answered {proto:?}, not TCPROS"
                )));
            }
        };
        let addr = (host.as_str(), port)
            .to_socket_addrs()
            .map_err(|e| failed(&format!("resolving {host}"), &e))?
            .next()
            .ok_or_else(|| LinkError::Failed(format!("{host} resolves to no address")))?;
        let stream = TcpStream::connect_timeout(&addr, CALL_TIMEOUT)
            .map_err(|e| failed(&format!("connecting to {host}:{port}"), &e))?;
        let _ = stream.set_nodelay(true);
        let _ = stream.set_read_timeout(Some(CALL_TIMEOUT));
        if let Ok(mut s) = link.stream.lock() {
            *s = stream.try_clone().ok();
        }
        if link.stop.load(Ordering::Relaxed) {
            return Ok(());
        }
        let header = tcpros::encode_header(&[
            ("callerid", &node.name),
            ("topic", &self.topic),
            ("md5sum", self.ty.md5sum),
            ("type", self.ty.name),
            ("message_definition", self.ty.definition),
            ("tcp_nodelay", "1"),
        ]);
        let mut w = &stream;
        std::io::Write::write_all(&mut w, &header).map_err(|e| failed("sending the header", &e))?;
        let mut r = &stream;
        let h = tcpros::read_header(&mut r).map_err(|e| failed("reading the header", &e))?;
        if let Some(err) = h.get("error") {
            return Err(LinkError::Refused(err.clone()));
        }
        let md5 = h.get("md5sum").map(String::as_str).unwrap_or("");
        if md5 != self.ty.md5sum && md5 != "*" && self.ty.md5sum != "*" {
            return Err(LinkError::Refused(format!(
                "it publishes [{}] with md5sum {md5}, this bridge reads [{}] ({})",
                h.get("type").map(String::as_str).unwrap_or("?"),
                self.ty.name,
                self.ty.md5sum
            )));
        }
        let _ = stream.set_read_timeout(None);
        let field = |k: &str| h.get(k).cloned().unwrap_or_default();
        let conn = Arc::new(ConnInfo {
            callerid: field("callerid"),
            type_name: field("type"),
            md5sum: field("md5sum"),
            definition: field("message_definition"),
        });
        link.connected.store(true, Ordering::Relaxed);
        info!(topic = %self.topic, publisher = %link.uri, "connected to the ROS 1 publisher {}", h.get("callerid").map(String::as_str).unwrap_or("?"));
        let mut r = std::io::BufReader::with_capacity(1 << 16, &stream);
        loop {
            let mut buf = self.pool.try_recv().unwrap_or_default();
            match tcpros::read_message(&mut r, &mut buf) {
                Ok(()) => self.push(Incoming {
                    publisher: link.uri.clone(),
                    conn: conn.clone(),
                    data: buf,
                }),
                Err(e) if e.kind() == std::io::ErrorKind::UnexpectedEof => return Ok(()),
                Err(_) if link.stop.load(Ordering::Relaxed) || node.stopped() => return Ok(()),
                Err(e) => return Err(failed("reading", &e)),
            }
        }
    }

    /// Queues a message, dropping (and counting) the oldest when the queue is full.
    fn push(&self, mut m: Incoming) {
        loop {
            match self.tx.try_send(m) {
                Ok(()) => return,
                Err(TrySendError::Full(back)) => {
                    if self.oldest.try_recv().is_ok() {
                        self.dropped.fetch_add(1, Ordering::Relaxed);
                    }
                    m = back;
                }
                Err(TrySendError::Disconnected(_)) => return,
            }
        }
    }

    /// getBusInfo rows.
    pub(crate) fn bus_info(&self) -> Vec<Value> {
        self.links
            .lock()
            .map(|l| {
                l.values()
                    .map(|l| {
                        Value::Array(vec![
                            (l.id as i32).into(),
                            l.uri.to_string().into(),
                            "i".into(),
                            "TCPROS".into(),
                            self.topic.clone().into(),
                            Value::Bool(l.connected.load(Ordering::Relaxed)),
                            "".into(),
                        ])
                    })
                    .collect()
            })
            .unwrap_or_default()
    }

    /// Disconnects every publisher.
    pub(crate) fn close(&self) {
        self.closed.store(true, Ordering::Relaxed);
        if let Ok(mut l) = self.links.lock() {
            l.values().for_each(|l| l.kill());
            l.clear();
        }
    }
}

enum LinkError {
    /// The publisher answered with an `error` header or another type: not retried.
    Refused(String),
    /// Unreachable, or the connection broke: retried.
    Failed(String),
}

/// Subscribes to one topic; dropping it unregisters the topic and disconnects the publishers.
pub struct Subscriber {
    shared: Arc<SubShared>,
    node: Arc<Shared>,
    rx: Receiver<Incoming>,
    recycle: Sender<Vec<u8>>,
}

impl Subscriber {
    pub(crate) fn new(
        topic: &str,
        ty: MsgType,
        queue: usize,
        node: Arc<Shared>,
    ) -> (Arc<SubShared>, Subscriber) {
        let (tx, rx) = bounded(queue.max(1));
        let (recycle, pool) = bounded(queue.max(1) + 2);
        let shared = Arc::new(SubShared {
            topic: topic.to_string(),
            ty,
            registered: AtomicBool::new(false),
            links: Mutex::default(),
            tx,
            oldest: rx.clone(),
            pool,
            dropped: AtomicU64::new(0),
            closed: AtomicBool::new(false),
        });
        (
            shared.clone(),
            Subscriber {
                shared,
                node,
                rx,
                recycle,
            },
        )
    }

    /// The topic.
    pub fn topic(&self) -> &str {
        &self.shared.topic
    }

    /// Waits up to `timeout` for a message.
    pub fn recv(&self, timeout: Duration) -> Option<Incoming> {
        self.rx.recv_timeout(timeout).ok()
    }

    /// A message if one is waiting.
    pub fn try_recv(&self) -> Option<Incoming> {
        self.rx.try_recv().ok()
    }

    /// Gives a message's buffer back for the next message.
    pub fn recycle(&self, buf: Vec<u8>) {
        let _ = self.recycle.try_send(buf);
    }

    /// Messages dropped because the reader did not take them in time.
    pub fn dropped(&self) -> u64 {
        self.shared.dropped.load(Ordering::Relaxed)
    }

    /// Publishers connected now.
    pub fn publishers(&self) -> usize {
        self.shared
            .links
            .lock()
            .map(|l| {
                l.values()
                    .filter(|l| l.connected.load(Ordering::Relaxed))
                    .count()
            })
            .unwrap_or(0)
    }

    /// True once the master knows this subscription.
    pub fn is_registered(&self) -> bool {
        self.shared.registered.load(Ordering::Relaxed)
    }
}

impl Drop for Subscriber {
    fn drop(&mut self) {
        if let Ok(mut s) = self.node.subs.lock() {
            s.remove(&self.shared.topic);
        }
        self.shared.close();
        if self.shared.registered.load(Ordering::Relaxed)
            && let Err(e) = self.node.master(
                "unregisterSubscriber",
                &[
                    self.shared.topic.clone().into(),
                    self.node.api_uri.clone().into(),
                ],
            )
        {
            debug!(topic = %self.shared.topic, "unregisterSubscriber: {e}");
        }
    }
}
