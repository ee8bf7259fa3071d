//! Camera perturbations: the contract, and one module per family.
//!
//! A camera perturbation is built once for a (severity, seed, [`ImageGeometry`]): that is when it
//! computes its kernels, tables, textures and particle sets. It is then applied to each frame with
//! the frame's sequence number; the output is a pure function of (input, perturbation, severity,
//! seed, sequence number). Implementations write every byte of every output row (alpha is copied).
//!
//! Work inside `apply` is split into row bands with [`ops::par_rows`]; the number of threads is the
//! caller's rayon pool, and the result is the same whatever that number is.

pub mod blur;
pub mod color;
pub mod distortion;
pub mod noise;
pub mod ops;
pub mod pattern;
pub mod pointwise;
pub mod texture;
pub mod weather;

use crate::error::Result;
use crate::image::{ImageGeometry, ImageView, ImageViewMut};

/// What a camera perturbation is configured with.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct CameraSetup {
    /// Severity, 1..=5 (already validated).
    pub severity: u8,
    /// Seed of every random draw.
    pub seed: u64,
    /// The frames it will be applied to.
    pub geometry: ImageGeometry,
}

impl CameraSetup {
    /// Index 0..=4 into a five-level severity table.
    pub fn level(&self) -> usize {
        (self.severity.clamp(1, 5) - 1) as usize
    }
}

/// A configured camera perturbation.
pub trait CameraPerturbation: Send + Sync {
    /// Writes the perturbed `input` into `output`. Both have the geometry given at configuration
    /// (checked by the caller); strides may differ.
    fn apply(&self, input: &ImageView<'_>, output: &mut ImageViewMut<'_>, seq: u64);
}

/// A camera constructor as stored in the registry.
pub type CameraBuilder = fn(&CameraSetup) -> Result<Box<dyn CameraPerturbation>>;

/// Builds `builder` at `severity` with `seed` for `img`'s geometry and applies it once to frame
/// `seq`: the camera unit tests' way of running a perturbation.
#[cfg(test)]
pub(crate) fn apply_once(
    builder: CameraBuilder,
    severity: u8,
    seed: u64,
    img: &crate::image::Image,
    seq: u64,
) -> crate::image::Image {
    let setup = CameraSetup {
        severity,
        seed,
        geometry: img.geometry(),
    };
    let p = builder(&setup).expect("the perturbation builds");
    let mut out = crate::image::Image::with_geometry(img.geometry());
    p.apply(&img.view(), &mut out.view_mut(), seq);
    out
}
