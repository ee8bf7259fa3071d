//! Inputs shared by the criterion benches: the real KITTI frame and scan from `../shared/data`
//! (or `$PERTURB_SHARED_DATA`), scaled to the sizes the budgets are stated for.

use perturb_core::cloud::Cloud;
use perturb_core::formats::{kitti, picture};
use perturb_core::image::{Image, resize_bilinear};
use std::path::PathBuf;

/// The shared data directory, if present.
pub fn shared_data() -> Option<PathBuf> {
    let dir = std::env::var_os("PERTURB_SHARED_DATA")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../shared/data"));
    if dir.is_dir() {
        Some(dir)
    } else {
        eprintln!(
            "benchmarks need the real data at {} (set PERTURB_SHARED_DATA); skipping",
            dir.display()
        );
        None
    }
}

/// KITTI frame 000000 scaled to `w` x `h` (800x503 is the paper's frame, 1920x1208 the vehicle's).
pub fn kitti_frame(w: u32, h: u32) -> Option<Image> {
    let p = shared_data()?.join("kitti/image_2/000000.png");
    let img = picture::decode(&std::fs::read(p).ok()?).ok()?;
    Some(resize_bilinear(&img.view(), w, h))
}

/// KITTI scan 000000 (HDL-64E, about 115k points).
pub fn kitti_scan() -> Option<Cloud> {
    let p = shared_data()?.join("kitti/velodyne/000000.bin");
    kitti::decode_kitti(&std::fs::read(p).ok()?).ok()
}

/// A VLP-32C-sized cloud (about 58k points): every other point of the KITTI scan, which keeps its
/// real spatial structure at the point count of one VLP-32C revolution at 10 Hz.
pub fn vlp32c_sized_scan() -> Option<Cloud> {
    let full = kitti_scan()?;
    let step = full.layout.point_step as usize;
    let mut data = Vec::with_capacity(full.data.len() / 2);
    for p in full.data.chunks_exact(step).step_by(2) {
        data.extend_from_slice(p);
    }
    let n = data.len() / step;
    Cloud::from_vec(
        full.layout.clone(),
        data,
        n as u32,
        1,
        n * step,
        full.is_dense,
    )
    .ok()
}

/// A one-thread rayon pool, for the single-core figures.
pub fn single_thread() -> rayon::ThreadPool {
    rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .expect("thread pool")
}
