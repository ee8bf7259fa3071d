//! Hand-written AVX2 kernels where the compiler's own vectorisation falls short: [`super::ByteMap`]'s
//! forms 32 bytes at a time with the patched inputs blended in the same pass, C-F5's luma blend
//! and C-F4's gain blend in 16-bit lanes, C-C4/C-C5's value scale (a gain per pixel in float
//! lanes, the channels in 16-bit lanes), and the per-channel sums of a row by `vpsadbw`.
//!
//! The compiler runs a 16-bit multiply-high in 32-bit lanes when its multiplier is a broadcast
//! made before the loop, cannot merge the patches into the loop of the form, and widens or
//! shuffles more than the work needs. These kernels spell the instructions out. Each gives the
//! bytes of its scalar definition on every input (tests compare each with its scalar code on
//! every byte value or every colour pair that matters, every tail length and the patches).
//!
//! Each function handles the whole blocks of a row and returns how much it wrote; the caller
//! finishes the tail with the scalar code. Without AVX2 (or with
//! [`crate::camera::ops::force_baseline`] on) they write nothing and return 0.
//!
//! Unsafe code is allowed in this module for three things only: calling the AVX2 functions after
//! the CPU was checked to have them, unaligned loads and stores through pointers that stay inside
//! the slices they come from (each says why), and the multiply-high instructions written as
//! `asm!` on registers.
#![allow(unsafe_code)]

#[cfg(target_arch = "x86_64")]
use crate::camera::ops::{pixel_blocks, plane_blocks};
#[cfg(target_arch = "x86_64")]
use std::arch::x86_64::*;

/// What [`patched`] computes per byte before the patches (see `ByteMap`'s forms).
#[derive(Clone, Copy, Debug)]
pub(super) enum Kernel {
    /// `min(255, max(0, floor(v mul / 256) + add - sub) >> 7)`.
    Line { mul: u16, add: u16, sub: u16 },
    /// `v & and`.
    Mask { and: u8 },
    /// `table[v >> 4]`.
    Nibble { table: [u8; 16] },
}

/// `kernel` on every whole 32-byte block of `src`, then `dst[i] = outs[j]` where
/// `src[i] == keys[j]`; returns the bytes written.
pub(super) fn patched<const N: usize>(
    src: &[u8],
    dst: &mut [u8],
    kernel: Kernel,
    keys: [u8; N],
    outs: [u8; N],
) -> usize {
    #[cfg(target_arch = "x86_64")]
    if crate::camera::ops::wide_available() {
        // SAFETY: the CPU has AVX2 (`wide_available` checked it).
        return unsafe { patched_avx2(src, dst, kernel, keys, outs) };
    }
    let _ = (src, dst, kernel, keys, outs);
    0
}

/// The staircase `min(255, floor((v levels + 1) 257 / 2^16) scale)` of every whole 32-byte
/// block of `src`; returns the bytes written.
pub(super) fn steps(src: &[u8], dst: &mut [u8], levels: u16, scale: u16) -> usize {
    #[cfg(target_arch = "x86_64")]
    if crate::camera::ops::wide_available() {
        // SAFETY: the CPU has AVX2 (`wide_available` checked it).
        return unsafe { steps_avx2(src, dst, levels, scale) };
    }
    let _ = (src, dst, levels, scale);
    0
}

