//! Channel layout and sample conversion: alpha copies, padded rows, planar split and merge,
//! per-channel lookup tables, float-to-byte rounding.

use super::filter::reflect101;
use super::rows::par_rows;
use super::simd::wide_fn;
use crate::image::{ImageView, ImageViewMut, PixelFormat};

/// Copies the alpha byte of every pixel of `src` into `dst` (no-op for formats without alpha).
#[inline]
pub fn copy_alpha(format: PixelFormat, src: &[u8], dst: &mut [u8]) {
    if let Some(a) = format.alpha_offset() {
        let c = format.channels();
        for (s, d) in src.chunks_exact(c).zip(dst.chunks_exact_mut(c)) {
            d[a] = s[a];
        }
    }
}

/// Row `src` (`c` samples per pixel) padded by `r` pixels at each end with reflect-101 borders,
/// converted sample by sample with `f`, into `dst` (`(w + 2 r) c` long): the middle in one
/// pass, only the `2 r` end pixels through [`reflect101`].
pub fn pad_row<S: Copy, T>(src: &[S], c: usize, r: usize, dst: &mut [T], f: impl Fn(S) -> T) {
    let w = src.len() / c;
    for (d, s) in dst[r * c..(r + w) * c].iter_mut().zip(src) {
        *d = f(*s);
    }
    for px in (0..r).chain(r + w..w + 2 * r) {
        let sx = reflect101(px as i64 - r as i64, w);
        for (d, s) in dst[px * c..px * c + c]
            .iter_mut()
            .zip(&src[sx * c..sx * c + c])
        {
            *d = f(*s);
        }
    }
}

/// [`pad_row`] without a conversion: the middle is one `copy_from_slice`.
pub fn pad_row_copy<T: Copy>(src: &[T], c: usize, r: usize, dst: &mut [T]) {
    let w = src.len() / c;
    dst[r * c..(r + w) * c].copy_from_slice(src);
    for px in (0..r).chain(r + w..w + 2 * r) {
        let sx = reflect101(px as i64 - r as i64, w);
        dst[px * c..px * c + c].copy_from_slice(&src[sx * c..sx * c + c]);
    }
}

/// The first three `w`-long planes of `buf`: the red, green and blue planes of a row's scratch
/// buffer (at least `3 w` long).
///
/// ```
/// # use perturb_core::camera::ops::three_planes;
/// let mut buf = [0u8, 1, 2, 3, 4, 5, 6];
/// let [r, g, b] = three_planes(&mut buf, 2);
/// assert_eq!((&*r, &*g, &*b), (&[0, 1][..], &[2, 3][..], &[4, 5][..]));
/// ```
#[inline(always)]
pub fn three_planes<T>(buf: &mut [T], w: usize) -> [&mut [T]; 3] {
    let (r, rest) = buf.split_at_mut(w);
    let (g, rest) = rest.split_at_mut(w);
    [r, g, &mut rest[..w]]
}

/// Splits a row of colour pixels of `format` into three planes of floats, red, green and blue
/// (mono8: the grey value in all three). Each format gets its own loop with the channel positions
/// known at compile time, which lets the compiler vectorise it.
#[inline(always)]
pub fn split_rgb(src: &[u8], format: PixelFormat, [r, g, b]: [&mut [f32]; 3]) {
    // Inlined into the caller: its AVX2 copy (`wide_fn!`) vectorises the stride-3 loop well,
    // a function of its own would be compiled for the baseline CPU.
    #[inline(always)]
    fn each<const C: usize, const R: usize, const G: usize, const B: usize>(
        src: &[u8],
        [r, g, b]: [&mut [f32]; 3],
    ) {
        let planes = r.iter_mut().zip(g.iter_mut()).zip(b.iter_mut());
        for (((r, g), b), p) in planes.zip(src.chunks_exact(C)) {
            (*r, *g, *b) = (p[R] as f32, p[G] as f32, p[B] as f32);
        }
    }
    match format {
        PixelFormat::Rgb8 => each::<3, 0, 1, 2>(src, [r, g, b]),
        PixelFormat::Bgr8 => each::<3, 2, 1, 0>(src, [r, g, b]),
        PixelFormat::Rgba8 => each::<4, 0, 1, 2>(src, [r, g, b]),
        PixelFormat::Bgra8 => each::<4, 2, 1, 0>(src, [r, g, b]),
        PixelFormat::Mono8 => each::<1, 0, 0, 0>(src, [r, g, b]),
    }
}

/// [`split_rgb`] into planes of bytes.
#[inline(always)]
pub fn split_rgb_bytes(src: &[u8], format: PixelFormat, [r, g, b]: [&mut [u8]; 3]) {
    // Inlined, as in `split_rgb`.
    #[inline(always)]
    fn each<const C: usize, const R: usize, const G: usize, const B: usize>(
        src: &[u8],
        [r, g, b]: [&mut [u8]; 3],
    ) {
        let planes = r.iter_mut().zip(g.iter_mut()).zip(b.iter_mut());
        for (((r, g), b), p) in planes.zip(src.chunks_exact(C)) {
            (*r, *g, *b) = (p[R], p[G], p[B]);
        }
    }
    match format {
        PixelFormat::Rgb8 => each::<3, 0, 1, 2>(src, [r, g, b]),
        PixelFormat::Bgr8 => each::<3, 2, 1, 0>(src, [r, g, b]),
        PixelFormat::Rgba8 => each::<4, 0, 1, 2>(src, [r, g, b]),
        PixelFormat::Bgra8 => each::<4, 2, 1, 0>(src, [r, g, b]),
        PixelFormat::Mono8 => each::<1, 0, 0, 0>(src, [r, g, b]),
    }
}

