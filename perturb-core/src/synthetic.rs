//! Synthetic sensors: a street scene for the camera and a ray-cast VLP-32C, both moving slowly
//! forward frame after frame. They are what the demo and the tests run on when no recorded data is
//! at hand; frame `n` depends on `n` alone.
//!
//! The world: a straight two-lane road along +x (lane edges at y = ±3.5 m, a dashed centre line),
//! sidewalks, parked cars on both sides every 15 m, building walls at |y| = 12 m with gaps, and sky.
//! The ego vehicle drives at 5 m/s along +x.
//!
//! ```
//! use perturb_core::synthetic::{street_image, vlp32c_scan};
//! let img = street_image(160, 100, 0);
//! assert_eq!((img.width, img.height), (160, 100));
//! let scan = vlp32c_scan(0);
//! assert!(scan.len() > 20_000);
//! ```

use crate::cloud::{Cloud, Datatype, PointField, PointLayout};
use crate::image::{Image, PixelFormat};
use crate::rng::mix64;
use crate::sensor_model::VLP32C_ELEVATIONS;
use rayon::prelude::*;
use std::sync::Arc;

/// Ego speed in m/s.
pub const EGO_SPEED: f32 = 5.0;

#[derive(Clone, Copy)]
struct Aabb {
    min: [f32; 3],
    max: [f32; 3],
    color: [u8; 3],
    reflectivity: f32,
}

/// Parked cars and building walls around the ego position `ex` (world x of the ego vehicle).
fn obstacles(ex: f32) -> Vec<Aabb> {
    let mut v = Vec::new();
    let first = ((ex - 30.0) / 15.0).floor() as i64;
    for k in first..first + 10 {
        let x = k as f32 * 15.0;
        for (side, y) in [(0u64, 5.4f32), (1, -5.4)] {
            let h = mix64((k as u64).wrapping_mul(2).wrapping_add(side));
            if h.is_multiple_of(4) {
                continue; // a free parking spot
            }
            let palette = [
                [180, 30, 30],
                [30, 60, 160],
                [200, 200, 205],
                [25, 25, 28],
                [90, 110, 60],
            ];
            let color = palette[(h >> 8) as usize % palette.len()];
            let len = 4.0 + ((h >> 16) % 8) as f32 * 0.1;
            v.push(Aabb {
                min: [x, y - 0.9, 0.0],
                max: [x + len, y + 0.9, 1.45 + ((h >> 24) % 4) as f32 * 0.05],
                color,
                reflectivity: 0.6,
            });
        }
        // Building walls with gaps.
        for (side, y0, y1) in [(2u64, 12.0f32, 20.0f32), (3, -20.0, -12.0)] {
            let h = mix64((k as u64).wrapping_mul(7).wrapping_add(side));
            if h.is_multiple_of(5) {
                continue;
            }
            let shade = 120 + (h >> 8) as u8 % 80;
            v.push(Aabb {
                min: [x, y0, 0.0],
                max: [x + 14.0, y1, 8.0 + ((h >> 16) % 12) as f32],
                color: [shade, shade.saturating_sub(25), shade.saturating_sub(45)],
                reflectivity: 0.3,
            });
        }
    }
    v
}

/// Ray-box intersection (slab method): distance along the ray, if any, and the hit face normal
/// axis.
fn hit(b: &Aabb, o: [f32; 3], d: [f32; 3]) -> Option<(f32, usize)> {
    let (mut t0, mut t1, mut axis) = (0.0f32, f32::INFINITY, 0);
    for a in 0..3 {
        if d[a].abs() < 1e-9 {
            if o[a] < b.min[a] || o[a] > b.max[a] {
                return None;
            }
            continue;
        }
        let inv = 1.0 / d[a];
        let (mut ta, mut tb) = ((b.min[a] - o[a]) * inv, (b.max[a] - o[a]) * inv);
        if ta > tb {
            std::mem::swap(&mut ta, &mut tb);
        }
        if ta > t0 {
            t0 = ta;
            axis = a;
        }
        t1 = t1.min(tb);
        if t0 > t1 {
            return None;
        }
    }
    (t0 > 0.0).then_some((t0, axis))
}

fn ground_color(x: f32, y: f32) -> [u8; 3] {
    let ay = y.abs();
    let grain =
        (mix64(((x * 20.0) as i64 as u64) << 20 ^ (y * 20.0) as i64 as u64) % 17) as i32 - 8;
    let base: [i32; 3] = if (3.35..3.55).contains(&ay) || (ay < 0.08 && x.rem_euclid(9.0) < 3.0) {
        [225, 225, 215] // lane edge, dashed centre line
    } else if ay < 4.5 {
        [88, 88, 92] // asphalt
    } else if ay < 7.5 {
        [150, 146, 140] // parking strip and sidewalk
    } else {
        [70, 105, 55] // grass
    };
    base.map(|c| (c + grain).clamp(0, 255) as u8)
}

