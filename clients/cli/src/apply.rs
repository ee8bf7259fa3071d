//! `perturb apply`: one file, or every sensor message of a bag.

use crate::files::{Loaded, load, save_cloud, save_image, sensor_for};
use anyhow::{Context, Result, bail};
use perturb_bag::events::{EVENTS_TOPIC, EVENTS_TYPE, PerturbationEvent, encode_string};
use perturb_bag::{Bag, BagWriter, Filter, SensorMessage, WriterOptions};
use perturb_core::formats::ros::{CompressedImageMsg, Header, ImageMsg, PointCloud2Msg};
use perturb_core::formats::{FileKind, picture};
use perturb_core::image::Image;
use perturb_core::perturber::{CameraPerturber, LidarPerturber, Spec};
use perturb_core::registry::Modality;
use std::collections::HashMap;
use std::ops::ControlFlow;
use std::path::PathBuf;

/// Arguments of `perturb apply`.
#[derive(clap::Args)]
#[command(after_help = "Examples:
  perturb apply --id C-C7 --severity 3 frame.png -o rainy.png
  perturb apply --id L-A9 --severity 2 --seed 7 scan.bin -o foggy.bin
  perturb apply --id C-A1 --severity 1 recording.mcap -o perturbed_bag --topic /camera/image_raw

The output keeps the input's format and layout (PNG stays PNG, a PCD keeps its fields and DATA
encoding, a bag keeps every topic; messages of the other modality are copied unchanged). For a
bag, the sequence number of a message is its index on its topic plus --seq, and a
/perturb/events topic records which perturbation was applied to each frame.")]
pub struct Args {
    /// Perturbation ID or name (see `perturb list`).
    #[arg(long)]
    id: String,
    /// Severity: 1..5 for camera, 1..3 for LiDAR perturbations.
    #[arg(long, value_parser = clap::value_parser!(u8).range(1..=5))]
    severity: u8,
    /// Seed of every random draw.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Frame sequence number (animated effects and per-frame noise depend on it).
    #[arg(long, default_value_t = 0)]
    seq: u64,
    /// LiDAR sensor model: vlp32c, vlp16, hdl32e, hdl64e (default: hdl64e for KITTI .bin, vlp32c otherwise).
    #[arg(long)]
    sensor: Option<String>,
    /// Full-scale intensity of the cloud, 1 or 255 (default: the sensor model's).
    #[arg(long)]
    intensity_max: Option<f32>,
    /// For bags: only perturb these topics (repeatable; default all topics of the perturbation's modality).
    #[arg(long)]
    topic: Vec<String>,
    /// Input: .png .jpg .bin (KITTI) .pcd.bin (nuScenes) .pcd, or a rosbag2 .mcap file or directory.
    input: PathBuf,
    /// Output file (same format as the input), or for a bag the output bag directory.
    #[arg(short, long)]
    output: PathBuf,
}

/// Runs `perturb apply`.
pub fn run(a: Args) -> Result<()> {
    let spec = Spec::new(&a.id, a.severity, a.seed)?;
    let in_kind = if a.input.is_dir() {
        FileKind::Mcap
    } else {
        FileKind::from_path(&a.input)?
    };
    if in_kind == FileKind::Mcap {
        return apply_bag(&a, spec);
    }
    let out_kind = FileKind::from_path(&a.output)?;
    if out_kind != in_kind {
        bail!(
            "the output {} must have the input's format ({:?}), the perturbation keeps the format",
            a.output.display(),
            in_kind
        );
    }
    match load(&a.input)? {
        Loaded::Image(img, kind) => {
            if spec.entry.modality != Modality::Camera {
                bail!(
                    "{} is a LiDAR perturbation but {} is an image",
                    spec.entry.id,
                    a.input.display()
                );
            }
            let mut p = CameraPerturber::from_spec(spec)?;
            let out = p
                .apply_owned(&img.view(), a.seq)
                .with_context(|| format!("perturbing {}", a.input.display()))?;
            save_image(&a.output, &out.view(), kind)?;
        }
        Loaded::Cloud(cloud, kind, meta) => {
            if spec.entry.modality != Modality::Lidar {
                bail!(
                    "{} is a camera perturbation but {} is a point cloud",
                    spec.entry.id,
                    a.input.display()
                );
            }
            let sensor = sensor_for(Some(kind), a.sensor.as_deref(), a.intensity_max, false)?;
            let mut p = LidarPerturber::from_spec(spec, sensor)?;
            let out = p
                .apply_owned(&cloud.view(), a.seq, None)
                .with_context(|| format!("perturbing {}", a.input.display()))?;
            eprintln!("{} points in, {} out", cloud.len(), out.len());
            save_cloud(&a.output, &out.view(), kind, meta)?;
        }
    }
    Ok(())
}

fn apply_bag(a: &Args, spec: Spec) -> Result<()> {
    let bag = Bag::open(&a.input)?;
    let sensor = sensor_for(None, a.sensor.as_deref(), a.intensity_max, false)?;
    perturb_bag(
        &bag,
        &a.output,
        spec,
        a.seq,
        &sensor,
        &a.topic,
        false,
        &|| {},
    )?;
    Ok(())
}

