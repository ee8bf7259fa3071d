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
            claim_source(sourced, key("stream"), &c.stream)?;
            check_synthetic_camera(c).map_err(|(field, problem)| (key(&field), problem))?;
        }
        for (i, l) in self.synthetic.lidar.iter().enumerate() {
            check_stream(format!("synthetic.lidar[{i}].stream"), &l.stream)?;
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
            match format {
                perturb_bag::BagFormat::Rosbag2 => {
                    c.parse::<perturb_bag::Compression>().map(|_| ())
                }
                perturb_bag::BagFormat::Ros1 => {
                    c.parse::<perturb_bag::ros1::Ros1Compression>().map(|_| ())
                }
            }
            .map_err(|e| ("record.compression".to_string(), e))?;
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

    /// At least one adapter.
    fn check_not_empty(&self) -> Result<(), Problem> {
        let anything = !self.ingress.is_empty()
            || !self.egress.is_empty()
            || self.replay.is_some()
            || self.record.is_some()
            || !self.synthetic.camera.is_empty()
            || !self.synthetic.lidar.is_empty();
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

/// A stream name: 1-200 characters, no `.` or `..` segments, not starting with `/`, no `//`.
fn check_stream(key: String, s: &str) -> Result<(), Problem> {
    let path_like = s.split('/').any(|part| part == "." || part == "..");
    if path_like {
        return Err((
            key,
            format!("stream name `{s}` contains `.` or `..` segments: a stream name is not a path"),
        ));
    }
    if s.is_empty() || s.len() > 200 || s.starts_with('/') || s.contains("//") {
        return Err((
            key,
            format!(
                "stream name `{s}` must be 1-200 characters, not start with `/` nor contain `//`"
            ),
        ));
    }
    Ok(())
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
