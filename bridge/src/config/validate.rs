//! Checking a [`Config`] before anything starts: one validator per section, in file order, each
//! naming the key at fault.

use super::{
    Config, ConfigError, MAX_PRERENDER_BYTES, MAX_SYNTHETIC_FRAME_BYTES, SyntheticCamera,
    Transport, prerender_that_fits, synthetic_frame_bytes,
};
use crate::dds::Qos;
use std::collections::BTreeSet;

/// What is wrong, and where: (key, problem).
type Problem = (String, String);

/// The (transport, topic) pairs a section reads or writes.
type Topics = BTreeSet<(Transport, String)>;

impl Config {
    /// Checks everything that can be checked before starting; errors name the key.
    pub fn validate(&self, file: &str) -> Result<(), ConfigError> {
        self.check().map_err(|(key, problem)| ConfigError {
            file: file.to_string(),
            key,
            problem,
        })
    }

    fn check(&self) -> Result<(), Problem> {
        self.check_bridge()?;
        // Streams fed by a source (ingress, replay, synthetic sensors): one source each.
        let mut sourced = BTreeSet::new();
        let ingress_topics = self.check_ingress(&mut sourced)?;
        let egress_topics = self.check_egress(&ingress_topics)?;
        self.check_replay(&mut sourced)?;
        self.check_synthetic(&mut sourced)?;
        self.check_record()?;
        self.check_camera_info(&ingress_topics, &egress_topics)?;
        self.check_events(&ingress_topics, &egress_topics)?;
        self.check_kill()?;
        self.check_pose()?;
        self.check_view()?;
        self.check_ros1(&egress_topics)?;
        self.check_not_empty()
    }

    /// `[bridge]` and `[dds] interfaces` (when any DDS topic is configured).
    fn check_bridge(&self) -> Result<(), Problem> {
        if let Some(t) = self.bridge.stop_after_publishers_gone
            && !(t.is_finite() && t > 0.0 && t <= 86_400.0)
        {
            return Err((
                "bridge.stop_after_publishers_gone".into(),
                format!("{t} must be a number of seconds in (0, 86400]"),
            ));
        }
        self.bridge
            .qos
            .validate()
            .map_err(|e| ("bridge.qos".to_string(), e))?;
        if let Some(r) = &self.bridge.report {
            check_parent("bridge.report", r)?;
        }
        if !self.ingress.is_empty() || !self.egress.is_empty() {
            crate::dds::interfaces::resolve(&self.dds.interfaces).map_err(|e| {
                let problem = match e {
                    crate::dds::DdsError::Setup { reason, .. } => reason,
                    other => other.to_string(),
                };
                ("dds.interfaces".to_string(), problem)
            })?;
        }
        Ok(())
    }

    /// `[[ingress]]`: valid names, each topic read once, each stream fed once. Returns the
    /// topics read.
    fn check_ingress(&self, sourced: &mut BTreeSet<String>) -> Result<Topics, Problem> {
        let mut topics = BTreeSet::new();
        for (i, e) in self.ingress.iter().enumerate() {
            check_topic(format!("ingress[{i}].topic"), &e.topic)?;
            check_stream(format!("ingress[{i}].stream"), &e.stream)?;
            check_qos(format!("ingress[{i}].qos.depth"), &e.qos)?;
            if !topics.insert((e.transport, e.topic.clone())) {
                return Err((
                    format!("ingress[{i}].topic"),
                    format!("`{}` is read twice", e.topic),
                ));
            }
            claim_source(sourced, format!("ingress[{i}].stream"), &e.stream)?;
        }
        Ok(topics)
    }

