//! Blends across channels: C-F1's channel mixes, C-F5's blend towards the luma, C-F4's gain blend.

use super::bytemap::{fit_fixed, fit_fixed_near};
use crate::camera::ops::{copy_alpha, merge_rgb, split_rgb_bytes, three_planes, wide_fn};
use crate::image::PixelFormat;

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
///
/// Where both tables also have a [`Split16`] form (every C-F5 severity does) and the CPU has
/// AVX2, rows run in 16-bit lanes over byte planes ([`LumaBlend::row_in`]), with the same bytes.
#[derive(Clone, Copy, Debug)]
pub struct LumaBlend {
    keep: (u32, u32),
    luma: (u32, u32),
    /// The tables in 16-bit arithmetic, when both have that form and their sum stays in 16 bits.
    narrow: Option<(Split16, Split16)>,
}

/// A table `t[v] = a v + ((b v + 2^15) >> 16)` for every byte `v`: a slope with a 16-bit whole part
/// and a 16-bit fraction, rounded once, with `b` even, which 16-bit lanes compute exactly in two
/// multiplies: `a v` by multiply-low, and the rounded fraction by the rounding multiply-high
/// `(v (b / 2) + 2^14) >> 15` (`vpmulhrsw`, signed: `b / 2` is below 2^15).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Split16 {
    /// Whole part of the slope.
    pub a: u16,
    /// Fraction of the slope, in 2^-16.
    pub b: u16,
}

impl Split16 {
    /// The form of `table`, if it has one with an even `b` (searched around the table's mean
    /// slope; every C-F5 table has many).
    pub fn fit(table: &[u16; 256]) -> Option<Self> {
        let slope = (table[255] as f64 - table[0] as f64) / 255.0;
        if !(0.0..256.0).contains(&slope) {
            return None;
        }
        let a = slope.floor() as u16;
        let b0 = ((slope - a as f64) * 65536.0).round() as i64;
        (0..=4096)
            .flat_map(|d| [b0 - d, b0 + d])
            .filter_map(|b| u16::try_from(b).ok())
            .filter(|b| b % 2 == 0)
            .map(|b| Split16 { a, b })
            .find(|f| (0..=255u8).all(|v| f.eval(v as u16) == table[v as usize] as u32))
    }

    /// `a v + ((b v + 2^15) >> 16)`.
    #[inline(always)]
    pub fn eval(self, v: u16) -> u32 {
        self.a as u32 * v as u32 + ((self.b as u32 * v as u32 + (1 << 15)) >> 16)
    }
}

