//! Weather and illumination family (C-C): frost, snow, fog, brightness, contrast and the animated
//! overlays (rain, raindrops, lightning, smoke, sun glare, snowflakes).

use super::ops::{SaturationMap, apply_lut, copy_alpha, par_rows};
use super::pointwise::{ByteMap, scale_value};
use super::texture::{fbm, size_scale, value_noise};
use super::{CameraBuilder, CameraPerturbation};
use crate::image::{ImageView, ImageViewMut, PixelFormat};
use crate::rng::Rng;
use rayon::prelude::*;

/// The HSV value scaled by a factor and truncated, `V' = min(255, floor(V f))`, hue and
/// saturation kept: what [`super::ops::map_value`] computes with that table, in float planes (see
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
/// uint8 write, hue and saturation kept (computed in RGB, see [`super::ops::map_value`]).
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

/// The overlay blend weight of the animated effects (rain, lightning, smoke, sun glare) at
/// severities 1..5: the references' `out = (1 - i) I + i O` wherever the effect is present.
pub const OVERLAY_WEIGHT: [f32; 5] = [0.15, 0.25, 0.40, 0.60, 0.85];

/// Blends one row of a full-frame texture: `out = (1 - i) I + i T` per colour channel, with `t` the
/// weight `i` in 8.8 fixed point; alpha is copied.
fn blend_texture_row(format: PixelFormat, src: &[u8], tex: &[[u8; 3]], t: u32, dst: &mut [u8]) {
    let mix = |p: u8, v: u8| ((p as u32 * (256 - t) + v as u32 * t + 128) >> 8) as u8;
    let [ri, gi, bi] = format.rgb_offsets();
    match format.channels() {
        _ if format.is_mono() => {
            for ((p, q), tex) in src.iter().zip(dst.iter_mut()).zip(tex) {
                *q = mix(*p, crate::image::luma(tex[0], tex[1], tex[2]));
            }
        }
        3 => {
            for ((p, q), tex) in src.chunks_exact(3).zip(dst.chunks_exact_mut(3)).zip(tex) {
                q[ri] = mix(p[ri], tex[0]);
                q[gi] = mix(p[gi], tex[1]);
                q[bi] = mix(p[bi], tex[2]);
            }
        }
        _ => {
            for ((p, q), tex) in src.chunks_exact(4).zip(dst.chunks_exact_mut(4)).zip(tex) {
                q[ri] = mix(p[ri], tex[0]);
                q[gi] = mix(p[gi], tex[1]);
                q[bi] = mix(p[bi], tex[2]);
            }
            copy_alpha(format, src, dst);
        }
    }
}

/// C-C1 frost: blend weight of the frost texture, severities 1..5 (PerturbationDrive
/// `frost_filter`).
pub const FROST_WEIGHT: [f32; 5] = [0.15, 0.19, 0.25, 0.32, 0.40];
/// C-C2 snow: blend weight of the snow texture, severities 1..5 (PerturbationDrive
/// `snow_filter`).
pub const SNOW_WEIGHT: [f32; 5] = [0.15, 0.22, 0.30, 0.45, 0.60];

/// A procedural frost texture: a bluish-white base (mean about (185, 192, 203)) modulated by ridged
/// fBm, with dendritic ice crystals grown from random nuclei (segments branching at ±60 degrees).
pub fn frost_texture(seed: u64, w: usize, h: usize) -> Vec<[u8; 3]> {
    let scale = 6.0 / w.min(h).max(1) as f32;
    let mut tex: Vec<[u8; 3]> = (0..w * h)
        .into_par_iter()
        .map(|k| {
            let (x, y) = ((k % w) as f32 * scale, (k / w) as f32 * scale);
            let n = fbm(seed, x, y, 5, 0.55);
            let ridged = 1.0 - (2.0 * n - 1.0).abs();
            let fine = value_noise(seed ^ 0x5A5A, x * 9.0, y * 9.0);
            let v = 0.78 + 0.30 * ridged * ridged + 0.08 * fine;
            [
                (172.0 * v) as u8,
                (180.0 * v) as u8,
                (192.0 * v).min(255.0) as u8,
            ]
        })
        .collect();
    // Dendrites: bright thin branches.
    let mut rng = Rng::for_setup(seed, 0xC1);
    let px = |tex: &mut Vec<[u8; 3]>, x: f32, y: f32| {
        if x >= 0.0 && y >= 0.0 && (x as usize) < w && (y as usize) < h {
            let p = &mut tex[y as usize * w + x as usize];
            *p = [
                p[0].saturating_add(45),
                p[1].saturating_add(45),
                p[2].saturating_add(40),
            ];
        }
    };
    let nuclei = (w * h / 9000).max(4);
    let unit = (w.min(h) as f32 / 120.0).max(1.0);
    for _ in 0..nuclei {
        let (cx, cy) = (rng.f32() * w as f32, rng.f32() * h as f32);
        let mut stack: Vec<(f32, f32, f32, f32, u32)> = (0..6)
            .map(|k| {
                (
                    cx,
                    cy,
                    k as f32 * std::f32::consts::FRAC_PI_3 + rng.f32() * 0.3,
                    unit * (4.0 + rng.f32() * 6.0),
                    0,
                )
            })
            .collect();
        while let Some((x, y, a, len, depth)) = stack.pop() {
            let steps = len.ceil() as usize;
            let (dx, dy) = (a.cos(), a.sin());
            for s in 0..steps {
                px(&mut tex, x + dx * s as f32, y + dy * s as f32);
            }
            if depth < 3 {
                let (ex, ey) = (x + dx * len, y + dy * len);
                for turn in [-std::f32::consts::FRAC_PI_3, std::f32::consts::FRAC_PI_3] {
                    if rng.chance(0.7) {
                        stack.push((
                            x + dx * len * 0.5,
                            y + dy * len * 0.5,
                            a + turn,
                            len * 0.5,
                            depth + 1,
                        ));
                    }
                }
                stack.push((ex, ey, a + (rng.f32() - 0.5) * 0.3, len * 0.7, depth + 1));
            }
        }
    }
    tex
}

