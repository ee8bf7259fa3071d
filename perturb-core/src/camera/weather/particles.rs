//! Particles drawn per frame (C-C7 rain, C-C8 raindrops on the lens, C-C12 snowflakes).

use super::{Blend, OVERLAY_WEIGHT, PARTICLE_SIZE_AT, REFERENCE_FRAME, copy_frame, per_area};
use crate::camera::ops::par_rows;
use crate::camera::texture::size_scale;
use crate::camera::{CameraBuilder, CameraPerturbation, CameraSetup};
use crate::image::{ImageView, ImageViewMut};
use crate::math::Portable;
use crate::rng::Rng;
use rayon::prelude::*;

/// One rain streak of [`Rain`]: start position, fall speed (pixels per frame), length, width.
struct Streak {
    x: f32,
    y: f32,
    speed: f32,
    len: f32,
    width: f32,
}

/// C-C7 rain: falling rain streaks, procedural and animated. A fixed population of streaks, one per
/// 600 pixels of the frame ([`per_area`]: the same share of any frame covered), 1-2 px wide and
/// 10-30 px long, slanted by a wind angle within ±10 degrees drawn per seed, falls at its own speed
/// (relative to the frame: 25-50 px per frame at 503 rows); at frame n a streak is
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
pub const RAIN: CameraBuilder = |s| Ok(Box::new(Rain::new(s)));

impl Rain {
    /// The streak population of the setup's seed and frame size, and its severity's weight.
    pub fn new(s: &CameraSetup) -> Self {
        let (w, h) = (s.geometry.width as f32, s.geometry.height as f32);
        let k = size_scale(s.geometry.width, s.geometry.height).max(0.05);
        let mut rng = Rng::for_setup(s.seed, 0xC7);
        let slant = (rng.f32() * 20.0 - 10.0).to_radians().ptan();
        let (sw, sh) = PARTICLE_SIZE_AT;
        let n = per_area(
            (sw * sh) as f64 / RAIN_PIXELS_PER_STREAK,
            PARTICLE_SIZE_AT,
            s.geometry.width,
            s.geometry.height,
        );
        let streaks = (0..n)
            .map(|_| Streak {
                x: rng.f32() * w,
                y: rng.f32() * h,
                speed: (25.0 + rng.f32() * 25.0) * k,
                len: 10.0 + rng.f32() * 20.0,
                width: 1.0 + rng.f32(),
            })
            .collect();
        Rain {
            streaks,
            slant,
            weight: OVERLAY_WEIGHT[s.level()],
        }
    }
}

/// C-C7 rain: one streak per this many pixels of the frame.
pub const RAIN_PIXELS_PER_STREAK: f64 = 600.0;

/// Rows per band of [`Rain`]'s drawing: a band (about 0.4 MB of a 1920-wide frame) stays in
/// the core's cache while every streak that crosses it is drawn.
const RAIN_BAND: usize = 64;