    /// `[[egress]]`: valid names, no topic read back or written twice, a known kind for every
    /// stream. Returns the topics written.
    fn check_egress(&self, ingress_topics: &Topics) -> Result<Topics, Problem> {
        let kinds = self.source_kinds();
        let mut topics = BTreeSet::new();
        for (i, e) in self.egress.iter().enumerate() {
            check_topic(format!("egress[{i}].topic"), &e.topic)?;
            check_stream(format!("egress[{i}].stream"), &e.stream)?;
            check_qos(format!("egress[{i}].qos.depth"), &e.qos)?;
            if ingress_topics.contains(&(e.transport, e.topic.clone())) {
                return Err((
                    format!("egress[{i}].topic"),
                    format!(
                        "`{}` is also an ingress topic: the bridge would read its own output",
                        e.topic
                    ),
                ));
            }
            if !topics.insert((e.transport, e.topic.clone())) {
                return Err((
                    format!("egress[{i}].topic"),
                    format!("`{}` is written twice", e.topic),
                ));
            }
            // A replayed stream's kind is known once the bag is open.
            let replayed = self
                .replay
                .as_ref()
                .is_some_and(|r| r.topics.is_empty() || r.topics.values().any(|s| s == &e.stream));
            if e.kind.is_none() && !kinds.contains_key(&e.stream) && !replayed {
                return Err((
                    format!("egress[{i}].kind"),
                    format!(
                        "no source in this file feeds stream `{}`: say `kind = \"image\"` or `\"cloud\"`",
                        e.stream
                    ),
                ));
            }
        }
        Ok(topics)
    }

    /// `[replay]`: rate and offset, and the streams its topics feed.
    fn check_replay(&self, sourced: &mut BTreeSet<String>) -> Result<(), Problem> {
        let Some(r) = &self.replay else {
            return Ok(());
        };
        if !(r.rate >= 0.0 && r.rate.is_finite()) {
            return Err((
                "replay.rate".into(),
                format!("{} must be >= 0 (0 = as fast as possible)", r.rate),
            ));
        }
        if !(r.start_offset >= 0.0 && r.start_offset.is_finite()) {
            return Err((
                "replay.start_offset".into(),
                format!("{} must be >= 0 seconds", r.start_offset),
            ));
        }
        for (t, s) in &r.topics {
            check_stream(format!("replay.topics.\"{t}\""), s)?;
            claim_source(sourced, format!("replay.topics.\"{t}\""), s)?;
        }
        Ok(())
    }

    /// `[synthetic]`: the cameras' sizes, memory and rates, the LiDARs' rates.
    fn check_synthetic(&self, sourced: &mut BTreeSet<String>) -> Result<(), Problem> {
        for (i, c) in self.synthetic.camera.iter().enumerate() {
            let key = |field: &str| format!("synthetic.camera[{i}].{field}");
            check_stream(key("stream"), &c.stream)?;
            check_frame_id(key("frame_id"), &c.frame_id)?;
            claim_source(sourced, key("stream"), &c.stream)?;
            check_synthetic_camera(c).map_err(|(field, problem)| (key(&field), problem))?;
        }
        for (i, l) in self.synthetic.lidar.iter().enumerate() {
            check_stream(format!("synthetic.lidar[{i}].stream"), &l.stream)?;
            check_frame_id(format!("synthetic.lidar[{i}].frame_id"), &l.frame_id)?;
            claim_source(sourced, format!("synthetic.lidar[{i}].stream"), &l.stream)?;
            if !(l.rate_hz > 0.0 && l.rate_hz <= 100.0) {
                return Err((
                    format!("synthetic.lidar[{i}].rate_hz"),
                    format!("{} must be in (0, 100]", l.rate_hz),
                ));
            }
        }
        Ok(())
    }

