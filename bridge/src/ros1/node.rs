//! A ROS 1 node: its XML-RPC API (the "slave API" the master and other nodes call), its TCPROS
//! server, and its registration with the master, kept up across master outages and restarts.
//!
//! Registration runs in a supervisor thread: it waits for a master that is not up yet, registers
//! every publication and subscription, and then asks the master once a second who this node is
//! (`lookupNode`). A master that does not answer is waited for; a master that answers without
//! knowing this node was restarted, and everything is registered again (the master then sends
//! `publisherUpdate` to the subscribers, and subscribers get the current publishers).

use super::publisher::{PubShared, Publisher};
use super::subscriber::{SubShared, Subscriber};
use super::tcpros;
use super::xmlrpc::{self, Value};
use super::{Ros1Error, Ros1Settings};
use perturb_core::formats::ros1::MsgType;
use std::collections::BTreeMap;
use std::net::{TcpListener, TcpStream};
use std::sync::atomic::{AtomicBool, AtomicU32, Ordering};
use std::sync::{Arc, Mutex, Weak};
use std::time::{Duration, Instant};
use tracing::{debug, error, info, warn};

/// Timeout of one XML-RPC call to the master or a node.
pub(crate) const CALL_TIMEOUT: Duration = Duration::from_secs(5);

/// What every part of a node shares.
pub(crate) struct Shared {
    /// Global node name (`/perturb_bridge`).
    pub name: String,
    /// The master's URI.
    pub master_uri: String,
    /// The host advertised to other nodes.
    pub host: String,
    /// This node's XML-RPC URI.
    pub api_uri: String,
    /// The TCPROS server's port.
    pub tcpros_port: u16,
    pub(crate) pubs: Mutex<BTreeMap<String, Arc<PubShared>>>,
    pub(crate) subs: Mutex<BTreeMap<String, Arc<SubShared>>>,
    pub(crate) stop: AtomicBool,
    /// Connection ids for getBusInfo.
    pub(crate) next_conn_id: AtomicU32,
}

impl Shared {
    /// Calls the master.
    pub(crate) fn master(&self, method: &str, args: &[Value]) -> Result<Value, String> {
        let mut all = vec![Value::Str(self.name.clone())];
        all.extend_from_slice(args);
        let v = xmlrpc::call(&self.master_uri, method, &all, CALL_TIMEOUT)?;
        ros_value(v).map_err(|e| format!("{method}: {e}"))
    }

    pub(crate) fn stopped(&self) -> bool {
        self.stop.load(Ordering::Relaxed)
    }
}

/// Unwraps a ROS API reply `[code, status, value]`: the value when code is 1.
pub(crate) fn ros_value(v: Value) -> Result<Value, String> {
    let a = v
        .as_array()
        .filter(|a| a.len() == 3)
        .ok_or_else(|| format!("not a [code, status, value] reply: {v:?}"))?;
    match a[0].as_i32() {
        Some(1) => Ok(a[2].clone()),
        Some(c) => Err(format!(
            "code {c}: {}",
            a[1].as_str().unwrap_or("(no status message)")
        )),
        None => Err(format!("not a [code, status, value] reply: {v:?}")),
    }
}

/// A ROS 1 node speaking TCPROS natively.
pub struct Node {
    shared: Arc<Shared>,
    _xmlrpc: xmlrpc::Server,
    threads: Vec<std::thread::JoinHandle<()>>,
}

impl std::fmt::Debug for Node {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Node")
            .field("name", &self.shared.name)
            .field("api", &self.shared.api_uri)
            .field("master", &self.shared.master_uri)
            .finish()
    }
}

/// The address to listen on for an advertised host: loopback stays loopback, anything else
/// listens on every interface (as roscpp does) and is reached through the advertised name.
fn bind_host(host: &str) -> &'static str {
    if host == "localhost" || host.starts_with("127.") {
        "127.0.0.1"
    } else if host == "::1" {
        "[::1]"
    } else {
        "0.0.0.0"
    }
}

