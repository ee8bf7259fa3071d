//! Distortion family (C-D): geometric and sharpness changes.

use super::ops::{
    byte, copy_alpha, fill_quarters, gaussian_kernel, pad_row_copy, par_rows, reflect101, row_rng,
    wide_fn,
};
use super::{CameraBuilder, CameraPerturbation};
use crate::image::{ImageView, ImageViewMut};
use crate::rng::Rng;
use rayon::prelude::*;

/// The source pixels a band of remapped rows can reach: rows `top..top + rows` and columns
/// `-pad..w + pad` of the image, reflected (reflect-101) where they fall outside it, as one
/// contiguous block, so that a bilinear tap is four reads at fixed offsets with no border test.
struct Window {
    data: Vec<u8>,
    /// Bytes per window row: `(w + 2 pad) c`.
    stride: usize,
    top: i64,
    pad: usize,
}

impl Window {
    /// The window over rows `top..top + rows` of `input`, `pad` pixels of margin each side.
    fn new(input: &ImageView<'_>, top: i64, rows: usize, pad: usize) -> Self {
        let (w, h, c) = (
            input.width as usize,
            input.height as usize,
            input.format.channels(),
        );
        let stride = (w + 2 * pad) * c;
        let mut data = vec![0u8; stride * rows];
        for (i, out) in data.chunks_exact_mut(stride).enumerate() {
            let src = input.row(reflect101(top + i as i64, h));
            out[pad * c..(pad + w) * c].copy_from_slice(src);
            for k in 0..pad {
                let (l, r) = (k as i64 - pad as i64, (w + k) as i64);
                for (x, at) in [(l, k), (r, pad + w + k)] {
                    let sx = reflect101(x, w) * c;
                    out[at * c..at * c + c].copy_from_slice(&src[sx..sx + c]);
                }
            }
        }
        Window {
            data,
            stride,
            top,
            pad,
        }
    }
}

wide_fn! {
    /// One output row of `cv2.remap` with bilinear interpolation in OpenCV's fixed point: each source
    /// coordinate is rounded to 1/32 pixel (`INTER_BITS` = 5) and the four weights are products of
    /// those fractions (exact in 1/1024), rounded once; borders reflect (reflect-101, through the
    /// window's margins). Pixel `x` of row `y` samples `(x + dx[x], y + dy[x])`; `C` bytes per pixel,
    /// all interpolated. `columns` holds x as f32 for each x; the displacements must stay within the
    /// window's margin less one pixel (they are clamped to it, so a larger one cannot read outside).
    /// `taps` is working space (one entry per pixel).
    fn remap_row<const C: usize>(
        win: &Window,
        y: usize,
        fields: (&[f32], &[f32], &[f32]),
        taps: &mut Vec<(u32, u32, u32)>,
        dst: &mut [u8],
    ) {
        let (columns, dx, dy) = fields;
        // Source coordinates in 1/32 pixel, rounded half to even, in vectorisable passes: adding
        // 1.5 2^23 leaves the rounded integer in the low mantissa bits (exact for |v| < 2^22).
        let round = |v: f32| ((v + 12_582_912.0).to_bits() as i32).wrapping_sub(0x4B40_0000);
        let w = columns.len() as i32;
        let pad = win.pad as i32;
        let (rows, stride) = ((win.data.len() / win.stride) as i32, win.stride as i32);
        let (yf, top) = (y as f32, win.top as i32);
        // Per pixel: the window offset of its top-left tap and the two fractions.
        // A plain loop, not `collect`: a closure inside a `wide_fn!` body is compiled for AVX2,
        // and the library's collecting code (compiled for the baseline) cannot inline it.
        taps.resize(columns.len(), (0, 0, 0));
        for (t, ((&ox, &x), &oy)) in taps.iter_mut().zip(dx.iter().zip(columns).zip(dy)) {
            let (fx, fy) = (round((x + ox) * 32.0), round((yf + oy) * 32.0));
            let wx = (pad + (fx >> 5)).clamp(0, w + 2 * pad - 2);
            let wy = ((fy >> 5) - top).clamp(0, rows - 2);
            *t = (
                (wy * stride + wx * C as i32) as u32,
                (fx & 31) as u32,
                (fy & 31) as u32,
            );
        }
        let data = &win.data[..];
        let stride = win.stride;
        for (q, &(at, ax, ay)) in dst.chunks_exact_mut(C).zip(taps.iter()) {
            let at = at as usize;
            let weights = [
                (32 - ax) * (32 - ay),
                ax * (32 - ay),
                (32 - ax) * ay,
                ax * ay,
            ];
            let px = |i: usize| -> &[u8; C] { data[i..i + C].try_into().expect("one pixel") };
            let (pa, pb, pc, pd) = (px(at), px(at + C), px(at + stride), px(at + stride + C));
            for ch in 0..C {
                let v = pa[ch] as u32 * weights[0]
                    + pb[ch] as u32 * weights[1]
                    + pc[ch] as u32 * weights[2]
                    + pd[ch] as u32 * weights[3];
                q[ch] = ((v + 512) >> 10) as u8;
            }
        }
    }
}

