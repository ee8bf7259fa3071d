//! Interleaved f32 images for intermediate results: resampling, padding, vertical filtering.

use super::buffers::{frame_buffer, recycle};
use super::channels::pad_row_copy;
use super::filter::{reflect101, shifted_sum};
use super::simd::wide_fn;
use crate::image::ImageView;
use rayon::prelude::*;

/// An interleaved f32 image (same channel layout as the source), for intermediate results. Its
/// buffer goes back to [`frame_buffer`]'s spares when it is dropped.
#[derive(Clone, Debug)]
pub struct FloatImage {
    /// Width in pixels.
    pub w: usize,
    /// Height in pixels.
    pub h: usize,
    /// Channels per pixel.
    pub c: usize,
    /// `h * w * c` samples.
    pub data: Vec<f32>,
}

impl Drop for FloatImage {
    fn drop(&mut self) {
        recycle(std::mem::take(&mut self.data));
    }
}

impl FloatImage {
    /// Converts an 8-bit image (all channels, alpha included).
    pub fn from_view(v: &ImageView<'_>) -> Self {
        let (w, h, c) = (v.width as usize, v.height as usize, v.format.channels());
        let mut data = frame_buffer(w * h * c);
        data.par_chunks_mut((w * c).max(1))
            .enumerate()
            .for_each(|(y, row)| {
                for (d, s) in row.iter_mut().zip(v.row(y)) {
                    *d = *s as f32;
                }
            });
        FloatImage { w, h, c, data }
    }

    /// Row `y`.
    #[inline]
    pub fn row(&self, y: usize) -> &[f32] {
        &self.data[y * self.w * self.c..(y + 1) * self.w * self.c]
    }

    /// `FloatImage::from_view(v).pad_reflect(pad).downsample(f)` in one pass over the 8-bit
    /// image, without the two full-resolution float copies (same sums in the same order, so the
    /// same values).
    pub fn downsample_padded(v: &ImageView<'_>, pad: usize, f: usize) -> FloatImage {
        let (w, h, c) = (v.width as usize, v.height as usize, v.format.channels());
        let (pw, ph) = (w + 2 * pad, h + 2 * pad);
        let (w2, h2) = (pw.div_ceil(f), ph.div_ceil(f));
        // Source pixel of each padded column in the reflected borders.
        let border: Vec<(usize, usize)> = (0..pad)
            .chain(pad + w..pw)
            .map(|x| (x * c, reflect101(x as i64 - pad as i64, w) * c))
            .collect();
        let mut data = frame_buffer(w2 * h2 * c);
        data.par_chunks_mut((w2 * c).max(1))
            .enumerate()
            .for_each(|(y2, row)| {
                // Column sums of the f padded rows of this block, then sums of f columns.
                let ys = y2 * f..((y2 + 1) * f).min(ph);
                let ny = ys.len();
                let mut acc = vec![0f32; pw * c];
                for y in ys {
                    let src = v.row(reflect101(y as i64 - pad as i64, h));
                    for (a, s) in acc[pad * c..(pad + w) * c].iter_mut().zip(src) {
                        *a += *s as f32;
                    }
                    for &(d, sx) in &border {
                        for ch in 0..c {
                            acc[d + ch] += src[sx + ch] as f32;
                        }
                    }
                }
                for (x2, out) in row.chunks_exact_mut(c).enumerate() {
                    let xs = x2 * f..((x2 + 1) * f).min(pw);
                    let n = (ny * xs.len()) as f32;
                    for x in xs {
                        for (o, a) in out.iter_mut().zip(&acc[x * c..x * c + c]) {
                            *o += a;
                        }
                    }
                    for o in out {
                        *o /= n;
                    }
                }
            });
        FloatImage {
            w: w2,
            h: h2,
            c,
            data,
        }
    }

