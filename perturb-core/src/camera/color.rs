//! Colour and tone family (C-F): changes of hue, saturation and tone.

use super::ops::{byte, map_saturation, map_value, par_rows, wide_fn};
use super::pointwise::{ByteMap, ChannelMix, GainBlend, LumaBlend, channel_sums};
use super::{CameraBuilder, CameraPerturbation, CameraSetup};
use crate::error::Error;
use crate::image::{ImageView, ImageViewMut};
use rayon::prelude::*;
use rustfft::num_complex::Complex32;

pub(crate) fn refuse_mono(id: &'static str, s: &CameraSetup) -> Result<(), Error> {
    if s.geometry.format.is_mono() {
        return Err(Error::UnsupportedPixelFormat {
            id,
            format: "mono8 (it has no colour)",
        });
    }
    Ok(())
}

/// C-F5 grayscale: blend weight towards the luma, severities 1..5 (PerturbationDrive
/// `grayscale_filter`).
pub const GRAYSCALE_WEIGHT: [f32; 5] = [0.10, 0.20, 0.35, 0.55, 0.85];

/// C-F5 grayscale: `out = (1 - s) I + s Y` per colour channel with `Y = .299 R + .587 G + .114 B`,
/// in 8.8 fixed point (two 256-entry tables for the two terms), rounded; alpha is copied. The
/// tables are computed as 16.16 fixed-point lines in 32-bit lanes (same bytes, see
/// [`LumaBlend`]). Mono8 input is refused: it is already grey, so the perturbation would do
/// nothing.
pub struct Grayscale {
    keep: [u16; 256],
    luma: [u16; 256],
    /// The tables as 16.16 fixed-point lines (same bytes; found for every severity).
    fast: Option<LumaBlend>,
}

/// Registry constructor of C-F5.
pub const GRAYSCALE: CameraBuilder = |s| {
    refuse_mono("C-F5", s)?;
    Ok(Box::new(Grayscale::new(s)))
};

impl Grayscale {
    /// Configures the blend weight for the severity.
    pub fn new(setup: &CameraSetup) -> Self {
        let w = GRAYSCALE_WEIGHT[setup.level()];
        let keep = std::array::from_fn(|v| ((1.0 - w) * v as f32 * 256.0).round() as u16);
        let luma = std::array::from_fn(|v| (w * v as f32 * 256.0).round() as u16);
        Grayscale {
            keep,
            luma,
            fast: LumaBlend::fit(&keep, &luma),
        }
    }
}

impl CameraPerturbation for Grayscale {
    fn apply(&self, input: &ImageView<'_>, output: &mut ImageViewMut<'_>, _seq: u64) {
        let format = input.format;
        if let Some(fast) = &self.fast {
            return par_rows(input, output, |_, src, dst| fast.row(format, src, dst));
        }
        let [ri, gi, bi] = format.rgb_offsets();
        let c = format.channels();
        par_rows(input, output, |_, src, dst| {
            for (p, q) in src.chunks_exact(c).zip(dst.chunks_exact_mut(c)) {
                let y = crate::image::luma(p[ri], p[gi], p[bi]) as usize;
                let ly = self.luma[y];
                for ch in [ri, gi, bi] {
                    q[ch] = ((self.keep[p[ch] as usize] + ly + 128) >> 8).min(255) as u8;
                }
                if let Some(a) = format.alpha_offset() {
                    q[a] = p[a];
                }
            }
        });
    }
}

/// C-F6 saturation_increase: saturation factor, severities 1..5 (PerturbationDrive
/// `saturation_filter`).
pub const SATURATION_INCREASE: [f32; 5] = [1.05, 1.15, 1.40, 1.65, 1.90];
/// C-F8 saturation_decrease: saturation factor, severities 1..5 (PerturbationDrive
/// `saturation_decrease_filter`).
pub const SATURATION_DECREASE: [f32; 5] = [0.90, 0.85, 0.60, 0.35, 0.10];

/// C-F6 saturation_increase / C-F8 saturation_decrease: HSV saturation `S' = min(255, S m)`
/// (truncated, as the reference's uint8 write), hue and value kept; see [`map_saturation`] for how
/// this is computed in RGB. Mono8 is refused.
pub struct Saturation {
    lut: [u8; 256],
}

impl Saturation {
    /// Saturation scaled by `m`.
    pub fn new(m: f32) -> Self {
        Saturation {
            lut: std::array::from_fn(|s| (s as f32 * m).min(255.0) as u8),
        }
    }
}

/// Registry constructor of C-F6.
pub const SATURATION_UP: CameraBuilder = |s| {
    refuse_mono("C-F6", s)?;
    Ok(Box::new(Saturation::new(SATURATION_INCREASE[s.level()])))
};

/// Registry constructor of C-F8.
pub const SATURATION_DOWN: CameraBuilder = |s| {
    refuse_mono("C-F8", s)?;
    Ok(Box::new(Saturation::new(SATURATION_DECREASE[s.level()])))
};

impl CameraPerturbation for Saturation {
    fn apply(&self, input: &ImageView<'_>, output: &mut ImageViewMut<'_>, _seq: u64) {
        map_saturation(input, output, &self.lut);
    }
}

/// C-F7 posterize: levels per channel, severities 1..5 (PerturbationDrive `posterize_filter`).
pub const POSTERIZE_LEVELS: [u32; 5] = [128, 64, 32, 8, 4];

