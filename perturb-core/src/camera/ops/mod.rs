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
mod lanes;
mod rows;
mod simd;

pub use buffers::*;
pub use channels::*;
pub use filter::*;
pub use float_image::*;
pub use gaussian::*;
pub use hsv::*;
#[cfg(target_arch = "x86_64")]
pub(crate) use interleave::{pixel_blocks, plane_blocks};
pub use lanes::*;
pub use rows::*;
pub(crate) use simd::wide_fn;
pub use simd::*;

/// Serializes the tests of this crate that switch the dispatch ([`force_baseline`]) with those
/// whose assertions depend on it (a kernel that reports how much it did): the switch is
/// process-wide and the test harness runs tests on parallel threads.
#[cfg(test)]
pub(crate) fn dispatch_lock() -> std::sync::MutexGuard<'static, ()> {
    static LOCK: std::sync::Mutex<()> = std::sync::Mutex::new(());
    LOCK.lock().unwrap_or_else(|p| p.into_inner())
}
