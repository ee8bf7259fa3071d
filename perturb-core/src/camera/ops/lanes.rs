//! Eight f32 lanes as one number ([`F32x8`]), for generic numeric code that runs eight independent
//! computations at once: rustfft's and realfft's scalar algorithms, instantiated for `F32x8`,
//! transform eight rows or columns in one pass with every operation eight-wide (SIMD registers on
//! every CPU: SSE on x86-64, NEON on aarch64), and each lane gets exactly the bits the f32
//! algorithm gives that row alone.
//!
//! Why the bits are the same: the algorithms are generic over their number type and the same
//! for every type (the planner chooses by length only); every operation on `F32x8` is the f32
//! operation lane by lane (IEEE 754 fixes each result; rustc neither fuses a multiply and an add
//! nor reorders float arithmetic, whatever vector instructions it uses); constants come in through
//! `from_f64`, rounded as f32's `from_f64` rounds. A test compares every lane with the f32
//! transform on odd and prime lengths. (rustfft's own SIMD algorithms are a different matter:
//! they sum in other orders, and fuse on NEON, so each instruction set gets other bits.)

use rustfft::num_traits::{FromPrimitive, Num, One, Signed, Zero};
use std::ops::{Add, Div, Mul, Neg, Rem, Sub};

/// Eight f32 values operated on lane by lane (see the module).
#[derive(Clone, Copy, Debug, PartialEq)]
#[repr(transparent)]
pub struct F32x8(pub [f32; 8]);

/// A number type of one or more f32 lanes: the element type of the transforms of
/// [`crate::camera::color`]'s phase scrambling (`f32`, one transform at a time, or [`F32x8`],
/// eight).
pub trait Lanes: rustfft::FftNum {
    /// Lanes per value.
    const N: usize;
    /// Lane `i`.
    fn lane(&self, i: usize) -> f32;
    /// Sets lane `i`.
    fn set_lane(&mut self, i: usize, v: f32);
}

impl Lanes for f32 {
    const N: usize = 1;
    #[inline(always)]
    fn lane(&self, _: usize) -> f32 {
        *self
    }
    #[inline(always)]
    fn set_lane(&mut self, _: usize, v: f32) {
        *self = v;
    }
}

impl Lanes for F32x8 {
    const N: usize = 8;
    #[inline(always)]
    fn lane(&self, i: usize) -> f32 {
        self.0[i]
    }
    #[inline(always)]
    fn set_lane(&mut self, i: usize, v: f32) {
        self.0[i] = v;
    }
}

macro_rules! lane_op {
    ($tr:ident, $f:ident, $op:tt) => {
        impl $tr for F32x8 {
            type Output = Self;
            #[inline(always)]
            fn $f(self, o: Self) -> Self {
                F32x8(std::array::from_fn(|i| self.0[i] $op o.0[i]))
            }
        }
    };
}
lane_op!(Add, add, +);
lane_op!(Sub, sub, -);
lane_op!(Mul, mul, *);
lane_op!(Div, div, /);
lane_op!(Rem, rem, %);

impl Neg for F32x8 {
    type Output = Self;
    #[inline(always)]
    fn neg(self) -> Self {
        F32x8(self.0.map(|v| -v))
    }
}

impl Zero for F32x8 {
    #[inline(always)]
    fn zero() -> Self {
        F32x8([0.0; 8])
    }
    fn is_zero(&self) -> bool {
        self.0.iter().all(|v| *v == 0.0)
    }
}

impl One for F32x8 {
    #[inline(always)]
    fn one() -> Self {
        F32x8([1.0; 8])
    }
}

impl Num for F32x8 {
    type FromStrRadixErr = <f32 as Num>::FromStrRadixErr;
    /// The number in every lane.
    fn from_str_radix(s: &str, radix: u32) -> Result<Self, Self::FromStrRadixErr> {
        f32::from_str_radix(s, radix).map(|v| F32x8([v; 8]))
    }
}

/// Lane by lane; the predicates hold when they hold in every lane.
impl Signed for F32x8 {
    fn abs(&self) -> Self {
        F32x8(self.0.map(f32::abs))
    }
    fn abs_sub(&self, o: &Self) -> Self {
        let mut r = self.0;
        for (r, o) in r.iter_mut().zip(o.0) {
            *r = Signed::abs_sub(&*r, &o);
        }
        F32x8(r)
    }
    fn signum(&self) -> Self {
        F32x8(self.0.map(f32::signum))
    }
    fn is_positive(&self) -> bool {
        self.0.iter().all(|v| v.is_sign_positive() && *v != 0.0)
    }
    fn is_negative(&self) -> bool {
        self.0.iter().all(|v| v.is_sign_negative() && *v != 0.0)
    }
}

