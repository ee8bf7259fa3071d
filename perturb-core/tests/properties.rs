//! Property tests over image and cloud geometry: many random sizes, formats, strides and clouds,
//! where the catalogue tests use a few fixed ones.

use perturb_core::CameraPerturber;
use perturb_core::cloud::{Cloud, CloudView, Datatype, PointField, PointLayout};
use perturb_core::formats::pcd::{self, PcdData};
use perturb_core::image::{ImageView, ImageViewMut, PixelFormat};
use proptest::prelude::*;
use std::sync::Arc;

/// Random bytes of `len` from `seed` (a cheap generator: proptest picks the seed).
fn bytes(seed: u64, len: usize) -> Vec<u8> {
    let mut x = seed | 1;
    (0..len)
        .map(|_| {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            (x >> 24) as u8
        })
        .collect()
}

fn format() -> impl Strategy<Value = PixelFormat> {
    (0..PixelFormat::ALL.len()).prop_map(|i| PixelFormat::ALL[i])
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 200, ..ProptestConfig::default() })]

    /// A view needs exactly `stride (h - 1) + w c` bytes and a stride of at least a row; its rows
    /// are the pixel bytes without the padding.
    #[test]
    fn image_views_accept_exactly_the_bytes_their_geometry_needs(
        w in 1u32..48, h in 1u32..48, f in format(), pad in 0usize..9, seed in any::<u64>()
    ) {
        let row = w as usize * f.channels();
        let stride = row + pad;
        let need = stride * (h as usize - 1) + row;
        let data = bytes(seed, need);
        let view = ImageView::new(&data, w, h, stride, f).unwrap();
        for y in 0..h as usize {
            prop_assert_eq!(view.row(y), &data[y * stride..y * stride + row]);
        }
        prop_assert!(ImageView::new(&data[..need - 1], w, h, stride, f).is_err());
        if row > 1 {
            prop_assert!(ImageView::new(&data, w, h, row - 1, f).is_err());
        }
    }

    /// A perturbation writes the same pixels whatever the strides of its input and output: the
    /// padding is neither read nor written.
    #[test]
    fn perturbations_ignore_the_padding_of_both_buffers(
        w in 1u32..40, h in 1u32..40, f in format(), pad_in in 0usize..9, pad_out in 1usize..9,
        which in 0usize..4, severity in 1u8..=5, seed in any::<u64>()
    ) {
        let id = ["C-C6", "C-F7", "C-A1", "C-B3"][which];
        let row = w as usize * f.channels();
        let tight = bytes(seed, row * h as usize);
        let (si, so) = (row + pad_in, row + pad_out);
        let mut padded = vec![0xA5u8; si * h as usize];
        for y in 0..h as usize {
            padded[y * si..y * si + row].copy_from_slice(&tight[y * row..(y + 1) * row]);
        }
        let mut p = CameraPerturber::new(id, severity, seed).unwrap();
        let want = p.apply_owned(&ImageView::new(&tight, w, h, row, f).unwrap(), 3).unwrap();
        let mut out = vec![0x5Au8; so * h as usize];
        let input = ImageView::new(&padded, w, h, si, f).unwrap();
        let mut output = ImageViewMut::new(&mut out, w, h, so, f).unwrap();
        p.apply(&input, &mut output, 3).unwrap();
        for y in 0..h as usize {
            prop_assert_eq!(&out[y * so..y * so + row], &want.data[y * row..(y + 1) * row]);
            prop_assert!(out[y * so + row..(y + 1) * so].iter().all(|&b| b == 0x5A));
        }
    }

    /// Any cloud of finite xyz + intensity + ring points survives a PCD round trip in every
    /// encoding with the same bytes, and a view refuses a buffer one byte short.
    #[test]
    fn pcd_round_trips_random_clouds(n in 0usize..300, rows in 1u32..4, seed in any::<u64>()) {
        let layout = Arc::new(PointLayout::new(
            vec![
                PointField::new("x", 0, Datatype::Float32),
                PointField::new("y", 4, Datatype::Float32),
                PointField::new("z", 8, Datatype::Float32),
                PointField::new("intensity", 12, Datatype::Float32),
                PointField::new("ring", 16, Datatype::Uint16),
            ],
            18,
            false,
        ).unwrap());
        let width = (n as u32).div_ceil(rows).max(1);
        let points = (width * rows) as usize;
        let raw = bytes(seed, points * 18);
        let mut data = Vec::with_capacity(points * 18);
        for p in raw.chunks_exact(18) {
            for k in 0..4 {
                // Finite floats with a varied mantissa and exponent.
                let v = i16::from_le_bytes([p[2 * k], p[2 * k + 1]]) as f32 / 97.0;
                data.extend_from_slice(&v.to_le_bytes());
            }
            data.extend_from_slice(&p[16..18]);
        }
        let cloud = Cloud::from_vec(layout.clone(), data.clone(), width, rows, width as usize * 18, true).unwrap();
        for kind in [PcdData::Ascii, PcdData::Binary, PcdData::BinaryCompressed] {
            let file = pcd::encode(&cloud.view(), kind, [0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0]).unwrap();
            let back = pcd::decode(&file).unwrap();
            prop_assert_eq!(back.data, kind);
            prop_assert_eq!((back.cloud.width, back.cloud.height), (width, rows));
            prop_assert_eq!(&back.cloud.data, &data);
        }
        if !data.is_empty() {
            prop_assert!(CloudView::new(layout, &data[..data.len() - 1], width, rows, width as usize * 18, true).is_err());
        }
    }
}
