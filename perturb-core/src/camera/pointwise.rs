//! Per-pixel colour and tone kernels that run near the speed of a frame copy, with the same bytes
//! as the tables that define them.
//!
//! A perturbation whose output byte depends on one input byte is defined by a 256-entry table; a
//! table lookup per byte costs a load and does not vectorise. Most of these tables follow a simple
//! formula (a straight line clamped to 0..=255, a staircase), so [`ByteMap`] looks, once at
//! configuration time, for integer arithmetic in 16-bit lanes that gives exactly the table's 256
//! outputs (the few inputs where the nearest line misses by one, exact halves that the table's
//! float arithmetic rounded the other way, are patched afterwards), and keeps the lookup where
//! none fits. [`fit_fixed`] does the same for tables of 16-bit values in 16.16 fixed point.
//!
//! Every kernel here is checked against its table over all 256 inputs when it is built, so what
//! runs is always what the table says.

use super::ops::{byte, copy_alpha, merge_rgb, par_rows, par_rows_with, split_rgb_bytes, wide_fn};
use crate::image::{ImageView, ImageViewMut, PixelFormat};

/// Inputs a line may miss and still be used: each costs one compare-and-select pass over a row.
const MAX_PATCHES: usize = 8;

/// A byte-to-byte map of every colour byte (alpha is copied), as a table plus the fastest exact
/// way to compute it found at configuration time.
#[derive(Clone, Debug)]
pub struct ByteMap {
    lut: [u8; 256],
    form: Form,
}

#[derive(Clone, Debug, PartialEq)]
enum Form {
    /// A lookup per byte.
    Table,
    /// `min(255, max(0, floor(v mul / 256) + add - sub) >> 7)` in 16-bit lanes (a slope of
    /// `mul / 2^15`, results with 7 fractional bits), then `patches` (input, output) replace the
    /// inputs where that differs from the table.
    Line {
        mul: u16,
        add: u16,
        sub: u16,
        patches: Vec<(u8, u8)>,
    },
    /// `min(255, floor(v levels / 255) scale)`: the posterize staircase.
    Steps { levels: u16, scale: u16 },
}

impl ByteMap {
    /// A map computed by table lookup.
    pub fn table(lut: [u8; 256]) -> Self {
        ByteMap {
            lut,
            form: Form::Table,
        }
    }

    /// A map that is about `slope v + offset` clamped to 0..=255 (rounded), `0 <= slope < 2`:
    /// computed by a line in fixed point when one gives the table's bytes (with at most 8 patched
    /// inputs), else by lookup.
    pub fn line(lut: [u8; 256], slope: f64, offset: f64) -> Self {
        let form = fit_line(&lut, slope, offset).unwrap_or(Form::Table);
        ByteMap { lut, form }
    }

    /// A map that is the staircase `min(255, floor(v levels / 255) scale)` where the table is
    /// exactly that (else by lookup).
    pub fn steps(lut: [u8; 256], levels: u32, scale: u32) -> Self {
        let form = match (u16::try_from(levels), u16::try_from(scale)) {
            (Ok(levels), Ok(scale)) if levels <= 256 && levels as u32 * scale as u32 <= 65535 => {
                Form::Steps { levels, scale }
            }
            _ => Form::Table,
        };
        let form = if agrees(&lut, &form) {
            form
        } else {
            Form::Table
        };
        ByteMap { lut, form }
    }

    /// The table.
    pub fn lut(&self) -> &[u8; 256] {
        &self.lut
    }

    /// True when the map runs as arithmetic rather than as a lookup.
    pub fn is_arithmetic(&self) -> bool {
        self.form != Form::Table
    }

    /// Maps every byte of `src` into `dst` (same length; alpha is not special here).
    pub fn row(&self, src: &[u8], dst: &mut [u8]) {
        match &self.form {
            Form::Table => table_bytes(&self.lut, src, dst),
            Form::Line {
                mul,
                add,
                sub,
                patches,
            } => {
                line_bytes(src, *mul, *add, *sub, dst);
                patch(patches, src, dst);
            }
            Form::Steps { levels, scale } => steps_bytes(src, *levels, *scale, dst),
        }
    }

