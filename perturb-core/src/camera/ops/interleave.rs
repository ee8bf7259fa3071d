//! 32 pixels of three bytes each to three vectors of channel bytes and back, in AVX2 registers:
//! lets a per-pixel kernel run on an RGB or BGR row directly, without splitting the row into
//! planes in memory first and merging them after.
//!
//! Each 16-pixel half of the 96 bytes is three 16-byte pieces, and byte `i` of piece `j` is
//! channel `(i + j) mod 3` (16 is 1 modulo 3): at every position the three pieces hold the three
//! channels, one each. So two byte blends pick a channel's 16 bytes out of the pieces and one
//! byte shuffle puts them in pixel order; storing runs the same steps backwards. Fifteen
//! instructions each way for 32 pixels, loads and stores included. Only bytes move (a test
//! compares both ways with the plain loops).
//!
//! [`plane_blocks`] and [`pixel_blocks`] run a kernel of 32 pixels (three vectors) over planes or
//! over a row.
//!
//! Unsafe code is allowed in this module for unaligned loads and stores whose offsets are
//! checked to stay inside their slices (each says why).
#![allow(unsafe_code)]

#[cfg(target_arch = "x86_64")]
use std::arch::x86_64::*;

/// Per channel `k`: the byte masks choosing, at each position `i` of a 16-byte half, the piece
/// `(k - i) mod 3` that holds channel `k` there (`[k][0]` marks piece 1, `[k][1]` piece 2), and
/// the shuffle putting the chosen bytes in pixel order (pixel `p` is at `(3 p + k) mod 16`).
/// Both halves of each vector repeat the 16 bytes.
#[cfg(target_arch = "x86_64")]
const LOAD: ([[[u8; 32]; 2]; 3], [[u8; 32]; 3]) = {
    let mut pick = [[[0u8; 32]; 2]; 3];
    let mut order = [[0u8; 32]; 3];
    let mut k = 0;
    while k < 3 {
        let mut i = 0;
        while i < 32 {
            let piece = (k + 3 - i % 16 % 3) % 3;
            if piece > 0 {
                pick[k][piece - 1][i] = 0xff;
            }
            order[k][i] = ((3 * (i % 16) + k) % 16) as u8;
            i += 1;
        }
        k += 1;
    }
    (pick, order)
};

/// Per piece `j`: the byte masks choosing, at each position `i`, channel `(i + j) mod 3`
/// (`[j][0]` marks channel 1, `[j][1]` channel 2); per channel `k`: the shuffle putting pixel
/// `p` at position `(3 p + k) mod 16`, the inverse of [`LOAD`]'s order.
#[cfg(target_arch = "x86_64")]
const STORE: ([[[u8; 32]; 2]; 3], [[u8; 32]; 3]) = {
    let mut pick = [[[0u8; 32]; 2]; 3];
    let mut spread = [[0u8; 32]; 3];
    let mut j = 0;
    while j < 3 {
        let mut i = 0;
        while i < 32 {
            let channel = (i % 16 + j) % 3;
            if channel > 0 {
                pick[j][channel - 1][i] = 0xff;
            }
            i += 1;
        }
        j += 1;
    }
    let mut k = 0;
    while k < 3 {
        let mut p = 0;
        while p < 16 {
            let at = (3 * p + k) % 16;
            spread[k][at] = p as u8;
            spread[k][at + 16] = p as u8;
            p += 1;
        }
        k += 1;
    }
    (pick, spread)
};

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
#[inline]
fn table(t: &[u8; 32]) -> __m256i {
    // SAFETY: the table is 32 bytes, the size of the unaligned load.
    unsafe { _mm256_loadu_si256(t.as_ptr().cast()) }
}

/// The 32 pixels of `src` (at least 96 bytes, 3 per pixel) as three vectors: byte `p` of vector
/// `k` is byte `k` of pixel `p`.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
#[inline]
fn load3(src: &[u8]) -> [__m256i; 3] {
    assert!(src.len() >= 96, "32 pixels of 3 bytes");
    // SAFETY: the three 32-byte loads read bytes 0..96 of `src`, checked above.
    let [a, b, c] =
        [0, 32, 64].map(|at| unsafe { _mm256_loadu_si256(src.as_ptr().add(at).cast()) });
    // Piece j: bytes 16 j.. of the first 16 pixels, then of the next 16.
    let pieces = [
        _mm256_blend_epi32::<0xf0>(a, b),
        _mm256_permute2x128_si256::<0x21>(a, c),
        _mm256_blend_epi32::<0xf0>(b, c),
    ];
    let (pick, order) = &LOAD;
    std::array::from_fn(|k| {
        let [one, two] = pick[k].each_ref().map(|t| table(t));
        let first = _mm256_blendv_epi8(pieces[0], pieces[1], one);
        _mm256_shuffle_epi8(_mm256_blendv_epi8(first, pieces[2], two), table(&order[k]))
    })
}

