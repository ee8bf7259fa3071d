use super::*;
use crate::perturber::CameraPerturber;
use crate::rng::Rng;

/// `n` pseudo-random bytes.
fn noise(n: usize, seed: u64) -> Vec<u8> {
    let mut rng = Rng::from_key(seed);
    (0..n).map(|_| rng.next_u64() as u8).collect()
}

/// A frame of `e` with random samples and `pad` bytes of random padding per row, plus the same
/// padding after the last row (as a ROS message's `step * height`).
fn frame(e: &'static Encoding, w: u32, h: u32, pad: usize, seed: u64) -> (Vec<u8>, usize) {
    let step = e.row_bytes(w) + pad;
    (noise(step * h as usize, seed), step)
}

/// The working views before and after `f` changes some pixels, and the output.
fn perturb_with(
    input: &EncodedView<'_>,
    f: impl Fn(usize, usize, &mut [u8]),
) -> (Image, Image, Vec<u8>) {
    let mut scratch = Scratch::new();
    let mut out = vec![0xAB; input.data().len()];
    let (mut before, mut after) = (None, None);
    scratch
        .perturb(input, &mut out, |i, o| {
            before = Some(Image::from_view(i));
            o.copy_from(i)?;
            let c = i.format.channels();
            for y in 0..i.height as usize {
                for (x, p) in o.row_mut(y).chunks_exact_mut(c).enumerate() {
                    f(x, y, p);
                }
            }
            after = Some(Image::from_view(&o.as_view()));
            Ok(())
        })
        .unwrap();
    (before.unwrap(), after.unwrap(), out)
}

#[test]
fn every_name_is_unique_and_every_layout_has_its_eight_bit_row() {
    let mut names: Vec<&str> = ENCODINGS
        .iter()
        .flat_map(|e| std::iter::once(e.name).chain(e.aliases.iter().copied()))
        .collect();
    let n = names.len();
    names.sort();
    names.dedup();
    assert_eq!(names.len(), n, "a name or alias appears twice");
    for e in &ENCODINGS {
        assert!(matches!(e.bits, 8 | 16), "{e}");
        assert_eq!(e.eight_bit().layout, e.layout);
        assert_eq!(e.eight_bit().bits, 8);
        assert_eq!(Encoding::find(e.name).unwrap(), e);
        for a in e.aliases {
            assert_eq!(Encoding::find(a).unwrap(), e);
        }
    }
    for f in PixelFormat::ALL {
        let e = Encoding::of_format(f);
        assert_eq!(e.name, f.ros_encoding());
        assert!(e.is_working());
    }
    assert_eq!(Encoding::find("16UC1").unwrap().name, "mono16");
    assert_eq!(Encoding::find("8UC3").unwrap().name, "bgr8");
    assert_eq!(Encoding::find("uyvy").unwrap().name, "yuv422");
    let e = Encoding::find("32FC1").unwrap_err();
    assert!(matches!(&e, Error::UnsupportedEncoding { encoding } if encoding == "32FC1"));
    let text = e.to_string();
    assert!(
        text.contains("`32FC1`") && text.contains("bayer_grbg16") && text.contains("yuv422_yuy2"),
        "{text}"
    );
}