impl Node {
    /// Starts the node: its XML-RPC and TCPROS servers and the registration supervisor. It does
    /// not wait for the master; publications and subscriptions are registered once it answers.
    pub fn start(settings: &Ros1Settings) -> Result<Node, Ros1Error> {
        let setup = |what: &str, e: std::io::Error| Ros1Error::Setup {
            what: what.to_string(),
            reason: e.to_string(),
        };
        xmlrpc::split_uri(&settings.master_uri).map_err(|e| Ros1Error::Setup {
            what: "ros1.master_uri".into(),
            reason: e,
        })?;
        let bind = bind_host(&settings.host);
        let tcpros = TcpListener::bind((bind.trim_matches(|c| c == '[' || c == ']'), 0))
            .map_err(|e| setup("the TCPROS server", e))?;
        let tcpros_port = tcpros
            .local_addr()
            .map_err(|e| setup("the TCPROS server", e))?
            .port();
        // The XML-RPC handler needs the shared state, which needs the server's port: the
        // handler holds a weak reference filled in once both exist.
        let slot: Arc<Mutex<Weak<Shared>>> = Arc::new(Mutex::new(Weak::new()));
        let handler_slot = slot.clone();
        let server = xmlrpc::Server::start(
            &format!("{bind}:0"),
            Arc::new(move |method: &str, args: &[Value]| {
                let shared = handler_slot
                    .lock()
                    .map_err(|_| "node state poisoned".to_string())?
                    .upgrade()
                    .ok_or_else(|| "the node is shutting down".to_string())?;
                Ok(slave_api(&shared, method, args))
            }),
        )
        .map_err(|e| setup("the XML-RPC server", e))?;
        let host_in_uri = if settings.host.contains(':') && !settings.host.starts_with('[') {
            format!("[{}]", settings.host)
        } else {
            settings.host.clone()
        };
        let shared = Arc::new(Shared {
            name: settings.node_name.clone(),
            master_uri: settings.master_uri.clone(),
            host: settings.host.clone(),
            api_uri: format!("http://{host_in_uri}:{}/", server.port()),
            tcpros_port,
            pubs: Mutex::default(),
            subs: Mutex::default(),
            stop: AtomicBool::new(false),
            next_conn_id: AtomicU32::new(1),
        });
        *slot.lock().expect("fresh mutex") = Arc::downgrade(&shared);
        let mut threads = Vec::new();
        let s = shared.clone();
        tcpros
            .set_nonblocking(true)
            .map_err(|e| setup("the TCPROS server", e))?;
        threads.push(
            std::thread::Builder::new()
                .name("ros1-tcpros".into())
                .spawn(move || accept_loop(&s, tcpros))
                .map_err(|e| setup("a thread", e))?,
        );
        let s = shared.clone();
        threads.push(
            std::thread::Builder::new()
                .name("ros1-master".into())
                .spawn(move || supervise(&s))
                .map_err(|e| setup("a thread", e))?,
        );
        info!(
            node = %shared.name,
            api = %shared.api_uri,
            tcpros = tcpros_port,
            master = %shared.master_uri,
            "ROS 1 node started"
        );
        Ok(Node {
            shared,
            _xmlrpc: server,
            threads,
        })
    }

    /// The node's global name.
    pub fn name(&self) -> &str {
        &self.shared.name
    }

    /// The node's XML-RPC URI.
    pub fn api_uri(&self) -> &str {
        &self.shared.api_uri
    }

    /// Publishes `topic` with type `ty`; registered with the master as soon as it answers.
    pub fn advertise(&self, topic: &str, ty: MsgType) -> Result<Publisher, Ros1Error> {
        let mut pubs = self.shared.pubs.lock().map_err(|_| poisoned())?;
        if pubs.contains_key(topic) {
            return Err(Ros1Error::Setup {
                what: topic.to_string(),
                reason: "this node already publishes the topic".into(),
            });
        }
        let p = Arc::new(PubShared::new(topic, ty));
        pubs.insert(topic.to_string(), p.clone());
        Ok(Publisher::new(p, self.shared.clone()))
    }

