//! The AVX2 kernel of [`super::SaturationMap::scaled`]: 32 pixels at a time in float lanes,
//! giving the bytes of the fixed-point row (`saturation_row`) on every colour.
//!
//! The fixed-point row computes two roundings of a quotient by an 8-bit number `n`, each as a
//! product with `round(2^32 / n)` ([`super::reciprocals`]): the saturation `S = round(255 diff /
//! V)` and how far a channel `d` below `V` moves down, `round(d S' / S)`. The reciprocal's error
//! is far too small to move a quotient that is not a half across a rounding boundary (those lie
//! at least `1 / 510` from one), so each rounding is the exact rounding of the rational
//! quotient, but an exact half goes up or down with the sign of the reciprocal's error: up where
//! `round(2^32 / n) n >= 2^32`. That bit per `n` ([`TIES_UP`]) is what the float lanes need
//! besides the quotient: `floor((2 a + n - 1 + up(n)) / (2 n))` is `a / n` rounded that way,
//! and [`saturation_group`] computes such floors exactly in f32. A test compares the kernel with
//! the fixed-point row on every RGB colour.
//!
//! Unsafe code is allowed in this module for calling the AVX2 functions after the CPU was
//! checked to have them and for the loads of a 32-byte constant.
#![allow(unsafe_code)]

#[cfg(target_arch = "x86_64")]
use super::{pixel_blocks, plane_blocks};
#[cfg(target_arch = "x86_64")]
use std::arch::x86_64::*;

/// Bit `n` (word `n / 32`, bit `n % 32`) set where `round(2^32 / n) n >= 2^32`, for `n` in
/// 1..=255: the fixed-point rounding of a quotient by `n` takes exact halves up there (the
/// reciprocal is not below `2^32 / n`) and down elsewhere. Bit 0 is clear (no quotient by 0 is
/// rounded). (Read by the AVX2 kernel, and by a test on every target.)
#[cfg(any(target_arch = "x86_64", test))]
pub(super) const TIES_UP: [u32; 8] = {
    let mut bits = [0u32; 8];
    let mut n = 1u64;
    while n < 256 {
        if super::hsv::rounded_reciprocal(n) * n >= 1 << 32 {
            bits[(n / 32) as usize] |= 1 << (n % 32);
        }
        n += 1;
    }
    bits
};

/// [`super::SaturationMap::scaled`]`(m)` on the whole 32-pixel blocks of a row of 3-byte pixels,
/// `src` to `dst`, the channels taken apart and put back in registers (the map treats the three
/// channels alike, so their order does not matter); returns the pixels written. Without AVX2, or
/// for a factor that is not finite or is negative, it writes nothing and returns 0.
pub(super) fn saturation_rgb(m: f32, src: &[u8], dst: &mut [u8]) -> usize {
    #[cfg(target_arch = "x86_64")]
    if super::wide_available() && m.is_finite() && m >= 0.0 {
        // SAFETY: the CPU has AVX2 and FMA (`wide_available` checked them).
        return unsafe { saturation_rgb_avx2(m, src, dst) };
    }
    let _ = (m, src, dst);
    0
}

