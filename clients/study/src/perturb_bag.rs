//! Perturbing every sensor message of a bag: the copy `perturb apply BAG` and `perturb batch BAG`
//! write, with a `/perturb/events` record per perturbed frame.

use crate::error::{Result, StudyError};
use crate::progress::Progress;
use perturb_bag::events::{EVENTS_TOPIC, EVENTS_TYPE, PerturbationEvent, encode_string_for};
use perturb_bag::{AnyWriter, Bag, BagFormat, Filter, SensorMessage};
use perturb_core::encoding::Scratch;
use perturb_core::formats::picture;
use perturb_core::formats::ros::{CompressedImageMsg, Header, ImageMsg, PointCloud2Msg};
use perturb_core::perturber::{CameraPerturber, LidarPerturber, Spec};
use perturb_core::registry::Modality;
use perturb_core::sensor_model::SensorModel;
use std::collections::HashMap;
use std::ops::ControlFlow;
use std::path::Path;

/// Writes a copy of `bag` into the bag `out`, in the input's format (rosbag2 MCAP, or a ROS 1
/// `.bag` for ROS 1 inputs), with every message of the perturbation's modality (on `topics`, or
/// all topics when empty) perturbed, the others copied, and a /perturb/events record per
/// perturbed frame. The sequence number of a message is its index on its
/// topic plus `seq_offset`. Returns the number of input messages; damage in the input is an error
/// after the readable messages were written. `progress` gets one unit per input message and a
/// note per perturbed topic.
pub fn perturb_bag(
    bag: &Bag,
    out: &Path,
    spec: Spec,
    seq_offset: u64,
    sensor: &SensorModel,
    topics: &[String],
    progress: &dyn Progress,
) -> Result<u64> {
    let options = BagOptions {
        seq_offset,
        sensor: sensor.clone(),
        topics: topics.to_vec(),
        bit_depth: None,
        compression: None,
    };
    perturb_bag_with(bag, out, spec, &options, progress)
}

/// How [`perturb_bag_with`] treats a bag besides the perturbation.
#[derive(Clone, Debug)]
pub struct BagOptions {
    /// Added to a message's index on its topic to give its sequence number.
    pub seq_offset: u64,
    /// The LiDAR sensor model.
    pub sensor: SensorModel,
    /// Topics to perturb (all topics of the perturbation's modality when empty).
    pub topics: Vec<String>,
    /// Significant bits of 16-bit image samples (`mono16`, `bayer_*16`, ...; default 16).
    pub bit_depth: Option<u8>,
    /// Chunk compression of the output (see [`perturb_bag::AnyWriter::create`]; default zstd
    /// for rosbag2, none for ROS 1).
    pub compression: Option<String>,
}

/// [`perturb_bag`] with every option. Images in any encoding of the encoding table
/// (`perturb_core::encoding`: Bayer, YUV 4:2:2, 16-bit, ...) are perturbed through their working
/// view and written back in their own encoding, size, step and byte order.
pub fn perturb_bag_with(
    bag: &Bag,
    out: &Path,
    spec: Spec,
    options: &BagOptions,
    progress: &dyn Progress,
) -> Result<u64> {
    let BagOptions {
        seq_offset,
        ref sensor,
        ref topics,
        bit_depth,
        ref compression,
    } = *options;
    let (mut w, format, channel, events) = open_output(bag, out, compression.as_deref())?;
    let mut camera = match spec.entry.modality {
        Modality::Camera => Some(CameraJob {
            perturber: CameraPerturber::from_spec(spec)?,
            scratch: Scratch::new(),
            bit_depth,
        }),
        Modality::Lidar => None,
    };
    let mut lidar = match spec.entry.modality {
        Modality::Lidar => Some(LidarPerturber::from_spec(spec, sensor.clone())?),
        Modality::Camera => None,
    };
    let mut index: HashMap<String, u64> = HashMap::new();
    let mut perturbed: HashMap<String, u64> = HashMap::new();
    let report = bag.for_each(&Filter::default(), |m| {
        progress.inc(1);
        let ch = channel[m.topic];
        let selected = topics.is_empty() || topics.iter().any(|t| t == m.topic);
        let decoded = if selected { m.decode() } else { None };
        let (bytes, header) = match decoded {
            Some(Ok(msg)) => {
                let k = index.entry(m.topic.to_string()).or_default();
                let seq = *k + seq_offset;
                *k += 1;
                let out =
                    perturb_message(&msg, seq, m.header_seq(), camera.as_mut(), lidar.as_mut())
                        .map_err(|e| {
                            perturb_bag::BagError::Callback(format!(
                                "{}: `{}` at log time {}: {e}",
                                m.path.display(),
                                m.topic,
                                m.log_time
                            ))
                        })?;
                match out {
                    Some((bytes, h)) => (bytes, Some((h, seq))),
                    None => (m.data.to_vec(), None),
                }
            }
            Some(Err(e)) => return Err(e),
            None => (m.data.to_vec(), None),
        };
        w.write(ch, m.log_time, m.publish_time, &bytes)?;
        if let Some((header, seq)) = header {
            *perturbed.entry(m.topic.to_string()).or_default() += 1;
            let json = event_json(spec, m.topic, header, seq);
            w.write(
                events,
                m.log_time,
                m.publish_time,
                &encode_string_for(format, &json),
            )?;
        }
        Ok(ControlFlow::Continue(()))
    })?;
    let dir = w.finish()?;
    say_what_was_written(progress, spec, &perturbed, report.delivered, &dir);
    if let Some(d) = report.damage {
        return Err(StudyError::input(
            bag.paths().first().copied().unwrap_or(out),
            format!("the input bag is damaged; the messages before the damage were written: {d}"),
        ));
    }
    Ok(report.delivered)
}