/// C-D1 elastic: (alpha, sigma) of the displacement field, severities 1..5 (PerturbationDrive
/// `elastic`).
pub const ELASTIC_LEVELS: [(f32, f64); 5] =
    [(2.0, 0.4), (3.0, 0.75), (5.0, 0.9), (7.0, 1.2), (10.0, 1.5)];

/// C-D1 elastic: each frame draws two fields of U(-1, 1) alpha per pixel, smooths each with a
/// Gaussian of the severity's sigma (kernel 2 ceil(4 sigma) + 1, as OpenCV picks for float images),
/// and resamples the image at (x + dx, y + dy) bilinearly with reflected borders (`cv2.remap`, in its
/// fixed point: coordinates in 1/32 pixel). With
/// the reference's small sigmas this is a fine high-frequency jitter of the pixels (imagecorruptions'
/// smooth warp uses far larger sigmas; the project follows PerturbationDrive).
pub struct Elastic {
    seed: u64,
    alpha: f32,
    kernel: Vec<f32>,
}

/// Registry constructor of C-D1.
pub const ELASTIC: CameraBuilder = |s| {
    let (alpha, sigma) = ELASTIC_LEVELS[s.level()];
    let k = 2 * (4.0 * sigma).ceil() as usize + 1;
    Ok(Box::new(Elastic {
        seed: s.seed,
        alpha,
        kernel: gaussian_kernel(k, sigma),
    }))
};

impl Elastic {
    /// Row `y` of displacement field `salt` of frame `seq` before smoothing: U(-1, 1) alpha per
    /// pixel, one random stream per row, four 16-bit draws per 64-bit output.
    fn raw_row(&self, seq: u64, salt: u64, y: usize, row: &mut [f32]) {
        let mut rng = row_rng(self.seed, seq, salt, y);
        // (u + 1/2) / 2^15 - 1 for a 16-bit u: centred, steps of 2^-15 alpha (the remap rounds
        // to 1/32 pixel).
        let (unit, offset) = (self.alpha / 32768.0, self.alpha * (0.5 / 32768.0 - 1.0));
        fill_quarters(&mut rng, row, |u| u as f32 * unit + offset);
    }

    /// Horizontal smoothing of a raw row (reflect-101): the row padded once, then one shifted
    /// multiply-add per pair of symmetric taps.
    fn smooth_row(&self, raw: &[f32], padded: &mut Vec<f32>, out: &mut [f32]) {
        let (w, r) = (raw.len(), self.kernel.len() / 2);
        padded.resize(w + 2 * r, 0.0);
        pad_row_copy(raw, 1, r, padded);
        smooth_padded(&self.kernel, padded, out);
    }
}