/// [`saturation_rgb`] over byte planes of red, green and blue, in place.
pub(super) fn saturation_planes(m: f32, r: &mut [u8], g: &mut [u8], b: &mut [u8]) -> usize {
    #[cfg(target_arch = "x86_64")]
    if super::wide_available() && m.is_finite() && m >= 0.0 {
        // SAFETY: the CPU has AVX2 and FMA (`wide_available` checked them).
        return unsafe { saturation_planes_avx2(m, r, g, b) };
    }
    let _ = (m, r, g, b);
    0
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
fn saturation_rgb_avx2(m: f32, src: &[u8], dst: &mut [u8]) -> usize {
    pixel_blocks(src, dst, |x| saturation_block::<true>(m, x))
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
fn saturation_planes_avx2(m: f32, r: &mut [u8], g: &mut [u8], b: &mut [u8]) -> usize {
    plane_blocks([r, g, b], |x| saturation_block::<false>(m, x))
}

/// 0 or 1 per 32-bit lane: bit `n` of [`TIES_UP`] for `n` in 0..=255.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
#[inline]
fn ties_up(bits: __m256i, n: __m256i) -> __m256i {
    let word = _mm256_permutevar8x32_epi32(bits, _mm256_srli_epi32::<5>(n));
    let bit = _mm256_srlv_epi32(word, _mm256_and_si256(n, _mm256_set1_epi32(31)));
    _mm256_and_si256(bit, _mm256_set1_epi32(1))
}

/// 32 pixels' channels, a vector each, mapped as [`saturation_rgb`] does: eight pixels at a
/// time [`saturation_group`] gives how far each channel moves down from the value `V`, and the
/// bytes are `V` minus that, saturating at 0.
///
/// `ROWS` only tells apart the copies for rows and for planes: each then has one caller, which
/// the compiler inlines it into whatever its tuning (called once per block instead, it gets
/// and returns its vectors through memory, about 15 % slower; a build for this VM's own CPU did
/// that to the one shared copy).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
#[inline]
fn saturation_block<const ROWS: bool>(m: f32, x: [__m256i; 3]) -> [__m256i; 3] {
    // SAFETY: `TIES_UP` is 32 bytes, the size of the unaligned load.
    let bits = unsafe { _mm256_loadu_si256(TIES_UP.as_ptr().cast()) };
    let m = _mm256_set1_ps(m);
    let v = _mm256_max_epu8(_mm256_max_epu8(x[0], x[1]), x[2]);
    let diff = _mm256_sub_epi8(v, _mm256_min_epu8(_mm256_min_epu8(x[0], x[1]), x[2]));
    // Each channel's distance below the value (no channel exceeds it).
    let below = x.map(|c| _mm256_sub_epi8(v, c));
    // Pixels 8 q.. of a vector of bytes in 32-bit lanes.
    let widen = |b: __m256i, q: usize| {
        let half = match q / 2 {
            0 => _mm256_castsi256_si128(b),
            _ => _mm256_extracti128_si256::<1>(b),
        };
        let eight = match q % 2 {
            0 => half,
            _ => _mm_unpackhi_epi64(half, half),
        };
        _mm256_cvtepu8_epi32(eight)
    };
    let mut moves = [[_mm256_setzero_si256(); 3]; 4];
    // One call site, so that the group is inlined (the loop is unrolled after).
    for (q, moves) in moves.iter_mut().enumerate() {
        let below = below.map(|d| widen(d, q));
        *moves = saturation_group(m, bits, widen(v, q), widen(diff, q), below);
    }
    // The moves (not negative) packed with unsigned saturation to 16 bits, then to bytes (a
    // move above 255 becomes 255, which takes any value to 0 just as well); each 128-bit half
    // then holds four pixels of each group, which the permutation puts back in order.
    let order = _mm256_setr_epi32(0, 4, 1, 5, 2, 6, 3, 7);
    std::array::from_fn(|k| {
        let first = _mm256_packus_epi32(moves[0][k], moves[1][k]);
        let second = _mm256_packus_epi32(moves[2][k], moves[3][k]);
        let moves = _mm256_permutevar8x32_epi32(_mm256_packus_epi16(first, second), order);
        _mm256_subs_epu8(v, moves)
    })
}

/// Eight pixels of [`saturation_block`] in 32-bit lanes: their value `V`, the difference `diff`
/// of their largest and smallest channel and their channels' distances `d` below `V`; gives how
/// far each channel moves down from `V` (at least 0; anything above 255 means to 0). Per pixel:
/// `S = max(1, floor((510 diff + V - 1 + up(V)) / (2 max(V, 1))))` (the fixed-point row's `S`,
/// clamped the same way; black pixels get 1), `S' = floor(min(255, S m))` with the table's own
/// f32 operations, and per channel the move `floor((2 d S' + S - 1 + up(S)) / (2 S))`.
///
/// Both floors are exact. The first is the floor of the f32 product of `t + 1/2` (`t` the whole
/// numerator, below 2^18, so `t + 1/2` is exact) and the f32 quotient `0.5 / n`: that product
/// is within a relative 2^-23 of `(t + 1/2) / (2 n)`, which lies at least `1 / (4 n) >= 1 /
/// 1020` from a whole number, and the error at most 2^-23 of 256. The second is `d g + b` in
/// one fused rounding, `g = S' / S` and `b = (S - 1/2 + up(S)) / (2 S)` each correctly rounded:
/// within 2^-23 of 256 (about 3e-5) of the quotient wherever the move is below 256, and at
/// least 256 wherever it should be.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
#[inline]
fn saturation_group(
    m: __m256,
    bits: __m256i,
    v: __m256i,
    diff: __m256i,
    d: [__m256i; 3],
) -> [__m256i; 3] {
    let half = _mm256_set1_ps(0.5);
    // S: t + 1/2 = 510 diff + (V + up(V)) - 1/2, every step exact.
    let v_up = _mm256_cvtepi32_ps(_mm256_add_epi32(v, ties_up(bits, v)));
    let t = _mm256_fmadd_ps(
        _mm256_cvtepi32_ps(diff),
        _mm256_set1_ps(510.0),
        _mm256_sub_ps(v_up, half),
    );
    let n = _mm256_max_ps(_mm256_cvtepi32_ps(v), _mm256_set1_ps(1.0));
    // The product is not negative (t >= -1/2 only for black, where 1 is taken): truncation is
    // the floor.
    let s = _mm256_cvttps_epi32(_mm256_mul_ps(t, _mm256_div_ps(half, n)));
    let s = _mm256_max_epi32(s, _mm256_set1_epi32(1));
    let sf = _mm256_cvtepi32_ps(s);
    let s2 = _mm256_floor_ps(_mm256_min_ps(_mm256_mul_ps(sf, m), _mm256_set1_ps(255.0)));
    let g = _mm256_div_ps(s2, sf);
    let bias = _mm256_sub_ps(
        _mm256_cvtepi32_ps(_mm256_add_epi32(s, ties_up(bits, s))),
        half,
    );
    let b = _mm256_div_ps(bias, _mm256_add_ps(sf, sf));
    d.map(|d| _mm256_cvttps_epi32(_mm256_fmadd_ps(_mm256_cvtepi32_ps(d), g, b)))
}
