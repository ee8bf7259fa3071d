//! Blur family (C-B): convolutions and resampling that remove detail.

use super::ops::{
    GaussianRows, byte, copy_alpha, gaussian_blur, map_value, par_rows, reflect101, row_rng,
    wide_fn,
};
use super::{CameraBuilder, CameraPerturbation};
use crate::image::{Image, ImageView, ImageViewMut, PixelFormat};
use rayon::prelude::*;

/// C-B5 gaussian_blur: kernel size k, severities 1..5 (PerturbationDrive `gaussian_blur`, which
/// calls `cv2.GaussianBlur(k, k)` with sigma 0, so sigma = 0.3((k-1)/2 - 1) + 0.8 = .8 1.4 2.6 4.1 6.5).
pub const GAUSSIAN_KERNEL: [usize; 5] = [3, 7, 15, 25, 41];

/// C-B5 gaussian_blur: a k x k Gaussian with OpenCV's sigma for k and reflect-101 borders on every
/// colour channel; alpha is copied. Exact (OpenCV's 8-bit fixed point) up to k = 15; k = 25 is
/// computed at half and k = 41 at quarter resolution with the remaining width (see
/// [`super::ops::GaussianRows`]: mean error about 0.25 levels against the exact kernel).
pub struct GaussianBlur {
    k: usize,
}

/// Registry constructor of C-B5.
pub const GAUSSIAN: CameraBuilder = |s| {
    Ok(Box::new(GaussianBlur {
        k: GAUSSIAN_KERNEL[s.level()],
    }))
};

impl CameraPerturbation for GaussianBlur {
    fn apply(&self, input: &ImageView<'_>, output: &mut ImageViewMut<'_>, _seq: u64) {
        gaussian_blur(input, output, self.k, 0.0);
    }
}

/// C-B1 defocus_blur: disk radius in pixels, severities 1..5 (PerturbationDrive `defocus_blur`).
pub const DEFOCUS_RADIUS: [usize; 5] = [2, 5, 6, 9, 12];

/// C-B1 defocus_blur: an out-of-focus lens: convolution with the binary disk x^2 + y^2 <= r^2
/// (normalised), reflect-101 borders, as `cv2.filter2D` with the reference's kernel. Computed
/// exactly with per-row prefix sums: each disk row is one horizontal segment, two lookups.
pub struct DefocusBlur {
    /// Half-width of the disk's row at each vertical offset -r..=r.
    half_widths: Vec<usize>,
    /// Number of disk pixels.
    count: usize,
}

/// Registry constructor of C-B1.
pub const DEFOCUS: CameraBuilder = |s| {
    let r = DEFOCUS_RADIUS[s.level()] as i64;
    let half_widths: Vec<usize> = (-r..=r)
        .map(|dy| ((r * r - dy * dy) as f64).sqrt().floor() as usize)
        .collect();
    let count: usize = half_widths.iter().map(|w| 2 * w + 1).sum();
    Ok(Box::new(DefocusBlur { half_widths, count }))
};

/// Running sums modulo 2^16 of one row of `C`-byte pixels padded by `pad` reflected pixels at
/// each end: `pre[(x + 1) C + ch]` is the sum of the first `x + 1` padded samples of channel
/// `ch` (`pre[..C]` stays 0). The sums stay in registers from pixel to pixel.
fn prefix_row<const C: usize>(src: &[u8], pad: usize, pre: &mut [u16]) {
    let w = src.len() / C;
    let mut run = [0u16; C];
    let mut add = |sx: usize, out: &mut [u16]| {
        for ch in 0..C {
            run[ch] = run[ch].wrapping_add(src[sx * C + ch] as u16);
            out[ch] = run[ch];
        }
    };
    let mut outs = pre[C..].chunks_exact_mut(C);
    for (px, out) in outs.by_ref().take(pad).enumerate() {
        add(reflect101(px as i64 - pad as i64, w), out);
    }
    for (sx, out) in outs.by_ref().take(w).enumerate() {
        add(sx, out);
    }
    for (px, out) in outs.enumerate() {
        add(reflect101((w + px) as i64, w), out);
    }
}