impl CameraPerturbation for Elastic {
    fn apply(&self, input: &ImageView<'_>, output: &mut ImageViewMut<'_>, seq: u64) {
        let (w, h, c) = (
            input.width as usize,
            input.height as usize,
            input.format.channels(),
        );
        let format = input.format;
        let k = self.kernel.len();
        let r = k / 2;
        // Bands of rows; within a band the horizontally smoothed rows of both fields live in a
        // ring of k rows, so the fields are never held whole. Each source row's draws depend
        // only on (seed, seq, field, row), so rows shared by two bands are drawn identically.
        let columns: Vec<f32> = (0..w).map(|x| x as f32).collect();
        let rows = output.rows_mut();
        rows.into_par_iter()
            .enumerate()
            .chunks(128)
            .for_each(|chunk| {
                let y0 = chunk[0].0;
                let lo = y0 as i64 - r as i64;
                // The displacements are at most alpha (smoothed draws of U(-alpha, alpha)).
                let span = self.alpha.ceil() as usize + 2;
                let win = Window::new(input, y0 as i64 - span as i64, chunk.len() + 2 * span, span);
                let mut ring = [vec![0f32; k * w], vec![0f32; k * w]];
                let (mut raw, mut padded) = (vec![0f32; w], Vec::new());
                let slot = |i: usize| (i % k) * w..(i % k + 1) * w;
                let mut fill = |i: usize, ring: &mut [Vec<f32>; 2]| {
                    let sy = reflect101(lo + i as i64, h);
                    for (field, salt) in ring.iter_mut().zip([0xD1, 0xD2]) {
                        self.raw_row(seq, salt, sy, &mut raw);
                        self.smooth_row(&raw, &mut padded, &mut field[slot(i)]);
                    }
                };
                for i in 0..k - 1 {
                    fill(i, &mut ring);
                }
                let mut d = [vec![0f32; w], vec![0f32; w]];
                let mut taps = Vec::with_capacity(w);
                for (y, dst) in chunk {
                    let i0 = y - y0;
                    fill(i0 + k - 1, &mut ring);
                    // Vertical smoothing, symmetric taps paired.
                    for (out, field) in d.iter_mut().zip(&ring) {
                        smooth_ring(&self.kernel, field, i0, out);
                    }
                    let fields = (&columns[..], &d[0][..], &d[1][..]);
                    match c {
                        1 => remap_row::<1>(&win, y, fields, &mut taps, dst),
                        3 => remap_row::<3>(&win, y, fields, &mut taps, dst),
                        _ => remap_row::<4>(&win, y, fields, &mut taps, dst),
                    }
                    copy_alpha(format, input.row(y), dst);
                }
            });
    }
}

wide_fn! {
    /// `out[x] = sum_t kernel[t] padded[x + t]` for a symmetric kernel of length 2r + 1 (taps t
    /// and 2r - t share one multiply); `padded` is `out.len() + 2r` long.
    fn smooth_padded(kernel: &[f32], padded: &[f32], out: &mut [f32]) {
        let (w, r) = (out.len(), kernel.len() / 2);
        let kc = kernel[r];
        for (o, s) in out.iter_mut().zip(&padded[r..r + w]) {
            *o = kc * s;
        }
        for (t, k) in kernel[..r].iter().enumerate() {
            let (a, b) = (&padded[t..t + w], &padded[2 * r - t..2 * r - t + w]);
            for ((o, s), u) in out.iter_mut().zip(a).zip(b) {
                *o += k * (s + u);
            }
        }
    }
}

wide_fn! {
    /// The vertical smoothing of one output row from a ring of `kernel.len()` smoothed rows of
    /// `out.len()` samples, the row `i0 + t` in slot `(i0 + t) % k` (symmetric taps paired).
    fn smooth_ring(kernel: &[f32], ring: &[f32], i0: usize, out: &mut [f32]) {
        let (w, k) = (out.len(), kernel.len());
        let r = k / 2;
        let slot = |i: usize| &ring[(i % k) * w..(i % k + 1) * w];
        let kc = kernel[r];
        for (o, s) in out.iter_mut().zip(slot(i0 + r)) {
            *o = kc * s;
        }
        for (t, kw) in kernel[..r].iter().enumerate() {
            let (a, b) = (slot(i0 + t), slot(i0 + 2 * r - t));
            for ((o, s), u) in out.iter_mut().zip(a).zip(b) {
                *o += kw * (s + u);
            }
        }
    }
}

