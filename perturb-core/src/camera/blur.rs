//! Blur family (C-B): convolutions and resampling that remove detail.

use super::ops::{gaussian_kernel, opencv_sigma, separable_filter};
use super::{CameraBuilder, CameraPerturbation, CameraSetup};
use crate::image::{ImageView, ImageViewMut};

/// C-B5 gaussian_blur: kernel size k, severities 1..5 (PerturbationDrive `gaussian_blur`, which
/// calls `cv2.GaussianBlur(k, k)` with sigma 0, so sigma = 0.3((k-1)/2 - 1) + 0.8 = .8 1.4 2.6 4.1 6.5).
pub const GAUSSIAN_KERNEL: [usize; 5] = [3, 7, 15, 25, 41];

/// C-B5 gaussian_blur: separable k x k Gaussian with OpenCV's sigma for k and reflect-101 borders,
/// on every colour channel; alpha is copied. The kernel is built at configuration time.
pub struct GaussianBlur {
    kernel: Vec<f32>,
}

/// Registry constructor of C-B5.
pub const GAUSSIAN: CameraBuilder = |s| Ok(Box::new(GaussianBlur::new(s)));

impl GaussianBlur {
    /// Builds the kernel for the severity.
    pub fn new(setup: &CameraSetup) -> Self {
        let k = GAUSSIAN_KERNEL[setup.level()];
        GaussianBlur {
            kernel: gaussian_kernel(k, opencv_sigma(k)),
        }
    }
}

impl CameraPerturbation for GaussianBlur {
    fn apply(&self, input: &ImageView<'_>, output: &mut ImageViewMut<'_>, _seq: u64) {
        separable_filter(input, output, &self.kernel);
    }
}
