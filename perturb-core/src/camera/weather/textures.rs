//! Static textures blended over the frame (C-C1 frost, C-C2 snow, C-C3 fog).

use super::per_area;
use crate::camera::ops::{SaturationMap, copy_alpha, par_rows, par_rows_with};
use crate::camera::texture::{fbm, value_noise};
use crate::camera::{CameraBuilder, CameraPerturbation};
use crate::image::{ImageView, ImageViewMut, PixelFormat};
use crate::math::Portable;
use crate::rng::Rng;
use rayon::prelude::*;

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

/// C-C1 frost: one ice crystal per this many pixels of the frame.
pub const FROST_PIXELS_PER_CRYSTAL: f64 = 9000.0;
/// C-C1 frost: the length unit of a crystal's branches, pixels (503 / 120: the size at 800 x 503).
pub const FROST_BRANCH_UNIT: f32 = 4.19;
/// C-C2 snow: one flake sprite per this many pixels of the frame.
pub const SNOW_PIXELS_PER_FLAKE: f64 = 1500.0;
/// C-C2 snow: the size unit of a flake sprite, pixels (503 / 300: the size at 800 x 503).
pub const SNOW_FLAKE_UNIT: f32 = 1.68;

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
    draw_crystals(seed, w, h, &mut tex);
    tex
}

/// Draws frost's ice crystals (dendrites: bright thin branches grown from random nuclei) into
/// `tex`, a `w` x `h` texture: each pixel a branch crosses is brightened by 45 (40 in blue).
pub fn draw_crystals(seed: u64, w: usize, h: usize, tex: &mut [[u8; 3]]) {
    let mut rng = Rng::for_setup(seed, 0xC1);
    let px = |tex: &mut [[u8; 3]], x: f32, y: f32| {
        if x >= 0.0 && y >= 0.0 && (x as usize) < w && (y as usize) < h {
            let p = &mut tex[y as usize * w + x as usize];
            *p = [
                p[0].saturating_add(45),
                p[1].saturating_add(45),
                p[2].saturating_add(40),
            ];
        }
    };
    // Crystals per unit of area, their branches as long in pixels on every frame (the lengths at
    // the paper's 800 x 503): the same share of any frame is crystal.
    let nuclei = per_area(FROST_PIXELS_PER_CRYSTAL.recip(), (1, 1), w as u32, h as u32);
    let unit = FROST_BRANCH_UNIT;
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
            let (dx, dy) = (a.pcos(), a.psin());
            for s in 0..steps {
                px(tex, x + dx * s as f32, y + dy * s as f32);
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
    draw_snow_flakes(seed, w, h, &mut tex);
    tex
}

/// Draws snow's flake sprites (soft white discs and six-armed stars) into `tex`, a `w` x `h`
/// texture: each pixel a flake covers moves towards white by the flake's coverage.
pub fn draw_snow_flakes(seed: u64, w: usize, h: usize, tex: &mut [[u8; 3]]) {
    let mut rng = Rng::for_setup(seed, 0xC2);
    // Flakes per unit of area, as large in pixels on every frame (the sizes at the paper's
    // 800 x 503): the same share of any frame is flake.
    let unit = SNOW_FLAKE_UNIT;
    let flakes = per_area(SNOW_PIXELS_PER_FLAKE.recip(), (1, 1), w as u32, h as u32);
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
                    let ang = (dy as f32).patan2(dx as f32);
                    let arm = ((ang * 3.0).pcos().abs()).ppowf(40.0);
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
}

/// C-C1 frost / C-C2 snow: a static procedural texture T blended over the frame,
/// `out = (1 - i) I + i T`, then HSV saturation x 0.8 as the reference does after its blend
/// (see [`crate::camera::ops::map_saturation`]; mono8 skips that step). The texture is generated once per
/// (seed, resolution) at configuration time; the references stretch a photo (frost) or a
/// sprite sheet (snow) instead, which the project does not ship.
pub struct TextureOverlay {
    texture: Vec<[u8; 3]>,
    weight: f32,
    /// `S' = floor(0.8 S)`.
    desaturate: SaturationMap,
}

fn texture_overlay(texture: Vec<[u8; 3]>, weight: f32) -> TextureOverlay {
    TextureOverlay {
        texture,
        weight,
        desaturate: SaturationMap::scaled(0.8),
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
        let scratch = || (Vec::new(), Vec::new());
        par_rows_with(input, output, scratch, |(blended, planes), y, src, dst| {
            let tex = &self.texture[y * w..(y + 1) * w];
            if format.is_mono() {
                blend_texture_row(format, src, tex, t, dst);
            } else {
                blended.resize(dst.len(), 0);
                blend_texture_row(format, src, tex, t, blended);
                self.desaturate.row_in(format, blended, dst, planes);
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
