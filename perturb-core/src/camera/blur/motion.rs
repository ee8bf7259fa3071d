//! Motion blurs (C-B3 camera shake along a line, C-B4 zoom).

use crate::camera::ops::{byte, copy_alpha, par_rows, reflect101, wide_fn};
use crate::camera::{CameraBuilder, CameraPerturbation};
use crate::image::{ImageView, ImageViewMut};
use rayon::prelude::*;

/// C-B3 motion_blur: (kernel size n, angle theta in degrees from vertical), severities 1..5
/// (PerturbationDrive `motion_blur`).
pub const MOTION: [(usize, f64); 5] = [(2, 5.0), (4, 12.0), (6, 20.0), (10, 30.0), (15, 45.0)];

/// The reference's motion kernel as a list of (row, column) taps of an n x n kernel: for each row y,
/// column `int(tan(theta) (y - n/2) + n/2)` (truncated towards zero), kept inside the kernel.
pub fn motion_taps(n: usize, theta_deg: f64) -> Vec<(usize, usize)> {
    let t = crate::math::tan(theta_deg.to_radians());
    (0..n)
        .filter_map(|y| {
            let col = (t * (y as f64 - (n / 2) as f64) + (n / 2) as f64).trunc();
            (col >= 0.0 && (col as usize) < n).then_some((y, col as usize))
        })
        .collect()
}

/// C-B3 motion_blur: camera shake along a slanted line: the reference's deterministic line kernel
/// (one tap per kernel row, see [`motion_taps`]), normalised, applied like `cv2.filter2D` (anchor at
/// the kernel centre n/2, so even sizes sit off-centre as in the reference, reflect-101 borders).
/// Applied sparsely: n shifted copies summed.
pub struct MotionBlur {
    /// (dy, dx) offsets of the taps relative to the anchor.
    taps: Vec<(i64, i64)>,
}

/// Registry constructor of C-B3.
pub const MOTION_BLUR: CameraBuilder = |s| {
    let (n, theta) = MOTION[s.level()];
    let a = (n / 2) as i64;
    Ok(Box::new(MotionBlur {
        taps: motion_taps(n, theta)
            .into_iter()
            .map(|(y, x)| (y as i64 - a, x as i64 - a))
            .collect(),
    }))
};

impl CameraPerturbation for MotionBlur {
    fn apply(&self, input: &ImageView<'_>, output: &mut ImageViewMut<'_>, _seq: u64) {
        let (w, h, c) = (
            input.width as usize,
            input.height as usize,
            input.format.channels(),
        );
        let norm = 1.0 / self.taps.len().max(1) as f32;
        let format = input.format;
        par_rows(input, output, |y, src, dst| {
            let mut acc = vec![0u16; w * c];
            for &(dy, dx) in &self.taps {
                let row = input.row(reflect101(y as i64 + dy, h));
                // Inside the frame a tap is a shifted copy of the row (one contiguous add);
                // only the border columns are reflected one by one.
                let lo = ((-dx).max(0) as usize).min(w);
                let hi = (w as i64 - dx.max(0)).clamp(lo as i64, w as i64) as usize;
                if hi > lo {
                    let shift = (lo as i64 + dx) as usize * c;
                    add_widened(&row[shift..shift + (hi - lo) * c], &mut acc[lo * c..hi * c]);
                }
                for x in (0..lo).chain(hi..w) {
                    let sx = reflect101(x as i64 + dx, w);
                    for ch in 0..c {
                        acc[x * c + ch] += row[sx * c + ch] as u16;
                    }
                }
            }
            scale_round(&acc, norm, dst);
            copy_alpha(format, src, dst);
        });
    }
}

wide_fn! {
    /// `acc += row`, widened to u16.
    fn add_widened(row: &[u8], acc: &mut [u16]) {
        for (a, s) in acc.iter_mut().zip(row) {
            *a += *s as u16;
        }
    }
}

wide_fn! {
    /// `dst = round(acc norm)` (half up), saturated.
    fn scale_round(acc: &[u16], norm: f32, dst: &mut [u8]) {
        for (d, a) in dst.iter_mut().zip(acc) {
            *d = byte(*a as f32 * norm + 0.5);
        }
    }
}

