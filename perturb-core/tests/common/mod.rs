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

/// One module per catalogue entry of `$modality`, named after its ID (`c_a1`, `l_b3`), holding a
/// `#[test]` per property function of `$tests` (each `fn(&Entry)` in the calling file): `cargo
/// test -p perturb-core c_a1` checks one perturbation, and a failure in one entry does not hide
/// the others. A further test checks the entries listed are the catalogue's, in its order, so a
/// new perturbation needs its line.
#[allow(unused_macros)]
macro_rules! per_entry {
    ($modality:expr, $tests:tt, { $($module:ident => $id:literal),* $(,)? }) => {
        $( per_entry_module!($module, $id, $tests); )*

        #[test]
        fn every_entry_has_its_tests() {
            let listed = [$($id),*];
            let catalogue: Vec<&str> = perturb_core::registry::of_modality($modality)
                .map(|e| e.id)
                .collect();
            assert_eq!(listed.to_vec(), catalogue);
        }
    };
}

/// The module of one entry (see [`per_entry`]).
#[allow(unused_macros)]
macro_rules! per_entry_module {
    ($module:ident, $id:literal, [$($test:ident),* $(,)?]) => {
        mod $module {
            fn entry() -> &'static perturb_core::registry::Entry {
                perturb_core::find($id).expect("in the catalogue")
            }
            $(
                #[test]
                fn $test() {
                    super::$test(entry());
                }
            )*
        }
    };
}