/// The reference's posterize table: `min(255, floor(v / (255 / L)) floor(255 / (L - 1)))`.
pub fn posterize_lut(levels: u32) -> [u8; 256] {
    let step = 255.0 / levels as f64;
    let scale = (255 / (levels - 1)) as f64;
    std::array::from_fn(|v| ((v as f64 / step).floor() * scale).min(255.0) as u8)
}

/// C-F7 posterize: the reference's lookup table per channel (works on mono8 too). At s4 (L = 8)
/// the table has 9 output levels and at s5 (L = 4) {0, 85, 170, 255}, as in the reference. The
/// table is computed as its staircase in 16-bit integer arithmetic (same bytes, see
/// [`ByteMap::steps`]).
pub struct Posterize {
    map: ByteMap,
}

/// Registry constructor of C-F7.
pub const POSTERIZE: CameraBuilder = |s| {
    let levels = POSTERIZE_LEVELS[s.level()];
    Ok(Box::new(Posterize {
        map: ByteMap::steps(posterize_lut(levels), levels, 255 / (levels - 1)),
    }))
};

impl CameraPerturbation for Posterize {
    fn apply(&self, input: &ImageView<'_>, output: &mut ImageViewMut<'_>, _seq: u64) {
        self.map.apply(input, output);
    }
}

/// C-F4 white_balance: blend weight towards the gray-world balanced image, severities 1..5
/// (PerturbationDrive `white_balance_filter`).
pub const WHITE_BALANCE_WEIGHT: [f32; 5] = [0.10, 0.25, 0.50, 0.75, 0.99];

/// C-F4 white_balance: gray-world balance: each channel scaled by `mean(all channels) /
/// mean(channel)` (clipped, truncated to 8 bits as the reference), then `out = (1 - s) I + s WB`.
/// The channel means are measured on each frame (one pass), the rest is a per-channel table,
/// computed as fixed-point arithmetic where that gives the table's bytes (checked on each frame,
/// see [`GainBlend`]).
/// Mono8 is refused (a single channel is always balanced).
pub struct WhiteBalance {
    weight: f32,
}

/// Registry constructor of C-F4.
pub const WHITE_BALANCE: CameraBuilder = |s| {
    refuse_mono("C-F4", s)?;
    Ok(Box::new(WhiteBalance {
        weight: WHITE_BALANCE_WEIGHT[s.level()],
    }))
};

impl CameraPerturbation for WhiteBalance {
    fn apply(&self, input: &ImageView<'_>, output: &mut ImageViewMut<'_>, _seq: u64) {
        use rayon::prelude::*;
        let format = input.format;
        let c = format.channels();
        let [ri, gi, bi] = format.rgb_offsets();
        let sums = (0..input.height as usize)
            .into_par_iter()
            .with_min_len(16)
            .map(|y| channel_sums(input.row(y), c, [ri, gi, bi]))
            .reduce(|| [0; 3], |a, b| [a[0] + b[0], a[1] + b[1], a[2] + b[2]]);
        let n = (input.width as f64 * input.height as f64).max(1.0);
        let means = sums.map(|v| v as f64 / n);
        let all = (means[0] + means[1] + means[2]) / 3.0;
        let w = self.weight as f64;
        let gains = means.map(|m| if m > 0.0 { all / m } else { 1.0 });
        let luts: [[u8; 256]; 3] = std::array::from_fn(|k| {
            std::array::from_fn(|v| {
                let balanced = (v as f64 * gains[k]).min(255.0).floor();
                ((1.0 - w) * v as f64 + w * balanced)
                    .round()
                    .clamp(0.0, 255.0) as u8
            })
        });
        // The tables as fixed-point arithmetic where that gives their bytes (checked per frame).
        if let Some(fast) = GainBlend::fit(gains, w, &luts) {
            return par_rows(input, output, |_, src, dst| fast.row(format, src, dst));
        }
        par_rows(input, output, |_, src, dst| {
            for (p, q) in src.chunks_exact(c).zip(dst.chunks_exact_mut(c)) {
                q[ri] = luts[0][p[ri] as usize];
                q[gi] = luts[1][p[gi] as usize];
                q[bi] = luts[2][p[bi] as usize];
                if let Some(a) = format.alpha_offset() {
                    q[a] = p[a];
                }
            }
        });
    }
}

/// C-F1 false_color: the five colour manipulations of PerturbationDrive `false_color_filter`, one
/// per severity, on the channels (c0, c1, c2) in the image's own order as the reference does.
pub const FALSE_COLOR_MODES: [&str; 5] = [
    "rotate (c1, c2, c0)",
    "swap c0 c1",
    "swap c0 c2",
    "invert",
    "mix neighbours",
];

/// C-F1 false_color: s1 (c0, c1, c2) <- (c1, c2, c0); s2 swaps c0 and c1; s3 swaps c0 and c2;
/// s4 inverts (255 - I); s5 replaces each channel by the mean of itself and the next one,
/// c0 <- (c0 + c1) / 2, c1 <- (c1 + c2) / 2, c2 <- (c2 + c0) / 2.
///
/// Deviation: the reference computes s5 in uint8 and wraps around ((200, 100, 50) becomes
/// (22, 75, 125)); here the sums are done without overflow ((150, 75, 125)), which is what the
/// channel mixing intends. Mono8 is refused (one channel cannot be permuted).
pub struct FalseColor {
    mode: usize,
}

/// Registry constructor of C-F1.
pub const FALSE_COLOR: CameraBuilder = |s| {
    refuse_mono("C-F1", s)?;
    Ok(Box::new(FalseColor { mode: s.level() }))
};