/// C-D2 pixelate: scale factor of the low-resolution image, severities 1..5 (PerturbationDrive
/// `pixelate`).
pub const PIXELATE_FACTOR: [f64; 5] = [0.85, 0.55, 0.35, 0.20, 0.10];

/// C-D2 pixelate: blocky low resolution, as the reference intends: the image is reduced to
/// `floor(W f) x floor(H f)` by area averaging and enlarged back with nearest-neighbour sampling.
/// Output pixel x (of n) shows small pixel `floor(x s / n)`, and small pixel i averages exactly the
/// source pixels that show it, `ceil(n i / s) .. ceil(n (i + 1) / s)`: the footprint and the
/// mapping agree, so a frame made of constant blocks on that grid passes through unchanged and no
/// content moves (before issue 16 the footprint was rounded down while the mapping rounded up,
/// which shifted most columns by one pixel at f = 0.85 and made severity 1 stronger than 4).
///
/// Deviation: PerturbationDrive passes its interpolation flags in the `dst` position of
/// `cv2.resize`, so both resizes are bilinear and the result is blurry rather than blocky; this
/// implements the blocky pixelation its name and imagecorruptions describe.
pub struct Pixelate {
    factor: f64,
}

/// Registry constructor of C-D2.
pub const PIXELATE: CameraBuilder = |s| {
    Ok(Box::new(Pixelate {
        factor: PIXELATE_FACTOR[s.level()],
    }))
};

impl CameraPerturbation for Pixelate {
    fn apply(&self, input: &ImageView<'_>, output: &mut ImageViewMut<'_>, _seq: u64) {
        let (w, h, c) = (
            input.width as usize,
            input.height as usize,
            input.format.channels(),
        );
        let (sw, sh) = (
            ((w as f64 * self.factor) as usize).max(1),
            ((h as f64 * self.factor) as usize).max(1),
        );
        // Footprint of small pixel i along an axis of n pixels: the source pixels x with
        // floor(x s / n) = i, which the enlargement maps to it: [ceil(n i / s), ceil(n (i+1) / s)),
        // at least one pixel since s <= n.
        let span = |i: usize, n: usize, s: usize| {
            let a = (n * i).div_ceil(s);
            (a.min(n - 1), (n * (i + 1)).div_ceil(s).clamp(a + 1, n))
        };
        // Rounded division by a footprint size n through 32.32 reciprocals (exact for the sums
        // of at most a few hundred bytes that occur here).
        let most = (h.div_ceil(sh) + 1) * (w.div_ceil(sw) + 1);
        let recip: Vec<u64> = (0..=most as u64)
            .map(|n| if n == 0 { 0 } else { (1u64 << 32).div_ceil(n) })
            .collect();
        let xspans: Vec<(u32, u32)> = (0..sw)
            .map(|i| {
                let (a, b) = span(i, w, sw);
                (a as u32, b as u32)
            })
            .collect();
        let xmap: Vec<u32> = (0..w).map(|x| (x * sw / w).min(sw - 1) as u32).collect();
        // Output rows in runs showing the same small row j = floor(y sh / h): the run's first row
        // is enlarged from small row j, the others are copies of it.
        let mut runs: Vec<(usize, Vec<&mut [u8]>)> = Vec::with_capacity(sh);
        for (y, row) in output.rows_mut().into_iter().enumerate() {
            let j = (y * sh / h).min(sh - 1);
            match runs.last_mut() {
                Some((k, rows)) if *k == j => rows.push(row),
                _ => runs.push((j, vec![row])),
            }
        }
        let format = input.format;
        runs.into_par_iter().for_each_init(
            || PixelateRows {
                sums: vec![0; (w + 1) * c],
                small: vec![0; sw * c],
            },
            |buf, (j, mut rows)| {
                let (y0, y1) = span(j, h, sh);
                buf.column_sums(input, y0..y1, c);
                let n_rows = y1 - y0;
                let (first, rest) = rows.split_first_mut().expect("a run has a row");
                match c {
                    1 => buf.row::<1>(&xspans, n_rows, &recip, &xmap, first),
                    3 => buf.row::<3>(&xspans, n_rows, &recip, &xmap, first),
                    _ => buf.row::<4>(&xspans, n_rows, &recip, &xmap, first),
                }
                for r in rest.iter_mut() {
                    r.copy_from_slice(first);
                }
                if format.alpha_offset().is_some() {
                    for (y, r) in (y0..).zip(rows.iter_mut()) {
                        copy_alpha(format, input.row(y), r);
                    }
                }
            },
        );
    }
}