/// The output bag in the input's format (ROS 1 for a ROS 1 input), with a topic like each of
/// the input's and the events topic: (writer, format, channel per topic, events channel).
fn open_output(
    bag: &Bag,
    out: &Path,
    compression: Option<&str>,
) -> Result<(AnyWriter, BagFormat, HashMap<String, u16>, u16)> {
    let topics_in = bag.topics()?;
    let format = if bag.is_ros1_bag() || topics_in.iter().any(|t| t.message_encoding == "ros1") {
        BagFormat::Ros1
    } else {
        BagFormat::Rosbag2
    };
    let mut w = AnyWriter::create(out, format, compression)?;
    let mut channel = HashMap::new();
    for t in &topics_in {
        let id = w.add_topic_like(t)?;
        channel.insert(t.topic.clone(), id);
    }
    let events = w.add_topic(EVENTS_TOPIC, EVENTS_TYPE)?;
    Ok((w, format, channel, events))
}

/// The `/perturb/events` record of a perturbed message of `topic` (its header and sequence
/// number), as JSON.
fn event_json(spec: Spec, topic: &str, (sec, nsec, frame): HeaderOut, seq: u64) -> String {
    let ev = PerturbationEvent {
        topic: topic.to_string(),
        stream: None,
        seq,
        stamp_sec: sec,
        stamp_nanosec: nsec,
        frame_id: frame,
        id: Some(spec.entry.id.to_string()),
        severity: Some(spec.severity),
        seed: Some(spec.seed),
    };
    serde_json::to_string(&ev).expect("event serialises")
}

/// Notes what was perturbed per topic and written where (a warning when nothing was).
fn say_what_was_written(
    progress: &dyn Progress,
    spec: Spec,
    perturbed: &HashMap<String, u64>,
    delivered: u64,
    dir: &Path,
) {
    for (t, n) in perturbed {
        progress.note(&format!(
            "{t}: {n} messages perturbed with {} severity {}",
            spec.entry.id, spec.severity
        ));
    }
    if perturbed.is_empty() {
        progress.note(&format!(
            "warning: no {} message found to perturb",
            spec.entry.modality
        ));
    }
    let n_events: u64 = perturbed.values().sum();
    progress.note(&format!(
        "{delivered} messages of the input and {n_events} /perturb/events records written to {}",
        dir.display()
    ));
}

type HeaderOut = (i32, u32, String);

/// A camera perturbation with its conversion buffers (reused from image to image) and the bit
/// depth of 16-bit samples.
struct CameraJob {
    perturber: CameraPerturber,
    scratch: Scratch,
    bit_depth: Option<u8>,
}

/// Perturbs one decoded sensor message if it belongs to the perturbation's modality; returns the
/// re-encoded message (in ROS 1 serialization with its header `seq` when `ros1_seq` is given,
/// else CDR) and its header, or None to copy it unchanged.
fn perturb_message(
    msg: &SensorMessage<'_>,
    seq: u64,
    ros1_seq: Option<u32>,
    camera: Option<&mut CameraJob>,
    lidar: Option<&mut LidarPerturber>,
) -> perturb_core::Result<Option<(Vec<u8>, HeaderOut)>> {
    let hdr = |h: &Header<'_>| (h.stamp_sec, h.stamp_nanosec, h.frame_id.to_string());
    match (msg, camera, lidar) {
        (SensorMessage::Image(img), Some(cam), _) => {
            let mut view = img.view()?;
            if let Some(bits) = cam.bit_depth
                && view.encoding.bits == 16
            {
                view = view.with_bit_depth(bits)?;
            }
            // The same fields (encoding name, byte order, step), the perturbed data.
            let mut data = vec![0; img.data.len()];
            cam.perturber
                .apply_encoded(&view, &mut data, seq, &mut cam.scratch)?;
            let m = ImageMsg {
                data: &data,
                ..*img
            };
            let bytes = ros1_seq.map_or_else(|| m.encode(), |s| m.encode_ros1(s));
            Ok(Some((bytes, hdr(&img.header))))
        }
        (SensorMessage::Compressed(c), Some(cam), _) => {
            let decoded = picture::decode(c.data)?;
            let out = cam.perturber.apply_owned(&decoded.view(), seq)?;
            let data = if c.format.to_ascii_lowercase().contains("png") {
                picture::encode_png(&out.view())?
            } else {
                picture::encode_jpeg(&out.view(), 95)?
            };
            let m = CompressedImageMsg {
                header: c.header,
                format: c.format,
                data: &data,
            };
            let bytes = ros1_seq.map_or_else(|| m.encode(), |s| m.encode_ros1(s));
            Ok(Some((bytes, hdr(&c.header))))
        }
        (SensorMessage::Cloud(pc), _, Some(lid)) => {
            let view = pc.view()?;
            let out = lid.apply_owned(&view, seq, None)?;
            let m = PointCloud2Msg::from_view(pc.header, &out.view());
            let bytes = ros1_seq.map_or_else(|| m.encode(), |s| m.encode_ros1(s));
            Ok(Some((bytes, hdr(&pc.header))))
        }
        _ => Ok(None),
    }
}