impl CameraPerturbation for DefocusBlur {
    fn apply(&self, input: &ImageView<'_>, output: &mut ImageViewMut<'_>, _seq: u64) {
        let (w, h, c) = (
            input.width as usize,
            input.height as usize,
            input.format.channels(),
        );
        let r = self.half_widths.len() / 2;
        let pad = r;
        // Prefix sums of every row padded by reflection, modulo 2^16: prefix[x] = sum of
        // padded[0..x]. A segment's sum (at most (2r + 1) 255 < 2^16) is the wrapping difference
        // of two of them, exactly.
        let pw = w + 2 * pad;
        let mut prefix = vec![0u16; h * (pw + 1) * c];
        prefix
            .par_chunks_mut((pw + 1) * c)
            .enumerate()
            .for_each(|(y, pre)| match c {
                1 => prefix_row::<1>(input.row(y), pad, pre),
                3 => prefix_row::<3>(input.row(y), pad, pre),
                _ => prefix_row::<4>(input.row(y), pad, pre),
            });
        // Disk rows summed in u16 before widening: as many as fit 2^16 at the widest segment.
        let per_group = (u16::MAX as usize / ((2 * r + 1) * 255)).max(1);
        let format = input.format;
        let count = self.count as u64;
        let (half, recip) = ((count / 2) as u32, (1u64 << 32).div_ceil(count));
        let group_len = (per_group / 2).max(1);
        let rows = output.rows_mut();
        rows.into_par_iter()
            .with_min_len(8)
            .enumerate()
            .for_each_init(
                || (vec![0u32; w * c], vec![0u16; w * c]),
                |(acc, part), (y, dst)| {
                    let src = input.row(y);
                    acc.fill(0);
                    // Rows dy and -dy have the same half-width: they are summed together. Segment
                    // [x - hw, x + hw] of the unpadded row = padded [x + pad - hw, x + pad + hw].
                    let pre = |dy: i64| {
                        let sy = reflect101(y as i64 + dy, h);
                        &prefix[sy * (pw + 1) * c..(sy + 1) * (pw + 1) * c]
                    };
                    // Half-widths of the rows dy = 0..=r, in groups.
                    for (g, group) in self.half_widths[r..].chunks(group_len).enumerate() {
                        part.fill(0);
                        for (i, &hw) in group.iter().enumerate() {
                            let dy = (g * group_len + i) as i64;
                            let (lo, hi) = ((pad - hw) * c, (pad + hw + 1) * c);
                            let (a, b) = (pre(dy), pre(-dy));
                            let (ahi, alo) = (&a[hi..hi + w * c], &a[lo..lo + w * c]);
                            if dy == 0 {
                                disk_segments(part, (ahi, alo), None);
                            } else {
                                disk_segments(
                                    part,
                                    (ahi, alo),
                                    Some((&b[hi..][..w * c], &b[lo..])),
                                );
                            }
                        }
                        widen_into(part, acc);
                    }
                    // The disk has an odd number of pixels, so no sum lies halfway between two levels:
                    // round(a / n) = (a + n / 2) / n, the division as a multiplication.
                    divide_rounded(acc, half, recip, dst);
                    copy_alpha(format, src, dst);
                },
            );
    }
}

wide_fn! {
    /// Adds the segment sums `hi - lo` of one row of prefix sums (and of a second row when
    /// given) to `part`, modulo 2^16.
    fn disk_segments(part: &mut [u16], a: (&[u16], &[u16]), b: Option<(&[u16], &[u16])>) {
        let (ahi, alo) = a;
        match b {
            None => {
                for ((p, u), v) in part.iter_mut().zip(ahi).zip(alo) {
                    *p = p.wrapping_add(u.wrapping_sub(*v));
                }
            }
            Some((bhi, blo)) => {
                for ((((p, u), v), s), t) in part.iter_mut().zip(ahi).zip(alo).zip(bhi).zip(blo) {
                    *p = p
                        .wrapping_add(u.wrapping_sub(*v))
                        .wrapping_add(s.wrapping_sub(*t));
                }
            }
        }
    }
}