/// A worker's buffers for pixelate's rows.
struct PixelateRows {
    /// The footprint's column sums, then their running sums along the row (one pixel of zeros
    /// first).
    sums: Vec<u32>,
    /// One small row.
    small: Vec<u8>,
}

impl PixelateRows {
    /// The sums over `rows` of the input's columns, shifted by one pixel (`sums[C..]`).
    fn column_sums(&mut self, input: &ImageView<'_>, rows: std::ops::Range<usize>, c: usize) {
        let (first, rest) = self.sums.split_at_mut(c);
        first.fill(0);
        let (y0, y1) = (rows.start, rows.end);
        for (a, &v) in rest.iter_mut().zip(input.row(y0)) {
            *a = v as u32;
        }
        for y in y0 + 1..y1 {
            for (a, &v) in rest.iter_mut().zip(input.row(y)) {
                *a += v as u32;
            }
        }
    }

    /// Small row of area averages from the column sums (small pixel i: the columns of its span
    /// over `rows` rows, rounded, `recip[n]` the 32.32 reciprocal of n), enlarged into `dst`:
    /// pixel x shows small pixel `xmap[x]`.
    fn row<const C: usize>(
        &mut self,
        xspans: &[(u32, u32)],
        rows: usize,
        recip: &[u64],
        xmap: &[u32],
        dst: &mut [u8],
    ) {
        // Running sums along the row, kept in registers: entry x C + ch becomes channel ch's sum
        // over columns 0..x, so a span's sum is the difference of two entries.
        let mut run = [0u32; C];
        for px in self.sums[C..].chunks_exact_mut(C) {
            for (r, v) in run.iter_mut().zip(px) {
                *r += *v;
                *v = *r;
            }
        }
        let sums = &self.sums;
        for (q, &(x0, x1)) in self.small.chunks_exact_mut(C).zip(xspans) {
            let (x0, x1) = (x0 as usize, x1 as usize);
            let n = rows * (x1 - x0);
            let (r, half) = (recip[n], n as u32 / 2);
            let (a, b) = (&sums[x0 * C..x0 * C + C], &sums[x1 * C..x1 * C + C]);
            for ch in 0..C {
                q[ch] = ((((b[ch] - a[ch]) + half) as u64 * r) >> 32) as u8;
            }
        }
        let small = &self.small;
        for (q, &i) in dst.chunks_exact_mut(C).zip(xmap) {
            let i = i as usize * C;
            let p: [u8; C] = small[i..i + C].try_into().expect("C bytes");
            q.copy_from_slice(&p);
        }
    }
}

/// C-D3 sample_pairing: weight of the original image, severities 1..5 (PerturbationDrive
/// `sample_pairing_filter`).
pub const SAMPLE_PAIRING_ALPHA: [f32; 5] = [0.9, 0.7, 0.5, 0.3, 0.1];

/// C-D3 sample_pairing: blends the frame with an enlarged part of itself: a crop of H/2 x W/2 at an
/// offset uniform in [0, W/2) x [0, H/2), drawn per frame from (seed, sequence number), bilinearly
/// resized to H x W; `out = alpha I + (1 - alpha) C`.
pub struct SamplePairing {
    seed: u64,
    alpha: f32,
}

