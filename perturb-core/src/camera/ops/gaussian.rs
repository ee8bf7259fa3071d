//! Large Gaussian blurs at reduced resolution when the sigma allows, exact otherwise.

use super::buffers::frame_buffer;
use super::channels::{copy_alpha, round_u8};
use super::filter::{gaussian_kernel, opencv_sigma, separable_filter_q8};
use super::float_image::{FloatImage, lerp_row};
use super::rows::par_rows;
use super::simd::wide_fn;
use crate::image::{ImageView, ImageViewMut};
use rayon::prelude::*;

/// The resolution divisor [`GaussianRows`] works at for `sigma` on a `w` x `h` frame.
fn gaussian_factor(sigma: f64, w: usize, h: usize) -> usize {
    // The largest power of two (up to 8) that leaves a Gaussian of at least 1.5 reduced pixels to
    // apply at the reduced resolution: narrower ones are not smooth enough for the bilinear
    // upsampling to follow them within a level or two.
    let mut f = 1;
    while f < 8 && w >= 64 * f && h >= 64 * f && reduced_sigma(sigma, f * 2) >= 1.5 {
        f *= 2;
    }
    f
}

/// The sigma, in reduced pixels, that remains to apply after box-downsampling by `f` so that
/// downsampling, the Gaussian and bilinear upsampling together have the variance of `sigma`.
fn reduced_sigma(sigma: f64, f: usize) -> f64 {
    let ff = (f * f) as f64;
    ((sigma * sigma - (ff - 1.0) / 12.0 - ff / 6.0) / ff)
        .max(0.0)
        .sqrt()
}

/// A Gaussian blur of `input` as `cv2.GaussianBlur(k x k, sigma)`, read row by row (f32,
/// interleaved, alpha blurred too) with [`GaussianRows::row`], from any thread. Kernels below sigma
/// 3.15 are applied exactly (separable, reflect-101 borders). Wider ones are computed at a reduced
/// resolution (half up to sigma 6.3, quarter up to 12.6, an eighth beyond): box downsampling, an
/// exact Gaussian of the remaining width (the variance of the box and of the bilinear upsampling
/// subtracted, at least 1.5 reduced pixels), bilinear upsampling. On real frames this differs from
/// the exact kernel by about a quarter of a level on average (see the test), at a fraction of the
/// cost: the references' k = 41 and k = 113 kernels are what makes them slow.
pub struct GaussianRows {
    /// The blurred rows: at full resolution, or (reduced) the working resolution's rows already
    /// interpolated horizontally to full width, so that a full-resolution row is one lerp of two.
    rows: FloatImage,
    /// Vertical taps into `rows` when reduced: (first, second, weight of the second).
    ymap: Vec<(usize, usize, f32)>,
}

impl GaussianRows {
    /// Blurs `input` with a `k x k` Gaussian of `sigma` (OpenCV's sigma for k when 0).
    pub fn new(input: &ImageView<'_>, k: usize, sigma: f64) -> Self {
        let sigma = if sigma > 0.0 { sigma } else { opencv_sigma(k) };
        let (w, h, c) = (
            input.width as usize,
            input.height as usize,
            input.format.channels(),
        );
        let f = gaussian_factor(sigma, w, h);
        if f == 1 {
            let rows = FloatImage::from_view(input).convolve(&gaussian_kernel(k.max(1) | 1, sigma));
            return GaussianRows {
                rows,
                ymap: Vec::new(),
            };
        }
        let s2 = reduced_sigma(sigma, f);
        let k2 = (2.0 * (3.0 * s2).ceil() + 1.0) as usize;
        // Pad at full resolution (a multiple of f, wider than the kernel) so the borders reflect
        // exactly as the full-resolution filter does; crop when upsampling.
        let pad = ((3.0 * sigma).ceil() as usize).div_ceil(f) * f + f;
        let small = FloatImage::downsample_padded(input, pad, f).convolve(&gaussian_kernel(k2, s2));
        // Bilinear taps with pixel centres aligned, offset by the padding.
        let map = |i: usize, n: usize| {
            let p = (((i + pad) as f32 + 0.5) / f as f32 - 0.5).max(0.0);
            let i0 = (p as usize).min(n - 1);
            (i0, (i0 + 1).min(n - 1), p - i0 as f32)
        };
        let xmap: Vec<(usize, usize, f32)> = (0..w).map(|x| map(x, small.w)).collect();
        let ymap: Vec<(usize, usize, f32)> = (0..h).map(|y| map(y, small.h)).collect();
        // Horizontal interpolation once per working row (bilinear interpolation is separable):
        // only the rows the vertical taps reach.
        let first = ymap.first().map_or(0, |t| t.0);
        let last = ymap.last().map_or(0, |t| t.1);
        let mut data = frame_buffer((last + 1 - first) * w * c);
        data.par_chunks_mut((w * c).max(1))
            .enumerate()
            .for_each(|(i, out)| {
                let src = small.row(first + i);
                match c {
                    1 => lerp_row::<1>(src, &xmap, out),
                    3 => lerp_row::<3>(src, &xmap, out),
                    _ => lerp_row::<4>(src, &xmap, out),
                }
            });
        GaussianRows {
            rows: FloatImage {
                w,
                h: last + 1 - first,
                c,
                data,
            },
            ymap: ymap
                .into_iter()
                .map(|(a, b, t)| (a - first, b - first, t))
                .collect(),
        }
    }