    /// Maps every colour byte of `input` into `output`; alpha is copied.
    pub fn apply(&self, input: &ImageView<'_>, output: &mut ImageViewMut<'_>) {
        let format = input.format;
        par_rows(input, output, |_, src, dst| {
            let n = src.len().min(dst.len());
            self.row(&src[..n], &mut dst[..n]);
            copy_alpha(format, src, dst);
        });
    }
}

/// The output of `form` for input `v` (the scalar definition of each kernel).
fn eval(form: &Form, lut: &[u8; 256], v: u8) -> u8 {
    match form {
        Form::Table => lut[v as usize],
        Form::Line {
            mul,
            add,
            sub,
            patches,
        } => match patches.iter().find(|p| p.0 == v) {
            Some(&(_, out)) => out,
            None => line(v, *mul, *add, *sub),
        },
        Form::Steps { levels, scale } => step(v, *levels, *scale),
    }
}

fn agrees(lut: &[u8; 256], form: &Form) -> bool {
    (0..=255u8).all(|v| eval(form, lut, v) == lut[v as usize])
}

#[inline(always)]
fn line(v: u8, mul: u16, add: u16, sub: u16) -> u8 {
    // floor(v mul / 256) with 16-bit products only: v (mul >> 8) + floor(v (mul & 255) / 256).
    let v = v as u16;
    let scaled = v * (mul >> 8) + ((v * (mul & 255)) >> 8);
    (scaled.saturating_add(add).saturating_sub(sub) >> 7).min(255) as u8
}

/// `floor(v levels / 255)` as `floor((v levels + 1) 257 / 2^16)` (exact for `v levels` up to
/// 65280), times `scale`, at most 255.
#[inline(always)]
fn step(v: u8, levels: u16, scale: u16) -> u8 {
    let t = v as u16 * levels + 1;
    let q = ((t as u32 * 257) >> 16) as u16;
    (q * scale).min(255) as u8
}

/// The line of [`Form::Line`] closest to the table: slopes and offsets around the nominal ones,
/// the one that misses the fewest inputs, if it misses at most [`MAX_PATCHES`].
fn fit_line(lut: &[u8; 256], slope: f64, offset: f64) -> Option<Form> {
    let m0 = (slope * 32768.0).round() as i64;
    let o0 = ((offset + 0.5) * 128.0).round() as i64;
    let mut best: Option<Form> = None;
    let mut best_misses = usize::MAX;
    for mul in (m0 - 2).max(0)..=(m0 + 2).min(65535) {
        for off in o0 - 16..=o0 + 16 {
            let (add, sub) = (off.max(0), (-off).max(0));
            if add > 65535 || sub > 65535 {
                continue;
            }
            let (mul, add, sub) = (mul as u16, add as u16, sub as u16);
            let misses: Vec<(u8, u8)> = (0..=255u8)
                .filter(|&v| line(v, mul, add, sub) != lut[v as usize])
                .map(|v| (v, lut[v as usize]))
                .collect();
            if misses.len() < best_misses {
                best_misses = misses.len();
                best = Some(Form::Line {
                    mul,
                    add,
                    sub,
                    patches: misses,
                });
            }
        }
    }
    best.filter(|_| best_misses <= MAX_PATCHES)
}

/// `(mul, add)` with `(v mul + add) >> 16 == table[v]` for every v in 0..=255 and no 32-bit
/// overflow, if there is one: a table of rounded products `round(c v)` in 16.16 fixed point. For
/// each slope around the table's mean slope the offsets that fit every entry form an interval,
/// computed directly.
pub fn fit_fixed(table: &[u32; 256]) -> Option<(u32, u32)> {
    fit_fixed_near(table, (table[255] as f64 - table[0] as f64) / 255.0)
}

/// [`fit_fixed`] starting from the slope `slope` (the search ends sooner when it is close).
pub fn fit_fixed_near(table: &[u32; 256], slope: f64) -> Option<(u32, u32)> {
    if !(0.0..65536.0).contains(&slope) {
        return None;
    }
    let m0 = (slope * 65536.0).round() as i64;
    // The rounding of each entry moves the best slope by at most 1/255 of a step either way.
    for d in 0..=(65536 / 255 + 2) {
        for mul in [m0 - d, m0 + d] {
            if mul < 0 || (d == 0 && mul != m0) {
                continue;
            }
            // table[v] << 16 <= v mul + add < (table[v] + 1) << 16
            let mut lo = i64::MIN;
            let mut hi = i64::MAX;
            for (v, &t) in table.iter().enumerate() {
                let base = v as i64 * mul;
                lo = lo.max(((t as i64) << 16) - base);
                hi = hi.min((((t as i64) + 1) << 16) - base - 1);
            }
            let add = lo.max(0);
            if add <= hi && 255 * mul + add <= u32::MAX as i64 {
                return Some((mul as u32, add as u32));
            }
        }
    }
    None
}

