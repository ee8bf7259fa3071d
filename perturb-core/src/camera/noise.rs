//! Noise family (C-A): sensor noise and compression artefacts added to the pixel values.
//!
//! The random noises (gaussian, poisson, speckle) draw, for every colour byte, a value from the
//! distribution of the reference's output given that byte's input value. The distributions are
//! tabulated at configuration time as quantile tables (inverse CDFs), so a frame costs one random
//! draw and one table read per byte, whatever the distribution.

#[cfg(test)]
use super::CameraSetup;
use super::ops::{
    byte, copy_alpha, frame_buffer, frame_buffer_overwritten, merge_rgb, par_rows, recycle,
    row_rng, split_rgb, wide_fn,
};
use super::{CameraBuilder, CameraPerturbation};
use crate::image::{ImageView, ImageViewMut, PixelFormat};
use crate::rng::{Rng, normal_quantile};

/// Resolution of the per-value quantile tables: 2^QBITS equiprobable quantiles.
const QBITS: u32 = 11;
const QN: usize = 1 << QBITS;

/// For each input byte value, `QN` equiprobable output values (the midpoints of the quantile
/// bins of the output distribution).
struct QuantileTables(Box<[[u8; QN]; 256]>);

impl QuantileTables {
    /// Builds the tables from `quantile(v, p)`: the output value for input `v` at probability `p`.
    fn build(quantile: impl Fn(u8, f64) -> f64) -> Self {
        Self::build_indexed(|v, k| quantile(v, (k as f64 + 0.5) / QN as f64))
    }

    /// Builds the tables from `f(v, k)`: the output value for input `v` in quantile bin `k`.
    fn build_indexed(f: impl Fn(u8, usize) -> f64) -> Self {
        let mut t = vec![[0u8; QN]; 256].into_boxed_slice();
        for (v, row) in t.iter_mut().enumerate() {
            for (k, out) in row.iter_mut().enumerate() {
                *out = f(v as u8, k).round().clamp(0.0, 255.0) as u8;
            }
        }
        QuantileTables(t.try_into().expect("256 rows"))
    }

    /// Applies the tables to every colour byte, one independent draw per byte; alpha is copied.
    fn apply(
        &self,
        seed: u64,
        salt: u64,
        input: &ImageView<'_>,
        output: &mut ImageViewMut<'_>,
        seq: u64,
    ) {
        let format = input.format;
        let t = &self.0;
        par_rows(input, output, |y, src, dst| {
            let rng = row_rng(seed, seq, salt, y);
            table_row(t, rng, format.alpha_offset(), src, dst);
        });
    }
}

wide_fn! {
    /// One row of [`QuantileTables::apply`]: each colour byte `v` becomes `t[v][k]` for the next
    /// draw `k` of `rng`; the alpha byte (at `alpha` in 4-byte pixels) is copied.
    fn table_row(
        t: &[[u8; QN]; 256],
        rng: Rng,
        alpha: Option<usize>,
        src: &[u8],
        dst: &mut [u8],
    ) {
        let mut rng = rng;
        let mut draw = Draws::default();
        match alpha {
            None => {
                for (s, d) in src.iter().zip(dst.iter_mut()) {
                    *d = t[*s as usize][draw.next(&mut rng)];
                }
            }
            Some(a) => {
                for (s, d) in src.chunks_exact(4).zip(dst.chunks_exact_mut(4)) {
                    for c in 0..4 {
                        d[c] = if c == a {
                            s[c]
                        } else {
                            t[s[c] as usize][draw.next(&mut rng)]
                        };
                    }
                }
            }
        }
    }
}

/// Standard normal quantiles at the centres of the `QN` equiprobable bins.
fn normal_bins() -> Vec<f64> {
    (0..QN)
        .map(|k| normal_quantile((k as f64 + 0.5) / QN as f64))
        .collect()
}

/// Hands out `QBITS`-bit random indices, five per 64-bit draw.
#[derive(Default)]
struct Draws {
    bits: u64,
    left: u32,
}

impl Draws {
    #[inline]
    fn next(&mut self, rng: &mut Rng) -> usize {
        if self.left == 0 {
            self.bits = rng.next_u64();
            self.left = 64 / QBITS;
        }
        let v = (self.bits & (QN as u64 - 1)) as usize;
        self.bits >>= QBITS;
        self.left -= 1;
        v
    }
}

