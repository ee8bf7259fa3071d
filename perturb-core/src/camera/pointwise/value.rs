//! HSV value scaling with exact rounding, per colour channel.

use super::bytemap::ByteMap;
use crate::camera::ops::{byte, copy_alpha, merge_rgb, par_rows_with, split_rgb_bytes, wide_fn};
use crate::image::{ImageView, ImageViewMut, PixelFormat};

/// The exact rounding `round(p nv / v)` (halves up) of a channel `p <= v` scaled by `nv / v`, in
/// float: `k = nv / max(v, 1)` is within 2^-24 of the ratio, so `p k` is within 4e-5 of `p nv /
/// v`, while every such fraction that is not a half is at least `1 / 510` from one. Adding 2^-12
/// to the half pushes exact halves up and moves no other value across an integer. A black pixel
/// (`v = 0`) takes `nv` on every channel (`z = 1`).
#[inline(always)]
fn scale_channel(p: f32, z: f32, k: f32) -> f32 {
    (p + z) * k + (0.5 + 1.0 / 4096.0)
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

wide_fn! {
    /// One row of [`scale_value`]; `planes` holds three byte planes of the row's width.
    fn scale_value_row(format: PixelFormat, f: f32, src: &[u8], planes: &mut [u8], dst: &mut [u8]) {
        let w = planes.len() / 3;
        let (r, rest) = planes.split_at_mut(w);
        let (g, b) = rest.split_at_mut(w);
        split_rgb_bytes(src, format, [&mut *r, &mut *g, &mut *b]);
        for ((r, g), b) in r.iter_mut().zip(g.iter_mut()).zip(b.iter_mut()) {
            let v8 = (*r).max(*g).max(*b);
            let v = v8 as f32;
            let nv = (v * f).min(255.0).floor();
            let z = if v8 == 0 { 1.0 } else { 0.0 };
            let k = nv / v.max(1.0);
            *r = byte(scale_channel(*r as f32, z, k));
            *g = byte(scale_channel(*g as f32, z, k));
            *b = byte(scale_channel(*b as f32, z, k));
        }
        merge_rgb(format, [&*r, &*g, &*b], dst);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::camera::ops::byte;

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
                let z = if v == 0 { 1.0 } else { 0.0 };
                for p in 0..=v {
                    let want = (((p + z_fixed) * k_fixed + (1 << 23) + (1 << 12)) >> 24) as u8;
                    let got = byte(scale_channel(p as f32, z, k));
                    assert_eq!(got, want, "p {p} v {v} nv {nv}");
                }
            }
        }
    }
}