/// A procedural snow texture: a vertical grey gradient (about 190 at the top to 240 at the bottom)
/// with soft white flakes and six-armed star crystals.
pub fn snow_texture(seed: u64, w: usize, h: usize) -> Vec<[u8; 3]> {
    let mut tex: Vec<[u8; 3]> = (0..w * h)
        .map(|k| {
            let g = (190.0 + 50.0 * (k / w) as f32 / h.max(1) as f32) as u8;
            [g, g, g.saturating_add(4)]
        })
        .collect();
    let mut rng = Rng::for_setup(seed, 0xC2);
    let unit = (w.min(h) as f32 / 300.0).max(1.0);
    let flakes = (w * h) / 1500 + 8;
    for _ in 0..flakes {
        let (cx, cy) = (rng.f32() * w as f32, rng.f32() * h as f32);
        let r = unit * (1.0 + rng.f32() * 3.0);
        let star = rng.chance(0.3);
        let reach = (if star { 2.5 * r } else { r }).ceil() as i64;
        for dy in -reach..=reach {
            for dx in -reach..=reach {
                let (x, y) = (cx as i64 + dx, cy as i64 + dy);
                if x < 0 || y < 0 || x >= w as i64 || y >= h as i64 {
                    continue;
                }
                let d = ((dx * dx + dy * dy) as f32).sqrt();
                let a = if star {
                    let ang = (dy as f32).atan2(dx as f32);
                    let arm = ((ang * 3.0).cos().abs()).powf(40.0);
                    (arm * (1.0 - d / (2.5 * r))).max((1.0 - d / (0.7 * r)).max(0.0))
                } else {
                    (1.0 - d / r).max(0.0)
                };
                if a > 0.0 {
                    let p = &mut tex[y as usize * w + x as usize];
                    for ch in p.iter_mut() {
                        *ch = (*ch as f32 + (255.0 - *ch as f32) * a.min(1.0)) as u8;
                    }
                }
            }
        }
    }
    tex
}

/// C-C1 frost / C-C2 snow: a static procedural texture T blended over the frame,
/// `out = (1 - i) I + i T`, then HSV saturation x 0.8 as the reference does after its blend
/// (see [`super::ops::map_saturation`]; mono8 skips that step). The texture is generated once per
/// (seed, resolution) at configuration time; the references stretch a photo (frost) or a
/// sprite sheet (snow) instead, which the project does not ship.
pub struct TextureOverlay {
    texture: Vec<[u8; 3]>,
    weight: f32,
    desaturate: [u8; 256],
}

fn texture_overlay(texture: Vec<[u8; 3]>, weight: f32) -> TextureOverlay {
    TextureOverlay {
        texture,
        weight,
        desaturate: std::array::from_fn(|s| (s as f32 * 0.8) as u8),
    }
}

/// Registry constructor of C-C1.
pub const FROST: CameraBuilder = |s| {
    let (w, h) = (s.geometry.width as usize, s.geometry.height as usize);
    Ok(Box::new(texture_overlay(
        frost_texture(s.seed, w, h),
        FROST_WEIGHT[s.level()],
    )))
};

/// Registry constructor of C-C2.
pub const SNOW: CameraBuilder = |s| {
    let (w, h) = (s.geometry.width as usize, s.geometry.height as usize);
    Ok(Box::new(texture_overlay(
        snow_texture(s.seed, w, h),
        SNOW_WEIGHT[s.level()],
    )))
};

impl CameraPerturbation for TextureOverlay {
    fn apply(&self, input: &ImageView<'_>, output: &mut ImageViewMut<'_>, _seq: u64) {
        // Blend the texture, then scale the saturation down (colour formats), row by row.
        let format = input.format;
        let w = input.width as usize;
        let t = (self.weight * 256.0).round() as u32;
        let desaturate = SaturationMap::new(&self.desaturate);
        par_rows(input, output, |y, src, dst| {
            let tex = &self.texture[y * w..(y + 1) * w];
            if format.is_mono() {
                blend_texture_row(format, src, tex, t, dst);
            } else {
                let mut blended = vec![0u8; dst.len()];
                blend_texture_row(format, src, tex, t, &mut blended);
                desaturate.row(format, &blended, dst);
            }
        });
    }
}

/// C-C3 fog: blend weight of the fractal fog, severities 1..5 (PerturbationDrive `fog_mapping`).
pub const FOG_WEIGHT: [f32; 5] = [0.05, 0.12, 0.22, 0.35, 0.60];

