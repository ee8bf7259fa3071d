//! Gaussian filters (C-B5 Gaussian blur, C-B6 low pass on the value channel, C-B7 high pass).

use crate::camera::ops::{GaussianRows, byte, copy_alpha, gaussian_blur, map_value, par_rows};
use crate::camera::{CameraBuilder, CameraPerturbation};
use crate::image::{Image, ImageView, ImageViewMut, PixelFormat};
use rayon::prelude::*;

/// C-B5 gaussian_blur: kernel size k, severities 1..5 (PerturbationDrive `gaussian_blur`, which
/// calls `cv2.GaussianBlur(k, k)` with sigma 0, so sigma = 0.3((k-1)/2 - 1) + 0.8 = .8 1.4 2.6 4.1 6.5).
pub const GAUSSIAN_KERNEL: [usize; 5] = [3, 7, 15, 25, 41];

/// C-B5 gaussian_blur: a k x k Gaussian with OpenCV's sigma for k and reflect-101 borders on every
/// colour channel; alpha is copied. Exact (OpenCV's 8-bit fixed point) up to k = 15; k = 25 is
/// computed at half and k = 41 at quarter resolution with the remaining width (see
/// [`crate::camera::ops::GaussianRows`]: mean error about 0.25 levels against the exact kernel).
pub struct GaussianBlur {
    k: usize,
}

/// Registry constructor of C-B5.
pub const GAUSSIAN: CameraBuilder = |s| {
    Ok(Box::new(GaussianBlur {
        k: GAUSSIAN_KERNEL[s.level()],
    }))
};

impl CameraPerturbation for GaussianBlur {
    fn apply(&self, input: &ImageView<'_>, output: &mut ImageViewMut<'_>, _seq: u64) {
        gaussian_blur(input, output, self.k, 0.0);
    }
}

/// C-B6 low_pass: kernel size applied to the brightness channel, severities 1..5
/// (PerturbationDrive `low_pass_filter`: 15 23 30 36 40, rounded up to odd).
pub const LOW_PASS_KERNEL: [usize; 5] = [15, 23, 31, 37, 41];

/// C-B6 low_pass: a Gaussian blur of the HSV value channel only (OpenCV sigma for k), hue and
/// saturation kept: the scene loses its fine detail in brightness while colours stay in place.
/// The value plane is blurred (see [`crate::camera::ops::GaussianRows`]) and each pixel's channels are
/// rescaled to the blurred value (see [`crate::camera::ops::map_value`]).
pub struct LowPass {
    k: usize,
}

/// Registry constructor of C-B6.
pub const LOW_PASS: CameraBuilder = |s| {
    Ok(Box::new(LowPass {
        k: LOW_PASS_KERNEL[s.level()],
    }))
};

impl CameraPerturbation for LowPass {
    fn apply(&self, input: &ImageView<'_>, output: &mut ImageViewMut<'_>, _seq: u64) {
        let (w, h, c) = (
            input.width as usize,
            input.height as usize,
            input.format.channels(),
        );
        let [ri, gi, bi] = input.format.rgb_offsets();
        let mut v = Image::new(w as u32, h as u32, PixelFormat::Mono8);
        v.data
            .par_chunks_mut(w.max(1))
            .enumerate()
            .for_each(|(y, row)| {
                for (d, p) in row.iter_mut().zip(input.row(y).chunks_exact(c)) {
                    *d = p[ri].max(p[gi]).max(p[bi]);
                }
            });
        let mut blurred = Image::new(w as u32, h as u32, PixelFormat::Mono8);
        gaussian_blur(&v.view(), &mut blurred.view_mut(), self.k, 0.0);
        let blurred = blurred.data;
        map_value(input, output, |y, x, _| blurred[y * w + x]);
    }
}

/// C-B7 high_pass: kernel size of the Gaussian subtracted, severities 1..5 (PerturbationDrive
/// `high_pass_filter`; OpenCV sigmas 5.6 9.2 12.8 16.4 17.3).
pub const HIGH_PASS_KERNEL: [usize; 5] = [35, 59, 83, 107, 113];

/// C-B7 high_pass: unsharp-mask emphasis of edges and noise, `out = clip(2 I - G_k(I))` per colour
/// channel, with the Gaussian computed as in [`crate::camera::ops::GaussianRows`]; alpha is copied. The
/// paper notes its distortion is nearly flat across severities, as the reference's is.
pub struct HighPass {
    k: usize,
}

/// Registry constructor of C-B7.
pub const HIGH_PASS: CameraBuilder = |s| {
    Ok(Box::new(HighPass {
        k: HIGH_PASS_KERNEL[s.level()],
    }))
};

impl CameraPerturbation for HighPass {
    fn apply(&self, input: &ImageView<'_>, output: &mut ImageViewMut<'_>, _seq: u64) {
        let format = input.format;
        let gaussian = GaussianRows::new(input, self.k, 0.0);
        par_rows(input, output, |y, src, dst| {
            let mut blurred = vec![0f32; dst.len()];
            gaussian.row(y, &mut blurred);
            for ((d, &s), b) in dst.iter_mut().zip(src).zip(&mut blurred) {
                *b = 2.0 * s as f32 - *b;
                *d = byte(*b + 0.5);
            }
            copy_alpha(format, src, dst);
        });
    }
}
