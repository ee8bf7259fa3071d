//! C-A4 JPEG compression: the lossy part of baseline JPEG as libjpeg computes it.

use crate::camera::ops::{
    Block, byte, copy_alpha, frame_buffer_overwritten, merge_rgb, par_rows, recycle, split_rgb,
    three_planes, transpose_blocks, wide_fn,
};
use crate::camera::{CameraBuilder, CameraPerturbation};
use crate::image::{ImageView, ImageViewMut, PixelFormat};
use rayon::prelude::*;

/// C-A4 jpeg_compression: JPEG quality, severities 1..5 (PerturbationDrive `jpeg_filter`, which
/// round-trips through OpenCV's libjpeg).
pub const JPEG_QUALITY: [u8; 5] = [30, 18, 15, 10, 5];

/// The JPEG standard's example luminance quantisation table (ITU-T T.81 Annex K), natural order.
const LUMA_Q: [u16; 64] = [
    16, 11, 10, 16, 24, 40, 51, 61, 12, 12, 14, 19, 26, 58, 60, 55, 14, 13, 16, 24, 40, 57, 69, 56,
    14, 17, 22, 29, 51, 87, 80, 62, 18, 22, 37, 56, 68, 109, 103, 77, 24, 35, 55, 64, 81, 104, 113,
    92, 49, 64, 78, 87, 103, 121, 120, 101, 72, 92, 95, 98, 112, 100, 103, 99,
];
/// The JPEG standard's example chrominance quantisation table (Annex K), natural order.
const CHROMA_Q: [u16; 64] = [
    17, 18, 24, 47, 99, 99, 99, 99, 18, 21, 26, 66, 99, 99, 99, 99, 24, 26, 56, 99, 99, 99, 99, 99,
    47, 66, 99, 99, 99, 99, 99, 99, 99, 99, 99, 99, 99, 99, 99, 99, 99, 99, 99, 99, 99, 99, 99, 99,
    99, 99, 99, 99, 99, 99, 99, 99, 99, 99, 99, 99, 99, 99, 99, 99,
];

/// libjpeg's quality scaling of a base table (baseline: entries clamped to 1..255).
fn scaled_table(base: &[u16; 64], quality: u8) -> [f32; 64] {
    let q = quality.clamp(1, 100) as u32;
    let scale = if q < 50 { 5000 / q } else { 200 - 2 * q };
    base.map(|b| ((b as u32 * scale + 50) / 100).clamp(1, 255) as f32)
}

/// A quantisation table (natural order) transposed, with its reciprocals.
fn transposed_steps(q: &[f32; 64]) -> (Block, Block) {
    let q_t: Block = std::array::from_fn(|v| std::array::from_fn(|u| q[u * 8 + v]));
    (q_t, q_t.map(|row| row.map(|v| 1.0 / v)))
}

/// C-A4 jpeg_compression: the lossy part of baseline JPEG at the severity's quality, as libjpeg
/// does it for OpenCV's `imencode`: RGB to YCbCr (JFIF), 4:2:0 chroma subsampling (2x2 average),
/// 8x8 DCT of each plane (edges padded by replication), quantisation with the Annex K tables scaled
/// by libjpeg's quality formula, dequantisation, inverse DCT, libjpeg's "fancy" triangular chroma
/// upsampling, back to RGB. Entropy coding is lossless and skipped: the blocking, ringing and
/// colour bleeding are those of the real codec, at a fraction of the cost. Mono8 is a single luma
/// plane. Deterministic (no random draw).
pub struct JpegCompression {
    /// Luma and chroma quantisation steps, each as (table, reciprocals), transposed: the
    /// coefficients come out of the forward pass transposed.
    luma_q: (Block, Block),
    chroma_q: (Block, Block),
    /// Orthonormal DCT-II matrix: `m[u][x] = c(u)/2 cos((2x+1)u pi/16)` (its transpose is the
    /// inverse transform).
    m: Block,
    /// Band working sets of earlier frames, reused when the frame's layout is the same (a
    /// stream's frames share it), so a frame allocates none.
    spare: std::sync::Mutex<Vec<Bands>>,
}

/// Round to nearest (ties to even) without a libm call: adding and subtracting 1.5 x 2^23 pushes the
/// fraction out of an f32's mantissa. Exact for |x| < 2^22, far beyond any DCT coefficient.
#[inline]
fn round_f32(x: f32) -> f32 {
    const MAGIC: f32 = 12_582_912.0;
    (x + MAGIC) - MAGIC
}