impl CameraPerturbation for FalseColor {
    fn apply(&self, input: &ImageView<'_>, output: &mut ImageViewMut<'_>, _seq: u64) {
        let c = input.format.channels();
        let mix = ChannelMix::ALL[self.mode];
        par_rows(input, output, |_, src, dst| mix.row(c, src, dst));
    }
}

/// C-F3 histogram_equalization: CLAHE clip limit, severities 1..5 (PerturbationDrive
/// `histogram_equalisation`, `cv2.createCLAHE(clipLimit, (8, 8))` on the HSV value channel).
pub const CLAHE_CLIP: [f64; 5] = [1.0, 3.0, 5.0, 7.0, 10.0];

/// Contrast-limited adaptive histogram equalisation of an 8-bit plane, as OpenCV's CLAHE: the plane
/// is padded by reflection to a multiple of the 8 x 8 tile grid, each tile's histogram is clipped at
/// `max(clip x tile pixels / 256, 1)` with the excess spread evenly (the remainder one count at a
/// time at a regular step), its cumulative histogram scaled to 0..255 is the tile's table, and every
/// pixel blends the tables of its four nearest tile centres bilinearly. Matches
/// `cv2.createCLAHE(clip, (8, 8)).apply` to within one level (checked on real frames).
pub fn clahe(plane: &[u8], w: usize, h: usize, clip: f64, tiles: usize) -> Vec<u8> {
    // OpenCV pads only when a side is not a multiple of the grid, and then pads both sides by
    // `tiles - n % tiles`, a whole extra tile for a side that was already a multiple.
    let (pw, ph) = if w.is_multiple_of(tiles) && h.is_multiple_of(tiles) {
        (w, h)
    } else {
        (w + tiles - w % tiles, h + tiles - h % tiles)
    };
    let (tw, th) = ((pw / tiles).max(1), (ph / tiles).max(1));
    let at = |x: usize, y: usize| plane[reflect_index(y, h) * w + reflect_index(x, w)];
    let area = (tw * th) as f64;
    let limit = ((clip * area / 256.0) as usize).max(1);
    let scale = 255.0 / area;
    let luts: Vec<[u8; 256]> = (0..tiles * tiles)
        .into_par_iter()
        .map(|t| {
            let (tx, ty) = (t % tiles, t / tiles);
            let mut hist = [0usize; 256];
            for y in ty * th..(ty + 1) * th {
                for x in tx * tw..(tx + 1) * tw {
                    hist[at(x, y) as usize] += 1;
                }
            }
            let mut clipped = 0;
            for b in hist.iter_mut() {
                if *b > limit {
                    clipped += *b - limit;
                    *b = limit;
                }
            }
            let batch = clipped / 256;
            let mut residual = clipped - batch * 256;
            for b in hist.iter_mut() {
                *b += batch;
            }
            if let Some(step) = 256usize.checked_div(residual) {
                let step = step.max(1);
                let mut i = 0;
                while i < 256 && residual > 0 {
                    hist[i] += 1;
                    residual -= 1;
                    i += step;
                }
            }
            let mut lut = [0u8; 256];
            let mut sum = 0usize;
            for (v, b) in hist.iter().enumerate() {
                sum += b;
                lut[v] = (sum as f64 * scale).round().min(255.0) as u8;
            }
            lut
        })
        .collect();
    let (inv_tw, inv_th) = (1.0 / tw as f32, 1.0 / th as f32);
    let coord = |p: usize, inv: f32| {
        let f = p as f32 * inv - 0.5;
        let t1 = f.floor() as i64;
        let a = f - t1 as f32;
        let (t1c, t2c) = (
            t1.clamp(0, tiles as i64 - 1) as usize,
            (t1 + 1).clamp(0, tiles as i64 - 1) as usize,
        );
        (t1c, t2c, a)
    };
    let xs: Vec<(usize, usize, f32)> = (0..w).map(|x| coord(x, inv_tw)).collect();
    // Runs of columns that blend the same pair of tile columns: the four tables are picked once
    // per run, not per pixel.
    let mut runs: Vec<(usize, usize, usize, usize)> = Vec::new();
    for (x, &(tx1, tx2, _)) in xs.iter().enumerate() {
        match runs.last_mut() {
            Some(run) if (run.2, run.3) == (tx1, tx2) => run.1 = x + 1,
            _ => runs.push((x, x + 1, tx1, tx2)),
        }
    }
    let mut out = vec![0u8; w * h];
    out.par_chunks_mut(w.max(1)).enumerate().for_each_init(
        || vec![0f32; w],
        |vals, (y, row)| {
            let (ty1, ty2, ya) = coord(y, inv_th);
            let src = &plane[y * w..(y + 1) * w];
            // The table lookups pixel by pixel into floats, then the rounding to bytes in
            // one vectorised pass (a float-to-byte cast per pixel does not vectorise).
            for &(x0, x1, tx1, tx2) in &runs {
                let lut = |tx: usize, ty: usize| &luts[ty * tiles + tx];
                let (a, b) = (lut(tx1, ty1), lut(tx2, ty1));
                let (c, d) = (lut(tx1, ty2), lut(tx2, ty2));
                for ((o, &v), &(_, _, xa)) in
                    vals[x0..x1].iter_mut().zip(&src[x0..x1]).zip(&xs[x0..x1])
                {
                    let v = v as usize;
                    let top = a[v] as f32 * (1.0 - xa) + b[v] as f32 * xa;
                    let bot = c[v] as f32 * (1.0 - xa) + d[v] as f32 * xa;
                    *o = top * (1.0 - ya) + bot * ya;
                }
            }
            round_bytes(vals, row);
        },
    );
    out
}