/// Where a box can appear on screen: the pixel rectangle (inclusive, with a margin) covering the
/// projections of its corners, or the whole frame for a box the camera plane cuts; `None` for a
/// box entirely behind the camera, which no ray can hit.
fn screen_bounds(
    b: &Aabb,
    cam: [f32; 3],
    f: f32,
    (cx, cy): (f32, f32),
    (w, h): (u32, u32),
) -> Option<[i64; 4]> {
    let full = [0, w as i64 - 1, 0, h as i64 - 1];
    if b.max[0] <= cam[0] {
        return None;
    }
    if b.min[0] <= cam[0] + 1e-3 {
        return Some(full);
    }
    let (mut u0, mut u1, mut v0, mut v1) = (f32::MAX, f32::MIN, f32::MAX, f32::MIN);
    for corner in 0..8 {
        let x = if corner & 1 == 0 { b.min[0] } else { b.max[0] } - cam[0];
        let y = if corner & 2 == 0 { b.min[1] } else { b.max[1] } - cam[1];
        let z = if corner & 4 == 0 { b.min[2] } else { b.max[2] } - cam[2];
        // Pixel centre u + 0.5 looks along (1, -(u + 0.5 - cx) / f, -(v + 0.5 - cy) / f).
        let u = cx - f * y / x - 0.5;
        let v = cy - f * z / x - 0.5;
        u0 = u0.min(u);
        u1 = u1.max(u);
        v0 = v0.min(v);
        v1 = v1.max(v);
    }
    // Two pixels of margin absorb float rounding; the ray test below decides exactly.
    let r = [
        (u0.floor() as i64 - 2).max(0),
        (u1.ceil() as i64 + 2).min(w as i64 - 1),
        (v0.floor() as i64 - 2).max(0),
        (v1.ceil() as i64 + 2).min(h as i64 - 1),
    ];
    (r[0] <= r[1] && r[2] <= r[3]).then_some(r)
}

/// A street-scene frame of `width` x `height` rgb8 at frame `n` (30 frames per second): camera
/// 1.5 m above the road, looking along the road with a 90 degree horizontal field of view.
///
/// Each pixel casts a ray against the ground plane and the boxes whose screen rectangle holds the
/// pixel (the rectangles only skip boxes a ray cannot hit, so the picture is that of testing every
/// box).
pub fn street_image(width: u32, height: u32, n: u64) -> Image {
    let mut img = Image::new(width, height, PixelFormat::Rgb8);
    if width == 0 || height == 0 {
        return img;
    }
    let ex = EGO_SPEED * n as f32 / 30.0;
    let obs = obstacles(ex);
    let cam = [ex, 0.3, 1.5];
    let f = width as f32 / 2.0; // 90 degree horizontal field of view
    let (cx, cy) = (width as f32 / 2.0, height as f32 * 0.45);
    let visible: Vec<(Aabb, [i64; 4])> = obs
        .iter()
        .filter_map(|b| screen_bounds(b, cam, f, (cx, cy), (width, height)).map(|r| (*b, r)))
        .collect();
    let stride = img.stride;
    img.data
        .par_chunks_mut(stride)
        .enumerate()
        .for_each(|(v, row)| {
            let row_boxes: Vec<&(Aabb, [i64; 4])> = visible
                .iter()
                .filter(|(_, r)| r[2] <= v as i64 && v as i64 <= r[3])
                .collect();
            for u in 0..width as usize {
                // Camera frame: x forward, y left, z up.
                let d = [1.0, -(u as f32 + 0.5 - cx) / f, -(v as f32 + 0.5 - cy) / f];
                let mut best = f32::INFINITY;
                let mut color = [0u8; 3];
                for (b, r) in &row_boxes {
                    if (u as i64) < r[0] || (u as i64) > r[1] {
                        continue;
                    }
                    if let Some((t, axis)) = hit(b, cam, d)
                        && t < best
                    {
                        best = t;
                        let shade = [1.0, 0.8, 0.65][axis];
                        color = b.color.map(|c| (c as f32 * shade) as u8);
                    }
                }
                if d[2] < 0.0 {
                    let t = cam[2] / -d[2];
                    if t < best && t < 400.0 {
                        best = t;
                        color = ground_color(cam[0] + d[0] * t, cam[1] + d[1] * t);
                        let haze = (t / 400.0).min(1.0);
                        color = color.map(|c| (c as f32 * (1.0 - haze) + 190.0 * haze) as u8);
                    }
                }
                if best.is_infinite() {
                    let k = (-d[2]).clamp(-1.0, 0.0) + 1.0;
                    color = [
                        (110.0 + 60.0 * k) as u8,
                        (160.0 + 40.0 * k) as u8,
                        (230.0 + 15.0 * k) as u8,
                    ];
                }
                row[u * 3..u * 3 + 3].copy_from_slice(&color);
            }
        });
    img
}