/// C-B4 zoom_blur: the zoom factors z of each severity, as `arange(1, end, step)` in the reference
/// (PerturbationDrive `zoom_blur`): (end, step).
pub const ZOOM: [(f64, f64); 5] = [
    (1.01, 0.01),
    (1.11, 0.01),
    (1.15, 0.02),
    (1.21, 0.02),
    (1.31, 0.03),
];

/// The zoom factors of `arange(1, end, step)`, computed as numpy does (count = ceil((end - 1) /
/// step), value k = 1 + k step).
pub fn zoom_factors(end: f64, step: f64) -> Vec<f64> {
    let n = ((end - 1.0) / step).ceil() as usize;
    (0..n).map(|k| 1.0 + k as f64 * step).collect()
}

/// C-B4 zoom_blur: the radial smear of a fast forward motion: `out = (I + sum_z Z_z(I)) / (N + 1)`
/// where `Z_z` zooms the image by z about its centre (a centre crop of 1/z of the size, bilinearly
/// upscaled, as `scipy.ndimage.zoom` order 1 does). z = 1 is in every list, as in the reference.
/// Computed in one pass: each output pixel averages N + 1 bilinear samples at precomputed
/// coordinates (the zoom maps are separable, so they are one column table and one row table per
/// z), in 8.8 fixed point, the average rounded half up. Per factor and row the two source rows are
/// blended vertically over the columns the crop reads, then horizontally in runs of constant source offset.
pub struct ZoomBlur {
    /// The terms that are the frame itself: the frame plus every z = 1 in the list.
    identities: u32,
    /// Terms averaged: the frame plus one per factor.
    terms: u32,
    /// Per factor other than 1, for the configured frame size: column taps, the columns they
    /// read (lo..hi), row taps.
    maps: Vec<(ZoomTaps, usize, usize, Vec<AxisTap>)>,
}

/// Registry constructor of C-B4.
pub const ZOOM_BLUR: CameraBuilder = |s| {
    let (end, step) = ZOOM[s.level()];
    let factors = zoom_factors(end, step);
    let (w, h) = (s.geometry.width as usize, s.geometry.height as usize);
    let c = s.geometry.format.channels();
    let maps = factors
        .iter()
        .filter(|&&z| z != 1.0)
        .map(|&z| {
            let xm = zoom_axis(w, z);
            let lo = xm.first().map_or(0, |t| t.0 as usize);
            let hi = xm.last().map_or(0, |t| t.0 as usize + 2).min(w);
            (ZoomTaps::new(&xm, lo, c), lo, hi, zoom_axis(h, z))
        })
        .collect();
    Ok(Box::new(ZoomBlur {
        identities: factors.iter().filter(|&&z| z == 1.0).count() as u32 + 1,
        terms: factors.len() as u32 + 1,
        maps,
    }))
};

/// One bilinear tap along an axis: (first index, weight of the next index in 1/256). At the last
/// index the weight is 0.
type AxisTap = (u32, u16);

/// Bilinear source coordinates of a zoom by `z` about the centre along an axis of `n` pixels:
/// (first index, weight of the next, in 1/256).
fn zoom_axis(n: usize, z: f64) -> Vec<AxisTap> {
    let centre = (n as f64 - 1.0) / 2.0;
    (0..n)
        .map(|i| {
            let p = (centre + (i as f64 - centre) / z).clamp(0.0, (n - 1) as f64);
            let i0 = p.floor() as usize;
            (i0 as u32, ((p - i0 as f64) * 256.0).round() as u16)
        })
        .collect()
}

/// The horizontal taps of one zoom factor over a row of `c`-byte pixels, as runs of output pixels
/// whose first source pixel is at a constant offset (a zoom by z close to 1 keeps that offset for
/// about 1 / (1 - 1/z) pixels), so that each run is a blend of two contiguous slices.
/// Where the runs are short (strong zooms) the taps are taken pixel by pixel instead.
struct ZoomTaps {
    /// (first sample, end sample, offset of the source sample from the output sample) per run,
    /// in samples of the crop row; empty when the taps go pixel by pixel.
    runs: Vec<(usize, usize, isize)>,
    /// The weight of the second source pixel (1/256) of each output sample (runs).
    weights: Vec<i32>,
    /// Per output pixel: the offset of its first source sample and the weight of the second.
    pixels: Vec<(u32, i32)>,
}