    /// Subscribes to `topic` of type `ty`, keeping at most `queue` messages that the reader has
    /// not taken yet (the oldest is dropped and counted when a new one arrives).
    pub fn subscribe(
        &self,
        topic: &str,
        ty: MsgType,
        queue: usize,
    ) -> Result<Subscriber, Ros1Error> {
        let mut subs = self.shared.subs.lock().map_err(|_| poisoned())?;
        if subs.contains_key(topic) {
            return Err(Ros1Error::Setup {
                what: topic.to_string(),
                reason: "this node already subscribes to the topic".into(),
            });
        }
        let (s, sub) = Subscriber::new(topic, ty, queue, self.shared.clone());
        subs.insert(topic.to_string(), s);
        Ok(sub)
    }

    /// True while the master knows this node (every publication and subscription registered).
    pub fn is_registered(&self) -> bool {
        let pubs = self
            .shared
            .pubs
            .lock()
            .map(|p| p.values().all(|p| p.registered.load(Ordering::Relaxed)));
        let subs = self
            .shared
            .subs
            .lock()
            .map(|s| s.values().all(|s| s.registered.load(Ordering::Relaxed)));
        pubs.unwrap_or(false) && subs.unwrap_or(false)
    }
}

fn poisoned() -> Ros1Error {
    Ros1Error::Setup {
        what: "node".into(),
        reason: "internal state poisoned by a panic".into(),
    }
}

impl Drop for Node {
    fn drop(&mut self) {
        self.shared.stop.store(true, Ordering::Relaxed);
        unregister_all(&self.shared);
        for t in self.threads.drain(..) {
            let _ = t.join();
        }
        if let Ok(subs) = self.shared.subs.lock() {
            for s in subs.values() {
                s.close();
            }
        }
        if let Ok(pubs) = self.shared.pubs.lock() {
            for p in pubs.values() {
                p.close();
            }
        }
    }
}

/// Removes this node's registrations from the master (best effort, at shutdown).
fn unregister_all(s: &Shared) {
    let pubs: Vec<String> = s
        .pubs
        .lock()
        .map(|p| p.keys().cloned().collect())
        .unwrap_or_default();
    let subs: Vec<String> = s
        .subs
        .lock()
        .map(|p| p.keys().cloned().collect())
        .unwrap_or_default();
    for (method, topics) in [
        ("unregisterPublisher", pubs),
        ("unregisterSubscriber", subs),
    ] {
        for t in topics {
            if let Err(e) = s.master(method, &[t.clone().into(), s.api_uri.clone().into()]) {
                debug!("{method} {t}: {e}");
            }
        }
    }
}