    /// Box-downsamples by an integer factor (edge blocks average what they cover).
    pub fn downsample(&self, f: usize) -> FloatImage {
        let (w2, h2, c) = (self.w.div_ceil(f), self.h.div_ceil(f), self.c);
        let mut data = frame_buffer(w2 * h2 * c);
        data.par_chunks_mut((w2 * c).max(1))
            .enumerate()
            .for_each(|(y2, row)| {
                let ys = y2 * f..((y2 + 1) * f).min(self.h);
                let ny = ys.len();
                for x2 in 0..w2 {
                    let xs = x2 * f..((x2 + 1) * f).min(self.w);
                    let n = (ny * xs.len()) as f32;
                    for ch in 0..c {
                        let mut acc = 0.0;
                        for y in ys.clone() {
                            let r = self.row(y);
                            for x in xs.clone() {
                                acc += r[x * c + ch];
                            }
                        }
                        row[x2 * c + ch] = acc / n;
                    }
                }
            });
        FloatImage {
            w: w2,
            h: h2,
            c,
            data,
        }
    }

    /// Separable convolution with a symmetric kernel, reflect-101 borders.
    pub fn convolve(&self, kernel: &[f32]) -> FloatImage {
        let (w, h, c) = (self.w, self.h, self.c);
        let r = kernel.len() / 2;
        let row_len = w * c;
        // Horizontal: a sum of shifted copies of the padded row.
        let mut tmp = frame_buffer(self.data.len());
        tmp.par_chunks_mut(row_len.max(1))
            .enumerate()
            .for_each(|(y, dst)| {
                let src = self.row(y);
                let mut padded = vec![0f32; (w + 2 * r) * c];
                pad_row_copy(src, c, r, &mut padded);
                shifted_sum(kernel, &padded, c, dst);
            });
        // Vertical: a sum of (reflected) rows.
        let mut out = frame_buffer(self.data.len());
        out.par_chunks_mut(row_len.max(1))
            .enumerate()
            .for_each(|(y, dst)| {
                for (t, &kw) in kernel.iter().enumerate() {
                    let sy = reflect101(y as i64 + t as i64 - r as i64, h);
                    add_scaled(kw, &tmp[sy * row_len..(sy + 1) * row_len], dst);
                }
            });
        recycle(tmp);
        FloatImage { w, h, c, data: out }
    }

    /// Copy padded by `p` pixels on every side with reflect-101 borders.
    pub fn pad_reflect(&self, p: usize) -> FloatImage {
        let (w, h, c) = (self.w, self.h, self.c);
        let (pw, ph) = (w + 2 * p, h + 2 * p);
        let mut data = frame_buffer(pw * ph * c);
        data.par_chunks_mut(pw * c)
            .enumerate()
            .for_each(|(y, row)| {
                let src = self.row(reflect101(y as i64 - p as i64, h));
                pad_row_copy(src, c, p, row);
            });
        FloatImage {
            w: pw,
            h: ph,
            c,
            data,
        }
    }
}

/// Linear interpolation along a row of `C`-channel pixels: output pixel i is `(1 - t) vrow[x0] +
/// t vrow[x1]` for `(x0, x1, t) = xmap[i]`.
#[inline(always)]
pub(super) fn lerp_row<const C: usize>(
    vrow: &[f32],
    xmap: &[(usize, usize, f32)],
    row: &mut [f32],
) {
    for (out, &(x0, x1, wx)) in row.chunks_exact_mut(C).zip(xmap) {
        let p0: &[f32; C] = vrow[x0 * C..x0 * C + C].try_into().expect("C samples");
        let p1: &[f32; C] = vrow[x1 * C..x1 * C + C].try_into().expect("C samples");
        for ch in 0..C {
            out[ch] = p0[ch] + (p1[ch] - p0[ch]) * wx;
        }
    }
}

wide_fn! {
    /// `dst += k src`.
    fn add_scaled(k: f32, src: &[f32], dst: &mut [f32]) {
        for (d, s) in dst.iter_mut().zip(src) {
            *d += k * s;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn one_pass_padded_downsampling_equals_the_three_step_one() {
        let img = crate::synthetic::street_image(97, 61, 2);
        for (pad, f) in [(6usize, 2usize), (12, 4), (3, 3)] {
            let want = FloatImage::from_view(&img.view())
                .pad_reflect(pad)
                .downsample(f);
            let got = FloatImage::downsample_padded(&img.view(), pad, f);
            assert_eq!((got.w, got.h, got.c), (want.w, want.h, want.c));
            for (a, b) in got.data.iter().zip(&want.data) {
                assert!(
                    (a - b).abs() <= 1e-4 * b.abs().max(1.0),
                    "pad {pad} f {f}: {a} vs {b}"
                );
            }
        }
    }
}