/// `M B` for the DCT matrix `M` and every 8x8 block `B` of a band (8 rows of `pw` samples),
/// into `out`: the vertical transform of all the band's blocks at once, as long loops over the
/// band's width. With the even-odd split of the DCT-II: rows k and 7 - k enter the even outputs as
/// their sum and the odd ones as their difference (`m[u][7 - k] = +-m[u][k]`), half the
/// multiplications of the plain product; each output sums its four products in order from zero.
/// `scratch` holds 8 rows. With `SHIFT`, 128 is subtracted from every sample as it is read.
#[inline(always)]
fn dct_columns<const SHIFT: bool>(
    m: &Block,
    band: &[f32],
    pw: usize,
    scratch: &mut [f32],
    out: &mut [f32],
) {
    let shift = |v: f32| if SHIFT { v - 128.0 } else { v };
    let row = |r: usize| &band[r * pw..(r + 1) * pw];
    let (sums, diffs) = scratch.split_at_mut(4 * pw);
    for k in 0..4 {
        let (a, b) = (row(k), row(7 - k));
        let s = &mut sums[k * pw..(k + 1) * pw];
        let d = &mut diffs[k * pw..(k + 1) * pw];
        for (((s, d), &a), &b) in s.iter_mut().zip(d.iter_mut()).zip(a).zip(b) {
            let (a, b) = (shift(a), shift(b));
            *s = a + b;
            *d = a - b;
        }
    }
    for (u, o) in out.chunks_exact_mut(pw).take(8).enumerate() {
        let half = if u % 2 == 0 { &*sums } else { &*diffs };
        let (h0, rest) = half.split_at(pw);
        let (h1, rest) = rest.split_at(pw);
        let (h2, h3) = rest.split_at(pw);
        let [m0, m1, m2, m3] = [m[u][0], m[u][1], m[u][2], m[u][3]];
        for ((((o, a), b), c), d) in o.iter_mut().zip(h0).zip(h1).zip(h2).zip(&h3[..pw]) {
            let mut acc = 0.0f32;
            acc += m0 * a;
            acc += m1 * b;
            acc += m2 * c;
            acc += m3 * d;
            *o = acc;
        }
    }
}

/// `M^T C` (the inverse DCT) for the DCT matrix `M` and every 8x8 block `C` of a band, into
/// `out`, as long loops over the band's width: the even and odd coefficients' sums (each in
/// order from zero) for outputs x < 4 give outputs x and 7 - x as their sum and difference. With
/// `LAST`, every output is shifted back by 128 and clamped to 0..=255 as it is stored.
///
/// Only the band's first `ROWS` rows (1, 4 or 8) enter the sums: the caller has found the others
/// zero in every block (see [`live_rows`]), and leaving a zero term out of a sum that starts at
/// +0 changes no bit of it (the sum is never -0, so adding +-0 returns it unchanged). At the low
/// qualities most high frequencies quantise to zero in a whole band.
#[inline(always)]
fn idct_columns<const LAST: bool, const ROWS: usize>(
    m: &Block,
    band: &[f32],
    pw: usize,
    out: &mut [f32],
) {
    let finish = |v: f32| {
        if LAST {
            (v + 128.0).clamp(0.0, 255.0)
        } else {
            v
        }
    };
    let row = |u: usize| &band[u * pw..(u + 1) * pw];
    let (r0, r1, r2, r3) = (row(0), row(1), row(2), row(3));
    let (r4, r5, r6, r7) = (row(4), row(5), row(6), row(7));
    for x in 0..4 {
        let (top, bottom) = out.split_at_mut((7 - x) * pw);
        let (o1, o2) = (&mut top[x * pw..(x + 1) * pw], &mut bottom[..pw]);
        let mx: [f32; 8] = std::array::from_fn(|u| m[u][x]);
        // Every row sliced to the same length: the loop runs without bounds checks.
        let (o1, o2) = (&mut o1[..pw], &mut o2[..pw]);
        let (r0, r1, r2, r3) = (&r0[..pw], &r1[..pw], &r2[..pw], &r3[..pw]);
        let (r4, r5, r6, r7) = (&r4[..pw], &r5[..pw], &r6[..pw], &r7[..pw]);
        for l in 0..pw {
            let (mut even, mut odd) = (0.0f32, 0.0f32);
            even += mx[0] * r0[l];
            if ROWS > 1 {
                odd += mx[1] * r1[l];
                even += mx[2] * r2[l];
                odd += mx[3] * r3[l];
            }
            if ROWS > 4 {
                even += mx[4] * r4[l];
                odd += mx[5] * r5[l];
                even += mx[6] * r6[l];
                odd += mx[7] * r7[l];
            }
            o1[l] = finish(even + odd);
            o2[l] = finish(even - odd);
        }
    }
}