/// The slave API.
fn slave_api(s: &Arc<Shared>, method: &str, args: &[Value]) -> Value {
    let arg = |i: usize| args.get(i).and_then(Value::as_str).unwrap_or("");
    match method {
        "getPid" => ok((std::process::id() as i32).into()),
        "getMasterUri" => ok(s.master_uri.clone().into()),
        "getBusStats" => ok(Value::Array(vec![
            Value::Array(vec![]),
            Value::Array(vec![]),
            Value::Array(vec![]),
        ])),
        "getBusInfo" => {
            let mut rows = Vec::new();
            if let Ok(pubs) = s.pubs.lock() {
                for p in pubs.values() {
                    rows.extend(p.bus_info());
                }
            }
            if let Ok(subs) = s.subs.lock() {
                for sub in subs.values() {
                    rows.extend(sub.bus_info());
                }
            }
            ok(Value::Array(rows))
        }
        "getPublications" => {
            let list = s.pubs.lock().map(|p| {
                p.values()
                    .map(|p| topic_and_type(&p.topic, p.ty.name))
                    .collect()
            });
            ok(Value::Array(list.unwrap_or_default()))
        }
        "getSubscriptions" => {
            let list = s.subs.lock().map(|p| {
                p.values()
                    .map(|p| topic_and_type(&p.topic, p.ty.name))
                    .collect()
            });
            ok(Value::Array(list.unwrap_or_default()))
        }
        "paramUpdate" => ok(0.into()),
        "shutdown" => {
            warn!(
                "the ROS master asks node {} to shut down ({}): another node registered with the same name; this bridge keeps running but that node now owns the name",
                s.name,
                arg(1)
            );
            ok(0.into())
        }
        "publisherUpdate" => publisher_update(s, arg(1), args.get(2)),
        "requestTopic" => request_topic(s, arg(1), args.get(2)),
        other => Value::Array(vec![
            (-1).into(),
            format!("method `{other}` is not supported").into(),
            0.into(),
        ]),
    }
}

/// A successful slave API reply carrying `v`.
fn ok(v: Value) -> Value {
    Value::Array(vec![1.into(), "".into(), v])
}

/// A `[topic, type]` pair of `getPublications` / `getSubscriptions`.
fn topic_and_type(topic: &str, ty: &str) -> Value {
    Value::Array(vec![topic.to_string().into(), ty.into()])
}

/// `publisherUpdate`: the master's current publishers of `topic` (`uris`), for our subscription.
fn publisher_update(s: &Arc<Shared>, topic: &str, uris: Option<&Value>) -> Value {
    let uris: Vec<String> = uris
        .and_then(Value::as_array)
        .map(|a| {
            a.iter()
                .filter_map(|v| v.as_str().map(str::to_string))
                .collect()
        })
        .unwrap_or_default();
    let sub = s.subs.lock().ok().and_then(|m| m.get(topic).cloned());
    match sub {
        Some(sub) => {
            sub.update_publishers(&uris, s);
            ok(0.into())
        }
        None => Value::Array(vec![
            0.into(),
            format!("not subscribed to [{topic}]").into(),
            0.into(),
        ]),
    }
}

/// `requestTopic`: where a subscriber connects for `topic`, if we publish it and it offers
/// TCPROS among `protocols`.
fn request_topic(s: &Arc<Shared>, topic: &str, protocols: Option<&Value>) -> Value {
    let publishes = s.pubs.lock().is_ok_and(|p| p.contains_key(topic));
    let tcpros = protocols.and_then(Value::as_array).is_some_and(|a| {
        a.iter()
            .any(|p| p.as_array().and_then(|p| p.first()).and_then(Value::as_str) == Some("TCPROS"))
    });
    if !publishes {
        Value::Array(vec![
            (-1).into(),
            format!("Not a publisher of [{topic}]").into(),
            Value::Array(vec![]),
        ])
    } else if !tcpros {
        Value::Array(vec![
            0.into(),
            "no supported protocol implementations".into(),
            Value::Array(vec![]),
        ])
    } else {
        Value::Array(vec![
            1.into(),
            format!("ready on {}:{}", s.host, s.tcpros_port).into(),
            Value::Array(vec![
                "TCPROS".into(),
                s.host.clone().into(),
                (s.tcpros_port as i32).into(),
            ]),
        ])
    }
}

/// Accepts TCPROS connections from subscribers and hands each to its publication.
fn accept_loop(s: &Arc<Shared>, listener: TcpListener) {
    while !s.stopped() {
        match listener.accept() {
            Ok((stream, peer)) => {
                let s = s.clone();
                let _ = std::thread::Builder::new()
                    .name("ros1-link-out".into())
                    .spawn(move || {
                        if let Err(e) = serve_subscriber(&s, stream) {
                            debug!(%peer, "TCPROS connection refused: {e}");
                        }
                    });
            }
            Err(e) if e.kind() == std::io::ErrorKind::WouldBlock => {
                std::thread::sleep(Duration::from_millis(20));
            }
            Err(e) => {
                warn!("TCPROS server: accept failed: {e}");
                std::thread::sleep(Duration::from_millis(100));
            }
        }
    }
}

