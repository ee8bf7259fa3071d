//! `perturb demo --offline`: every perturbation once, in this process, on a synthetic frame and scan.

use anyhow::{Context, Result};
use perturb_core::formats::FileKind;
use perturb_core::perturber::{CameraPerturber, LidarPerturber};
use perturb_core::registry::{Modality, of_modality};
use perturb_core::sensor_model::SensorModel;
use perturb_core::synthetic::{street_image, vlp32c_scan};
use perturb_study::files::{save_cloud, save_image};
use std::path::Path;
use std::time::Instant;

/// Generates a synthetic street frame and VLP-32C scan, applies every implemented perturbation at
/// its middle severity, writes the results and prints the latency of each.
pub fn run(out: &Path, width: u32, height: u32) -> Result<()> {
    std::fs::create_dir_all(out).with_context(|| format!("cannot create {}", out.display()))?;
    let frame = street_image(width, height, 0);
    let scan = vlp32c_scan(0);
    save_image(&out.join("clean.png"), &frame.view(), FileKind::Png)?;
    save_cloud(&out.join("clean.pcd"), &scan.view(), FileKind::Pcd, None)?;
    println!(
        "synthetic camera {}x{} and VLP-32C scan ({} points) in {}",
        width,
        height,
        scan.len(),
        out.display()
    );
    println!(
        "{:<7} {:<24} {:>3} {:>9}  output",
        "id", "name", "sev", "ms"
    );
    for e in of_modality(Modality::Camera) {
        let s = 3;
        let mut p = CameraPerturber::new(e.id, s, 1)?;
        p.prepare(frame.geometry())?;
        let t = Instant::now();
        let perturbed = p.apply_owned(&frame.view(), 0)?;
        let ms = t.elapsed().as_secs_f64() * 1e3;
        let path = out.join(format!("{}_{}_s{s}.png", e.id, e.name));
        save_image(&path, &perturbed.view(), FileKind::Png)?;
        println!(
            "{:<7} {:<24} {:>3} {:>9.2}  {}",
            e.id,
            e.name,
            s,
            ms,
            path.display()
        );
    }
    for e in of_modality(Modality::Lidar) {
        let s = 2;
        let mut p = LidarPerturber::new(e.id, s, 1, SensorModel::vlp32c())?;
        let t = Instant::now();
        let perturbed = p.apply_owned(&scan.view(), 0, None)?;
        let ms = t.elapsed().as_secs_f64() * 1e3;
        let path = out.join(format!("{}_{}_s{s}.pcd", e.id, e.name));
        save_cloud(&path, &perturbed.view(), FileKind::Pcd, None)?;
        println!(
            "{:<7} {:<24} {:>3} {:>9.2}  {} ({} points)",
            e.id,
            e.name,
            s,
            ms,
            path.display(),
            perturbed.len()
        );
    }
    Ok(())
}
