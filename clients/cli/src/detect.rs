//! `perturb detect`: the clustering detector on one point-cloud file.

use anyhow::{Context, Result, bail};
use perturb_core::detector::{Detector, DetectorConfig, ObjectClass, points_in_boxes};
use perturb_core::lidar::{Box3, Points};
use perturb_study::files::{Loaded, describe_sensor, load, sensor_for};
use std::path::PathBuf;

/// Arguments of `perturb detect`.
#[derive(clap::Args)]
#[command(
    after_help = "The detector is the one the LiDAR metrics and the object-level perturbations use, after
Autoware Mini's lidar_cluster: x, y within 60 m (ego box removed), a ground that follows the
terrain (0.6 m cells, slopes up to 0.2), DBSCAN above it (0.25 m voxels, eps 0.5 m, 4 samples),
clusters longer than a bus split or dropped, L-shape boxes with a heading, and a class per box
from its shape: vehicle, pedestrian (pedestrian or cyclist sized) or other. It works in the
sensor's canonical frame (x forward, z up; --forward says which axis is forward) and prints
boxes in the cloud's own frame.

Output: one box per line, centre x y z and size length width height in metres, heading (yaw,
radians, about +z), class and the number of scan points inside the box; --json prints an array
of {\"center\": [x,y,z], \"size\": [l,w,h], \"yaw\": rad, \"class\": \"vehicle\", \"points\": n}.

Examples:
  perturb detect scan.bin
  perturb detect scan.pcd --json | jq length
  perturb apply --id L-B1 --severity 3 scan.bin -o thin.bin && perturb detect thin.bin"
)]
pub struct Args {
    /// Point-cloud file: KITTI .bin, nuScenes .pcd.bin or .pcd.
    pub scan: PathBuf,
    /// Print JSON instead of a table.
    #[arg(long)]
    pub json: bool,
    /// LiDAR sensor model used to read the cloud: vlp32c, vlp16, hdl32e, hdl64e (default:
    /// hdl64e for KITTI .bin, hdl32e for nuScenes .pcd.bin, vlp32c otherwise).
    #[arg(long)]
    pub sensor: Option<String>,
    /// LiDAR forward axis: +x, -x, +y or -y (default: +y for nuScenes .pcd.bin, +x otherwise).
    #[arg(long, allow_hyphen_values = true)]
    pub forward: Option<String>,
    /// Only the boxes classed as road users (vehicle, pedestrian).
    #[arg(long)]
    pub objects: bool,
    /// Only the boxes of this class: vehicle, pedestrian or other.
    #[arg(long)]
    pub class: Option<String>,
}

/// A detected box and the scan points inside it.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct Detection {
    /// Centre [x, y, z], metres, sensor frame.
    pub center: [f32; 3],
    /// [length, width, height], metres.
    pub size: [f32; 3],
    /// Heading of the length, radians.
    pub yaw: f32,
    /// `vehicle`, `pedestrian` (pedestrian or cyclist sized) or `other`.
    pub class: ObjectClass,
    /// Points of the scan inside the box.
    pub points: usize,
}

/// Runs `perturb detect`.
pub fn run(a: Args) -> Result<()> {
    let (cloud, kind) = match load(&a.scan)? {
        Loaded::Cloud(c, kind, _) => (c, kind),
        Loaded::Image(..) => bail!(
            "{} is an image; `perturb detect` needs a point cloud (.bin .pcd.bin .pcd)",
            a.scan.display()
        ),
    };
    let sensor = sensor_for(Some(kind), a.sensor.as_deref(), a.forward.as_deref(), None)?;
    if !a.json {
        eprintln!("{}", describe_sensor(&sensor));
    }
    let p = Points::extract(&cloud.view(), &sensor, false)
        .with_context(|| format!("reading the points of {}", a.scan.display()))?;
    let config = match (&a.class, a.objects) {
        (Some(c), _) => DetectorConfig::only(
            ObjectClass::parse(c).map_err(|e| anyhow::anyhow!("--class: {e}"))?,
        ),
        (None, true) => DetectorConfig::objects(),
        (None, false) => DetectorConfig::default(),
    };
    let found = Detector::new(config).detect_classified(&p);
    let boxes: Vec<Box3> = found.iter().map(|d| d.bbox).collect();
    let counts = points_in_boxes(&p, &boxes);
    let dets: Vec<Detection> = found
        .iter()
        .zip(&counts)
        .map(|(d, &n)| {
            // Reported in the cloud's own frame.
            let b = d.bbox.to_sensor(&sensor.axes);
            Detection {
                center: b.center,
                size: b.size,
                yaw: b.yaw,
                class: d.class,
                points: n,
            }
        })
        .collect();
    if a.json {
        // One object per line: readable, and easy to grep or diff.
        let lines = dets
            .iter()
            .map(serde_json::to_string)
            .collect::<serde_json::Result<Vec<_>>>()?;
        if lines.is_empty() {
            println!("[]");
        } else {
            println!("[\n  {}\n]", lines.join(",\n  "));
        }
        return Ok(());
    }
    println!(
        "{}: {} points, {} detections",
        a.scan.display(),
        p.len(),
        dets.len()
    );
    println!(
        "{:>4} {:>8} {:>8} {:>7} {:>7} {:>6} {:>6} {:>7} {:<10} {:>7}",
        "#", "x", "y", "z", "length", "width", "height", "yaw", "class", "points"
    );
    for (i, d) in dets.iter().enumerate() {
        println!(
            "{:>4} {:>8.2} {:>8.2} {:>7.2} {:>7.2} {:>6.2} {:>6.2} {:>7.3} {:<10} {:>7}",
            i,
            d.center[0],
            d.center[1],
            d.center[2],
            d.size[0],
            d.size[1],
            d.size[2],
            d.yaw,
            d.class.as_str(),
            d.points
        );
    }
    Ok(())
}