/// Writes a copy of `bag` into the bag directory `out` with every message of the perturbation's
/// modality (on `topics`, or all topics when empty) perturbed, the others copied, and a
/// /perturb/events record per perturbed frame. The sequence number of a message is its index on its
/// topic plus `seq_offset`. Returns the number of input messages; damage in the input is an error
/// after the readable messages were written. `tick` is called once per input message.
#[allow(clippy::too_many_arguments)]
pub fn perturb_bag(
    bag: &Bag,
    out: &std::path::Path,
    spec: Spec,
    seq_offset: u64,
    sensor: &perturb_core::sensors::SensorModel,
    topics: &[String],
    quiet: bool,
    tick: &(dyn Fn() + Sync),
) -> Result<u64> {
    let mut w = BagWriter::create(out, &WriterOptions::default())?;
    let mut channel = HashMap::new();
    for t in &bag.topics()? {
        let id = w.add_topic_with_schema(
            &t.topic,
            &t.type_name,
            &t.schema_encoding,
            &t.schema,
            t.metadata.clone(),
        )?;
        channel.insert(t.topic.clone(), id);
    }
    let events = w.add_topic(EVENTS_TOPIC, EVENTS_TYPE)?;
    let mut camera = match spec.entry.modality {
        Modality::Camera => Some(CameraPerturber::from_spec(spec)?),
        Modality::Lidar => None,
    };
    let mut lidar = match spec.entry.modality {
        Modality::Lidar => Some(LidarPerturber::from_spec(spec, sensor.clone())?),
        Modality::Camera => None,
    };
    let mut index: HashMap<String, u64> = HashMap::new();
    let mut perturbed: HashMap<String, u64> = HashMap::new();
    let report = bag.for_each(&Filter::default(), |m| {
        tick();
        let ch = channel[m.topic];
        let selected = topics.is_empty() || topics.iter().any(|t| t == m.topic);
        let decoded = if selected { m.decode() } else { None };
        let (bytes, header) = match decoded {
            Some(Ok(msg)) => {
                let k = index.entry(m.topic.to_string()).or_default();
                let seq = *k + seq_offset;
                *k += 1;
                let out =
                    perturb_message(&msg, seq, camera.as_mut(), lidar.as_mut()).map_err(|e| {
                        perturb_bag::BagError::Callback(format!(
                            "{}: `{}` at log time {}: {e:#}",
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
        if let Some(((sec, nsec, frame), seq)) = header {
            *perturbed.entry(m.topic.to_string()).or_default() += 1;
            let ev = PerturbationEvent {
                topic: m.topic.to_string(),
                stream: None,
                seq,
                stamp_sec: sec,
                stamp_nanosec: nsec,
                frame_id: frame,
                id: Some(spec.entry.id.to_string()),
                severity: Some(spec.severity),
                seed: Some(spec.seed),
            };
            let json = serde_json::to_string(&ev).expect("event serialises");
            w.write(events, m.log_time, m.publish_time, &encode_string(&json))?;
        }
        Ok(ControlFlow::Continue(()))
    })?;
    let dir = w.finish()?;
    if !quiet {
        for (t, n) in &perturbed {
            eprintln!(
                "{t}: {n} messages perturbed with {} severity {}",
                spec.entry.id, spec.severity
            );
        }
        if perturbed.is_empty() {
            eprintln!(
                "warning: no {} message found to perturb",
                spec.entry.modality
            );
        }
        let events: u64 = perturbed.values().sum();
        eprintln!(
            "{} messages of the input and {events} /perturb/events records written to {}",
            report.delivered,
            dir.display()
        );
    }
    if let Some(d) = report.damage {
        bail!("the input bag is damaged; the messages before the damage were written: {d}");
    }
    Ok(report.delivered)
}

type HeaderOut = (i32, u32, String);

/// Perturbs one decoded sensor message if it belongs to the perturbation's modality; returns the
/// re-encoded message and its header, or None to copy it unchanged.
fn perturb_message(
    msg: &SensorMessage<'_>,
    seq: u64,
    camera: Option<&mut CameraPerturber>,
    lidar: Option<&mut LidarPerturber>,
) -> Result<Option<(Vec<u8>, HeaderOut)>> {
    let hdr = |h: &Header<'_>| (h.stamp_sec, h.stamp_nanosec, h.frame_id.to_string());
    match (msg, camera, lidar) {
        (SensorMessage::Image(img), Some(cam), _) => {
            let view = img.view()?;
            let mut out = Image::from_vec(
                vec![0; view.stride * view.height as usize],
                view.width,
                view.height,
                view.stride,
                view.format,
            )?;
            cam.apply(&view, &mut out.view_mut(), seq)?;
            let m = ImageMsg::from_view(img.header, &out.view());
            Ok(Some((m.encode(), hdr(&img.header))))
        }
        (SensorMessage::Compressed(c), Some(cam), _) => {
            let decoded = picture::decode(c.data)?;
            let out = cam.apply_owned(&decoded.view(), seq)?;
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
            Ok(Some((m.encode(), hdr(&c.header))))
        }
        (SensorMessage::Cloud(pc), _, Some(lid)) => {
            let view = pc.view()?;
            let out = lid.apply_owned(&view, seq, None)?;
            let m = PointCloud2Msg::from_view(pc.header, &out.view());
            Ok(Some((m.encode(), hdr(&pc.header))))
        }
        _ => Ok(None),
    }
}
