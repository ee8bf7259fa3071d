//! Animated overlays (C-C9 lightning, C-C10 smoke).

use super::{OVERLAY_WEIGHT, blend_into, copy_frame};
use crate::camera::ops::{apply_lut, par_rows};
use crate::camera::texture::size_scale;
use crate::camera::{CameraBuilder, CameraPerturbation};
use crate::image::{ImageView, ImageViewMut};
use crate::math::Portable;
use crate::rng::Rng;
use rayon::prelude::*;

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

impl Lightning {
    /// The bolt of strike `strike` on a `w` x `h` frame: the main path from the top edge, then
    /// three branches leaving it.
    fn paths(&self, strike: u64, w: f32, h: f32) -> Vec<Vec<(f32, f32)>> {
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
        paths
    }
}

/// The stamp drawn along a bolt's paths: per row offset, the (dx, coverage, is-core) of the pixels
/// it covers by more than 1%: full inside the core radius, a Gaussian glow around it.
fn glow_stamp(core: f32, glow: f32) -> Vec<StampRow> {
    let rr = glow.ceil() as i64;
    (-rr..=rr)
        .map(|dy| {
            let row = (-rr..=rr)
                .filter_map(|dx| {
                    let d = ((dx * dx + dy * dy) as f32).sqrt();
                    let (cov, is_core) = if d <= core {
                        (1.0, true)
                    } else {
                        let g = (-(d - core).powi(2) / (2.0 * (glow / 2.5).powi(2))).pexp() * 0.12;
                        (g, false)
                    };
                    (cov > 0.01).then_some((dx, cov, is_core))
                })
                .collect();
            (dy, row)
        })
        .collect()
}

/// Stamps `stamp` along `path` every `0.7 core` pixels with opacity `a` times the stamp's
/// coverage times the path's `strength`: a white-violet core, a bluer glow.
fn draw_path(
    output: &mut ImageViewMut<'_>,
    path: &[(f32, f32)],
    stamp: &[StampRow],
    core: f32,
    (a, strength): (f32, f32),
) {
    let (iw, ih) = (output.width as i64, output.height as i64);
    let f = output.format;
    let c = f.channels();
    let rgb = f.rgb_offsets();
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
            for (dy, pixels) in stamp {
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
                    blend_into(f, rgb, px, colour, alpha);
                }
            }
        }
    }
}

impl CameraPerturbation for Lightning {
    fn apply(&self, input: &ImageView<'_>, output: &mut ImageViewMut<'_>, seq: u64) {
        let (w, h) = (input.width as f32, input.height as f32);
        let k = size_scale(input.width, input.height).max(0.05);
        let age = seq % STRIKE_FRAMES;
        let paths = self.paths(seq / STRIKE_FRAMES, w, h);
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
        let stamp = glow_stamp(core, glow);
        for (pi, path) in paths.iter().enumerate() {
            let strength = if pi == 0 { 1.0 } else { 0.7 };
            draw_path(output, path, &stamp, core, (a, strength));
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