wide_fn! {
    /// `acc += part`, widened.
    fn widen_into(part: &[u16], acc: &mut [u32]) {
        for (a, p) in acc.iter_mut().zip(part) {
            *a += *p as u32;
        }
    }
}

wide_fn! {
    /// `dst = (acc + half) recip >> 32`: a rounded division by a constant as a multiplication.
    fn divide_rounded(acc: &[u32], half: u32, recip: u64, dst: &mut [u8]) {
        for (d, a) in dst.iter_mut().zip(acc) {
            *d = (((*a + half) as u64 * recip) >> 32) as u8;
        }
    }
}

/// C-B2 glass_blur: maximum displacement in pixels, severities 1..5 (PerturbationDrive
/// `glass_blur`).
pub const GLASS_DISPLACEMENT: [i64; 5] = [2, 5, 6, 9, 12];

/// C-B2 glass_blur: frosted glass: every output pixel is the input pixel at a random offset
/// (dy, dx), each uniform in [-d, d], clipped to the image, drawn anew every frame. As in
/// PerturbationDrive there is no Gaussian pre- or post-blur (imagecorruptions' variant has them).
pub struct GlassBlur {
    seed: u64,
    d: i64,
}

/// Registry constructor of C-B2.
pub const GLASS: CameraBuilder = |s| {
    Ok(Box::new(GlassBlur {
        seed: s.seed,
        d: GLASS_DISPLACEMENT[s.level()],
    }))
};

impl CameraPerturbation for GlassBlur {
    fn apply(&self, input: &ImageView<'_>, output: &mut ImageViewMut<'_>, seq: u64) {
        let (w, h, c) = (
            input.width as i64,
            input.height as i64,
            input.format.channels(),
        );
        let span = (2 * self.d + 1) as u64;
        let format = input.format;
        par_rows(input, output, |y, src, dst| {
            let mut rng = row_rng(self.seed, seq, 0xB2, y);
            for (x, q) in dst.chunks_exact_mut(c).enumerate() {
                let r = rng.next_u64();
                let dy = (((r & 0xffff_ffff) * span) >> 32) as i64 - self.d;
                let dx = (((r >> 32) * span) >> 32) as i64 - self.d;
                let sy = (y as i64 + dy).clamp(0, h - 1) as usize;
                let sx = (x as i64 + dx).clamp(0, w - 1) as usize;
                q.copy_from_slice(&input.row(sy)[sx * c..sx * c + c]);
            }
            copy_alpha(format, src, dst);
        });
    }
}

/// C-B3 motion_blur: (kernel size n, angle theta in degrees from vertical), severities 1..5
/// (PerturbationDrive `motion_blur`).
pub const MOTION: [(usize, f64); 5] = [(2, 5.0), (4, 12.0), (6, 20.0), (10, 30.0), (15, 45.0)];