impl ZoomTaps {
    fn new(xm: &[AxisTap], lo: usize, c: usize) -> Self {
        let mut runs: Vec<(usize, usize, isize)> = Vec::new();
        for (x, &(x0, _)) in xm.iter().enumerate() {
            let off = (x0 as isize - lo as isize - x as isize) * c as isize;
            match runs.last_mut() {
                Some(run) if run.2 == off => run.1 += c,
                _ => runs.push((x * c, x * c + c, off)),
            }
        }
        // Runs pay off from about 4 pixels on (measured with the AVX2 copies).
        if runs.len() * 4 > xm.len() {
            let pixels = xm
                .iter()
                .map(|&(x0, wx)| (((x0 as usize - lo) * c) as u32, wx as i32))
                .collect();
            return ZoomTaps {
                runs: Vec::new(),
                weights: Vec::new(),
                pixels,
            };
        }
        let weights = xm
            .iter()
            .flat_map(|&(_, wx)| std::iter::repeat_n(wx as i32, c))
            .collect();
        ZoomTaps {
            runs,
            weights,
            pixels: Vec::new(),
        }
    }

    /// Adds one horizontally blended sample per output sample of `vrow` (vertically blended,
    /// 8.8, with one spare pixel at the end so that the next column always exists): `a + (b -
    /// a) wx` with `a` scaled by 256, in wrapping 32-bit arithmetic (the total is positive and
    /// below 2^32, so it comes out exact).
    fn add(&self, vrow: &[u16], c: usize, acc: &mut [u32]) {
        if self.runs.is_empty() {
            match c {
                1 => zoom_pixels::<1>(vrow, &self.pixels, acc),
                3 => zoom_pixels::<3>(vrow, &self.pixels, acc),
                _ => zoom_pixels::<4>(vrow, &self.pixels, acc),
            }
            return;
        }
        zoom_runs(&self.runs, &self.weights, vrow, c, acc);
    }
}

wide_fn! {
    /// [`ZoomTaps::add`] in runs of constant source offset.
    fn zoom_runs(
        runs: &[(usize, usize, isize)],
        weights: &[i32],
        vrow: &[u16],
        c: usize,
        acc: &mut [u32],
    ) {
        for &(j0, j1, off) in runs {
            let base = (j0 as isize + off) as usize;
            let n = j1 - j0;
            let (a, b) = (&vrow[base..base + n], &vrow[base + c..base + c + n]);
            for (((o, &a), &b), &wx) in acc[j0..j1].iter_mut().zip(a).zip(b).zip(&weights[j0..j1])
            {
                let (a, b) = (a as i32, b as i32);
                *o = o.wrapping_add(((a << 8) + (b - a) * wx) as u32);
            }
        }
    }
}

wide_fn! {
    /// [`ZoomTaps::add`] pixel by pixel, `C` samples each.
    fn zoom_pixels<const C: usize>(vrow: &[u16], xm: &[(u32, i32)], acc: &mut [u32]) {
        for (out, &(i, wx)) in acc.chunks_exact_mut(C).zip(xm) {
            let two = &vrow[i as usize..i as usize + 2 * C];
            let (p, q): (&[u16; C], &[u16; C]) = (
                two[..C].try_into().expect("C"),
                two[C..].try_into().expect("C"),
            );
            for (ch, o) in out.iter_mut().enumerate() {
                let (a, b) = (p[ch] as i32, q[ch] as i32);
                *o = o.wrapping_add(((a << 8) + (b - a) * wx) as u32);
            }
        }
    }
}

wide_fn! {
    /// The vertical blend of two source rows for one zoom factor: `a (256 - wy) + b wy` (8.8).
    fn zoom_vertical(r0: &[u8], r1: &[u8], wy: u16, vrow: &mut [u16]) {
        if wy == 0 {
            for (v, a) in vrow.iter_mut().zip(r0) {
                *v = (*a as u16) << 8;
            }
        } else {
            for ((v, a), b) in vrow.iter_mut().zip(r0).zip(r1) {
                *v = *a as u16 * (256 - wy) + *b as u16 * wy;
            }
        }
    }
}