#[test]
fn bad_frames_are_refused_naming_the_field_and_value() {
    let data = vec![0u8; 10_000];
    let cases: [(&str, u32, u32, usize, ImageField, u64, &str); 7] = [
        (
            "bayer_rggb8",
            641,
            10,
            642,
            ImageField::Width,
            641,
            "width 641 is odd",
        ),
        (
            "bayer_bggr16",
            64,
            9,
            128,
            ImageField::Height,
            9,
            "height 9 is odd",
        ),
        (
            "yuv422",
            63,
            4,
            200,
            ImageField::Width,
            63,
            "width 63 is odd",
        ),
        (
            "yuv422_yuy2",
            64,
            3,
            127,
            ImageField::Step,
            127,
            "step 127 is smaller than width 64 x 2 bytes per pixel = 128",
        ),
        (
            "mono16",
            40,
            4,
            79,
            ImageField::Step,
            79,
            "step 79 is smaller",
        ),
        (
            "rgb16",
            100,
            20,
            600,
            ImageField::Data,
            10_000,
            "data length 10000 is shorter than the 12000 bytes of 20 rows of step 600",
        ),
        (
            "bayer_rggb8",
            2,
            2,
            1,
            ImageField::Step,
            1,
            "invalid bayer_rggb8 image: step 1",
        ),
    ];
    for (name, w, h, step, field, value, text) in cases {
        let e = EncodedView::from_ros(&data, w, h, step, name, 0).unwrap_err();
        assert!(
            matches!(e, Error::ImageField { field: f, value: v, encoding, .. } if f == field && v == value && encoding == name),
            "{name}: {e:?}"
        );
        assert!(e.to_string().contains(text), "{name}: {e}");
    }
    // A YUV frame may have an odd height; a Bayer frame may not.
    assert!(EncodedView::from_ros(&data, 64, 3, 128, "yuv422", 0).is_ok());
    let e = EncodedView::from_ros(&data, 4, 4, 4, "yuv444", 0).unwrap_err();
    assert!(e.to_string().contains("yuv444"), "{e}");
    // Bit depths: 9..=16 for 16-bit encodings only.
    let v = EncodedView::from_ros(&data, 4, 4, 8, "mono16", 0).unwrap();
    assert_eq!(v.with_bit_depth(12).unwrap().bit_depth, 12);
    let e = v.with_bit_depth(17).unwrap_err();
    assert!(
        e.to_string().contains("bit depth 17 is outside 9..=16"),
        "{e}"
    );
    let v = EncodedView::from_ros(&data, 4, 4, 4, "mono8", 0).unwrap();
    assert!(v.with_bit_depth(12).is_err());
}

#[test]
fn an_unchanged_working_view_gives_the_input_bytes_back_in_every_encoding() {
    for (k, e) in ENCODINGS.iter().enumerate() {
        for (w, h, pad) in [(12, 6, 0), (10, 4, 5), (2, 2, 1), (0, 0, 0)] {
            let (data, step) = frame(e, w, h, pad, k as u64);
            for big_endian in [false, true] {
                let input = EncodedView::new(&data, w, h, step, e, big_endian).unwrap();
                let (_, _, out) = perturb_with(&input, |_, _, _| {});
                assert_eq!(out, data, "{e} {w}x{h} pad {pad} be {big_endian}");
            }
        }
    }
}

#[test]
fn pixels_the_perturbation_left_alone_keep_their_input_bytes() {
    // The perturbation brightens the left third of the frame.
    let (w, h) = (24u32, 8u32);
    let changed = |x: usize| x < 8;
    for (k, e) in ENCODINGS.iter().enumerate() {
        let (data, step) = frame(e, w, h, 3, 100 + k as u64);
        let input = EncodedView::new(&data, w, h, step, e, k % 2 == 0).unwrap();
        let (before, after, out) = perturb_with(&input, |x, _, p| {
            if changed(x) {
                p.iter_mut().for_each(|b| *b = b.saturating_add(40));
            }
        });
        let bpp = e.bytes_per_pixel();
        let mut differ = 0;
        for y in 0..h as usize {
            let (i, o) = (input.row(y), &out[y * step..y * step + input.row_bytes()]);
            for x in 0..w as usize {
                // YUV pixels share their pair's chroma: a pair is kept when both are.
                let kept = if matches!(e.layout, Yuv422(_)) {
                    !changed(x & !1)
                } else {
                    !changed(x)
                };
                let px = x * bpp..(x + 1) * bpp;
                if kept {
                    assert_eq!(i[px.clone()], o[px], "{e} ({x}, {y})");
                } else if i[px.clone()] != o[px] {
                    differ += 1;
                }
            }
            // Padding from the input.
            assert_eq!(
                data[y * step + input.row_bytes()..(y + 1) * step],
                out[y * step + input.row_bytes()..(y + 1) * step],
                "{e} padding of row {y}"
            );
        }
        assert!(differ > 0, "{e}: the brightened pixels did not change");
        assert_ne!(before, after);
    }
}

#[test]
fn demosaicking_a_flat_colour_gives_that_colour_everywhere_and_mosaicking_inverts_it() {
    let (w, h) = (10u32, 6u32);
    let colour = [200u8, 100, 30];
    for p in BayerPattern::ALL {
        let name = format!("bayer_{:?}8", p).to_lowercase();
        let e = Encoding::find(&name).unwrap();
        let data: Vec<u8> = (0..(w * h) as usize)
            .map(|i| colour[p.channel(i % w as usize, i / w as usize)])
            .collect();
        let input = EncodedView::new(&data, w, h, w as usize, e, false).unwrap();
        let mut s = Scratch::new();
        let v = s.to_working(&input);
        assert!(
            v.data().chunks_exact(3).all(|px| px == colour),
            "{name}: {:?}",
            &v.data()[..9]
        );
    }
    assert_eq!(BayerPattern::Rggb.channel(0, 0), 0);
    assert_eq!(BayerPattern::Rggb.channel(1, 1), 2);
    assert_eq!(BayerPattern::Grbg.channel(1, 0), 0);
    assert_eq!(BayerPattern::Gbrg.channel(0, 1), 0);
}