    /// `[record]`: streams listed once, something to record, a known format and compression.
    fn check_record(&self) -> Result<(), Problem> {
        let Some(r) = &self.record else {
            return Ok(());
        };
        if r.streams.is_empty() {
            return Err(("record.streams".into(), "is empty".into()));
        }
        let mut seen = BTreeSet::new();
        for (i, s) in r.streams.iter().enumerate() {
            check_stream(format!("record.streams[{i}]"), s)?;
            if !seen.insert(s) {
                return Err((
                    format!("record.streams[{i}]"),
                    format!("stream `{s}` is listed twice (every frame would be recorded twice)"),
                ));
            }
        }
        if !r.raw && !r.perturbed {
            return Err((
                "record.raw".into(),
                "both `raw` and `perturbed` are false: nothing to record".into(),
            ));
        }
        if let Some(t) = r.seconds
            && !(t > 0.0 && t.is_finite())
        {
            return Err((
                "record.seconds".into(),
                format!("{t} must be a positive number of seconds"),
            ));
        }
        let format = match &r.format {
            Some(f) => f
                .parse::<perturb_bag::BagFormat>()
                .map_err(|e| ("record.format".to_string(), e))?,
            None => perturb_bag::BagFormat::default(),
        };
        if let Some(c) = &r.compression {
            perturb_bag::check_compression(format, c)
                .map_err(|e| ("record.compression".to_string(), e))?;
        }
        Ok(())
    }

    /// The deadlines of `[[egress]]` entries.
    fn check_deadline(i: usize, e: &super::EgressEntry) -> Result<(), Problem> {
        if let Some(d) = e.deadline_ms
            && !(d.is_finite() && d > 0.0 && d <= 10_000.0)
        {
            return Err((
                format!("egress[{i}].deadline_ms"),
                format!("{d} must be in (0, 10000] milliseconds"),
            ));
        }
        if let Some(r) = e.rate_hz
            && !(r.is_finite() && r > 0.0 && r <= 1000.0)
        {
            return Err((
                format!("egress[{i}].rate_hz"),
                format!("{r} must be in (0, 1000] frames per second"),
            ));
        }
        Ok(())
    }

    /// `camera_info` on ingress and egress entries: valid topics, each sink fed by an ingress
    /// of the same stream on the same transport, no topic read or written twice.
    fn check_camera_info(
        &self,
        ingress_topics: &Topics,
        egress_topics: &Topics,
    ) -> Result<(), Problem> {
        let mut read = ingress_topics.clone();
        for (i, e) in self.ingress.iter().enumerate() {
            let Some(t) = &e.camera_info else { continue };
            let key = format!("ingress[{i}].camera_info");
            check_topic(key.clone(), t)?;
            if e.ros_type == crate::dds::RosType::PointCloud2 {
                return Err((key, "a point cloud stream has no camera_info".into()));
            }
            if !read.insert((e.transport, t.clone())) {
                return Err((key, format!("`{t}` is read twice")));
            }
        }
        let mut written = egress_topics.clone();
        for (i, e) in self.egress.iter().enumerate() {
            Self::check_deadline(i, e)?;
            let Some(t) = &e.camera_info else { continue };
            let key = format!("egress[{i}].camera_info");
            check_topic(key.clone(), t)?;
            let source = self
                .ingress
                .iter()
                .find(|g| g.stream == e.stream && g.camera_info.is_some());
            match source {
                None => {
                    return Err((
                        key,
                        format!(
                            "no [[ingress]] of stream `{}` names the camera_info to relay (add `camera_info = \"<the driver's camera_info topic>\"` to it)",
                            e.stream
                        ),
                    ));
                }
                Some(g) if g.transport != e.transport => {
                    return Err((
                        key,
                        "camera_info is relayed unchanged, so its source and sink must be on the same transport (both ROS 1 or both ROS 2)".into(),
                    ));
                }
                Some(_) => {}
            }
            if read.contains(&(e.transport, t.clone())) {
                return Err((
                    key,
                    format!("`{t}` is also read by this bridge: it would read its own output"),
                ));
            }
            if !written.insert((e.transport, t.clone())) {
                return Err((key, format!("`{t}` is written twice")));
            }
        }
        Ok(())
    }

    /// `[events]`: a valid topic nobody else reads or writes here.
    fn check_events(&self, ingress_topics: &Topics, egress_topics: &Topics) -> Result<(), Problem> {
        let (Some(e), Some(transport)) = (&self.events, self.events_transport()) else {
            return Ok(());
        };
        check_topic("events.topic".into(), &e.topic)?;
        let pair = (transport, e.topic.clone());
        if ingress_topics.contains(&pair) || egress_topics.contains(&pair) {
            return Err((
                "events.topic".into(),
                format!("`{}` is also an ingress or egress topic", e.topic),
            ));
        }
        Ok(())
    }

