//! Noise family (C-A): sensor noise added to the pixel values.

use super::ops::{par_rows, row_rng};
use super::{CameraBuilder, CameraPerturbation, CameraSetup};
use crate::image::{ImageView, ImageViewMut};
use crate::rng::normal_quantile;

/// C-A1 gaussian_noise: standard deviation of the additive noise, in units of full scale (0..1),
/// severities 1..5 (PerturbationDrive `gaussian_noise`).
pub const GAUSSIAN_SIGMA: [f64; 5] = [0.03, 0.06, 0.12, 0.18, 0.22];

/// C-A1 gaussian_noise: `out = clip(x + N(0, sigma))` on every colour channel independently.
///
/// The reference draws float64 normals and returns float32; here the noise for an 8-bit value is
/// `round(255 sigma z)`, drawn by inverse-CDF lookup in a 65536-entry table built at configuration
/// time (the quantile of each 1/65536 bin's centre), so a frame costs one table read per byte. The
/// result is rounded instead of truncated (the reference's uint8 cast biases by -0.5 level). Alpha
/// is copied.
pub struct GaussianNoise {
    seed: u64,
    table: Box<[i16; 65536]>,
}

/// Registry constructor of C-A1.
pub const GAUSSIAN: CameraBuilder = |s| Ok(Box::new(GaussianNoise::new(s)));

impl GaussianNoise {
    /// Builds the quantile table for the severity.
    pub fn new(setup: &CameraSetup) -> Self {
        let sigma = GAUSSIAN_SIGMA[setup.level()] * 255.0;
        let mut table = Box::new([0i16; 65536]);
        for (k, t) in table.iter_mut().enumerate() {
            let z = normal_quantile((k as f64 + 0.5) / 65536.0);
            *t = (sigma * z).round().clamp(-1024.0, 1024.0) as i16;
        }
        GaussianNoise {
            seed: setup.seed,
            table,
        }
    }
}

impl CameraPerturbation for GaussianNoise {
    fn apply(&self, input: &ImageView<'_>, output: &mut ImageViewMut<'_>, seq: u64) {
        let alpha = input.format.alpha_offset();
        let c = input.format.channels();
        par_rows(input, output, |y, src, dst| {
            let mut rng = row_rng(self.seed, seq, 0xA1, y);
            let mut bits = 0u64;
            let mut left = 0;
            for (i, (s, d)) in src.iter().zip(dst.iter_mut()).enumerate() {
                if alpha.is_some_and(|a| i % c == a) {
                    *d = *s;
                    continue;
                }
                if left == 0 {
                    bits = rng.next_u64();
                    left = 4;
                }
                let n = self.table[(bits & 0xffff) as usize];
                bits >>= 16;
                left -= 1;
                *d = (*s as i16 + n).clamp(0, 255) as u8;
            }
        });
    }
}
