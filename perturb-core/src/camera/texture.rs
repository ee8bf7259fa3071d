//! Drawing primitives and procedural textures shared by the pattern and weather perturbations:
//! filled shapes on image rows, value noise and fBm fields, alpha blending of RGBA sprites.

use crate::image::{ImageViewMut, PixelFormat};
use crate::rng::mix64;

/// Pixel sizes of the references are for the paper's 800 x 503 frames: this factor scales them to
/// a frame of `w` x `h` (1 at 800 x 503, 2.4 at 1920 x 1208).
pub fn size_scale(w: u32, h: u32) -> f32 {
    w.min(h) as f32 / 503.0
}

/// Sets the colour channels of pixel (x, y) to `rgb` (grey for mono8), alpha untouched; ignores
/// coordinates outside the image.
#[inline]
pub fn put(out: &mut ImageViewMut<'_>, x: i64, y: i64, rgb: [u8; 3]) {
    if (0..out.height as i64).contains(&y) {
        let format = out.format;
        fill_span(format, out.row_mut(y as usize), x, x + 1, rgb);
    }
}

/// A filled disc of radius `r` (pixels whose centre satisfies dx^2 + dy^2 <= r^2), like
/// `cv2.circle(..., thickness=-1)` without anti-aliasing; one row span per row, clipped.
pub fn fill_disc(out: &mut ImageViewMut<'_>, cx: i64, cy: i64, r: i64, rgb: [u8; 3]) {
    let format = out.format;
    for y in (cy - r).max(0)..(cy + r + 1).min(out.height as i64) {
        let dy = y - cy;
        let half = (((r * r - dy * dy) as f64).sqrt()).floor() as i64;
        fill_span(
            format,
            out.row_mut(y as usize),
            cx - half,
            cx + half + 1,
            rgb,
        );
    }
}

/// A filled axis-aligned rectangle [x0, x1) x [y0, y1), clipped to the image.
pub fn fill_rect(out: &mut ImageViewMut<'_>, x0: i64, y0: i64, x1: i64, y1: i64, rgb: [u8; 3]) {
    let format = out.format;
    for y in y0.max(0)..y1.min(out.height as i64) {
        fill_span(format, out.row_mut(y as usize), x0, x1, rgb);
    }
}

/// Sets the colour channels of pixels `x0..x1` of one row of `format` pixels to `rgb` (grey for
/// mono8), alpha untouched, as [`put`] on each; the span is clipped to the row.
pub fn fill_span(format: PixelFormat, row: &mut [u8], x0: i64, x1: i64, rgb: [u8; 3]) {
    let c = format.channels();
    let w = (row.len() / c) as i64;
    let (x0, x1) = (x0.clamp(0, w) as usize, x1.clamp(0, w) as usize);
    if x0 >= x1 {
        return;
    }
    let span = &mut row[x0 * c..x1 * c];
    if format.is_mono() {
        span.fill(crate::image::luma(rgb[0], rgb[1], rgb[2]));
    } else if c == 3 && rgb[0] == rgb[1] && rgb[1] == rgb[2] {
        span.fill(rgb[0]);
    } else {
        let [ri, gi, bi] = format.rgb_offsets();
        for p in span.chunks_exact_mut(c) {
            p[ri] = rgb[0];
            p[gi] = rgb[1];
            p[bi] = rgb[2];
        }
    }
}

/// Smooth value noise in [0, 1) at (x, y) on a lattice of spacing 1, from `seed`.
pub fn value_noise(seed: u64, x: f32, y: f32) -> f32 {
    let (xi, yi) = (x.floor(), y.floor());
    let (fx, fy) = (x - xi, y - yi);
    let (xi, yi) = (xi as i64, yi as i64);
    let lattice = |i: i64, j: i64| {
        (mix64(
            seed ^ (i as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15)
                ^ (j as u64).wrapping_mul(0xC2B2_AE3D_27D4_EB4F),
        ) >> 40) as f32
            / (1u64 << 24) as f32
    };
    let s = |t: f32| t * t * (3.0 - 2.0 * t);
    let (sx, sy) = (s(fx), s(fy));
    let a = lattice(xi, yi) + (lattice(xi + 1, yi) - lattice(xi, yi)) * sx;
    let b = lattice(xi, yi + 1) + (lattice(xi + 1, yi + 1) - lattice(xi, yi + 1)) * sx;
    a + (b - a) * sy
}

