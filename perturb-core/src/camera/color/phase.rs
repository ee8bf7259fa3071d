//! Phase scrambling (C-F2): the Fourier phase of each channel randomised, the amplitude kept.

use crate::camera::ops::{F32x8, Lanes};
use crate::camera::{CameraBuilder, CameraPerturbation};
use crate::image::{ImageView, ImageViewMut};
use rayon::prelude::*;
use rustfft::num_complex::{Complex, Complex32};

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
/// are built at configuration time, with rustfft's scalar algorithms on every CPU, eight rows or
/// columns at a time (see [`FftPlan`]), and the working buffers (about 8 bytes per pixel per colour
/// channel) are kept from frame to frame. A frame makes three passes over memory: the row
/// transforms, the column transforms (a block of columns is gathered, transformed, scrambled and
/// transformed back while it sits in the cache), and the inverse row transforms, which write the
/// output bytes directly.
pub struct PhaseScrambling {
    seed: u64,
    w: usize,
    h: usize,
    /// The transforms, eight rows or columns at a time (the default).
    lanes: FftPlan<F32x8>,
    /// The transforms one row or column at a time, built at the first frame that asks for the
    /// portable path ([`crate::camera::ops::portable_forced`]): the same bytes.
    single: std::sync::OnceLock<FftPlan<f32>>,
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

/// Lane `l` of a complex value of lanes, as a complex f32.
#[inline(always)]
fn lane_of<V: Lanes>(v: &Complex<V>, l: usize) -> Complex32 {
    Complex32::new(v.re.lane(l), v.im.lane(l))
}

/// Sets lane `l` of a complex value of lanes.
#[inline(always)]
fn set_lane_of<V: Lanes>(v: &mut Complex<V>, l: usize, c: Complex32) {
    v.re.set_lane(l, c.re);
    v.im.set_lane(l, c.im);
}

/// Bits of one quantised phase draw.
const PHASE_BITS: u32 = 12;

/// Columns of the half spectrum transformed together: a block is gathered from the row
/// transforms' tiles, transformed, scrambled and transformed back while it sits in the cache.
const COLUMN_BLOCK: usize = 16;

/// Rows per task of the row transforms.
const ROW_BAND: usize = 16;

/// The transforms of a frame, rustfft's and realfft's scalar algorithms on every CPU, over
/// numbers of `V::N` lanes: `f32` transforms one row or column at a time, [`F32x8`] eight at a
/// time with every operation eight-wide and each lane the f32 bits (`camera/ops/lanes.rs`). Both
/// give the same bytes on x86-64 with and without AVX2 and on aarch64.
///
/// rustfft's planner, with the crate's default features, picks AVX, SSE or NEON algorithms at run
/// time. They sum in other orders than the scalar ones, and NEON's fuse multiplies and adds (on a
/// 1920x1208 frame 97-99.7 % of the bins differed in their last bits before rounding, enough to
/// move output bytes), so this crate turns those features off (`Cargo.toml`) and plans with
/// `FftPlannerScalar`; realfft's planner builds its inner transform with rustfft's `FftPlanner`,
/// which without the features has the scalar algorithms only (a test checks it plans what
/// `FftPlannerScalar` plans). The scalar algorithms' arithmetic is plain Rust, which rustc never
/// fuses or reorders; their twiddle factors are the C library's `cos` and `sin` in f64 rounded
/// to f32, where libraries that differ by an ulp give the same f32 unless the exact value lies
/// within an ulp of a rounding boundary of f32, about one twiddle in 10^8 (a test checks every
/// twiddle of the common frame sizes is far from one). Eight at a time, a frame took 0.45x the
/// time of one at a time at 1920x1208 and 0.48x at 800x503 on this project's x86-64 VM
/// (docs/performance.md, "aarch64").
struct FftPlan<V: Lanes> {
    r2c: std::sync::Arc<dyn realfft::RealToComplex<V>>,
    c2r: std::sync::Arc<dyn realfft::ComplexToReal<V>>,
    col_fwd: std::sync::Arc<dyn rustfft::Fft<V>>,
    col_inv: std::sync::Arc<dyn rustfft::Fft<V>>,
}

impl<V: Lanes> FftPlan<V> {
    fn new(w: usize, h: usize) -> Self {
        let mut real = realfft::RealFftPlanner::<V>::new();
        let mut cplx = rustfft::FftPlannerScalar::<V>::new();
        FftPlan {
            r2c: real.plan_fft_forward(w),
            c2r: real.plan_fft_inverse(w),
            col_fwd: cplx.plan_fft_forward(h),
            col_inv: cplx.plan_fft_inverse(h),
        }
    }
}

/// Working space of the inverse row transforms of one task: `V::N` half-spectrum rows, the
/// scratch, and the output rows.
type InverseWork<V> = (Vec<Complex<V>>, Vec<Complex<V>>, Vec<V>);

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
        let amp = s as f64 * std::f64::consts::PI;
        let levels = 1usize << PHASE_BITS;
        PhaseScrambling {
            seed,
            w,
            h,
            lanes: FftPlan::new(w, h),
            single: std::sync::OnceLock::new(),
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

    /// The one-at-a-time transforms, planned at their first use.
    fn single(&self) -> &FftPlan<f32> {
        self.single.get_or_init(|| FftPlan::new(self.w, self.h))
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
        let (w, h) = (self.w, self.h);
        let nt = (w / 2 + 1).div_ceil(COLUMN_BLOCK);
        let nb = h.div_ceil(ROW_BAND);
        (nt, nb, nb * ROW_BAND)
    }

    /// Real FFT of every row of `nc` channels into `buf.rows`, `V::N` rows at a time; `load(y,
    /// lines)` writes row `y` of each channel into `lines` (`nc` lines of `w` after one another).
    /// Bands of rows run on the worker threads.
    fn forward_rows<V: Lanes>(
        &self,
        plan: &FftPlan<V>,
        nc: usize,
        buf: &mut Buffers,
        load: &(dyn Fn(usize, &mut [f32]) + Sync),
    ) {
        let (w, h) = (self.w, self.h);
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
                    (
                        vec![0f32; nc * w],
                        vec![V::zero(); nc * w],
                        plan.r2c.make_output_vec(),
                        plan.r2c.make_scratch_vec(),
                    )
                },
                |(lines, input, spec, scratch), (i, band)| {
                    let y0 = i * r;
                    let rows = r.min(h - y0);
                    for g in (0..rows).step_by(V::N) {
                        let n = V::N.min(rows - g);
                        for l in 0..V::N {
                            if l < n {
                                load(y0 + g + l, lines);
                            } else {
                                lines.fill(0.0);
                            }
                            for (d, &v) in input.iter_mut().zip(lines.iter()) {
                                d.set_lane(l, v);
                            }
                        }
                        for (line, tiles) in input
                            .chunks_exact_mut(w)
                            .zip(band.chunks_exact_mut(nt * r * t))
                        {
                            plan.r2c
                                .process_with_scratch(line, spec, scratch)
                                .expect("sizes match the plan");
                            for (tile, part) in tiles.chunks_exact_mut(r * t).zip(spec.chunks(t)) {
                                for l in 0..n {
                                    let row = &mut tile[(g + l) * t..][..part.len()];
                                    for (d, v) in row.iter_mut().zip(part) {
                                        *d = lane_of(v, l);
                                    }
                                }
                            }
                        }
                    }
                },
            );
    }

    /// Column transforms of `nc` channels, one tile of [`COLUMN_BLOCK`] columns at a time, `V::N`
    /// columns per transform: gather the tile from `buf.rows` into blocks of columns, FFT them,
    /// multiply by the scrambling multiplier, inverse FFT, and store them row by row into the
    /// tile of `buf.cols`. The blocks stay in the cache through all of it.
    ///
    /// The multiplier of bin (ky, kx) is `M = (e^(i theta(ky, kx)) + e^(-i theta(-ky, -kx))) /
    /// 2`; the partner bin lies in column `-kx` of the full spectrum, read backwards from ky = 1.
    fn scramble_columns<V: Lanes>(
        &self,
        plan: &FftPlan<V>,
        nc: usize,
        buf: &mut Buffers,
        seq: u64,
    ) {
        let (w, h) = (self.w, self.h);
        let wh = w / 2 + 1;
        let (nt, _, hp) = self.tiling();
        let (t, r) = (COLUMN_BLOCK, ROW_BAND);
        let groups = t.div_ceil(V::N);
        let len = plan
            .col_fwd
            .get_inplace_scratch_len()
            .max(plan.col_inv.get_inplace_scratch_len());
        let m = |a: u16, b: u16| {
            let mask = |q: u16| (q & 0xFFF) as usize;
            let (a, b) = (self.trig[mask(a)], self.trig[mask(b)]);
            Complex32::new((a.0 + b.0) * 0.5, (a.1 - b.1) * 0.5)
        };
        let zero = Complex::new(V::zero(), V::zero());
        let Buffers { rows, cols } = buf;
        let rows: &[Complex32] = rows;
        cols.par_chunks_mut(hp * t).enumerate().for_each_init(
            || {
                (
                    vec![zero; groups * h],
                    vec![zero; len],
                    vec![0u16; h],
                    vec![0u16; h],
                )
            },
            |(blocks, scratch, here, there), (i, tile)| {
                let (k, b) = (i / nt, i % nt);
                let x0 = b * t;
                let n = t.min(wh - x0);
                let blocks = &mut blocks[..n.div_ceil(V::N) * h];
                blocks.fill(zero);
                for (band, src) in rows.chunks_exact(nc * nt * r * t).enumerate() {
                    let src = &src[i * r * t..(i + 1) * r * t];
                    for (j, row) in src.chunks_exact(t).enumerate().take(h - band * r) {
                        for (c, v) in row[..n].iter().enumerate() {
                            set_lane_of(&mut blocks[c / V::N * h + band * r + j], c % V::N, *v);
                        }
                    }
                }
                plan.col_fwd.process_with_scratch(blocks, scratch);
                for c in 0..n {
                    let (block, l) = (&mut blocks[c / V::N * h..][..h], c % V::N);
                    let kx = x0 + c;
                    self.column_draws(seq, k, kx, here);
                    self.column_draws(seq, k, (w - kx) % w, there);
                    let scale = |v: &mut Complex<V>, a: u16, b: u16| {
                        let mut x = lane_of(v, l);
                        x *= m(a, b);
                        set_lane_of(v, l, x);
                    };
                    scale(&mut block[0], here[0], there[0]);
                    for ((v, &a), &b) in block[1..]
                        .iter_mut()
                        .zip(&here[1..])
                        .zip(there[1..].iter().rev())
                    {
                        scale(v, a, b);
                    }
                }
                plan.col_inv.process_with_scratch(blocks, scratch);
                for (y, row) in tile.chunks_exact_mut(t).take(h).enumerate() {
                    for (c, v) in row[..n].iter_mut().enumerate() {
                        *v = lane_of(&blocks[c / V::N * h + y], c % V::N);
                    }
                }
            },
        );
    }

    /// Inverse real FFT of rows `y0 .. y0 + out.len() / w` (at most one band, `y0` a multiple of
    /// [`ROW_BAND`]) of channel `k`'s scrambled spectrum into `out`, `V::N` rows at a time, not
    /// normalised (scaled by `w h`).
    fn inverse_rows<V: Lanes>(
        &self,
        plan: &FftPlan<V>,
        buf: &Buffers,
        k: usize,
        y0: usize,
        out: &mut [f32],
        (line, scratch, back): &mut InverseWork<V>,
    ) {
        let w = self.w;
        let wh = w / 2 + 1;
        let (nt, _, hp) = self.tiling();
        let t = COLUMN_BLOCK;
        line.resize(wh, Complex::new(V::zero(), V::zero()));
        back.resize(w, V::zero());
        for (g, out) in out.chunks_mut(V::N * w).enumerate() {
            let n = out.len() / w;
            let tiles = buf.cols.chunks_exact(hp * t).skip(k * nt).take(nt);
            for (tile, x0) in tiles.zip((0..wh).step_by(t)) {
                let cols = t.min(wh - x0);
                for l in 0..V::N {
                    let dst = &mut line[x0..x0 + cols];
                    if l < n {
                        let src = &tile[(y0 + g * V::N + l) * t..][..cols];
                        for (d, v) in dst.iter_mut().zip(src) {
                            set_lane_of(d, l, *v);
                        }
                    } else {
                        // Lanes past the band's last row transform zeros, never read.
                        for d in dst {
                            set_lane_of(d, l, Complex32::new(0.0, 0.0));
                        }
                    }
                }
            }
            // The DC and Nyquist bins of a real signal's rows must be real for the inverse.
            line[0].im = V::zero();
            if w.is_multiple_of(2) {
                line[wh - 1].im = V::zero();
            }
            plan.c2r
                .process_with_scratch(line, back, scratch)
                .expect("sizes match the plan");
            for (l, out) in out.chunks_exact_mut(w).enumerate() {
                for (d, v) in out.iter_mut().zip(back.iter()) {
                    *d = v.lane(l);
                }
            }
        }
    }

    /// The frame through the transforms of `plan`.
    fn run<V: Lanes>(
        &self,
        plan: &FftPlan<V>,
        input: &ImageView<'_>,
        output: &mut ImageViewMut<'_>,
        seq: u64,
    ) {
        let w = input.width as usize;
        let format = input.format;
        let nc = format.color_channels();
        let mut buf = {
            let mut spare = self.spare.lock().unwrap_or_else(|e| e.into_inner());
            spare.pop().unwrap_or_default()
        };
        // Colour channels are read and written in one pass over each row (three strided passes
        // cost more than the row transforms).
        self.forward_rows(plan, nc, &mut buf, &|y, lines| {
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
        self.scramble_columns(plan, nc, &mut buf, seq);
        let norm = 1.0 / (w * self.h) as f32;
        let byte = |v: f32| crate::camera::ops::byte(v * norm + 0.5);
        let mut rows = output.rows_mut();
        rows.par_chunks_mut(ROW_BAND).enumerate().for_each_init(
            || {
                let work = (Vec::new(), plan.c2r.make_scratch_vec(), Vec::new());
                (vec![0f32; nc * ROW_BAND * w], vec![0u8; nc * w], work)
            },
            |(planes, bytes, work), (i, band)| {
                let (y0, n) = (i * ROW_BAND, band.len());
                for (k, plane) in planes.chunks_exact_mut(ROW_BAND * w).enumerate() {
                    self.inverse_rows(plan, &buf, k, y0, &mut plane[..n * w], work);
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

impl CameraPerturbation for PhaseScrambling {
    fn apply(&self, input: &ImageView<'_>, output: &mut ImageViewMut<'_>, seq: u64) {
        if crate::camera::ops::portable_forced() {
            self.run(self.single(), input, output, seq);
        } else {
            self.run(&self.lanes, input, output, seq);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The three passes over one grey plane `x` (`p`'s size) with the transforms of `plan`: the
    /// scrambled plane, not normalised.
    fn scrambled_plane<V: Lanes>(
        p: &PhaseScrambling,
        plan: &FftPlan<V>,
        x: &[f64],
        seq: u64,
    ) -> Vec<f32> {
        let w = p.w;
        let mut buf = Buffers::default();
        p.forward_rows(plan, 1, &mut buf, &|y, line| {
            for (d, v) in line.iter_mut().zip(&x[y * w..(y + 1) * w]) {
                *d = *v as f32;
            }
        });
        p.scramble_columns(plan, 1, &mut buf, seq);
        let mut plane = vec![0f32; w * p.h];
        let mut work = (Vec::new(), plan.c2r.make_scratch_vec(), Vec::new());
        for (band, out) in plane.chunks_mut(ROW_BAND * w).enumerate() {
            p.inverse_rows(plan, &buf, 0, band * ROW_BAND, out, &mut work);
        }
        plane
    }

    /// The transforms eight at a time (the default) and one at a time (the portable path) give
    /// the same bytes, on odd sizes (partial groups of lanes in rows and columns, partial tiles
    /// and bands) in every channel layout.
    #[test]
    fn eight_at_a_time_and_one_at_a_time_give_the_same_bytes() {
        use crate::image::{Image, PixelFormat};
        for (w, h, format) in [
            (7u32, 5u32, PixelFormat::Rgb8),
            (61, 17, PixelFormat::Bgr8),
            (203, 61, PixelFormat::Rgb8),
            (67, 29, PixelFormat::Bgra8),
            (45, 17, PixelFormat::Mono8),
            (1, 1, PixelFormat::Rgb8),
        ] {
            let mut img = Image::new(w, h, format);
            for (i, v) in img.data.iter_mut().enumerate() {
                *v = ((i * 97 + i / 7) % 253) as u8;
            }
            let p = PhaseScrambling::new(5, w as usize, h as usize, 0.38);
            let [lanes, single] = [0, 1].map(|k| {
                let mut out = Image::with_geometry(img.geometry());
                if k == 0 {
                    p.run(&p.lanes, &img.view(), &mut out.view_mut(), 3);
                } else {
                    p.run(p.single(), &img.view(), &mut out.view_mut(), 3);
                }
                out.data
            });
            assert_eq!(lanes, single, "{w}x{h} {format}");
        }
    }

    /// The process-wide switch (`force_baseline`, as `PERTURB_PORTABLE=1`) reaches the
    /// transforms: with it a frame goes through the one-at-a-time plan, without it through the
    /// eight-wide one, with the same bytes.
    #[test]
    fn the_portable_switch_picks_one_at_a_time_with_the_same_bytes() {
        use crate::camera::ops::force_baseline;
        use crate::image::{Image, PixelFormat};
        let _dispatch = crate::camera::ops::dispatch_lock();
        let mut img = Image::new(151, 37, PixelFormat::Rgb8);
        for (i, v) in img.data.iter_mut().enumerate() {
            *v = ((i * 31 + i / 11) % 251) as u8;
        }
        let p = PhaseScrambling::new(8, 151, 37, 0.26);
        let frame = |portable: bool| {
            force_baseline(portable);
            let mut out = Image::with_geometry(img.geometry());
            p.apply(&img.view(), &mut out.view_mut(), 4);
            force_baseline(false);
            out.data
        };
        let default = frame(false);
        // (Under PERTURB_PORTABLE=1 both frames take the portable path.)
        let env = crate::camera::ops::portable_from_env();
        assert!(
            env || p.single.get().is_none(),
            "the default path planned one at a time"
        );
        let portable = frame(true);
        assert!(
            p.single.get().is_some(),
            "the switch did not reach the transforms"
        );
        assert_eq!(default, portable);
    }

    #[test]
    fn phase_scrambling_is_the_real_part_of_the_dft_with_random_phases() {
        // The reference's computation, written out as a direct 2-D DFT on a small plane with odd
        // and even sizes: F = DFT(x); out = Re IDFT(F e^(i theta)).
        // 19 rows: two bands, the second with a partial group of lanes.
        for (w, h) in [(6usize, 5usize), (7, 4), (5, 19)] {
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
            let planes = [
                scrambled_plane(&p, &p.lanes, &x, 9),
                scrambled_plane(&p, p.single(), &x, 9),
            ];
            assert_eq!(
                planes[0], planes[1],
                "{w}x{h}: eight at a time and one at a time"
            );
            let plane = &planes[0];
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