wide_fn! {
    /// `dst[i] = lut[src[i]]`.
    fn table_bytes(lut: &[u8; 256], src: &[u8], dst: &mut [u8]) {
        for (d, s) in dst.iter_mut().zip(src) {
            *d = lut[*s as usize];
        }
    }
}

wide_fn! {
    /// The line of [`Form::Line`] on every byte.
    fn line_bytes(src: &[u8], mul: u16, add: u16, sub: u16, dst: &mut [u8]) {
        for (d, &s) in dst.iter_mut().zip(src) {
            *d = line(s, mul, add, sub);
        }
    }
}

/// `dst[i] = out` where `src[i] == v`, for every `(v, out)` of `patches`, in one pass.
fn patch(patches: &[(u8, u8)], src: &[u8], dst: &mut [u8]) {
    fn fixed<const N: usize>(patches: &[(u8, u8)], src: &[u8], dst: &mut [u8]) {
        let keys = std::array::from_fn(|i| patches[i].0);
        let outs = std::array::from_fn(|i| patches[i].1);
        patch_bytes::<N>(src, keys, outs, dst);
    }
    match patches.len() {
        0 => {}
        1 => fixed::<1>(patches, src, dst),
        2 => fixed::<2>(patches, src, dst),
        3 => fixed::<3>(patches, src, dst),
        4 => fixed::<4>(patches, src, dst),
        5 => fixed::<5>(patches, src, dst),
        6 => fixed::<6>(patches, src, dst),
        7 => fixed::<7>(patches, src, dst),
        _ => fixed::<MAX_PATCHES>(patches, src, dst),
    }
}

wide_fn! {
    /// `dst[i] = outs[j]` where `src[i] == keys[j]`.
    fn patch_bytes<const N: usize>(src: &[u8], keys: [u8; N], outs: [u8; N], dst: &mut [u8]) {
        for (d, &s) in dst.iter_mut().zip(src) {
            let mut o = *d;
            for j in 0..N {
                // A select, not a conditional store: it vectorises.
                o = if s == keys[j] { outs[j] } else { o };
            }
            *d = o;
        }
    }
}

wide_fn! {
    /// The staircase of [`Form::Steps`] on every byte.
    fn steps_bytes(src: &[u8], levels: u16, scale: u16, dst: &mut [u8]) {
        for (d, &s) in dst.iter_mut().zip(src) {
            *d = step(s, levels, scale);
        }
    }
}

/// The three channel permutations and two arithmetic mixes of C-F1 false colour, on the
/// channels (c0, c1, c2) in the image's own order.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ChannelMix {
    /// (c0, c1, c2) <- (c1, c2, c0).
    Rotate,
    /// c0 and c1 swapped.
    Swap01,
    /// c0 and c2 swapped.
    Swap02,
    /// 255 - c.
    Invert,
    /// Each channel the floored mean of itself and the next: c0 <- (c0 + c1) / 2, c1 <- (c1 + c2)
    /// / 2, c2 <- (c2 + c0) / 2.
    MeanNext,
}

impl ChannelMix {
    /// The five mixes, severities 1..5 of C-F1.
    pub const ALL: [ChannelMix; 5] = [
        ChannelMix::Rotate,
        ChannelMix::Swap01,
        ChannelMix::Swap02,
        ChannelMix::Invert,
        ChannelMix::MeanNext,
    ];

    /// The mix of one pixel's three colour bytes.
    #[inline(always)]
    pub fn pixel(self, [a, b, d]: [u8; 3]) -> [u8; 3] {
        let mean = |x: u8, y: u8| ((x as u16 + y as u16) >> 1) as u8;
        match self {
            ChannelMix::Rotate => [b, d, a],
            ChannelMix::Swap01 => [b, a, d],
            ChannelMix::Swap02 => [d, b, a],
            ChannelMix::Invert => [255 - a, 255 - b, 255 - d],
            ChannelMix::MeanNext => [mean(a, b), mean(b, d), mean(d, a)],
        }
    }