impl LumaBlend {
    /// The arithmetic form of the tables `keep` and `luma`, if both have one.
    pub fn fit(keep: &[u16; 256], luma: &[u16; 256]) -> Option<Self> {
        let widen = |t: &[u16; 256]| -> [u32; 256] { std::array::from_fn(|v| t[v] as u32) };
        let narrow = match (Split16::fit(keep), Split16::fit(luma)) {
            // The sum keep + luma + 128 must stay below 2^16 for every channel and luma.
            (Some(k), Some(l)) if keep[255] as u32 + luma[255] as u32 + 128 <= 65535 => {
                Some((k, l))
            }
            _ => None,
        };
        Some(LumaBlend {
            keep: fit_fixed(&widen(keep))?,
            luma: fit_fixed(&widen(luma))?,
            narrow,
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

    /// [`Self::row`] in 16-bit lanes where the tables have that form and the CPU has AVX2 (RGB
    /// and BGR rows row to row, other layouts through byte planes: `planes` grows to three bytes
    /// per pixel and can be reused from row to row); the same bytes.
    pub fn row_in(&self, format: PixelFormat, src: &[u8], dst: &mut [u8], planes: &mut Vec<u8>) {
        let Some((keep, luma)) = self.narrow else {
            return self.row(format, src, dst);
        };
        if format.is_mono() || !crate::camera::ops::wide_available() {
            return self.row(format, src, dst);
        }
        planes.resize(3 * (src.len() / format.channels()), 0);
        luma_blend_planar(*self, (keep, luma), format, src, planes, dst);
    }

    /// The blend of one pixel's red, green and blue.
    #[inline(always)]
    fn pixel(&self, r: u8, g: u8, b: u8) -> [u8; 3] {
        let ((km, ka), (lm, la)) = (self.keep, self.luma);
        let (r, g, b) = (r as u32, g as u32, b as u32);
        let y = (r * 19595 + g * 38470 + b * 7471 + 32768) >> 16;
        let ly = ((y * lm + la) >> 16) + 128;
        let blend = |c: u32| ((((c * km + ka) >> 16) + ly) >> 8).min(255) as u8;
        [blend(r), blend(g), blend(b)]
    }
}

wide_fn! {
    /// [`LumaBlend`] over `C`-byte pixels with red at `R` and blue at `B` (green at 1).
    fn luma_blend<const C: usize, const R: usize, const B: usize>(
        m: LumaBlend,
        src: &[u8],
        dst: &mut [u8],
    ) {
        for (p, q) in src.chunks_exact(C).zip(dst.chunks_exact_mut(C)) {
            [q[R], q[1], q[B]] = m.pixel(p[R], p[1], p[B]);
            if C == 4 {
                q[3] = p[3];
            }
        }
    }
}

wide_fn! {
    /// [`LumaBlend::row_in`]: blended 32 pixels at a time in 16-bit lanes, straight from row to
    /// row for RGB and BGR, otherwise (and for the tail) with the row split into the three byte
    /// planes of `planes` and merged back (the last pixels one by one); alpha copied.
    fn luma_blend_planar(
        m: LumaBlend,
        narrow: (Split16, Split16),
        format: PixelFormat,
        src: &[u8],
        planes: &mut [u8],
        dst: &mut [u8],
    ) {
        // RGB and BGR rows' whole blocks straight from row to row, the rest through planes.
        let direct = match format {
            PixelFormat::Rgb8 | PixelFormat::Bgr8 => {
                let bgr = format == PixelFormat::Bgr8;
                super::avx2::luma_blend_rgb(narrow.0, narrow.1, bgr, src, dst)
            }
            _ => 0,
        };
        let (src, dst) = (&src[3 * direct..], &mut dst[3 * direct..]);
        let w = planes.len() / 3 - direct;
        let [r, g, b] = three_planes(planes, w);
        split_rgb_bytes(src, format, [&mut *r, &mut *g, &mut *b]);
        let done = super::avx2::luma_blend_planes(narrow.0, narrow.1, r, g, b);
        let rest = r[done..].iter_mut().zip(&mut g[done..]).zip(&mut b[done..]);
        for ((r, g), b) in rest {
            [*r, *g, *b] = m.pixel(*r, *g, *b);
        }
        merge_rgb(format, [&*r, &*g, &*b], dst);
        copy_alpha(format, src, dst);
    }
}

/// Per-colour-channel sums of a row of `c`-byte pixels (red, green, blue at `rgb`), vectorised:
/// 16 pixels' bytes at a time into 32-bit lanes, folded per channel at the end.
pub fn channel_sums(src: &[u8], c: usize, rgb: [usize; 3]) -> [u64; 3] {
    // The whole blocks through `vpsadbw` where the CPU has AVX2, the rest in 32-bit lanes.
    fn both<const C: usize, const N: usize>(src: &[u8]) -> [u64; 4] {
        let (head, done) = super::avx2::channel_byte_sums::<C>(src);
        if done == src.len() {
            return head;
        }
        let rest = byte_sums::<C, N>(&src[done..]);
        std::array::from_fn(|i| head[i] + rest[i])
    }
    let sums = match c {
        3 => both::<3, 48>(src),
        4 => both::<4, 64>(src),
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
///
/// Where the CPU has AVX2 the rows run in 16-bit lanes: the gain's 16.16 product split into an
/// integer and a fraction part (`a v + mulhi(v, f)` plus the carry of the low product and `ga`,
/// the same value), and the blend as `v + ((mulhi(64 (b - v), W) + K) >> 5)`, `W` and `K` fitted
/// per channel to the table (see [`narrow_byte`]; without a fit the 32-bit form runs).
#[derive(Clone, Copy, Debug)]
pub struct GainBlend {
    /// Per channel (in the order red, green, blue): gain multiplier and offset.
    gain: [(u32, u32); 3],
    /// Weights of the input and of the balanced value.
    w: (u32, u32),
    /// Per channel: the rounding offset of the blend.
    add: [u32; 3],
    /// Per channel: the 16-bit blend's weight and offset, where one gives the table.
    narrow: Option<[(i16, i16); 3]>,
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
        let narrow = (0..3)
            .map(|k| fit_narrow_blend(gain[k], w, &luts[k]))
            .collect::<Option<Vec<_>>>()
            .map(|n| [n[0], n[1], n[2]]);
        Some(GainBlend {
            gain,
            w: (w1, w2),
            add,
            narrow,
        })
    }

    /// Whether the rows run in 16-bit lanes where the CPU has AVX2 (a blend fitted every
    /// channel's table).
    pub fn is_narrow(&self) -> bool {
        self.narrow.is_some()
    }

    /// The constants of each byte of a `format` pixel, for [`GainRows::row`].
    pub fn rows(&self, format: PixelFormat) -> GainRows {
        let [ri, gi, bi] = format.rgb_offsets();
        // Alpha passes through as `v w1 + v w2`, which the blend offset 2^15 rounds back to v
        // (w1 + w2 is 2^16, give or take the weights' rounding); in 16-bit lanes as a gain of
        // one and a blend of nothing.
        let mut at = [(65536u32, 0u32, 1u32 << 15); 4];
        let mut narrow_at = [(65536u32, 0u32, 0i16, 0i16); 4];
        for (k, i) in [ri, gi, bi].into_iter().enumerate() {
            at[i] = (self.gain[k].0, self.gain[k].1, self.add[k]);
            if let Some(n) = self.narrow {
                narrow_at[i] = (self.gain[k].0, self.gain[k].1, n[k].0, n[k].1);
            }
        }
        let c = format.channels();
        let lanes = self.narrow.filter(|_| c >= 3).map(|_| {
            Box::new(super::avx2::gain_lanes(c, |i| {
                let (gm, ga, w, k) = narrow_at[i];
                [(gm >> 16) as u16, gm as u16, ga as u16, w as u16, k as u16]
            }))
        });
        GainRows {
            at,
            w: self.w,
            c,
            lanes,
        }
    }
}

/// A [`GainBlend`] ready for the rows of one pixel format.
#[derive(Clone, Debug)]
pub struct GainRows {
    /// Per byte of a pixel: gain multiplier, gain offset, blend offset.
    at: [(u32, u32, u32); 4],
    /// Weights of the input and of the balanced value.
    w: (u32, u32),
    /// Bytes per pixel.
    c: usize,
    /// The 16-bit lanes' constants, where the blend fitted.
    lanes: Option<Box<super::avx2::GainLanes>>,
}

impl GainRows {
    /// Balances one row of pixels (a colour format; alpha copied).
    pub fn row(&self, src: &[u8], dst: &mut [u8]) {
        let c = self.c;
        if !(65535..=65537).contains(&(self.w.0 + self.w.1)) {
            // Alpha would not pass through: weights that do not sum to one (not C-F4's).
            return self.row_by_pixel(src, dst);
        }
        let done = match (&self.lanes, c) {
            (Some(lanes), 3) => super::avx2::gain_blend::<3>(lanes, src, dst),
            (Some(lanes), 4) => super::avx2::gain_blend::<4>(lanes, src, dst),
            _ => 0,
        };
        let (src, dst) = (&src[done..], &mut dst[done..]);
        if src.is_empty() {
            return;
        }
        match c {
            3 => gain_blend::<48>(std::array::from_fn(|i| self.at[i % 3]), self.w, src, dst),
            4 => gain_blend::<64>(std::array::from_fn(|i| self.at[i % 4]), self.w, src, dst),
            _ => dst.copy_from_slice(src),
        }
    }

    fn row_by_pixel(&self, src: &[u8], dst: &mut [u8]) {
        let c = self.c;
        for (p, q) in src.chunks_exact(c).zip(dst.chunks_exact_mut(c)) {
            for i in 0..3 {
                q[i] = gain_blend_byte(p[i], self.at[i], self.w);
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

/// The 16-bit lanes' byte: the balanced value `b = min(255, (v gm + ga) >> 16)` (what the lanes
/// compute as `(gm >> 16) v + mulhi(v, gm & 0xffff)` plus a carry), then the blend
/// `v + ((mulhi(64 (b - v), w) + k) >> 5)` with the signed 16-bit multiply-high
/// `mulhi(x, w) = floor(x w / 2^16)`, that is `v + floor((b - v) w / 2^15 + k / 32)`.
pub fn narrow_byte(v: u8, (gm, ga): (u32, u32), (w, k): (i16, i16)) -> u8 {
    let v = v as i32;
    let b = ((v as u32 * gm + ga) >> 16).min(255) as i32;
    let high = (64 * (b - v) * w as i32) >> 16;
    (v + ((high + k as i32) >> 5)) as u8
}

/// The 16-bit blend `(w, k)` of [`narrow_byte`] that gives `lut` for the gain `gain`, searched
/// near `w 2^15`: for each weight every entry bounds `k` from both sides.
fn fit_narrow_blend(gain: (u32, u32), w: f64, lut: &[u8; 256]) -> Option<(i16, i16)> {
    let w0 = (w * 32768.0).round() as i32;
    let pairs: [(i32, i32); 256] = std::array::from_fn(|v| {
        let b = ((v as u32 * gain.0 + gain.1) >> 16).min(255) as i32;
        (b - v as i32, lut[v] as i32 - v as i32)
    });
    let weights = std::iter::once(w0).chain((1..=16).flat_map(|step| [w0 - step, w0 + step]));
    for weight in weights.filter(|w| (0..=32767).contains(w)) {
        // floor((high + k) / 32) == want  <=>  32 want - high <= k <= 32 want + 31 - high
        let (mut lo, mut hi) = (-1024, 1024);
        for &(d, want) in &pairs {
            let high = (64 * d * weight) >> 16;
            lo = lo.max(32 * want - high);
            hi = hi.min(32 * want + 31 - high);
        }
        if lo <= hi {
            let fit = (weight as i16, lo as i16);
            // The bound is exact; checked once more on the bytes themselves.
            if (0..=255u8).all(|v| narrow_byte(v, gain, fit) == lut[v as usize]) {
                return Some(fit);
            }
        }
    }
    None
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn luma_and_gain_blends_reproduce_their_tables() {
        // Grayscale's two tables at every severity fit, and the blend equals the table formula
        // on every (channel, luma) pair.
        for w in crate::camera::color::GRAYSCALE_WEIGHT {
            let (keep, luma) = crate::camera::color::grayscale_tables(w);
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
        let (mut fitted, mut narrow) = (0, 0);
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
                narrow += m.is_narrow() as usize;
                for format in [PixelFormat::Rgb8, PixelFormat::Bgra8] {
                    let c = format.channels();
                    let rows = m.rows(format);
                    // Every value at every place of a 32-pixel block, and rows whose tails
                    // are not whole blocks; alpha is kept.
                    for px in [256 + 32 * 31, 256 + 7, 31] {
                        let src: Vec<u8> =
                            (0..px * c).map(|i| (i / c + i / (32 * c)) as u8).collect();
                        let mut dst = vec![0; src.len()];
                        rows.row(&src, &mut dst);
                        let [ri, gi, bi] = format.rgb_offsets();
                        for (p, q) in src.chunks_exact(c).zip(dst.chunks_exact(c)) {
                            let got = [q[ri], q[gi], q[bi]];
                            let want = [0, 1, 2].map(|k| luts[k][p[[ri, gi, bi][k]] as usize]);
                            assert_eq!(got, want, "w {w} gains {gains:?} {p:?} {format}");
                            if c == 4 {
                                assert_eq!(q[3], p[3], "alpha");
                            }
                        }
                    }
                }
            }
        }
        assert!(fitted >= 15, "only {fitted} of 20 white balances fitted");
        assert_eq!(
            narrow, fitted,
            "the 16-bit blend fitted {narrow} of {fitted}"
        );
    }

    #[test]
    fn the_16_bit_luma_blend_gives_the_bytes_of_the_32_bit_one() {
        // Every severity's tables have the 16-bit form, equal to the tables on every byte; the
        // 16-bit luma split into high and low coefficient bytes equals the luma on every colour;
        // rows through the planes (AVX2 blocks and the scalar tail) equal the pixel-by-pixel rows
        // for every format and many lengths.
        for w in crate::camera::color::GRAYSCALE_WEIGHT {
            let (keep, luma) = crate::camera::color::grayscale_tables(w);
            let m = LumaBlend::fit(&keep, &luma).expect("grayscale tables fit");
            let (k, l) = m.narrow.expect("16-bit forms");
            for v in 0..=255u16 {
                assert_eq!(k.eval(v), keep[v as usize] as u32, "w {w} keep {v}");
                assert_eq!(l.eval(v), luma[v as usize] as u32, "w {w} luma {v}");
            }
            let pixels: Vec<u8> = (0..4 * 300u32).map(|i| (i * 97 + i / 7) as u8).collect();
            let mut planes = Vec::new();
            for format in [
                PixelFormat::Rgb8,
                PixelFormat::Bgr8,
                PixelFormat::Rgba8,
                PixelFormat::Bgra8,
            ] {
                let c = format.channels();
                for n in (0..40).chain([255, 300]) {
                    let src = &pixels[..n * c];
                    let (mut want, mut got) = (vec![0; n * c], vec![0; n * c]);
                    m.row(format, src, &mut want);
                    m.row_in(format, src, &mut got, &mut planes);
                    assert_eq!(got, want, "w {w} {format} {n} pixels");
                }
            }
        }
        for r in 0..=255u32 {
            for g in 0..=255u32 {
                for b in 0..=255u32 {
                    let hi = r * 76 + g * 150 + b * 29;
                    let lo = r * 139 + g * 70 + b * 47;
                    let y = (hi + (lo >> 8) + 128) >> 8;
                    assert_eq!(y, crate::image::luma(r as u8, g as u8, b as u8) as u32);
                }
            }
        }
    }

    #[test]
    fn channel_sums_match_a_plain_sum() {
        // Every length from none to several whole blocks (of 32 pixels) and a tail; a row of
        // 255s too (the widest sums).
        let mixed: Vec<u8> = (0..4 * 301).map(|i| (i * 37 % 256) as u8).collect();
        let white = vec![255u8; 4 * 301];
        for row in [mixed, white] {
            for (c, rgb) in [(3, [0, 1, 2]), (3, [2, 1, 0]), (4, [2, 1, 0])] {
                for px in 0..=301 {
                    let row = &row[..px * c];
                    let want: [u64; 3] =
                        rgb.map(|o| row.chunks_exact(c).map(|p| p[o] as u64).sum());
                    assert_eq!(channel_sums(row, c, rgb), want, "{c} {rgb:?} {px} pixels");
                }
            }
        }
    }
}