    /// Writes blurred row `y` (`w * c` samples) into `out`.
    pub fn row(&self, y: usize, out: &mut [f32]) {
        if self.ymap.is_empty() {
            out.copy_from_slice(self.rows.row(y));
            return;
        }
        let (y0, y1, wy) = self.ymap[y];
        lerp(self.rows.row(y0), self.rows.row(y1), wy, out);
    }
}

wide_fn! {
    /// `out = a + (b - a) t`.
    fn lerp(a: &[f32], b: &[f32], t: f32, out: &mut [f32]) {
        for ((o, a), b) in out.iter_mut().zip(a).zip(b) {
            *o = a + (b - a) * t;
        }
    }
}

/// A Gaussian blur written into `output` (u8, rounded); see [`GaussianRows`]. Kernels applied
/// exactly stream through [`separable_filter_q8`]: OpenCV's own 8-bit fixed point, no full-frame
/// float copies.
pub fn gaussian_blur(input: &ImageView<'_>, output: &mut ImageViewMut<'_>, k: usize, sigma: f64) {
    let sigma = if sigma > 0.0 { sigma } else { opencv_sigma(k) };
    if gaussian_factor(sigma, input.width as usize, input.height as usize) == 1 {
        separable_filter_q8(input, output, &gaussian_kernel(k.max(1) | 1, sigma));
        return;
    }
    let blurred = GaussianRows::new(input, k, sigma);
    let format = input.format;
    par_rows(input, output, |y, src, dst| {
        let mut row = vec![0f32; dst.len()];
        blurred.row(y, &mut row);
        round_u8(&row, dst);
        copy_alpha(format, src, dst);
    });
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::image::{Image, PixelFormat};

    #[test]
    fn reduced_resolution_gaussian_is_close_to_the_exact_kernel() {
        let img = crate::synthetic::street_image(320, 200, 3);
        let exact = FloatImage::from_view(&img.view());
        for (k, sigma) in [
            (15usize, 2.6f64),
            (25, 4.1),
            (41, 6.5),
            (59, 9.2),
            (113, 17.3),
        ] {
            let want = exact.convolve(&gaussian_kernel(k, sigma));
            let mut got = Image::new(320, 200, PixelFormat::Rgb8);
            gaussian_blur(&img.view(), &mut got.view_mut(), k, sigma);
            let (mut sum, mut max) = (0.0f64, 0.0f32);
            for (a, b) in got.data.iter().zip(&want.data) {
                let e = (*a as f32 - b).abs();
                sum += e as f64;
                max = max.max(e);
            }
            let mean = sum / got.data.len() as f64;
            eprintln!("GAUSS k {k} mean {mean:.3} max {max:.2}");
            assert!(
                mean < 0.6 && max < 8.0,
                "k {k}: mean error {mean:.3}, max {max:.2}"
            );
        }
    }
}
