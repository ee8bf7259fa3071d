//! `perturb detect`: the clustering detector on one point-cloud file.

use anyhow::{Context, Result, bail};
use perturb_core::detector::{Detector, DetectorConfig};
use perturb_core::lidar::{Box3, Points};
use perturb_core::sensors::SensorModel;
use perturb_study::files::{Loaded, load};
use std::path::PathBuf;

/// Arguments of `perturb detect`.
#[derive(clap::Args)]
#[command(
    after_help = "The detector is the one the LiDAR metrics and the object-level perturbations use, after
Autoware Mini's lidar_cluster: crop to x, y in [-60, 60) m and z in [-2.5, 0.1) m (sensor frame,
ego box removed), grid ground removal (0.6 m cells, 0.15 m tolerance), 0.25 m voxel grid, DBSCAN
(eps 0.7 m, 4 samples), minimum-area boxes. It has no classifier: walls and vegetation are
clusters too (--objects drops the ones too large to be a road user).

Output: one box per line, centre x y z and size length width height in metres, heading (yaw,
radians, the direction of the length, in (-pi/2, pi/2]) and the number of scan points inside the
box; --json prints an array of {\"center\": [x,y,z], \"size\": [l,w,h], \"yaw\": rad, \"points\": n}.

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
    /// LiDAR sensor model used to read the cloud: vlp32c, vlp16, hdl32e, hdl64e (only the
    /// intensity scale depends on it; the detector uses x, y, z).
    #[arg(long)]
    pub sensor: Option<String>,
    /// Drop clusters too large to be a road user (longer than 20 m or over 50 m^2).
    #[arg(long)]
    pub objects: bool,
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
    /// Points of the scan inside the box.
    pub points: usize,
}

/// The number of points of `p` inside each box.
pub fn points_in_boxes(p: &Points, boxes: &[Box3]) -> Vec<usize> {
    /// A box prepared for the point test: centre, cos and sin of the heading, half sizes, and
    /// the squared radius of its footprint for a quick rejection.
    struct Pre {
        ctr: [f32; 3],
        c: f32,
        s: f32,
        h: [f32; 3],
        r2: f32,
    }
    let pre: Vec<Pre> = boxes
        .iter()
        .map(|b| {
            let (s, c) = b.yaw.sin_cos();
            let h = [b.size[0] * 0.5, b.size[1] * 0.5, b.size[2] * 0.5];
            Pre {
                ctr: b.center,
                c,
                s,
                h,
                r2: (h[0] * h[0] + h[1] * h[1]) * 1.0001 + 1e-6,
            }
        })
        .collect();
    let mut counts = vec![0; boxes.len()];
    for i in 0..p.len() {
        let (x, y, z) = (p.x[i], p.y[i], p.z[i]);
        for (k, b) in pre.iter().enumerate() {
            let (dx, dy, dz) = (x - b.ctr[0], y - b.ctr[1], z - b.ctr[2]);
            if dx * dx + dy * dy > b.r2 || dz.abs() > b.h[2] {
                continue;
            }
            let lx = dx * b.c + dy * b.s;
            let ly = dy * b.c - dx * b.s;
            if lx.abs() <= b.h[0] && ly.abs() <= b.h[1] {
                counts[k] += 1;
            }
        }
    }
    counts
}

/// Runs `perturb detect`.
pub fn run(a: Args) -> Result<()> {
    let cloud = match load(&a.scan)? {
        Loaded::Cloud(c, _, _) => c,
        Loaded::Image(..) => bail!(
            "{} is an image; `perturb detect` needs a point cloud (.bin .pcd.bin .pcd)",
            a.scan.display()
        ),
    };
    let sensor = match a.sensor.as_deref() {
        Some(s) => SensorModel::by_name(s)?,
        None => SensorModel::default(),
    };
    let p = Points::extract(&cloud.view(), &sensor, false)
        .with_context(|| format!("reading the points of {}", a.scan.display()))?;
    let config = if a.objects {
        DetectorConfig::objects()
    } else {
        DetectorConfig::default()
    };
    let boxes = Detector::new(config).detect(&p);
    let counts = points_in_boxes(&p, &boxes);
    let dets: Vec<Detection> = boxes
        .iter()
        .zip(&counts)
        .map(|(b, &n)| Detection {
            center: b.center,
            size: b.size,
            yaw: b.yaw,
            points: n,
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
        "{:>4} {:>8} {:>8} {:>7} {:>7} {:>6} {:>6} {:>7} {:>7}",
        "#", "x", "y", "z", "length", "width", "height", "yaw", "points"
    );
    for (i, d) in dets.iter().enumerate() {
        println!(
            "{:>4} {:>8.2} {:>8.2} {:>7.2} {:>7.2} {:>6.2} {:>6.2} {:>7.3} {:>7}",
            i,
            d.center[0],
            d.center[1],
            d.center[2],
            d.size[0],
            d.size[1],
            d.size[2],
            d.yaw,
            d.points
        );
    }
    Ok(())
}