    /// `[kill]`: a valid topic, one rule, a usable dead-man time, a definition for an unknown
    /// ROS 2 type.
    fn check_kill(&self) -> Result<(), Problem> {
        let (Some(k), Some(transport)) = (&self.kill, self.kill_transport()) else {
            return Ok(());
        };
        check_topic("kill.topic".into(), &k.topic)?;
        if k.kill_when.is_some() && k.kill_unless.is_some() {
            return Err((
                "kill.kill_unless".into(),
                "give `kill_when` or `kill_unless`, not both".into(),
            ));
        }
        if let Some(d) = k.deadman_s
            && !(d.is_finite() && d > 0.0 && d <= 3600.0)
        {
            return Err((
                "kill.deadman_s".into(),
                format!("{d} must be in (0, 3600] seconds"),
            ));
        }
        if transport == Transport::Dds {
            let def = match &k.definition {
                Some(d) => d.clone(),
                None => crate::msgs::ros2_definition(&k.ros2_type).ok_or_else(|| {
                    (
                        "kill.definition".to_string(),
                        format!(
                            "the bridge does not know the ROS 2 type `{}`: give its definition (the .msg text with its dependencies)",
                            k.ros2_type
                        ),
                    )
                })?,
            };
            let codec = perturb_bag::dynamic::MessageCodec::new(
                &k.ros2_type,
                "ros2msg",
                def.as_bytes(),
                "cdr",
            )
            .map_err(|e| ("kill.definition".to_string(), e.to_string()))?;
            codec
                .path(&k.field)
                .map_err(|e| ("kill.field".to_string(), e.to_string()))?;
        }
        Ok(())
    }

    /// `[pose]`: a valid topic and rate, a definition for an unknown ROS 2 type.
    fn check_pose(&self) -> Result<(), Problem> {
        let (Some(p), Some(transport)) = (&self.pose, self.pose_transport()) else {
            return Ok(());
        };
        check_topic("pose.topic".into(), &p.topic)?;
        if !(p.max_rate_hz.is_finite() && p.max_rate_hz > 0.0 && p.max_rate_hz <= 1000.0) {
            return Err((
                "pose.max_rate_hz".into(),
                format!("{} must be in (0, 1000]", p.max_rate_hz),
            ));
        }
        if transport == Transport::Dds {
            let def = match &p.definition {
                Some(d) => d.clone(),
                None => crate::msgs::ros2_definition(&p.ros2_type).ok_or_else(|| {
                    (
                        "pose.definition".to_string(),
                        format!(
                            "the bridge does not know the ROS 2 type `{}`: give its definition",
                            p.ros2_type
                        ),
                    )
                })?,
            };
            let codec = perturb_bag::dynamic::MessageCodec::new(
                &p.ros2_type,
                "ros2msg",
                def.as_bytes(),
                "cdr",
            )
            .map_err(|e| ("pose.definition".to_string(), e.to_string()))?;
            let base = match &p.field {
                Some(f) => f.trim_end_matches(".x").to_string(),
                None => perturb_bag::dynamic::position_path(&codec).ok_or_else(|| {
                    (
                        "pose.field".to_string(),
                        format!("cannot tell where the position is in `{}`", p.ros2_type),
                    )
                })?,
            };
            codec
                .path(&format!("{base}.x"))
                .map_err(|e| ("pose.field".to_string(), e.to_string()))?;
        }
        Ok(())
    }