/// How many leading rows of a band of 8 rows of `pw` samples [`idct_columns`] must sum: 1 when
/// rows 1..8 are all zero, 4 when rows 4..8 are, 8 otherwise. The rows are scanned whole, by
/// OR-ing the samples' bits without their signs (a loop the compiler vectorises, far cheaper
/// than the sums it can save).
#[inline(always)]
fn live_rows(band: &[f32], pw: usize) -> usize {
    let zero = |u: usize| {
        let bits = band[u * pw..(u + 1) * pw]
            .iter()
            .fold(0u32, |acc, &v| acc | (v.to_bits() & 0x7fff_ffff));
        bits == 0
    };
    if !(4..8).all(zero) {
        8
    } else if !(1..4).all(zero) {
        4
    } else {
        1
    }
}

/// Registry constructor of C-A4.
pub const JPEG: CameraBuilder = |s| {
    let q = JPEG_QUALITY[s.level()];
    Ok(Box::new(JpegCompression {
        luma_q: transposed_steps(&scaled_table(&LUMA_Q, q)),
        chroma_q: transposed_steps(&scaled_table(&CHROMA_Q, q)),
        m: dct_matrix(),
        spare: Default::default(),
    }))
};

/// The orthonormal DCT-II matrix `m[u][x] = c(u)/2 cos((2x+1)u pi/16)`, `c(0) = 1/sqrt(2)`,
/// `c(u) = 1` otherwise.
fn dct_matrix() -> Block {
    let mut m = [[0f32; 8]; 8];
    for (u, row) in m.iter_mut().enumerate() {
        for (x, b) in row.iter_mut().enumerate() {
            let c = if u == 0 {
                std::f64::consts::FRAC_1_SQRT_2
            } else {
                1.0
            };
            *b = (c / 2.0
                * crate::math::cos((2 * x + 1) as f64 * u as f64 * std::f64::consts::PI / 16.0))
                as f32;
        }
    }
    m
}

/// A plane of f32 samples, padded to whole 8x8 blocks by edge replication.
struct Plane {
    /// Padded width (a multiple of 8).
    w: usize,
    data: Vec<f32>,
}

impl Plane {
    /// A `w x h` plane whose every sample the caller writes (rows `0..h` up to `w`, then
    /// [`Plane::pad`]): not zeroed first.
    fn overwritten(w: usize, h: usize) -> Self {
        let (pw, ph) = (w.div_ceil(8) * 8, h.div_ceil(8) * 8);
        Plane {
            w: pw,
            data: frame_buffer_overwritten(pw * ph.max(8)),
        }
    }

    /// Returns the plane's buffer for the next frame.
    fn recycle(self) {
        recycle(self.data);
    }

    /// Replicates the last real column and row into the padding.
    fn pad(&mut self, w: usize, h: usize) {
        let pw = self.w;
        let ph = self.data.len() / pw;
        for r in 0..h {
            let row = &mut self.data[r * pw..(r + 1) * pw];
            let last = row[w - 1];
            row[w..].fill(last);
        }
        for r in h..ph {
            self.data.copy_within((h - 1) * pw..h * pw, r * pw);
        }
    }
}

impl JpegCompression {
    /// DCT, quantise, dequantise, inverse DCT of every 8x8 block of `p` (level-shifted by 128),
    /// in place, in parallel over block rows.
    fn roundtrip_plane(&self, p: &mut Plane, (q_t, qinv_t): &(Block, Block)) {
        use rayon::prelude::*;
        let pw = p.w;
        let m = &self.m;
        p.data.par_chunks_mut(pw * 8).for_each_init(
            || (vec![0f32; 8 * pw], vec![0f32; 8 * pw]),
            |(s1, s2), band| roundtrip_band(m, q_t, qinv_t, pw, band, s1, s2),
        );
    }
}

