//! Every perturbation's output, hashed, against the hashes recorded in `tests/output_hashes.txt`:
//! a change of any byte of any perturbation at any severity, on the real KITTI frame and scan and on
//! odd synthetic sizes, fails here. Speed-ups must keep the bytes; a deliberate change of output
//! (a fix, a new model) re-records the file, and the commit says why:
//!
//! ```sh
//! PERTURB_BLESS=1 cargo test -p perturb-core --test output_hashes
//! git diff perturb-core/tests/output_hashes.txt   # exactly the perturbations meant to change
//! ```
//!
//! With `wide_and_baseline_code_give_the_same_bytes` (both CPU paths give the same bytes) this pins
//! the output of both paths. The real data's rows are checked only when `../shared/data` is there.

mod common;

use perturb_core::cloud::Cloud;
use perturb_core::image::{Image, PixelFormat, resize_bilinear};
use perturb_core::perturber::{CameraPerturber, LidarPerturber};
use perturb_core::registry::{Modality, of_modality};
use perturb_core::sensor_model::SensorModel;
use std::collections::BTreeMap;
use std::path::PathBuf;

/// FNV-1a, 64 bits: stable across platforms and Rust versions (the standard hasher is not).
fn fnv(bytes: &[u8]) -> u64 {
    bytes.iter().fold(0xcbf2_9ce4_8422_2325, |h, &b| {
        (h ^ b as u64).wrapping_mul(0x0000_0100_0000_01b3)
    })
}

fn recorded_path() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/output_hashes.txt")
}

/// A synthetic frame with gradients, hard edges, saturated and black pixels, in `format`.
fn synthetic(w: u32, h: u32, format: PixelFormat) -> Image {
    let mut img = Image::new(w, h, PixelFormat::Rgb8);
    for (i, p) in img.data.chunks_exact_mut(3).enumerate() {
        let (x, y) = (i % w as usize, i / w as usize);
        p[0] = (x * 255 / w.max(1) as usize) as u8;
        p[1] = (y * 255 / h.max(1) as usize) as u8;
        p[2] = ((x * 7 + y * 13) % 256) as u8;
        if (x / 9 + y / 5) % 7 == 0 {
            p.copy_from_slice(&[0, 0, 0]);
        } else if (x / 11 + y / 3) % 13 == 0 {
            p.copy_from_slice(&[255, 255, 250]);
        }
    }
    let mut out = img.convert(format);
    if let Some(a) = format.alpha_offset() {
        for (i, p) in out.data.chunks_exact_mut(4).enumerate() {
            p[a] = (i * 31 % 256) as u8;
        }
    }
    out
}

/// The camera inputs: odd sizes in three formats, and the KITTI frame at its own size and at the
/// paper's 800x503 when the real data is there.
fn camera_inputs() -> Vec<(String, Image)> {
    let mut inputs: Vec<(String, Image)> = [
        (203, 61, PixelFormat::Rgb8),
        (67, 29, PixelFormat::Bgra8),
        (45, 17, PixelFormat::Mono8),
        (5, 3, PixelFormat::Bgr8),
    ]
    .into_iter()
    .map(|(w, h, f)| (format!("synthetic {w}x{h} {f}"), synthetic(w, h, f)))
    .collect();
    if let Some(frame) = common::kitti_image("output_hashes (camera, real frame)", 0) {
        let scaled = resize_bilinear(&frame.view(), 800, 503);
        inputs.push(("kitti 000000 800x503 rgb8".into(), scaled));
        let odd = resize_bilinear(&frame.view(), 641, 403).convert(PixelFormat::Rgba8);
        inputs.push(("kitti 000000 641x403 rgba8".into(), odd));
    }
    inputs
}

fn camera_hashes() -> BTreeMap<String, String> {
    let mut out = BTreeMap::new();
    for (name, img) in camera_inputs() {
        for e in of_modality(Modality::Camera) {
            for s in e.severities() {
                let key = format!("{} s{s} {name}", e.id);
                let value = match CameraPerturber::new(e.id, s, 7)
                    .and_then(|mut p| p.apply_owned(&img.view(), 11))
                {
                    Ok(o) => format!("{:016x}", fnv(&o.data)),
                    Err(err) => format!("error: {err}"),
                };
                out.insert(key, value);
            }
        }
    }
    out
}

fn lidar_hashes() -> BTreeMap<String, String> {
    let mut out = BTreeMap::new();
    let Some(scan) = common::kitti_scan("output_hashes (lidar, real scan)", 0) else {
        return out;
    };
    // Every third point of the scan: a real cloud, a third of the test time.
    let layout = scan.layout.clone();
    let step = layout.point_step as usize;
    let data: Vec<u8> = scan
        .data
        .chunks_exact(step)
        .step_by(3)
        .flatten()
        .copied()
        .collect();
    let n = data.len() / step;
    let cloud = Cloud::from_vec(layout, data, n as u32, 1, n * step, true).unwrap();
    for e in of_modality(Modality::Lidar) {
        for s in e.severities() {
            let key = format!("{} s{s} kitti 000000 every third point", e.id);
            let value = match LidarPerturber::new(e.id, s, 7, SensorModel::hdl64e())
                .and_then(|mut p| p.apply_owned(&cloud.view(), 11, None))
            {
                Ok(o) => format!("{:016x} {} points", fnv(&o.data), o.len()),
                Err(err) => format!("error: {err}"),
            };
            out.insert(key, value);
        }
    }
    out
}

#[test]
fn outputs_match_the_recorded_hashes() {
    let mut got = camera_hashes();
    got.extend(lidar_hashes());
    let path = recorded_path();
    if std::env::var("PERTURB_BLESS").is_ok_and(|v| v == "1") {
        // Keep the rows of inputs this machine does not have (the real data's, without it).
        let mut all = read_recorded(&path);
        all.extend(got);
        let text: String = all.iter().map(|(k, v)| format!("{k}: {v}\n")).collect();
        std::fs::write(&path, text).unwrap();
        eprintln!("recorded {} hashes in {}", all.len(), path.display());
        return;
    }
    let recorded = read_recorded(&path);
    let mut differ = Vec::new();
    for (k, v) in &got {
        match recorded.get(k) {
            Some(r) if r == v => {}
            Some(r) => differ.push(format!("{k}: recorded {r}, now {v}")),
            None => differ.push(format!("{k}: not recorded (now {v})")),
        }
    }
    assert!(
        differ.is_empty(),
        "{} of {} outputs differ from {} (PERTURB_BLESS=1 re-records them after a deliberate \
         change):\n{}",
        differ.len(),
        got.len(),
        path.display(),
        differ.join("\n")
    );
}

fn read_recorded(path: &PathBuf) -> BTreeMap<String, String> {
    let text = std::fs::read_to_string(path).unwrap_or_default();
    text.lines()
        .filter_map(|l| l.split_once(": "))
        .map(|(k, v)| (k.to_string(), v.to_string()))
        .collect()
}