    /// Mixes every pixel of a row of `c`-byte pixels (3 or 4; the fourth byte, alpha, copied).
    pub fn row(self, c: usize, src: &[u8], dst: &mut [u8]) {
        match (c, self) {
            // Inverting every byte of a three-byte format is one flat loop.
            (3, ChannelMix::Invert) => invert_bytes(src, dst),
            (3, _) => mix_pixels::<3>(self, src, dst),
            _ => mix_pixels::<4>(self, src, dst),
        }
    }
}

wide_fn! {
    /// `dst = 255 - src`, byte by byte.
    fn invert_bytes(src: &[u8], dst: &mut [u8]) {
        for (d, s) in dst.iter_mut().zip(src) {
            *d = 255 - s;
        }
    }
}

wide_fn! {
    /// [`ChannelMix::pixel`] of every `C`-byte pixel; a fourth byte is copied.
    fn mix_pixels<const C: usize>(mix: ChannelMix, src: &[u8], dst: &mut [u8]) {
        // One loop per mix, so that each loop body is branch-free.
        macro_rules! each {
            ($m:expr) => {
                for (p, q) in src.chunks_exact(C).zip(dst.chunks_exact_mut(C)) {
                    let [x, y, z] = $m.pixel([p[0], p[1], p[2]]);
                    q[0] = x;
                    q[1] = y;
                    q[2] = z;
                    if C == 4 {
                        q[3] = p[3];
                    }
                }
            };
        }
        match mix {
            ChannelMix::Rotate => each!(ChannelMix::Rotate),
            ChannelMix::Swap01 => each!(ChannelMix::Swap01),
            ChannelMix::Swap02 => each!(ChannelMix::Swap02),
            ChannelMix::Invert => each!(ChannelMix::Invert),
            ChannelMix::MeanNext => each!(ChannelMix::MeanNext),
        }
    }
}

/// C-F5's blend towards the luma, `out = (keep[c] + luma[Y] + 128) >> 8` per colour channel
/// (`Y` the BT.601 luma of the pixel, [`crate::image::luma`]), with both 16-bit tables computed as
/// their 16.16 fixed-point lines (found by [`fit_fixed`]; `None` when a table is no such line).
#[derive(Clone, Copy, Debug)]
pub struct LumaBlend {
    keep: (u32, u32),
    luma: (u32, u32),
}

impl LumaBlend {
    /// The arithmetic form of the tables `keep` and `luma`, if both have one.
    pub fn fit(keep: &[u16; 256], luma: &[u16; 256]) -> Option<Self> {
        let widen = |t: &[u16; 256]| -> [u32; 256] { std::array::from_fn(|v| t[v] as u32) };
        Some(LumaBlend {
            keep: fit_fixed(&widen(keep))?,
            luma: fit_fixed(&widen(luma))?,
        })
    }

    /// Blends one row of `format` pixels (a colour format; alpha copied).
    pub fn row(&self, format: PixelFormat, src: &[u8], dst: &mut [u8]) {
        match format {
            PixelFormat::Rgb8 => luma_blend::<3, 0, 2>(*self, src, dst),
            PixelFormat::Bgr8 => luma_blend::<3, 2, 0>(*self, src, dst),
            PixelFormat::Rgba8 => luma_blend::<4, 0, 2>(*self, src, dst),
            PixelFormat::Bgra8 => luma_blend::<4, 2, 0>(*self, src, dst),
            PixelFormat::Mono8 => dst.copy_from_slice(src),
        }
    }
}

wide_fn! {
    /// [`LumaBlend`] over `C`-byte pixels with red at `R` and blue at `B` (green at 1).
    fn luma_blend<const C: usize, const R: usize, const B: usize>(
        m: LumaBlend,
        src: &[u8],
        dst: &mut [u8],
    ) {
        let ((km, ka), (lm, la)) = (m.keep, m.luma);
        for (p, q) in src.chunks_exact(C).zip(dst.chunks_exact_mut(C)) {
            let (r, g, b) = (p[R] as u32, p[1] as u32, p[B] as u32);
            let y = (r * 19595 + g * 38470 + b * 7471 + 32768) >> 16;
            let ly = ((y * lm + la) >> 16) + 128;
            let blend = |c: u32| ((((c * km + ka) >> 16) + ly) >> 8).min(255) as u8;
            q[R] = blend(r);
            q[1] = blend(g);
            q[B] = blend(b);
            if C == 4 {
                q[3] = p[3];
            }
        }
    }
}

