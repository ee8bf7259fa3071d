//! PCD decoding (ascii, binary, binary_compressed), then a read of every point's x, y, z.
#![no_main]
perturb_fuzz::capped_allocator!();

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    if let Ok(f) = perturb_core::formats::pcd::decode(data) {
        let v = f.cloud.view();
        if let Ok(xyz) = v.layout().xyz_readers() {
            for i in 0..v.len() {
                let p = v.point(i);
                let _ = xyz.iter().map(|r| r.read_f32(p)).sum::<f32>();
            }
        }
    }
});