    /// `[ros1]`: `/clock` only from a replay and not written twice; the node's settings.
    fn check_ros1(&self, egress_topics: &Topics) -> Result<(), Problem> {
        if self.ros1.clock {
            if self.replay.is_none() {
                return Err((
                    "ros1.clock".into(),
                    "/clock is published from a replayed bag: add a [replay] section or remove `clock`".into(),
                ));
            }
            if egress_topics.contains(&(Transport::Ros1, "/clock".to_string())) {
                return Err((
                    "ros1.clock".into(),
                    "an [[egress]] already writes the ROS 1 topic /clock".into(),
                ));
            }
        }
        if self.uses_ros1() {
            self.ros1_settings().map_err(|e| {
                let (key, problem) = e.split_once(": ").unwrap_or(("(ros1)", &e));
                (format!("ros1.{key}"), problem.to_string())
            })?;
        }
        Ok(())
    }

    /// `[view]`: a loopback address unless `allow_remote`, the rates, sizes and streams.
    fn check_view(&self) -> Result<(), Problem> {
        let Some(v) = &self.view else {
            return Ok(());
        };
        let ip = if v.bind == "localhost" {
            std::net::IpAddr::V4(std::net::Ipv4Addr::LOCALHOST)
        } else {
            v.bind.parse::<std::net::IpAddr>().map_err(|_| {
                (
                    "view.bind".to_string(),
                    format!("`{}` is not an IP address (e.g. 127.0.0.1, ::1)", v.bind),
                )
            })?
        };
        if !ip.is_loopback() && !v.allow_remote {
            return Err((
                "view.bind".into(),
                format!(
                    "`{}` is not a loopback address: whoever reaches it sees the cameras and can                      switch perturbations and the kill switch; bind 127.0.0.1 (and tunnel, e.g.                      ssh -L 8765:127.0.0.1:8765), or set `view.allow_remote = true` to serve it anyway",
                    v.bind
                ),
            ));
        }
        let rate = |key: &str, r: f64| {
            if r.is_finite() && r > 0.0 && r <= 60.0 {
                Ok(())
            } else {
                Err((
                    format!("view.{key}"),
                    format!("{r} must be in (0, 60] per second"),
                ))
            }
        };
        rate("rate_hz", v.rate_hz)?;
        rate("cloud_rate_hz", v.cloud_rate_hz)?;
        let whole = |key: &str, n: u64, lo: u64, hi: u64| {
            if (lo..=hi).contains(&n) {
                Ok(())
            } else {
                Err((format!("view.{key}"), format!("{n} must be in {lo}..={hi}")))
            }
        };
        whole("max_width", u64::from(v.max_width), 16, 16_384)?;
        whole("jpeg_quality", u64::from(v.jpeg_quality), 1, 100)?;
        whole("max_points", u64::from(v.max_points), 1, 10_000_000)?;
        whole("backlog", v.backlog as u64, 1, 100_000)?;
        let t = v.stats_interval_s;
        if !(t.is_finite() && (0.1..=60.0).contains(&t)) {
            return Err((
                "view.stats_interval_s".into(),
                format!("{t} must be in [0.1, 60] seconds"),
            ));
        }
        let mut seen = BTreeSet::new();
        for (i, st) in v.streams.iter().enumerate() {
            check_stream(format!("view.streams[{i}]"), st)?;
            if !seen.insert(st) {
                return Err((
                    format!("view.streams[{i}]"),
                    format!("stream `{st}` is listed twice"),
                ));
            }
        }
        Ok(())
    }

    /// At least one adapter.
    fn check_not_empty(&self) -> Result<(), Problem> {
        let anything = !self.ingress.is_empty()
            || !self.egress.is_empty()
            || self.replay.is_some()
            || self.record.is_some()
            || !self.synthetic.camera.is_empty()
            || !self.synthetic.lidar.is_empty()
            || self.kill.is_some()
            || self.pose.is_some()
            || self.view.is_some();
        if !anything {
            return Err((
                "(file)".into(),
                "no adapter configured: add [[ingress]], [[egress]], [replay], [record] or [synthetic]".into(),
            ));
        }
        Ok(())
    }
}