impl CameraPerturbation for ZoomBlur {
    fn apply(&self, input: &ImageView<'_>, output: &mut ImageViewMut<'_>, _seq: u64) {
        let (w, h, c) = (
            input.width as usize,
            input.height as usize,
            input.format.channels(),
        );
        let (identities, n) = (self.identities, self.terms);
        let (half, recip) = (n << 15, (1u32 << 20).div_ceil(n));
        let format = input.format;
        let rows = output.rows_mut();
        rows.into_par_iter()
            .with_min_len(8)
            .enumerate()
            .for_each_init(
                || (vec![0u32; w * c], vec![0u16; (w + 1) * c]),
                |(acc, vrow), (y, dst)| {
                    // The identity terms, then one bilinear sample per factor, in 8.8 fixed
                    // point: the two source rows blended vertically once per factor (over the
                    // columns it reads), then one horizontal blend per output sample (the same
                    // integers as the direct 2x2 blend, so the same result).
                    let src = input.row(y);
                    zoom_start(src, identities, acc);
                    for (xm, lo, hi, ym) in &self.maps {
                        let (y0, wy) = ym[y];
                        let (y0, y1) = (y0 as usize, (y0 as usize + 1).min(h - 1));
                        let (r0, r1) = (
                            &input.row(y0)[lo * c..hi * c],
                            &input.row(y1)[lo * c..hi * c],
                        );
                        zoom_vertical(r0, r1, wy, vrow);
                        xm.add(vrow, c, acc);
                    }
                    zoom_finish(acc, half, recip, dst);
                    copy_alpha(format, src, dst);
                },
            );
    }
}

wide_fn! {
    /// The identity terms of the zoom average: `acc = (v identities) << 16`.
    fn zoom_start(src: &[u8], identities: u32, acc: &mut [u32]) {
        for (a, &v) in acc.iter_mut().zip(src) {
            *a = (v as u32 * identities) << 16;
        }
    }
}

wide_fn! {
    /// round(acc / (n 2^16)) = floor(t / n) with t = (acc + n 2^15) >> 16 below 2^12, the
    /// division by n as a multiplication by `recip` = ceil(2^20 / n) (exact in that range);
    /// `half` = n 2^15.
    fn zoom_finish(acc: &[u32], half: u32, recip: u32, dst: &mut [u8]) {
        for (d, a) in dst.iter_mut().zip(acc) {
            *d = ((((a + half) >> 16) * recip) >> 20) as u8;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::image::PixelFormat;

    #[test]
    fn zoom_blur_equals_the_direct_two_by_two_blend() {
        for format in [PixelFormat::Rgb8, PixelFormat::Rgba8, PixelFormat::Mono8] {
            let base = crate::synthetic::street_image(37, 23, 1);
            let img = base.convert(format);
            let (w, h, c) = (37usize, 23usize, format.channels());
            for sev in [2u8, 5] {
                let got = crate::camera::apply_once(ZOOM_BLUR, sev, 1, &img, 0);
                let (end, step) = ZOOM[sev as usize - 1];
                let factors = zoom_factors(end, step);
                let n = factors.len() as u32 + 1;
                for y in 0..h {
                    for x in 0..w {
                        for ch in 0..c {
                            let mut acc = (img.view().row(y)[x * c + ch] as u32) << 16;
                            for &z in &factors {
                                let (x0, wx) = zoom_axis(w, z)[x];
                                let (y0, wy) = zoom_axis(h, z)[y];
                                let x1 = (x0 + 1).min(w as u32 - 1);
                                let y1 = (y0 + 1).min(h as u32 - 1);
                                let p = |yy: u32, xx: u32| {
                                    img.view().row(yy as usize)[xx as usize * c + ch] as u32
                                };
                                let (wx, wy) = (wx as u32, wy as u32);
                                let top = p(y0, x0) * (256 - wx) + p(y0, x1) * wx;
                                let bot = p(y1, x0) * (256 - wx) + p(y1, x1) * wx;
                                acc += top * (256 - wy) + bot * wy;
                            }
                            // Rounded half up.
                            let want = ((acc + n * 32768) / (n * 65536)) as u8;
                            if format.channels() == 4 && ch == 3 {
                                continue;
                            }
                            assert_eq!(got.view().row(y)[x * c + ch], want, "{format:?} s{sev}");
                        }
                    }
                }
            }
        }
    }
}