/// Per-colour-channel sums of a row of `c`-byte pixels (red, green, blue at `rgb`), vectorised:
/// 16 pixels' bytes at a time into 32-bit lanes, folded per channel at the end.
pub fn channel_sums(src: &[u8], c: usize, rgb: [usize; 3]) -> [u64; 3] {
    let sums = match c {
        3 => byte_sums::<3, 48>(src),
        4 => byte_sums::<4, 64>(src),
        _ => {
            let s: u64 = src.iter().map(|&v| v as u64).sum();
            return [s; 3];
        }
    };
    rgb.map(|i| sums[i])
}

wide_fn! {
    /// Sums of the bytes of a row at each position modulo `C` (`N = 16 C`).
    fn byte_sums<const C: usize, const N: usize>(src: &[u8]) -> [u64; 4] {
        let mut acc = [0u32; N];
        let mut out = [0u64; 4];
        let mut fold = |acc: &mut [u32; N]| {
            for (i, a) in acc.iter_mut().enumerate() {
                out[i % C] += *a as u64;
                *a = 0;
            }
        };
        let mut chunks = src.chunks_exact(N);
        // A lane holds 2^24 bytes of 255 at most: fold every 65536 chunks (rows are far
        // shorter).
        let mut n = 0;
        for chunk in &mut chunks {
            for (a, &v) in acc.iter_mut().zip(chunk) {
                *a += v as u32;
            }
            n += 1;
            if n == 65536 {
                fold(&mut acc);
                n = 0;
            }
        }
        fold(&mut acc);
        for (i, &v) in chunks.remainder().iter().enumerate() {
            out[i % C] += v as u64;
        }
        out
    }
}

/// C-F4's per-channel tables `out = round((1 - w) v + w min(255, floor(v g)))` computed as
/// `b = min(255, (v gm + ga) >> 16)` and `out = (v w1 + b w2 + add) >> 16`, per channel, when
/// that gives every table entry (checked; `None` otherwise).
#[derive(Clone, Copy, Debug)]
pub struct GainBlend {
    /// Per channel (in the order red, green, blue): gain multiplier and offset.
    gain: [(u32, u32); 3],
    /// Weights of the input and of the balanced value.
    w: (u32, u32),
    /// Per channel: the rounding offset of the blend.
    add: [u32; 3],
}

impl GainBlend {
    /// Fits the three channels' gains `gains` and blend weight `w` to their tables `luts`.
    pub fn fit(gains: [f64; 3], w: f64, luts: &[[u8; 256]; 3]) -> Option<Self> {
        let w1 = ((1.0 - w) * 65536.0).round() as u32;
        let w2 = (w * 65536.0).round() as u32;
        let mut gain = [(0, 0); 3];
        let mut add = [0; 3];
        for k in 0..3 {
            if !(0.0..256.0).contains(&gains[k]) {
                return None;
            }
            let floors: [u32; 256] = std::array::from_fn(|v| (v as f64 * gains[k]).floor() as u32);
            gain[k] = fit_fixed_near(&floors, gains[k])?;
            // The blend's offset: every entry bounds it from both sides.
            let (mut lo, mut hi) = (0i64, i64::MAX);
            for v in 0..256u32 {
                let b = ((v * gain[k].0 + gain[k].1) >> 16).min(255);
                let base = (v * w1 + b * w2) as i64;
                let t = luts[k][v as usize] as i64;
                lo = lo.max((t << 16) - base);
                hi = hi.min(((t + 1) << 16) - base - 1);
            }
            if lo > hi || lo + 255 * 65536 > u32::MAX as i64 {
                return None;
            }
            add[k] = lo as u32;
        }
        Some(GainBlend {
            gain,
            w: (w1, w2),
            add,
        })
    }

