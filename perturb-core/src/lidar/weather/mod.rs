//! Weather family (L-A): snow, rain and fog, physics-based and lightweight.
//!
//! | ID | model | module |
//! |---|---|---|
//! | L-A1, L-A5 | LISA Monte-Carlo scattering (Marshall-Gunn snow, Marshall-Palmer rain) | [`lisa`] |
//! | L-A7, L-A8 | Hahner fog: attenuation and soft-target fog returns | [`fog`] |
//! | L-A2, L-A3 | Hahner snowfall: per-beam snowflake occlusion (L-A2 also wets the ground) | [`snow`] |
//! | L-A4, L-A6, L-A9 | lightweight constant-time approximations | [`fast`] |
//!
//! L-A10 strong sunlight is with the noise perturbations (`lidar::noise`).
//!
//! Intensity: every model here works on the sensor model's explicit scale
//! ([`crate::lidar::Points::intensity_max`]): LISA on reflectance in 0..1, Hahner's models on 0..255,
//! converted from and back to the cloud's own scale. A cloud without an intensity field is treated
//! as mid-scale reflectance (documented per model).

pub mod fast;
pub mod fog;
pub mod lisa;
pub mod snow;

/// Speed of light in m/s.
pub const C_LIGHT: f64 = 299_792_458.0;

/// Intensity of point `i` on a 0..1 scale (0.5 when the cloud has no intensity field).
#[inline]
pub(crate) fn unit_intensity(p: &super::Points, i: usize) -> f64 {
    match &p.intensity {
        Some(v) => (v[i] as f64 / p.intensity_max.max(1e-6) as f64).clamp(0.0, 1.0),
        None => 0.5,
    }
}
