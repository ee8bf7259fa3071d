//! HSV value scaling with exact rounding, per colour channel.

use super::bytemap::ByteMap;
use crate::camera::ops::{
    copy_alpha, merge_rgb, par_rows_with, split_rgb_bytes, three_planes, wide_fn,
};
use crate::image::{ImageView, ImageViewMut, PixelFormat};

/// `p nv / v` for a channel `p <= v` scaled by `nv / v`, plus `offset`, in float; [`nearest`]
/// then gives its exact rounding `round(p nv / v)` with halves up. `k = nv / max(v, 1)` is within
/// 2^-24 of the ratio, so `p k` is within 4e-5 of `p nv / v`, while every such fraction that is
/// not a half is at least `1 / 510` from one. The offset [`NUDGE`] (2^-12) moves exact halves
/// strictly above the half, so rounding to nearest takes them up, and moves no other value across
/// a half. A black pixel (`v = 0`, every channel 0) takes `nv` on every channel: its offset is
/// `nv + NUDGE` (exact in f32). A test checks every `(v, nv, p)` against exact integer arithmetic.
#[inline(always)]
fn scale_channel(p: f32, k: f32, offset: f32) -> f32 {
    p * k + offset
}

/// What [`scale_channel`] adds to push exact halves up.
pub(super) const NUDGE: f32 = 1.0 / 4096.0;

/// `x` in `[0, 255.5)` rounded to the nearest byte: adding 2^23 leaves no fraction in an f32's
/// mantissa, so the low byte of the sum's bits is the rounded value. [`scale_channel`]'s values are
/// never within 2^-13 of a half, so how ties round does not matter.
#[inline(always)]
fn nearest(x: f32) -> u8 {
    (x + 8_388_608.0).to_bits() as u8
}

/// The HSV value of every pixel scaled by `f` and truncated, `V' = min(255, floor(V f))` (C-C4 and
/// C-C5), hue and saturation kept: every colour channel becomes `round(c V' / V)` (halves up), as
/// [`crate::camera::ops::map_value`] with the table `V -> min(255, floor(V f))` computes, per pixel in
/// float (`V'` with the table's own float operations) over byte planes of the row. Alpha is copied; mono8 maps its
/// single channel through `mono`.
pub fn scale_value(input: &ImageView<'_>, output: &mut ImageViewMut<'_>, f: f32, mono: &ByteMap) {
    let format = input.format;
    if format.is_mono() {
        return mono.apply(input, output);
    }
    let w = input.width as usize;
    par_rows_with(
        input,
        output,
        || vec![0u8; 3 * w],
        |planes, _, src, dst| {
            scale_value_row(format, f, src, planes, dst);
            copy_alpha(format, src, dst);
        },
    );
}

/// One pixel of [`scale_value`]: `[r, g, b]` with its value scaled by `f`.
#[inline(always)]
fn scale_pixel(f: f32, [r, g, b]: [u8; 3]) -> [u8; 3] {
    let v8 = r.max(g).max(b);
    let v = v8 as f32;
    let nv = (v * f).min(255.0).floor();
    let k = nv / v.max(1.0);
    let offset = if v8 == 0 { nv + NUDGE } else { NUDGE };
    [r, g, b].map(|c| nearest(scale_channel(c as f32, k, offset)))
}