/// The f32 conversion in every lane (so constants round as they do for f32).
impl FromPrimitive for F32x8 {
    fn from_i64(n: i64) -> Option<Self> {
        f32::from_i64(n).map(|v| F32x8([v; 8]))
    }
    fn from_u64(n: u64) -> Option<Self> {
        f32::from_u64(n).map(|v| F32x8([v; 8]))
    }
    fn from_f32(n: f32) -> Option<Self> {
        Some(F32x8([n; 8]))
    }
    fn from_f64(n: f64) -> Option<Self> {
        f32::from_f64(n).map(|v| F32x8([v; 8]))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rustfft::num_complex::Complex;

    fn bits<V: Lanes>(v: &[Complex<V>], lane: usize) -> Vec<(u32, u32)> {
        v.iter()
            .map(|c| (c.re.lane(lane).to_bits(), c.im.lane(lane).to_bits()))
            .collect()
    }

    /// Every lane of rustfft's and realfft's transforms over `F32x8` is bit for bit the f32
    /// transform of that lane's data, forward and inverse, on odd, prime and smooth lengths
    /// (Rader's, Bluestein's and the mixed-radix algorithms all run).
    #[test]
    fn every_lane_is_the_f32_transform_of_its_data() {
        for n in [1usize, 5, 61, 151, 203, 375, 401, 1208, 1242, 1920] {
            let data = |l: usize, i: usize| ((i * 37 + l * 101) % 251) as f32 - 100.5;
            let mut p1 = rustfft::FftPlannerScalar::<f32>::new();
            let mut p8 = rustfft::FftPlannerScalar::<F32x8>::new();
            for dir in [
                rustfft::FftDirection::Forward,
                rustfft::FftDirection::Inverse,
            ] {
                let (f1, f8) = (p1.plan_fft(n, dir), p8.plan_fft(n, dir));
                let mut b8: Vec<Complex<F32x8>> = (0..n)
                    .map(|i| {
                        let re = F32x8(std::array::from_fn(|l| data(l, i)));
                        let im = F32x8(std::array::from_fn(|l| data(l + 3, i)));
                        Complex::new(re, im)
                    })
                    .collect();
                f8.process(&mut b8);
                for l in 0..8 {
                    let mut b1: Vec<Complex<f32>> = (0..n)
                        .map(|i| Complex::new(data(l, i), data(l + 3, i)))
                        .collect();
                    f1.process(&mut b1);
                    assert_eq!(bits(&b8, l), bits(&b1, 0), "length {n} {dir:?} lane {l}");
                }
            }
            let mut r1 = realfft::RealFftPlanner::<f32>::new();
            let mut r8 = realfft::RealFftPlanner::<F32x8>::new();
            let (a1, a8) = (r1.plan_fft_forward(n), r8.plan_fft_forward(n));
            let (i1, i8) = (r1.plan_fft_inverse(n), r8.plan_fft_inverse(n));
            let mut x8: Vec<F32x8> = (0..n)
                .map(|i| F32x8(std::array::from_fn(|l| data(l, i))))
                .collect();
            let mut s8 = a8.make_output_vec();
            a8.process(&mut x8, &mut s8).expect("sizes match");
            let mut back8 = i8.make_output_vec();
            let mut s8_in = s8.clone();
            for s in [0, n / 2] {
                s8_in[s].im = F32x8::zero();
            }
            i8.process(&mut s8_in, &mut back8).expect("sizes match");
            for l in 0..8 {
                let mut x1: Vec<f32> = (0..n).map(|i| data(l, i)).collect();
                let mut s1 = a1.make_output_vec();
                a1.process(&mut x1, &mut s1).expect("sizes match");
                assert_eq!(bits(&s8, l), bits(&s1, 0), "real length {n} lane {l}");
                let mut back1 = i1.make_output_vec();
                for s in [0, n / 2] {
                    s1[s].im = 0.0;
                }
                i1.process(&mut s1, &mut back1).expect("sizes match");
                let lane: Vec<u32> = back8.iter().map(|v| v.lane(l).to_bits()).collect();
                let one: Vec<u32> = back1.iter().map(|v| v.to_bits()).collect();
                assert_eq!(lane, one, "inverse real length {n} lane {l}");
            }
        }
    }

    #[test]
    fn lane_arithmetic_is_f32_arithmetic() {
        let a = F32x8([1.5, -2.0, 0.1, 3.0, f32::MAX, -0.0, 7.0, 1e-40]);
        // No 0/0: the bits of a NaN are the CPU's choice (x86-64 sets its sign, aarch64 does not).
        let b = F32x8([0.3, 4.0, 0.2, -3.0, 2.0, 0.5, 7.0, 3.0]);
        for (i, (&x, &y)) in a.0.iter().zip(&b.0).enumerate() {
            assert_eq!((a + b).0[i].to_bits(), (x + y).to_bits());
            assert_eq!((a - b).0[i].to_bits(), (x - y).to_bits());
            assert_eq!((a * b).0[i].to_bits(), (x * y).to_bits());
            assert_eq!((a / b).0[i].to_bits(), (x / y).to_bits());
            assert_eq!((-a).0[i].to_bits(), (-x).to_bits());
        }
        let c = F32x8::from_f64(0.1).expect("finite");
        assert_eq!(c.0, [0.1f32; 8]);
        assert_eq!(F32x8::from_u64(3).expect("small").0, [3.0; 8]);
        assert!(F32x8::one().is_positive() && (-F32x8::one()).is_negative());
    }
}
