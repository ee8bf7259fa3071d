//! In-place transposes of the 8x8 blocks of a band of 8 float rows (the JPEG round trip's
//! horizontal transforms run as vertical ones between two of them).
//!
//! The AVX2 copy is hand-written: eight row loads, the 24 shuffles of the classic 8x8
//! transpose, eight stores. The compiler's code for the portable one went through memory
//! (about 300 instructions per block where the AVX2 copy has 40). A transpose only moves
//! values, so both give the same floats; a test compares them.
//!
//! Unsafe code is allowed in this module for calling the AVX2 copy after the CPU was checked
//! to have AVX2, and for its loads and stores, whose offsets are checked against the band's
//! length before the loop.
#![allow(unsafe_code)]

#[cfg(target_arch = "x86_64")]
use std::arch::x86_64::*;

/// An 8x8 block of floats, row by row.
pub type Block = [[f32; 8]; 8];

/// Transposes every 8x8 block of a band in place: the band is 8 rows of `pw` floats (`pw` a
/// multiple of 8; a last partial block is left as it is).
///
/// ```
/// # use perturb_core::camera::ops::transpose_blocks;
/// let mut band: Vec<f32> = (0..128).map(|i| i as f32).collect(); // 8 rows of 16
/// transpose_blocks(&mut band, 16);
/// assert_eq!(band[1], 16.0); // row 0, column 1 was row 1, column 0
/// assert_eq!(band[16 + 8], 8.0 + 1.0); // block 2: row 1, column 0 was row 0, column 1
/// ```
pub fn transpose_blocks(band: &mut [f32], pw: usize) {
    assert!(band.len() >= 8 * pw, "a band is 8 rows of {pw} samples");
    #[cfg(target_arch = "x86_64")]
    if super::wide_available() {
        // SAFETY: the CPU has AVX2 (`wide_available` checked it).
        return unsafe { transpose_blocks_avx2(band, pw) };
    }
    transpose_blocks_portable(band, pw)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn transpose_blocks_avx2(band: &mut [f32], pw: usize) {
    let p = band.as_mut_ptr();
    for bx in 0..pw / 8 {
        let at = |y: usize| y * pw + 8 * bx;
        // SAFETY: every access is the 8 floats from `at(y)` for y < 8, which end at most at
        // `7 pw + pw = 8 pw <= band.len()` (asserted by the caller).
        unsafe {
            let r: [__m256; 8] = std::array::from_fn(|y| _mm256_loadu_ps(p.add(at(y))));
            for (y, t) in transpose8_avx(r).into_iter().enumerate() {
                _mm256_storeu_ps(p.add(at(y)), t);
            }
        }
    }
}

/// The transpose of 8 rows of 8 floats: interleave pairs of rows, then pairs of pairs, then
/// swap 128-bit halves.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
#[inline]
fn transpose8_avx(r: [__m256; 8]) -> [__m256; 8] {
    // t0 = a00 a10 a01 a11 | a04 a14 a05 a15, t1 = a02 a12 a03 a13 | a06 a16 a07 a17, ...
    let t = [
        _mm256_unpacklo_ps(r[0], r[1]),
        _mm256_unpackhi_ps(r[0], r[1]),
        _mm256_unpacklo_ps(r[2], r[3]),
        _mm256_unpackhi_ps(r[2], r[3]),
        _mm256_unpacklo_ps(r[4], r[5]),
        _mm256_unpackhi_ps(r[4], r[5]),
        _mm256_unpacklo_ps(r[6], r[7]),
        _mm256_unpackhi_ps(r[6], r[7]),
    ];
    // s[k] (k < 4) = column k of rows 0-3 | column k + 4 of rows 0-3; s[k + 4] for rows 4-7.
    let s = [
        _mm256_shuffle_ps::<0x44>(t[0], t[2]),
        _mm256_shuffle_ps::<0xee>(t[0], t[2]),
        _mm256_shuffle_ps::<0x44>(t[1], t[3]),
        _mm256_shuffle_ps::<0xee>(t[1], t[3]),
        _mm256_shuffle_ps::<0x44>(t[4], t[6]),
        _mm256_shuffle_ps::<0xee>(t[4], t[6]),
        _mm256_shuffle_ps::<0x44>(t[5], t[7]),
        _mm256_shuffle_ps::<0xee>(t[5], t[7]),
    ];
    [
        _mm256_permute2f128_ps::<0x20>(s[0], s[4]),
        _mm256_permute2f128_ps::<0x20>(s[1], s[5]),
        _mm256_permute2f128_ps::<0x20>(s[2], s[6]),
        _mm256_permute2f128_ps::<0x20>(s[3], s[7]),
        _mm256_permute2f128_ps::<0x31>(s[0], s[4]),
        _mm256_permute2f128_ps::<0x31>(s[1], s[5]),
        _mm256_permute2f128_ps::<0x31>(s[2], s[6]),
        _mm256_permute2f128_ps::<0x31>(s[3], s[7]),
    ]
}

/// [`transpose_blocks`] without AVX2.
fn transpose_blocks_portable(band: &mut [f32], pw: usize) {
    for bx in 0..pw / 8 {
        let at = |y: usize| y * pw + bx * 8..y * pw + bx * 8 + 8;
        let mut blk = [[0f32; 8]; 8];
        for (y, row) in blk.iter_mut().enumerate() {
            *row = band[at(y)].try_into().expect("8 samples");
        }
        for (y, row) in transpose8(&blk).iter().enumerate() {
            band[at(y)].copy_from_slice(row);
        }
    }
}

/// The transpose of an 8x8 block, in three stages of two-row shuffles (interleave pairs, then
/// pairs of pairs, then halves): each stage is one shuffle instruction per row when the rows are
/// vectors, where an element-by-element transpose goes through memory.
#[inline(always)]
fn transpose8(a: &Block) -> Block {
    #[inline(always)]
    fn lo(x: &[f32; 8], y: &[f32; 8]) -> [f32; 8] {
        [x[0], y[0], x[1], y[1], x[4], y[4], x[5], y[5]]
    }
    #[inline(always)]
    fn hi(x: &[f32; 8], y: &[f32; 8]) -> [f32; 8] {
        [x[2], y[2], x[3], y[3], x[6], y[6], x[7], y[7]]
    }
    #[inline(always)]
    fn lo2(x: &[f32; 8], y: &[f32; 8]) -> [f32; 8] {
        [x[0], x[1], y[0], y[1], x[4], x[5], y[4], y[5]]
    }
    #[inline(always)]
    fn hi2(x: &[f32; 8], y: &[f32; 8]) -> [f32; 8] {
        [x[2], x[3], y[2], y[3], x[6], x[7], y[6], y[7]]
    }
    #[inline(always)]
    fn lo4(x: &[f32; 8], y: &[f32; 8]) -> [f32; 8] {
        [x[0], x[1], x[2], x[3], y[0], y[1], y[2], y[3]]
    }
    #[inline(always)]
    fn hi4(x: &[f32; 8], y: &[f32; 8]) -> [f32; 8] {
        [x[4], x[5], x[6], x[7], y[4], y[5], y[6], y[7]]
    }
    // After stage 1, t[2i] and t[2i+1] interleave rows 2i and 2i+1.
    let t = [
        lo(&a[0], &a[1]),
        hi(&a[0], &a[1]),
        lo(&a[2], &a[3]),
        hi(&a[2], &a[3]),
        lo(&a[4], &a[5]),
        hi(&a[4], &a[5]),
        lo(&a[6], &a[7]),
        hi(&a[6], &a[7]),
    ];
    // After stage 2, u[k] (k < 4) holds columns k and k + 4 of rows 0-3, u[k + 4] of rows 4-7.
    let u = [
        lo2(&t[0], &t[2]),
        hi2(&t[0], &t[2]),
        lo2(&t[1], &t[3]),
        hi2(&t[1], &t[3]),
        lo2(&t[4], &t[6]),
        hi2(&t[4], &t[6]),
        lo2(&t[5], &t[7]),
        hi2(&t[5], &t[7]),
    ];
    [
        lo4(&u[0], &u[4]),
        lo4(&u[1], &u[5]),
        lo4(&u[2], &u[6]),
        lo4(&u[3], &u[7]),
        hi4(&u[0], &u[4]),
        hi4(&u[1], &u[5]),
        hi4(&u[2], &u[6]),
        hi4(&u[3], &u[7]),
    ]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_shuffle_transpose_is_a_transpose() {
        let a: Block = std::array::from_fn(|i| std::array::from_fn(|j| (i * 8 + j) as f32));
        let t = transpose8(&a);
        for i in 0..8 {
            for j in 0..8 {
                assert_eq!(t[j][i], a[i][j]);
            }
        }
    }

    #[test]
    fn both_copies_transpose_every_block_of_a_band() {
        // 5 whole blocks and a partial one left as it is, through the dispatch (AVX2 where the
        // CPU has it) and the portable copy.
        let pw = 44;
        let band: Vec<f32> = (0..8 * pw + 3)
            .map(|i| (i * 7 % 1000) as f32 - 0.5)
            .collect();
        let mut want = band.clone();
        for bx in 0..pw / 8 {
            for y in 0..8 {
                for x in 0..8 {
                    want[y * pw + 8 * bx + x] = band[x * pw + 8 * bx + y];
                }
            }
        }
        let mut fast = band.clone();
        transpose_blocks(&mut fast, pw);
        assert_eq!(fast, want);
        let mut portable = band;
        transpose_blocks_portable(&mut portable, pw);
        assert_eq!(portable, want);
    }
}
