//! Runtime dispatch to an AVX2 copy of per-row kernels (`wide_fn!`), with two switches that force
//! the portable (baseline) copy: [`force_baseline`] for tests and benchmarks in one process, and
//! the environment variable [`PORTABLE_VAR`] (`PERTURB_PORTABLE=1`) for a whole process tree.

/// The environment variable that makes every instruction-set dispatch of this library take its
/// portable path, in every program built on it (`perturb`, `perturbd`, `perturb-bridge`, the
/// Python package): `PERTURB_PORTABLE=1`. Read once, at the first dispatch; unset, empty or `0`
/// leaves the choice to the CPU, any other value forces the portable path.
///
/// What it reaches: the `wide_fn!` kernels and the hand-written AVX2 kernels (all go through
/// [`wide_available`]), and the FFTs of phase scrambling (rustfft's and realfft's scalar
/// algorithms on every CPU, `camera/color/phase.rs` says why), which run eight transforms at a
/// time in SIMD registers by default and one at a time with the switch ([`portable_forced`]);
/// the float functions whose results differ between C libraries (`exp`, `ln`, `sin`, ...)
/// come from the `libm` crate where they decide bytes, so the portable path and the default give
/// the same bytes on x86-64 with and without AVX2 and on aarch64; the switch lets anyone check
/// that on their own computer (README, "aarch64").
pub const PORTABLE_VAR: &str = "PERTURB_PORTABLE";

/// Whether [`PORTABLE_VAR`] asks for the portable path in this process (read once).
pub fn portable_from_env() -> bool {
    static PORTABLE: std::sync::OnceLock<bool> = std::sync::OnceLock::new();
    *PORTABLE.get_or_init(|| portable_value(std::env::var_os(PORTABLE_VAR).as_deref()))
}

/// [`PORTABLE_VAR`]'s meaning: unset, empty or `0` is off, anything else on.
fn portable_value(v: Option<&std::ffi::OsStr>) -> bool {
    v.is_some_and(|v| !v.is_empty() && v != "0")
}

/// Whether the functions defined with `wide_fn!` (and the hand-written AVX2 kernels) run their
/// AVX2 copy: on x86-64 CPUs that have AVX2, FMA, BMI1, BMI2 and LZCNT (the x86-64-v3 level,
/// every x86-64 CPU since about 2015), unless [`force_baseline`] is on or [`PORTABLE_VAR`] is set.
/// Always false on other architectures (aarch64 runs the baseline copy, compiled there for NEON:
/// docs/performance.md, "aarch64", says why no NEON copy was written). The check is a few cached
/// loads.
#[inline]
pub fn wide_available() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        !BASELINE_ONLY.load(std::sync::atomic::Ordering::Relaxed)
            && !portable_from_env()
            && std::arch::is_x86_feature_detected!("avx2")
            && std::arch::is_x86_feature_detected!("fma")
            && std::arch::is_x86_feature_detected!("bmi1")
            && std::arch::is_x86_feature_detected!("bmi2")
            && std::arch::is_x86_feature_detected!("lzcnt")
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}

/// Whether the portable path is forced in this process ([`force_baseline`] or [`PORTABLE_VAR`]),
/// whatever the CPU: for dispatches whose fast path is not an x86-64 instruction set (phase
/// scrambling's transforms run eight at a time on every CPU by default, one at a time when this
/// is true, with the same bytes).
#[inline]
pub fn portable_forced() -> bool {
    BASELINE_ONLY.load(std::sync::atomic::Ordering::Relaxed) || portable_from_env()
}

/// When set, [`wide_available`] is false.
static BASELINE_ONLY: std::sync::atomic::AtomicBool = std::sync::atomic::AtomicBool::new(false);

/// Makes the `wide_fn!` functions run their baseline copy only (`true`) or the widest the CPU
/// has (`false`, the default, unless [`PORTABLE_VAR`] is set), on every thread: for tests and
/// benchmarks that compare the two.
pub fn force_baseline(on: bool) {
    BASELINE_ONLY.store(on, std::sync::atomic::Ordering::Relaxed);
}

/// Defines a function whose body is compiled twice, for the build's baseline target and for
/// AVX2 (with FMA, BMI1, BMI2 and LZCNT), and runs the copy this CPU can run
/// ([`wide_available`]). The AVX2 copy's inner loops work on eight floats or 32-bit integers at a
/// time instead of four (the baseline, `x86-64-v2`, has 128-bit vectors only). Both copies compute
/// the same values: Rust never fuses a multiply and an add by itself or reorders float
/// arithmetic, so wider instructions change only how many lanes run at once; a test compares the
/// two paths on every camera perturbation. Calling the AVX2 copy is `unsafe`, sound because the
/// features are checked first. (Kernels the compiler does not vectorise well from plain Rust are
/// written with intrinsics instead, as `camera/pointwise/avx2.rs`.)
///
/// Meant for kernels that run per row or per band (the check is a few cached loads per call).
/// Functions the body calls get the wider code only where they are inlined into it. Closures in
/// the body are compiled for AVX2 too, so library code that calls them without being inlined
/// (`collect`, `for_each` on long adapter chains) cannot inline them back and calls them once
/// per element: write such loops as `for` loops over slices. Const generic parameters are
/// supported, type parameters are not.
macro_rules! wide_fn {
    (
        $(#[$meta:meta])*
        $vis:vis fn $name:ident $(<$(const $cg:ident: $ct:ty),+>)?
            ($($arg:ident: $ty:ty),* $(,)?) $(-> $ret:ty)? $body:block
    ) => {
        $(#[$meta])*
        $vis fn $name $(<$(const $cg: $ct),+>)? ($($arg: $ty),*) $(-> $ret)? {
            #[cfg(target_arch = "x86_64")]
            #[target_feature(enable = "avx2,fma,bmi1,bmi2,lzcnt")]
            fn wide $(<$(const $cg: $ct),+>)? ($($arg: $ty),*) $(-> $ret)? $body
            #[inline(always)]
            fn base $(<$(const $cg: $ct),+>)? ($($arg: $ty),*) $(-> $ret)? $body
            #[cfg(target_arch = "x86_64")]
            // Unsafe: calling the AVX2 copy (the features are checked first).
            #[allow(unsafe_code)]
            if $crate::camera::ops::wide_available() {
                // SAFETY: the CPU has every feature the copy is compiled for (`wide_available`
                // checked), which is all such a function needs.
                return unsafe { wide $(::<$($cg),+>)? ($($arg),*) };
            }
            base $(::<$($cg),+>)? ($($arg),*)
        }
    };
}
pub(crate) use wide_fn;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn portable_variable_is_off_only_when_unset_empty_or_zero() {
        use std::ffi::OsStr;
        assert!(!portable_value(None));
        assert!(!portable_value(Some(OsStr::new(""))));
        assert!(!portable_value(Some(OsStr::new("0"))));
        for on in ["1", "yes", "true"] {
            assert!(portable_value(Some(OsStr::new(on))), "{on}");
        }
    }
}
