//! `perturb apply`: one file, or every sensor message of a bag.

use anyhow::{Context, Result, bail};
use perturb_bag::Bag;
use perturb_core::formats::FileKind;
use perturb_core::perturber::{CameraPerturber, LidarPerturber, Spec};
use perturb_core::registry::Modality;
use perturb_study::files::{Loaded, describe_sensor, load, save_cloud, save_image, sensor_for};
use std::path::PathBuf;

/// Arguments of `perturb apply`.
#[derive(clap::Args)]
#[command(after_help = "Examples:
  perturb apply --id C-C7 --severity 3 frame.png -o rainy.png
  perturb apply --id L-A9 --severity 2 --seed 7 scan.bin -o foggy.bin
  perturb apply --id C-A1 --severity 1 recording.mcap -o perturbed_bag --topic /camera/image_raw
  perturb apply --id L-B1 --severity 2 drive.bag -o perturbed.bag

The output keeps the input's format and layout (PNG stays PNG, a PCD keeps its fields and DATA
encoding, a bag keeps every topic; messages of the other modality are copied unchanged). A ROS 1
input (.bag, or ROS 1 profile MCAP) gives a ROS 1 .bag: OUT if it ends in .bag, else OUT/OUT.bag;
a rosbag2 input gives a rosbag2 bag directory. For a
bag, the sequence number of a message is its index on its topic plus --seq, and a
/perturb/events topic records which perturbation was applied to each frame.

Images in a bag may have any encoding of the encoding table (`perturb info` names it; Bayer
8/16 bit, YUV 4:2:2, mono16, rgb16, ... see docs/encodings.md): they are perturbed through an
8-bit working view and written back in their own encoding, size, step and byte order, the same
bytes perturbd writes for the same frame.")]
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
    /// LiDAR sensor model: vlp32c, vlp16, hdl32e, hdl64e (default: hdl64e for KITTI .bin, hdl32e for nuScenes .pcd.bin, vlp32c otherwise).
    #[arg(long)]
    sensor: Option<String>,
    /// LiDAR forward axis: +x, -x, +y or -y (default: +y for nuScenes .pcd.bin, +x otherwise).
    #[arg(long, allow_hyphen_values = true)]
    forward: Option<String>,
    /// Full-scale intensity of the cloud, 1 or 255 (default: the sensor model's).
    #[arg(long)]
    intensity_max: Option<f32>,
    /// For bags: only perturb these topics (repeatable; default all topics of the perturbation's modality).
    #[arg(long)]
    topic: Vec<String>,
    /// For bags: significant bits of 16-bit image samples (mono16, bayer_*16, ...), 9..16
    /// (default 16; 12 for a 12-bit sensor stored in 16-bit containers).
    #[arg(long, value_parser = clap::value_parser!(u8).range(9..=16))]
    bit_depth: Option<u8>,
    /// For bags: chunk compression of the output; rosbag2 zstd (the default), zstd:LEVEL
    /// (1..19), lz4 or none; ROS 1 none (the default), bz2 or lz4.
    #[arg(long)]
    compression: Option<String>,
    /// Input: .png .jpg .bin (KITTI) .pcd.bin (nuScenes) .pcd, a rosbag2 .mcap file or directory, or a ROS 1 .bag.
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
    if a.bit_depth.is_some() {
        bail!("--bit-depth applies to 16-bit image messages in bags, not to image files");
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
            let sensor = sensor_for(
                Some(kind),
                a.sensor.as_deref(),
                a.forward.as_deref(),
                a.intensity_max,
            )?;
            eprintln!("{}", describe_sensor(&sensor));
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
    let sensor = sensor_for(
        None,
        a.sensor.as_deref(),
        a.forward.as_deref(),
        a.intensity_max,
    )?;
    eprintln!("{}", describe_sensor(&sensor));
    let options = perturb_study::perturb_bag::BagOptions {
        seq_offset: a.seq,
        sensor,
        topics: a.topic.clone(),
        bit_depth: a.bit_depth,
        compression: a.compression.clone(),
    };
    perturb_study::perturb_bag::perturb_bag_with(
        &bag,
        &a.output,
        spec,
        &options,
        &crate::progress::Notes,
    )?;
    Ok(())
}
