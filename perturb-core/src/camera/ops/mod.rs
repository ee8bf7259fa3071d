//! Building blocks shared by the camera perturbations: row-parallel iteration with deterministic
//! per-row random streams, per-channel lookup tables, Gaussian kernels and separable convolution.

mod buffers;
mod channels;
mod filter;
mod float_image;
mod gaussian;
mod hsv;
mod hsv_avx2;
mod interleave;
mod rows;
mod simd;
mod transpose;

pub use buffers::*;
pub use channels::*;
pub use filter::*;
pub use float_image::*;
pub use gaussian::*;
pub use hsv::*;
#[cfg(target_arch = "x86_64")]
pub(crate) use interleave::{pixel_blocks, plane_blocks};
pub use rows::*;
pub(crate) use simd::wide_fn;
pub use simd::*;
pub use transpose::*;