wide_fn! {
    /// `dst = clamp(round(src))` (half away from zero), NaN to 0.
    fn round_bytes(src: &[f32], dst: &mut [u8]) {
        for (d, s) in dst.iter_mut().zip(src) {
            *d = byte(s.round());
        }
    }
}

/// Reflect-101 for indices past the end only (padding to whole tiles is on the bottom and right).
fn reflect_index(i: usize, n: usize) -> usize {
    super::ops::reflect101(i as i64, n)
}

/// C-F3 histogram_equalization: CLAHE (see [`clahe`]) on the HSV value channel, hue and saturation
/// kept (the channels are rescaled to the new value, see [`super::ops::map_value`]): local contrast
/// is boosted, noise in dark flat areas too. Works on mono8 (the single channel is the value).
pub struct HistogramEqualization {
    clip: f64,
}

/// Registry constructor of C-F3.
pub const HISTOGRAM_EQUALIZATION: CameraBuilder = |s| {
    Ok(Box::new(HistogramEqualization {
        clip: CLAHE_CLIP[s.level()],
    }))
};

impl CameraPerturbation for HistogramEqualization {
    fn apply(&self, input: &ImageView<'_>, output: &mut ImageViewMut<'_>, _seq: u64) {
        let (w, h, c) = (
            input.width as usize,
            input.height as usize,
            input.format.channels(),
        );
        let [ri, gi, bi] = input.format.rgb_offsets();
        let mut v = vec![0u8; w * h];
        v.par_chunks_mut(w.max(1)).enumerate().for_each(|(y, row)| {
            for (d, p) in row.iter_mut().zip(input.row(y).chunks_exact(c)) {
                *d = p[ri].max(p[gi]).max(p[bi]);
            }
        });
        let eq = clahe(&v, w, h, self.clip, 8);
        map_value(input, output, |y, x, _| eq[y * w + x]);
    }
}

/// C-F2 phase_scrambling: phase noise amplitude s (in units of pi), severities 1..5
/// (PerturbationDrive `phase_scrambling`).
pub const PHASE_SCRAMBLE: [f32; 5] = [0.05, 0.15, 0.26, 0.38, 0.55];

/// C-F2 phase_scrambling: per colour channel, the 2-D Fourier transform F of the frame gets a random
/// phase `theta_k = s pi U(0, 1)` added at every frequency bin (drawn anew each frame from (seed,
/// sequence number)), and the output is `clip(Re IFFT(F e^(i theta)))`: the power spectrum is kept,
/// the spatial structure is scrambled.
///
/// The reference's phases are not Hermitian-symmetric, so it keeps the real part of a complex
/// result. The real part equals the inverse transform of `F M` with `M_k = (e^(i theta_k) +
/// e^(-i theta_-k)) / 2`, which is Hermitian: this implementation multiplies the half spectrum of a
/// real FFT by `M` and computes exactly the reference's output at half the cost (a unit test checks
/// it against a direct DFT). The uniform draws are quantised to 4096 levels so that `cos` and `sin`
/// come from a table built at configuration time (a phase step of at most 0.0004 rad). Frame sizes
/// with large prime factors transform more slowly (rustfft chooses Rader / Bluestein); the FFT plans
/// are built at configuration time, and the working buffers (about 8 bytes per pixel per colour
/// channel) are kept from frame to frame. A frame makes three passes over memory: the row
/// transforms, the column transforms (a block of columns is gathered, transformed, scrambled and
/// transformed back while it sits in the cache), and the inverse row transforms, which write the
/// output bytes directly.
pub struct PhaseScrambling {
    seed: u64,
    plan: FftPlan,
    /// `(cos, sin)` of `s pi (i + 0.5) / 4096` for the 4096 quantised draws.
    trig: Box<[(f32, f32); 1 << PHASE_BITS]>,
    /// Working buffers of finished frames, reused by the next ones (a frame's spectra are tens
    /// of megabytes: fresh pages each time cost more than some of the transforms).
    spare: std::sync::Mutex<Vec<Buffers>>,
}

/// The working buffers of a frame, kept from frame to frame: the half spectra (`h x (w/2 + 1)`
/// bins per colour channel) after the row transforms and after the column transforms, both in
/// tiles of [`ROW_BAND`] x [`COLUMN_BLOCK`] bins so that every pass reads and writes kilobytes at
/// a time (a column read across a row-major spectrum touches a page per row).
///
/// `rows` holds bands of rows; a band holds each channel's tiles left to right, each tile
/// row-major. `cols` holds each channel's tiles of columns, each tile row-major over all rows
/// (rounded up to whole bands).
#[derive(Default)]
struct Buffers {
    rows: Vec<Complex32>,
    cols: Vec<Complex32>,
}

/// Copies one row of a tile: a fixed-size copy for full rows (a `memmove` call per 128 bytes
/// costs more than the copy).
#[inline]
fn copy_tile_row(dst: &mut [Complex32], src: &[Complex32]) {
    match (
        <&mut [Complex32; COLUMN_BLOCK]>::try_from(&mut *dst),
        <&[Complex32; COLUMN_BLOCK]>::try_from(src),
    ) {
        (Ok(d), Ok(s)) => *d = *s,
        _ => dst.copy_from_slice(src),
    }
}

