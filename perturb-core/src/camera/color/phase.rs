//! Phase scrambling (C-F2): the Fourier phase of each channel randomised, the amplitude kept.

use crate::camera::{CameraBuilder, CameraPerturbation};
use crate::image::{ImageView, ImageViewMut};
use rayon::prelude::*;
use rustfft::num_complex::Complex32;

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
/// are built at configuration time, with rustfft's scalar algorithms on every CPU (see
/// [`FftPlan`]), and the working buffers (about 8 bytes per pixel per colour
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

/// The transforms of a frame, rustfft's scalar algorithms on every CPU: the same bytes on x86-64
/// with and without AVX2 and on aarch64.
///
/// rustfft's planner, with the crate's default features, picks AVX, SSE or NEON algorithms at run
/// time. They sum in other orders than the scalar ones (on a 1920x1208 frame 97-99.7 % of the
/// bins differed in their last bits before rounding, enough to move output bytes), so this crate
/// turns those features off (`Cargo.toml`) and plans the column transforms with
/// `FftPlannerScalar`; realfft's planner builds its inner transform with rustfft's `FftPlanner`,
/// which without the features has the scalar algorithms only (a test checks it plans what
/// `FftPlannerScalar` plans). The scalar algorithms' arithmetic is plain Rust, which rustc never
/// fuses or reorders; their twiddle factors are the C library's `cos` and `sin` in f64 rounded
/// to f32, where libraries that differ by an ulp give the same f32 unless the exact value lies
/// within an ulp of a rounding boundary of f32, about one twiddle in 10^8 (a test checks every
/// twiddle of the common frame sizes is far from one). Against the SIMD planner on this
/// project's x86-64 VM, a 1920x1208 frame costs about a third more time (docs/performance.md).
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
        let mut cplx = rustfft::FftPlannerScalar::<f32>::new();
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
                    (crate::math::cos(t) as f32, crate::math::sin(t) as f32)
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
        let mut rng =
            crate::camera::ops::row_rng(self.seed, seq, 0xF2 + ((channel as u64) << 32), kx);
        // The top PHASE_BITS of each 16-bit draw.
        crate::camera::ops::fill_quarters(&mut rng, out, |q| q >> (16 - PHASE_BITS));
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
                crate::camera::ops::split_rgb(src, format, [l0, l1, l2]);
            } else {
                for (d, &v) in lines.iter_mut().zip(src) {
                    *d = v as f32;
                }
            }
        });
        self.scramble_columns(nc, &mut buf, seq);
        let norm = 1.0 / (w * self.plan.h) as f32;
        let byte = |v: f32| crate::camera::ops::byte(v * norm + 0.5);
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
                        crate::camera::ops::merge_rgb(format, [b0, b1, b2], dst);
                    } else {
                        dst.copy_from_slice(bytes);
                    }
                    crate::camera::ops::copy_alpha(format, input.row(y0 + r), dst);
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

    /// Frame sides the twiddle test covers: the common camera sizes (1920x1208 and 2064x1544
    /// automotive, 1920x1080, 1280x720, 1242x375 and the other KITTI widths, 800x503, 640x480)
    /// and the sizes of the output-hash test.
    const SIDES: [usize; 30] = [
        1920, 1208, 1080, 1280, 720, 2064, 1544, 1242, 375, 1224, 370, 1238, 374, 1241, 376, 800,
        503, 640, 480, 3840, 2160, 641, 403, 203, 61, 67, 29, 45, 17, 401,
    ];

    /// The transform lengths whose twiddles rustfft (scalar planner) and realfft may compute for
    /// a transform of length `n`, and more: every divisor (mixed radix, butterflies), `p - 1` for
    /// every prime factor (Rader's inner transform), `2 p` and the power of two above it
    /// (Bluestein's), recursively.
    fn twiddle_lengths(n: usize, out: &mut std::collections::BTreeSet<usize>) {
        if n == 0 || !out.insert(n) {
            return;
        }
        for d in (1..n).filter(|d| n.is_multiple_of(*d)) {
            twiddle_lengths(d, out);
        }
        let primes = (2..=n).filter(|p| n.is_multiple_of(*p) && (2..*p).all(|q| p % q != 0));
        for p in primes.filter(|&p| p > 2) {
            twiddle_lengths(p - 1, out);
            twiddle_lengths(2 * p, out);
            twiddle_lengths((2 * p - 1).next_power_of_two(), out);
        }
    }

    /// Every twiddle factor rustfft and realfft compute for the lengths of [`SIDES`] (`cos` and
    /// `sin` of `-2 pi i / n` in f64, rounded to f32) is the same f32 for any f64 within 2 ulp of
    /// `libm`'s: so the C library of any machine (within an ulp of the exact value, as glibc's and
    /// musl's are) gives these transforms the same twiddles, and the scalar algorithms the same
    /// bytes.
    #[test]
    fn twiddles_of_common_frame_sizes_round_alike_in_every_c_library() {
        let mut lengths = std::collections::BTreeSet::new();
        for n in SIDES {
            twiddle_lengths(n, &mut lengths);
            twiddle_lengths(n / 2, &mut lengths);
        }
        let mut checked = 0usize;
        for &n in &lengths {
            let constant = -2f64 * std::f64::consts::PI / n as f64;
            for i in 0..n {
                let angle = constant * i as f64;
                for v in [crate::math::cos(angle), crate::math::sin(angle)] {
                    let lo = v.next_down().next_down() as f32;
                    let hi = v.next_up().next_up() as f32;
                    assert!(
                        lo == hi,
                        "twiddle {i} of {n}: {v:e} lies near an f32 boundary"
                    );
                    checked += 1;
                }
            }
        }
        assert!(checked > 100_000, "{checked} twiddles");
    }

    /// The planner realfft builds its transforms with (rustfft's `FftPlanner`) plans what
    /// `FftPlannerScalar` plans, bit for bit on odd and prime lengths: a SIMD feature of rustfft
    /// switched back on (by this crate or any other in the build) fails here on a CPU that has
    /// the SIMD instructions.
    #[test]
    fn default_planner_gives_the_scalar_planners_bytes() {
        for n in [5usize, 17, 61, 97, 151, 203, 375, 401, 1208, 1242] {
            let x: Vec<Complex32> = (0..n)
                .map(|i| Complex32::new(((i * 37) % 251) as f32, ((i * 11) % 7) as f32 - 3.0))
                .collect();
            let mut auto = rustfft::FftPlanner::<f32>::new();
            let mut scalar = rustfft::FftPlannerScalar::<f32>::new();
            for direction in [
                rustfft::FftDirection::Forward,
                rustfft::FftDirection::Inverse,
            ] {
                let [a, b] =
                    [auto.plan_fft(n, direction), scalar.plan_fft(n, direction)].map(|plan| {
                        let mut v = x.clone();
                        plan.process(&mut v);
                        v.iter()
                            .flat_map(|c| [c.re.to_bits(), c.im.to_bits()])
                            .collect::<Vec<_>>()
                    });
                assert_eq!(a, b, "length {n}, {direction:?}");
            }
        }
    }
}