/// Reads a subscriber's header, answers it (or refuses it with an `error` header) and serves
/// it the publication's messages until it goes.
fn serve_subscriber(s: &Arc<Shared>, stream: TcpStream) -> Result<(), String> {
    stream.set_nonblocking(false).map_err(|e| e.to_string())?;
    stream
        .set_read_timeout(Some(Duration::from_secs(5)))
        .map_err(|e| e.to_string())?;
    let mut r = &stream;
    let h = tcpros::read_header(&mut r).map_err(|e| format!("reading the header: {e}"))?;
    let refuse = |msg: String| -> Result<(), String> {
        let mut w = &stream;
        let _ = std::io::Write::write_all(&mut w, &tcpros::encode_header(&[("error", &msg)]));
        Err(msg)
    };
    if h.contains_key("service") {
        return refuse("this node offers no services".into());
    }
    let topic = h.get("topic").cloned().unwrap_or_default();
    let caller = h.get("callerid").cloned().unwrap_or_default();
    let Some(p) = s.pubs.lock().ok().and_then(|m| m.get(&topic).cloned()) else {
        return refuse(format!("{} does not publish [{topic}]", s.name));
    };
    let md5 = h.get("md5sum").map(String::as_str).unwrap_or("");
    let ty = h.get("type").map(String::as_str).unwrap_or("");
    if md5 != "*" && md5 != p.ty.md5sum {
        let msg = if !ty.is_empty() && ty != "*" && ty != p.ty.name {
            format!("topic types do not match: [{ty}] vs. [{}]", p.ty.name)
        } else {
            format!(
                "Client [{caller}] wants topic [{topic}] to have datatype/md5sum [{ty}/{md5}], but our version has [{}/{}]. Dropping connection.",
                p.ty.name, p.ty.md5sum
            )
        };
        warn!("{topic}: {msg}");
        return refuse(msg);
    }
    let reply = tcpros::encode_header(&[
        ("callerid", &s.name),
        ("topic", &topic),
        ("type", p.ty.name),
        ("md5sum", p.ty.md5sum),
        ("message_definition", p.ty.definition),
        ("latching", "0"),
    ]);
    let mut w = &stream;
    std::io::Write::write_all(&mut w, &reply).map_err(|e| format!("answering: {e}"))?;
    if h.get("tcp_nodelay").is_some_and(|v| v == "1") {
        let _ = stream.set_nodelay(true);
    }
    let _ = stream.set_read_timeout(None);
    let id = s.next_conn_id.fetch_add(1, Ordering::Relaxed);
    p.serve(id, caller, stream, s);
    Ok(())
}

