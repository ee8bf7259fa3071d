//! The kill switch from the vehicle: a topic (`std_msgs/Bool`, or any message read by field
//! path, like the autonomy stack's engage or takeover state) that, when it says so, returns every
//! stream to raw frames from the next frame on, and keeps them so until a person arms the
//! daemon again (`perturb ctl arm`).
//!
//! When the topic's field equals `kill_when` (or differs from `kill_unless`), or, with
//! `deadman_s`, when its publisher goes silent for that long or disappears after it was seen:
//! 1. the bridge's own latch is set at once: every guarded egress publishes raw frames from its
//!    next frame, without waiting for the daemon (see [`crate::guard`]);
//! 2. the daemon's kill switch is engaged over its control channel (`perturb ctl off --all`),
//!    retried until it answers, so it stays engaged across restarts of either process;
//! 3. a `kill` record goes on the events channel.
//!
//! The bridge's latch is released only when the daemon says it was armed again and the topic no
//! longer says kill (a condition that still holds engages it again at once).

use crate::adapter::{Adapter, Control, POLL};
use crate::bus::Bus;
use crate::daemon_link::DaemonLink;
use crate::events::EventsHub;
use crate::frame::wall_ns;
use crate::guard::LocalKill;
use crate::msgs::{FieldReader, SmallEndpoint};
use crate::stats::{AdapterReport, log_bad};
use anyhow::{Context, Result};
use perturb_bag::dynamic::Value;
use perturb_bag::events::EventRecord;
use perturb_wire::TransportOptions;
use perturb_wire::control::ControlRequest;
use std::sync::Arc;
use std::time::{Duration, Instant};

/// What the kill topic's field is compared with.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(untagged)]
pub enum Expected {
    /// `true` / `false`.
    Bool(bool),
    /// An integer or a float (an enum's value).
    Number(f64),
    /// A string.
    Text(String),
}

impl Expected {
    /// True if `v` equals this value.
    pub fn matches(&self, v: &Value) -> bool {
        match self {
            Expected::Bool(b) => v.as_bool() == Some(*b),
            Expected::Number(n) => v.as_f64() == Some(*n),
            Expected::Text(t) => v.as_str() == Some(t.as_str()),
        }
    }
}

/// When the kill switch engages.
#[derive(Clone, Debug, PartialEq)]
pub enum Rule {
    /// When the field equals this value (`kill_when = true` for a takeover flag).
    When(Expected),
    /// When the field differs from this value (`kill_unless = true` for an engage flag).
    Unless(Expected),
}

impl Rule {
    /// True if `v` says kill.
    pub fn kills(&self, v: &Value) -> bool {
        match self {
            Rule::When(e) => e.matches(v),
            Rule::Unless(e) => !e.matches(v),
        }
    }
}

/// The kill switch watcher.
pub struct KillWatch {
    /// The topic.
    pub topic: String,
    /// Its ROS 2 type (ROS 1: the publisher says).
    pub ros2_type: String,
    /// The field path read.
    pub field: String,
    /// Its definition, for a ROS 2 type the bridge does not know.
    pub definition: Option<String>,
    /// When it kills.
    pub rule: Rule,
    /// Dead-man: kill when the topic goes silent this long, or its publisher disappears.
    pub deadman: Option<Duration>,
    /// Where the topic is read.
    pub endpoint: SmallEndpoint,
    /// The bridge's latch.
    pub latch: Arc<LocalKill>,
    /// Where kill records go.
    pub events: Option<Arc<EventsHub>>,
    /// The daemon's namespace and control service.
    pub iox2: TransportOptions,
    /// The daemon's control service.
    pub control_service: String,
}

impl Adapter for KillWatch {
    fn name(&self) -> String {
        let t = self.endpoint.prefix();
        format!("kill switch <- {t}{}", self.topic)
    }

    fn is_sink(&self) -> bool {
        true
    }

