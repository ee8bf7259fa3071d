//! Float functions with the same bits on every CPU: the exponentials, logarithms, powers and
//! trigonometric functions of the `libm` crate (a Rust port of musl's C library, compiled by
//! rustc like the rest of this crate), used wherever such a result decides an output byte or
//! point.
//!
//! `f64::exp`, `f32::sin` and the like call the C library of the machine the program runs on.
//! Its results are within an ulp of the exact value but not always the same bits: glibc on x86-64
//! picks an FMA or a plain build of `exp`, `log`, `pow`, `sin`, `cos` at run time by the CPU it
//! finds, aarch64's glibc is compiled with fused multiply-adds throughout, and other versions
//! (a Jetson's Ubuntu, a developer's Fedora) change the code again. One ulp is enough to move a
//! rounding to a byte, so the output hashes would hold per machine only. Rust itself never fuses
//! a multiply and an add nor reorders float arithmetic, so code compiled by rustc, `libm`
//! included, computes the same bits on x86-64 (with and without AVX2) and aarch64; `libm`'s
//! architecture-specific parts are exact operations (`sqrt`, `fma`, `rint`), bit-identical in
//! hardware and in software.
//!
//! `sqrt`, `mul_add`, `floor`, `round`, `abs`, `min`/`max` and `powi` need nothing of this: IEEE
//! 754 fixes their results (or rustc computes them itself). The natural logarithm is `log` (f64)
//! and `logf` (f32), as in C.
//!
//! Every transcendental call of `lidar/` (the detector included) and `camera/` goes through
//! here (through [`Portable`] where the code is a method chain); the standard library's own
//! methods are left to tests that compare with them.

pub use libm::{
    atan2, atan2f, cos, cosf, exp, expf, hypot, hypotf, log, logf, pow, powf, sin, sincos, sincosf,
    sinf, tan, tanf,
};

/// The same functions as methods of `f32` and `f64`, for code written in method chains: `p` for
/// portable, then the standard library's name (`x.psin()` for `x.sin()`, `r.ppowf(e)` for
/// `r.powf(e)`, `v.pln()` for `v.ln()`). Each calls this module's `libm` function of its type.
///
/// ```
/// use perturb_core::math::Portable;
/// let (s, c) = 0.5f64.psin_cos();
/// assert!((s * s + c * c - 1.0).abs() < 1e-15);
/// assert_eq!(2.0f32.ppowf(10.0), 1024.0);
/// ```
pub trait Portable: Sized {
    /// `e^self`.
    fn pexp(self) -> Self;
    /// Natural logarithm.
    fn pln(self) -> Self;
    /// `self^e`.
    fn ppowf(self, e: Self) -> Self;
    /// Sine (radians).
    fn psin(self) -> Self;
    /// Cosine (radians).
    fn pcos(self) -> Self;
    /// Sine and cosine (radians).
    fn psin_cos(self) -> (Self, Self);
    /// Tangent (radians).
    fn ptan(self) -> Self;
    /// Arc sine (radians).
    fn pasin(self) -> Self;
    /// Four-quadrant arc tangent of `self / x` (radians).
    fn patan2(self, x: Self) -> Self;
    /// `sqrt(self^2 + y^2)` without undue overflow.
    fn phypot(self, y: Self) -> Self;
    /// Cube root.
    fn pcbrt(self) -> Self;
}

macro_rules! portable {
    ($t:ty, $exp:ident, $log:ident, $pow:ident, $sin:ident, $cos:ident, $sincos:ident, $tan:ident,
     $asin:ident, $atan2:ident, $hypot:ident, $cbrt:ident) => {
        impl Portable for $t {
            fn pexp(self) -> Self {
                libm::$exp(self)
            }
            fn pln(self) -> Self {
                libm::$log(self)
            }
            fn ppowf(self, e: Self) -> Self {
                libm::$pow(self, e)
            }
            fn psin(self) -> Self {
                libm::$sin(self)
            }
            fn pcos(self) -> Self {
                libm::$cos(self)
            }
            fn psin_cos(self) -> (Self, Self) {
                libm::$sincos(self)
            }
            fn ptan(self) -> Self {
                libm::$tan(self)
            }
            fn pasin(self) -> Self {
                libm::$asin(self)
            }
            fn patan2(self, x: Self) -> Self {
                libm::$atan2(self, x)
            }
            fn phypot(self, y: Self) -> Self {
                libm::$hypot(self, y)
            }
            fn pcbrt(self) -> Self {
                libm::$cbrt(self)
            }
        }
    };
}

portable!(
    f64, exp, log, pow, sin, cos, sincos, tan, asin, atan2, hypot, cbrt
);
portable!(
    f32, expf, logf, powf, sinf, cosf, sincosf, tanf, asinf, atan2f, hypotf, cbrtf
);

#[cfg(test)]
mod tests {
    /// The functions agree with the C library's to within 2 ulp on a sweep of arguments (a
    /// wrong export, say `log10` for `log`, would be far off), and give exactly the values that
    /// are exact in IEEE arithmetic.
    #[test]
    fn agree_with_the_c_library_to_an_ulp_or_two() {
        let ulps = |a: f64, b: f64| (a.to_bits() as i64 - b.to_bits() as i64).unsigned_abs();
        for i in 1..2000 {
            let x = i as f64 * 0.0137 - 9.0;
            let y = i as f64 * 0.051;
            for (name, got, want) in [
                ("exp", super::exp(x), x.exp()),
                ("log", super::log(y), y.ln()),
                ("sin", super::sin(x), x.sin()),
                ("cos", super::cos(x), x.cos()),
                ("tan", super::tan(x / 7.0), (x / 7.0).tan()),
                ("atan2", super::atan2(x, y - 40.0), x.atan2(y - 40.0)),
                ("hypot", super::hypot(x, y), x.hypot(y)),
                ("pow", super::pow(y, x / 3.0), y.powf(x / 3.0)),
            ] {
                assert!(ulps(got, want) <= 2, "{name}({x}, {y}): {got} vs {want}");
            }
            let (xf, yf) = (x as f32, y as f32);
            let ulpf = |a: f32, b: f32| (a.to_bits() as i32 - b.to_bits() as i32).unsigned_abs();
            for (name, got, want) in [
                ("expf", super::expf(xf), xf.exp()),
                ("logf", super::logf(yf), yf.ln()),
                ("sinf", super::sinf(xf), xf.sin()),
                ("cosf", super::cosf(xf), xf.cos()),
                ("tanf", super::tanf(xf / 7.0), (xf / 7.0).tan()),
                ("atan2f", super::atan2f(xf, yf - 40.0), xf.atan2(yf - 40.0)),
                ("hypotf", super::hypotf(xf, yf), xf.hypot(yf)),
                ("powf", super::powf(yf, xf / 3.0), yf.powf(xf / 3.0)),
            ] {
                assert!(ulpf(got, want) <= 2, "{name}({xf}, {yf}): {got} vs {want}");
            }
            assert_eq!(super::sincos(x), (super::sin(x), super::cos(x)));
            assert_eq!(super::sincosf(xf), (super::sinf(xf), super::cosf(xf)));
        }
        assert_eq!(super::exp(0.0), 1.0);
        assert_eq!(super::log(1.0), 0.0);
        assert_eq!(super::powf(2.0, 10.0), 1024.0);
    }
}