/// Fractal Brownian motion: `octaves` of value noise, each at twice the frequency and `gain` times
/// the amplitude of the previous one; normalised to [0, 1).
pub fn fbm(seed: u64, x: f32, y: f32, octaves: u32, gain: f32) -> f32 {
    let (mut amp, mut freq, mut sum, mut norm) = (1.0, 1.0, 0.0, 0.0);
    for o in 0..octaves {
        sum += amp * value_noise(seed.wrapping_add(o as u64 * 7919), x * freq, y * freq);
        norm += amp;
        amp *= gain;
        freq *= 2.0;
    }
    sum / norm
}

/// An RGBA sprite layer the size of the frame: colour and coverage per pixel. Built at
/// configuration time, blended per frame.
#[derive(Clone, Debug)]
pub struct Layer {
    /// Width.
    pub w: usize,
    /// Height.
    pub h: usize,
    /// Premultiplied-free RGB per pixel.
    pub rgb: Vec<[u8; 3]>,
    /// Coverage per pixel, 0..=255.
    pub alpha: Vec<u8>,
}

impl Layer {
    /// A fully transparent layer.
    pub fn new(w: usize, h: usize) -> Self {
        Layer {
            w,
            h,
            rgb: vec![[0; 3]; w * h],
            alpha: vec![0; w * h],
        }
    }
}

/// Blends `layer` over the frame where its alpha is non-zero: `out = (1 - i a) I + i a O` with `i`
/// the overlay weight and `a` the layer's coverage; rows outside the layer are copied. This is the
/// references' overlay step (`(1 - i) I + i O` where the key mask is set) with soft edges.
pub fn blend_layer(
    input: &crate::image::ImageView<'_>,
    output: &mut ImageViewMut<'_>,
    layer: &Layer,
    weight: f32,
    dx: i64,
    dy: i64,
) {
    let format = input.format;
    let c = format.channels();
    let [ri, gi, bi] = format.rgb_offsets();
    let w = input.width as i64;
    let wq = (weight.clamp(0.0, 1.0) * 256.0) as u32;
    super::ops::par_rows(input, output, |y, src, dst| {
        dst.copy_from_slice(src);
        let ly = y as i64 - dy;
        if ly < 0 || ly >= layer.h as i64 {
            return;
        }
        let lrow = ly as usize * layer.w;
        for x in 0..w.min(layer.w as i64 + dx).max(0) {
            let lx = x - dx;
            if lx < 0 || lx >= layer.w as i64 || x >= w {
                continue;
            }
            let k = lrow + lx as usize;
            let a = layer.alpha[k] as u32;
            if a == 0 {
                continue;
            }
            let t = (a * wq + 128) >> 8; // 0..=256
            let o = layer.rgb[k];
            let p = &mut dst[x as usize * c..x as usize * c + c];
            if format == PixelFormat::Mono8 {
                let l = crate::image::luma(o[0], o[1], o[2]) as u32;
                p[0] = ((p[0] as u32 * (256 - t) + l * t + 128) >> 8) as u8;
            } else {
                for (ch, ov) in [(ri, o[0]), (gi, o[1]), (bi, o[2])] {
                    p[ch] = ((p[ch] as u32 * (256 - t) + ov as u32 * t + 128) >> 8) as u8;
                }
            }
        }
    });
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn noise_is_smooth_bounded_and_seeded() {
        let a = value_noise(1, 3.25, 7.5);
        assert!((0.0..1.0).contains(&a));
        assert_eq!(a, value_noise(1, 3.25, 7.5));
        assert_ne!(a, value_noise(2, 3.25, 7.5));
        assert!((value_noise(1, 3.25, 7.5) - value_noise(1, 3.26, 7.5)).abs() < 0.05);
        let f = fbm(3, 0.3, 0.9, 5, 0.5);
        assert!((0.0..1.0).contains(&f));
    }
}