/// Bits of one quantised phase draw.
const PHASE_BITS: u32 = 12;

/// Columns of the half spectrum transformed together: a block is gathered from the row
/// transforms' tiles, transformed, scrambled and transformed back while it sits in the cache.
const COLUMN_BLOCK: usize = 16;

/// Rows per task of the row transforms.
const ROW_BAND: usize = 16;

struct FftPlan {
    w: usize,
    h: usize,
    r2c: std::sync::Arc<dyn realfft::RealToComplex<f32>>,
    c2r: std::sync::Arc<dyn realfft::ComplexToReal<f32>>,
    col_fwd: std::sync::Arc<dyn rustfft::Fft<f32>>,
    col_inv: std::sync::Arc<dyn rustfft::Fft<f32>>,
}

/// Registry constructor of C-F2.
pub const PHASE_SCRAMBLING: CameraBuilder = |s| {
    Ok(Box::new(PhaseScrambling::new(
        s.seed,
        s.geometry.width as usize,
        s.geometry.height as usize,
        PHASE_SCRAMBLE[s.level()],
    )))
};

impl PhaseScrambling {
    /// Plans the transforms of a `w x h` frame and tabulates the phases for amplitude `s` (in
    /// units of pi).
    fn new(seed: u64, w: usize, h: usize, s: f32) -> Self {
        let (w, h) = (w.max(1), h.max(1));
        let mut real = realfft::RealFftPlanner::<f32>::new();
        let mut cplx = rustfft::FftPlanner::<f32>::new();
        let amp = s as f64 * std::f64::consts::PI;
        let levels = 1usize << PHASE_BITS;
        PhaseScrambling {
            seed,
            plan: FftPlan {
                w,
                h,
                r2c: real.plan_fft_forward(w),
                c2r: real.plan_fft_inverse(w),
                col_fwd: cplx.plan_fft_forward(h),
                col_inv: cplx.plan_fft_inverse(h),
            },
            trig: (0..levels)
                .map(|i| {
                    let t = amp * (i as f64 + 0.5) / levels as f64;
                    (t.cos() as f32, t.sin() as f32)
                })
                .collect::<Vec<_>>()
                .try_into()
                .expect("one entry per level"),
            spare: std::sync::Mutex::new(Vec::new()),
        }
    }

    /// The quantised uniform draws of column `kx` of the full spectrum of `channel` for frame
    /// `seq`, one per row (`out` is `h` long; one random stream per column): draw `q` stands for
    /// the phase `s pi (q + 0.5) / 4096`.
    fn column_draws(&self, seq: u64, channel: usize, kx: usize, out: &mut [u16]) {
        let mut rng = super::ops::row_rng(self.seed, seq, 0xF2 + ((channel as u64) << 32), kx);
        // The top PHASE_BITS of each 16-bit draw.
        super::ops::fill_quarters(&mut rng, out, |q| q >> (16 - PHASE_BITS));
    }

    /// The tiling of the half spectrum: (tiles of [`COLUMN_BLOCK`] columns, bands of
    /// [`ROW_BAND`] rows, rows rounded up to whole bands).
    fn tiling(&self) -> (usize, usize, usize) {
        let FftPlan { w, h, .. } = self.plan;
        let nt = (w / 2 + 1).div_ceil(COLUMN_BLOCK);
        let nb = h.div_ceil(ROW_BAND);
        (nt, nb, nb * ROW_BAND)
    }

    /// Real FFT of every row of `nc` channels into `buf.rows`; `load(y, lines)` writes row `y`
    /// of each channel into `lines` (`nc` lines of `w` after one another). Bands of rows run on
    /// the worker threads.
    fn forward_rows(
        &self,
        nc: usize,
        buf: &mut Buffers,
        load: &(dyn Fn(usize, &mut [f32]) + Sync),
    ) {
        let FftPlan { w, h, .. } = self.plan;
        let (nt, nb, hp) = self.tiling();
        let (t, r) = (COLUMN_BLOCK, ROW_BAND);
        let zero = Complex32::new(0.0, 0.0);
        buf.rows.resize(nb * nc * nt * r * t, zero);
        buf.cols.resize(nc * nt * hp * t, zero);
        buf.rows
            .par_chunks_mut(nc * nt * r * t)
            .enumerate()
            .for_each_init(
                || {
                    let r2c = &self.plan.r2c;
                    (
                        vec![0f32; nc * w],
                        r2c.make_output_vec(),
                        r2c.make_scratch_vec(),
                    )
                },
                |(lines, spec, scratch), (i, band)| {
                    let y0 = i * r;
                    for j in 0..r.min(h - y0) {
                        load(y0 + j, lines);
                        for (line, tiles) in lines
                            .chunks_exact_mut(w)
                            .zip(band.chunks_exact_mut(nt * r * t))
                        {
                            self.plan
                                .r2c
                                .process_with_scratch(line, spec, scratch)
                                .expect("sizes match the plan");
                            for (tile, part) in tiles.chunks_exact_mut(r * t).zip(spec.chunks(t)) {
                                copy_tile_row(&mut tile[j * t..j * t + part.len()], part);
                            }
                        }
                    }
                },
            );
    }

