//! `sensor_msgs/Image`, `CompressedImage` and `PointCloud2` decoding in CDR (ROS 2) and in the
//! ROS 1 serialization, and the views the bridge and the daemon build over them (the first byte
//! picks the message type and the encoding).
#![no_main]
perturb_fuzz::capped_allocator!();

use perturb_core::formats::ros::{CompressedImageMsg, ImageMsg, PointCloud2Msg};

fn image(m: ImageMsg<'_>) {
    let _ = m.view();
}

fn compressed(m: CompressedImageMsg<'_>) {
    let _ = perturb_core::formats::picture::decode(m.data);
}

fn cloud(m: PointCloud2Msg<'_>) {
    if let Ok(v) = m.view()
        && let Ok(xyz) = v.layout().xyz_readers()
    {
        for i in 0..v.len() {
            let p = v.point(i);
            let _ = xyz.iter().map(|r| r.read_f32(p)).sum::<f32>();
        }
    }
}

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    let Some((&kind, msg)) = data.split_first() else {
        return;
    };
    match kind % 6 {
        0 => ImageMsg::decode(msg).map(image).unwrap_or(()),
        1 => CompressedImageMsg::decode(msg).map(compressed).unwrap_or(()),
        2 => PointCloud2Msg::decode(msg).map(cloud).unwrap_or(()),
        3 => ImageMsg::decode_ros1(msg).map(|m| image(m.1)).unwrap_or(()),
        4 => CompressedImageMsg::decode_ros1(msg)
            .map(|m| compressed(m.1))
            .unwrap_or(()),
        _ => PointCloud2Msg::decode_ros1(msg)
            .map(|m| cloud(m.1))
            .unwrap_or(()),
    }
});