/// A diamond-square (plasma) fog field at `w` x `h`, min-max normalised to 0..255: a
/// (2^ceil(log2 max(w, h)) + 1)^2 grid with corners U(0, 1), every new point the mean of its
/// square's or diamond's corners plus U(0, 1) x 0.6 x 2^-level, bilinearly resized.
///
/// Deviation: the reference keeps the displacement at 0.6 on every level, which turns the finest
/// levels into pixel-scale grain (a screen-door pattern, not fog); here it halves with each level,
/// as the plasma fractal does, so the fog has smooth large-scale structure. Grid, corners, the 0.6
/// amplitude, the resize and the normalisation are the reference's.
pub fn diamond_square_fog(seed: u64, w: usize, h: usize) -> Vec<u8> {
    let n = w.max(h).max(2).next_power_of_two();
    let size = n + 1;
    let mut g = vec![0f32; size * size];
    let mut rng = Rng::for_setup(seed, 0xC3);
    for (x, y) in [(0, 0), (n, 0), (0, n), (n, n)] {
        g[y * size + x] = rng.f32();
    }
    let mut step = n;
    let mut amp = 0.6f32;
    while step > 1 {
        let half = step / 2;
        // Diamond step: centres of squares.
        for y in (half..n).step_by(step) {
            for x in (half..n).step_by(step) {
                let m = (g[(y - half) * size + x - half]
                    + g[(y - half) * size + x + half]
                    + g[(y + half) * size + x - half]
                    + g[(y + half) * size + x + half])
                    / 4.0;
                g[y * size + x] = m + rng.f32() * amp;
            }
        }
        // Square step: edge midpoints, averaging the neighbours that exist.
        for y in (0..size).step_by(half) {
            let start = if (y / half).is_multiple_of(2) {
                half
            } else {
                0
            };
            for x in (start..size).step_by(step) {
                let mut sum = 0.0;
                let mut cnt = 0.0;
                for (dx, dy) in [
                    (-(half as i64), 0i64),
                    (half as i64, 0),
                    (0, -(half as i64)),
                    (0, half as i64),
                ] {
                    let (nx, ny) = (x as i64 + dx, y as i64 + dy);
                    if nx >= 0 && ny >= 0 && nx < size as i64 && ny < size as i64 {
                        sum += g[ny as usize * size + nx as usize];
                        cnt += 1.0;
                    }
                }
                g[y * size + x] = sum / cnt + rng.f32() * amp;
            }
        }
        step = half;
        amp *= 0.5;
    }
    // Resize to w x h (bilinear), then min-max normalise.
    let mut out = vec![0f32; w * h];
    let (sx, sy) = (size as f32 / w as f32, size as f32 / h as f32);
    for y in 0..h {
        let fy = ((y as f32 + 0.5) * sy - 0.5).clamp(0.0, (size - 1) as f32);
        let (y0, wy) = (fy.floor() as usize, fy - fy.floor());
        let y1 = (y0 + 1).min(size - 1);
        for x in 0..w {
            let fx = ((x as f32 + 0.5) * sx - 0.5).clamp(0.0, (size - 1) as f32);
            let (x0, wx) = (fx.floor() as usize, fx - fx.floor());
            let x1 = (x0 + 1).min(size - 1);
            let a = g[y0 * size + x0] * (1.0 - wx) + g[y0 * size + x1] * wx;
            let b = g[y1 * size + x0] * (1.0 - wx) + g[y1 * size + x1] * wx;
            out[y * w + x] = a * (1.0 - wy) + b * wy;
        }
    }
    let (mn, mx) = out
        .iter()
        .fold((f32::INFINITY, f32::NEG_INFINITY), |(a, b), &v| {
            (a.min(v), b.max(v))
        });
    let span = (mx - mn).max(1e-6);
    out.iter()
        .map(|v| ((v - mn) / span * 255.0).round() as u8)
        .collect()
}

/// C-C3 fog: `out = (1 - s) I + s F` with F the diamond-square fog field (grey), generated once
/// per (seed, resolution) at configuration time (the reference's pure-Python generator takes
/// 0.4-1.5 s per frame).
pub struct Fog {
    texture: Vec<[u8; 3]>,
    weight: f32,
}

/// Registry constructor of C-C3.
pub const FOG: CameraBuilder = |s| {
    let (w, h) = (s.geometry.width as usize, s.geometry.height as usize);
    let field = diamond_square_fog(s.seed, w, h);
    Ok(Box::new(Fog {
        texture: field.into_iter().map(|v| [v, v, v]).collect(),
        weight: FOG_WEIGHT[s.level()],
    }))
};

impl CameraPerturbation for Fog {
    fn apply(&self, input: &ImageView<'_>, output: &mut ImageViewMut<'_>, _seq: u64) {
        let (format, w) = (input.format, input.width as usize);
        let t = (self.weight * 256.0).round() as u32;
        par_rows(input, output, |y, src, dst| {
            blend_texture_row(format, src, &self.texture[y * w..(y + 1) * w], t, dst)
        });
    }
}

/// Blends `rgb` into pixel (x, y) of `out` with coverage `a` (0..1), alpha untouched.
#[inline]
fn blend_px(out: &mut ImageViewMut<'_>, x: i64, y: i64, rgb: [f32; 3], a: f32) {
    if x < 0 || y < 0 || x >= out.width as i64 || y >= out.height as i64 || a <= 0.0 {
        return;
    }
    let f = out.format;
    let c = f.channels();
    let row = out.row_mut(y as usize);
    blend_into(
        f,
        f.rgb_offsets(),
        &mut row[x as usize * c..x as usize * c + c],
        rgb,
        a.min(1.0),
    );
}

/// Blends `rgb` into the pixel bytes `p` of `format` (colour bytes at `rgb_at`) with coverage `a`
/// (0..=1), alpha untouched.
#[inline]
fn blend_into(format: PixelFormat, rgb_at: [usize; 3], p: &mut [u8], rgb: [f32; 3], a: f32) {
    if format.is_mono() {
        let l = 0.299 * rgb[0] + 0.587 * rgb[1] + 0.114 * rgb[2];
        p[0] = (p[0] as f32 * (1.0 - a) + l * a + 0.5) as u8;
        return;
    }
    for (ch, v) in rgb_at.into_iter().zip(rgb) {
        p[ch] = (p[ch] as f32 * (1.0 - a) + v * a + 0.5) as u8;
    }
}

fn copy_frame(input: &ImageView<'_>, output: &mut ImageViewMut<'_>) {
    par_rows(input, output, |_, s, d| d.copy_from_slice(s));
}

/// One rain streak of [`Rain`]: start position, fall speed (pixels per frame), length, width.
struct Streak {
    x: f32,
    y: f32,
    speed: f32,
    len: f32,
    width: f32,
}

