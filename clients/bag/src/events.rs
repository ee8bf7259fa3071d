//! The perturbation event channel: one `std_msgs/msg/String` message per perturbed frame, holding a
//! JSON object that says which perturbation was active for that frame, so every experiment can be
//! analysed afterwards with any bag reader (no custom message type needed).
//!
//! ```
//! use perturb_bag::events::{PerturbationEvent, decode_string, encode_string};
//! let ev = PerturbationEvent { topic: "/cam".into(), stream: None, seq: 3, stamp_sec: 1, stamp_nanosec: 2,
//!     frame_id: "cam".into(), id: Some("C-A1".into()), severity: Some(2), seed: Some(7) };
//! let cdr = encode_string(&serde_json::to_string(&ev).unwrap());
//! let back: PerturbationEvent = serde_json::from_str(&decode_string(&cdr).unwrap()).unwrap();
//! assert_eq!(back, ev);
//! ```

/// The topic of the event channel.
pub const EVENTS_TOPIC: &str = "/perturb/events";
/// Its message type.
pub const EVENTS_TYPE: &str = "std_msgs/msg/String";

/// Which perturbation was applied to one frame (all fields `None` when the frame passed through
/// unperturbed).
#[derive(Clone, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct PerturbationEvent {
    /// The topic of the frame.
    pub topic: String,
    /// The daemon stream, when recorded from the live pipeline.
    pub stream: Option<String>,
    /// The frame's sequence number (the one the perturbation was seeded with).
    pub seq: u64,
    /// The frame's header stamp, seconds.
    pub stamp_sec: i32,
    /// The frame's header stamp, nanoseconds.
    pub stamp_nanosec: u32,
    /// The frame's frame_id.
    pub frame_id: String,
    /// Perturbation ID, or None.
    pub id: Option<String>,
    /// Severity, or None.
    pub severity: Option<u8>,
    /// Seed, or None.
    pub seed: Option<u64>,
}

/// Encodes a `std_msgs/msg/String` in little-endian CDR.
pub fn encode_string(s: &str) -> Vec<u8> {
    let mut b = Vec::with_capacity(s.len() + 9);
    b.extend_from_slice(&[0, 1, 0, 0]);
    b.extend_from_slice(&(s.len() as u32 + 1).to_le_bytes());
    b.extend_from_slice(s.as_bytes());
    b.push(0);
    b
}

/// Encodes a `std_msgs/String` in the encoding of a bag format (CDR or ROS 1).
pub fn encode_string_for(format: crate::BagFormat, s: &str) -> Vec<u8> {
    match format {
        crate::BagFormat::Rosbag2 => encode_string(s),
        crate::BagFormat::Ros1 => perturb_core::formats::ros1::encode_string(s),
    }
}

/// Decodes a `std_msgs/msg/String` from CDR (either byte order).
pub fn decode_string(b: &[u8]) -> Option<String> {
    if b.len() < 8 {
        return None;
    }
    let n = match b[1] {
        1 | 3 => u32::from_le_bytes(b[4..8].try_into().ok()?),
        _ => u32::from_be_bytes(b[4..8].try_into().ok()?),
    } as usize;
    let body = b.get(8..8 + n)?;
    let body = body.strip_suffix(&[0]).unwrap_or(body);
    String::from_utf8(body.to_vec()).ok()
}

/// The version of the events record ([`EventRecord`]); records without one are version 1 (the
/// fields of [`PerturbationEvent`] only).
pub const EVENTS_VERSION: u32 = 2;

/// What an events record reports.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum EventKind {
    /// One frame as the ADS received it: which perturbation it carries, or why it is raw.
    #[default]
    Frame,
    /// Frames lost, with their count and cause.
    Gap,
    /// The kill switch was engaged (`reason` says by what).
    Kill,
    /// The kill switch was released (`perturb ctl arm`).
    Arm,
    /// In `changes` mode: the stream's state, repeated once a second while nothing changes.
    Heartbeat,
}