/// C-A1 gaussian_noise: standard deviation of the additive noise, in units of full scale (0..1),
/// severities 1..5 (PerturbationDrive `gaussian_noise`).
pub const GAUSSIAN_SIGMA: [f64; 5] = [0.03, 0.06, 0.12, 0.18, 0.22];

/// C-A1 gaussian_noise: `out = clip(x + N(0, sigma))` on every colour channel independently.
///
/// Tabulated as described in the module: for input value `v` the output is
/// `clip(round(v + 255 sigma z))`. The result is rounded where the reference's uint8 conversion
/// truncates (a -0.5 level bias the project does not copy). Alpha is copied.
pub struct GaussianNoise {
    seed: u64,
    tables: QuantileTables,
}

/// Registry constructor of C-A1.
pub const GAUSSIAN: CameraBuilder = |s| {
    let sigma = GAUSSIAN_SIGMA[s.level()] * 255.0;
    Ok(Box::new(GaussianNoise {
        seed: s.seed,
        tables: {
            let z = normal_bins();
            QuantileTables::build_indexed(|v, k| v as f64 + sigma * z[k])
        },
    }))
};

impl CameraPerturbation for GaussianNoise {
    fn apply(&self, input: &ImageView<'_>, output: &mut ImageViewMut<'_>, seq: u64) {
        self.tables.apply(self.seed, 0xA1, input, output, seq);
    }
}

/// C-A2 poisson_noise: photon count scale lambda, severities 1..5 (PerturbationDrive
/// `poisson_noise`): lower lambda, fewer photons, stronger noise.
pub const POISSON_LAMBDA: [f64; 5] = [120.0, 105.0, 87.0, 55.0, 30.0];

/// C-A2 poisson_noise: `out = clip(Poisson(x lambda) / lambda)` with x = v / 255, per colour byte.
///
/// For each of the 256 input values the Poisson law of mean `v lambda / 255` is tabulated at
/// configuration time as a quantile table (the reference draws a float64 Poisson variate per
/// element, 60 ms at 640x480 in Python). Output rounded to the nearest level.
pub struct PoissonNoise {
    seed: u64,
    tables: QuantileTables,
}

fn poisson_quantile(mean: f64, p: f64) -> f64 {
    if mean <= 0.0 {
        return 0.0;
    }
    // Sequential search of the CDF from 0; means are at most 120 here.
    let mut k = 0.0;
    let mut pmf = (-mean).exp();
    let mut cdf = pmf;
    while cdf < p && k < 10_000.0 {
        k += 1.0;
        pmf *= mean / k;
        cdf += pmf;
    }
    k
}

/// Registry constructor of C-A2.
pub const POISSON: CameraBuilder = |s| {
    let lambda = POISSON_LAMBDA[s.level()];
    Ok(Box::new(PoissonNoise {
        seed: s.seed,
        tables: QuantileTables::build(|v, p| {
            poisson_quantile(v as f64 / 255.0 * lambda, p) / lambda * 255.0
        }),
    }))
};

impl CameraPerturbation for PoissonNoise {
    fn apply(&self, input: &ImageView<'_>, output: &mut ImageViewMut<'_>, seq: u64) {
        self.tables.apply(self.seed, 0xA2, input, output, seq);
    }
}

/// C-A5 speckle_noise: standard deviation of the multiplicative noise, severities 1..5
/// (PerturbationDrive `speckle_noise_filter`).
pub const SPECKLE_SIGMA: [f64; 5] = [0.02, 0.05, 0.09, 0.14, 0.20];

/// C-A5 speckle_noise: `out = clip(I N(1, sigma))` per colour byte (multiplicative Gaussian noise:
/// dark pixels stay dark, bright ones scatter most), tabulated per input value.
pub struct SpeckleNoise {
    seed: u64,
    tables: QuantileTables,
}

/// Registry constructor of C-A5.
pub const SPECKLE: CameraBuilder = |s| {
    let sigma = SPECKLE_SIGMA[s.level()];
    Ok(Box::new(SpeckleNoise {
        seed: s.seed,
        tables: {
            let z = normal_bins();
            QuantileTables::build_indexed(|v, k| v as f64 * (1.0 + sigma * z[k]))
        },
    }))
};