/// Keeps the registrations with the master; see the module documentation.
fn supervise(s: &Arc<Shared>) {
    let mut master_up = false;
    let mut waiting_since: Option<Instant> = None;
    let mut warned_at: Option<Instant> = None;
    let mut last_check = Instant::now();
    let mut name_taken = false;
    while !s.stopped() {
        let pending = register_pending(s);
        match pending {
            Ok(n) => {
                if !master_up {
                    master_up = true;
                    if waiting_since.take().is_some() || n > 0 {
                        info!(master = %s.master_uri, "registered {n} topic(s) with the ROS master");
                    }
                }
            }
            Err(e) => {
                if master_up {
                    warn!(master = %s.master_uri, "lost the ROS master ({e}); waiting for it");
                }
                master_up = false;
                mark_unregistered(s);
                let since = *waiting_since.get_or_insert_with(Instant::now);
                if warned_at.is_none_or(|t| t.elapsed() >= Duration::from_secs(30)) {
                    warn!(
                        master = %s.master_uri,
                        "waiting for the ROS master ({e}; {:.0} s so far)",
                        since.elapsed().as_secs_f64()
                    );
                    warned_at = Some(Instant::now());
                }
            }
        }
        if master_up && last_check.elapsed() >= Duration::from_secs(1) {
            last_check = Instant::now();
            match s.master("lookupNode", &[s.name.clone().into()]) {
                Ok(v) if v.as_str() == Some(s.api_uri.as_str()) => name_taken = false,
                Ok(v) => {
                    if !name_taken {
                        error!(
                            "the ROS master says node {} is at {:?}, not at this bridge ({}): another node took the name; give this bridge another [ros1] node_name",
                            s.name, v, s.api_uri
                        );
                        name_taken = true;
                    }
                }
                Err(e) if e.starts_with("lookupNode: code") => {
                    info!(master = %s.master_uri, "the ROS master no longer knows this node (it was restarted): registering again");
                    mark_unregistered(s);
                }
                Err(e) => {
                    warn!(master = %s.master_uri, "lost the ROS master ({e}); waiting for it");
                    master_up = false;
                    mark_unregistered(s);
                    waiting_since = Some(Instant::now());
                    warned_at = Some(Instant::now());
                }
            }
        }
        sleep_unless_stopped(s, Duration::from_millis(100));
    }
}

fn sleep_unless_stopped(s: &Shared, d: Duration) {
    let end = Instant::now() + d;
    while !s.stopped() && Instant::now() < end {
        std::thread::sleep(Duration::from_millis(20).min(end - Instant::now()));
    }
}

fn mark_unregistered(s: &Shared) {
    if let Ok(p) = s.pubs.lock() {
        p.values()
            .for_each(|p| p.registered.store(false, Ordering::Relaxed));
    }
    if let Ok(p) = s.subs.lock() {
        p.values()
            .for_each(|p| p.registered.store(false, Ordering::Relaxed));
    }
}

/// Registers every publication and subscription the master does not know yet; returns how many
/// it registered, or the error of the first call that failed.
fn register_pending(s: &Arc<Shared>) -> Result<usize, String> {
    let pubs: Vec<Arc<PubShared>> = s
        .pubs
        .lock()
        .map_err(|_| "poisoned".to_string())?
        .values()
        .filter(|p| !p.registered.load(Ordering::Relaxed))
        .cloned()
        .collect();
    let subs: Vec<Arc<SubShared>> = s
        .subs
        .lock()
        .map_err(|_| "poisoned".to_string())?
        .values()
        .filter(|p| !p.registered.load(Ordering::Relaxed))
        .cloned()
        .collect();
    let mut n = 0;
    if pubs.is_empty() && subs.is_empty() {
        // Nothing to register: just check the master answers.
        s.master("getUri", &[])?;
        return Ok(0);
    }
    for p in pubs {
        s.master(
            "registerPublisher",
            &[
                p.topic.clone().into(),
                p.ty.name.into(),
                s.api_uri.clone().into(),
            ],
        )?;
        p.registered.store(true, Ordering::Relaxed);
        debug!(topic = %p.topic, "registered publisher");
        n += 1;
    }
    for sub in subs {
        let v = s.master(
            "registerSubscriber",
            &[
                sub.topic.clone().into(),
                sub.ty.name.into(),
                s.api_uri.clone().into(),
            ],
        )?;
        sub.registered.store(true, Ordering::Relaxed);
        let uris: Vec<String> = v
            .as_array()
            .map(|a| {
                a.iter()
                    .filter_map(|v| v.as_str().map(str::to_string))
                    .collect()
            })
            .unwrap_or_default();
        debug!(topic = %sub.topic, publishers = uris.len(), "registered subscriber");
        sub.update_publishers(&uris, s);
        n += 1;
    }
    Ok(n)
}
