//! Weather and illumination family (C-C): frost, snow, fog, brightness, contrast and the animated
//! overlays (rain, raindrops, lightning, smoke, sun glare, snowflakes).

mod illumination;
mod overlays;
mod particles;
mod textures;

pub use illumination::*;
pub use overlays::*;
pub use particles::*;
pub use textures::*;

use super::ops::par_rows;
use crate::image::{ImageView, ImageViewMut, PixelFormat};

/// How many particles a `w` x `h` frame holds when `per_frame` of them fill a `reference` frame:
/// particles are counted per unit of image area, at a fixed size in pixels, so that they cover the
/// same share of any frame, whatever its size and shape (rounded, at least one).
///
/// Every counted effect (C-C1's ice crystals, C-C2's flakes, C-C7's streaks, C-C8's drops, C-C12's
/// flakes) uses it: the reference's per-frame count at its own size is the calibration point
/// (PerturbationDrive's 320 x 240 for the drops and snowflakes), the sizes are those tuned at the
/// paper's 800 x 503 ([`PARTICLE_SIZE_AT`]). A larger frame shows more particles of the same
/// pixel size, not larger ones: the project does not know the lens, and an area density keeps
/// the coverage (and the cost per pixel) of a severity the same on every camera.
pub fn per_area(per_frame: f64, reference: (u32, u32), w: u32, h: u32) -> usize {
    let area = w as f64 * h as f64;
    let reference = (reference.0 as f64 * reference.1 as f64).max(1.0);
    ((per_frame * area / reference).round() as usize).max(1)
}

/// The frame size at which the particles' pixel sizes were tuned (the paper's 800 x 503).
pub const PARTICLE_SIZE_AT: (u32, u32) = (800, 503);

/// PerturbationDrive's native frame, where its per-frame particle counts hold.
pub const REFERENCE_FRAME: (u32, u32) = (320, 240);

/// The overlay blend weight of the animated effects (rain, lightning, smoke, sun glare) at
/// severities 1..5: the references' `out = (1 - i) I + i O` wherever the effect is present.
pub const OVERLAY_WEIGHT: [f32; 5] = [0.15, 0.25, 0.40, 0.60, 0.85];

/// Blends `rgb` into pixel (x, y) of `out` with coverage `a` (0..1), alpha untouched.
#[inline]
fn blend_px(out: &mut ImageViewMut<'_>, x: i64, y: i64, rgb: [f32; 3], a: f32) {
    if x < 0 || y < 0 || x >= out.width as i64 || y >= out.height as i64 || a <= 0.0 {
        return;
    }
    let blend = Blend::new(out.format, rgb, a);
    let c = out.format.channels();
    let row = out.row_mut(y as usize);
    blend.pixel(&mut row[x as usize * c..x as usize * c + c]);
}

/// Blends `rgb` into the pixel bytes `p` of `format` (colour bytes at `rgb_at`) with coverage `a`
/// (0..=1), alpha untouched.
#[inline]
fn blend_into(format: PixelFormat, rgb_at: [usize; 3], p: &mut [u8], rgb: [f32; 3], a: f32) {
    Blend::with_offsets(format, rgb_at, rgb, a).pixel(p);
}

/// One colour blended with one coverage into many pixels: `p (1 - a) + v a`, rounded (halves up),
/// per colour channel, with `1 - a` and `v a` computed once (the same values as computing them per
/// pixel). Mono8 blends the colour's BT.601 luma.
#[derive(Clone, Copy, Debug)]
struct Blend {
    mono: bool,
    rgb_at: [usize; 3],
    keep: f32,
    add: [f32; 3],
}

impl Blend {
    /// The blend of `rgb` with coverage `a` (clamped to at most 1) into `format` pixels.
    #[inline]
    fn new(format: PixelFormat, rgb: [f32; 3], a: f32) -> Self {
        Self::with_offsets(format, format.rgb_offsets(), rgb, a.min(1.0))
    }

    #[inline]
    fn with_offsets(format: PixelFormat, rgb_at: [usize; 3], rgb: [f32; 3], a: f32) -> Self {
        let mono = format.is_mono();
        let add = if mono {
            let l = 0.299 * rgb[0] + 0.587 * rgb[1] + 0.114 * rgb[2];
            [l * a; 3]
        } else {
            rgb.map(|v| v * a)
        };
        Blend {
            mono,
            rgb_at,
            keep: 1.0 - a,
            add,
        }
    }

    /// Blends into the bytes of one pixel.
    #[inline(always)]
    fn pixel(&self, p: &mut [u8]) {
        if self.mono {
            p[0] = (p[0] as f32 * self.keep + self.add[0] + 0.5) as u8;
            return;
        }
        for (ch, add) in self.rgb_at.into_iter().zip(self.add) {
            p[ch] = (p[ch] as f32 * self.keep + add + 0.5) as u8;
        }
    }
}

fn copy_frame(input: &ImageView<'_>, output: &mut ImageViewMut<'_>) {
    par_rows(input, output, |_, s, d| d.copy_from_slice(s));
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::camera::CameraBuilder;
    use crate::image::{Image, PixelFormat};

    fn run(b: CameraBuilder, sev: u8, img: &Image) -> Image {
        crate::camera::apply_once(b, sev, 1, img, 0)
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
        crate::camera::apply_once(b, sev, 3, img, seq)
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