#[test]
fn demosaicking_interpolates_bilinearly_and_mirrors_at_the_border() {
    // A 4x4 rggb mosaic with distinct samples; a few pixels by hand.
    let m: Vec<u8> = (0..16).map(|i| (i * 10 + 5) as u8).collect();
    let e = Encoding::find("bayer_rggb8").unwrap();
    let input = EncodedView::new(&m, 4, 4, 4, e, false).unwrap();
    let mut s = Scratch::new();
    let v = s.to_working(&input);
    let px = |x: usize, y: usize| &v.row(y)[3 * x..3 * x + 3];
    let at = |x: usize, y: usize| m[y * 4 + x] as u16;
    let avg = |v: &[u16]| ((v.iter().sum::<u16>() + v.len() as u16 / 2) / v.len() as u16) as u8;
    // (1, 1) is blue: red from the diagonals, green from the edges.
    assert_eq!(
        px(1, 1),
        [
            avg(&[at(0, 0), at(2, 0), at(0, 2), at(2, 2)]),
            avg(&[at(1, 0), at(1, 2), at(0, 1), at(2, 1)]),
            at(1, 1) as u8
        ]
    );
    // (1, 0) is green in a red row: red left/right, blue above/below (row -1 mirrors row 1).
    assert_eq!(
        px(1, 0),
        [avg(&[at(0, 0), at(2, 0)]), at(1, 0) as u8, at(1, 1) as u8]
    );
    // (0, 0) is red: column -1 mirrors column 1, row -1 row 1.
    assert_eq!(
        px(0, 0),
        [
            at(0, 0) as u8,
            avg(&[at(0, 1), at(0, 1), at(1, 0), at(1, 0)]),
            at(1, 1) as u8
        ]
    );
    // (3, 3) is blue at the far corner: column 4 mirrors column 2, row 4 row 2.
    assert_eq!(
        px(3, 3),
        [
            at(2, 2) as u8,
            avg(&[at(3, 2), at(3, 2), at(2, 3), at(2, 3)]),
            at(3, 3) as u8
        ]
    );
}

#[test]
fn yuv_decodes_as_opencv_and_its_constants_are_the_bt601_matrix_and_its_inverse() {
    // (Y, U, V) -> RGB as OpenCV 5.0's cvtColor(COLOR_YUV2RGB_UYVY) gives them.
    let cases = [
        ([16, 128, 128], [0, 0, 0]),
        ([235, 128, 128], [255, 255, 255]),
        ([0, 128, 128], [0, 0, 0]),
        ([128, 128, 255], [255, 27, 130]),
        ([128, 255, 128], [130, 81, 255]),
        ([81, 90, 240], [254, 0, 0]),
    ];
    for ([y, u, v], rgb) in cases {
        assert_eq!(yuv::pair_to_rgb([y, u, y, v]), [rgb, rgb], "{y} {u} {v}");
    }
    let c = [1.164, 1.596, -0.813, -0.391, 2.018];
    for (k, c) in yuv::DECODE.iter().zip(c) {
        assert_eq!(*k, (c * (1u32 << 20) as f64).round() as i32);
    }
    // The inverse of [[cy, 0, cvr], [cy, cug, cvg], [cy, cub, 0]] (columns y, u, v).
    let m = [[c[0], 0.0, c[1]], [c[0], c[3], c[2]], [c[0], c[4], 0.0]];
    let det = m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1])
        - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
        + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0]);
    for (i, row) in yuv::ENCODE.iter().enumerate() {
        for (j, k) in row.iter().enumerate() {
            // inverse[i][j] = cofactor[j][i] / det
            let (r, s) = ([0, 1, 2].map(|a| a != j), [0, 1, 2].map(|a| a != i));
            let rows: Vec<usize> = (0..3).filter(|a| r[*a]).collect();
            let cols: Vec<usize> = (0..3).filter(|a| s[*a]).collect();
            let minor = m[rows[0]][cols[0]] * m[rows[1]][cols[1]]
                - m[rows[0]][cols[1]] * m[rows[1]][cols[0]];
            let sign = if (i + j) % 2 == 0 { 1.0 } else { -1.0 };
            let want = (sign * minor / det * 65536.0).round() as i32;
            assert_eq!(*k, want, "ENCODE[{i}][{j}]");
        }
    }
}