/// One record of the events channel (`/perturb/events`, `std_msgs/String` holding this object
/// as JSON), version [`EVENTS_VERSION`]; its JSON schema is `docs/events.schema.json`. A frame
/// record carries every field of [`PerturbationEvent`] (version 1), so readers of version 1 read
/// it too; they must skip records whose `kind` is not `frame`.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default)]
pub struct EventRecord {
    /// [`EVENTS_VERSION`].
    pub version: u32,
    /// What the record reports.
    pub kind: EventKind,
    /// The topic the frame went out on (frame, gap, heartbeat).
    pub topic: String,
    /// The middleware stream.
    pub stream: Option<String>,
    /// The frame's sequence number (frame, heartbeat: the last frame's; gap: the first frame
    /// after the gap).
    pub seq: u64,
    /// The frame's header stamp, seconds.
    pub stamp_sec: i32,
    /// The frame's header stamp, nanoseconds.
    pub stamp_nanosec: u32,
    /// The frame's frame_id.
    pub frame_id: String,
    /// The perturbation applied to the frame, or None.
    pub id: Option<String>,
    /// Its severity.
    pub severity: Option<u8>,
    /// Its seed.
    pub seed: Option<u64>,
    /// True if the frame the ADS received is the perturbed one (with `id`); false when it is
    /// raw (no perturbation active, or `reason`).
    pub applied: bool,
    /// Why a raw frame went out in place of the perturbed one: `late` (missed its deadline),
    /// `daemon_down`, `killed` (the kill switch); for kill records what engaged it.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub reason: Option<String>,
    /// The campaign step that chose the perturbation (1-based), if a campaign did.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub step: Option<u16>,
    /// Gap records: why the frames were lost (`upstream`, `daemon_down`, `daemon_late`,
    /// `egress`, `recorder`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub cause: Option<String>,
    /// Gap records: how many frames.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub count: Option<u64>,
    /// Wall-clock time the record was made, ns since the Unix epoch.
    pub t_wall_ns: u64,
}

impl EventRecord {
    /// A frame record.
    #[allow(clippy::too_many_arguments)]
    pub fn frame(
        stream: &str,
        topic: &str,
        seq: u64,
        stamp: (i32, u32),
        frame_id: &str,
        applied: Option<(&str, u8, u64)>,
        reason: Option<&str>,
        t_wall_ns: u64,
    ) -> Self {
        EventRecord {
            version: EVENTS_VERSION,
            kind: EventKind::Frame,
            topic: topic.to_string(),
            stream: Some(stream.to_string()),
            seq,
            stamp_sec: stamp.0,
            stamp_nanosec: stamp.1,
            frame_id: frame_id.to_string(),
            id: applied.map(|a| a.0.to_string()),
            severity: applied.map(|a| a.1),
            seed: applied.map(|a| a.2),
            applied: applied.is_some(),
            reason: reason.map(str::to_string),
            t_wall_ns,
            ..Default::default()
        }
    }

    /// A gap record: `count` frames of `stream` lost to `cause` before frame `seq`.
    pub fn gap(
        stream: &str,
        topic: &str,
        seq: u64,
        cause: &str,
        count: u64,
        t_wall_ns: u64,
    ) -> Self {
        EventRecord {
            version: EVENTS_VERSION,
            kind: EventKind::Gap,
            topic: topic.to_string(),
            stream: Some(stream.to_string()),
            seq,
            cause: Some(cause.to_string()),
            count: Some(count),
            t_wall_ns,
            ..Default::default()
        }
    }

    /// A kill (`engaged`) or arm record.
    pub fn kill(engaged: bool, reason: &str, t_wall_ns: u64) -> Self {
        EventRecord {
            version: EVENTS_VERSION,
            kind: if engaged {
                EventKind::Kill
            } else {
                EventKind::Arm
            },
            reason: Some(reason.to_string()),
            t_wall_ns,
            ..Default::default()
        }
    }

    /// Reads a record of any version (a version-1 record is a frame record).
    pub fn parse(json: &str) -> Result<Self, serde_json::Error> {
        let mut r: EventRecord = serde_json::from_str(json)?;
        if r.version < 2 {
            r.version = 1;
            r.kind = EventKind::Frame;
            r.applied = r.id.is_some();
        }
        Ok(r)
    }
}

#[cfg(test)]
mod record_tests {
    use super::*;

    #[test]
    fn frame_records_are_read_by_version_1_readers_and_old_records_read_as_frames() {
        let r = EventRecord::frame(
            "cam",
            "/camera/image_raw",
            7,
            (1, 2),
            "cam",
            Some(("C-A1", 3, 42)),
            None,
            99,
        );
        let json = serde_json::to_string(&r).unwrap();
        let old: PerturbationEvent = serde_json::from_str(&json).unwrap();
        assert_eq!(
            (old.seq, old.id.as_deref(), old.severity),
            (7, Some("C-A1"), Some(3))
        );
        assert_eq!(EventRecord::parse(&json).unwrap(), r);
        let v1 = serde_json::to_string(&old).unwrap();
        let back = EventRecord::parse(&v1).unwrap();
        assert_eq!(
            (back.version, back.kind, back.applied),
            (1, EventKind::Frame, true)
        );
        let raw = EventRecord::frame("cam", "/c", 8, (1, 2), "cam", None, Some("late"), 0);
        let json = serde_json::to_string(&raw).unwrap();
        assert!(
            json.contains("\"applied\":false") && json.contains("\"reason\":\"late\""),
            "{json}"
        );
        let gap = EventRecord::gap("cam", "/c", 9, "daemon_down", 12, 0);
        let back = EventRecord::parse(&serde_json::to_string(&gap).unwrap()).unwrap();
        assert_eq!(
            (back.kind, back.count, back.cause.as_deref()),
            (EventKind::Gap, Some(12), Some("daemon_down"))
        );
    }
}