    /// Column transforms of `nc` channels, one tile of [`COLUMN_BLOCK`] columns at a time:
    /// gather the tile from `buf.rows` into a column-major block, FFT it, multiply by the
    /// scrambling multiplier, inverse FFT, and store it row by row into its tile of `buf.cols`.
    /// The block stays in the cache through all of it.
    ///
    /// The multiplier of bin (ky, kx) is `M = (e^(i theta(ky, kx)) + e^(-i theta(-ky, -kx))) /
    /// 2`; the partner bin lies in column `-kx` of the full spectrum, read backwards from ky = 1.
    fn scramble_columns(&self, nc: usize, buf: &mut Buffers, seq: u64) {
        let FftPlan { w, h, .. } = self.plan;
        let wh = w / 2 + 1;
        let (nt, _, hp) = self.tiling();
        let (t, r) = (COLUMN_BLOCK, ROW_BAND);
        let zero = Complex32::new(0.0, 0.0);
        let len = self
            .plan
            .col_fwd
            .get_inplace_scratch_len()
            .max(self.plan.col_inv.get_inplace_scratch_len());
        let m = |a: u16, b: u16| {
            let mask = |q: u16| (q & 0xFFF) as usize;
            let (a, b) = (self.trig[mask(a)], self.trig[mask(b)]);
            Complex32::new((a.0 + b.0) * 0.5, (a.1 - b.1) * 0.5)
        };
        let Buffers { rows, cols } = buf;
        let rows: &[Complex32] = rows;
        cols.par_chunks_mut(hp * t).enumerate().for_each_init(
            || {
                (
                    vec![zero; t * h],
                    vec![zero; len],
                    vec![0u16; h],
                    vec![0u16; h],
                )
            },
            |(block, scratch, here, there), (i, tile)| {
                let (k, b) = (i / nt, i % nt);
                let x0 = b * t;
                let n = t.min(wh - x0);
                let block = &mut block[..n * h];
                for (band, src) in rows.chunks_exact(nc * nt * r * t).enumerate() {
                    let src = &src[i * r * t..(i + 1) * r * t];
                    for (j, row) in src.chunks_exact(t).enumerate().take(h - band * r) {
                        for (c, &v) in row[..n].iter().enumerate() {
                            block[c * h + band * r + j] = v;
                        }
                    }
                }
                self.plan.col_fwd.process_with_scratch(block, scratch);
                for (j, col) in block.chunks_exact_mut(h).enumerate() {
                    let kx = x0 + j;
                    self.column_draws(seq, k, kx, here);
                    self.column_draws(seq, k, (w - kx) % w, there);
                    col[0] *= m(here[0], there[0]);
                    for ((v, &a), &b) in col[1..]
                        .iter_mut()
                        .zip(&here[1..])
                        .zip(there[1..].iter().rev())
                    {
                        *v *= m(a, b);
                    }
                }
                self.plan.col_inv.process_with_scratch(block, scratch);
                for (y, row) in tile.chunks_exact_mut(t).take(h).enumerate() {
                    for (c, v) in row[..n].iter_mut().enumerate() {
                        *v = block[c * h + y];
                    }
                }
            },
        );
    }

    /// Inverse real FFT of rows `y0 .. y0 + out.len() / w` (at most one band, `y0` a multiple of
    /// [`ROW_BAND`]) of channel `k`'s scrambled spectrum into `out`, not normalised (scaled by
    /// `w h`); `line` and `scratch` are working space.
    fn inverse_rows(
        &self,
        buf: &Buffers,
        k: usize,
        y0: usize,
        out: &mut [f32],
        (line, scratch): &mut (Vec<Complex32>, Vec<Complex32>),
    ) {
        let w = self.plan.w;
        let wh = w / 2 + 1;
        let (nt, _, hp) = self.tiling();
        let t = COLUMN_BLOCK;
        let n = out.len() / w;
        line.resize(n * wh, Complex32::new(0.0, 0.0));
        let tiles = buf.cols.chunks_exact(hp * t).skip(k * nt).take(nt);
        for (tile, x0) in tiles.zip((0..wh).step_by(t)) {
            let cols = t.min(wh - x0);
            for (r, src) in tile[y0 * t..(y0 + n) * t].chunks_exact(t).enumerate() {
                copy_tile_row(&mut line[r * wh + x0..r * wh + x0 + cols], &src[..cols]);
            }
        }
        for (row, out) in line.chunks_exact_mut(wh).zip(out.chunks_exact_mut(w)) {
            // The DC and Nyquist bins of a real signal's rows must be real for the inverse.
            row[0].im = 0.0;
            if w.is_multiple_of(2) {
                row[wh - 1].im = 0.0;
            }
            self.plan
                .c2r
                .process_with_scratch(row, out, scratch)
                .expect("sizes match the plan");
        }
    }
}