/// C-C7 rain: falling rain streaks, procedural and animated. A fixed population of streaks (density
/// proportional to the frame area), 1-2 px wide and 10-30 px long at 800 x 503 (scaled), slanted
/// by a wind angle within ±10 degrees drawn per seed, falls at its own speed; at frame n a streak is
/// at its start position advanced by n x speed along the slant, wrapped around the frame, so any
/// frame is computed from (seed, n) alone. The streaks are pale bluish and blended with the
/// reference's overlay weight i = .15 .25 .40 .60 .85 (only the weight changes with severity, as
/// the reference's video overlay).
pub struct Rain {
    streaks: Vec<Streak>,
    slant: f32,
    weight: f32,
}

/// Registry constructor of C-C7.
pub const RAIN: CameraBuilder = |s| {
    let (w, h) = (s.geometry.width as f32, s.geometry.height as f32);
    let k = size_scale(s.geometry.width, s.geometry.height).max(0.05);
    let mut rng = Rng::for_setup(s.seed, 0xC7);
    let slant = (rng.f32() * 20.0 - 10.0).to_radians().tan();
    let n = ((w * h) / 600.0) as usize + 1;
    let streaks = (0..n)
        .map(|_| Streak {
            x: rng.f32() * w,
            y: rng.f32() * h,
            speed: (25.0 + rng.f32() * 25.0) * k,
            len: (10.0 + rng.f32() * 20.0) * k,
            width: (1.0 + rng.f32()) * k.max(0.5),
        })
        .collect();
    Ok(Box::new(Rain {
        streaks,
        slant,
        weight: OVERLAY_WEIGHT[s.level()],
    }))
};

impl CameraPerturbation for Rain {
    fn apply(&self, input: &ImageView<'_>, output: &mut ImageViewMut<'_>, seq: u64) {
        copy_frame(input, output);
        let (w, h) = (input.width as f32, input.height as f32);
        let colour = [205.0, 215.0, 235.0];
        for s in &self.streaks {
            let fall = s.speed * (seq % 1_000_000) as f32;
            let y = (s.y + fall).rem_euclid(h + s.len) - s.len;
            let x = (s.x + self.slant * fall).rem_euclid(w);
            let steps = s.len.ceil() as i64;
            let half = s.width / 2.0;
            for t in 0..steps {
                let (py, px) = (y + t as f32, x + self.slant * t as f32);
                // Fade in along the streak: its head is the brightest.
                let a = self.weight * (0.4 + 0.6 * t as f32 / steps as f32);
                let mut dx = -half;
                while dx <= half {
                    blend_px(output, (px + dx) as i64, py as i64, colour, a);
                    dx += 1.0;
                }
            }
        }
    }
}

/// C-C12 snowflakes: flakes at the reference's 320 x 240, severities 1..5 (PerturbationDrive
/// `effects_snowflake_dynamic`: N = 100 (scale + 1) with its scale 0..4, so 100 .. 500; the
/// table read 200 .. 600, from severities 1..5 taken for the scale, until issue 16).
pub const SNOWFLAKES_LEVELS: [usize; 5] = [100, 200, 300, 400, 500];

/// C-C12 snowflakes: driving into snow: soft white flakes stream radially away from the image
/// centre at constant speed, as the reference moves them, and grow as they come closer. Each flake
/// has a direction, a start distance, a speed and a size; at frame n its distance from the centre
/// is `(d0 + v n) mod R` (R the half-diagonal), so the population is stationary and any frame is
/// computed from (seed, n) alone. Counts scale with the frame area from the reference's 100 (s + 1) at its size;
/// the reference renders each flake with its raindrop code at radius 1-3 and takes 70-460 ms per
/// frame, here a flake is a soft disc drawn directly. All flakes have one colour, so compositing
/// them one over the other is `out = c + (I - c) T` with `T` the product of `1 - a` over the flakes
/// covering a pixel: the flakes only multiply into a transmittance plane, and the frame is blended
/// once (one rounding instead of one per flake).
pub struct Snowflakes {
    flakes: Vec<(f32, f32, f32, f32, f32)>,
    /// Distances from the centre of a `(2 m + 1)^2` square, row-major.
    dist: Vec<f32>,
    /// Half-size of the largest flake's square.
    m: i64,
}

/// Registry constructor of C-C12.
pub const SNOWFLAKES: CameraBuilder = |s| {
    let (w, h) = (s.geometry.width as f32, s.geometry.height as f32);
    let k = size_scale(s.geometry.width, s.geometry.height).max(0.05);
    let n = (SNOWFLAKES_LEVELS[s.level()] as f32 * (w * h) / (320.0 * 240.0)) as usize + 1;
    let mut rng = Rng::for_setup(s.seed, 0xC12);
    let flakes = (0..n)
        .map(|_| {
            let angle = rng.f32() * std::f32::consts::TAU;
            let d0 = rng.f32() * (w * w + h * h).sqrt() / 2.0;
            // The reference moves flakes by up to 5 px per frame at 320 x 240.
            let speed = (2.0 + rng.f32() * 4.0) * (w.min(h) / 240.0);
            let radius = (1.5 + rng.f32() * 2.5) * k;
            (angle, d0, speed, 0.0, radius)
        })
        .collect::<Vec<_>>();
    // A flake's radius at most doubles on its way out.
    let m = flakes.iter().map(|f| f.4 * 2.0).fold(0.0, f32::max).ceil() as i64 + 1;
    let dist = (-m..=m)
        .flat_map(|dy| (-m..=m).map(move |dx| ((dx * dx + dy * dy) as f32).sqrt()))
        .collect();
    Ok(Box::new(Snowflakes { flakes, dist, m }))
};