/// C-F5's blend ([`super::LumaBlend`]) over byte planes of red, green and blue, in place, 32
/// pixels at a time as two halves of 16-bit lanes; returns the pixels written. The luma is
/// `(hi + (lo >> 8) + 128) >> 8` with `hi` and `lo` the sums of the channels times the high and
/// low bytes of BT.601's 16-bit weights (exactly `luma`'s rounding: a test checks every colour).
pub(super) fn luma_blend_planes(
    keep: super::Split16,
    luma: super::Split16,
    r: &mut [u8],
    g: &mut [u8],
    b: &mut [u8],
) -> usize {
    #[cfg(target_arch = "x86_64")]
    if crate::camera::ops::wide_available() {
        // SAFETY: the CPU has AVX2 (`wide_available` checked it).
        return unsafe { luma_blend_planes_avx2(keep, luma, r, g, b) };
    }
    let _ = (keep, luma, r, g, b);
    0
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn luma_blend_planes_avx2(
    keep: super::Split16,
    luma: super::Split16,
    r: &mut [u8],
    g: &mut [u8],
    b: &mut [u8],
) -> usize {
    plane_blocks([r, g, b], |x| luma_blend_block(keep, luma, x))
}

/// [`luma_blend_planes`] on the whole 32-pixel blocks of a row of 3-byte pixels, `src` to `dst`
/// (red first, or blue first with `bgr`), the channels taken apart and put back in registers;
/// returns the pixels written.
pub(super) fn luma_blend_rgb(
    keep: super::Split16,
    luma: super::Split16,
    bgr: bool,
    src: &[u8],
    dst: &mut [u8],
) -> usize {
    #[cfg(target_arch = "x86_64")]
    if crate::camera::ops::wide_available() {
        // SAFETY: the CPU has AVX2 (`wide_available` checked it).
        return unsafe { luma_blend_rgb_avx2(keep, luma, bgr, src, dst) };
    }
    let _ = (keep, luma, bgr, src, dst);
    0
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn luma_blend_rgb_avx2(
    keep: super::Split16,
    luma: super::Split16,
    bgr: bool,
    src: &[u8],
    dst: &mut [u8],
) -> usize {
    // Blue-first rows swap the first and last channel on the way in and out.
    let swap = |[a, g, b]: [__m256i; 3]| if bgr { [b, g, a] } else { [a, g, b] };
    pixel_blocks(src, dst, |x| swap(luma_blend_block(keep, luma, swap(x))))
}

/// 32 pixels' red, green and blue of [`luma_blend_planes`], a vector each.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
#[inline]
fn luma_blend_block(keep: super::Split16, luma: super::Split16, x: [__m256i; 3]) -> [__m256i; 3] {
    let splat = |v: u16| _mm256_set1_epi16(v as i16);
    let (ka, kb, la, lb) = (
        splat(keep.a),
        splat(keep.b / 2),
        splat(luma.a),
        splat(luma.b / 2),
    );
    let [r_hi, g_hi, b_hi] = [76, 150, 29].map(splat);
    let [r_lo, g_lo, b_lo] = [139, 70, 47].map(splat);
    let c128 = splat(128);
    let zero = _mm256_setzero_si256();
    // `a v + ((b v + 2^15) >> 16)` with `b` even: the fraction by the rounding multiply-high.
    let split = |v: __m256i, a: __m256i, half_b: __m256i| {
        _mm256_add_epi16(_mm256_mullo_epi16(v, a), _mm256_mulhrs_epi16(v, half_b))
    };
    // Sixteen pixels in 16-bit lanes: the three blended channels.
    let blend = |[rv, gv, bv]: [__m256i; 3]| {
        let mul_add3 = |x: __m256i, y: __m256i, z: __m256i| {
            let sum = _mm256_add_epi16(_mm256_mullo_epi16(rv, x), _mm256_mullo_epi16(gv, y));
            _mm256_add_epi16(sum, _mm256_mullo_epi16(bv, z))
        };
        let hi = mul_add3(r_hi, g_hi, b_hi);
        let lo = mul_add3(r_lo, g_lo, b_lo);
        let y = _mm256_add_epi16(_mm256_add_epi16(hi, c128), _mm256_srli_epi16::<8>(lo));
        let y = _mm256_srli_epi16::<8>(y);
        let ly = _mm256_add_epi16(split(y, la, lb), c128);
        let mut out = [rv, gv, bv];
        for v in &mut out {
            *v = _mm256_srli_epi16::<8>(_mm256_add_epi16(split(*v, ka, kb), ly));
        }
        out
    };
    let lo = blend([x[0], x[1], x[2]].map(|v| _mm256_unpacklo_epi8(v, zero)));
    let hi = blend([x[0], x[1], x[2]].map(|v| _mm256_unpackhi_epi8(v, zero)));
    // At most 255 per lane: the pack keeps it and undoes the unpacks' order.
    [0, 1, 2].map(|c| _mm256_packus_epi16(lo[c], hi[c]))
}

/// C-C4/C-C5's HSV value scale ([`super::scale_value`]) over byte planes of red, green and blue,
/// in place, 32 pixels at a time; returns the pixels written (none for a factor `f` that is not
/// finite). Per pixel, in float lanes, the new value `V' = min(255, floor(V f))` with the scalar
/// code's operations and the gain `K = floor(V' 2^17 / V) + 1` (one division, as `value_gain`);
/// then each channel in 16-bit lanes is `(c K + 2^16) >> 17`: with `K = 2^16 hi + lo`, the
/// rounded half of `c hi + ((c lo) >> 16)` (the low half of `c lo` is below `2^16`, the `+ 2^16`
/// a `+ 1` before the halving): one multiply, one multiply-high and one average. That is
/// `round(c V' / V)` with halves up for every channel `c <= V` (a test checks every `V`, `V'` and
/// `c`), the scalar code's bytes. A black pixel's lanes divide 0 by 0: whatever gain that gives
/// multiplies channels that are all 0 (with a finite factor its new value is 0 too).
pub(super) fn value_scale_planes(f: f32, r: &mut [u8], g: &mut [u8], b: &mut [u8]) -> usize {
    #[cfg(target_arch = "x86_64")]
    if crate::camera::ops::wide_available() && f.is_finite() {
        // SAFETY: the CPU has AVX2 (`wide_available` checked it).
        return unsafe { value_scale_planes_avx2(f, r, g, b) };
    }
    let _ = (f, r, g, b);
    0
}

/// The gain of [`value_scale_planes`] for a value `v >= 1` and new value `nv`, computed as its
/// float lanes do: the f32 quotient of `nv 2^17` (exact) by `v`, truncated, plus one.
#[cfg(test)]
pub(super) fn value_gain(v: u8, nv: u8) -> u32 {
    (((nv as u32) << 17) as f32 / v as f32) as u32 + 1
}

/// [`value_scale_planes`] on the whole 32-pixel blocks of a row of 3-byte pixels, `src` to
/// `dst`, the channels taken apart and put back in registers (the scale treats the three
/// channels alike, so their order does not matter); returns the pixels written.
pub(super) fn value_scale_rgb(f: f32, src: &[u8], dst: &mut [u8]) -> usize {
    #[cfg(target_arch = "x86_64")]
    if crate::camera::ops::wide_available() && f.is_finite() {
        // SAFETY: the CPU has AVX2 (`wide_available` checked it).
        return unsafe { value_scale_rgb_avx2(f, src, dst) };
    }
    let _ = (f, src, dst);
    0
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn value_scale_rgb_avx2(f: f32, src: &[u8], dst: &mut [u8]) -> usize {
    pixel_blocks(src, dst, |x| value_scale_block(f, x))
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn value_scale_planes_avx2(f: f32, r: &mut [u8], g: &mut [u8], b: &mut [u8]) -> usize {
    plane_blocks([r, g, b], |x| value_scale_block(f, x))
}

/// 32 pixels' channels of [`value_scale_planes`], a vector each.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
#[inline]
fn value_scale_block(f: f32, x: [__m256i; 3]) -> [__m256i; 3] {
    let zero = _mm256_setzero_si256();
    let (f, top, scale) = (
        _mm256_set1_ps(f),
        _mm256_set1_ps(255.0),
        _mm256_set1_ps(131_072.0),
    );
    let (low, one) = (_mm256_set1_epi32(0xffff), _mm256_set1_epi32(1));
    // Eight pixels' gains from their values in 32-bit lanes.
    let gains = |v: __m256i| {
        let v = _mm256_cvtepi32_ps(v);
        let nv = _mm256_floor_ps(_mm256_min_ps(_mm256_mul_ps(v, f), top));
        let k = _mm256_div_ps(_mm256_mul_ps(nv, scale), v);
        _mm256_add_epi32(_mm256_cvttps_epi32(k), one)
    };
    // Sixteen pixels' gains from their values in 16-bit lanes, as the low and high halves in
    // the same 16-bit lanes (the unpacks and packs keep each 128-bit half's order).
    let halves = |v: __m256i| {
        let k = [
            _mm256_unpacklo_epi16(v, zero),
            _mm256_unpackhi_epi16(v, zero),
        ]
        .map(gains);
        let lo = _mm256_packus_epi32(_mm256_and_si256(k[0], low), _mm256_and_si256(k[1], low));
        let hi = _mm256_packus_epi32(_mm256_srli_epi32::<16>(k[0]), _mm256_srli_epi32::<16>(k[1]));
        (lo, hi)
    };
    let scale = |c: __m256i, (lo, hi): (__m256i, __m256i)| {
        _mm256_avg_epu16(_mm256_mullo_epi16(c, hi), mulhi_epu16(c, lo))
    };
    let v = _mm256_max_epu8(_mm256_max_epu8(x[0], x[1]), x[2]);
    let k_lo = halves(_mm256_unpacklo_epi8(v, zero));
    let k_hi = halves(_mm256_unpackhi_epi8(v, zero));
    let mut out = x;
    for c in &mut out {
        let lo = scale(_mm256_unpacklo_epi8(*c, zero), k_lo);
        let hi = scale(_mm256_unpackhi_epi8(*c, zero), k_hi);
        // At most 255 per lane (the rounded `c V' / V <= V'`): the pack keeps it and undoes
        // the unpacks' order.
        *c = _mm256_packus_epi16(lo, hi);
    }
    out
}

/// Sums of the bytes of `src` at each position modulo `C` (3 or 4: the pixels' channels) over
/// its whole blocks of `32 C` bytes, and the bytes summed; the caller sums the rest. Each 32-byte
/// vector is summed whole and with all but one channel masked off by `vpsadbw`, eight bytes into
/// a 64-bit lane (no overflow on any row); the last channel is the whole minus the others.
pub(super) fn channel_byte_sums<const C: usize>(src: &[u8]) -> ([u64; 4], usize) {
    #[cfg(target_arch = "x86_64")]
    if crate::camera::ops::wide_available() {
        // SAFETY: the CPU has AVX2 (`wide_available` checked it).
        return unsafe { channel_byte_sums_avx2::<C>(src) };
    }
    let _ = src;
    ([0; 4], 0)
}

/// `masks[j][k]`: 0xff where byte `i` of block `j` (byte `32 j + i` of a run of pixels of `C`
/// bytes) is channel `k`, 0 elsewhere.
#[cfg(target_arch = "x86_64")]
const fn channel_masks<const C: usize>() -> [[[u8; 32]; 3]; C] {
    let mut masks = [[[0u8; 32]; 3]; C];
    let mut i = 0;
    while i < 32 * C {
        if i % C < 3 {
            masks[i / 32][i % C][i % 32] = 0xff;
        }
        i += 1;
    }
    masks
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn channel_byte_sums_avx2<const C: usize>(src: &[u8]) -> ([u64; 4], usize) {
    // Masks for channels 0 and 1 (and 2 with alpha) per block, the last colour channel from
    // the whole sum.
    let masks: [[__m256i; 3]; C] = const { channel_masks::<C>() }.map(|block| {
        // SAFETY: each mask is 32 bytes, the size of the unaligned load.
        block.map(|m| unsafe { _mm256_loadu_si256(m.as_ptr().cast()) })
    });
    let zero = _mm256_setzero_si256();
    let mut whole = zero;
    let mut parts = [zero; 3];
    let mut n = 0;
    for block in src.chunks_exact(32 * C) {
        for (j, chunk) in block.chunks_exact(32).enumerate() {
            // SAFETY: `chunk` is 32 bytes, the size of the unaligned load.
            let x = unsafe { _mm256_loadu_si256(chunk.as_ptr().cast()) };
            whole = _mm256_add_epi64(whole, _mm256_sad_epu8(x, zero));
            for (k, part) in parts.iter_mut().enumerate().take(C - 1) {
                let masked = _mm256_and_si256(x, masks[j][k]);
                *part = _mm256_add_epi64(*part, _mm256_sad_epu8(masked, zero));
            }
        }
        n += 32 * C;
    }
    let total = |v: __m256i| {
        let mut lanes = [0u64; 4];
        // SAFETY: `lanes` is 32 bytes, the size of the unaligned store.
        unsafe { _mm256_storeu_si256(lanes.as_mut_ptr().cast(), v) };
        lanes.iter().sum::<u64>()
    };
    let mut sums = [0u64; 4];
    for k in 0..C - 1 {
        sums[k] = total(parts[k]);
    }
    sums[C - 1] = total(whole) - sums[..C - 1].iter().sum::<u64>();
    (sums, n)
}

/// The constants of [`gain_blend`]'s 16-bit lanes: for each of the (at most four) 32-byte
/// vectors of a block and each of its two unpacked halves, five vectors of 16 lanes: the gain's
/// integer multiplier, its fraction multiplier, the carry threshold (see [`gain_lanes`]), the
/// blend's weight and offset.
pub(super) type GainLanes = [[[u16; 16]; 5]; 8];

/// [`GainLanes`] for pixels of `c` bytes from the constants of each byte of a pixel:
/// `at(i) = [gain >> 16, gain & 0xffff, gain offset, blend weight, blend offset]` for byte `i`.
/// The gain offset becomes the threshold `(0xffff - offset) ^ 0x8000` that the low product,
/// its top bit flipped, exceeds (signed) exactly when adding the offset carries.
pub(super) fn gain_lanes(c: usize, at: impl Fn(usize) -> [u16; 5]) -> GainLanes {
    std::array::from_fn(|half| {
        let (vector, high) = (half / 2, half % 2 == 1);
        // Lane `l` of an unpacked half holds byte `l` (low) or `l + 8` (high) of its 128-bit
        // lane: bytes 0-7 and 16-23 in the low half, 8-15 and 24-31 in the high one.
        let byte = |l: usize| 32 * vector + (l / 8) * 16 + l % 8 + if high { 8 } else { 0 };
        let mut lanes = [[0u16; 16]; 5];
        for l in 0..16 {
            let [a, f, offset, w, k] = at(byte(l) % c);
            let threshold = (0xffff - offset) ^ 0x8000;
            for (lane, x) in lanes.iter_mut().zip([a, f, threshold, w, k]) {
                lane[l] = x;
            }
        }
        lanes
    })
}

/// [`super::GainBlend`]'s 16-bit lanes over the whole `32 C`-byte blocks (`C` bytes per pixel)
/// of `src`, 32 bytes at a time as two halves of 16 lanes; returns the bytes written. Each lane
/// computes [`super::narrow_byte`] with its byte's constants in `lanes`.
pub(super) fn gain_blend<const C: usize>(lanes: &GainLanes, src: &[u8], dst: &mut [u8]) -> usize {
    #[cfg(target_arch = "x86_64")]
    if crate::camera::ops::wide_available() {
        // SAFETY: the CPU has AVX2 (`wide_available` checked it).
        return unsafe { gain_blend_avx2::<C>(lanes, src, dst) };
    }
    let _ = (lanes, src, dst);
    0
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn gain_blend_avx2<const C: usize>(lanes: &GainLanes, src: &[u8], dst: &mut [u8]) -> usize {
    // SAFETY: each lane array is 32 bytes, the size of the unaligned load.
    let load = |x: &[u16; 16]| unsafe { _mm256_loadu_si256(x.as_ptr().cast()) };
    let consts: [[__m256i; 5]; 8] = std::array::from_fn(|h| lanes[h].each_ref().map(load));
    let zero = _mm256_setzero_si256();
    let top = _mm256_set1_epi16(255);
    let sign = _mm256_set1_epi16(i16::MIN);
    let half = |v: __m256i, [a, f, threshold, w, k]: [__m256i; 5]| {
        let low = _mm256_mullo_epi16(v, f);
        let whole = _mm256_add_epi16(_mm256_mullo_epi16(v, a), mulhi_epu16(v, f));
        // -1 where the low product plus the gain offset carries.
        let carry = _mm256_cmpgt_epi16(_mm256_xor_si256(low, sign), threshold);
        let balanced = _mm256_min_epu16(_mm256_sub_epi16(whole, carry), top);
        let d = _mm256_slli_epi16::<6>(_mm256_sub_epi16(balanced, v));
        let step = _mm256_srai_epi16::<5>(_mm256_add_epi16(mulhi_epi16(d, w), k));
        _mm256_add_epi16(v, step)
    };
    let mut n = 0;
    for (s, d) in src.chunks_exact(32 * C).zip(dst.chunks_exact_mut(32 * C)) {
        for j in 0..C {
            // SAFETY: `s` and `d` hold `32 C` bytes: the 32-byte load and store at `32 j` stay
            // inside.
            let x = unsafe { _mm256_loadu_si256(s.as_ptr().add(32 * j).cast()) };
            let lo = half(_mm256_unpacklo_epi8(x, zero), consts[2 * j]);
            let hi = half(_mm256_unpackhi_epi8(x, zero), consts[2 * j + 1]);
            // Every lane is a byte value: the pack keeps it and undoes the unpacks' order.
            let out = _mm256_packus_epi16(lo, hi);
            // SAFETY: as the load.
            unsafe { _mm256_storeu_si256(d.as_mut_ptr().add(32 * j).cast(), out) };
        }
        n += 32 * C;
    }
    n
}

/// Calls `f(x)` on each whole 32-byte block of `src` and stores its result in the same place of
/// `dst`; returns the bytes written.
#[cfg(target_arch = "x86_64")]
#[inline(always)]
fn blocks(src: &[u8], dst: &mut [u8], mut f: impl FnMut(__m256i) -> __m256i) -> usize {
    let mut n = 0;
    for (s, d) in src.chunks_exact(32).zip(dst.chunks_exact_mut(32)) {
        // SAFETY: `s` and `d` are 32 bytes long, the size of the unaligned load and store.
        unsafe {
            let x = _mm256_loadu_si256(s.as_ptr().cast());
            _mm256_storeu_si256(d.as_mut_ptr().cast(), f(x));
        }
        n += 32;
    }
    n
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn patched_avx2<const N: usize>(
    src: &[u8],
    dst: &mut [u8],
    kernel: Kernel,
    keys: [u8; N],
    outs: [u8; N],
) -> usize {
    let keys = keys.map(|k| _mm256_set1_epi8(k as i8));
    let outs = outs.map(|o| _mm256_set1_epi8(o as i8));
    let patch = |x: __m256i, mut y: __m256i| {
        for j in 0..N {
            y = _mm256_blendv_epi8(y, outs[j], _mm256_cmpeq_epi8(x, keys[j]));
        }
        y
    };
    match kernel {
        // A zero offset is left out of the arithmetic (contrast's lines never add).
        Kernel::Line { mul, add: 0, sub } => line_blocks::<false>(src, dst, mul, 0, sub, patch),
        Kernel::Line { mul, add, sub } => line_blocks::<true>(src, dst, mul, add, sub, patch),
        Kernel::Mask { and } => {
            let and = _mm256_set1_epi8(and as i8);
            blocks(src, dst, |x| patch(x, _mm256_and_si256(x, and)))
        }
        Kernel::Nibble { table } => {
            // The 16-entry table in both 128-bit halves (the shuffle looks up within each).
            // SAFETY: `table` is 16 bytes, the size of the unaligned load.
            let table = unsafe { _mm_loadu_si128(table.as_ptr().cast()) };
            let table = _mm256_broadcastsi128_si256(table);
            let low4 = _mm256_set1_epi8(0x0f);
            blocks(src, dst, |x| {
                // v >> 4 per byte: a 16-bit shift, then the bits from the next byte masked off.
                let high = _mm256_and_si256(_mm256_srli_epi16::<4>(x), low4);
                patch(x, _mm256_shuffle_epi8(table, high))
            })
        }
    }
}

/// [`Kernel::Line`] over the whole 32-byte blocks, then `patch(input, output)`; `ADD` false when
/// `add` is 0.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
#[inline]
fn line_blocks<const ADD: bool>(
    src: &[u8],
    dst: &mut [u8],
    mul: u16,
    add: u16,
    sub: u16,
    patch: impl Fn(__m256i, __m256i) -> __m256i,
) -> usize {
    let zero = _mm256_setzero_si256();
    let mul = _mm256_set1_epi16(mul as i16);
    let add = _mm256_set1_epi16(add as i16);
    let sub = _mm256_set1_epi16(sub as i16);
    // Half of the bytes as `v << 8` in 16-bit lanes: the multiply-high is floor(v mul / 256).
    let half = |v8: __m256i| {
        let mut scaled = mulhi_epu16(v8, mul);
        if ADD {
            scaled = _mm256_adds_epu16(scaled, add);
        }
        _mm256_srli_epi16::<7>(_mm256_subs_epu16(scaled, sub))
    };
    blocks(src, dst, |x| {
        let lo = half(_mm256_unpacklo_epi8(zero, x));
        let hi = half(_mm256_unpackhi_epi8(zero, x));
        // At most 511 per lane: the pack saturates to 255 and undoes the unpacks' order.
        patch(x, _mm256_packus_epi16(lo, hi))
    })
}

/// A function running one two-operand AVX2 instruction on registers, through `asm!`.
macro_rules! one_instruction {
    ($(#[$doc:meta])* fn $name:ident = $instruction:literal) => {
        $(#[$doc])*
        #[cfg(target_arch = "x86_64")]
        #[target_feature(enable = "avx2")]
        #[inline]
        fn $name(a: __m256i, b: __m256i) -> __m256i {
            let out;
            // SAFETY: one AVX2 instruction on registers (the features are this function's), no
            // memory.
            unsafe {
                std::arch::asm!(
                    concat!($instruction, " {o}, {a}, {b}"),
                    o = lateout(ymm_reg) out,
                    a = in(ymm_reg) a,
                    b = in(ymm_reg) b,
                    options(pure, nomem, nostack, preserves_flags),
                );
            }
            out
        }
    };
}

one_instruction! {
    /// `_mm256_mulhi_epu16` as the one instruction it names. The intrinsic is written as 32-bit
    /// products that the compiler matches back to `vpmulhuw` only when it sees both operands
    /// widened from 16 bits; with a multiplier broadcast before the loop it does not, and runs the
    /// multiply in 32-bit lanes (twice the instructions).
    fn mulhi_epu16 = "vpmulhuw"
}

one_instruction! {
    /// `_mm256_mulhi_epi16` (signed) as the one instruction it names, for the reason of
    /// [`mulhi_epu16`].
    fn mulhi_epi16 = "vpmulhw"
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn steps_avx2(src: &[u8], dst: &mut [u8], levels: u16, scale: u16) -> usize {
    let zero = _mm256_setzero_si256();
    let levels = _mm256_set1_epi16(levels as i16);
    let scale = _mm256_set1_epi16(scale as i16);
    let one = _mm256_set1_epi16(1);
    let k257 = _mm256_set1_epi16(257);
    let max = _mm256_set1_epi16(255);
    let half = |v: __m256i| {
        let t = _mm256_add_epi16(_mm256_mullo_epi16(v, levels), one);
        let q = _mm256_mulhi_epu16(t, k257);
        _mm256_min_epu16(_mm256_mullo_epi16(q, scale), max)
    };
    blocks(src, dst, |x| {
        let lo = half(_mm256_unpacklo_epi8(x, zero));
        let hi = half(_mm256_unpackhi_epi8(x, zero));
        _mm256_packus_epi16(lo, hi)
    })
}