/// A pair of samples that decodes well inside the RGB cube.
fn mid_pair(rng: &mut Rng) -> [u8; 4] {
    let mut at = |lo: u64, n: u64| (lo + rng.next_u64() % n) as u8;
    [at(80, 90), at(108, 40), at(80, 90), at(108, 40)]
}

#[test]
fn a_yuv_change_decodes_to_the_perturbed_pixels_within_rounding() {
    let mut rng = Rng::from_key(7);
    let luma = |p: [u8; 3]| 0.299 * p[0] as f64 + 0.587 * p[1] as f64 + 0.114 * p[2] as f64;
    let (mut same, mut own) = (0, 0.0f64);
    for _ in 0..20_000 {
        let q = mid_pair(&mut rng);
        let before = yuv::pair_to_rgb(q);
        let mut step = || (rng.next_u64() % 41) as i32 - 20;
        let d = [[step(), step(), step()], [step(), step(), step()]];
        let shift = |p: [u8; 3], d: [i32; 3]| [0, 1, 2].map(|c| (p[c] as i32 + d[c]) as u8);
        // The same change on both pixels: the output decodes to the perturbed pixels.
        let after = [shift(before[0], d[0]), shift(before[1], d[0])];
        let back = yuv::pair_to_rgb(yuv::pair_back(q, before, after));
        for (b, a) in back.iter().zip(&after) {
            for (x, y) in b.iter().zip(a) {
                same = same.max((*x as i32 - *y as i32).abs());
            }
        }
        // Different changes: each pixel keeps its own luma; the pair shares the mean chroma.
        let after = [shift(before[0], d[0]), shift(before[1], d[1])];
        let back = yuv::pair_to_rgb(yuv::pair_back(q, before, after));
        for (b, a) in back.iter().zip(&after) {
            own = own.max((luma(*b) - luma(*a)).abs());
        }
    }
    assert!(same <= 3, "worst channel difference {same}");
    assert!(own <= 2.5, "worst luma difference {own}");
}

#[test]
fn sixteen_bit_transfer_keeps_the_range_the_precision_and_the_eight_bit_result() {
    for depth in [16u8, 14, 12, 10] {
        let max = deep::max_value(depth);
        let s = max as f64 / 255.0;
        let mut worst: f64 = 0.0;
        for v in 0..=max {
            let v = v as u16;
            let v8 = deep::to8(v, depth);
            assert_eq!(v8 as f64, (v as f64 / s).round().min(255.0), "{depth} {v}");
            for p8 in 0..=255u8 {
                let out = deep::transfer(v, v8, p8, depth);
                if p8 == v8 {
                    assert_eq!(out, v);
                    continue;
                }
                assert!(out as u32 <= max, "{depth}: {v} -> {p8}: {out}");
                assert_eq!(deep::to8(out, depth), p8, "{depth}: {v} -> {p8}: {out}");
                let target = (v as f64 + (p8 as f64 - v8 as f64) * s).clamp(0.0, max as f64);
                worst = worst.max((out as f64 - target).abs());
            }
        }
        // 16 bits: exactly v + 257 (p8 - v8); fewer: within one 16-bit unit.
        let bound = if depth == 16 { 0.0 } else { 1.0 };
        assert!(worst <= bound, "{depth} bits: {worst}");
    }
    // Values above a 12-bit maximum read as 255 and pass through unchanged.
    assert_eq!(deep::to8(5000, 12), 255);
    assert_eq!(deep::transfer(5000, 255, 255, 12), 5000);
}