wide_fn! {
    /// DCT, quantise, dequantise, inverse DCT of every 8x8 block of a band of 8 rows of `pw`
    /// samples (level-shifted by 128), in place; `q_t` and `qinv_t` are the quantisation table
    /// and its reciprocals, transposed; `s1`, `s2` hold 8 rows each. Each transform runs over
    /// the whole band (vertical passes as long loops, the horizontal ones as vertical passes
    /// between block transposes): per coefficient the same operations in the same order as a
    /// block-by-block transform.
    fn roundtrip_band(
        m: &Block,
        q_t: &Block,
        qinv_t: &Block,
        pw: usize,
        band: &mut [f32],
        s1: &mut [f32],
        s2: &mut [f32],
    ) {
        // Forward, the samples level-shifted by 128 as the first pass reads them: the
        // coefficients C = M B M^T come out transposed, C^T = M (M B)^T; they are quantised and
        // dequantised as C^T.
        dct_columns::<true>(m, band, pw, s1, s2);
        transpose_blocks(s2, pw);
        dct_columns::<false>(m, s2, pw, s1, band);
        for (row, (qi, q)) in band.chunks_exact_mut(pw).zip(qinv_t.iter().zip(q_t)) {
            for blk in row.chunks_exact_mut(8) {
                for ((coef, qi), q) in blk.iter_mut().zip(qi).zip(q) {
                    *coef = round_f32(*coef * qi) * q;
                }
            }
        }
        // Inverse: B = M^T C M = M^T (M^T C^T)^T.
        // The last pass shifts back by 128 and clamps to 0..=255 as it stores.
        match live_rows(band, pw) {
            1 => idct_columns::<false, 1>(m, band, pw, s2),
            4 => idct_columns::<false, 4>(m, band, pw, s2),
            _ => idct_columns::<false, 8>(m, band, pw, s2),
        }
        transpose_blocks(s2, pw);
        match live_rows(s2, pw) {
            1 => idct_columns::<true, 1>(m, s2, pw, band),
            4 => idct_columns::<true, 4>(m, s2, pw, band),
            _ => idct_columns::<true, 8>(m, s2, pw, band),
        }
    }
}

wide_fn! {
    /// JFIF RGB to YCbCr of one row of `c`-byte pixels: luma into `y`, chroma added into the
    /// half-width `cb`, `cr` (left pixel of each pair first), or with `FIRST` (the first image
    /// row of a chroma row) added to zero and written there, so that the chroma rows need no
    /// clearing. `work` (3 `y.len()` floats) holds the row deinterleaved, so that the arithmetic
    /// runs on contiguous arrays.
    fn to_ycc<const FIRST: bool>(
        src: &[u8],
        format: PixelFormat,
        work: &mut [f32],
        y: &mut [f32],
        cb: &mut [f32],
        cr: &mut [f32],
    ) {
        let w = y.len();
        let [r, g, b] = three_planes(work, w);
        split_rgb(src, format, [&mut *r, &mut *g, &mut *b]);
        let luma = |r: f32, g: f32, b: f32| 0.299 * r + 0.587 * g + 0.114 * b;
        let blue = |r: f32, g: f32, b: f32| -0.168_736 * r - 0.331_264 * g + 0.5 * b;
        let red = |r: f32, g: f32, b: f32| 0.5 * r - 0.418_688 * g - 0.081_312 * b;
        // Whole pairs of pixels in one loop (each chroma sum adds the left pixel, then the
        // right one), an odd last pixel on its own.
        let n = w / 2;
        fn pairs(p: &[f32], n: usize) -> std::slice::ChunksExact<'_, f32> {
            p[..2 * n].chunks_exact(2)
        }
        let (cbp, crp) = (&mut cb[..n], &mut cr[..n]);
        let out = y[..2 * n].chunks_exact_mut(2).zip(cbp).zip(crp);
        let rgb = pairs(r, n).zip(pairs(g, n)).zip(pairs(b, n));
        for (((yv, cbv), crv), ((r, g), b)) in out.zip(rgb) {
            yv[0] = luma(r[0], g[0], b[0]);
            yv[1] = luma(r[1], g[1], b[1]);
            let (cb0, cr0) = if FIRST { (0.0, 0.0) } else { (*cbv, *crv) };
            *cbv = (cb0 + blue(r[0], g[0], b[0])) + blue(r[1], g[1], b[1]);
            *crv = (cr0 + red(r[0], g[0], b[0])) + red(r[1], g[1], b[1]);
        }
        if w % 2 == 1 {
            let (r, g, b) = (r[w - 1], g[w - 1], b[w - 1]);
            y[w - 1] = luma(r, g, b);
            let (cb0, cr0) = if FIRST { (0.0, 0.0) } else { (cb[n], cr[n]) };
            cb[n] = cb0 + blue(r, g, b);
            cr[n] = cr0 + red(r, g, b);
        }
    }
}