    /// Balances one row of `format` pixels (a colour format; alpha copied).
    pub fn row(&self, format: PixelFormat, src: &[u8], dst: &mut [u8]) {
        let [ri, gi, bi] = format.rgb_offsets();
        // The constants of each byte of a pixel: alpha passes through as `v w1 + v w2`, which
        // the blend offset 2^15 rounds back to v (w1 + w2 is 2^16, give or take the weights'
        // rounding).
        let c = format.channels();
        let mut at = [(65536u32, 0u32, 1u32 << 15); 4];
        for (k, i) in [ri, gi, bi].into_iter().enumerate() {
            at[i] = (self.gain[k].0, self.gain[k].1, self.add[k]);
        }
        if !(65535..=65537).contains(&(self.w.0 + self.w.1)) {
            // Alpha would not pass through: weights that do not sum to one (not C-F4's).
            return self.row_by_pixel(c, &at, src, dst);
        }
        match c {
            3 => gain_blend::<48>(std::array::from_fn(|i| at[i % 3]), self.w, src, dst),
            4 => gain_blend::<64>(std::array::from_fn(|i| at[i % 4]), self.w, src, dst),
            _ => dst.copy_from_slice(src),
        }
    }

    fn row_by_pixel(&self, c: usize, at: &[(u32, u32, u32); 4], src: &[u8], dst: &mut [u8]) {
        for (p, q) in src.chunks_exact(c).zip(dst.chunks_exact_mut(c)) {
            for i in 0..3 {
                q[i] = gain_blend_byte(p[i], at[i], self.w);
            }
            if c == 4 {
                q[3] = p[3];
            }
        }
    }
}

#[inline(always)]
fn gain_blend_byte(v: u8, (gm, ga, add): (u32, u32, u32), (w1, w2): (u32, u32)) -> u8 {
    let v = v as u32;
    let b = ((v * gm + ga) >> 16).min(255);
    ((v * w1 + b * w2 + add) >> 16) as u8
}

wide_fn! {
    /// [`GainBlend`] over a row, `N` bytes (16 pixels) at a time with each byte's constants
    /// `at[i]` (gain multiplier, gain offset, blend offset); the rest byte by byte.
    fn gain_blend<const N: usize>(
        at: [(u32, u32, u32); N],
        w: (u32, u32),
        src: &[u8],
        dst: &mut [u8],
    ) {
        let mut s = src.chunks_exact(N);
        let mut d = dst.chunks_exact_mut(N);
        for (s, d) in (&mut s).zip(&mut d) {
            for i in 0..N {
                d[i] = gain_blend_byte(s[i], at[i], w);
            }
        }
        for (i, (q, &p)) in d.into_remainder().iter_mut().zip(s.remainder()).enumerate() {
            *q = gain_blend_byte(p, at[i], w);
        }
    }
}

/// The exact rounding `round(p nv / v)` (halves up) of a channel `p <= v` scaled by `nv / v`, in
/// float: `k = nv / max(v, 1)` is within 2^-24 of the ratio, so `p k` is within 4e-5 of `p nv /
/// v`, while every such fraction that is not a half is at least `1 / 510` from one. Adding 2^-12
/// to the half pushes exact halves up and moves no other value across an integer. A black pixel
/// (`v = 0`) takes `nv` on every channel (`z = 1`).
#[inline(always)]
fn scale_channel(p: f32, z: f32, k: f32) -> f32 {
    (p + z) * k + (0.5 + 1.0 / 4096.0)
}

/// The HSV value of every pixel scaled by `f` and truncated, `V' = min(255, floor(V f))` (C-C4 and
/// C-C5), hue and saturation kept: every colour channel becomes `round(c V' / V)` (halves up), as
/// [`super::ops::map_value`] with the table `V -> min(255, floor(V f))` computes, per pixel in
/// float (`V'` with the table's own float operations) over byte planes of the row. Alpha is copied; mono8 maps its
/// single channel through `mono`.
pub fn scale_value(input: &ImageView<'_>, output: &mut ImageViewMut<'_>, f: f32, mono: &ByteMap) {
    let format = input.format;
    if format.is_mono() {
        return mono.apply(input, output);
    }
    let w = input.width as usize;
    par_rows_with(
        input,
        output,
        || vec![0u8; 3 * w],
        |planes, _, src, dst| {
            scale_value_row(format, f, src, planes, dst);
            copy_alpha(format, src, dst);
        },
    );
}