impl CameraPerturbation for SpeckleNoise {
    fn apply(&self, input: &ImageView<'_>, output: &mut ImageViewMut<'_>, seq: u64) {
        self.tables.apply(self.seed, 0xA5, input, output, seq);
    }
}

/// C-A3 impulse_noise: fraction p of the colour elements hit, severities 1..5 (PerturbationDrive
/// `impulse_noise`); half become salt (255), half pepper (0).
pub const IMPULSE_AMOUNT: [f64; 5] = [0.01, 0.02, 0.04, 0.065, 0.10];

/// C-A3 impulse_noise: `n = ceil(p H W C / 2)` element coordinates set to 255, then `n` set to 0
/// (C = colour channels), drawn uniformly with replacement, so later draws may overwrite earlier
/// ones as in the reference.
///
/// Deviation: the reference draws each index with an exclusive upper bound of `dim - 1`, so the
/// last row, the last column and the third channel are never hit; here every element can be.
pub struct ImpulseNoise {
    seed: u64,
    amount: f64,
}

/// Registry constructor of C-A3.
pub const IMPULSE: CameraBuilder = |s| {
    Ok(Box::new(ImpulseNoise {
        seed: s.seed,
        amount: IMPULSE_AMOUNT[s.level()],
    }))
};

impl ImpulseNoise {
    /// Number of salt (and of pepper) draws for a frame.
    pub fn draws(&self, width: u32, height: u32, format: PixelFormat) -> usize {
        (self.amount * width as f64 * height as f64 * format.color_channels() as f64 / 2.0).ceil()
            as usize
    }
}

impl CameraPerturbation for ImpulseNoise {
    fn apply(&self, input: &ImageView<'_>, output: &mut ImageViewMut<'_>, seq: u64) {
        par_rows(input, output, |_, s, d| d.copy_from_slice(s));
        let (w, h, f) = (input.width as u64, input.height as u64, input.format);
        let cc = f.color_channels() as u64;
        let offsets = f.rgb_offsets();
        let n = self.draws(input.width, input.height, f);
        let mut rng = Rng::for_frame(self.seed, seq, 0xA3);
        for (value, _) in [(255u8, 0), (0u8, 1)] {
            for _ in 0..n {
                let e = rng.below(w * h * cc);
                let (pix, ch) = (e / cc, (e % cc) as usize);
                let (y, x) = ((pix / w) as usize, (pix % w) as usize);
                let row = output.row_mut(y);
                row[x * f.channels() + offsets[ch]] = value;
            }
        }
    }
}

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
}