wide_fn! {
    /// libjpeg's "fancy" horizontal upsampling of one chroma row `t` (already weighted 3:1
    /// vertically) to `out`: sample `2i` weighs `t[i]` 3/4 and `t[i - 1]` 1/4, sample `2i + 1` weighs
    /// `t[i]` 3/4 and `t[i + 1]` 1/4 (edges replicated); the result is scaled by 1/16 and the 128
    /// offset removed.
    fn upsample_row(t: &[f32], out: &mut [f32]) {
        let n = t.len();
        let f = |c: f32, side: f32| (3.0 * c + side) * (1.0 / 16.0) - 128.0;
        // The edge samples (which replicate their neighbour) on their own, the interior pairs
        // 1..n-1 (always whole: the row is 2n - 1 or 2n long) without index clamps.
        let edge = |i: usize, pair: &mut [f32]| {
            let c = t[i];
            pair[0] = f(c, t[i.saturating_sub(1)]);
            if let Some(odd) = pair.get_mut(1) {
                *odd = f(c, t[(i + 1).min(n - 1)]);
            }
        };
        let first = out.len().min(2);
        edge(0, &mut out[..first]);
        let done = if n > 2 {
            let (left, centre, right) = (&t[..n - 2], &t[1..n - 1], &t[2..]);
            let interior = &mut out[2..2 * (n - 1)];
            for (((pair, &c), &l), &r) in interior.chunks_exact_mut(2).zip(centre).zip(left).zip(right) {
                pair[0] = f(c, l);
                pair[1] = f(c, r);
            }
            n - 1
        } else {
            1
        };
        if 2 * done < out.len() {
            edge(done, &mut out[2 * done..]);
        }
    }
}

wide_fn! {
    /// Chroma sums to averages (`inv` the reciprocal of the samples summed), with the 128
    /// offset.
    fn average_chroma(cb: &mut [f32], cr: &mut [f32], inv: f32) {
        for (b, r) in cb.iter_mut().zip(cr.iter_mut()) {
            *b = *b * inv + 128.0;
            *r = *r * inv + 128.0;
        }
    }
}

wide_fn! {
    /// `t = 3 a + b`: the vertical weights of the fancy upsampling.
    fn weigh_rows(a: &[f32], b: &[f32], t: &mut [f32]) {
        for ((d, a), b) in t.iter_mut().zip(a).zip(b) {
            *d = 3.0 * a + b;
        }
    }
}

wide_fn! {
    /// JFIF YCbCr (chroma already without its 128 offset) to RGB bytes, one plane each in
    /// `planes` (3 `y.len()` bytes), merged into the row `dst` of `format` pixels (alpha left as
    /// it is).
    fn ycc_to_rgb(
        y: &[f32],
        u: &[f32],
        v: &[f32],
        planes: &mut [u8],
        format: PixelFormat,
        dst: &mut [u8],
    ) {
        let w = y.len();
        let [r, g, b] = three_planes(planes, w);
        let yuv = y.iter().zip(u).zip(v);
        for (((((&y, &u), &v), pr), pg), pb) in yuv.zip(&mut *r).zip(&mut *g).zip(&mut *b) {
            let yy = y + 0.5;
            *pr = byte(yy + 1.402 * v);
            *pg = byte(yy - 0.344_136 * u - 0.714_136 * v);
            *pb = byte(yy + 1.772 * u);
        }
        merge_rgb(format, [&*r, &*g, &*b], dst);
    }
}

impl JpegCompression {
    /// A mono8 frame: the luma plane only.
    fn apply_mono(&self, input: &ImageView<'_>, output: &mut ImageViewMut<'_>) {
        let (w, h) = (input.width as usize, input.height as usize);
        let mut y = Plane::overwritten(w, h);
        let pw = y.w;
        y.data
            .par_chunks_mut(pw)
            .take(h)
            .enumerate()
            .for_each(|(r, row)| {
                for (d, s) in row.iter_mut().zip(input.row(r)) {
                    *d = *s as f32;
                }
            });
        y.pad(w, h);
        self.roundtrip_plane(&mut y, &self.luma_q);
        par_rows(input, output, |r, _, dst| {
            for (x, d) in dst.iter_mut().enumerate() {
                *d = byte(y.data[r * pw + x] + 0.5);
            }
        });
        y.recycle();
    }
}

/// Luma rows per band: one block row of chroma (8 rows at 4:2:0) is two of luma.
const BAND_ROWS: usize = 16;

/// The geometry of a colour frame's planes: `w` x `h` luma, `cw` x `ch` chroma, each padded to
/// whole blocks (`pw`, `cpw` samples per row, `ph` luma rows).
#[derive(Clone, Copy, PartialEq)]
struct Layout {
    w: usize,
    h: usize,
    cw: usize,
    ch: usize,
    pw: usize,
    cpw: usize,
    ph: usize,
    /// Bands of [`BAND_ROWS`] luma rows (8 chroma rows).
    bands: usize,
}

impl Layout {
    fn of(input: &ImageView<'_>) -> Self {
        let (w, h) = (input.width as usize, input.height as usize);
        let (cw, ch) = (w.div_ceil(2), h.div_ceil(2));
        Layout {
            w,
            h,
            cw,
            ch,
            pw: w.div_ceil(8) * 8,
            cpw: cw.div_ceil(8) * 8,
            ph: h.div_ceil(8) * 8,
            bands: h.div_ceil(BAND_ROWS),
        }
    }