    fn run(self: Box<Self>, _bus: &dyn Bus, mut ctl: Control) -> Result<AdapterReport> {
        let name = self.name();
        let mut reader = self
            .endpoint
            .reader(&self.topic, &self.ros2_type, crate::dds::Qos::default(), 16)
            .with_context(|| format!("the kill switch topic {}", self.topic))?;
        ctl.ready();
        let mut rep = AdapterReport {
            name: name.clone(),
            ..Default::default()
        };
        let mut field = FieldReader::new(&self.field, self.definition.clone());
        let mut daemon = DaemonLink::new(&self.iox2, &self.control_service, "kill");
        let mut last_msg: Option<Instant> = None;
        let mut publisher_seen = false;
        // What the topic says now (None: nothing yet), and why.
        let mut says_kill: Option<String> = None;
        // The daemon acknowledged the kill.
        let mut daemon_killed = false;
        let mut last_status = Instant::now();
        while !ctl.stopped() {
            let mut latest: Option<Value> = None;
            let r = reader.take(POLL.min(Duration::from_millis(20)), &mut |m| {
                rep.received += 1;
                match field.read(&m) {
                    Ok(v) => latest = Some(v),
                    Err(e) => {
                        rep.bad += 1;
                        log_bad(&name, rep.bad, &e);
                    }
                }
            });
            if let Err(e) = r {
                rep.failed += 1;
                log_bad(&name, rep.failed, &e);
            }
            let now = Instant::now();
            if let Some(v) = latest {
                last_msg = Some(now);
                says_kill = self
                    .rule
                    .kills(&v)
                    .then(|| format!("kill topic {}: {} = {v:?}", self.topic, self.field));
            }
            if reader.publishers().is_some_and(|n| n > 0) {
                publisher_seen = true;
            }
            // The dead man's condition, afresh each time round.
            let deadman = self.deadman.and_then(|d| {
                if last_msg.is_some_and(|t| now.duration_since(t) >= d) {
                    Some(format!(
                        "dead man: kill topic {} silent for {:.2} s",
                        self.topic,
                        d.as_secs_f64()
                    ))
                } else if publisher_seen && reader.publishers() == Some(0) {
                    Some(format!(
                        "dead man: the publisher of kill topic {} went away",
                        self.topic
                    ))
                } else {
                    None
                }
            });
            let kill_now = says_kill.clone().or(deadman);
            if let Some(why) = &kill_now {
                if !self.latch.engaged() {
                    self.latch.set(true);
                    rep.forwarded += 1;
                    tracing::warn!(
                        "{name}: kill switch engaged ({why}): every stream passes raw frames until `perturb ctl arm`"
                    );
                    if let Some(ev) = &self.events {
                        ev.send(EventRecord::kill(true, why, wall_ns()));
                    }
                    daemon_killed = false;
                }
                if !daemon_killed {
                    match daemon.request(&ControlRequest::Kill {
                        reason: Some(why.clone()),
                    }) {
                        Ok(r) if r.ok => daemon_killed = true,
                        Ok(r) => log_bad(&name, 1, &r.error.unwrap_or_default()),
                        Err(e) => {
                            tracing::debug!("{name}: the daemon did not take the kill yet: {e:#}")
                        }
                    }
                }
            }
            // Released only by an arm of the daemon, and only once the topic no longer says
            // kill (armed while it still does: the daemon is engaged again).
            if self.latch.engaged()
                && daemon_killed
                && now.duration_since(last_status) >= Duration::from_millis(250)
            {
                last_status = now;
                if let Ok(r) = daemon.request(&ControlRequest::Status)
                    && r.ok
                    && r.killed.is_none()
                {
                    if kill_now.is_none() {
                        self.latch.set(false);
                        tracing::warn!(
                            "{name}: the daemon was armed again: the kill switch is released"
                        );
                        if let Some(ev) = &self.events {
                            ev.send(EventRecord::kill(false, "perturb ctl arm", wall_ns()));
                        }
                    } else {
                        daemon_killed = false;
                    }
                }
            }
        }
        Ok(rep)
    }
}