/// The reference's motion kernel as a list of (row, column) taps of an n x n kernel: for each row y,
/// column `int(tan(theta) (y - n/2) + n/2)` (truncated towards zero), kept inside the kernel.
pub fn motion_taps(n: usize, theta_deg: f64) -> Vec<(usize, usize)> {
    let t = theta_deg.to_radians().tan();
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

/// C-B6 low_pass: kernel size applied to the brightness channel, severities 1..5
/// (PerturbationDrive `low_pass_filter`: 15 23 30 36 40, rounded up to odd).
pub const LOW_PASS_KERNEL: [usize; 5] = [15, 23, 31, 37, 41];

/// C-B6 low_pass: a Gaussian blur of the HSV value channel only (OpenCV sigma for k), hue and
/// saturation kept: the scene loses its fine detail in brightness while colours stay in place.
/// The value plane is blurred (see [`super::ops::GaussianRows`]) and each pixel's channels are
/// rescaled to the blurred value (see [`super::ops::map_value`]).
pub struct LowPass {
    k: usize,
}

/// Registry constructor of C-B6.
pub const LOW_PASS: CameraBuilder = |s| {
    Ok(Box::new(LowPass {
        k: LOW_PASS_KERNEL[s.level()],
    }))
};

impl CameraPerturbation for LowPass {
    fn apply(&self, input: &ImageView<'_>, output: &mut ImageViewMut<'_>, _seq: u64) {
        let (w, h, c) = (
            input.width as usize,
            input.height as usize,
            input.format.channels(),
        );
        let [ri, gi, bi] = input.format.rgb_offsets();
        let mut v = Image::new(w as u32, h as u32, PixelFormat::Mono8);
        v.data
            .par_chunks_mut(w.max(1))
            .enumerate()
            .for_each(|(y, row)| {
                for (d, p) in row.iter_mut().zip(input.row(y).chunks_exact(c)) {
                    *d = p[ri].max(p[gi]).max(p[bi]);
                }
            });
        let mut blurred = Image::new(w as u32, h as u32, PixelFormat::Mono8);
        gaussian_blur(&v.view(), &mut blurred.view_mut(), self.k, 0.0);
        let blurred = blurred.data;
        map_value(input, output, |y, x, _| blurred[y * w + x]);
    }
}

/// C-B7 high_pass: kernel size of the Gaussian subtracted, severities 1..5 (PerturbationDrive
/// `high_pass_filter`; OpenCV sigmas 5.6 9.2 12.8 16.4 17.3).
pub const HIGH_PASS_KERNEL: [usize; 5] = [35, 59, 83, 107, 113];

/// C-B7 high_pass: unsharp-mask emphasis of edges and noise, `out = clip(2 I - G_k(I))` per colour
/// channel, with the Gaussian computed as in [`super::ops::GaussianRows`]; alpha is copied. The
/// paper notes its distortion is nearly flat across severities, as the reference's is.
pub struct HighPass {
    k: usize,
}

/// Registry constructor of C-B7.
pub const HIGH_PASS: CameraBuilder = |s| {
    Ok(Box::new(HighPass {
        k: HIGH_PASS_KERNEL[s.level()],
    }))
};

impl CameraPerturbation for HighPass {
    fn apply(&self, input: &ImageView<'_>, output: &mut ImageViewMut<'_>, _seq: u64) {
        let format = input.format;
        let gaussian = GaussianRows::new(input, self.k, 0.0);
        par_rows(input, output, |y, src, dst| {
            let mut blurred = vec![0f32; dst.len()];
            gaussian.row(y, &mut blurred);
            for ((d, &s), b) in dst.iter_mut().zip(src).zip(&mut blurred) {
                *b = 2.0 * s as f32 - *b;
                *d = byte(*b + 0.5);
            }
            copy_alpha(format, src, dst);
        });
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::camera::CameraSetup;

    fn run(b: CameraBuilder, sev: u8, img: &Image) -> Image {
        let p = b(&CameraSetup {
            severity: sev,
            seed: 1,
            geometry: img.geometry(),
        })
        .unwrap();
        let mut out = Image::with_geometry(img.geometry());
        p.apply(&img.view(), &mut out.view_mut(), 0);
        out
    }

    #[test]
    fn zoom_blur_equals_the_direct_two_by_two_blend() {
        for format in [PixelFormat::Rgb8, PixelFormat::Rgba8, PixelFormat::Mono8] {
            let base = crate::synthetic::street_image(37, 23, 1);
            let img = base.convert(format);
            let (w, h, c) = (37usize, 23usize, format.channels());
            for sev in [2u8, 5] {
                let got = run(ZOOM_BLUR, sev, &img);
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

    fn var(img: &Image) -> f64 {
        let n = img.data.len() as f64;
        let m = img.data.iter().map(|&v| v as f64).sum::<f64>() / n;
        img.data
            .iter()
            .map(|&v| (v as f64 - m).powi(2))
            .sum::<f64>()
            / n
    }

    #[test]
    fn blurs_keep_the_mean_and_lose_variance_with_severity() {
        let img = crate::synthetic::street_image(200, 120, 1);
        let mean = |i: &Image| i.data.iter().map(|&v| v as f64).sum::<f64>() / i.data.len() as f64;
        for b in [GAUSSIAN, DEFOCUS, MOTION_BLUR, ZOOM_BLUR] {
            let mut last = var(&img) + 1.0;
            for s in 1..=5 {
                let out = run(b, s, &img);
                assert!((mean(&out) - mean(&img)).abs() < 1.5, "mean kept");
                let v = var(&out);
                assert!(
                    v <= last + 1.0,
                    "variance falls with severity: s{s} {v} > {last}"
                );
                last = v;
            }
        }
    }

    #[test]
    fn motion_kernel_is_the_reference_line() {
        assert_eq!(
            motion_taps(15, 45.0),
            (0..15).map(|y| (y, y)).collect::<Vec<_>>()
        );
        assert_eq!(motion_taps(2, 5.0), vec![(0, 0), (1, 1)]);
        // Near-vertical: theta 12 degrees from vertical on a 4 x 4 kernel.
        assert_eq!(motion_taps(4, 12.0), vec![(0, 1), (1, 1), (2, 2), (3, 2)]);
    }

    #[test]
    fn zoom_factor_lists_match_numpy_arange() {
        let n: Vec<usize> = ZOOM
            .iter()
            .map(|&(e, s)| zoom_factors(e, s).len())
            .collect();
        // numpy: [2, 12, 8, 11, 11] (float error puts 1.01 and 1.11 inside the first two ranges).
        assert_eq!(n, vec![2, 12, 8, 11, 11]);
        assert!((zoom_factors(1.31, 0.03)[10] - 1.30).abs() < 1e-12);
    }

    #[test]
    fn defocus_is_a_disk_average() {
        // A single bright pixel spreads into a disk of the configured radius.
        let mut img = Image::new(41, 41, PixelFormat::Mono8);
        img.data[20 * 41 + 20] = 255;
        let out = run(DEFOCUS, 2, &img); // r = 5: 81 pixels
        let lit = out.data.iter().filter(|&&v| v > 0).count();
        assert_eq!(lit, 81);
        assert_eq!(out.data[20 * 41 + 25], 3, "edge of the disk");
        assert_eq!(out.data[20 * 41 + 26], 0, "outside the disk");
    }

    #[test]
    fn glass_blur_only_moves_pixels_within_reach() {
        let mut img = Image::new(64, 64, PixelFormat::Mono8);
        for (i, v) in img.data.iter_mut().enumerate() {
            *v = (i % 64) as u8 * 4; // value encodes the column
        }
        let out = run(GLASS, 1, &img); // d = 2
        for y in 0..64 {
            for x in 0..64 {
                let sx = out.data[y * 64 + x] as i64 / 4;
                assert!((sx - x as i64).abs() <= 2);
            }
        }
        assert_ne!(out, img);
    }

    #[test]
    fn high_pass_sharpens_edges() {
        let mut img = Image::new(80, 80, PixelFormat::Mono8);
        for (i, v) in img.data.iter_mut().enumerate() {
            *v = if i % 80 < 40 { 80 } else { 160 };
        }
        let out = run(HIGH_PASS, 1, &img);
        // Overshoot on both sides of the edge, flat far away.
        assert!(out.data[40 * 80 + 38] < 80 && out.data[40 * 80 + 41] > 160);
        assert_eq!(out.data[40 * 80 + 2], 80);
    }
}
