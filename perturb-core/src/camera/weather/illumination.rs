//! Illumination (C-C4, C-C5, C-C6, C-C11): brightness up and down, contrast, sun glare.

use super::{OVERLAY_WEIGHT, blend_px};
use crate::camera::ops::par_rows;
use crate::camera::pointwise::{ByteMap, scale_value};
use crate::camera::{CameraBuilder, CameraPerturbation};
use crate::image::{ImageView, ImageViewMut};
use crate::math::Portable;
use crate::rng::Rng;

/// The HSV value scaled by a factor and truncated, `V' = min(255, floor(V f))`, hue and
/// saturation kept: what [`crate::camera::ops::map_value`] computes with that table, in float planes (see
/// [`scale_value`]; the same bytes).
pub struct ValueScale {
    factor: f32,
    /// The table, for mono8 (whose one channel is the value).
    mono: ByteMap,
}

impl ValueScale {
    /// Value scaled by `f`.
    pub fn new(f: f32) -> Self {
        ValueScale {
            factor: f,
            mono: ByteMap::line(value_lut(f), f as f64, -0.5),
        }
    }
}

impl CameraPerturbation for ValueScale {
    fn apply(&self, input: &ImageView<'_>, output: &mut ImageViewMut<'_>, _seq: u64) {
        scale_value(input, output, self.factor, &self.mono);
    }
}

/// C-C4 brightness_increase: value factor, severities 1..5 (PerturbationDrive
/// `increase_brightness`).
pub const BRIGHTNESS_INCREASE: [f32; 5] = [1.1, 1.2, 1.3, 1.5, 1.7];
/// C-C5 brightness_decrease: value factor, severities 1..5 (the project's mirror of
/// `increase_brightness`; the reference has no decrease, see the catalogue).
pub const BRIGHTNESS_DECREASE: [f32; 5] = [0.9, 0.8, 0.7, 0.5, 0.3];

fn value_lut(f: f32) -> [u8; 256] {
    std::array::from_fn(|v| (v as f32 * f).min(255.0) as u8)
}

/// C-C4 brightness_increase: over-exposure, HSV `V <- min(255, V f)` truncated as the reference's
/// uint8 write, hue and saturation kept (computed in RGB, see [`crate::camera::ops::map_value`]).
pub const BRIGHTNESS_UP: CameraBuilder =
    |s| Ok(Box::new(ValueScale::new(BRIGHTNESS_INCREASE[s.level()])));

/// C-C5 brightness_decrease: under-exposure, HSV `V <- V f`, the mirror of C-C4.
pub const BRIGHTNESS_DOWN: CameraBuilder =
    |s| Ok(Box::new(ValueScale::new(BRIGHTNESS_DECREASE[s.level()])));

/// C-C6 contrast: contrast factor, severities 1..5 (PerturbationDrive `contrast`, increase only).
pub const CONTRAST_FACTOR: [f32; 5] = [1.1, 1.2, 1.3, 1.5, 1.7];

/// C-C6 contrast: `out = clip(127.5 + (I - 127.5) f)` on every channel, rounded (the reference
/// returns floats). A per-value table, computed as a clamped line in 16-bit integer arithmetic
/// (same bytes, see [`ByteMap::line`]).
pub struct Contrast {
    map: ByteMap,
}

/// Registry constructor of C-C6.
pub const CONTRAST: CameraBuilder = |s| {
    let f = CONTRAST_FACTOR[s.level()];
    let lut =
        std::array::from_fn(|v| (127.5 + (v as f32 - 127.5) * f).round().clamp(0.0, 255.0) as u8);
    Ok(Box::new(Contrast {
        map: ByteMap::line(lut, f as f64, 127.5 * (1.0 - f as f64)),
    }))
};

impl CameraPerturbation for Contrast {
    fn apply(&self, input: &ImageView<'_>, output: &mut ImageViewMut<'_>, _seq: u64) {
        self.map.apply(input, output);
    }
}

/// C-C11 sun_glare: a low sun in the frame with a bright core, a halo, a horizontal streak and lens
/// ghosts, procedural and animated, blended with the overlay weight i = .15 .25 .40 .60 .85. The
/// sun drifts slowly on a path set by the seed (frame n computed from (seed, n)); the ghosts lie on
/// the line from the sun through the image centre, in tinted colours, as a lens flare does. The
/// radial and streak profiles are tables built at configuration time.
pub struct SunGlare {
    seed: u64,
    weight: f32,
    /// Coverage by squared distance from the core, in units of (scale / 64)^2.
    radial: Vec<f32>,
}