/// Registry constructor of C-D3.
pub const SAMPLE_PAIRING: CameraBuilder = |s| {
    Ok(Box::new(SamplePairing {
        seed: s.seed,
        alpha: SAMPLE_PAIRING_ALPHA[s.level()],
    }))
};

impl CameraPerturbation for SamplePairing {
    fn apply(&self, input: &ImageView<'_>, output: &mut ImageViewMut<'_>, seq: u64) {
        let (w, h, c) = (
            input.width as usize,
            input.height as usize,
            input.format.channels(),
        );
        let (cw, ch) = ((w / 2).max(1), (h / 2).max(1));
        let mut rng = Rng::for_frame(self.seed, seq, 0xD3);
        let ox = rng.below((w / 2).max(1) as u64) as f32;
        let oy = rng.below((h / 2).max(1) as u64) as f32;
        let (sx, sy) = (cw as f32 / w as f32, ch as f32 / h as f32);
        let a = self.alpha;
        let format = input.format;
        // The crop's sampling positions depend on x or y alone: (first, second, weight) per
        // column and per row, as `sample_reflect` computes them per pixel.
        let tap = |f: f32, n: usize| {
            let f0 = f.floor();
            let i0 = f0 as i64;
            (reflect101(i0, n), reflect101(i0 + 1, n), f - f0)
        };
        let cols: Vec<(usize, usize, f32)> = (0..w)
            .map(|x| {
                let (a, b, wx) = tap(
                    ox + ((x as f32 + 0.5) * sx - 0.5).clamp(0.0, (cw - 1) as f32),
                    w,
                );
                (a * c, b * c, wx)
            })
            .collect();
        // The columns the crop reads.
        let lo = cols.iter().map(|t| t.0.min(t.1)).min().unwrap_or(0);
        let hi = cols.iter().map(|t| t.0.max(t.1) + c).max().unwrap_or(0);
        let cols: Vec<(usize, usize, f32)> = cols
            .into_iter()
            .map(|(xa, xb, wx)| (xa - lo, xb - lo, wx))
            .collect();
        let rows = output.rows_mut();
        rows.into_par_iter()
            .with_min_len(8)
            .enumerate()
            .for_each_init(
                || (vec![0f32; hi - lo], vec![0f32; w * c]),
                |(vrow, hrow), (y, dst)| {
                    let src = input.row(y);
                    let (ya, yb, wy) = tap(
                        oy + ((y as f32 + 0.5) * sy - 0.5).clamp(0.0, (ch - 1) as f32),
                        h,
                    );
                    // Bilinear interpolation is separable: the vertical blend of the two crop
                    // rows once per column, then one horizontal blend per output sample.
                    let (ra, rb) = (&input.row(ya)[lo..hi], &input.row(yb)[lo..hi]);
                    for ((v, &p), &q) in vrow.iter_mut().zip(ra).zip(rb) {
                        *v = p as f32 * (1.0 - wy) + q as f32 * wy;
                    }
                    match c {
                        1 => pair_row::<1>(vrow, &cols, a, src, hrow, dst),
                        3 => pair_row::<3>(vrow, &cols, a, src, hrow, dst),
                        _ => pair_row::<4>(vrow, &cols, a, src, hrow, dst),
                    }
                    copy_alpha(format, src, dst);
                },
            );
    }
}

/// One row of [`SamplePairing`]: the crop sample `p` at each output pixel is the horizontal blend
/// of the vertically blended crop row `vrow` at `cols[x]`, rounded; `out = a I + (1 - a) p`. The
/// taps are gathered pixel by pixel into `hrow` (`src.len()` floats), then the rounding and the
/// blend run over contiguous samples.
fn pair_row<const C: usize>(
    vrow: &[f32],
    cols: &[(usize, usize, f32)],
    a: f32,
    src: &[u8],
    hrow: &mut [f32],
    dst: &mut [u8],
) {
    for (h, &(xa, xb, wx)) in hrow.chunks_exact_mut(C).zip(cols) {
        let va: [f32; C] = vrow[xa..xa + C].try_into().expect("C samples");
        let vb: [f32; C] = vrow[xb..xb + C].try_into().expect("C samples");
        for k in 0..C {
            h[k] = va[k] * (1.0 - wx) + vb[k] * wx + 0.5;
        }
    }
    pair_blend(hrow, a, src, dst);
}

