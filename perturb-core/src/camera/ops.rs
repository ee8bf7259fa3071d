//! Building blocks shared by the camera perturbations: row-parallel iteration with deterministic
//! per-row random streams, per-channel lookup tables, Gaussian kernels and separable convolution.

use crate::image::{ImageView, ImageViewMut, PixelFormat};
use crate::rng::Rng;
use rayon::prelude::*;

/// Rows handed to one rayon task; large enough that scheduling is negligible.
const ROWS_PER_TASK: usize = 8;

/// Calls `f(y, input_row, output_row)` for every row, in parallel on the current rayon pool.
pub fn par_rows<F>(input: &ImageView<'_>, output: &mut ImageViewMut<'_>, f: F)
where
    F: Fn(usize, &[u8], &mut [u8]) + Send + Sync,
{
    let rows = output.rows_mut();
    rows.into_par_iter()
        .with_min_len(ROWS_PER_TASK)
        .enumerate()
        .for_each(|(y, out)| f(y, input.row(y), out));
}

/// A random stream for row `y` of frame `seq`: independent per row, so rows can run in any order
/// on any thread and give the same bytes.
#[inline]
pub fn row_rng(seed: u64, seq: u64, salt: u64, y: usize) -> Rng {
    Rng::from_key(crate::rng::hash(&[seed, seq, salt, y as u64]))
}

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

/// True if byte `i` of a row is a colour channel (not alpha).
#[inline]
pub fn is_color_byte(format: PixelFormat, i: usize) -> bool {
    match format.alpha_offset() {
        Some(a) => i % format.channels() != a,
        None => true,
    }
}

/// Applies a 256-entry lookup table to every colour byte; alpha is copied.
pub fn apply_lut(input: &ImageView<'_>, output: &mut ImageViewMut<'_>, lut: &[u8; 256]) {
    let format = input.format;
    par_rows(input, output, |_, src, dst| {
        for (i, (s, d)) in src.iter().zip(dst.iter_mut()).enumerate() {
            *d = if is_color_byte(format, i) {
                lut[*s as usize]
            } else {
                *s
            };
        }
    });
}

/// OpenCV's default sigma for a k x k Gaussian: 0.3((k-1)/2 - 1) + 0.8.
pub fn opencv_sigma(k: usize) -> f64 {
    0.3 * ((k as f64 - 1.0) * 0.5 - 1.0) + 0.8
}

/// A normalised 1-D Gaussian kernel of odd size `k` and standard deviation `sigma`.
pub fn gaussian_kernel(k: usize, sigma: f64) -> Vec<f32> {
    let r = (k / 2) as i64;
    let w: Vec<f64> = (-r..=r)
        .map(|i| (-(i * i) as f64 / (2.0 * sigma * sigma)).exp())
        .collect();
    let s: f64 = w.iter().sum();
    w.iter().map(|v| (v / s) as f32).collect()
}

/// Reflect-101 border index (OpenCV's default): ... 2 1 | 0 1 2 ... n-1 | n-2 ...
#[inline]
pub fn reflect101(i: i64, n: usize) -> usize {
    if n == 1 {
        return 0;
    }
    let n = n as i64;
    let period = 2 * (n - 1);
    let mut m = i.rem_euclid(period);
    if m >= n {
        m = period - m;
    }
    m as usize
}

/// Separable convolution of every colour channel with the same symmetric 1-D `kernel` horizontally
/// and vertically, reflect-101 borders, rounding to u8; alpha is copied. The vertical pass runs over
/// horizontally filtered f32 rows kept in a ring per task, so memory stays O(k x row).
pub fn separable_filter(input: &ImageView<'_>, output: &mut ImageViewMut<'_>, kernel: &[f32]) {
    let (w, h) = (input.width as usize, input.height as usize);
    let c = input.format.channels();
    let r = kernel.len() / 2;
    let format = input.format;
    let row_len = w * c;
    // Horizontal pass of one input row into `dst` (f32, interleaved).
    let hpass = |y: usize, dst: &mut [f32]| {
        let src = input.row(y);
        if w <= 2 * r + 1 || w < 4 {
            for x in 0..w {
                for ch in 0..c {
                    let mut acc = 0.0f32;
                    for (t, &kw) in kernel.iter().enumerate() {
                        let sx = reflect101(x as i64 + t as i64 - r as i64, w);
                        acc += kw * src[sx * c + ch] as f32;
                    }
                    dst[x * c + ch] = acc;
                }
            }
            return;
        }
        // Pad the row once, then a straight dot product per output byte.
        let mut padded = vec![0f32; (w + 2 * r) * c];
        for (px, chunk) in padded.chunks_exact_mut(c).enumerate() {
            let sx = reflect101(px as i64 - r as i64, w);
            for ch in 0..c {
                chunk[ch] = src[sx * c + ch] as f32;
            }
        }
        dst.fill(0.0);
        for (t, &kw) in kernel.iter().enumerate() {
            let shifted = &padded[t * c..t * c + row_len];
            for (d, s) in dst.iter_mut().zip(shifted) {
                *d += kw * s;
            }
        }
    };
    let rows = output.rows_mut();
    let band = 16usize;
    rows.into_par_iter()
        .enumerate()
        .chunks(band)
        .for_each(|chunk| {
            let y0 = chunk[0].0;
            let y1 = y0 + chunk.len();
            // Horizontally filtered rows y0-r .. y1+r (reflected).
            let lo = y0 as i64 - r as i64;
            let n = y1 - y0 + 2 * r;
            let mut hrows = vec![0f32; n * row_len];
            for (k, dst) in hrows.chunks_exact_mut(row_len.max(1)).enumerate() {
                if row_len == 0 {
                    break;
                }
                hpass(reflect101(lo + k as i64, h), dst);
            }
            let mut acc = vec![0f32; row_len];
            for (y, out) in chunk {
                acc.fill(0.0);
                for (t, &kw) in kernel.iter().enumerate() {
                    let base = (y - y0 + t) * row_len;
                    for (a, s) in acc.iter_mut().zip(&hrows[base..base + row_len]) {
                        *a += kw * s;
                    }
                }
                let src = input.row(y);
                for (i, (o, a)) in out.iter_mut().zip(&acc).enumerate() {
                    *o = if is_color_byte(format, i) {
                        (a + 0.5).clamp(0.0, 255.0) as u8
                    } else {
                        src[i]
                    };
                }
            }
        });
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::image::Image;

    #[test]
    fn reflect101_matches_opencv() {
        let idx: Vec<usize> = (-3..8).map(|i| reflect101(i, 5)).collect();
        assert_eq!(idx, vec![3, 2, 1, 0, 1, 2, 3, 4, 3, 2, 1]);
        assert_eq!(reflect101(-4, 1), 0);
    }

    #[test]
    fn opencv_sigmas() {
        for (k, s) in [(3, 0.8), (7, 1.4), (15, 2.6), (25, 4.1), (41, 6.5)] {
            assert!((opencv_sigma(k) - s).abs() < 1e-9, "k {k}");
        }
    }

    #[test]
    fn separable_filter_preserves_constant_images() {
        let mut img = Image::new(13, 9, PixelFormat::Rgba8);
        for (i, b) in img.data.iter_mut().enumerate() {
            *b = if i % 4 == 3 { (i % 251) as u8 } else { 77 };
        }
        let mut out = Image::new(13, 9, PixelFormat::Rgba8);
        separable_filter(&img.view(), &mut out.view_mut(), &gaussian_kernel(7, 1.4));
        assert_eq!(out, img, "constant colour stays constant, alpha copied");
    }
}
