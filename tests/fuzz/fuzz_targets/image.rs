//! PNG and JPEG decoding (`perturb_core::formats::picture::decode`), then a view of the result.
#![no_main]
perturb_fuzz::capped_allocator!();

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    if let Ok(img) = perturb_core::formats::picture::decode(data) {
        let v = img.view();
        assert!(v.data().len() >= v.geometry().row_bytes() * v.height as usize);
    }
});