/// Writes three vectors of channel bytes as 32 pixels into `dst` (at least 96 bytes): byte `k`
/// of pixel `p` is byte `p` of vector `k`. The inverse of [`load3`].
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
#[inline]
fn store3(dst: &mut [u8], channels: [__m256i; 3]) {
    assert!(dst.len() >= 96, "32 pixels of 3 bytes");
    let (pick, spread) = &STORE;
    // Each channel's bytes at the positions they take in the pieces.
    let mut at = [_mm256_setzero_si256(); 3];
    for (k, x) in channels.into_iter().enumerate() {
        at[k] = _mm256_shuffle_epi8(x, table(&spread[k]));
    }
    let [x0, x1, x2] = pick.each_ref().map(|[one, two]| {
        let first = _mm256_blendv_epi8(at[0], at[1], table(one));
        _mm256_blendv_epi8(first, at[2], table(two))
    });
    let out = [
        _mm256_permute2x128_si256::<0x20>(x0, x1),
        _mm256_blend_epi32::<0xf0>(x2, x0),
        _mm256_permute2x128_si256::<0x31>(x1, x2),
    ];
    for (at, v) in [0, 32, 64].into_iter().zip(out) {
        // SAFETY: the three 32-byte stores write bytes 0..96 of `dst`, checked above.
        unsafe { _mm256_storeu_si256(dst.as_mut_ptr().add(at).cast(), v) };
    }
}

/// Runs `block` on every whole 32-pixel block of three byte planes, in place (one vector per
/// plane); returns the pixels done.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
#[inline]
pub(crate) fn plane_blocks(
    [a, b, c]: [&mut [u8]; 3],
    mut block: impl FnMut([__m256i; 3]) -> [__m256i; 3],
) -> usize {
    let n = a.len().min(b.len()).min(c.len()) / 32 * 32;
    for i in (0..n).step_by(32) {
        // SAFETY: `i + 32 <= n`, within each plane: the 32-byte loads and stores stay inside.
        let x = [&*a, &*b, &*c].map(|p| unsafe { _mm256_loadu_si256(p.as_ptr().add(i).cast()) });
        for (plane, bytes) in [&mut *a, &mut *b, &mut *c].into_iter().zip(block(x)) {
            // SAFETY: as the loads.
            unsafe { _mm256_storeu_si256(plane.as_mut_ptr().add(i).cast(), bytes) };
        }
    }
    n
}

/// Runs `block` on every whole 32-pixel block of a row of 3-byte pixels, `src` to `dst`, the
/// channels taken apart by [`load3`] and put back by [`store3`]; returns the pixels done.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
#[inline]
pub(crate) fn pixel_blocks(
    src: &[u8],
    dst: &mut [u8],
    mut block: impl FnMut([__m256i; 3]) -> [__m256i; 3],
) -> usize {
    let mut n = 0;
    for (s, d) in src.chunks_exact(96).zip(dst.chunks_exact_mut(96)) {
        store3(d, block(load3(s)));
        n += 32;
    }
    n
}

#[cfg(all(test, target_arch = "x86_64"))]
mod tests {
    use super::*;

    #[test]
    fn load_and_store_move_every_byte_like_the_plain_loops() {
        if !super::super::wide_available() {
            eprintln!("skipped: this CPU has no AVX2");
            return;
        }
        // Bytes that all differ within a block, at several offsets into a longer row.
        let row: Vec<u8> = (0..400u32).map(|i| (i * 167 + 11) as u8).collect();
        for off in [0, 1, 3, 96, 200, 304] {
            let src = &row[off..off + 96];
            // SAFETY: the CPU has AVX2 (checked above).
            let channels = unsafe { load3(src) };
            let mut planes = [[0u8; 32]; 3];
            for (plane, x) in planes.iter_mut().zip(channels) {
                // SAFETY: as above; the store writes the 32-byte array.
                unsafe { _mm256_storeu_si256(plane.as_mut_ptr().cast(), x) };
            }
            for p in 0..32 {
                for k in 0..3 {
                    assert_eq!(planes[k][p], src[3 * p + k], "offset {off} pixel {p}");
                }
            }
            let mut dst = [0x55u8; 100];
            // SAFETY: as above.
            unsafe { store3(&mut dst[2..], channels) };
            assert_eq!(&dst[2..98], src, "offset {off}");
            assert_eq!(
                [dst[0], dst[1], dst[98], dst[99]],
                [0x55; 4],
                "wrote outside"
            );
        }
    }
}