/// A synthetic camera's size, frame and pre-render memory and rate; the problem names the field.
fn check_synthetic_camera(c: &SyntheticCamera) -> Result<(), Problem> {
    if c.width == 0 || c.height == 0 || c.width > 16384 || c.height > 16384 {
        return Err((
            "width".into(),
            format!("{}x{} is not a usable size (1..=16384)", c.width, c.height),
        ));
    }
    let frame = synthetic_frame_bytes(c.width, c.height);
    if frame > MAX_SYNTHETIC_FRAME_BYTES {
        return Err((
            "width".into(),
            format!(
                "{}x{} frames take {} MiB each, more than the {} MiB a synthetic frame may take (e.g. 8192x8192)",
                c.width,
                c.height,
                frame >> 20,
                MAX_SYNTHETIC_FRAME_BYTES >> 20
            ),
        ));
    }
    if frame * c.prerender as u64 > MAX_PRERENDER_BYTES {
        return Err((
            "prerender".into(),
            format!(
                "{} pre-rendered frames of {}x{} take {} MiB, more than {} MiB: use prerender = {} or less (0 renders every frame live)",
                c.prerender,
                c.width,
                c.height,
                (frame * c.prerender as u64) >> 20,
                MAX_PRERENDER_BYTES >> 20,
                prerender_that_fits(c.width, c.height, c.prerender)
            ),
        ));
    }
    if !(c.rate_hz > 0.0 && c.rate_hz <= 1000.0) {
        return Err((
            "rate_hz".into(),
            format!("{} must be in (0, 1000]", c.rate_hz),
        ));
    }
    Ok(())
}

/// Marks `stream` as fed by the source at `key`; a second source is an error.
fn claim_source(sourced: &mut BTreeSet<String>, key: String, stream: &str) -> Result<(), Problem> {
    if !sourced.insert(stream.to_string()) {
        return Err((key, format!("stream `{stream}` already has a source")));
    }
    Ok(())
}

/// A frame_id the wire header can carry (at most [`perturb_wire::header::FRAME_ID_LEN`] bytes).
fn check_frame_id(key: String, f: &str) -> Result<(), Problem> {
    let max = perturb_wire::header::FRAME_ID_LEN;
    if f.len() > max || f.contains('\0') {
        return Err((
            key,
            format!(
                "frame_id of {} bytes: the frame header holds at most {max} bytes, without NUL",
                f.len()
            ),
        ));
    }
    Ok(())
}

/// A file to be written: its folder must exist (a report or state file that cannot be written
/// would be noticed only when the bridge stops).
fn check_parent(key: &str, path: &std::path::Path) -> Result<(), Problem> {
    let dir = path
        .parent()
        .filter(|d| !d.as_os_str().is_empty())
        .unwrap_or(std::path::Path::new("."));
    if !dir.is_dir() {
        return Err((
            key.to_string(),
            format!(
                "{}: the folder {} does not exist",
                path.display(),
                dir.display()
            ),
        ));
    }
    Ok(())
}

/// A stream name, by the rule the daemon uses too ([`perturb_wire::names::check_stream`]).
fn check_stream(key: String, s: &str) -> Result<(), Problem> {
    perturb_wire::names::check_stream(s).map_err(|e| (key, e))
}

/// A ROS topic name: absolute, `/`-separated tokens of letters, digits and `_`, none starting
/// with a digit.
fn check_topic(key: String, t: &str) -> Result<(), Problem> {
    let ok = t.starts_with('/')
        && t.len() > 1
        && !t.ends_with('/')
        && !t.contains("//")
        && t[1..]
            .split('/')
            .all(|p| !p.is_empty() && !p.starts_with(|c: char| c.is_ascii_digit()))
        && t.chars()
            .all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '/');
    if !ok {
        return Err((
            key,
            format!(
                "`{t}` is not a ROS 2 topic name (absolute, `/`-separated tokens of letters, digits and `_`, not starting with a digit)"
            ),
        ));
    }
    Ok(())
}

/// A topic's QoS: a history depth of 1..=1000.
fn check_qos(key: String, q: &Qos) -> Result<(), Problem> {
    if q.depth == 0 || q.depth > 1000 {
        return Err((key, format!("depth {} must be 1..=1000", q.depth)));
    }
    Ok(())
}
