//! `camera_info` travels with its image: an ingress with `camera_info = "<source topic>"` reads
//! the driver's calibration messages, and the egress of the same stream with `camera_info =
//! "<sink topic>"` publishes each of them, unchanged (same header, same bytes, same type), right
//! after the image with the same stamp goes out; so a consumer that pairs image and camera_info
//! by exact stamp (image_transport's CameraSubscriber, image_proc) finds both under the names it
//! subscribes to. A camera_info that comes after its image goes out at once; one whose image never
//! comes (the image was lost) goes out half a second later, or once eight newer ones wait. Both topics are on the same transport (ROS 1, or ROS 2); the sink is
//! advertised as `sensor_msgs/CameraInfo` when the bridge starts.

use crate::msgs::{CAMERA_INFO, SmallEndpoint, SmallWriter, Wire};
use std::collections::VecDeque;
use std::sync::Mutex;

/// The ROS 2 type of `camera_info`.
pub const ROS2_TYPE: &str = "sensor_msgs/msg/CameraInfo";

/// One received camera_info: its stamp and bytes.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Calibration {
    /// Header stamp (seconds, nanoseconds).
    pub stamp: (i32, u32),
    /// The message as received.
    pub data: Vec<u8>,
    /// Its serialization.
    pub wire: Wire,
    /// When the ingress received it.
    pub arrived: std::time::Instant,
}

/// The header stamp of a message that starts with a `std_msgs/Header` (ROS 1: `seq`, then
/// `time`; CDR: the encapsulation header, then `builtin_interfaces/Time`).
pub fn stamp_of(data: &[u8], wire: Wire) -> Option<(i32, u32)> {
    let at = match wire {
        Wire::Ros1 => 4,
        Wire::Cdr => 4,
    };
    let b = data.get(at..at + 8)?;
    let le = match wire {
        Wire::Ros1 => true,
        Wire::Cdr => data.get(1).is_some_and(|&e| e & 1 == 1),
    };
    let (s, n) = (b[..4].try_into().ok()?, b[4..].try_into().ok()?);
    Some(if le {
        (i32::from_le_bytes(s), u32::from_le_bytes(n))
    } else {
        (i32::from_be_bytes(s), u32::from_be_bytes(n))
    })
}

/// What the ingress and the egress of one stream share.
#[derive(Debug, Default)]
pub struct CameraInfoLink {
    waiting: Mutex<VecDeque<Calibration>>,
    /// The last one received (the live view shows it beside the stream's frames).
    latest: Mutex<Option<Calibration>>,
}

/// How many camera_info messages wait for their image before the oldest goes out anyway.
const WAIT: usize = 8;
/// How long a camera_info waits for its image before it goes out anyway.
const WAIT_TIME: std::time::Duration = std::time::Duration::from_millis(500);

impl CameraInfoLink {
    /// The ingress side: a camera_info arrived.
    pub fn push(&self, c: Calibration) {
        *self.latest.lock().unwrap_or_else(|p| p.into_inner()) = Some(c.clone());
        self.waiting
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .push_back(c);
    }

    /// The last camera_info received, if any.
    pub fn latest(&self) -> Option<Calibration> {
        self.latest
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .clone()
    }

    /// The egress side: the camera_info messages to publish now that the last image out was
    /// stamped `stamp` (those stamped at or before it, the oldest beyond [`WAIT`], those
    /// waiting longer than [`WAIT_TIME`]).
    pub fn take_for(&self, stamp: (i32, u32), now: std::time::Instant) -> Vec<Calibration> {
        let mut w = self.waiting.lock().unwrap_or_else(|p| p.into_inner());
        let mut out = Vec::new();
        while let Some(c) = w.front() {
            let due = (c.stamp.0, c.stamp.1) <= stamp
                || w.len() > WAIT
                || now.saturating_duration_since(c.arrived) >= WAIT_TIME;
            if !due {
                break;
            }
            out.extend(w.pop_front());
        }
        out
    }
}

/// The egress side's writer: `sensor_msgs/CameraInfo` on the sink topic, advertised when the
/// bridge starts (so the stack's subscribers are connected before the first calibration comes).
pub struct CameraInfoSink {
    /// The sink topic.
    pub topic: String,
    writer: Box<dyn SmallWriter>,
    /// Messages published.
    pub published: u64,
    /// Messages that could not be published.
    pub failed: u64,
    /// The stamp of the last image out.
    last_image: (i32, u32),
}

impl CameraInfoSink {
    /// A sink on `topic` of `endpoint`.
    pub fn new(topic: String, endpoint: &SmallEndpoint) -> anyhow::Result<Self> {
        let writer = endpoint.writer(&topic, CAMERA_INFO, crate::dds::Qos::default())?;
        Ok(CameraInfoSink {
            topic,
            writer,
            published: 0,
            failed: 0,
            last_image: (i32::MIN, 0),
        })
    }

    /// Publishes what `link` holds for the image stamped `stamp`, which just went out.
    pub fn after_image(&mut self, link: &CameraInfoLink, stamp: (i32, u32)) {
        self.last_image = self.last_image.max(stamp);
        self.poll(link);
    }

    /// Publishes what is due: a camera_info that came after its image, or waited too long.
    pub fn poll(&mut self, link: &CameraInfoLink) {
        for c in link.take_for(self.last_image, std::time::Instant::now()) {
            let r = if self.writer.wire() == c.wire {
                self.writer.write(&c.data)
            } else {
                Err(anyhow::anyhow!(
                    "a camera_info in another serialization than the sink's transport"
                ))
            };
            match r {
                Ok(()) => self.published += 1,
                Err(e) => {
                    self.failed += 1;
                    crate::stats::log_bad(
                        &format!("camera_info -> {}", self.topic),
                        self.failed,
                        &e,
                    );
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cal(sec: i32) -> Calibration {
        let mut data = vec![0, 1, 0, 0];
        data.extend_from_slice(&sec.to_le_bytes());
        data.extend_from_slice(&7u32.to_le_bytes());
        Calibration {
            stamp: stamp_of(&data, Wire::Cdr).unwrap(),
            data,
            wire: Wire::Cdr,
            arrived: std::time::Instant::now(),
        }
    }

    #[test]
    fn calibrations_wait_for_their_image_and_never_pile_up() {
        let l = CameraInfoLink::default();
        assert_eq!(cal(5).stamp, (5, 7));
        for s in [1, 2, 3] {
            l.push(cal(s));
        }
        let now = std::time::Instant::now();
        let due = l.take_for((2, 7), now);
        assert_eq!(due.iter().map(|c| c.stamp.0).collect::<Vec<_>>(), [1, 2]);
        for s in 4..14 {
            l.push(cal(s));
        }
        let due = l.take_for((0, 0), now);
        assert_eq!(due.len(), 3, "the oldest beyond 8 go out anyway");
        let due = l.take_for((0, 0), std::time::Instant::now() + WAIT_TIME);
        assert_eq!(due.len(), 8, "and every one that waited half a second");
        let mut ros1 = vec![0u8; 4];
        ros1.extend_from_slice(&9u32.to_le_bytes());
        ros1.extend_from_slice(&3u32.to_le_bytes());
        assert_eq!(stamp_of(&ros1, Wire::Ros1), Some((9, 3)));
    }
}
