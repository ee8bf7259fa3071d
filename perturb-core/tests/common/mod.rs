//! Shared helpers of the integration tests: the real recorded data in `../shared/data`.
#![allow(dead_code)]

use perturb_core::cloud::Cloud;
use perturb_core::formats::{kitti, picture};
use perturb_core::image::{Image, resize_bilinear};
use std::path::PathBuf;

/// `../shared/data` (or `$PERTURB_SHARED_DATA`), or `None` with a message saying the test skips
/// (a failure under `CI=true`, where the data must be there).
pub fn shared_data(test: &str) -> Option<PathBuf> {
    let dir = std::env::var_os("PERTURB_SHARED_DATA")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../shared/data"));
    if dir.is_dir() {
        Some(dir)
    } else {
        assert!(
            std::env::var("CI").ok().as_deref() != Some("true"),
            "{test}: real data not found at {} and CI=true (set PERTURB_SHARED_DATA)",
            dir.display()
        );
        eprintln!(
            "skipping {test}: real data not found at {} (set PERTURB_SHARED_DATA)",
            dir.display()
        );
        None
    }
}

/// KITTI frame `000000` or `000001` (rgb8).
pub fn kitti_image(test: &str, idx: u32) -> Option<Image> {
    let p = shared_data(test)?.join(format!("kitti/image_2/{idx:06}.png"));
    Some(picture::decode(&std::fs::read(&p).expect("read KITTI png")).expect("decode KITTI png"))
}

/// A KITTI frame scaled to `w` x `h`.
pub fn kitti_image_scaled(test: &str, w: u32, h: u32) -> Option<Image> {
    let img = kitti_image(test, 0)?;
    Some(resize_bilinear(&img.view(), w, h))
}

/// KITTI scan `000000` or `000001` (float32 x, y, z, reflectance; about 120k points).
pub fn kitti_scan(test: &str, idx: u32) -> Option<Cloud> {
    let p = shared_data(test)?.join(format!("kitti/velodyne/{idx:06}.bin"));
    Some(
        kitti::decode_kitti(&std::fs::read(&p).expect("read KITTI bin")).expect("decode KITTI bin"),
    )
}
