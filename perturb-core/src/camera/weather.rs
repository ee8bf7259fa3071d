//! Weather and illumination family (C-C): frost, snow, fog, brightness, contrast and the animated
//! overlays (rain, raindrops, lightning, smoke, sun glare, snowflakes).

use super::ops::{apply_lut, map_value};
use super::{CameraBuilder, CameraPerturbation};
use crate::image::{ImageView, ImageViewMut};

/// A change of HSV value through a 256-entry table, hue and saturation kept (see
/// [`super::ops::map_value`]).
pub struct ValueMap {
    lut: [u8; 256],
}

impl CameraPerturbation for ValueMap {
    fn apply(&self, input: &ImageView<'_>, output: &mut ImageViewMut<'_>, _seq: u64) {
        let lut = &self.lut;
        map_value(input, output, |_, _, v| lut[v as usize]);
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
pub const BRIGHTNESS_UP: CameraBuilder = |s| {
    Ok(Box::new(ValueMap {
        lut: value_lut(BRIGHTNESS_INCREASE[s.level()]),
    }))
};

/// C-C5 brightness_decrease: under-exposure, HSV `V <- V f`, the mirror of C-C4.
pub const BRIGHTNESS_DOWN: CameraBuilder = |s| {
    Ok(Box::new(ValueMap {
        lut: value_lut(BRIGHTNESS_DECREASE[s.level()]),
    }))
};

/// C-C6 contrast: contrast factor, severities 1..5 (PerturbationDrive `contrast`, increase only).
pub const CONTRAST_FACTOR: [f32; 5] = [1.1, 1.2, 1.3, 1.5, 1.7];

/// C-C6 contrast: `out = clip(127.5 + (I - 127.5) f)` on every channel, rounded (the reference
/// returns floats). A per-value table.
pub struct Contrast {
    lut: [u8; 256],
}

/// Registry constructor of C-C6.
pub const CONTRAST: CameraBuilder = |s| {
    let f = CONTRAST_FACTOR[s.level()];
    Ok(Box::new(Contrast {
        lut: std::array::from_fn(|v| {
            (127.5 + (v as f32 - 127.5) * f).round().clamp(0.0, 255.0) as u8
        }),
    }))
};

impl CameraPerturbation for Contrast {
    fn apply(&self, input: &ImageView<'_>, output: &mut ImageViewMut<'_>, _seq: u64) {
        apply_lut(input, output, &self.lut);
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

    #[test]
    fn contrast_stretches_around_mid_grey() {
        let i = Image::from_vec(vec![0, 100, 128, 200, 255], 5, 1, 5, PixelFormat::Mono8).unwrap();
        assert_eq!(run(CONTRAST, 5, &i).data, vec![0, 81, 128, 251, 255]);
    }
}