type Block = [[f32; 8]; 8];

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
/// `scratch` holds 8 rows.
#[inline(always)]
fn dct_columns(m: &Block, band: &[f32], pw: usize, scratch: &mut [f32], out: &mut [f32]) {
    let row = |r: usize| &band[r * pw..(r + 1) * pw];
    let (sums, diffs) = scratch.split_at_mut(4 * pw);
    for k in 0..4 {
        let (a, b) = (row(k), row(7 - k));
        let s = &mut sums[k * pw..(k + 1) * pw];
        let d = &mut diffs[k * pw..(k + 1) * pw];
        for (((s, d), a), b) in s.iter_mut().zip(d.iter_mut()).zip(a).zip(b) {
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
/// order from zero) for outputs x < 4 give outputs x and 7 - x as their sum and difference.
#[inline(always)]
fn idct_columns(m: &Block, band: &[f32], pw: usize, out: &mut [f32]) {
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
            odd += mx[1] * r1[l];
            even += mx[2] * r2[l];
            odd += mx[3] * r3[l];
            even += mx[4] * r4[l];
            odd += mx[5] * r5[l];
            even += mx[6] * r6[l];
            odd += mx[7] * r7[l];
            o1[l] = even + odd;
            o2[l] = even - odd;
        }
    }
}

/// Transposes every 8x8 block of a band in place.
#[inline(always)]
fn transpose_blocks(band: &mut [f32], pw: usize) {
    for bx in 0..pw / 8 {
        let at = |y: usize| y * pw + bx * 8..y * pw + bx * 8 + 8;
        let mut blk = [[0f32; 8]; 8];
        for (y, row) in blk.iter_mut().enumerate() {
            *row = band[at(y)].try_into().expect("8 samples");
        }
        for (y, row) in transpose8(&blk).iter().enumerate() {
            band[at(y)].copy_from_slice(row);
        }
    }
}

/// The transpose of an 8x8 block, in three stages of two-row shuffles (interleave pairs, then
/// pairs of pairs, then halves): each stage is one shuffle instruction per row when the rows are
/// vectors, where an element-by-element transpose goes through memory.
#[inline(always)]
fn transpose8(a: &Block) -> Block {
    #[inline(always)]
    fn lo(x: &[f32; 8], y: &[f32; 8]) -> [f32; 8] {
        [x[0], y[0], x[1], y[1], x[4], y[4], x[5], y[5]]
    }
    #[inline(always)]
    fn hi(x: &[f32; 8], y: &[f32; 8]) -> [f32; 8] {
        [x[2], y[2], x[3], y[3], x[6], y[6], x[7], y[7]]
    }
    #[inline(always)]
    fn lo2(x: &[f32; 8], y: &[f32; 8]) -> [f32; 8] {
        [x[0], x[1], y[0], y[1], x[4], x[5], y[4], y[5]]
    }
    #[inline(always)]
    fn hi2(x: &[f32; 8], y: &[f32; 8]) -> [f32; 8] {
        [x[2], x[3], y[2], y[3], x[6], x[7], y[6], y[7]]
    }
    #[inline(always)]
    fn lo4(x: &[f32; 8], y: &[f32; 8]) -> [f32; 8] {
        [x[0], x[1], x[2], x[3], y[0], y[1], y[2], y[3]]
    }
    #[inline(always)]
    fn hi4(x: &[f32; 8], y: &[f32; 8]) -> [f32; 8] {
        [x[4], x[5], x[6], x[7], y[4], y[5], y[6], y[7]]
    }
    // After stage 1, t[2i] and t[2i+1] interleave rows 2i and 2i+1.
    let t = [
        lo(&a[0], &a[1]),
        hi(&a[0], &a[1]),
        lo(&a[2], &a[3]),
        hi(&a[2], &a[3]),
        lo(&a[4], &a[5]),
        hi(&a[4], &a[5]),
        lo(&a[6], &a[7]),
        hi(&a[6], &a[7]),
    ];
    // After stage 2, u[k] (k < 4) holds columns k and k + 4 of rows 0-3, u[k + 4] of rows 4-7.
    let u = [
        lo2(&t[0], &t[2]),
        hi2(&t[0], &t[2]),
        lo2(&t[1], &t[3]),
        hi2(&t[1], &t[3]),
        lo2(&t[4], &t[6]),
        hi2(&t[4], &t[6]),
        lo2(&t[5], &t[7]),
        hi2(&t[5], &t[7]),
    ];
    [
        lo4(&u[0], &u[4]),
        lo4(&u[1], &u[5]),
        lo4(&u[2], &u[6]),
        lo4(&u[3], &u[7]),
        hi4(&u[0], &u[4]),
        hi4(&u[1], &u[5]),
        hi4(&u[2], &u[6]),
        hi4(&u[3], &u[7]),
    ]
}

/// Registry constructor of C-A4.
pub const JPEG: CameraBuilder = |s| {
    let q = JPEG_QUALITY[s.level()];
    let mut m = [[0f32; 8]; 8];
    for (u, row) in m.iter_mut().enumerate() {
        for (x, b) in row.iter_mut().enumerate() {
            let c = if u == 0 {
                std::f64::consts::FRAC_1_SQRT_2
            } else {
                1.0
            };
            *b = (c / 2.0 * ((2 * x + 1) as f64 * u as f64 * std::f64::consts::PI / 16.0).cos())
                as f32;
        }
    }
    Ok(Box::new(JpegCompression {
        luma_q: transposed_steps(&scaled_table(&LUMA_Q, q)),
        chroma_q: transposed_steps(&scaled_table(&CHROMA_Q, q)),
        m,
    }))
};

/// A plane of f32 samples, padded to whole 8x8 blocks by edge replication.
struct Plane {
    /// Padded width (a multiple of 8).
    w: usize,
    data: Vec<f32>,
}

impl Plane {
    /// A zeroed `w x h` plane, in a finished frame's buffer when one is free (fresh pages cost
    /// a fault and a zeroing each; see [`frame_buffer`]). Hand it back with [`Plane::recycle`].
    fn new(w: usize, h: usize) -> Self {
        let (pw, ph) = (w.div_ceil(8) * 8, h.div_ceil(8) * 8);
        Plane {
            w: pw,
            data: frame_buffer(pw * ph.max(8)),
        }
    }

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
        for v in band.iter_mut() {
            *v -= 128.0;
        }
        // Forward: the coefficients C = M B M^T come out transposed, C^T = M (M B)^T; they are
        // quantised and dequantised as C^T.
        dct_columns(m, band, pw, s1, s2);
        transpose_blocks(s2, pw);
        dct_columns(m, s2, pw, s1, band);
        for (row, (qi, q)) in band.chunks_exact_mut(pw).zip(qinv_t.iter().zip(q_t)) {
            for blk in row.chunks_exact_mut(8) {
                for ((coef, qi), q) in blk.iter_mut().zip(qi).zip(q) {
                    *coef = round_f32(*coef * qi) * q;
                }
            }
        }
        // Inverse: B = M^T C M = M^T (M^T C^T)^T.
        idct_columns(m, band, pw, s2);
        transpose_blocks(s2, pw);
        idct_columns(m, s2, pw, band);
        for v in band.iter_mut() {
            *v = (*v + 128.0).clamp(0.0, 255.0);
        }
    }
}

