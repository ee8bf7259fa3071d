//! The synthetic sensor source: street-scene camera frames ([`perturb_core::synthetic::street_image`])
//! and VLP-32C scans with ring and time fields ([`perturb_core::synthetic::vlp32c_scan`]) at
//! fixed rates into `<stream>/raw`.
//!
//! Rendering a 1920x1208 frame takes longer than a 33 ms frame period on a small machine (about
//! 0.1 s on two cores), so by default the first `prerender` frames of the drive are rendered at
//! start-up and cycled; the header stamp is the wall-clock time of publication, the sequence
//! number keeps counting.

use crate::adapter::{Adapter, Control};
use crate::bus::{Bus, Side};
use crate::config::{SyntheticCamera, SyntheticLidar};
use crate::frame::{FrameMeta, Hops, OwnedPayload, Payload, StreamKind, monotonic_ns, wall_ns};
use crate::stats::{AdapterReport, log_bad};
use anyhow::Result;
use perturb_core::cloud::Cloud;
use perturb_core::formats::ros::{Header, ImageMsg, PointCloud2Msg};
use perturb_core::image::Image;
use perturb_core::synthetic::{street_image, vlp32c_scan};
use std::time::{Duration, Instant};

enum Sensor {
    Camera(SyntheticCamera),
    Lidar(SyntheticLidar),
}

/// One synthetic sensor.
pub struct Synthetic {
    sensor: Sensor,
}

impl Synthetic {
    /// A camera.
    pub fn camera(c: SyntheticCamera) -> Self {
        Synthetic {
            sensor: Sensor::Camera(c),
        }
    }

    /// A LiDAR.
    pub fn lidar(l: SyntheticLidar) -> Self {
        Synthetic {
            sensor: Sensor::Lidar(l),
        }
    }
}

enum Frames {
    Images(Vec<Image>),
    Clouds(Vec<Cloud>),
}

impl Adapter for Synthetic {
    fn name(&self) -> String {
        match &self.sensor {
            Sensor::Camera(c) => format!(
                "synthetic camera {}x{} @ {} Hz -> {}/raw",
                c.width, c.height, c.rate_hz, c.stream
            ),
            Sensor::Lidar(l) => format!("synthetic VLP-32C @ {} Hz -> {}/raw", l.rate_hz, l.stream),
        }
    }

    fn is_sink(&self) -> bool {
        false
    }

    fn run(self: Box<Self>, bus: &dyn Bus, mut ctl: Control) -> Result<AdapterReport> {
        let name = self.name();
        let (stream, kind, rate, frame_id, count) = match &self.sensor {
            Sensor::Camera(c) => (
                &c.stream,
                StreamKind::Image,
                c.rate_hz,
                &c.frame_id,
                c.count,
            ),
            Sensor::Lidar(l) => (
                &l.stream,
                StreamKind::Cloud,
                l.rate_hz,
                &l.frame_id,
                l.count,
            ),
        };
        let mut publisher = bus.publisher(stream, kind, Side::Raw)?;
        let Some(cache) = self.prerender(&ctl, &name) else {
            return Ok(AdapterReport {
                name,
                ..Default::default()
            });
        };
        ctl.ready();
        let mut rep = AdapterReport {
            name: name.clone(),
            ..Default::default()
        };
        let period = Duration::from_secs_f64(1.0 / rate);
        let start = Instant::now();
        let mut seq = 0u64;
        while !ctl.stopped() && count.is_none_or(|c| seq < c) {
            let due = start + period.mul_f64(seq as f64);
            let now = Instant::now();
            if due > now && !ctl.sleep(due - now) {
                break;
            }
            let wall = wall_ns();
            let (sec, nanosec) = ((wall / 1_000_000_000) as i32, (wall % 1_000_000_000) as u32);
            let header = Header {
                stamp_sec: sec,
                stamp_nanosec: nanosec,
                frame_id,
            };
            let mut live = None;
            let payload = self.payload(&cache, &mut live, seq, header);
            rep.received += 1;
            let meta = FrameMeta {
                seq,
                log_time: wall,
                applied: None,
                lost_before: 0,
                step: 0,
                hops: Hops {
                    source: monotonic_ns(),
                    ..Default::default()
                },
            };
            match publisher.publish(&meta, &payload) {
                Ok(()) => rep.forwarded += 1,
                Err(e) => {
                    rep.failed += 1;
                    log_bad(&name, rep.failed, &e);
                }
            }
            seq += 1;
        }
        rep.undelivered = publisher.undelivered();
        Ok(rep)
    }
}

impl Synthetic {
    /// Renders the frames kept for the run (`prerender` of them), frame by frame so that a stop
    /// (SIGINT) during a long pre-render is heeded at once (None then); the size and the count
    /// were bounded by the configuration check.
    fn prerender(&self, ctl: &Control, name: &str) -> Option<Frames> {
        let t = Instant::now();
        let (cache, prerender) = match &self.sensor {
            Sensor::Camera(c) => (
                Frames::Images(render_all(c.prerender, ctl, name, |n| {
                    street_image(c.width, c.height, n)
                })?),
                c.prerender,
            ),
            Sensor::Lidar(l) => (
                Frames::Clouds(render_all(l.prerender, ctl, name, vlp32c_scan)?),
                l.prerender,
            ),
        };
        if prerender > 0 {
            tracing::info!(
                "{name}: rendered {prerender} frames in {:.1} s",
                t.elapsed().as_secs_f64()
            );
        }
        Some(cache)
    }

    /// Frame `seq` with `header`: a cached frame lent as it is (no copy), or one rendered now
    /// into `live` when nothing was pre-rendered.
    fn payload<'a>(
        &self,
        cache: &'a Frames,
        live: &'a mut Option<OwnedPayload>,
        seq: u64,
        header: Header<'a>,
    ) -> Payload<'a> {
        match cache {
            Frames::Images(v) if !v.is_empty() => Payload::Image(ImageMsg::from_view(
                header,
                &v[(seq % v.len() as u64) as usize].view(),
            )),
            Frames::Clouds(v) if !v.is_empty() => Payload::Cloud(PointCloud2Msg::from_view(
                header,
                &v[(seq % v.len() as u64) as usize].view(),
            )),
            _ => {
                let rendered = match &self.sensor {
                    Sensor::Camera(c) => OwnedPayload::Image {
                        sec: 0,
                        nanosec: 0,
                        frame_id: header.frame_id.to_string(),
                        image: street_image(c.width, c.height, seq),
                    },
                    Sensor::Lidar(_) => OwnedPayload::Cloud {
                        sec: 0,
                        nanosec: 0,
                        frame_id: header.frame_id.to_string(),
                        cloud: vlp32c_scan(seq),
                    },
                };
                match live.insert(rendered) {
                    OwnedPayload::Image { image, .. } => {
                        Payload::Image(ImageMsg::from_view(header, &image.view()))
                    }
                    OwnedPayload::Cloud { cloud, .. } => {
                        Payload::Cloud(PointCloud2Msg::from_view(header, &cloud.view()))
                    }
                    other => other.payload(),
                }
            }
        }
    }
}

/// Frames 0..count of `render`; None when the run is stopped part-way.
fn render_all<T>(
    count: u32,
    ctl: &Control,
    name: &str,
    render: impl Fn(u64) -> T,
) -> Option<Vec<T>> {
    let mut frames = Vec::with_capacity(count as usize);
    for n in 0..count as u64 {
        if ctl.stopped() {
            tracing::info!("{name}: stopped while pre-rendering (frame {n} of {count})");
            return None;
        }
        frames.push(render(n));
    }
    Some(frames)
}