impl CameraPerturbation for Snowflakes {
    fn apply(&self, input: &ImageView<'_>, output: &mut ImageViewMut<'_>, seq: u64) {
        let (wi, hi) = (input.width as usize, input.height as usize);
        let (w, h) = (wi as f32, hi as f32);
        let (cx, cy) = (w / 2.0, h / 2.0);
        let reach = (w * w + h * h).sqrt() / 2.0;
        let (m, side) = (self.m, 2 * self.m as usize + 1);
        let mut trans = vec![1f32; wi * hi];
        // Where each flake is at this frame: centre pixel and radius. Drawn top to bottom so the
        // transmittance plane is walked nearly in order (the product does not depend on the order).
        let mut placed: Vec<(i64, i64, f32)> = self
            .flakes
            .iter()
            .map(|&(angle, d0, speed, _, radius)| {
                let d = (d0 + speed * (seq % 1_000_000) as f32).rem_euclid(reach);
                let (x, y) = (cx + angle.cos() * d, cy + angle.sin() * d);
                // Flakes grow as they come closer.
                (y as i64, x as i64, radius * (1.0 + d / reach))
            })
            .collect();
        placed.sort_unstable_by_key(|&(y, x, _)| (y, x));
        for (yc, xc, r) in placed {
            let ri = (r.ceil() as i64 + 1).min(m);
            let inv = 1.0 / (r + 0.5);
            let (x0, x1) = ((xc - ri).max(0), (xc + ri).min(wi as i64 - 1));
            if x0 > x1 {
                continue;
            }
            for yy in (yc - ri).max(0)..=(yc + ri).min(hi as i64 - 1) {
                let drow = (yy - yc + m) as usize * side;
                let dists =
                    &self.dist[drow + (x0 - xc + m) as usize..=drow + (x1 - xc + m) as usize];
                let start = yy as usize * wi;
                let ts = &mut trans[start + x0 as usize..=start + x1 as usize];
                for (t, &dd) in ts.iter_mut().zip(dists) {
                    let a = (1.0 - dd * inv).clamp(0.0, 1.0) * 0.95;
                    *t *= 1.0 - a;
                }
            }
        }
        let format = input.format;
        let c = format.channels();
        let colour = if format.is_mono() {
            [0.299 * 250.0 + 0.587 * 250.0 + 0.114 * 252.0; 3]
        } else {
            [250.0, 250.0, 252.0]
        };
        let mut at = [0usize; 3];
        if !format.is_mono() {
            at = format.rgb_offsets();
        }
        par_rows(input, output, |y, src, dst| {
            dst.copy_from_slice(src);
            let ts = &trans[y * wi..(y + 1) * wi];
            for (q, &t) in dst.chunks_exact_mut(c).zip(ts) {
                if t < 1.0 {
                    for (&ch, v) in at.iter().zip(colour) {
                        q[ch] = (v + (q[ch] as f32 - v) * t + 0.5) as u8;
                    }
                }
            }
        });
    }
}

/// C-C8 raindrops: the largest radius of a respawned drop at 320 x 240, severities 1..5
/// (PerturbationDrive `effects_rain_dynamic`: respawn radius randint(1, 5 (s + 1))).
pub const RAINDROP_MAX_RADIUS: [f32; 5] = [5.0, 10.0, 15.0, 20.0, 25.0];

/// Drops on the windshield at once (the reference keeps 9 at 320 x 240; the count is per frame,
/// independent of resolution, since drops scale with the frame).
pub const RAINDROP_COUNT: usize = 12;

/// C-C8 raindrops: water drops on the windshield that refract the scene and slide down. Each drop
/// is a circle, or a circle with a lower half-ellipse (a teardrop); it shows an inverted, minified,
/// slightly blurred view of the scene around it (the lens a drop forms), with a darker rim, and a
/// soft edge. Drops slide down at a speed set by their size (as the reference's 3 / 1 / 2 pixel
/// steps) and respawn near the top with a new radius uniform in [1, r_max] (the severity); a drop's
/// life is a fixed-period cycle, so frame n is computed from (seed, n) alone. Sizes and positions
/// scale with the frame (the reference hard-codes 320 x 240).
pub struct Raindrops {
    seed: u64,
    r_max: f32,
    /// Per drop: speed in pixels per frame at 240 rows, phase in frames.
    drops: Vec<(f32, f32)>,
}

/// Registry constructor of C-C8.
pub const RAINDROPS: CameraBuilder = |s| {
    let mut rng = Rng::for_setup(s.seed, 0xC8);
    Ok(Box::new(Raindrops {
        seed: s.seed,
        r_max: RAINDROP_MAX_RADIUS[s.level()],
        drops: (0..RAINDROP_COUNT)
            .map(|_| (0.6 + rng.f32() * 1.2, rng.f32() * 10_000.0))
            .collect(),
    }))
};

