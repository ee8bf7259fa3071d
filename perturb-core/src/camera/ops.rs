//! Building blocks shared by the camera perturbations: row-parallel iteration with deterministic
//! per-row random streams, per-channel lookup tables, Gaussian kernels and separable convolution.

use crate::image::{ImageView, ImageViewMut, PixelFormat};
use crate::rng::Rng;
use rayon::prelude::*;

/// Rows handed to one rayon task; large enough that scheduling is negligible.
const ROWS_PER_TASK: usize = 8;

/// Calls `f(y, input_row, output_row)` for every row, in parallel on the current rayon pool.
pub fn par_rows<F>(input: &ImageView<'_>, output: &mut ImageViewMut<'_>, f: F)
where
    F: Fn(usize, &[u8], &mut [u8]) + Send + Sync,
{
    let rows = output.rows_mut();
    rows.into_par_iter()
        .with_min_len(ROWS_PER_TASK)
        .enumerate()
        .for_each(|(y, out)| f(y, input.row(y), out));
}

/// [`par_rows`] with per-worker state: `init()` makes a worker's state (row buffers), which
/// `f(state, y, input_row, output_row)` reuses from row to row.
pub fn par_rows_with<T, I, F>(input: &ImageView<'_>, output: &mut ImageViewMut<'_>, init: I, f: F)
where
    I: Fn() -> T + Send + Sync,
    F: Fn(&mut T, usize, &[u8], &mut [u8]) + Send + Sync,
{
    let rows = output.rows_mut();
    rows.into_par_iter()
        .with_min_len(ROWS_PER_TASK)
        .enumerate()
        .for_each_init(init, |state, (y, out)| f(state, y, input.row(y), out));
}

/// Whether the functions defined with `wide_fn!` run their AVX2 copy: on x86-64 CPUs that have
/// AVX2, FMA, BMI1, BMI2 and LZCNT (the x86-64-v3 level, every x86-64 CPU since about 2015),
/// unless [`force_baseline`] is on. The check is a few cached loads.
#[inline]
pub fn wide_available() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        !BASELINE_ONLY.load(std::sync::atomic::Ordering::Relaxed)
            && std::arch::is_x86_feature_detected!("avx2")
            && std::arch::is_x86_feature_detected!("fma")
            && std::arch::is_x86_feature_detected!("bmi1")
            && std::arch::is_x86_feature_detected!("bmi2")
            && std::arch::is_x86_feature_detected!("lzcnt")
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}

/// When set, [`wide_available`] is false.
static BASELINE_ONLY: std::sync::atomic::AtomicBool = std::sync::atomic::AtomicBool::new(false);

/// Makes the `wide_fn!` functions run their baseline copy only (`true`) or the widest the CPU
/// has (`false`, the default), on every thread: for tests and benchmarks that compare the two.
pub fn force_baseline(on: bool) {
    BASELINE_ONLY.store(on, std::sync::atomic::Ordering::Relaxed);
}