    /// The output rows that band `k` completes, and the rows band `k - 1`'s completion left: rows
    /// up to `16 k + 14` need chroma rows up to `8 k + 7` (band `k`), the band's last row also
    /// the next band's first chroma row (libjpeg's upsampling looks one chroma row down).
    fn rows_done_after(&self, k: usize) -> std::ops::Range<usize> {
        let start = (BAND_ROWS * k).saturating_sub(1);
        let end = if k + 1 == self.bands {
            self.h
        } else {
            BAND_ROWS * k + BAND_ROWS - 1
        };
        start..end
    }
}

/// The working set of a run of bands: the planes of two bands (the previous one and the current
/// one, alternating by band parity), whose samples stay in cache from the colour conversion
/// through the transforms to the upsampling, instead of whole-frame planes.
struct Bands {
    at: Layout,
    /// Per parity: 16 luma rows, 8 rows of each chroma plane.
    y: [Vec<f32>; 2],
    cb: [Vec<f32>; 2],
    cr: [Vec<f32>; 2],
    /// Scratch of the colour conversion (4 w), the transforms (8 pw each), the upsampling
    /// (cw, 2 w) and the interleaving (3 w).
    work: Vec<f32>,
    s1: Vec<f32>,
    s2: Vec<f32>,
    t: Vec<f32>,
    uv: Vec<f32>,
    planes: Vec<u8>,
}

impl Bands {
    fn new(at: Layout) -> Self {
        let two = |n: usize| [vec![0f32; n], vec![0f32; n]];
        Bands {
            at,
            y: two(BAND_ROWS * at.pw),
            cb: two(8 * at.cpw),
            cr: two(8 * at.cpw),
            work: vec![0f32; 3 * at.w],
            s1: vec![0f32; 8 * at.pw.max(at.cpw)],
            s2: vec![0f32; 8 * at.pw.max(at.cpw)],
            t: vec![0f32; at.cw],
            uv: vec![0f32; 2 * at.w],
            planes: vec![0u8; 3 * at.w],
        }
    }

    /// Band `k` of the three planes: converted to YCbCr with chroma averaged over 2 x 2 pixels
    /// (4:2:0), padded to whole blocks by edge replication, then every block through DCT,
    /// quantisation, dequantisation and inverse DCT.
    fn fill(&mut self, jpeg: &JpegCompression, input: &ImageView<'_>, k: usize) {
        let at = self.at;
        let (w, pw, cw, cpw) = (at.w, at.pw, at.cw, at.cpw);
        let slot = k % 2;
        let (y, cb, cr) = (&mut self.y[slot], &mut self.cb[slot], &mut self.cr[slot]);
        // Each chroma row is written by the first image row over it and added to by the second
        // (none is left unwritten: a chroma row below the frame is copied from the last one).
        let top = BAND_ROWS * k;
        let rows = at.ph.min(top + BAND_ROWS) - top;
        for i in 0..rows {
            let r = top + i;
            if r < at.h {
                let (yrow, c) = (&mut y[i * pw..(i + 1) * pw], (i / 2) * cpw);
                let (cbrow, crrow) = (&mut cb[c..c + cpw], &mut cr[c..c + cpw]);
                let convert = if i % 2 == 0 {
                    to_ycc::<true>
                } else {
                    to_ycc::<false>
                };
                convert(
                    input.row(r),
                    input.format,
                    &mut self.work,
                    &mut yrow[..w],
                    cbrow,
                    crrow,
                );
                let last = yrow[w - 1];
                yrow[w..].fill(last);
            } else {
                // Below the frame: the last real row (in this band: the padding is under 8 rows).
                y.copy_within((at.h - 1 - top) * pw..(at.h - top) * pw, i * pw);
            }
        }
        let ctop = 8 * k;
        for (j, cy) in (ctop..ctop + 8).enumerate() {
            let c = j * cpw;
            if cy < at.ch {
                let (cbrow, crrow) = (&mut cb[c..c + cpw], &mut cr[c..c + cpw]);
                // Averages of 1, 2 or 4 samples: a power of two, so multiplying by the
                // reciprocal is exact. Only an odd width's last column has one sample per row.
                let nrows = (at.h - 2 * cy).min(2);
                let per_row = |cx: usize| (2 * cx + 2).min(w) - 2 * cx;
                let inv = |cx: usize| 1.0 / (nrows * per_row(cx)) as f32;
                let full = w / 2;
                average_chroma(&mut cbrow[..full], &mut crrow[..full], inv(0));
                if full < cw {
                    average_chroma(&mut cbrow[full..cw], &mut crrow[full..cw], inv(full));
                }
                for p in [cbrow, crrow] {
                    let last = p[cw - 1];
                    p[cw..].fill(last);
                }
            } else {
                let src = (at.ch - 1 - ctop) * cpw;
                cb.copy_within(src..src + cpw, c);
                cr.copy_within(src..src + cpw, c);
            }
        }
        let (s1, s2) = (&mut self.s1, &mut self.s2);
        let m = &jpeg.m;
        for block_row in y[..rows * pw].chunks_exact_mut(8 * pw) {
            let (q, qinv) = &jpeg.luma_q;
            roundtrip_band(
                m,
                q,
                qinv,
                pw,
                block_row,
                &mut s1[..8 * pw],
                &mut s2[..8 * pw],
            );
        }
        for p in [cb, cr] {
            let (q, qinv) = &jpeg.chroma_q;
            roundtrip_band(m, q, qinv, cpw, p, &mut s1[..8 * cpw], &mut s2[..8 * cpw]);
        }
    }