impl CameraPerturbation for Rain {
    /// Draws the streaks in bands of rows (in parallel): each band is copied from the input, then
    /// every streak that crosses it is drawn into it, in streak order, so every pixel receives its
    /// streaks in the same order as when drawing streak after streak over the whole frame (the same
    /// bytes), while the frame is walked once instead of once per streak row.
    fn apply(&self, input: &ImageView<'_>, output: &mut ImageViewMut<'_>, seq: u64) {
        let (w, h) = (input.width as f32, input.height as f32);
        let colour = [205.0, 215.0, 235.0];
        let format = output.format;
        let c = format.channels();
        let width = output.width as i64;
        // Where each streak is in this frame: head position, rows drawn, half width.
        let placed: Vec<(f32, f32, i64, f32)> = self
            .streaks
            .iter()
            .map(|s| {
                let fall = s.speed * (seq % 1_000_000) as f32;
                let y = (s.y + fall).rem_euclid(h + s.len) - s.len;
                let x = (s.x + self.slant * fall).rem_euclid(w);
                (x, y, s.len.ceil() as i64, s.width / 2.0)
            })
            .collect();
        let mut rows = output.rows_mut();
        rows.par_chunks_mut(RAIN_BAND)
            .enumerate()
            .for_each(|(band, rows)| {
                let top = band * RAIN_BAND;
                for (k, row) in rows.iter_mut().enumerate() {
                    row.copy_from_slice(input.row(top + k));
                }
                let (lo, hi) = (top as i64, (top + rows.len()) as i64);
                for &(x, y, steps, half) in &placed {
                    // A streak's rows `(y + t) as i64` never decrease with t.
                    if steps <= 0 || ((y + (steps - 1) as f32) as i64) < lo || y as i64 >= hi {
                        continue;
                    }
                    for t in 0..steps {
                        let (py, px) = (y + t as f32, x + self.slant * t as f32);
                        // Fade in along the streak: its head is the brightest.
                        let a = self.weight * (0.4 + 0.6 * t as f32 / steps as f32);
                        let r = py as i64;
                        if r < lo || r >= hi || a <= 0.0 {
                            continue;
                        }
                        let blend = Blend::new(format, colour, a);
                        let row = &mut rows[(r - lo) as usize];
                        let mut dx = -half;
                        while dx <= half {
                            let col = (px + dx) as i64;
                            if (0..width).contains(&col) {
                                let at = col as usize * c;
                                blend.pixel(&mut row[at..at + c]);
                            }
                            dx += 1.0;
                        }
                    }
                }
            });
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
/// computed from (seed, n) alone. Counts are per unit of image area ([`per_area`]): the
/// reference's 100 (s + 1) per 320 x 240 frame; flakes are 1.5-4 px in radius on every frame;
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
    // The flakes fill the disc around the centre (out to the half-diagonal), of which the frame
    // shows a share that depends on its shape: the count is corrected so that the flakes the
    // frame shows (and their growing area) are the reference's per unit of area.
    let (rw, rh) = REFERENCE_FRAME;
    let shown = in_frame_flake_area(rw as f64, rh as f64)
        / in_frame_flake_area(w.max(1.0) as f64, h.max(1.0) as f64);
    let n = per_area(
        SNOWFLAKES_LEVELS[s.level()] as f64 * shown,
        REFERENCE_FRAME,
        s.geometry.width,
        s.geometry.height,
    );
    let mut rng = Rng::for_setup(s.seed, 0xC12);
    let flakes = (0..n)
        .map(|_| {
            let angle = rng.f32() * std::f32::consts::TAU;
            let d0 = rng.f32() * (w * w + h * h).sqrt() / 2.0;
            // The reference moves flakes by up to 5 px per frame at 320 x 240.
            let speed = (2.0 + rng.f32() * 4.0) * (w.min(h) / 240.0);
            let radius = 1.5 + rng.f32() * 2.5;
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

/// The mean, over the flakes of [`Snowflakes`] (direction uniform, distance `d` uniform in
/// `[0, R)`, R the half-diagonal, area growing as `(1 + d / R)^2`), of the flake area a `w` x `h`
/// frame shows: the integral over directions of `((1 + L / R)^3 - 1) / 3`, `L` the distance to the
/// frame's edge along the direction (at most R).
fn in_frame_flake_area(w: f64, h: f64) -> f64 {
    let r = 0.5 * w.phypot(h);
    let steps = 3600;
    (0..steps)
        .map(|k| {
            let a = (k as f64 + 0.5) / steps as f64 * std::f64::consts::TAU;
            let (s, c) = a.psin_cos();
            let to_edge = (0.5 * w / c.abs().max(1e-12)).min(0.5 * h / s.abs().max(1e-12));
            let l = to_edge.min(r) / r;
            ((1.0 + l).powi(3) - 1.0) / 3.0
        })
        .sum::<f64>()
        / steps as f64
}

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
                let (x, y) = (cx + angle.pcos() * d, cy + angle.psin() * d);
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

/// Drops on the windshield at once per 320 x 240 frame (the reference keeps 9 there); a frame of
/// another size holds as many per unit of area ([`per_area`]).
pub const RAINDROP_COUNT: usize = 9;

/// C-C8 raindrops: water drops on the windshield that refract the scene and slide down. Each drop
/// is a circle, or a circle with a lower half-ellipse (a teardrop); it shows an inverted, minified,
/// slightly blurred view of the scene around it (the lens a drop forms), with a darker rim, and a
/// soft edge. Drops slide down at a speed set by their size (as the reference's 3 / 1 / 2 pixel
/// steps, relative to the frame's height) and respawn near the top with a new radius uniform in
/// [1, r_max] pixels (the severity; the reference's sizes at its 320 x 240, kept in pixels on
/// every frame); a drop's life is a fixed-period cycle, so frame n is computed from (seed, n)
/// alone. The number of drops is per unit of image area ([`RAINDROP_COUNT`] per 320 x 240): the
/// reference hard-codes 320 x 240.
pub struct Raindrops {
    seed: u64,
    r_max: f32,
    /// Per drop: speed in pixels per frame at 240 rows, phase in frames.
    drops: Vec<(f32, f32)>,
}

/// Registry constructor of C-C8.
pub const RAINDROPS: CameraBuilder = |s| {
    let mut rng = Rng::for_setup(s.seed, 0xC8);
    let count = per_area(
        RAINDROP_COUNT as f64,
        REFERENCE_FRAME,
        s.geometry.width,
        s.geometry.height,
    );
    Ok(Box::new(Raindrops {
        seed: s.seed,
        r_max: RAINDROP_MAX_RADIUS[s.level()],
        drops: (0..count)
            .map(|_| (0.6 + rng.f32() * 1.2, rng.f32() * 10_000.0))
            .collect(),
    }))
};

impl CameraPerturbation for Raindrops {
    fn apply(&self, input: &ImageView<'_>, output: &mut ImageViewMut<'_>, seq: u64) {
        copy_frame(input, output);
        let (w, h) = (input.width as f32, input.height as f32);
        // Speeds and the spawn band are relative to the frame's height; radii are in pixels. A
        // drop's cycle is as long at every severity (room for the largest drop of any), so that
        // the severities draw the same positions and differ only by the drops' sizes.
        let k = h / 240.0;
        let c = input.format.channels();
        let r_top = RAINDROP_MAX_RADIUS[RAINDROP_MAX_RADIUS.len() - 1];
        for (i, &(speed, phase)) in self.drops.iter().enumerate() {
            let v = speed * k;
            let period = ((h + 3.0 * r_top) / v).max(1.0);
            let t = seq as f32 + phase;
            let cycle = (t / period).floor();
            let age = t - cycle * period;
            let mut rng = Rng::for_frame(self.seed, cycle as u64, 0xC80 + i as u64);
            let r = (1.0 + rng.f32() * (self.r_max - 1.0)).max(1.0);
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::image::{Image, ImageGeometry, PixelFormat};

    /// Rain drawn as before the bands: the frame copied, then streak after streak, pixel by pixel.
    fn rain_streak_by_streak(rain: &Rain, input: &Image, seq: u64) -> Image {
        let mut out = input.clone();
        let mut view = out.view_mut();
        let (w, h) = (input.width as f32, input.height as f32);
        for s in &rain.streaks {
            let fall = s.speed * (seq % 1_000_000) as f32;
            let y = (s.y + fall).rem_euclid(h + s.len) - s.len;
            let x = (s.x + rain.slant * fall).rem_euclid(w);
            let steps = s.len.ceil() as i64;
            let half = s.width / 2.0;
            for t in 0..steps {
                let (py, px) = (y + t as f32, x + rain.slant * t as f32);
                let a = rain.weight * (0.4 + 0.6 * t as f32 / steps as f32);
                let mut dx = -half;
                while dx <= half {
                    super::super::blend_px(
                        &mut view,
                        (px + dx) as i64,
                        py as i64,
                        [205.0, 215.0, 235.0],
                        a,
                    );
                    dx += 1.0;
                }
            }
        }
        out
    }

    #[test]
    fn rain_in_bands_gives_the_bytes_of_streak_after_streak() {
        let mut rng = Rng::from_key(7);
        for (w, h, format) in [
            (800, 503, PixelFormat::Rgb8),
            (333, 130, PixelFormat::Bgra8),
            (97, 200, PixelFormat::Mono8),
            (5, 3, PixelFormat::Rgb8),
        ] {
            let c = format.channels();
            let data: Vec<u8> = (0..w * h * c).map(|_| rng.next_u32() as u8).collect();
            let input = Image::from_vec(data, w as u32, h as u32, w * c, format).unwrap();
            for severity in [1, 5] {
                let setup = CameraSetup {
                    severity,
                    seed: 3,
                    geometry: ImageGeometry::new(w as u32, h as u32, format),
                };
                let rain = Rain::new(&setup);
                for seq in [0, 1, 17, 999_999, 1_000_003] {
                    let mut out = input.clone();
                    rain.apply(&input.view(), &mut out.view_mut(), seq);
                    let want = rain_streak_by_streak(&rain, &input, seq);
                    assert!(
                        out.data != input.data || w * h < 100,
                        "{w}x{h}: rain drew nothing"
                    );
                    assert_eq!(
                        out.data, want.data,
                        "{w}x{h} {format:?} s{severity} seq {seq}"
                    );
                }
            }
        }
    }
}
