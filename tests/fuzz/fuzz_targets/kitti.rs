//! KITTI velodyne `.bin` and nuScenes `.pcd.bin` decoding.
#![no_main]
perturb_fuzz::capped_allocator!();

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    if let Ok(c) = perturb_core::formats::kitti::decode_kitti(data) {
        assert_eq!(c.len() * 16, data.len());
    }
    let _ = perturb_core::formats::kitti::decode_nuscenes(data);
});