impl CameraPerturbation for Raindrops {
    fn apply(&self, input: &ImageView<'_>, output: &mut ImageViewMut<'_>, seq: u64) {
        copy_frame(input, output);
        let (w, h) = (input.width as f32, input.height as f32);
        let k = h / 240.0;
        let c = input.format.channels();
        let r_top = self.r_max * k;
        for (i, &(speed, phase)) in self.drops.iter().enumerate() {
            let v = speed * k;
            let period = ((h + 3.0 * r_top) / v).max(1.0);
            let t = seq as f32 + phase;
            let cycle = (t / period).floor();
            let age = t - cycle * period;
            let mut rng = Rng::for_frame(self.seed, cycle as u64, 0xC80 + i as u64);
            let r = (1.0 + rng.f32() * (self.r_max - 1.0)).max(1.0) * k;
            let cx = rng.f32() * w;
            let cy = rng.f32() * 40.0 * k - r + v * age;
            let tail = if rng.chance(0.5) {
                1.3 * 3f32.sqrt() * 0.5
            } else {
                0.0
            };
            // Pixels of the drop: a circle plus, for teardrops, a lower half-ellipse.
            let (x0, x1) = ((cx - r).floor() as i64, (cx + r).ceil() as i64);
            let (y0, y1) = (
                (cy - r).floor() as i64,
                (cy + r * (1.0 + tail)).ceil() as i64,
            );
            for y in y0..=y1 {
                if y < 0 || y >= h as i64 {
                    continue;
                }
                for x in x0..=x1 {
                    if x < 0 || x >= w as i64 {
                        continue;
                    }
                    let (dx, dy) = (x as f32 - cx, y as f32 - cy);
                    let mut d = (dx * dx + dy * dy).sqrt() / r;
                    if dy > 0.0 && tail > 0.0 {
                        d = d.min(((dx / r).powi(2) + (dy / (r * (1.0 + tail))).powi(2)).sqrt());
                    }
                    if d > 1.0 {
                        continue;
                    }
                    // Refraction: an inverted, minified view of the scene around the drop.
                    let (sx, sy) = (cx - dx * 0.55, cy - dy * 0.55 - r * 0.3);
                    let mut acc = [0f32; 4];
                    for (ox, oy) in [
                        (-1.0f32, -1.0f32),
                        (1.0, -1.0),
                        (-1.0, 1.0),
                        (1.0, 1.0),
                        (0.0, 0.0),
                    ] {
                        let px = (sx + ox * r * 0.08).clamp(0.0, w - 1.0) as usize;
                        let py = (sy + oy * r * 0.08).clamp(0.0, h - 1.0) as usize;
                        let p = &input.row(py)[px * c..px * c + c];
                        for ch in 0..c {
                            acc[ch] += p[ch] as f32 / 5.0;
                        }
                    }
                    // Soft edge, darker rim.
                    let alpha = ((1.0 - d) / 0.15).clamp(0.0, 1.0);
                    let shade = if d > 0.75 {
                        0.55 + 0.45 * (1.0 - d) / 0.25
                    } else {
                        1.0
                    } * (1.02 - 0.1 * dy / r);
                    let row = output.row_mut(y as usize);
                    let q = &mut row[x as usize * c..x as usize * c + c];
                    let alpha_ch = input.format.alpha_offset();
                    for ch in 0..c {
                        if Some(ch) == alpha_ch {
                            continue;
                        }
                        let v = (acc[ch] * shade).clamp(0.0, 255.0);
                        q[ch] = (q[ch] as f32 * (1.0 - alpha) + v * alpha + 0.5) as u8;
                    }
                }
            }
        }
    }
}

/// One row of the lightning stamp: the row offset and the (dx, coverage, is-core) of its pixels.
type StampRow = (i64, Vec<(i64, f32, bool)>);

/// C-C9 lightning: a bolt from the sky with branches, glow, flicker and flashes, procedural and
/// animated, blended with the overlay weight i = .15 .25 .40 .60 .85. A new strike (new bolt shape
/// from fractal midpoint displacement, new position) every 12 frames; within a strike the bolt
/// flickers and, on its first frames, the whole frame is lit by a flash. Everything at frame n is
/// computed from (seed, n).
pub struct Lightning {
    seed: u64,
    weight: f32,
}

/// Frames per lightning strike.
pub const STRIKE_FRAMES: u64 = 12;

/// Registry constructor of C-C9.
pub const LIGHTNING: CameraBuilder = |s| {
    Ok(Box::new(Lightning {
        seed: s.seed,
        weight: OVERLAY_WEIGHT[s.level()],
    }))
};

/// A fractal bolt polyline from (x0, y0) to (x1, y1): midpoint displacement, the displacement
/// halving with each of `levels` subdivisions.
fn bolt(rng: &mut Rng, a: (f32, f32), b: (f32, f32), amp: f32, levels: u32) -> Vec<(f32, f32)> {
    let mut pts = vec![a, b];
    let mut amp = amp;
    for _ in 0..levels {
        let mut next = Vec::with_capacity(pts.len() * 2);
        for win in pts.windows(2) {
            let (p, q) = (win[0], win[1]);
            let (mx, my) = ((p.0 + q.0) / 2.0, (p.1 + q.1) / 2.0);
            let (dx, dy) = (q.0 - p.0, q.1 - p.1);
            let len = (dx * dx + dy * dy).sqrt().max(1e-3);
            let off = (rng.f32() * 2.0 - 1.0) * amp;
            next.push(p);
            next.push((mx - dy / len * off, my + dx / len * off));
        }
        next.push(*pts.last().expect("non-empty"));
        pts = next;
        amp *= 0.5;
    }
    pts
}

