//! Hue, saturation and tone per pixel (C-F1 white balance, C-F4 false colour, C-F5 grayscale,
//! C-F6/C-F8 saturation, C-F7 posterize).

use super::refuse_mono;
use crate::camera::ops::{SaturationMap, par_rows, par_rows_with};
use crate::camera::pointwise::{ByteMap, ChannelMix, GainBlend, LumaBlend, channel_sums};
use crate::camera::{CameraBuilder, CameraPerturbation, CameraSetup};
use crate::image::{ImageView, ImageViewMut};

/// C-F5 grayscale: blend weight towards the luma, severities 1..5 (PerturbationDrive
/// `grayscale_filter`).
pub const GRAYSCALE_WEIGHT: [f32; 5] = [0.10, 0.20, 0.35, 0.55, 0.85];

/// C-F5 grayscale: `out = (1 - s) I + s Y` per colour channel with `Y = .299 R + .587 G + .114 B`,
/// in 8.8 fixed point (two 256-entry tables for the two terms), rounded; alpha is copied. The
/// tables are computed as 16.16 fixed-point lines in 32-bit lanes, or with AVX2 as split 16-bit
/// slopes in 16-bit lanes over byte planes (same bytes, see [`LumaBlend`]). Mono8 input is refused: it is already grey, so the perturbation would do
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
        let (keep, luma) = grayscale_tables(GRAYSCALE_WEIGHT[setup.level()]);
        Grayscale {
            keep,
            luma,
            fast: LumaBlend::fit(&keep, &luma),
        }
    }
}

/// C-F5's two tables for the blend weight `w`, in 8.8 fixed point: the kept part of a channel
/// `round((1 - w) v 256)` and the luma's part `round(w v 256)`.
pub fn grayscale_tables(w: f32) -> ([u16; 256], [u16; 256]) {
    (
        std::array::from_fn(|v| ((1.0 - w) * v as f32 * 256.0).round() as u16),
        std::array::from_fn(|v| (w * v as f32 * 256.0).round() as u16),
    )
}

impl CameraPerturbation for Grayscale {
    fn apply(&self, input: &ImageView<'_>, output: &mut ImageViewMut<'_>, _seq: u64) {
        let format = input.format;
        if let Some(fast) = &self.fast {
            return par_rows_with(input, output, Vec::new, |planes, _, src, dst| {
                fast.row_in(format, src, dst, planes)
            });
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
/// (truncated, as the reference's uint8 write), hue and value kept; see [`SaturationMap`] for how
/// this is computed in RGB. Mono8 is refused.
pub struct Saturation {
    map: SaturationMap,
}

impl Saturation {
    /// Saturation scaled by `m`.
    pub fn new(m: f32) -> Self {
        Saturation {
            map: SaturationMap::scaled(m),
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
        self.map.apply(input, output);
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
/// table is computed as one AND per byte (s1-s3, 32 levels and more) or one 16-entry lookup of
/// the byte's high half (s4, s5), with the input 255 patched where it differs (same bytes, see
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
            let rows = fast.rows(format);
            return par_rows(input, output, |_, src, dst| rows.row(src, dst));
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
