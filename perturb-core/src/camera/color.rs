//! Colour and tone family (C-F): changes of hue, saturation and tone.

use super::ops::par_rows;
use super::{CameraBuilder, CameraPerturbation, CameraSetup};
use crate::error::Error;
use crate::image::{ImageView, ImageViewMut};

/// C-F5 grayscale: blend weight towards the luma, severities 1..5 (PerturbationDrive
/// `grayscale_filter`).
pub const GRAYSCALE_WEIGHT: [f32; 5] = [0.10, 0.20, 0.35, 0.55, 0.85];

/// C-F5 grayscale: `out = (1 - s) I + s Y` per colour channel with `Y = .299 R + .587 G + .114 B`,
/// rounded; alpha is copied. Mono8 input is refused: it is already grey, so the perturbation would
/// do nothing.
pub struct Grayscale {
    weight: f32,
}

/// Registry constructor of C-F5.
pub const GRAYSCALE: CameraBuilder = |s| {
    if s.geometry.format.is_mono() {
        return Err(Error::UnsupportedPixelFormat {
            id: "C-F5",
            format: "mono8 (already grey)",
        });
    }
    Ok(Box::new(Grayscale::new(s)))
};

impl Grayscale {
    /// Configures the blend weight for the severity.
    pub fn new(setup: &CameraSetup) -> Self {
        Grayscale {
            weight: GRAYSCALE_WEIGHT[setup.level()],
        }
    }
}

impl CameraPerturbation for Grayscale {
    fn apply(&self, input: &ImageView<'_>, output: &mut ImageViewMut<'_>, _seq: u64) {
        let format = input.format;
        let [ri, gi, bi] = format.rgb_offsets();
        let c = format.channels();
        let s = self.weight;
        par_rows(input, output, |_, src, dst| {
            for (p, q) in src.chunks_exact(c).zip(dst.chunks_exact_mut(c)) {
                let y = 0.299 * p[ri] as f32 + 0.587 * p[gi] as f32 + 0.114 * p[bi] as f32;
                for ch in [ri, gi, bi] {
                    q[ch] = ((1.0 - s) * p[ch] as f32 + s * y + 0.5).clamp(0.0, 255.0) as u8;
                }
                if let Some(a) = format.alpha_offset() {
                    q[a] = p[a];
                }
            }
        });
    }
}