wide_fn! {
    /// JFIF RGB to YCbCr of one row of `c`-byte pixels: luma into `y`, chroma added into the
    /// half-width `cb`, `cr` (left pixel of each pair first). `work` (4 `y.len()` floats) holds the
    /// row deinterleaved, so that the arithmetic runs on contiguous arrays.
    fn to_ycc(
        src: &[u8],
        format: PixelFormat,
        work: &mut [f32],
        y: &mut [f32],
        cb: &mut [f32],
        cr: &mut [f32],
    ) {
        let w = y.len();
        let (r, rest) = work.split_at_mut(w);
        let (g, rest) = rest.split_at_mut(w);
        let (b, t) = rest.split_at_mut(w);
        split_rgb(src, format, [&mut *r, &mut *g, &mut *b]);
        let rgb = || r.iter().zip(g.iter()).zip(b.iter());
        for (yv, ((&r, &g), &b)) in y.iter_mut().zip(rgb()) {
            *yv = 0.299 * r + 0.587 * g + 0.114 * b;
        }
        // Whole pairs in one branch-free loop, an odd last sample on its own.
        let pair_sums = |t: &[f32], out: &mut [f32]| {
            let pairs = t.chunks_exact(2);
            let last = pairs.remainder().first().copied();
            let n = pairs.len();
            for (o, pair) in out.iter_mut().zip(pairs) {
                *o = (*o + pair[0]) + pair[1];
            }
            if let (Some(a), Some(o)) = (last, out.get_mut(n)) {
                *o += a;
            }
        };
        for (tv, ((&r, &g), &b)) in t.iter_mut().zip(rgb()) {
            *tv = -0.168_736 * r - 0.331_264 * g + 0.5 * b;
        }
        pair_sums(t, cb);
        for (tv, ((&r, &g), &b)) in t.iter_mut().zip(rgb()) {
            *tv = 0.5 * r - 0.418_688 * g - 0.081_312 * b;
        }
        pair_sums(t, cr);
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
    /// JFIF YCbCr (chroma already without its 128 offset) to RGB bytes, one plane each.
    fn ycc_to_rgb(y: &[f32], u: &[f32], v: &[f32], r: &mut [u8], g: &mut [u8], b: &mut [u8]) {
        let yuv = y.iter().zip(u).zip(v);
        for (((((&y, &u), &v), pr), pg), pb) in yuv.zip(r).zip(g).zip(b) {
            let yy = y + 0.5;
            *pr = byte(yy + 1.402 * v);
            *pg = byte(yy - 0.344_136 * u - 0.714_136 * v);
            *pb = byte(yy + 1.772 * u);
        }
    }
}

impl CameraPerturbation for JpegCompression {
    fn apply(&self, input: &ImageView<'_>, output: &mut ImageViewMut<'_>, _seq: u64) {
        use rayon::prelude::*;
        let (w, h) = (input.width as usize, input.height as usize);
        let f = input.format;
        if f.is_mono() {
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
            return;
        }
        let (cw, ch) = (w.div_ceil(2), h.div_ceil(2));
        let mut yp = Plane::overwritten(w, h);
        let mut cb = Plane::new(cw, ch);
        let mut cr = Plane::new(cw, ch);
        let (ypw, cpw) = (yp.w, cb.w);
        // Colour conversion and 2x2 chroma averaging, one pair of image rows per chroma row.
        yp.data
            .par_chunks_mut(2 * ypw)
            .zip(cb.data.par_chunks_mut(cpw).zip(cr.data.par_chunks_mut(cpw)))
            .take(ch)
            .enumerate()
            .for_each_init(
                || vec![0f32; 4 * w],
                |work, (cy, (ypair, (cbrow, crrow)))| {
                    let r0 = 2 * cy;
                    let nrows = (h - r0).min(2);
                    for k in 0..nrows {
                        let yrow = &mut ypair[k * ypw..k * ypw + w];
                        to_ycc(input.row(r0 + k), f, work, yrow, cbrow, crrow);
                    }
                    // Averages of 1, 2 or 4 samples: a power of two, so multiplying by the
                    // reciprocal is exact. Only an odd width's last column has one sample
                    // per row.
                    let per_row = |cx: usize| (2 * cx + 2).min(w) - 2 * cx;
                    let inv = |cx: usize| 1.0 / (nrows * per_row(cx)) as f32;
                    let full = w / 2;
                    average_chroma(&mut cbrow[..full], &mut crrow[..full], inv(0));
                    if full < cw {
                        average_chroma(&mut cbrow[full..cw], &mut crrow[full..cw], inv(full));
                    }
                },
            );
        yp.pad(w, h);
        cb.pad(cw, ch);
        cr.pad(cw, ch);
        self.roundtrip_plane(&mut yp, &self.luma_q);
        self.roundtrip_plane(&mut cb, &self.chroma_q);
        self.roundtrip_plane(&mut cr, &self.chroma_q);
        // Fancy upsampling: each output sample weighs its nearest chroma sample 3/4 and the next one
        // 1/4 in each direction (9/16, 3/16, 3/16, 1/16): vertical weights first, then
        // horizontal, then the colour conversion on contiguous rows (vectorisable); the bytes are
        // interleaved last.

        let vertical = |p: &Plane, cy: usize, ny: usize, t: &mut [f32]| {
            weigh_rows(&p.data[cy * cpw..][..cw], &p.data[ny * cpw..][..cw], t);
        };
        let rows = output.rows_mut();
        rows.into_par_iter()
            .with_min_len(8)
            .enumerate()
            .for_each_init(
                || (vec![0f32; cw], vec![0f32; 2 * w], vec![0u8; 3 * w]),
                |(t, uv, planes), (r, dst)| {
                    let cy = r / 2;
                    let ny = if r % 2 == 0 {
                        cy.saturating_sub(1)
                    } else {
                        (cy + 1).min(ch - 1)
                    };
                    let (u, v) = uv.split_at_mut(w);
                    vertical(&cb, cy, ny, t);
                    upsample_row(t, u);
                    vertical(&cr, cy, ny, t);
                    upsample_row(t, v);
                    let yrow = &yp.data[r * ypw..][..w];
                    let (p0, rest) = planes.split_at_mut(w);
                    let (p1, p2) = rest.split_at_mut(w);
                    ycc_to_rgb(yrow, u, v, p0, p1, p2);
                    merge_rgb(f, [&*p0, &*p1, &*p2], dst);
                    copy_alpha(f, input.row(r), dst);
                },
            );
        for p in [yp, cb, cr] {
            p.recycle();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::image::Image;

    fn flat(v: u8, w: u32, h: u32) -> Image {
        let mut img = Image::new(w, h, PixelFormat::Rgb8);
        img.data.fill(v);
        img
    }

    fn stats(img: &Image) -> (f64, f64) {
        let n = img.data.len() as f64;
        let m = img.data.iter().map(|&v| v as f64).sum::<f64>() / n;
        let var = img
            .data
            .iter()
            .map(|&v| (v as f64 - m).powi(2))
            .sum::<f64>()
            / n;
        (m, var.sqrt())
    }

    fn run(b: CameraBuilder, sev: u8, img: &Image, seq: u64) -> Image {
        let p = b(&CameraSetup {
            severity: sev,
            seed: 5,
            geometry: img.geometry(),
        })
        .unwrap();
        let mut out = Image::with_geometry(img.geometry());
        p.apply(&img.view(), &mut out.view_mut(), seq);
        out
    }

    #[test]
    fn gaussian_noise_has_the_configured_sigma() {
        let img = flat(128, 300, 200);
        for s in 1..=5u8 {
            let (m, sd) = stats(&run(GAUSSIAN, s, &img, 0));
            let want = GAUSSIAN_SIGMA[s as usize - 1] * 255.0;
            assert!((m - 128.0).abs() < 0.3, "s{s} mean {m}");
            // Clipping at 0/255 shrinks the tails slightly at the top severities.
            assert!((sd - want).abs() / want < 0.03, "s{s} sd {sd} want {want}");
        }
    }

    #[test]
    fn poisson_noise_variance_follows_the_photon_count() {
        // Var(k / lambda * 255) = 255^2 x / lambda for k ~ Poisson(x lambda).
        let img = flat(100, 300, 200);
        for s in 1..=5u8 {
            let lambda = POISSON_LAMBDA[s as usize - 1];
            let (m, sd) = stats(&run(POISSON, s, &img, 0));
            let want = 255.0 * (100.0 / 255.0 / lambda).sqrt();
            assert!((m - 100.0).abs() < 1.0, "s{s} mean {m}");
            assert!((sd - want).abs() / want < 0.05, "s{s} sd {sd} want {want}");
        }
    }

    #[test]
    fn speckle_noise_is_multiplicative() {
        // 100 x (1 + 0.2 z) stays inside 0..255 for |z| < 7, so no clipping distorts the spread.
        let bright = run(SPECKLE, 5, &flat(100, 200, 100), 0);
        let dark = run(SPECKLE, 5, &flat(20, 200, 100), 0);
        let (_, sb) = stats(&bright);
        let (_, sd) = stats(&dark);
        assert!((sb - 100.0 * 0.2).abs() < 1.0, "{sb}");
        assert!((sd - 20.0 * 0.2).abs() < 0.6, "{sd}");
    }

    #[test]
    fn impulse_noise_hits_the_configured_count_everywhere() {
        let img = flat(128, 101, 67);
        for s in 1..=5u8 {
            let out = run(IMPULSE, s, &img, 3);
            let p = IMPULSE_AMOUNT[s as usize - 1];
            let n = (p * 101.0 * 67.0 * 3.0 / 2.0).ceil();
            let salt = out.data.iter().filter(|&&v| v == 255).count() as f64;
            let pepper = out.data.iter().filter(|&&v| v == 0).count() as f64;
            // Draws with replacement collide (and pepper overwrites salt) a little.
            let total = 101.0 * 67.0 * 3.0;
            assert!(
                salt <= n && salt > n * (1.0 - 2.0 * n / total) - 10.0,
                "s{s} salt {salt} of {n}"
            );
            assert!(
                pepper <= n && pepper > n * (1.0 - n / total) - 10.0,
                "s{s} pepper {pepper} of {n}"
            );
        }
        // The reference's blind spots (last row, last column, third channel) are hit here.
        let out = run(IMPULSE, 5, &img, 1);
        let last_row = out.view().row(66).iter().any(|&v| v != 128);
        let last_col = (0..67).any(|y| out.view().row(y)[100 * 3..].iter().any(|&v| v != 128));
        let blue = out.data.chunks_exact(3).any(|p| p[2] != 128);
        assert!(last_row && last_col && blue);
    }

    #[test]
    fn the_shuffle_transpose_is_a_transpose() {
        let a: Block = std::array::from_fn(|i| std::array::from_fn(|j| (i * 8 + j) as f32));
        let t = transpose8(&a);
        for i in 0..8 {
            for j in 0..8 {
                assert_eq!(t[j][i], a[i][j]);
            }
        }
    }

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
        let low = run(JPEG, 5, &ramp, 0);
        let high = run(JPEG, 1, &ramp, 0);
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
        let flat_img = flat(77, 24, 24);
        let out = run(JPEG, 5, &flat_img, 0);
        assert!(out.data.iter().all(|&v| v == 68), "{:?}", &out.data[..6]);
        assert!(run(JPEG, 1, &flat_img, 0).data.iter().all(|&v| v == 77));
    }
}