#[test]
fn big_endian_frames_are_read_and_written_in_their_byte_order() {
    let e = Encoding::find("mono16").unwrap();
    let (w, h) = (8u32, 4u32);
    let values: Vec<u16> = (0..w * h).map(|i| (i * 2000 + 77) as u16).collect();
    let le: Vec<u8> = values.iter().flat_map(|v| v.to_le_bytes()).collect();
    let be: Vec<u8> = values.iter().flat_map(|v| v.to_be_bytes()).collect();
    let darken = |_: usize, _: usize, p: &mut [u8]| p[0] /= 2;
    let (bl, _, out_le) = perturb_with(&EncodedView::new(&le, w, h, 16, e, false).unwrap(), darken);
    let (bb, _, out_be) = perturb_with(&EncodedView::new(&be, w, h, 16, e, true).unwrap(), darken);
    assert_eq!(bl, bb, "the same working view from either byte order");
    let swapped: Vec<u8> = out_be.chunks_exact(2).flat_map(|b| [b[1], b[0]]).collect();
    assert_eq!(swapped, out_le);
    assert_ne!(out_le, le);
    // 12 significant bits: 4095 is white in the working view.
    let v12: Vec<u8> = [0u16, 4095, 2048, 1]
        .iter()
        .flat_map(|v| v.to_le_bytes())
        .collect();
    let view = EncodedView::new(&v12, 4, 1, 8, e, false)
        .unwrap()
        .with_bit_depth(12)
        .unwrap();
    let mut s = Scratch::new();
    assert_eq!(s.to_working(&view).data(), &[0, 255, 128, 0]);
}

#[test]
fn a_perturbation_gives_the_same_bytes_through_the_perturber_and_the_parts() {
    for name in [
        "bayer_grbg8",
        "bayer_rggb16",
        "yuv422_yuy2",
        "bgr16",
        "mono16",
        "rgb8",
    ] {
        let e = Encoding::find(name).unwrap();
        let (data, step) = frame(e, 32, 16, 2, 9);
        let input = EncodedView::new(&data, 32, 16, step, e, false).unwrap();
        let mut p = CameraPerturber::new("C-C4", 3, 5).unwrap();
        let a = p.apply_encoded_owned(&input, 11).unwrap();
        let mut scratch = Scratch::new();
        let mut b = vec![0; data.len()];
        p.apply_encoded(&input, &mut b, 11, &mut scratch).unwrap();
        p.apply_encoded(&input, &mut b, 11, &mut scratch).unwrap();
        assert_eq!(a, b, "{name}: a reused scratch gives the same bytes");
        // The parts, by hand.
        let mut s = Scratch::new();
        let wi = Image::from_view(&s.to_working(&input));
        let wo = p.apply_owned(&wi.view(), 11).unwrap();
        let mut c = vec![0; data.len()];
        s.from_working(&input, &wo.view(), &mut c).unwrap();
        assert_eq!(a, c, "{name}");
        assert_ne!(a, data, "{name}: C-C4 changes the frame");
    }
}

#[test]
fn a_short_output_or_a_wrong_working_view_is_an_error() {
    let e = Encoding::find("bayer_rggb8").unwrap();
    let data = vec![9u8; 16];
    let input = EncodedView::new(&data, 4, 4, 4, e, false).unwrap();
    let mut p = CameraPerturber::new("C-C4", 1, 0).unwrap();
    let err = p
        .apply_encoded(&input, &mut [0; 15], 0, &mut Scratch::new())
        .unwrap_err();
    assert!(
        matches!(
            err,
            Error::OutputTooSmall {
                needed: 16,
                available: 15
            }
        ),
        "{err}"
    );
    let mut s = Scratch::new();
    let wrong = Image::new(4, 2, PixelFormat::Rgb8);
    let err = s
        .from_working(&input, &wrong.view(), &mut [0; 16])
        .unwrap_err();
    assert!(err.to_string().contains("4x2 rgb8"), "{err}");
}

/// Both copies of the row kernels (baseline and, on CPUs that have it, AVX2) on frames wide
/// enough for several blocks and a remainder.
fn on_both_paths(f: impl Fn()) {
    let _dispatch = crate::camera::ops::dispatch_lock();
    for baseline in [true, false] {
        crate::camera::ops::force_baseline(baseline);
        f();
    }
    crate::camera::ops::force_baseline(false);
}

