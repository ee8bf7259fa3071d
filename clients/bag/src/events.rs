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