/// The `velodyne_pointcloud` PointXYZIRT layout: x, y, z float32, intensity float32 at 16, ring
/// uint16 at 20, time float32 at 24 (seconds from the start of the scan), 32 bytes per point.
pub fn velodyne_layout() -> PointLayout {
    PointLayout {
        fields: vec![
            PointField::new("x", 0, Datatype::Float32),
            PointField::new("y", 4, Datatype::Float32),
            PointField::new("z", 8, Datatype::Float32),
            PointField::new("intensity", 16, Datatype::Float32),
            PointField::new("ring", 20, Datatype::Uint16),
            PointField::new("time", 24, Datatype::Float32),
        ],
        point_step: 32,
        big_endian: false,
    }
}

/// One revolution of a VLP-32C at frame `n` (10 Hz, 0.2 degree azimuth steps, 1.9 m above the
/// road): about 40-55k points with intensity 0..255, ring and per-point time.
pub fn vlp32c_scan(n: u64) -> Cloud {
    let ex = EGO_SPEED * n as f32 / 10.0;
    let obs = obstacles(ex);
    let o = [ex, 0.3, 1.9];
    let steps = 1800usize;
    let layout = velodyne_layout();
    let rows: Vec<Vec<[f32; 6]>> = (0..steps)
        .into_par_iter()
        .map(|a| {
            let az = a as f32 * std::f32::consts::TAU / steps as f32;
            let mut pts = Vec::with_capacity(32);
            for (ring, elev) in VLP32C_ELEVATIONS.iter().enumerate() {
                let (se, ce) = crate::math::sincosf(elev.to_radians());
                let d = [ce * crate::math::cosf(az), ce * crate::math::sinf(az), se];
                let mut best = f32::INFINITY;
                let mut refl = 0.0;
                for b in &obs {
                    if let Some((t, _)) = hit(b, o, d)
                        && t < best
                    {
                        best = t;
                        refl = b.reflectivity;
                    }
                }
                if d[2] < 0.0 {
                    let t = o[2] / -d[2];
                    if t < best {
                        best = t;
                        let g = ground_color(o[0] + d[0] * t, o[1] + d[1] * t);
                        refl = if g[0] > 200 { 0.8 } else { 0.12 };
                    }
                }
                if !(1.0..=100.0).contains(&best) {
                    continue;
                }
                let jitter = ((mix64(n ^ (a as u64) << 8 ^ ring as u64) % 1000) as f32 / 1000.0
                    - 0.5)
                    * 0.02;
                let r = best + jitter;
                let intensity = (255.0 * refl * (1.0 - r / 150.0)).clamp(1.0, 255.0).round();
                let time = a as f32 / steps as f32 * 0.1;
                pts.push([d[0] * r, d[1] * r, d[2] * r, intensity, ring as f32, time]);
            }
            pts
        })
        .collect();
    let n_pts: usize = rows.iter().map(Vec::len).sum();
    let mut cloud = Cloud::zeroed(Arc::new(layout.clone()), n_pts);
    let rd = |name: &str| layout.reader(name).expect("velodyne field");
    let (rx, ry, rz, ri, rr, rt) = (
        rd("x"),
        rd("y"),
        rd("z"),
        rd("intensity"),
        rd("ring"),
        rd("time"),
    );
    for (p, dst) in rows.iter().flatten().zip(cloud.data.chunks_exact_mut(32)) {
        rx.write_f32(dst, p[0]);
        ry.write_f32(dst, p[1]);
        rz.write_f32(dst, p[2]);
        ri.write_f32(dst, p[3]);
        rr.write_f64(dst, p[4] as f64);
        rt.write_f32(dst, p[5]);
    }
    cloud
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frames_move_and_are_reproducible() {
        let a = street_image(120, 80, 3);
        assert_eq!(a, street_image(120, 80, 3));
        assert_ne!(a, street_image(120, 80, 30));
        let s = vlp32c_scan(2);
        assert_eq!(s, vlp32c_scan(2));
        assert_ne!(s.data, vlp32c_scan(3).data);
        let ring = s.layout.reader("ring").unwrap();
        let max_ring = (0..s.len())
            .map(|i| ring.read_f64(s.view().point(i)) as u32)
            .max()
            .unwrap();
        assert_eq!(max_ring, 31);
    }

    #[test]
    fn scan_sees_the_ground_at_the_mount_height() {
        let s = vlp32c_scan(0);
        let z = s.layout.reader("z").unwrap();
        let lowest = (0..s.len())
            .map(|i| z.read_f32(s.view().point(i)))
            .fold(f32::INFINITY, f32::min);
        assert!((lowest + 1.9).abs() < 0.05, "lowest z {lowest}");
    }
}