wide_fn! {
    /// One row of [`scale_value`]; `planes` holds three byte planes of the row's width.
    fn scale_value_row(format: PixelFormat, f: f32, src: &[u8], planes: &mut [u8], dst: &mut [u8]) {
        let w = planes.len() / 3;
        let (r, rest) = planes.split_at_mut(w);
        let (g, b) = rest.split_at_mut(w);
        split_rgb_bytes(src, format, [&mut *r, &mut *g, &mut *b]);
        for ((r, g), b) in r.iter_mut().zip(g.iter_mut()).zip(b.iter_mut()) {
            let v8 = (*r).max(*g).max(*b);
            let v = v8 as f32;
            let nv = (v * f).min(255.0).floor();
            let z = if v8 == 0 { 1.0 } else { 0.0 };
            let k = nv / v.max(1.0);
            *r = byte(scale_channel(*r as f32, z, k));
            *g = byte(scale_channel(*g as f32, z, k));
            *b = byte(scale_channel(*b as f32, z, k));
        }
        merge_rgb(format, [&*r, &*g, &*b], dst);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_posterize_staircase_gives_the_tables_bytes() {
        // Every level count gives the table's bytes; the powers of two (the severities' counts,
        // whose step 255 / L the table's float division represents exactly) as arithmetic.
        for levels in 2..=256u32 {
            let lut = crate::camera::color::posterize_lut(levels);
            let scale = 255 / (levels - 1);
            let m = ByteMap::steps(lut, levels, scale);
            assert!(
                m.is_arithmetic() || !levels.is_power_of_two(),
                "{levels} levels"
            );
            let src: Vec<u8> = (0..=255).collect();
            let mut dst = vec![0; 256];
            m.row(&src, &mut dst);
            assert_eq!(dst, lut, "{levels} levels");
        }
    }

    #[test]
    fn lines_reproduce_their_tables_including_the_float_ties() {
        // Contrast tables (f32 arithmetic, whose ties at f = 1.2 round both ways) and a few
        // clamped lines of other slopes and offsets.
        let contrast = |f: f32| -> [u8; 256] {
            std::array::from_fn(|v| {
                (127.5 + (v as f32 - 127.5) * f).round().clamp(0.0, 255.0) as u8
            })
        };
        let mut cases: Vec<([u8; 256], f64, f64)> = [1.1f32, 1.2, 1.3, 1.5, 1.7, 0.8, 0.5]
            .map(|f| (contrast(f), f as f64, 127.5 * (1.0 - f as f64)))
            .to_vec();
        for (a, b) in [(0.9f64, 12.0f64), (1.05, -3.0), (0.3, 100.0)] {
            let lut = std::array::from_fn(|v| (a * v as f64 + b).round().clamp(0.0, 255.0) as u8);
            cases.push((lut, a, b));
        }
        let src: Vec<u8> = (0..=255).rev().chain(0..=255).collect();
        for (lut, slope, offset) in cases {
            let m = ByteMap::line(lut, slope, offset);
            assert!(m.is_arithmetic(), "slope {slope} offset {offset}");
            let mut dst = vec![0; src.len()];
            m.row(&src, &mut dst);
            let want: Vec<u8> = src.iter().map(|&v| lut[v as usize]).collect();
            assert_eq!(dst, want, "slope {slope} offset {offset}");
        }
        // A table that is no line keeps the lookup, and still maps right.
        let wild: [u8; 256] = std::array::from_fn(|v| (v * 97 % 256) as u8);
        let m = ByteMap::line(wild, 1.0, 0.0);
        assert!(!m.is_arithmetic());
        let mut dst = vec![0; src.len()];
        m.row(&src, &mut dst);
        assert!(src.iter().zip(&dst).all(|(&s, &d)| d == wild[s as usize]));
    }

    #[test]
    fn fixed_point_fits_are_exact_or_absent() {
        for c in [0.1f32, 0.35, 0.55, 0.9, 0.999, 1.0] {
            let table: [u32; 256] = std::array::from_fn(|v| (c * v as f32 * 256.0).round() as u32);
            let (mul, add) = fit_fixed(&table).unwrap_or_else(|| panic!("no fit for {c}"));
            for (v, &t) in table.iter().enumerate() {
                assert_eq!((v as u32 * mul + add) >> 16, t, "c {c} v {v}");
            }
        }
        // Too steep for 32 bits, or not a line: no fit.
        let steep: [u32; 256] = std::array::from_fn(|v| (1.7 * v as f32 * 256.0).round() as u32);
        assert_eq!(fit_fixed(&steep), None);
        let bent: [u32; 256] = std::array::from_fn(|v| (v * v) as u32);
        assert_eq!(fit_fixed(&bent), None);
    }

    #[test]
    fn float_value_scaling_rounds_exactly_like_the_fixed_point() {
        // Every channel p <= v and every new value nv: the float form against map_value's
        // 8.24 fixed point (exact rounding of p nv / v, halves up; black takes nv).
        let recip = crate::camera::ops::reciprocals();
        for v in 0..=255u32 {
            for nv in 0..=255u32 {
                let (k_fixed, z_fixed) = if v == 0 {
                    (nv << 24, 1)
                } else {
                    (((nv as u64 * recip[v as usize] + 255) >> 8) as u32, 0)
                };
                let k = nv as f32 / (v as f32).max(1.0);
                let z = if v == 0 { 1.0 } else { 0.0 };
                for p in 0..=v {
                    let want = (((p + z_fixed) * k_fixed + (1 << 23) + (1 << 12)) >> 24) as u8;
                    let got = byte(scale_channel(p as f32, z, k));
                    assert_eq!(got, want, "p {p} v {v} nv {nv}");
                }
            }
        }
    }

    #[test]
    fn luma_and_gain_blends_reproduce_their_tables() {
        // Grayscale's two tables at every severity fit, and the blend equals the table formula
        // on every (channel, luma) pair.
        for w in crate::camera::color::GRAYSCALE_WEIGHT {
            let keep: [u16; 256] =
                std::array::from_fn(|v| ((1.0 - w) * v as f32 * 256.0).round() as u16);
            let luma: [u16; 256] = std::array::from_fn(|v| (w * v as f32 * 256.0).round() as u16);
            let m = LumaBlend::fit(&keep, &luma).expect("grayscale tables fit");
            let ((km, ka), (lm, la)) = (m.keep, m.luma);
            for c in 0..256u32 {
                assert_eq!(
                    (c * km + ka) >> 16,
                    keep[c as usize] as u32,
                    "w {w} keep {c}"
                );
                assert_eq!(
                    (c * lm + la) >> 16,
                    luma[c as usize] as u32,
                    "w {w} luma {c}"
                );
            }
        }
        // White balance: gains from dark to bright channels, every weight.
        let mut fitted = 0;
        for w in crate::camera::color::WHITE_BALANCE_WEIGHT.map(|w| w as f64) {
            for gains in [
                [1.0, 1.0, 1.0],
                [0.73, 1.21, 1.4],
                [2.9, 0.5, 1.0001],
                [0.0, 7.3, 1.0],
            ] {
                let luts: [[u8; 256]; 3] = std::array::from_fn(|k| {
                    std::array::from_fn(|v| {
                        let b = (v as f64 * gains[k]).min(255.0).floor();
                        ((1.0 - w) * v as f64 + w * b).round().clamp(0.0, 255.0) as u8
                    })
                });
                let Some(m) = GainBlend::fit(gains, w, &luts) else {
                    continue;
                };
                fitted += 1;
                for format in [PixelFormat::Rgb8, PixelFormat::Bgra8] {
                    let c = format.channels();
                    let src: Vec<u8> = (0..256 * c).map(|i| (i / c) as u8).collect();
                    let mut dst = vec![0; src.len()];
                    m.row(format, &src, &mut dst);
                    let [ri, gi, bi] = format.rgb_offsets();
                    for (v, q) in dst.chunks_exact(c).enumerate() {
                        let got = [q[ri], q[gi], q[bi]];
                        let want = [luts[0][v], luts[1][v], luts[2][v]];
                        assert_eq!(got, want, "w {w} gains {gains:?} v {v} {format}");
                    }
                }
            }
        }
        assert!(fitted >= 15, "only {fitted} of 20 white balances fitted");
    }

    #[test]
    fn channel_sums_match_a_plain_sum() {
        let row: Vec<u8> = (0..4 * 301).map(|i| (i * 37 % 256) as u8).collect();
        for (c, rgb) in [(3, [0, 1, 2]), (3, [2, 1, 0]), (4, [2, 1, 0])] {
            let n = row.len() / c * c;
            let want: [u64; 3] = rgb.map(|o| row[..n].chunks_exact(c).map(|p| p[o] as u64).sum());
            assert_eq!(channel_sums(&row[..n], c, rgb), want, "{c} {rgb:?}");
        }
    }
}