#[test]
fn yuv_rows_give_the_pair_by_pair_values_on_every_path() {
    on_both_paths(|| {
        let (w, h) = (100u32, 3u32);
        for name in ["yuv422", "yuv422_yuy2"] {
            let e = Encoding::find(name).unwrap();
            let Yuv422(order) = e.layout else {
                unreachable!()
            };
            let [oy0, ou, oy1, ov] = order.offsets();
            let data = noise(e.row_bytes(w) * h as usize, 3);
            let input = EncodedView::new(&data, w, h, e.row_bytes(w), e, false).unwrap();
            let mut s = Scratch::new();
            let before = Image::from_view(&s.to_working(&input));
            for (i, q) in data.chunks_exact(4).enumerate() {
                let [a, b] = yuv::pair_to_rgb([q[oy0], q[ou], q[oy1], q[ov]]);
                assert_eq!(
                    before.data[6 * i..6 * i + 6],
                    [a, b].concat(),
                    "{name} pair {i}"
                );
            }
            let mut after = before.clone();
            let change = noise(after.data.len(), 4);
            for (i, (p, c)) in after.data.iter_mut().zip(change).enumerate() {
                // A third of the pixels unchanged, the rest moved by up to +-30.
                if (i / 3) % 3 != 0 {
                    *p = (*p as i32 + (c % 61) as i32 - 30).clamp(0, 255) as u8;
                }
            }
            let mut out = vec![0u8; data.len()];
            s.from_working(&input, &after.view(), &mut out).unwrap();
            for (i, (q, o)) in data.chunks_exact(4).zip(out.chunks_exact(4)).enumerate() {
                let px = |v: &[u8]| [[v[0], v[1], v[2]], [v[3], v[4], v[5]]];
                let want = yuv::pair_back(
                    [q[oy0], q[ou], q[oy1], q[ov]],
                    px(&before.data[6 * i..]),
                    px(&after.data[6 * i..]),
                );
                assert_eq!([o[oy0], o[ou], o[oy1], o[ov]], want, "{name} pair {i}");
            }
        }
    });
}

#[test]
fn demosaicking_matches_a_plain_per_pixel_reference_on_every_pattern() {
    // The reference: every missing colour the rounded mean of its same-colour neighbours among
    // the eight around (four at most), the border mirrored.
    fn reference(m: &[u8], w: usize, h: usize, p: BayerPattern) -> Vec<u8> {
        let at = |x: isize, y: isize| {
            let r = |i: isize, n: usize| {
                if i < 0 {
                    -i
                } else if i >= n as isize {
                    2 * n as isize - 2 - i
                } else {
                    i
                }
            };
            let (x, y) = (r(x, w) as usize, r(y, h) as usize);
            (m[y * w + x] as u32, p.channel(x, y))
        };
        let mut out = vec![0u8; w * h * 3];
        for y in 0..h as isize {
            for x in 0..w as isize {
                let (own, c) = at(x, y);
                for k in 0..3 {
                    let v = if k == c {
                        own
                    } else {
                        // Edge neighbours first; the diagonals only when no edge one has it.
                        let pick = |d: &[(isize, isize)]| {
                            let v: Vec<u32> = d
                                .iter()
                                .map(|&(dx, dy)| at(x + dx, y + dy))
                                .filter(|s| s.1 == k)
                                .map(|s| s.0)
                                .collect();
                            (!v.is_empty()).then(|| {
                                (v.iter().sum::<u32>() + v.len() as u32 / 2) / v.len() as u32
                            })
                        };
                        pick(&[(-1, 0), (1, 0), (0, -1), (0, 1)])
                            .or_else(|| pick(&[(-1, -1), (1, -1), (-1, 1), (1, 1)]))
                            .unwrap()
                    };
                    out[(y as usize * w + x as usize) * 3 + k] = v as u8;
                }
            }
        }
        out
    }
    on_both_paths(|| {
        let (w, h) = (70u32, 6u32);
        for p in BayerPattern::ALL {
            let e = Encoding::find(&format!("bayer_{:?}8", p).to_lowercase()).unwrap();
            let m = noise((w * h) as usize, 5);
            let input = EncodedView::new(&m, w, h, w as usize, e, false).unwrap();
            let mut s = Scratch::new();
            let got = s.to_working(&input).data().to_vec();
            assert_eq!(got, reference(&m, w as usize, h as usize, p), "{e}");
        }
    });
}

#[test]
fn a_write_back_without_its_conversion_is_an_error() {
    for name in ["mono16", "yuv422", "bayer_rggb16"] {
        let e = Encoding::find(name).unwrap();
        let data = vec![0u8; e.row_bytes(4) * 2];
        let input = EncodedView::new(&data, 4, 2, e.row_bytes(4), e, false).unwrap();
        let working = Image::with_geometry(input.working_geometry());
        let err = Scratch::new()
            .from_working(&input, &working.view(), &mut vec![0; data.len()])
            .unwrap_err();
        assert!(
            err.to_string().contains("without the frame's to_working"),
            "{name}: {err}"
        );
    }
}