/// Writes three planes of bytes, red, green and blue, into the colour channels of a row of
/// `format` pixels; alpha is left as it is. Mono8 takes the red plane. The counterpart of
/// [`split_rgb`].
#[inline(always)]
pub fn merge_rgb(format: PixelFormat, [r, g, b]: [&[u8]; 3], dst: &mut [u8]) {
    // Inlined, as in `split_rgb`.
    #[inline(always)]
    fn each<const C: usize, const R: usize, const G: usize, const B: usize>(
        [r, g, b]: [&[u8]; 3],
        dst: &mut [u8],
    ) {
        let planes = r.iter().zip(g).zip(b);
        for (((&r, &g), &b), p) in planes.zip(dst.chunks_exact_mut(C)) {
            (p[R], p[G], p[B]) = (r, g, b);
        }
    }
    match format {
        PixelFormat::Rgb8 => each::<3, 0, 1, 2>([r, g, b], dst),
        PixelFormat::Bgr8 => each::<3, 2, 1, 0>([r, g, b], dst),
        PixelFormat::Rgba8 => each::<4, 0, 1, 2>([r, g, b], dst),
        PixelFormat::Bgra8 => each::<4, 2, 1, 0>([r, g, b], dst),
        PixelFormat::Mono8 => {
            let n = dst.len().min(r.len());
            dst[..n].copy_from_slice(&r[..n]);
        }
    }
}

/// Applies a 256-entry lookup table to every colour byte; alpha is copied.
pub fn apply_lut(input: &ImageView<'_>, output: &mut ImageViewMut<'_>, lut: &[u8; 256]) {
    let format = input.format;
    par_rows(input, output, |_, src, dst| {
        for (s, d) in src.iter().zip(dst.iter_mut()) {
            *d = lut[*s as usize];
        }
        copy_alpha(format, src, dst);
    });
}

wide_fn! {
    /// Rounds non-negative samples to u8 (saturating at 255).
    pub fn round_u8(src: &[f32], dst: &mut [u8]) {
        for (d, s) in dst.iter_mut().zip(src) {
            *d = byte(s + 0.5);
        }
    }
}

/// `v as u8`: `v` truncated toward zero and saturated to 0..=255, NaN to 0; but written so that
/// loops over it vectorise (Rust's saturating float-to-int casts compile to a scalar conversion
/// and NaN test per value). The clamped value is floored (one instruction with SSE4.1) and
/// added to 2^23, which puts the integer in the low bits of the mantissa.
///
/// ```
/// # use perturb_core::camera::ops::byte;
/// assert_eq!(byte(254.9), 254);
/// assert_eq!(byte(-3.0), 0);
/// assert_eq!(byte(1e9), 255);
/// ```
#[inline(always)]
// max then min, not clamp: max maps NaN to 0, clamp would carry it on.
#[allow(clippy::manual_clamp)]
pub fn byte(v: f32) -> u8 {
    (v.max(0.0).min(255.0).floor() + 8_388_608.0).to_bits() as u8
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn byte_is_the_saturating_cast() {
        // Every f32 between -2 and 258 in steps of 1/64 (exact halves and integers included),
        // the largest values below each integer, and the special values.
        let mut values: Vec<f32> = (-128..=258 * 64).map(|i| i as f32 / 64.0).collect();
        values.extend((1..=256).map(|k| f32::from_bits((k as f32).to_bits() - 1)));
        values.extend([
            f32::NAN,
            f32::INFINITY,
            f32::NEG_INFINITY,
            f32::MAX,
            f32::MIN,
            -0.0,
            1e-30,
            255.999_99,
            256.0,
            8_388_608.0,
        ]);
        for v in values {
            assert_eq!(byte(v), v as u8, "byte({v})");
        }
    }

    #[test]
    fn split_and_merge_rgb_follow_each_formats_channel_positions() {
        let rgb = crate::image::rgb_test_row(5, 53);
        for format in PixelFormat::ALL {
            let img = rgb.convert(format);
            let mut planes = [[0f32; 5]; 3];
            let [r, g, b] = &mut planes;
            split_rgb(&img.data, format, [r, g, b]);
            for (x, p) in img.data.chunks_exact(format.channels()).enumerate() {
                let [ri, gi, bi] = format.rgb_offsets();
                let want = [p[ri], p[gi], p[bi]].map(|v| v as f32);
                assert_eq!(
                    [planes[0][x], planes[1][x], planes[2][x]],
                    want,
                    "{format:?}"
                );
            }
            // Merging the planes back gives the same row, alpha untouched.
            let bytes = planes.map(|p| p.map(|v| v as u8));
            let mut out = img.data.clone();
            out.iter_mut()
                .enumerate()
                .filter(|(i, _)| Some(i % format.channels()) != format.alpha_offset())
                .for_each(|(_, v)| *v = 0);
            merge_rgb(format, [&bytes[0], &bytes[1], &bytes[2]], &mut out);
            assert_eq!(out, img.data, "{format:?}");
        }
    }
}
