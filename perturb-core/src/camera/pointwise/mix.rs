//! Blends across channels: C-F1's channel mixes, C-F5's blend towards the luma, C-F4's gain blend.

use super::bytemap::{fit_fixed, fit_fixed_near};
use crate::camera::ops::wide_fn;
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

#[cfg(test)]
mod tests {
    use super::*;

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