    /// Output row `r` from the decoded bands with libjpeg's fancy upsampling: each output sample
    /// weighs its nearest chroma sample 3/4 and the next one 1/4 in each direction (9/16, 3/16,
    /// 3/16, 1/16): vertical weights first, then horizontal, then the colour conversion on
    /// contiguous rows (vectorisable); the bytes are interleaved last.
    fn emit(&mut self, input: &ImageView<'_>, r: usize, dst: &mut [u8]) {
        let at = self.at;
        let (w, cw, cpw) = (at.w, at.cw, at.cpw);
        let cy = r / 2;
        let ny = if r.is_multiple_of(2) {
            cy.saturating_sub(1)
        } else {
            (cy + 1).min(at.ch - 1)
        };
        let (u, v) = self.uv.split_at_mut(w);
        for (planes, out) in [(&self.cb, &mut *u), (&self.cr, &mut *v)] {
            // Chroma rows `cy` and `ny`: in the band of their parity, at their place in the band.
            let row = |cy: usize| &planes[(cy / 8) % 2][(cy % 8) * cpw..][..cw];
            weigh_rows(row(cy), row(ny), &mut self.t);
            upsample_row(&self.t, out);
        }
        let yrow = &self.y[(r / BAND_ROWS) % 2][(r % BAND_ROWS) * at.pw..][..w];
        ycc_to_rgb(yrow, u, v, &mut self.planes, input.format, dst);
        copy_alpha(input.format, input.row(r), dst);
    }
}

