//! Shared helpers of the integration tests: the real recorded data in `../shared/data`.
#![allow(dead_code)]

use perturb_core::cloud::{Cloud, Datatype, PointField, PointLayout};
use perturb_core::formats::{kitti, picture};
use perturb_core::image::{Image, resize_bilinear};
use std::path::{Path, PathBuf};
use std::sync::Arc;

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

/// The first PointCloud2 of a ROS 1 MCAP (the `ros1` profile: ROS 1 serialisation), decoded by
/// hand (little-endian, u32 length prefixes), with its frame id.
pub fn ros1_cloud(path: &Path) -> (Cloud, String) {
    let bytes = std::fs::read(path).expect("read mcap");
    for m in mcap::MessageStream::new(&bytes).expect("mcap") {
        let m = m.expect("message");
        let schema = m.channel.schema.as_ref().map(|s| s.name.as_str());
        if schema != Some("sensor_msgs/PointCloud2") {
            continue;
        }
        let d = &m.data[..];
        let mut o = 0usize;
        let mut u32_ = || {
            let v = u32::from_le_bytes(d[o..o + 4].try_into().unwrap());
            o += 4;
            v
        };
        let (_seq, _sec, _nsec) = (u32_(), u32_(), u32_());
        let len = u32_() as usize;
        let frame = String::from_utf8(d[o..o + len].to_vec()).unwrap();
        o += len;
        let u32_ = |o: &mut usize| {
            let v = u32::from_le_bytes(d[*o..*o + 4].try_into().unwrap());
            *o += 4;
            v
        };
        let height = u32_(&mut o);
        let width = u32_(&mut o);
        let nf = u32_(&mut o);
        let mut fields = Vec::new();
        for _ in 0..nf {
            let l = u32_(&mut o) as usize;
            let name = String::from_utf8(d[o..o + l].to_vec()).unwrap();
            o += l;
            let offset = u32_(&mut o);
            let dt = d[o];
            o += 1;
            let count = u32_(&mut o);
            let mut f = PointField::new(&name, offset, Datatype::from_code(dt).expect("datatype"));
            f.count = count;
            fields.push(f);
        }
        let big_endian = d[o] != 0;
        o += 1;
        let step = u32_(&mut o);
        let row_step = u32_(&mut o);
        let n = u32_(&mut o) as usize;
        let data = d[o..o + n].to_vec();
        let layout = Arc::new(PointLayout::new(fields, step, big_endian).unwrap());
        let cloud =
            Cloud::from_vec(layout, data, width, height, row_step as usize, true).expect("cloud");
        return (cloud, frame);
    }
    panic!("no PointCloud2 in {}", path.display());
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
