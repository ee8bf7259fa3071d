//! The vehicle's position for the daemon's campaign: the bridge reads the pose topic (any type
//! with a position, read by field path: `PoseStamped`, `Odometry`, ...) and sends each position
//! to `perturbd`, which switches the campaign's route and geofence steps on it. Positions are
//! sent as they come, at most `max_rate_hz` a second (the latest wins).

use crate::adapter::{Adapter, Control, POLL};
use crate::bus::Bus;
use crate::daemon_link::DaemonLink;
use crate::msgs::{SmallEndpoint, SmallMsg};
use crate::stats::{AdapterReport, log_bad};
use anyhow::{Context, Result};
use perturb_bag::dynamic::{FieldPath, MessageCodec};
use perturb_wire::TransportOptions;
use perturb_wire::control::ControlRequest;
use std::time::{Duration, Instant};

/// The pose forwarder.
pub struct PoseFeed {
    /// The topic.
    pub topic: String,
    /// Its ROS 2 type (ROS 1: the publisher says).
    pub ros2_type: String,
    /// The position's field path (default: found from the type).
    pub field: Option<String>,
    /// The type's definition, for a ROS 2 type the bridge does not know.
    pub definition: Option<String>,
    /// At most this many positions a second go to the daemon.
    pub max_rate_hz: f64,
    /// Where the topic is read.
    pub endpoint: SmallEndpoint,
    /// The daemon's namespace.
    pub iox2: TransportOptions,
    /// The daemon's control service.
    pub control_service: String,
}

/// Reads x and y of messages of one type at a time.
struct Position {
    ty: String,
    codec: MessageCodec,
    x: FieldPath,
    y: FieldPath,
}

impl PoseFeed {
    fn position(&self, m: &SmallMsg<'_>, cached: &mut Option<Position>) -> Result<[f64; 2]> {
        if cached.as_ref().is_none_or(|p| p.ty != m.type_name) {
            let def = m
                .definition
                .filter(|d| !d.is_empty())
                .map(str::to_string)
                .or_else(|| self.definition.clone())
                .with_context(|| format!("no definition of `{}`", m.type_name))?;
            let (dialect, enc) = match m.wire {
                crate::msgs::Wire::Ros1 => ("ros1msg", "ros1"),
                crate::msgs::Wire::Cdr => ("ros2msg", "cdr"),
            };
            let codec = MessageCodec::new(m.type_name, dialect, def.as_bytes(), enc)?;
            let base = match &self.field {
                Some(f) => f.trim_end_matches(".x").to_string(),
                None => perturb_bag::dynamic::position_path(&codec).with_context(|| {
                    format!(
                        "cannot tell where the position is in `{}`: give [pose] field",
                        m.type_name
                    )
                })?,
            };
            let x = codec.path(&format!("{base}.x"))?;
            let y = codec.path(&format!("{base}.y"))?;
            *cached = Some(Position {
                ty: m.type_name.to_string(),
                codec,
                x,
                y,
            });
        }
        let p = cached.as_ref().expect("set above");
        Ok([
            p.codec.get_f64(m.data, &p.x)?,
            p.codec.get_f64(m.data, &p.y)?,
        ])
    }
}

impl Adapter for PoseFeed {
    fn name(&self) -> String {
        let t = self.endpoint.prefix();
        format!("pose <- {t}{} -> perturbd", self.topic)
    }

    fn is_sink(&self) -> bool {
        true
    }

    fn run(self: Box<Self>, _bus: &dyn Bus, mut ctl: Control) -> Result<AdapterReport> {
        let name = self.name();
        let mut reader = self
            .endpoint
            .reader(&self.topic, &self.ros2_type, crate::dds::Qos::default(), 8)
            .with_context(|| format!("the pose topic {}", self.topic))?;
        ctl.ready();
        let mut rep = AdapterReport {
            name: name.clone(),
            ..Default::default()
        };
        let mut daemon = DaemonLink::new(&self.iox2, &self.control_service, "pose");
        let mut cached = None;
        let min_gap = Duration::from_secs_f64(1.0 / self.max_rate_hz.max(0.1));
        let mut last_sent: Option<Instant> = None;
        let mut pending: Option<[f64; 2]> = None;
        while !ctl.stopped() {
            let r = reader.take(POLL.min(Duration::from_millis(20)), &mut |m| {
                rep.received += 1;
                match self.position(&m, &mut cached) {
                    Ok(p) => pending = Some(p),
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
            if let Some([x, y]) = pending
                && last_sent.is_none_or(|t| t.elapsed() >= min_gap)
            {
                match daemon.request(&ControlRequest::Pose { x, y }) {
                    Ok(r) if r.ok => {
                        rep.forwarded += 1;
                        pending = None;
                        last_sent = Some(Instant::now());
                    }
                    Ok(r) => {
                        rep.failed += 1;
                        log_bad(&name, rep.failed, &r.error.unwrap_or_default());
                        pending = None;
                    }
                    Err(e) => {
                        // No daemon now: the next position goes when it is back.
                        rep.failed += 1;
                        if rep.failed == 1 || rep.failed.is_multiple_of(100) {
                            tracing::warn!("{name}: the daemon does not take positions: {e:#}");
                        }
                        pending = None;
                    }
                }
            }
        }
        Ok(rep)
    }
}