impl CameraPerturbation for PhaseScrambling {
    fn apply(&self, input: &ImageView<'_>, output: &mut ImageViewMut<'_>, seq: u64) {
        let w = input.width as usize;
        let format = input.format;
        let nc = format.color_channels();
        let mut buf = {
            let mut spare = self.spare.lock().unwrap_or_else(|e| e.into_inner());
            spare.pop().unwrap_or_default()
        };
        // Colour channels are read and written in one pass over each row (three strided passes
        // cost more than the row transforms).
        self.forward_rows(nc, &mut buf, &|y, lines| {
            let src = input.row(y);
            if nc == 3 {
                let (l0, rest) = lines.split_at_mut(w);
                let (l1, l2) = rest.split_at_mut(w);
                super::ops::split_rgb(src, format, [l0, l1, l2]);
            } else {
                for (d, &v) in lines.iter_mut().zip(src) {
                    *d = v as f32;
                }
            }
        });
        self.scramble_columns(nc, &mut buf, seq);
        let norm = 1.0 / (w * self.plan.h) as f32;
        let byte = |v: f32| super::ops::byte(v * norm + 0.5);
        let mut rows = output.rows_mut();
        rows.par_chunks_mut(ROW_BAND).enumerate().for_each_init(
            || {
                let work = (Vec::new(), self.plan.c2r.make_scratch_vec());
                (vec![0f32; nc * ROW_BAND * w], vec![0u8; nc * w], work)
            },
            |(planes, bytes, work), (i, band)| {
                let (y0, n) = (i * ROW_BAND, band.len());
                for (k, plane) in planes.chunks_exact_mut(ROW_BAND * w).enumerate() {
                    self.inverse_rows(&buf, k, y0, &mut plane[..n * w], work);
                }
                for (r, dst) in band.iter_mut().enumerate() {
                    for (k, out) in bytes.chunks_exact_mut(w).enumerate() {
                        let plane = &planes[(k * ROW_BAND + r) * w..][..w];
                        for (b, &v) in out.iter_mut().zip(plane) {
                            *b = byte(v);
                        }
                    }
                    if nc == 3 {
                        let (b0, rest) = bytes.split_at(w);
                        let (b1, b2) = rest.split_at(w);
                        super::ops::merge_rgb(format, [b0, b1, b2], dst);
                    } else {
                        dst.copy_from_slice(bytes);
                    }
                    super::ops::copy_alpha(format, input.row(y0 + r), dst);
                }
            },
        );
        self.spare
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .push(buf);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::image::{Image, PixelFormat};

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

    fn px(r: u8, g: u8, b: u8) -> Image {
        Image::from_vec(vec![r, g, b], 1, 1, 3, PixelFormat::Rgb8).unwrap()
    }

    #[test]
    fn false_color_modes() {
        let i = px(200, 100, 50);
        assert_eq!(run(FALSE_COLOR, 1, &i).data, vec![100, 50, 200]);
        assert_eq!(run(FALSE_COLOR, 2, &i).data, vec![100, 200, 50]);
        assert_eq!(run(FALSE_COLOR, 3, &i).data, vec![50, 100, 200]);
        assert_eq!(run(FALSE_COLOR, 4, &i).data, vec![55, 155, 205]);
        assert_eq!(
            run(FALSE_COLOR, 5, &i).data,
            vec![150, 75, 125],
            "no uint8 wrap-around"
        );
    }

    #[test]
    fn posterize_levels_match_the_reference_table() {
        let distinct = |l| {
            let t = posterize_lut(l);
            let mut v: Vec<u8> = t.to_vec();
            v.dedup();
            v
        };
        assert_eq!(distinct(4), vec![0, 85, 170, 255]);
        assert_eq!(distinct(8).len(), 9);
        // The reference formula reaches L at v = 255, so L + 1 levels for L = 128, 64, 32
        // (numpy: 129, 65, 33, 9, 4 distinct values).
        assert_eq!(distinct(128).len(), 129);
        assert_eq!(distinct(64).len(), 65);
        assert_eq!(distinct(32).len(), 33);
    }

    #[test]
    fn saturation_scales_colourfulness_and_keeps_value_and_grey() {
        let i = px(200, 120, 80);
        let up = run(SATURATION_UP, 5, &i);
        let down = run(SATURATION_DOWN, 5, &i);
        assert_eq!(up.data[0], 200);
        assert_eq!(down.data[0], 200, "value (max) kept");
        assert!(
            up.data[2] < 80 && down.data[2] > 180,
            "{:?} {:?}",
            up.data,
            down.data
        );
        // Decrease at s5 keeps 10% of the saturation: the channels nearly meet at V.
        assert!(down.data.iter().all(|&v| v >= 188));
        assert_eq!(
            run(SATURATION_UP, 5, &px(90, 90, 90)).data,
            vec![90, 90, 90]
        );
    }

    #[test]
    fn white_balance_evens_out_a_colour_cast() {
        let mut img = Image::new(8, 8, PixelFormat::Rgb8);
        for p in img.data.chunks_exact_mut(3) {
            p.copy_from_slice(&[180, 120, 60]);
        }
        let out = run(WHITE_BALANCE, 5, &img);
        let p = &out.data[..3];
        assert!(p.iter().all(|&v| (v as i32 - 120).abs() <= 2), "{p:?}");
        let mild = run(WHITE_BALANCE, 1, &img);
        assert!(
            mild.data[0] < 180 && mild.data[0] > 170,
            "{:?}",
            &mild.data[..3]
        );
    }

    #[test]
    fn clahe_behaves_as_opencv() {
        // A low-contrast ramp: CLAHE spreads its values; higher clip limits spread them more.
        let (w, h) = (64, 64);
        let plane: Vec<u8> = (0..w * h).map(|i| 100 + ((i % w) / 8) as u8).collect();
        let spread = |clip| {
            let o = clahe(&plane, w, h, clip, 8);
            let (mn, mx) = (
                o.iter().min().copied().unwrap(),
                o.iter().max().copied().unwrap(),
            );
            // Along a row the mapping keeps the order of the input values.
            let row = &o[32 * w..33 * w];
            assert!(row.windows(2).all(|p| p[0] <= p[1] + 1), "{row:?}");
            (mx - mn) as i32
        };
        // The 8-value ramp stays 6-7 levels wide (OpenCV gives spreads 6 and 7 for clips 1 and 10):
        // within each tile the ramp has one value per column band, so clipping limits the gain.
        let (s1, s10) = (spread(1.0), spread(10.0));
        assert!((5..=7).contains(&s1) && s10 >= s1, "{s1} {s10}");
        // A random plane is stretched to the full range, as OpenCV does.
        let mut r = crate::rng::Rng::for_setup(4, 4);
        let noise: Vec<u8> = (0..100 * 75).map(|_| 40 + r.below(160) as u8).collect();
        let o = clahe(&noise, 100, 75, 3.0, 8);
        assert!(o.iter().max().unwrap() - o.iter().min().unwrap() > 230);
    }

    #[test]
    fn phase_scrambling_is_the_real_part_of_the_dft_with_random_phases() {
        // The reference's computation, written out as a direct 2-D DFT on a small plane with odd
        // and even sizes: F = DFT(x); out = Re IDFT(F e^(i theta)).
        for (w, h) in [(6usize, 5usize), (7, 4)] {
            let p = PhaseScrambling::new(3, w, h, 0.55);
            let x: Vec<f64> = (0..w * h).map(|i| ((i * 37) % 251) as f64).collect();
            let mut field = vec![0u16; w * h];
            for (kx, col) in field.chunks_exact_mut(h).enumerate() {
                p.column_draws(9, 0, kx, col);
            }
            let theta = |ky: usize, kx: usize| {
                let (c, s) = p.trig[field[kx * h + ky] as usize];
                (s as f64).atan2(c as f64)
            };
            let tau = std::f64::consts::TAU;
            let mut spec = vec![(0f64, 0f64); w * h];
            for ky in 0..h {
                for kx in 0..w {
                    let (mut re, mut im) = (0.0, 0.0);
                    for y in 0..h {
                        for xx in 0..w {
                            let a =
                                -tau * ((ky * y) as f64 / h as f64 + (kx * xx) as f64 / w as f64);
                            re += x[y * w + xx] * a.cos();
                            im += x[y * w + xx] * a.sin();
                        }
                    }
                    let t = theta(ky, kx);
                    spec[ky * w + kx] = (re * t.cos() - im * t.sin(), re * t.sin() + im * t.cos());
                }
            }
            let mut buf = Buffers::default();
            p.forward_rows(1, &mut buf, &|y, line| {
                for (d, v) in line.iter_mut().zip(&x[y * w..(y + 1) * w]) {
                    *d = *v as f32;
                }
            });
            p.scramble_columns(1, &mut buf, 9);
            let mut plane = vec![0f32; w * h];
            let mut work = (Vec::new(), p.plan.c2r.make_scratch_vec());
            for (band, out) in plane.chunks_mut(ROW_BAND * w).enumerate() {
                p.inverse_rows(&buf, 0, band * ROW_BAND, out, &mut work);
            }
            for y in 0..h {
                for xx in 0..w {
                    let mut re = 0.0;
                    for ky in 0..h {
                        for kx in 0..w {
                            let a =
                                tau * ((ky * y) as f64 / h as f64 + (kx * xx) as f64 / w as f64);
                            let (sr, si) = spec[ky * w + kx];
                            re += sr * a.cos() - si * a.sin();
                        }
                    }
                    let want = re / (w * h) as f64;
                    let got = plane[y * w + xx] as f64 / (w * h) as f64;
                    assert!(
                        (want - got).abs() < 1e-2,
                        "{w}x{h} ({xx},{y}): {got} vs {want}"
                    );
                }
            }
        }
    }

    #[test]
    fn phase_scrambling_keeps_the_mean_and_scrambles_more_with_severity() {
        let img = crate::synthetic::street_image(96, 60, 0);
        let mean = |i: &Image| i.data.iter().map(|&v| v as f64).sum::<f64>() / i.data.len() as f64;
        let mad = |o: &Image| {
            o.data
                .iter()
                .zip(&img.data)
                .map(|(a, b)| (*a as f64 - *b as f64).abs())
                .sum::<f64>()
                / o.data.len() as f64
        };
        let mut last = 0.0;
        for s in 1..=5 {
            let p = PHASE_SCRAMBLING(&CameraSetup {
                severity: s,
                seed: 2,
                geometry: img.geometry(),
            })
            .unwrap();
            let mut out = Image::with_geometry(img.geometry());
            p.apply(&img.view(), &mut out.view_mut(), 0);
            // The DC bin is scaled by cos(theta_0), theta_0 in [0, s pi]: the mean can only shrink,
            // and by no more than that factor (clipping at 0 and 255 aside).
            let ratio = mean(&out) / mean(&img);
            let lowest = (PHASE_SCRAMBLE[s as usize - 1] * std::f32::consts::PI).cos() as f64;
            assert!(ratio <= 1.02 && ratio >= lowest - 0.05, "s{s}: {ratio}");
            let d = mad(&out);
            assert!(d > last, "s{s}: {d} <= {last}");
            last = d;
        }
    }

    #[test]
    fn grayscale_top_severity_is_near_neutral() {
        let out = run(GRAYSCALE, 5, &px(200, 40, 90));
        let spread = out.data.iter().max().unwrap() - out.data.iter().min().unwrap();
        assert!(spread <= 24, "{:?}", out.data);
        assert!(run(GRAYSCALE, 1, &px(200, 40, 90)).data[0] > 180);
    }
}