impl CameraPerturbation for Lightning {
    fn apply(&self, input: &ImageView<'_>, output: &mut ImageViewMut<'_>, seq: u64) {
        let (w, h) = (input.width as f32, input.height as f32);
        let k = size_scale(input.width, input.height).max(0.05);
        let strike = seq / STRIKE_FRAMES;
        let age = seq % STRIKE_FRAMES;
        let mut rng = Rng::for_frame(self.seed, strike, 0xC9);
        let x0 = (0.15 + rng.f32() * 0.7) * w;
        let end = (
            x0 + (rng.f32() - 0.5) * 0.4 * w,
            (0.45 + rng.f32() * 0.35) * h,
        );
        let mut paths = vec![bolt(&mut rng, (x0, 0.0), end, 0.18 * h, 7)];
        for _ in 0..3 {
            let main = &paths[0];
            let from = main[(rng.f32() * 0.7 * main.len() as f32) as usize + main.len() / 10];
            let to = (
                from.0 + (rng.f32() - 0.5) * 0.3 * w,
                from.1 + (0.1 + rng.f32() * 0.2) * h,
            );
            paths.push(bolt(&mut rng, from, to, 0.06 * h, 5));
        }
        // Flicker: strong at the start of the strike, a re-strike, then fading.
        let flicker = [
            1.0, 0.55, 0.9, 0.7, 0.45, 0.35, 0.3, 0.25, 0.2, 0.2, 0.15, 0.15,
        ][age as usize % 12];
        let a = self.weight * flicker;
        let flash = if age < 3 {
            self.weight * 0.35 * flicker
        } else {
            0.0
        };
        if flash > 0.0 {
            // The sky lights up: every colour channel moves towards a pale white.
            let t = (flash * 256.0) as u32;
            let lut = std::array::from_fn(|v| ((v as u32 * (256 - t) + 235 * t) >> 8) as u8);
            apply_lut(input, output, &lut);
        } else {
            copy_frame(input, output);
        }
        let (core, glow) = ((1.5 * k).max(1.0), 10.0 * k);
        // The stamp drawn along the paths: per row offset, the (dx, coverage, is-core) of the
        // pixels it covers by more than 1%.
        let rr = glow.ceil() as i64;
        let stamp: Vec<StampRow> = (-rr..=rr)
            .map(|dy| {
                let row = (-rr..=rr)
                    .filter_map(|dx| {
                        let d = ((dx * dx + dy * dy) as f32).sqrt();
                        let (cov, is_core) = if d <= core {
                            (1.0, true)
                        } else {
                            let g =
                                (-(d - core).powi(2) / (2.0 * (glow / 2.5).powi(2))).exp() * 0.12;
                            (g, false)
                        };
                        (cov > 0.01).then_some((dx, cov, is_core))
                    })
                    .collect();
                (dy, row)
            })
            .collect();
        let (iw, ih) = (input.width as i64, input.height as i64);
        let f = output.format;
        let c = f.channels();
        let [ri, gi, bi] = f.rgb_offsets();
        for (pi, path) in paths.iter().enumerate() {
            let strength = if pi == 0 { 1.0 } else { 0.7 };
            for seg in path.windows(2) {
                let (p, q) = (seg[0], seg[1]);
                let len = ((q.0 - p.0).powi(2) + (q.1 - p.1).powi(2)).sqrt();
                let steps = (len / (core * 0.7)).ceil().max(1.0) as usize;
                for sidx in 0..=steps {
                    let t = sidx as f32 / steps as f32;
                    let (cx, cy) = (
                        (p.0 + (q.0 - p.0) * t) as i64,
                        (p.1 + (q.1 - p.1) * t) as i64,
                    );
                    for (dy, pixels) in &stamp {
                        let y = cy + dy;
                        if y < 0 || y >= ih {
                            continue;
                        }
                        let row = output.row_mut(y as usize);
                        for &(dx, cov, is_core) in pixels {
                            let x = cx + dx;
                            let alpha = (a * cov * strength).min(1.0);
                            if x < 0 || x >= iw || alpha <= 0.0 {
                                continue;
                            }
                            let colour = if is_core {
                                [245.0, 240.0, 255.0]
                            } else {
                                [180.0, 170.0, 255.0]
                            };
                            let px = &mut row[x as usize * c..x as usize * c + c];
                            blend_into(f, [ri, gi, bi], px, colour, alpha);
                        }
                    }
                }
            }
        }
    }
}

/// C-C10 smoke: drifting grey smoke clouds, procedural and animated, blended with the overlay
/// weight i = .15 .25 .40 .60 .85 where the smoke is. A periodic fBm field (built once per seed and
/// resolution) is thresholded into clouds and scrolls
/// diagonally by a fixed step per frame, wrapping, so frame n is computed from (seed, n). The smoke
/// is grey with darker cores; density is smoothstep(0.36, 0.64, fBm).
pub struct Smoke {
    w: usize,
    h: usize,
    density: Vec<u8>,
    weight: f32,
    step: (f32, f32),
}

/// Registry constructor of C-C10.
pub const SMOKE: CameraBuilder = |s| {
    let (w, h) = (
        s.geometry.width.max(1) as usize,
        s.geometry.height.max(1) as usize,
    );
    let period = 4.0f32;
    let scale = period / w.max(h) as f32;
    // Periodic value noise: the lattice wraps every `period` cells in both directions, so the
    // field tiles and scrolling never shows a seam.
    let seed = s.seed;
    let lattice = move |i: i64, j: i64, o: u64| {
        let (i, j) = (
            i.rem_euclid((period as i64) << o),
            j.rem_euclid((period as i64) << o),
        );
        (crate::rng::mix64(
            seed ^ o.wrapping_mul(0x51)
                ^ (i as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15)
                ^ (j as u64).wrapping_mul(0xC2B2_AE3D_27D4_EB4F),
        ) >> 40) as f32
            / (1u64 << 24) as f32
    };
    let noise = move |x: f32, y: f32, o: u64| {
        let (xi, yi) = (x.floor(), y.floor());
        let (fx, fy) = (x - xi, y - yi);
        let (xi, yi) = (xi as i64, yi as i64);
        let sm = |t: f32| t * t * (3.0 - 2.0 * t);
        let (sx, sy) = (sm(fx), sm(fy));
        let a = lattice(xi, yi, o) + (lattice(xi + 1, yi, o) - lattice(xi, yi, o)) * sx;
        let b = lattice(xi, yi + 1, o) + (lattice(xi + 1, yi + 1, o) - lattice(xi, yi + 1, o)) * sx;
        a + (b - a) * sy
    };
    let (tw, th) = (w.max(h), w.max(h));
    let density: Vec<u8> = (0..tw * th)
        .into_par_iter()
        .map(|i| {
            let (x, y) = ((i % tw) as f32 * scale, (i / tw) as f32 * scale);
            let mut v = 0.0;
            let mut amp = 0.5;
            for o in 0..5u64 {
                let f = (1u64 << o) as f32;
                v += amp * noise(x * f, y * f, o);
                amp *= 0.5;
            }
            let v = v / 0.96875;
            let t = ((v - 0.36) / 0.28).clamp(0.0, 1.0);
            (t * t * (3.0 - 2.0 * t) * 255.0) as u8
        })
        .collect();
    Ok(Box::new(Smoke {
        w: tw,
        h: th,
        density,
        weight: OVERLAY_WEIGHT[s.level()],
        step: (0.004 * tw as f32, 0.0015 * th as f32),
    }))
};