/// Defines a function whose body is compiled twice, for the build's baseline target and for
/// AVX2 (with FMA, BMI1, BMI2 and LZCNT), and runs the copy this CPU can run
/// ([`wide_available`]). The AVX2 copy's inner loops work on eight floats or 32-bit integers at a
/// time instead of four (the baseline, `x86-64-v2`, has 128-bit vectors only). Both copies compute
/// the same values: Rust never fuses a multiply and an add by itself or reorders float
/// arithmetic, so wider instructions change only how many lanes run at once; a test compares the
/// two paths on every camera perturbation. Calling the AVX2 copy is the crate's one `unsafe`
/// operation, sound because the features are checked first.
///
/// Meant for kernels that run per row or per band (the check is a few cached loads per call).
/// Functions the body calls get the wider code only where they are inlined into it. Closures in
/// the body are compiled for AVX2 too, so library code that calls them without being inlined
/// (`collect`, `for_each` on long adapter chains) cannot inline them back and calls them once
/// per element: write such loops as `for` loops over slices. Const generic parameters are
/// supported, type parameters are not.
macro_rules! wide_fn {
    (
        $(#[$meta:meta])*
        $vis:vis fn $name:ident $(<$(const $cg:ident: $ct:ty),+>)?
            ($($arg:ident: $ty:ty),* $(,)?) $(-> $ret:ty)? $body:block
    ) => {
        $(#[$meta])*
        $vis fn $name $(<$(const $cg: $ct),+>)? ($($arg: $ty),*) $(-> $ret)? {
            #[cfg(target_arch = "x86_64")]
            #[target_feature(enable = "avx2,fma,bmi1,bmi2,lzcnt")]
            fn wide $(<$(const $cg: $ct),+>)? ($($arg: $ty),*) $(-> $ret)? $body
            #[inline(always)]
            fn base $(<$(const $cg: $ct),+>)? ($($arg: $ty),*) $(-> $ret)? $body
            #[cfg(target_arch = "x86_64")]
            if $crate::camera::ops::wide_available() {
                // SAFETY: the CPU has every feature the copy is compiled for (`wide_available`
                // checked), which is all such a function needs.
                return unsafe { wide $(::<$($cg),+>)? ($($arg),*) };
            }
            base $(::<$($cg),+>)? ($($arg),*)
        }
    };
}
pub(crate) use wide_fn;

/// A random stream for row `y` of frame `seq`: independent per row, so rows can run in any order
/// on any thread and give the same bytes.
#[inline]
pub fn row_rng(seed: u64, seq: u64, salt: u64, y: usize) -> Rng {
    Rng::from_key(crate::rng::hash(&[seed, seq, salt, y as u64]))
}

/// Fills `out` with `f` of successive 16-bit draws from `rng`, four per 64-bit output, low
/// quarter first (a fixed block of four per output, which the compiler keeps in registers).
#[inline]
pub fn fill_quarters<T: Copy>(rng: &mut Rng, out: &mut [T], f: impl Fn(u16) -> T) {
    let quarters = |bits: u64| [0, 1, 2, 3].map(|i| f((bits >> (16 * i)) as u16));
    let mut quads = out.chunks_exact_mut(4);
    for quad in &mut quads {
        quad.copy_from_slice(&quarters(rng.next_u64()));
    }
    let rest = quads.into_remainder();
    if !rest.is_empty() {
        let n = rest.len();
        rest.copy_from_slice(&quarters(rng.next_u64())[..n]);
    }
}

/// Copies the alpha byte of every pixel of `src` into `dst` (no-op for formats without alpha).
#[inline]
pub fn copy_alpha(format: PixelFormat, src: &[u8], dst: &mut [u8]) {
    if let Some(a) = format.alpha_offset() {
        let c = format.channels();
        for (s, d) in src.chunks_exact(c).zip(dst.chunks_exact_mut(c)) {
            d[a] = s[a];
        }
    }
}

/// Row `src` (`c` samples per pixel) padded by `r` pixels at each end with reflect-101 borders,
/// converted sample by sample with `f`, into `dst` (`(w + 2 r) c` long): the middle in one
/// pass, only the `2 r` end pixels through [`reflect101`].
pub fn pad_row<S: Copy, T>(src: &[S], c: usize, r: usize, dst: &mut [T], f: impl Fn(S) -> T) {
    let w = src.len() / c;
    for (d, s) in dst[r * c..(r + w) * c].iter_mut().zip(src) {
        *d = f(*s);
    }
    for px in (0..r).chain(r + w..w + 2 * r) {
        let sx = reflect101(px as i64 - r as i64, w);
        for (d, s) in dst[px * c..px * c + c]
            .iter_mut()
            .zip(&src[sx * c..sx * c + c])
        {
            *d = f(*s);
        }
    }
}

/// [`pad_row`] without a conversion: the middle is one `copy_from_slice`.
pub fn pad_row_copy<T: Copy>(src: &[T], c: usize, r: usize, dst: &mut [T]) {
    let w = src.len() / c;
    dst[r * c..(r + w) * c].copy_from_slice(src);
    for px in (0..r).chain(r + w..w + 2 * r) {
        let sx = reflect101(px as i64 - r as i64, w);
        dst[px * c..px * c + c].copy_from_slice(&src[sx * c..sx * c + c]);
    }
}

/// Splits a row of colour pixels of `format` into three planes of floats, red, green and blue
/// (mono8: the grey value in all three). Each format gets its own loop with the channel positions
/// known at compile time, which lets the compiler vectorise it.
#[inline(always)]
pub fn split_rgb(src: &[u8], format: PixelFormat, [r, g, b]: [&mut [f32]; 3]) {
    fn each<const C: usize, const R: usize, const G: usize, const B: usize>(
        src: &[u8],
        [r, g, b]: [&mut [f32]; 3],
    ) {
        let planes = r.iter_mut().zip(g.iter_mut()).zip(b.iter_mut());
        for (((r, g), b), p) in planes.zip(src.chunks_exact(C)) {
            (*r, *g, *b) = (p[R] as f32, p[G] as f32, p[B] as f32);
        }
    }
    match format {
        PixelFormat::Rgb8 => each::<3, 0, 1, 2>(src, [r, g, b]),
        PixelFormat::Bgr8 => each::<3, 2, 1, 0>(src, [r, g, b]),
        PixelFormat::Rgba8 => each::<4, 0, 1, 2>(src, [r, g, b]),
        PixelFormat::Bgra8 => each::<4, 2, 1, 0>(src, [r, g, b]),
        PixelFormat::Mono8 => each::<1, 0, 0, 0>(src, [r, g, b]),
    }
}

/// [`split_rgb`] into planes of bytes.
#[inline(always)]
pub fn split_rgb_bytes(src: &[u8], format: PixelFormat, [r, g, b]: [&mut [u8]; 3]) {
    fn each<const C: usize, const R: usize, const G: usize, const B: usize>(
        src: &[u8],
        [r, g, b]: [&mut [u8]; 3],
    ) {
        let planes = r.iter_mut().zip(g.iter_mut()).zip(b.iter_mut());
        for (((r, g), b), p) in planes.zip(src.chunks_exact(C)) {
            (*r, *g, *b) = (p[R], p[G], p[B]);
        }
    }
    match format {
        PixelFormat::Rgb8 => each::<3, 0, 1, 2>(src, [r, g, b]),
        PixelFormat::Bgr8 => each::<3, 2, 1, 0>(src, [r, g, b]),
        PixelFormat::Rgba8 => each::<4, 0, 1, 2>(src, [r, g, b]),
        PixelFormat::Bgra8 => each::<4, 2, 1, 0>(src, [r, g, b]),
        PixelFormat::Mono8 => each::<1, 0, 0, 0>(src, [r, g, b]),
    }
}

/// Writes three planes of bytes, red, green and blue, into the colour channels of a row of
/// `format` pixels; alpha is left as it is. Mono8 takes the red plane. The counterpart of
/// [`split_rgb`].
#[inline(always)]
pub fn merge_rgb(format: PixelFormat, [r, g, b]: [&[u8]; 3], dst: &mut [u8]) {
    fn each<const C: usize, const R: usize, const G: usize, const B: usize>(
        [r, g, b]: [&[u8]; 3],
        dst: &mut [u8],
    ) {
        let planes = r.iter().zip(g).zip(b);
        for (((&r, &g), &b), p) in planes.zip(dst.chunks_exact_mut(C)) {
            (p[R], p[G], p[B]) = (r, g, b);
        }
    }
    match format {
        PixelFormat::Rgb8 => each::<3, 0, 1, 2>([r, g, b], dst),
        PixelFormat::Bgr8 => each::<3, 2, 1, 0>([r, g, b], dst),
        PixelFormat::Rgba8 => each::<4, 0, 1, 2>([r, g, b], dst),
        PixelFormat::Bgra8 => each::<4, 2, 1, 0>([r, g, b], dst),
        PixelFormat::Mono8 => {
            let n = dst.len().min(r.len());
            dst[..n].copy_from_slice(&r[..n]);
        }
    }
}

/// Applies a 256-entry lookup table to every colour byte; alpha is copied.
pub fn apply_lut(input: &ImageView<'_>, output: &mut ImageViewMut<'_>, lut: &[u8; 256]) {
    let format = input.format;
    par_rows(input, output, |_, src, dst| {
        for (s, d) in src.iter().zip(dst.iter_mut()) {
            *d = lut[*s as usize];
        }
        copy_alpha(format, src, dst);
    });
}

/// OpenCV's default sigma for a k x k Gaussian: 0.3((k-1)/2 - 1) + 0.8.
pub fn opencv_sigma(k: usize) -> f64 {
    0.3 * ((k as f64 - 1.0) * 0.5 - 1.0) + 0.8
}

/// A normalised 1-D Gaussian kernel of odd size `k` and standard deviation `sigma`.
pub fn gaussian_kernel(k: usize, sigma: f64) -> Vec<f32> {
    let r = (k / 2) as i64;
    let w: Vec<f64> = (-r..=r)
        .map(|i| (-(i * i) as f64 / (2.0 * sigma * sigma)).exp())
        .collect();
    let s: f64 = w.iter().sum();
    w.iter().map(|v| (v / s) as f32).collect()
}

/// Reflect-101 border index (OpenCV's default): ... 2 1 | 0 1 2 ... n-1 | n-2 ...
#[inline]
pub fn reflect101(i: i64, n: usize) -> usize {
    // The common case first: no division.
    if i >= 0 && (i as usize) < n {
        return i as usize;
    }
    if n == 1 {
        return 0;
    }
    let n = n as i64;
    let period = 2 * (n - 1);
    let mut m = i.rem_euclid(period);
    if m >= n {
        m = period - m;
    }
    m as usize
}

/// Separable convolution of every colour channel with the same symmetric 1-D `kernel` horizontally
/// and vertically, reflect-101 borders, rounding to u8; alpha is copied. The vertical pass runs over
/// horizontally filtered f32 rows kept in a ring per task, so memory stays O(k x row).
pub fn separable_filter(input: &ImageView<'_>, output: &mut ImageViewMut<'_>, kernel: &[f32]) {
    let (w, h) = (input.width as usize, input.height as usize);
    let c = input.format.channels();
    let r = kernel.len() / 2;
    let format = input.format;
    let row_len = w * c;
    // Horizontal pass of one input row into `dst` (f32, interleaved).
    let hpass = |y: usize, dst: &mut [f32]| {
        let src = input.row(y);
        if w <= 2 * r + 1 || w < 4 {
            for x in 0..w {
                for ch in 0..c {
                    let mut acc = 0.0f32;
                    for (t, &kw) in kernel.iter().enumerate() {
                        let sx = reflect101(x as i64 + t as i64 - r as i64, w);
                        acc += kw * src[sx * c + ch] as f32;
                    }
                    dst[x * c + ch] = acc;
                }
            }
            return;
        }
        // Pad the row once, then a sum of shifted copies (one vector op per tap).
        let mut padded = vec![0f32; (w + 2 * r) * c];
        pad_row(src, c, r, &mut padded, |v| v as f32);
        shifted_sum(kernel, &padded, c, dst);
    };
    let rows = output.rows_mut();
    let band = 16usize;
    rows.into_par_iter()
        .enumerate()
        .chunks(band)
        .for_each(|chunk| {
            let y0 = chunk[0].0;
            let y1 = y0 + chunk.len();
            // Horizontally filtered rows y0-r .. y1+r (reflected).
            let lo = y0 as i64 - r as i64;
            let n = y1 - y0 + 2 * r;
            let mut hrows = vec![0f32; n * row_len];
            for (k, dst) in hrows.chunks_exact_mut(row_len.max(1)).enumerate() {
                if row_len == 0 {
                    break;
                }
                hpass(reflect101(lo + k as i64, h), dst);
            }
            let mut acc = vec![0f32; row_len];
            for (y, out) in chunk {
                let rows = &hrows[(y - y0) * row_len..(y - y0 + kernel.len()) * row_len];
                shifted_sum(kernel, rows, row_len, &mut acc);
                round_u8(&acc, out);
                copy_alpha(format, input.row(y), out);
            }
        });
}

wide_fn! {
    /// `dst[i] = sum_t kernel[t] src[i + t step]` (from zero, taps in order): a 1-D filter as a
    /// sum of shifted copies, one vector operation per tap; `src` is `dst.len() + (taps - 1)
    /// step` long.
    fn shifted_sum(kernel: &[f32], src: &[f32], step: usize, dst: &mut [f32]) {
        dst.fill(0.0);
        let n = dst.len();
        for (t, &kw) in kernel.iter().enumerate() {
            for (d, s) in dst.iter_mut().zip(&src[t * step..t * step + n]) {
                *d += kw * s;
            }
        }
    }
}

/// A separable blur with a non-negative symmetric kernel in OpenCV's 8-bit fixed point (what
/// `cv2.GaussianBlur` does on `uint8` images): weights quantised to 8 fractional bits (summing to
/// exactly 256), the horizontal pass kept as u16 with 8 fractional bits, the vertical pass
/// accumulated in u32 and rounded to u8. Within 1.5 levels of the f32 [`separable_filter`] (tap
/// quantisation), about twice as fast (16-bit lanes, one multiply per pair of symmetric taps).
/// Alpha is copied. A kernel of even length or not symmetric goes to [`separable_filter`].
pub fn separable_filter_q8(input: &ImageView<'_>, output: &mut ImageViewMut<'_>, kernel: &[f32]) {
    let (w, h) = (input.width as usize, input.height as usize);
    let c = input.format.channels();
    let r = kernel.len() / 2;
    let format = input.format;
    let row_len = w * c;
    if w <= 2 * r + 1 || h <= 2 * r + 1 || w < 4 {
        return separable_filter(input, output, kernel);
    }
    let mut q: Vec<u16> = kernel
        .iter()
        .map(|&k| (k.max(0.0) * 256.0).round() as u16)
        .collect();
    let total: i32 = q.iter().map(|&v| v as i32).sum();
    q[r] = (q[r] as i32 + 256 - total).clamp(0, 256) as u16;
    if q.len().is_multiple_of(2) || q.iter().zip(q.iter().rev()).any(|(a, b)| a != b) {
        // The passes below pair taps t and 2r - t.
        return separable_filter(input, output, kernel);
    }
    let hpass = |y: usize, padded: &mut [u16], dst: &mut [u16]| {
        pad_row(input.row(y), c, r, padded, |v| v as u16);
        q8_row(&q, padded, c, dst);
    };
    // Bands of rows; within a band the horizontal pass of each source row is kept in a ring of
    // 2r + 1 rows (small enough to stay in cache), so each is computed once per band.
    let k = 2 * r + 1;
    let rows = output.rows_mut();
    rows.into_par_iter()
        .enumerate()
        .chunks(128)
        .for_each(|chunk| {
            let y0 = chunk[0].0;
            let lo = y0 as i64 - r as i64;
            let mut padded = vec![0u16; (w + 2 * r) * c];
            let mut ring = vec![0u16; k * row_len];
            // Source row lo + i lives in slot i % k.
            let slot = |i: usize| (i % k) * row_len..(i % k + 1) * row_len;
            for i in 0..k - 1 {
                hpass(
                    reflect101(lo + i as i64, h),
                    &mut padded,
                    &mut ring[slot(i)],
                );
            }
            let mut acc = vec![0u32; row_len];
            for (y, out) in chunk {
                let i0 = y - y0;
                let last = i0 + k - 1;
                hpass(
                    reflect101(lo + last as i64, h),
                    &mut padded,
                    &mut ring[slot(last)],
                );
                q8_column(&q, &ring, i0, &mut acc, out);
                copy_alpha(format, input.row(y), out);
            }
        });
}

wide_fn! {
    /// The horizontal pass of [`separable_filter_q8`] over one padded row (`r` pixels of `c`
    /// samples each side): the kernel is symmetric, so taps t and 2r - t share a weight and each
    /// pair is one multiply of the two samples' sum (the same integers, modulo 2^16, as tap by
    /// tap).
    fn q8_row(q: &[u16], padded: &[u16], c: usize, dst: &mut [u16]) {
        let (r, row_len) = (q.len() / 2, dst.len());
        let centre = &padded[r * c..r * c + row_len];
        for (d, s) in dst.iter_mut().zip(centre) {
            *d = q[r].wrapping_mul(*s);
        }
        for (t, &kw) in q[..r].iter().enumerate() {
            if kw == 0 {
                continue;
            }
            let (a, b) = (&padded[t * c..], &padded[(2 * r - t) * c..]);
            for ((d, a), b) in dst.iter_mut().zip(&a[..row_len]).zip(&b[..row_len]) {
                *d = d.wrapping_add(kw.wrapping_mul(a.wrapping_add(*b)));
            }
        }
    }
}

wide_fn! {
    /// The vertical pass of [`separable_filter_q8`] for one output row: the ring holds
    /// `q.len()` horizontally filtered rows of `out.len()` samples, row `i0 + t` in slot `(i0 +
    /// t) % q.len()`; rounded and saturated into `out` (`acc` is working space).
    fn q8_column(q: &[u16], ring: &[u16], i0: usize, acc: &mut [u32], out: &mut [u8]) {
        let (k, row_len) = (q.len(), out.len());
        let r = k / 2;
        let row = |t: usize| &ring[((i0 + t) % k) * row_len..((i0 + t) % k + 1) * row_len];
        let kc = q[r] as u32;
        for (a, s) in acc.iter_mut().zip(row(r)) {
            *a = (1 << 15) + kc * *s as u32;
        }
        for (t, &kw) in q[..r].iter().enumerate() {
            if kw == 0 {
                continue;
            }
            let kw = kw as u32;
            for ((a, s), u) in acc.iter_mut().zip(row(t)).zip(row(2 * r - t)) {
                *a += kw * (*s as u32 + *u as u32);
            }
        }
        for (o, a) in out.iter_mut().zip(acc.iter()) {
            *o = (*a >> 16).min(255) as u8;
        }
    }
}

/// OpenCV's 8-bit RGB to HSV (`COLOR_RGB2HSV`): H in 0..180, S and V in 0..255, with OpenCV's
/// fixed-point rounding, so a round trip reproduces the references' quantisation.
#[inline]
pub fn rgb_to_hsv(r: u8, g: u8, b: u8) -> (u8, u8, u8) {
    const SHIFT: i32 = 12;
    let (r, g, b) = (r as i32, g as i32, b as i32);
    let v = r.max(g).max(b);
    let vmin = r.min(g).min(b);
    let diff = v - vmin;
    let s = if v == 0 {
        0
    } else {
        let sdiv = ((255 << SHIFT) as f64 / v as f64).round() as i32;
        (diff * sdiv + (1 << (SHIFT - 1))) >> SHIFT
    };
    let mut h = if diff == 0 {
        0
    } else {
        let num = if v == r {
            g - b
        } else if v == g {
            b - r + 2 * diff
        } else {
            r - g + 4 * diff
        };
        let hdiv = ((180 << SHIFT) as f64 / (6.0 * diff as f64)).round() as i32;
        (num * hdiv + (1 << (SHIFT - 1))) >> SHIFT
    };
    if h < 0 {
        h += 180;
    }
    (h as u8, s as u8, v as u8)
}

/// OpenCV's 8-bit HSV to RGB (`COLOR_HSV2RGB`, H in 0..180): computed in float and rounded.
#[inline]
pub fn hsv_to_rgb(h: u8, s: u8, v: u8) -> (u8, u8, u8) {
    let (hf, sf, vf) = (h as f32 * (6.0 / 180.0), s as f32 / 255.0, v as f32 / 255.0);
    let (r, g, b) = if sf == 0.0 {
        (vf, vf, vf)
    } else {
        let mut hh = hf;
        let mut sector = hh.floor() as i32;
        hh -= sector as f32;
        if sector < 0 {
            sector += 6;
        }
        let sector = (sector % 6) as usize;
        let tab = [
            vf,
            vf * (1.0 - sf),
            vf * (1.0 - sf * hh),
            vf * (1.0 - sf * (1.0 - hh)),
        ];
        const SECTOR: [[usize; 3]; 6] = [
            [1, 3, 0],
            [1, 0, 2],
            [3, 0, 1],
            [0, 2, 1],
            [0, 1, 3],
            [2, 1, 0],
        ];
        let [bi, gi, ri] = SECTOR[sector];
        (tab[ri], tab[gi], tab[bi])
    };
    let q = |x: f32| (x * 255.0).round().clamp(0.0, 255.0) as u8;
    (q(r), q(g), q(b))
}

/// Applies `f(h, s, v) -> (h, s, v)` to every pixel through OpenCV-exact HSV conversions; alpha is
/// copied. For mono8 the single channel is treated as V with zero saturation.
pub fn map_hsv<F>(input: &ImageView<'_>, output: &mut ImageViewMut<'_>, f: F)
where
    F: Fn(u8, u8, u8) -> (u8, u8, u8) + Send + Sync,
{
    let format = input.format;
    let c = format.channels();
    let [ri, gi, bi] = format.rgb_offsets();
    par_rows(input, output, |_, src, dst| {
        for (p, q) in src.chunks_exact(c).zip(dst.chunks_exact_mut(c)) {
            if format.is_mono() {
                q[0] = f(0, 0, p[0]).2;
                continue;
            }
            let (h, s, v) = rgb_to_hsv(p[ri], p[gi], p[bi]);
            let (h, s, v) = f(h, s, v);
            let (r, g, b) = hsv_to_rgb(h, s, v);
            q[ri] = r;
            q[gi] = g;
            q[bi] = b;
            if let Some(a) = format.alpha_offset() {
                q[a] = p[a];
            }
        }
    });
}

/// `2^32 / v` for v in 1..=255 (0 for v = 0), rounded: replaces a division by an 8-bit value with
/// a multiplication.
pub fn reciprocals() -> &'static [u64; 256] {
    static R: std::sync::OnceLock<[u64; 256]> = std::sync::OnceLock::new();
    R.get_or_init(|| {
        std::array::from_fn(|v| {
            if v == 0 {
                0
            } else {
                ((1u64 << 32) + v as u64 / 2) / v as u64
            }
        })
    })
}

/// Changes the HSV value of every pixel and keeps hue and saturation, in RGB directly: each colour
/// channel is scaled by `V' / V` (`V` = max of the channels). `vmap(y, x, v)` gives the new value.
/// This is what converting to HSV, changing V and converting back computes, without OpenCV's 8-bit
/// quantisation of hue (2 degree steps) and saturation on the way; results agree within ±1-2 levels.
/// Each channel is `round(p V' / V)` exactly (halves up), in 32-bit fixed point.
/// Alpha is copied; mono8 maps its single channel.
pub fn map_value<F>(input: &ImageView<'_>, output: &mut ImageViewMut<'_>, vmap: F)
where
    F: Fn(usize, usize, u8) -> u8 + Send + Sync,
{
    let format = input.format;
    let c = format.channels();
    let recip = reciprocals();
    par_rows(input, output, |y, src, dst| {
        if format.is_mono() {
            for (x, (s, d)) in src.iter().zip(dst.iter_mut()).enumerate() {
                *d = vmap(y, x, *s);
            }
            return;
        }
        match c {
            3 => value_row::<3, F>(src, dst, y, &vmap, recip),
            _ => value_row::<4, F>(src, dst, y, &vmap, recip),
        }
        copy_alpha(format, src, dst);
    });
}

/// One row of [`map_value`]. Per pixel the factor `k = nv / v` in 8.24 fixed point (and `z =
/// 0`), or `k = nv`, `z = 1` where v = 0 (black: every channel becomes nv); colour channel `p`
/// becomes `round((p + z) k / 2^24)`. A channel is at most v, so the product stays below 2^32;
/// the factor's error (under 2^-15 of a level) and the small bias cannot cross a rounding
/// boundary, which sits at least 1 / 510 of a level from any p nv / v: exact halves round up.
/// Every colour format keeps its three colour bytes first (alpha, if any, is byte 3), and the
/// formula is the same for each of them, so the channel order does not matter here.
fn value_row<const C: usize, F>(src: &[u8], dst: &mut [u8], y: usize, vmap: &F, recip: &[u64; 256])
where
    F: Fn(usize, usize, u8) -> u8,
{
    for (x, (p, q)) in src.chunks_exact(C).zip(dst.chunks_exact_mut(C)).enumerate() {
        let v = p[0].max(p[1]).max(p[2]);
        let nv = vmap(y, x, v) as u64;
        let (k, z) = if v == 0 {
            ((nv << 24) as u32, 1)
        } else {
            (((nv * recip[v as usize] + 255) >> 8) as u32, 0)
        };
        for ch in 0..3 {
            q[ch] = (((p[ch] as u32 + z) * k + (1 << 23) + (1 << 12)) >> 24) as u8;
        }
    }
}

/// Changes the HSV saturation of every pixel and keeps hue and value, in RGB directly: with
/// `S = round(255 (V - min) / V)` (OpenCV's 8-bit saturation) and `S' = smap(S)`, every channel's
/// distance below `V` is scaled by `S' / S`. Gray pixels stay gray. Mono8 is copied (it has no
/// saturation); callers refuse it where that makes the perturbation a no-op.
pub fn map_saturation(input: &ImageView<'_>, output: &mut ImageViewMut<'_>, smap: &[u8; 256]) {
    let map = SaturationMap::new(smap);
    let format = input.format;
    par_rows(input, output, |_, src, dst| map.row(format, src, dst));
}

/// The saturation mapping of [`map_saturation`] prepared for use row by row.
pub struct SaturationMap {
    /// Per saturation S: the factor S' / S in 32.32 fixed point.
    gain: [i64; 256],
}

impl SaturationMap {
    /// Prepares the mapping `S -> smap[S]` of the HSV saturation.
    pub fn new(smap: &[u8; 256]) -> Self {
        let recip = reciprocals();
        let mut gain = [0i64; 256];
        for (s, g) in gain.iter_mut().enumerate().skip(1) {
            *g = smap[s] as i64 * recip[s] as i64;
        }
        SaturationMap { gain }
    }

    /// Maps one row of `format` pixels from `src` into `dst` (mono8 is copied, alpha is copied).
    pub fn row(&self, format: PixelFormat, src: &[u8], dst: &mut [u8]) {
        let rgb = format.rgb_offsets();
        match format.channels() {
            _ if format.is_mono() => dst.copy_from_slice(src),
            3 => saturation_row::<3>(src, dst, rgb, reciprocals(), &self.gain),
            4 => {
                saturation_row::<4>(src, dst, rgb, reciprocals(), &self.gain);
                copy_alpha(format, src, dst);
            }
            _ => unreachable!("colour formats have 3 or 4 channels"),
        }
    }
}

/// One row of [`map_saturation`] for pixels of `C` bytes with colour bytes at `rgb`.
#[inline(always)]
fn saturation_row<const C: usize>(
    src: &[u8],
    dst: &mut [u8],
    [ri, gi, bi]: [usize; 3],
    recip: &[u64; 256],
    gain: &[i64; 256],
) {
    for (p, q) in src.chunks_exact(C).zip(dst.chunks_exact_mut(C)) {
        let (r, g, b) = (p[ri] as i64, p[gi] as i64, p[bi] as i64);
        let v = r.max(g).max(b);
        let diff = v - r.min(g).min(b);
        // S = round(255 diff / V), then c' = V - (V - c) S' / S, with
        // reciprocal tables.
        // When diff = 0 every channel equals V and the gain does not matter.
        let s = ((diff * 255 * recip[v as usize] as i64 + (1 << 31)) >> 32).clamp(1, 255);
        let k = gain[s as usize];
        for (ch, val) in [(ri, r), (gi, g), (bi, b)] {
            q[ch] = (v - (((v - val) * k + (1 << 31)) >> 32)).clamp(0, 255) as u8;
        }
    }
}

/// Finished frames' f32 buffers, kept for the next frames: a frame's intermediate images are
/// tens of megabytes, and memory fresh from the system costs a page fault and a zeroing per 4 KiB
/// page on every frame (measured: a k = 25 Gaussian at 2.3 MP takes 40 ms on fresh pages, 18 ms on
/// reused ones). At most [`SPARE_BUFFERS`] are kept.
static SPARE: std::sync::Mutex<Vec<Vec<f32>>> = std::sync::Mutex::new(Vec::new());

/// How many finished buffers [`frame_buffer`] keeps for reuse.
const SPARE_BUFFERS: usize = 8;

/// A zeroed buffer of `len` samples, reusing a finished frame's buffer when one is large enough.
pub fn frame_buffer(len: usize) -> Vec<f32> {
    let reused = SPARE.lock().ok().and_then(|mut spare| {
        let i = spare.iter().position(|b| b.capacity() >= len)?;
        Some(spare.swap_remove(i))
    });
    match reused {
        Some(mut b) => {
            b.clear();
            b.resize(len, 0.0);
            b
        }
        None => vec![0f32; len],
    }
}

/// A buffer of `len` samples for a caller that overwrites every one of them: a finished frame's
/// buffer is reused as it is (its old samples left in place), saving the zeroing of
/// [`frame_buffer`].
pub fn frame_buffer_overwritten(len: usize) -> Vec<f32> {
    let reused = SPARE.lock().ok().and_then(|mut spare| {
        let i = spare.iter().position(|b| b.capacity() >= len)?;
        Some(spare.swap_remove(i))
    });
    match reused {
        Some(mut b) => {
            b.truncate(len);
            b.resize(len, 0.0);
            b
        }
        None => vec![0f32; len],
    }
}

/// Hands a buffer back for [`frame_buffer`] to reuse (small ones are simply freed; when the spare
/// list is full the smallest buffer goes).
pub fn recycle(buffer: Vec<f32>) {
    if buffer.capacity() < 1 << 16 {
        return;
    }
    if let Ok(mut spare) = SPARE.lock() {
        spare.push(buffer);
        if spare.len() > SPARE_BUFFERS {
            let smallest = (0..spare.len())
                .min_by_key(|&i| spare[i].capacity())
                .unwrap_or(0);
            spare.swap_remove(smallest);
        }
    }
}

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
fn lerp_row<const C: usize>(vrow: &[f32], xmap: &[(usize, usize, f32)], row: &mut [f32]) {
    for (out, &(x0, x1, wx)) in row.chunks_exact_mut(C).zip(xmap) {
        let p0: &[f32; C] = vrow[x0 * C..x0 * C + C].try_into().expect("C samples");
        let p1: &[f32; C] = vrow[x1 * C..x1 * C + C].try_into().expect("C samples");
        for ch in 0..C {
            out[ch] = p0[ch] + (p1[ch] - p0[ch]) * wx;
        }
    }
}

/// The resolution divisor [`GaussianRows`] works at for `sigma` on a `w` x `h` frame.
fn gaussian_factor(sigma: f64, w: usize, h: usize) -> usize {
    // The largest power of two (up to 8) that leaves a Gaussian of at least 1.5 reduced pixels to
    // apply at the reduced resolution: narrower ones are not smooth enough for the bilinear
    // upsampling to follow them within a level or two.
    let mut f = 1;
    while f < 8 && w >= 64 * f && h >= 64 * f && reduced_sigma(sigma, f * 2) >= 1.5 {
        f *= 2;
    }
    f
}

/// The sigma, in reduced pixels, that remains to apply after box-downsampling by `f` so that
/// downsampling, the Gaussian and bilinear upsampling together have the variance of `sigma`.
fn reduced_sigma(sigma: f64, f: usize) -> f64 {
    let ff = (f * f) as f64;
    ((sigma * sigma - (ff - 1.0) / 12.0 - ff / 6.0) / ff)
        .max(0.0)
        .sqrt()
}

/// A Gaussian blur of `input` as `cv2.GaussianBlur(k x k, sigma)`, read row by row (f32,
/// interleaved, alpha blurred too) with [`GaussianRows::row`], from any thread. Kernels below sigma
/// 3.15 are applied exactly (separable, reflect-101 borders). Wider ones are computed at a reduced
/// resolution (half up to sigma 6.3, quarter up to 12.6, an eighth beyond): box downsampling, an
/// exact Gaussian of the remaining width (the variance of the box and of the bilinear upsampling
/// subtracted, at least 1.5 reduced pixels), bilinear upsampling. On real frames this differs from
/// the exact kernel by about a quarter of a level on average (see the test), at a fraction of the
/// cost: the references' k = 41 and k = 113 kernels are what makes them slow.
pub struct GaussianRows {
    /// The blurred rows: at full resolution, or (reduced) the working resolution's rows already
    /// interpolated horizontally to full width, so that a full-resolution row is one lerp of two.
    rows: FloatImage,
    /// Vertical taps into `rows` when reduced: (first, second, weight of the second).
    ymap: Vec<(usize, usize, f32)>,
}

impl GaussianRows {
    /// Blurs `input` with a `k x k` Gaussian of `sigma` (OpenCV's sigma for k when 0).
    pub fn new(input: &ImageView<'_>, k: usize, sigma: f64) -> Self {
        let sigma = if sigma > 0.0 { sigma } else { opencv_sigma(k) };
        let (w, h, c) = (
            input.width as usize,
            input.height as usize,
            input.format.channels(),
        );
        let f = gaussian_factor(sigma, w, h);
        if f == 1 {
            let rows = FloatImage::from_view(input).convolve(&gaussian_kernel(k.max(1) | 1, sigma));
            return GaussianRows {
                rows,
                ymap: Vec::new(),
            };
        }
        let s2 = reduced_sigma(sigma, f);
        let k2 = (2.0 * (3.0 * s2).ceil() + 1.0) as usize;
        // Pad at full resolution (a multiple of f, wider than the kernel) so the borders reflect
        // exactly as the full-resolution filter does; crop when upsampling.
        let pad = ((3.0 * sigma).ceil() as usize).div_ceil(f) * f + f;
        let small = FloatImage::downsample_padded(input, pad, f).convolve(&gaussian_kernel(k2, s2));
        // Bilinear taps with pixel centres aligned, offset by the padding.
        let map = |i: usize, n: usize| {
            let p = (((i + pad) as f32 + 0.5) / f as f32 - 0.5).max(0.0);
            let i0 = (p as usize).min(n - 1);
            (i0, (i0 + 1).min(n - 1), p - i0 as f32)
        };
        let xmap: Vec<(usize, usize, f32)> = (0..w).map(|x| map(x, small.w)).collect();
        let ymap: Vec<(usize, usize, f32)> = (0..h).map(|y| map(y, small.h)).collect();
        // Horizontal interpolation once per working row (bilinear interpolation is separable):
        // only the rows the vertical taps reach.
        let first = ymap.first().map_or(0, |t| t.0);
        let last = ymap.last().map_or(0, |t| t.1);
        let mut data = frame_buffer((last + 1 - first) * w * c);
        data.par_chunks_mut((w * c).max(1))
            .enumerate()
            .for_each(|(i, out)| {
                let src = small.row(first + i);
                match c {
                    1 => lerp_row::<1>(src, &xmap, out),
                    3 => lerp_row::<3>(src, &xmap, out),
                    _ => lerp_row::<4>(src, &xmap, out),
                }
            });
        GaussianRows {
            rows: FloatImage {
                w,
                h: last + 1 - first,
                c,
                data,
            },
            ymap: ymap
                .into_iter()
                .map(|(a, b, t)| (a - first, b - first, t))
                .collect(),
        }
    }

    /// Writes blurred row `y` (`w * c` samples) into `out`.
    pub fn row(&self, y: usize, out: &mut [f32]) {
        if self.ymap.is_empty() {
            out.copy_from_slice(self.rows.row(y));
            return;
        }
        let (y0, y1, wy) = self.ymap[y];
        lerp(self.rows.row(y0), self.rows.row(y1), wy, out);
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

wide_fn! {
    /// `out = a + (b - a) t`.
    fn lerp(a: &[f32], b: &[f32], t: f32, out: &mut [f32]) {
        for ((o, a), b) in out.iter_mut().zip(a).zip(b) {
            *o = a + (b - a) * t;
        }
    }
}

wide_fn! {
    /// Rounds non-negative samples to u8 (saturating at 255).
    pub fn round_u8(src: &[f32], dst: &mut [u8]) {
        for (d, s) in dst.iter_mut().zip(src) {
            *d = byte(s + 0.5);
        }
    }
}

/// `v as u8`: `v` truncated toward zero and saturated to 0..=255, NaN to 0; but written so that
/// loops over it vectorise (Rust's saturating float-to-int casts compile to a scalar conversion
/// and NaN test per value). The clamped value is floored (one instruction with SSE4.1) and
/// added to 2^23, which puts the integer in the low bits of the mantissa.
///
/// ```
/// # use perturb_core::camera::ops::byte;
/// assert_eq!(byte(254.9), 254);
/// assert_eq!(byte(-3.0), 0);
/// assert_eq!(byte(1e9), 255);
/// ```
#[inline(always)]
// max then min, not clamp: max maps NaN to 0, clamp would carry it on.
#[allow(clippy::manual_clamp)]
pub fn byte(v: f32) -> u8 {
    (v.max(0.0).min(255.0).floor() + 8_388_608.0).to_bits() as u8
}

/// A Gaussian blur written into `output` (u8, rounded); see [`GaussianRows`]. Kernels applied
/// exactly stream through [`separable_filter_q8`]: OpenCV's own 8-bit fixed point, no full-frame
/// float copies.
pub fn gaussian_blur(input: &ImageView<'_>, output: &mut ImageViewMut<'_>, k: usize, sigma: f64) {
    let sigma = if sigma > 0.0 { sigma } else { opencv_sigma(k) };
    if gaussian_factor(sigma, input.width as usize, input.height as usize) == 1 {
        separable_filter_q8(input, output, &gaussian_kernel(k.max(1) | 1, sigma));
        return;
    }
    let blurred = GaussianRows::new(input, k, sigma);
    let format = input.format;
    par_rows(input, output, |y, src, dst| {
        let mut row = vec![0f32; dst.len()];
        blurred.row(y, &mut row);
        round_u8(&row, dst);
        copy_alpha(format, src, dst);
    });
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::image::Image;

    #[test]
    fn byte_is_the_saturating_cast() {
        // Every f32 between -2 and 258 in steps of 1/64 (exact halves and integers included),
        // the largest values below each integer, and the special values.
        let mut values: Vec<f32> = (-128..=258 * 64).map(|i| i as f32 / 64.0).collect();
        values.extend((1..=256).map(|k| f32::from_bits((k as f32).to_bits() - 1)));
        values.extend([
            f32::NAN,
            f32::INFINITY,
            f32::NEG_INFINITY,
            f32::MAX,
            f32::MIN,
            -0.0,
            1e-30,
            255.999_99,
            256.0,
            8_388_608.0,
        ]);
        for v in values {
            assert_eq!(byte(v), v as u8, "byte({v})");
        }
    }

    #[test]
    fn split_and_merge_rgb_follow_each_formats_channel_positions() {
        let rgb = crate::image::rgb_test_row(5, 53);
        for format in PixelFormat::ALL {
            let img = rgb.convert(format);
            let mut planes = [[0f32; 5]; 3];
            let [r, g, b] = &mut planes;
            split_rgb(&img.data, format, [r, g, b]);
            for (x, p) in img.data.chunks_exact(format.channels()).enumerate() {
                let [ri, gi, bi] = format.rgb_offsets();
                let want = [p[ri], p[gi], p[bi]].map(|v| v as f32);
                assert_eq!(
                    [planes[0][x], planes[1][x], planes[2][x]],
                    want,
                    "{format:?}"
                );
            }
            // Merging the planes back gives the same row, alpha untouched.
            let bytes = planes.map(|p| p.map(|v| v as u8));
            let mut out = img.data.clone();
            out.iter_mut()
                .enumerate()
                .filter(|(i, _)| Some(i % format.channels()) != format.alpha_offset())
                .for_each(|(_, v)| *v = 0);
            merge_rgb(format, [&bytes[0], &bytes[1], &bytes[2]], &mut out);
            assert_eq!(out, img.data, "{format:?}");
        }
    }

    #[test]
    fn reflect101_matches_opencv() {
        let idx: Vec<usize> = (-3..8).map(|i| reflect101(i, 5)).collect();
        assert_eq!(idx, vec![3, 2, 1, 0, 1, 2, 3, 4, 3, 2, 1]);
        assert_eq!(reflect101(-4, 1), 0);
    }

    #[test]
    fn map_value_scales_channels_with_exact_rounding() {
        // Every (channel, value) pair with channel <= value, against the rational
        // round(p nv / v) with halves up, for a value map that hits many ratios.
        let pixels: Vec<[u8; 3]> = (1..=255u8)
            .flat_map(|v| (0..=v).map(move |p| [v, p, p / 2]))
            .chain([[0, 0, 0]])
            .collect();
        let w = pixels.len() as u32;
        let mut img = Image::new(w, 1, PixelFormat::Rgb8);
        img.data = pixels.concat();
        let nv = |v: u8| (v as u32 * 37 % 256) as u8;
        let mut out = Image::new(w, 1, PixelFormat::Rgb8);
        map_value(&img.view(), &mut out.view_mut(), |_, _, v| nv(v));
        for (p, q) in img.data.chunks_exact(3).zip(out.data.chunks_exact(3)) {
            let v = p[0] as u32;
            for ch in 0..3 {
                let want = if v == 0 {
                    nv(0) as u32
                } else {
                    (2 * p[ch] as u32 * nv(p[0]) as u32 + v) / (2 * v)
                };
                assert_eq!(q[ch] as u32, want, "pixel {p:?} channel {ch}");
            }
        }
        // Every other format gives the same pixels, alpha copied.
        for format in PixelFormat::ALL.into_iter().filter(|f| !f.is_mono()) {
            // The image in `format` with alpha 77.
            let in_format = |img: &Image| {
                let mut i = img.convert(format);
                if let Some(a) = format.alpha_offset() {
                    let c = format.channels();
                    i.data.iter_mut().skip(a).step_by(c).for_each(|v| *v = 77);
                }
                i
            };
            let src = in_format(&img);
            let mut got = Image::new(w, 1, format);
            map_value(&src.view(), &mut got.view_mut(), |_, _, v| nv(v));
            assert_eq!(got, in_format(&out), "{format:?}");
        }
    }

    #[test]
    fn hsv_matches_opencv_reference_values() {
        // Expected values worked by hand from OpenCV's fixed-point formulas (hsv_shift 12).
        assert_eq!(rgb_to_hsv(255, 0, 0), (0, 255, 255));
        assert_eq!(rgb_to_hsv(0, 255, 0), (60, 255, 255));
        assert_eq!(rgb_to_hsv(0, 0, 255), (120, 255, 255));
        assert_eq!(rgb_to_hsv(200, 100, 50), (10, 191, 200));
        assert_eq!(rgb_to_hsv(10, 20, 30), (105, 170, 30));
        assert_eq!(hsv_to_rgb(10, 191, 200), (200, 100, 50));
        assert_eq!(hsv_to_rgb(0, 0, 77), (77, 77, 77));
        // Round trips stay within the 8-bit quantisation.
        for (r, g, b) in [
            (12u8, 200u8, 90u8),
            (250, 250, 1),
            (3, 4, 5),
            (128, 64, 255),
        ] {
            let (h, s, v) = rgb_to_hsv(r, g, b);
            let (r2, g2, b2) = hsv_to_rgb(h, s, v);
            for (a, b) in [(r, r2), (g, g2), (b, b2)] {
                assert!(
                    (a as i32 - b as i32).abs() <= 4,
                    "{r} {g} {b} -> {r2} {g2} {b2}"
                );
            }
        }
    }

    #[test]
    fn fixed_point_gaussian_stays_within_rounding_of_the_float_convolution() {
        let img = crate::synthetic::street_image(320, 200, 5);
        let exact = FloatImage::from_view(&img.view());
        for (k, sigma) in [(3usize, 0.8f64), (7, 1.4), (15, 2.6)] {
            let want = exact.convolve(&gaussian_kernel(k, sigma));
            let mut got = Image::new(320, 200, PixelFormat::Rgb8);
            gaussian_blur(&img.view(), &mut got.view_mut(), k, sigma);
            let mut differ = 0;
            for (a, b) in got.data.iter().zip(&want.data) {
                let e = (*a as f32 - b).abs();
                // Quantising the taps to 1/256 (as OpenCV does) moves a few values just past
                // one level.
                assert!(e < 1.5, "k {k}: {a} vs {b}");
                differ += (*a != (b + 0.5).clamp(0.0, 255.0) as u8) as usize;
            }
            assert!(
                differ * 10 < got.data.len(),
                "k {k}: {differ} samples differ"
            );
        }
    }

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

    #[test]
    fn reduced_resolution_gaussian_is_close_to_the_exact_kernel() {
        let img = crate::synthetic::street_image(320, 200, 3);
        let exact = FloatImage::from_view(&img.view());
        for (k, sigma) in [
            (15usize, 2.6f64),
            (25, 4.1),
            (41, 6.5),
            (59, 9.2),
            (113, 17.3),
        ] {
            let want = exact.convolve(&gaussian_kernel(k, sigma));
            let mut got = Image::new(320, 200, PixelFormat::Rgb8);
            gaussian_blur(&img.view(), &mut got.view_mut(), k, sigma);
            let (mut sum, mut max) = (0.0f64, 0.0f32);
            for (a, b) in got.data.iter().zip(&want.data) {
                let e = (*a as f32 - b).abs();
                sum += e as f64;
                max = max.max(e);
            }
            let mean = sum / got.data.len() as f64;
            eprintln!("GAUSS k {k} mean {mean:.3} max {max:.2}");
            assert!(
                mean < 0.6 && max < 8.0,
                "k {k}: mean error {mean:.3}, max {max:.2}"
            );
        }
    }

    #[test]
    fn opencv_sigmas() {
        for (k, s) in [(3, 0.8), (7, 1.4), (15, 2.6), (25, 4.1), (41, 6.5)] {
            assert!((opencv_sigma(k) - s).abs() < 1e-9, "k {k}");
        }
    }

    #[test]
    fn separable_filter_preserves_constant_images() {
        let mut img = Image::new(13, 9, PixelFormat::Rgba8);
        for (i, b) in img.data.iter_mut().enumerate() {
            *b = if i % 4 == 3 { (i % 251) as u8 } else { 77 };
        }
        let mut out = Image::new(13, 9, PixelFormat::Rgba8);
        separable_filter(&img.view(), &mut out.view_mut(), &gaussian_kernel(7, 1.4));
        assert_eq!(out, img, "constant colour stays constant, alpha copied");
    }
}