/// Registry constructor of C-C11.
pub const SUN_GLARE: CameraBuilder = |s| {
    let radial = (0..64 * 64 * 4)
        .map(|d2| {
            let d = (d2 as f32).sqrt() / 64.0; // in units of the core radius
            let core = (-(d * d) / 0.5).pexp();
            let halo = 0.55 * (-d / 3.0).pexp();
            (core + halo).min(1.0)
        })
        .collect();
    Ok(Box::new(SunGlare {
        seed: s.seed,
        weight: OVERLAY_WEIGHT[s.level()],
        radial,
    }))
};

impl CameraPerturbation for SunGlare {
    fn apply(&self, input: &ImageView<'_>, output: &mut ImageViewMut<'_>, seq: u64) {
        let (w, h) = (input.width as f32, input.height as f32);
        let mut rng = Rng::for_setup(self.seed, 0xC11);
        let (bx, by, phase) = (
            0.2 + 0.6 * rng.f32(),
            0.1 + 0.2 * rng.f32(),
            rng.f32() * 100.0,
        );
        let t = seq as f32 + phase;
        let sx = (bx + 0.06 * (t / 90.0).psin()) * w;
        let sy = (by + 0.03 * (t / 130.0).pcos()) * h;
        let core = 0.16 * w.min(h);
        let format = input.format;
        let c = format.channels();
        let [ri, gi, bi] = format.rgb_offsets();
        let wgt = self.weight;
        let table = &self.radial;
        let unit2 = (core / 64.0) * (core / 64.0);
        let streak_h = 0.02 * h;
        // The streak's horizontal falloff, per column.
        let falloff: Vec<f32> = (0..input.width)
            .map(|x| (-((x as f32 - sx).abs() / w) * 1.5).pexp())
            .collect();
        // Beyond this many pixels from the sun the radial table is 0.
        let reach = (table.len() as f32 * unit2).sqrt().ceil() + 1.0;
        par_rows(input, output, |y, src, dst| {
            let dy = y as f32 - sy;
            let streak_v = (-(dy * dy) / (2.0 * streak_h * streak_h)).pexp();
            // Where neither the streak nor the radial profile reaches, coverage rounds to 0.
            let streak_off = streak_v * 0.9 * wgt * 256.0 < 1.0;
            let (x0, x1) = if !streak_off {
                (0, input.width as usize)
            } else if dy.abs() >= reach {
                (0, 0)
            } else {
                (
                    (sx - reach).floor().max(0.0) as usize,
                    ((sx + reach).ceil().max(0.0) as usize).min(input.width as usize),
                )
            };
            let x1 = x1.max(x0);
            dst[..x0 * c].copy_from_slice(&src[..x0 * c]);
            dst[x1 * c..].copy_from_slice(&src[x1 * c..]);
            for (x, (p, q)) in src[x0 * c..x1 * c]
                .chunks_exact(c)
                .zip(dst[x0 * c..x1 * c].chunks_exact_mut(c))
                .enumerate()
            {
                let x = x + x0;
                let dx = x as f32 - sx;
                let d2 = (dx * dx + dy * dy) / unit2;
                let mut a = if (d2 as usize) < table.len() {
                    table[d2 as usize]
                } else {
                    0.0
                };
                a = a.max(streak_v * 0.9 * falloff[x]);
                let t = (a * wgt * 256.0) as u32;
                if t == 0 {
                    q.copy_from_slice(p);
                    continue;
                }
                if format.is_mono() {
                    q[0] = ((p[0] as u32 * (256 - t) + 252 * t) >> 8) as u8;
                    continue;
                }
                for (ch, v) in [(ri, 255u32), (gi, 248), (bi, 225)] {
                    q[ch] = ((p[ch] as u32 * (256 - t) + v * t) >> 8) as u8;
                }
                if let Some(al) = format.alpha_offset() {
                    q[al] = p[al];
                }
            }
        });
        // Ghosts along the line through the centre.
        let (cx, cy) = (w / 2.0, h / 2.0);
        for (k, (pos, rad, col)) in [
            (0.6f32, 0.25f32, [120.0, 255.0, 140.0]),
            (1.2, 0.5, [200.0, 120.0, 255.0]),
            (1.6, 0.35, [255.0, 180.0, 90.0]),
            (2.0, 0.8, [130.0, 200.0, 255.0]),
        ]
        .into_iter()
        .enumerate()
        {
            let (gx, gy) = (sx + (cx - sx) * pos, sy + (cy - sy) * pos);
            let r = core * rad * (1.0 + k as f32 * 0.3);
            let ri_ = r.ceil() as i64;
            for oy in -ri_..=ri_ {
                for ox in -ri_..=ri_ {
                    let d = ((ox * ox + oy * oy) as f32).sqrt() / r;
                    if d <= 1.0 {
                        let cov = 0.22 * (1.0 - d * d) * wgt;
                        blend_px(output, gx as i64 + ox, gy as i64 + oy, col, cov);
                    }
                }
            }
        }
    }
}
