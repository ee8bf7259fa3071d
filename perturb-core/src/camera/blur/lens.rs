//! Lens and glass blurs (C-B1 defocus, C-B2 glass).

use crate::camera::ops::{copy_alpha, par_rows, reflect101, row_rng, wide_fn};
use crate::camera::{CameraBuilder, CameraPerturbation};
use crate::image::{ImageView, ImageViewMut};
use rayon::prelude::*;

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