impl CameraPerturbation for JpegCompression {
    fn apply(&self, input: &ImageView<'_>, output: &mut ImageViewMut<'_>, _seq: u64) {
        if input.format.is_mono() {
            self.apply_mono(input, output);
            return;
        }
        // Runs of whole bands, one per task; a run starts by decoding the band before it (the
        // upsampling of its first row looks one chroma row up), so no run waits for another.
        let at = Layout::of(input);
        let threads = rayon::current_num_threads();
        let runs = if threads == 1 {
            1
        } else {
            (2 * threads).min(at.bands.div_ceil(4)).max(1)
        };
        let mut rows = output.rows_mut();
        let mut tasks = Vec::with_capacity(runs);
        for i in (0..runs).rev() {
            let (k0, k1) = (i * at.bands / runs, (i + 1) * at.bands / runs);
            let start = at.rows_done_after(k0).start;
            tasks.push((k0..k1, start, rows.split_off(start)));
        }
        tasks.into_par_iter().for_each(|(run, start, mut rows)| {
            let spare = self.spare.lock().ok().and_then(|mut v| v.pop());
            let mut bands = spare
                .filter(|b| b.at == at)
                .unwrap_or_else(|| Bands::new(at));
            if run.start > 0 {
                bands.fill(self, input, run.start - 1);
            }
            for k in run {
                bands.fill(self, input, k);
                for r in at.rows_done_after(k) {
                    bands.emit(input, r, &mut *rows[r - start]);
                }
            }
            if let Ok(mut v) = self.spare.lock() {
                v.push(bands);
            }
        });
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::image::{Image, PixelFormat};

    #[test]
    fn jpeg_quantisation_matches_libjpeg_scaling_and_blocks_appear() {
        // libjpeg: quality 50 leaves the Annex K table unchanged, quality 10 scales by 5.
        assert_eq!(scaled_table(&LUMA_Q, 50)[0], 16.0);
        assert_eq!(scaled_table(&LUMA_Q, 10)[0], 80.0);
        assert_eq!(scaled_table(&CHROMA_Q, 5)[63], 255.0);
        // A smooth horizontal ramp becomes 8-pixel blocks at quality 5: within a block the error
        // pattern repeats, and the block edges show steps.
        let mut ramp = Image::new(64, 16, PixelFormat::Mono8);
        for (i, v) in ramp.data.iter_mut().enumerate() {
            *v = ((i % 64) * 3) as u8;
        }
        let low = crate::camera::apply_once(JPEG, 5, 5, &ramp, 0);
        let high = crate::camera::apply_once(JPEG, 1, 5, &ramp, 0);
        let err = |o: &Image| {
            o.data
                .iter()
                .zip(&ramp.data)
                .map(|(a, b)| (*a as f64 - *b as f64).abs())
                .sum::<f64>()
        };
        assert!(
            err(&low) > err(&high),
            "quality 5 distorts more than quality 30"
        );
        // A flat image stays flat; its level moves by at most the DC quantisation step / 8, as in
        // libjpeg: at quality 5 the DC step is 160, so 77 (-51 after the level shift, DC -408)
        // becomes round(-408 / 160) x 160 / 8 + 128 = 68.
        let mut flat_img = Image::new(24, 24, PixelFormat::Rgb8);
        flat_img.data.fill(77);
        let out = crate::camera::apply_once(JPEG, 5, 5, &flat_img, 0);
        assert!(out.data.iter().all(|&v| v == 68), "{:?}", &out.data[..6]);
        assert!(
            crate::camera::apply_once(JPEG, 1, 5, &flat_img, 0)
                .data
                .iter()
                .all(|&v| v == 77)
        );
    }

    #[test]
    fn the_inverse_transform_of_the_live_rows_alone_keeps_every_bit() {
        // Bands whose rows past 1 or 4 are zero (some -0): the shortened sums give the bits of
        // the full ones, in both passes; a nonzero sample anywhere in a row keeps it live.
        let m = dct_matrix();
        let pw = 40;
        for live in [1, 4, 8] {
            let mut band: Vec<f32> = (0..8 * pw)
                .map(|i| ((i * 7919 % 1000) as f32 - 500.0) * 0.37)
                .collect();
            for (i, v) in band.iter_mut().enumerate().skip(live * pw) {
                *v = if i % 3 == 0 { -0.0 } else { 0.0 };
            }
            assert_eq!(live_rows(&band, pw), live);
            for last in [false, true] {
                let (mut full, mut short) = (vec![0f32; 8 * pw], vec![0f32; 8 * pw]);
                if last {
                    idct_columns::<true, 8>(&m, &band, pw, &mut full);
                } else {
                    idct_columns::<false, 8>(&m, &band, pw, &mut full);
                }
                match (last, live) {
                    (false, 1) => idct_columns::<false, 1>(&m, &band, pw, &mut short),
                    (false, 4) => idct_columns::<false, 4>(&m, &band, pw, &mut short),
                    (true, 1) => idct_columns::<true, 1>(&m, &band, pw, &mut short),
                    (true, 4) => idct_columns::<true, 4>(&m, &band, pw, &mut short),
                    (false, _) => idct_columns::<false, 8>(&m, &band, pw, &mut short),
                    (true, _) => idct_columns::<true, 8>(&m, &band, pw, &mut short),
                }
                let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
                assert_eq!(bits(&full), bits(&short), "live {live} last {last}");
            }
            // One nonzero sample in the last row makes every row live.
            band[8 * pw - 1] = 1e-30;
            assert_eq!(live_rows(&band, pw), 8);
        }
    }

    #[test]
    fn runs_of_bands_give_the_bytes_of_one_run() {
        // Tall odd frames split into up to six runs of bands (each decoding the band before it)
        // against the whole frame in one run on one thread, in both colour layouts.
        for (w, h, format) in [(61, 200, PixelFormat::Rgb8), (33, 131, PixelFormat::Bgra8)] {
            let mut img = Image::new(w, h, format);
            for (i, v) in img.data.iter_mut().enumerate() {
                *v = ((i * 7919) % 251) as u8 ^ (i / (4 * w as usize)) as u8;
            }
            let pool = |n| {
                rayon::ThreadPoolBuilder::new()
                    .num_threads(n)
                    .build()
                    .unwrap()
            };
            for level in 1..=5 {
                let run =
                    |n| pool(n).install(|| crate::camera::apply_once(JPEG, level, 5, &img, 0));
                let one = run(1);
                assert_ne!(one.data, img.data, "{w}x{h} s{level}: unchanged");
                assert_eq!(
                    run(3).data,
                    one.data,
                    "{w}x{h} {format} s{level}: 3 threads"
                );
            }
        }
    }
}
