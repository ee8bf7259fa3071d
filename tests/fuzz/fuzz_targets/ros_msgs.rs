//! CDR `sensor_msgs/Image`, `CompressedImage` and `PointCloud2` decoding, and the views the
//! bridge and the daemon build over them (the first byte picks the message type).
#![no_main]
perturb_fuzz::capped_allocator!();

use perturb_core::formats::ros::{CompressedImageMsg, ImageMsg, PointCloud2Msg};

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    let Some((&kind, msg)) = data.split_first() else {
        return;
    };
    match kind % 3 {
        0 => {
            if let Ok(m) = ImageMsg::decode(msg) {
                let _ = m.view();
            }
        }
        1 => {
            if let Ok(m) = CompressedImageMsg::decode(msg) {
                let _ = perturb_core::formats::picture::decode(m.data);
            }
        }
        _ => {
            if let Ok(m) = PointCloud2Msg::decode(msg)
                && let Ok(v) = m.view()
                && let Ok(xyz) = v.layout().xyz_readers()
            {
                for i in 0..v.len() {
                    let p = v.point(i);
                let _ = xyz.iter().map(|r| r.read_f32(p)).sum::<f32>();
                }
            }
        }
    }
});