wide_fn! {
    /// `dst = round(a src + (1 - a) trunc(h))` (with `h` already offset by one half).
    fn pair_blend(h: &[f32], a: f32, src: &[u8], dst: &mut [u8]) {
        for ((q, &s), &h) in dst.iter_mut().zip(src).zip(h) {
            let p = byte(h);
            *q = byte(a * s as f32 + (1.0 - a) * p as f32 + 0.5);
        }
    }
}

/// C-D4 sharpen: (centre boost k, weight w of the original), severities 1..5 (PerturbationDrive
/// `sharpen_filter`).
pub const SHARPEN_LEVELS: [(i32, f64); 5] = [(1, 0.9), (2, 0.8), (3, 0.7), (4, 0.6), (5, 0.5)];

/// C-D4 sharpen: over-sharpening with the reference's kernel [[-1,-1,-1],[-1,8+k,-1],[-1,-1,-1]],
/// whose sum is k and which is not normalised, so it also brightens by k and saturates in 8 bits
/// (`cv2.filter2D`, reflect-101 borders); then `out = w I + (1 - w) S`, computed exactly in tenths
/// and rounded half to even (OpenCV's `addWeighted` rounds its float sum half to even, so it can
/// differ by one level on the exact ties). A flat grey 100 becomes 100, 120, 146, 162, 178 at
/// severities 1..5.
pub struct Sharpen {
    k: i32,
    /// The weight of the original, in tenths.
    w10: i32,
}

/// Registry constructor of C-D4.
pub const SHARPEN: CameraBuilder = |s| {
    let (k, w) = SHARPEN_LEVELS[s.level()];
    Ok(Box::new(Sharpen {
        k,
        w10: (w * 10.0).round() as i32,
    }))
};

impl CameraPerturbation for Sharpen {
    fn apply(&self, input: &ImageView<'_>, output: &mut ImageViewMut<'_>, _seq: u64) {
        let (w, h, c) = (
            input.width as usize,
            input.height as usize,
            input.format.channels(),
        );
        let format = input.format;
        let centre = 9 + self.k; // 8 + k, plus one to cancel the centre's -1 in the 3x3 sum below
        let row_len = w * c;
        par_rows(input, output, |y, src, dst| {
            let rows = [-1i64, 0, 1].map(|d| input.row(reflect101(y as i64 + d, h)));
            // Vertical sums of the three rows, then 3x3 box sums along the row.
            let mut col = vec![0i16; row_len];
            column_sums(rows, &mut col);
            let mut boxes = vec![0i16; row_len];
            box_sums(&col, &mut boxes, c);
            sharpen_row(&src[..row_len], &boxes, centre, self.w10, dst);
            copy_alpha(format, src, dst);
        });
    }
}

wide_fn! {
    /// Sums of three rows, sample by sample.
    fn column_sums(rows: [&[u8]; 3], col: &mut [i16]) {
        let n = col.len();
        let [a, b, d] = rows.map(|r| &r[..n]);
        for (((o, a), b), d) in col.iter_mut().zip(a).zip(b).zip(d) {
            *o = *a as i16 + *b as i16 + *d as i16;
        }
    }
}

wide_fn! {
    /// The sharpened blend of one row: the 3x3 kernel's result `s = clamp(centre v - box)` and
    /// `(w10 v + (10 - w10) s) / 10` rounded half to even.
    fn sharpen_row(src: &[u8], boxes: &[i16], centre: i32, w10: i32, dst: &mut [u8]) {
        for ((d, &v), &b) in dst.iter_mut().zip(src).zip(boxes) {
            let v = v as i32;
            let s = (centre * v - b as i32).clamp(0, 255);
            let n = w10 * v + (10 - w10) * s;
            let (q, r) = (n / 10, n % 10);
            *d = (q + (r > 5 || (r == 5 && q & 1 == 1)) as i32) as u8;
        }
    }
}

