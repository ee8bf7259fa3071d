//! Times the perturbations on a real KITTI frame or scan, single-threaded.
//!
//! ```text
//! cargo run --release -p perturb-core --example bench -- camera 1920 1208 [ID ...]
//! cargo run --release -p perturb-core --example bench -- lidar [ID ...]
//! cargo run --release -p perturb-core --example bench -- detector
//! ```
//! The data comes from `../shared/data` (or `$PERTURB_SHARED_DATA`); `PERTURB_BENCH_FRAMES` sets
//! the frames timed per severity (default 10). `perturb bench` is the full
//! report; this example is the quick loop while working on one perturbation.

use perturb_core::bench::{Timing, time_camera, time_lidar};
use perturb_core::formats::{kitti, picture};
use perturb_core::image::resize_bilinear;
use perturb_core::registry::{Modality, of_modality};
use perturb_core::sensor_model::SensorModel;
use std::path::PathBuf;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let data = std::env::var_os("PERTURB_SHARED_DATA")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from("../shared/data"));
    let modality = args.first().map(String::as_str).unwrap_or("camera");
    let pool = rayon::ThreadPoolBuilder::new().num_threads(1).build()?;
    // Frames timed per perturbation and severity (the median is reported).
    let frames: usize = std::env::var("PERTURB_BENCH_FRAMES").map_or(Ok(10), |s| s.parse())?;
    let mut rows: Vec<Timing> = Vec::new();
    if modality == "detector" {
        return detector(&data);
    }
    if modality == "camera" {
        let w: u32 = args.get(1).map_or(Ok(1920), |s| s.parse())?;
        let h: u32 = args.get(2).map_or(Ok(1208), |s| s.parse())?;
        let ids = &args[3.min(args.len())..];
        let frame = picture::decode(&std::fs::read(data.join("kitti/image_2/000000.png"))?)?;
        let frame = resize_bilinear(&frame.view(), w, h);
        for e in of_modality(Modality::Camera) {
            if !ids.is_empty() && !ids.iter().any(|i| i.eq_ignore_ascii_case(e.id)) {
                continue;
            }
            for s in e.severities() {
                rows.push(pool.install(|| time_camera(e, s, 1, &frame.view(), frames))?);
            }
        }
    } else {
        let ids = &args[1.min(args.len())..];
        let scan = kitti::decode_kitti(&std::fs::read(data.join("kitti/velodyne/000000.bin"))?)?;
        let sensor = SensorModel::hdl64e();
        for e in of_modality(Modality::Lidar) {
            if !ids.is_empty() && !ids.iter().any(|i| i.eq_ignore_ascii_case(e.id)) {
                continue;
            }
            for s in e.severities() {
                rows.push(pool.install(|| time_lidar(e, s, 1, &sensor, &scan.view(), frames))?);
            }
        }
    }
    println!(
        "{:<7} {:<24} {:>3} {:>10} {:>10} {:>10}",
        "id", "name", "sev", "setup_ms", "median_ms", "max_ms"
    );
    for t in rows {
        println!(
            "{:<7} {:<24} {:>3} {:>10.2} {:>10.2} {:>10.2}",
            t.id, t.name, t.severity, t.setup_ms, t.median_ms, t.max_ms
        );
    }
    Ok(())
}

/// The clustering detector alone on the KITTI scans: median of 20 runs per scan.
fn detector(data: &std::path::Path) -> Result<(), Box<dyn std::error::Error>> {
    use perturb_core::detector::{Detector, DetectorConfig};
    use perturb_core::lidar::Points;
    for f in ["kitti/velodyne/000000.bin", "kitti/velodyne/000001.bin"] {
        let scan = kitti::decode_kitti(&std::fs::read(data.join(f))?)?;
        let p = Points::extract(&scan.view(), &SensorModel::hdl64e(), false)?;
        let mut d = Detector::new(DetectorConfig::default());
        let mut times: Vec<f64> = (0..20)
            .map(|_| {
                let t = std::time::Instant::now();
                std::hint::black_box(d.detect(&p));
                t.elapsed().as_secs_f64() * 1e3
            })
            .collect();
        times.sort_by(f64::total_cmp);
        println!(
            "{f}: {} points, detect median {:.2} ms, max {:.2} ms",
            p.len(),
            times[10],
            times[19]
        );
    }
    Ok(())
}