impl CameraPerturbation for Smoke {
    fn apply(&self, input: &ImageView<'_>, output: &mut ImageViewMut<'_>, seq: u64) {
        let format = input.format;
        let c = format.channels();
        let [ri, gi, bi] = format.rgb_offsets();
        let n = (seq % 1_000_000) as f32;
        let (ox, oy) = (
            (n * self.step.0) as usize % self.w,
            (n * self.step.1) as usize % self.h,
        );
        let wq = (self.weight * 256.0) as u32;
        par_rows(input, output, |y, src, dst| {
            let trow = &self.density[((y + oy) % self.h) * self.w..][..self.w];
            for (x, (p, q)) in src.chunks_exact(c).zip(dst.chunks_exact_mut(c)).enumerate() {
                let d = trow[(x + ox) % self.w] as u32;
                let t = (d * wq) >> 8;
                let grey = 150 - ((d * 60) >> 8);
                if format.is_mono() {
                    q[0] = ((p[0] as u32 * (256 - t) + grey * t) >> 8) as u8;
                    continue;
                }
                for (ch, tint) in [(ri, 0u32), (gi, 0), (bi, 6)] {
                    q[ch] = ((p[ch] as u32 * (256 - t) + (grey + tint) * t) >> 8) as u8;
                }
                if let Some(a) = format.alpha_offset() {
                    q[a] = p[a];
                }
            }
        });
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
            let core = (-(d * d) / 0.5).exp();
            let halo = 0.55 * (-d / 3.0).exp();
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
        let sx = (bx + 0.06 * (t / 90.0).sin()) * w;
        let sy = (by + 0.03 * (t / 130.0).cos()) * h;
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
            .map(|x| (-((x as f32 - sx).abs() / w) * 1.5).exp())
            .collect();
        // Beyond this many pixels from the sun the radial table is 0.
        let reach = (table.len() as f32 * unit2).sqrt().ceil() + 1.0;
        par_rows(input, output, |y, src, dst| {
            let dy = y as f32 - sy;
            let streak_v = (-(dy * dy) / (2.0 * streak_h * streak_h)).exp();
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::camera::CameraSetup;
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

    #[test]
    fn brightness_scales_value_and_keeps_hue() {
        let i = Image::from_vec(vec![100, 50, 20], 1, 1, 3, PixelFormat::Rgb8).unwrap();
        let up = run(BRIGHTNESS_UP, 4, &i);
        assert_eq!(up.data, vec![150, 75, 30]);
        let down = run(BRIGHTNESS_DOWN, 5, &i);
        assert_eq!(down.data, vec![30, 15, 6]);
        // Saturating at 255 keeps the channel ratios below it.
        let b = Image::from_vec(vec![200, 90, 50], 1, 1, 3, PixelFormat::Rgb8).unwrap();
        assert_eq!(run(BRIGHTNESS_UP, 5, &b).data, vec![255, 115, 64]);
    }

    fn run_seq(b: CameraBuilder, sev: u8, img: &Image, seq: u64) -> Image {
        let p = b(&CameraSetup {
            severity: sev,
            seed: 3,
            geometry: img.geometry(),
        })
        .unwrap();
        let mut out = Image::with_geometry(img.geometry());
        p.apply(&img.view(), &mut out.view_mut(), seq);
        out
    }

    #[test]
    fn animated_effects_move_and_any_frame_is_reproducible_alone() {
        let img = crate::synthetic::street_image(240, 150, 0);
        for b in [RAIN, RAINDROPS, LIGHTNING, SMOKE, SUN_GLARE, SNOWFLAKES] {
            let f40 = run_seq(b, 3, &img, 40);
            let f41 = run_seq(b, 3, &img, 41);
            assert_ne!(f40, f41, "frame 40 and 41 differ");
            // A fresh instance computing frame 40 directly gives the same bytes.
            assert_eq!(run_seq(b, 3, &img, 40), f40);
        }
    }

    #[test]
    fn static_textures_look_like_their_reference() {
        let (w, h) = (320, 200);
        let frost = frost_texture(1, w, h);
        let mean =
            |t: &[[u8; 3]], k: usize| t.iter().map(|p| p[k] as f64).sum::<f64>() / t.len() as f64;
        let m = [mean(&frost, 0), mean(&frost, 1), mean(&frost, 2)];
        assert!(
            m[2] > m[0] && (m[0] - 185.0).abs() < 25.0 && (m[2] - 203.0).abs() < 25.0,
            "bluish white: {m:?}"
        );
        let snow = snow_texture(1, w, h);
        assert!(
            snow[0][0] < snow[(h - 1) * w][0],
            "grey gradient brighter towards the bottom"
        );
        let fog = diamond_square_fog(1, w, h);
        assert_eq!(
            (fog.iter().min(), fog.iter().max()),
            (Some(&0), Some(&255)),
            "min-max normalised"
        );
    }

    #[test]
    fn stronger_with_severity() {
        let img = crate::synthetic::street_image(200, 120, 0);
        let mad = |o: &Image| {
            o.data
                .iter()
                .zip(&img.data)
                .map(|(a, b)| (*a as f64 - *b as f64).abs())
                .sum::<f64>()
        };
        for b in [
            FROST,
            SNOW,
            FOG,
            RAIN,
            SMOKE,
            SUN_GLARE,
            SNOWFLAKES,
            BRIGHTNESS_UP,
            BRIGHTNESS_DOWN,
        ] {
            let d: Vec<f64> = (1..=5).map(|s| mad(&run_seq(b, s, &img, 5))).collect();
            assert!(d.windows(2).all(|w| w[1] >= w[0]), "{d:?}");
        }
    }

    #[test]
    fn contrast_stretches_around_mid_grey() {
        let i = Image::from_vec(vec![0, 100, 128, 200, 255], 5, 1, 5, PixelFormat::Mono8).unwrap();
        assert_eq!(run(CONTRAST, 5, &i).data, vec![0, 81, 128, 251, 255]);
    }
}