/// Sums of three horizontally adjacent samples of a row of `c`-channel pixels (`col`), with
/// reflect-101 borders, into `out`.
fn box_sums(col: &[i16], out: &mut [i16], c: usize) {
    let w = col.len() / c;
    let at = |x: usize, ch: usize| col[x * c + ch];
    for x in [0, w - 1] {
        for ch in 0..c {
            let (l, r) = (reflect101(x as i64 - 1, w), reflect101(x as i64 + 1, w));
            out[x * c + ch] = at(l, ch) + at(x, ch) + at(r, ch);
        }
    }
    if w > 2 {
        for ((o, a), (b, d)) in out[c..(w - 1) * c]
            .iter_mut()
            .zip(&col[..(w - 2) * c])
            .zip(col[c..(w - 1) * c].iter().zip(&col[2 * c..]))
        {
            *o = a + b + d;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    use crate::image::{Image, PixelFormat};

    fn run(b: CameraBuilder, sev: u8, img: &Image, seq: u64) -> Image {
        crate::camera::apply_once(b, sev, 1, img, seq)
    }

    #[test]
    fn sharpen_on_flat_grey_matches_the_reference_values() {
        let mut img = Image::new(5, 5, PixelFormat::Mono8);
        img.data.fill(100);
        let got: Vec<u8> = (1..=5).map(|s| run(SHARPEN, s, &img, 0).data[12]).collect();
        assert_eq!(got, vec![100, 120, 146, 162, 178]);
    }

    #[test]
    fn pixelate_is_blocky() {
        let img = crate::synthetic::street_image(200, 100, 0);
        let out = run(PIXELATE, 5, &img, 0); // 20 x 10 blocks of 10 x 10 pixels
        for by in 0..10 {
            for bx in 0..20 {
                let first = &out.data[(by * 10 * 200 + bx * 10) * 3..][..3];
                for y in 0..10 {
                    for x in 0..10 {
                        assert_eq!(
                            &out.data[((by * 10 + y) * 200 + bx * 10 + x) * 3..][..3],
                            first
                        );
                    }
                }
            }
        }
    }

    #[test]
    fn pixelate_keeps_blocks_on_its_grid() {
        // A frame of constant blocks laid on the grid pixelate maps to (output pixel x shows small
        // pixel floor(x s / n)) passes through unchanged at every severity: nothing shifts.
        for (w, h) in [(200usize, 100usize), (641, 403), (37, 23)] {
            for s in 1..=5u8 {
                let f = PIXELATE_FACTOR[s as usize - 1];
                let (sw, sh) = (
                    ((w as f64 * f) as usize).max(1),
                    ((h as f64 * f) as usize).max(1),
                );
                let mut img = Image::new(w as u32, h as u32, PixelFormat::Rgb8);
                for y in 0..h {
                    for x in 0..w {
                        let (i, j) = (x * sw / w, y * sh / h);
                        let v = [
                            (i * 37 + j * 11) as u8,
                            (i * 5 + j * 91) as u8,
                            (i ^ j) as u8,
                        ];
                        img.data[(y * w + x) * 3..][..3].copy_from_slice(&v);
                    }
                }
                let out = run(PIXELATE, s, &img, 0);
                assert_eq!(out.data, img.data, "{w}x{h} s{s}");
            }
        }
    }

    #[test]
    fn elastic_and_pairing_change_with_the_frame() {
        let img = crate::synthetic::street_image(120, 80, 0);
        for b in [ELASTIC, SAMPLE_PAIRING] {
            assert_ne!(run(b, 3, &img, 1), run(b, 3, &img, 2));
            assert_eq!(run(b, 3, &img, 1), run(b, 3, &img, 1));
        }
    }
}