wide_fn! {
    /// One row of [`scale_value`]; `planes` holds three byte planes of the row's width.
    fn scale_value_row(format: PixelFormat, f: f32, src: &[u8], planes: &mut [u8], dst: &mut [u8]) {
        // RGB and BGR rows' whole blocks straight from row to row (the scale treats the
        // channels alike), the rest through planes.
        let direct = match format {
            PixelFormat::Rgb8 | PixelFormat::Bgr8 => super::avx2::value_scale_rgb(f, src, dst),
            _ => 0,
        };
        let (src, dst) = (&src[3 * direct..], &mut dst[3 * direct..]);
        let w = planes.len() / 3 - direct;
        let [r, g, b] = three_planes(planes, w);
        split_rgb_bytes(src, format, [&mut *r, &mut *g, &mut *b]);
        let done = super::avx2::value_scale_planes(f, r, g, b);
        let rest = r[done..].iter_mut().zip(&mut g[done..]).zip(&mut b[done..]);
        for ((r, g), b) in rest {
            [*r, *g, *b] = scale_pixel(f, [*r, *g, *b]);
        }
        merge_rgb(format, [&*r, &*g, &*b], dst);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn float_value_scaling_rounds_exactly_like_the_fixed_point() {
        // Every channel p <= v and every new value nv: the float form against map_value's
        // 8.24 fixed point (exact rounding of p nv / v, halves up; black takes nv).
        let recip = crate::camera::ops::reciprocals();
        for v in 0..=255u32 {
            for nv in 0..=255u32 {
                let (k_fixed, z_fixed) = if v == 0 {
                    (nv << 24, 1)
                } else {
                    (((nv as u64 * recip[v as usize] + 255) >> 8) as u32, 0)
                };
                let k = nv as f32 / (v as f32).max(1.0);
                let offset = if v == 0 { nv as f32 + NUDGE } else { NUDGE };
                for p in 0..=v {
                    let want = (((p + z_fixed) * k_fixed + (1 << 23) + (1 << 12)) >> 24) as u8;
                    let got = nearest(scale_channel(p as f32, k, offset));
                    assert_eq!(got, want, "p {p} v {v} nv {nv}");
                    // The AVX2 kernel's fused multiply-add (one rounding instead of two).
                    let fused = nearest((p as f32).mul_add(k, offset));
                    assert_eq!(fused, want, "fused: p {p} v {v} nv {nv}");
                }
            }
        }
    }

    #[test]
    fn the_wide_kernels_gains_round_every_channel_exactly() {
        // Every value v, new value nv and channel c <= v: (c K + 2^16) >> 17 with the kernel's
        // gain against the exact rounding of c nv / v, halves up.
        for v in 1..=255u8 {
            for nv in 0..=255u8 {
                let k = super::super::avx2::value_gain(v, nv) as u64;
                let (v, nv) = (v as u64, nv as u64);
                for c in 0..=v {
                    let want = (2 * c * nv + v) / (2 * v);
                    assert_eq!((c * k + (1 << 16)) >> 17, want, "c {c} v {v} nv {nv}");
                }
            }
        }
    }

    #[test]
    fn the_wide_kernel_scales_every_channel_and_value_like_the_pixel_code() {
        let _dispatch = crate::camera::ops::dispatch_lock();
        // Every (channel, value) pair, with the value in each of the three channels, and black;
        // a tail that is not a whole block. Without AVX2 the kernel writes nothing (checked too).
        let mut pixels = vec![[0, 0, 0]];
        for v in 0..=255u8 {
            for p in 0..=v {
                let q = ((p as u32 * 37 + v as u32) % (v as u32 + 1)) as u8;
                pixels.extend([[p, v, q], [v, q, p], [q, p, v]]);
            }
        }
        pixels.truncate(pixels.len() / 32 * 32 + 13);
        let factors = crate::camera::weather::BRIGHTNESS_INCREASE
            .into_iter()
            .chain(crate::camera::weather::BRIGHTNESS_DECREASE)
            .chain([0.0, 1.0, 2.5, 300.0]);
        for f in factors {
            let [mut r, mut g, mut b] =
                [0, 1, 2].map(|c| pixels.iter().map(|p| p[c]).collect::<Vec<u8>>());
            let done = super::super::avx2::value_scale_planes(f, &mut r, &mut g, &mut b);
            let wide = crate::camera::ops::wide_available();
            assert_eq!(done, if wide { pixels.len() / 32 * 32 } else { 0 }, "f {f}");
            for (i, &p) in pixels.iter().enumerate().take(done) {
                assert_eq!([r[i], g[i], b[i]], scale_pixel(f, p), "f {f} pixel {p:?}");
            }
            // The same pixels as one row of 3-byte pixels, row to row.
            let row = pixels.concat();
            let mut out = vec![0u8; row.len()];
            assert_eq!(super::super::avx2::value_scale_rgb(f, &row, &mut out), done);
            for (i, &p) in pixels.iter().enumerate().take(done) {
                assert_eq!(
                    out[3 * i..3 * i + 3],
                    scale_pixel(f, p),
                    "row: f {f} pixel {p:?}"
                );
            }
            assert!(
                out[3 * done..].iter().all(|&v| v == 0),
                "f {f}: wrote past the blocks"
            );
        }
        // A factor that is not finite is left to the pixel code.
        let [mut r, mut g, mut b] = [[0u8; 32]; 3];
        assert_eq!(
            super::super::avx2::value_scale_planes(f32::INFINITY, &mut r, &mut g, &mut b),
            0
        );
    }
}
