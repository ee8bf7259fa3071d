//! 16-bit samples and the 8-bit working view.
//!
//! A 16-bit sample holds a value of `bit_depth` significant bits (16 by default; 10, 12 or 14
//! for sensors that store fewer in a 16-bit container), `max = 2^bit_depth - 1`. Its 8-bit
//! working value is
//!
//! ```text
//! v8 = round(v16 * 255 / max)          (halves up; 255 for values above max)
//! ```
//!
//! After the perturbation turned `v8` into `p8`, the output sample is the input's value plus the
//! change the perturbation made, in 16-bit units, kept inside the 16-bit values whose 8-bit
//! value is `p8`:
//!
//! ```text
//! out16 = v16                                                    if p8 == v8
//! out16 = clamp(v16 + round((p8 - v8) * max / 255), lo(p8), hi(p8))  otherwise
//! ```
//!
//! where `lo(p)..=hi(p)` are the values in `0..=max` that map to `p`. So: a sample the
//! perturbation left alone keeps its 16 bits exactly (its bytes too, in either byte order); a
//! changed sample keeps the input's precision below the 8-bit step (`out16 - v16` is the
//! perturbation's change times `max / 255`, within half a 16-bit unit, moved further only by the
//! clamp, which at 16 bits never acts since `max / 255 = 257` exactly); and the output read back
//! at 8 bits is exactly the perturbation's output. No value is clipped to 8 bits: the range stays
//! `0..=max`.

use super::{EncodedView, par_rows_mut};
use crate::camera::ops::wide_fn;
use std::sync::OnceLock;

/// The largest value of a `bit_depth`-bit sample.
pub const fn max_value(bit_depth: u8) -> u32 {
    (1u32 << bit_depth) - 1
}

/// The 8-bit working value of a 16-bit sample of `bit_depth` bits (rounded, halves up; 255 for
/// values above the depth's maximum).
pub const fn to8(v: u16, bit_depth: u8) -> u8 {
    let max = max_value(bit_depth);
    if bit_depth == 16 {
        // round(v / 257): v + 128.5 is never a multiple of 257, so the floor of (v + 128) / 257
        // is the rounded quotient.
        return ((v as u32 + 128) / 257) as u8;
    }
    let q = (510 * v as u32 + max) / (2 * max);
    if q > 255 { 255 } else { q as u8 }
}

/// The smallest 16-bit value whose 8-bit value is `p` (at `bit_depth` bits).
const fn lo(p: u8, bit_depth: u8) -> u32 {
    if p == 0 {
        return 0;
    }
    // to8(v) >= p  <=>  510 v + max >= 2 max p  <=>  v >= max (2p - 1) / 510.
    let max = max_value(bit_depth);
    (max * (2 * p as u32 - 1)).div_ceil(510)
}

/// The output sample for input `v16` whose working value `v8` the perturbation made `p8` (see
/// the module documentation).
pub const fn transfer(v16: u16, v8: u8, p8: u8, bit_depth: u8) -> u16 {
    if p8 == v8 {
        return v16;
    }
    let max = max_value(bit_depth) as i64;
    let n = (p8 as i64 - v8 as i64) * max;
    // round(n / 255), halves up.
    let d = (2 * n + 255).div_euclid(510);
    let low = lo(p8, bit_depth) as i64;
    let high = if p8 == 255 {
        max
    } else {
        lo(p8 + 1, bit_depth) as i64 - 1
    };
    let out = v16 as i64 + d;
    (if out < low {
        low
    } else if out > high {
        high
    } else {
        out
    }) as u16
}

/// [`to8`] of every 16-bit value, per bit depth below 16 (a division per sample otherwise).
fn table(bit_depth: u8) -> &'static [u8; 65536] {
    static TABLES: [OnceLock<Box<[u8; 65536]>>; 8] = [const { OnceLock::new() }; 8];
    TABLES[(bit_depth - 9) as usize].get_or_init(|| {
        let mut t = Box::new([0u8; 65536]);
        for (v, o) in t.iter_mut().enumerate() {
            *o = to8(v as u16, bit_depth);
        }
        t
    })
}

#[inline(always)]
fn read<const BE: bool>(b: &[u8]) -> u16 {
    if BE {
        u16::from_be_bytes([b[0], b[1]])
    } else {
        u16::from_le_bytes([b[0], b[1]])
    }
}

#[inline(always)]
fn write<const BE: bool>(v: u16, b: &mut [u8]) {
    b.copy_from_slice(&if BE { v.to_be_bytes() } else { v.to_le_bytes() });
}

/// The 8-bit working values of every sample of `input` (16-bit) into `dst`, `row` samples per
/// row, rows tight.
pub(super) fn reduce(input: &EncodedView<'_>, dst: &mut [u8], row: usize) {
    fn rows<const BE: bool>(input: &EncodedView<'_>, dst: &mut [u8], row: usize) {
        let depth = input.bit_depth;
        let t = (depth < 16).then(|| table(depth));
        par_rows_mut(dst, row, row, input.height as usize, |y, d| {
            let src = input.row(y);
            match t {
                None => reduce16::<BE>(src, d),
                Some(t) => {
                    for (o, s) in d.iter_mut().zip(src.chunks_exact(2)) {
                        *o = t[read::<BE>(s) as usize];
                    }
                }
            }
        });
    }
    if input.big_endian {
        rows::<true>(input, dst, row);
    } else {
        rows::<false>(input, dst, row);
    }
}

wide_fn! {
    /// [`to8`] of a row of 16-bit samples at 16 bits.
    fn reduce16<const BE: bool>(src: &[u8], dst: &mut [u8]) {
        for (o, s) in dst.iter_mut().zip(src.chunks_exact(2)) {
            *o = to8(read::<BE>(s), 16);
        }
    }
}

wide_fn! {
    /// [`transfer`] of a row of 16-bit samples at 16 bits: `clamp(v16 + 257 (p8 - v8))`.
    fn back16<const BE: bool>(src: &[u8], v8: &[u8], p8: &[u8], out: &mut [u8]) {
        let samples = out.chunks_exact_mut(2).zip(src.chunks_exact(2)).zip(v8).zip(p8);
        for (((o, s), &v), &p) in samples {
            let x = read::<BE>(s) as i32 + 257 * (p as i32 - v as i32);
            write::<BE>(x.clamp(0, 65535) as u16, o);
        }
    }
}

/// Writes every 16-bit sample of `input` into `out` (rows `input.step` apart) by [`transfer`]:
/// `v8` the working values [`reduce`] gave, `p8` the perturbed ones (both `row` samples per row,
/// tight). At 16 bits `transfer` is `clamp(v16 + 257 (p8 - v8), 0, 65535)` (the bucket clamp
/// never acts there), computed without branches; at fewer bits through tables of the change and
/// of the buckets.
pub(super) fn write_back(
    input: &EncodedView<'_>,
    v8: &[u8],
    p8: &[u8],
    row: usize,
    out: &mut [u8],
) {
    fn rows<const BE: bool>(
        input: &EncodedView<'_>,
        v8: &[u8],
        p8: &[u8],
        row: usize,
        out: &mut [u8],
    ) {
        let depth = input.bit_depth;
        let tables = (depth < 16).then(|| Buckets::new(depth));
        par_rows_mut(
            out,
            input.step,
            input.row_bytes(),
            input.height as usize,
            |y, o| {
                let src = input.row(y);
                let (v, p) = (&v8[y * row..][..row], &p8[y * row..][..row]);
                match &tables {
                    None => back16::<BE>(src, v, p, o),
                    Some(t) => {
                        let samples = o.chunks_exact_mut(2).zip(src.chunks_exact(2)).zip(v).zip(p);
                        for (((o, s), &v), &p) in samples {
                            if v == p {
                                o.copy_from_slice(s);
                            } else {
                                write::<BE>(t.transfer(read::<BE>(s), v, p), o);
                            }
                        }
                    }
                }
            },
        );
    }
    if input.big_endian {
        rows::<true>(input, v8, p8, row, out);
    } else {
        rows::<false>(input, v8, p8, row, out);
    }
}

/// [`transfer`] of a bit depth below 16 by tables: the rounded change per difference of 8-bit
/// values, and each 8-bit value's range of 16-bit values.
struct Buckets {
    change: [i32; 511],
    lo: [i32; 256],
    hi: [i32; 256],
}

impl Buckets {
    fn new(depth: u8) -> Self {
        let max = max_value(depth) as i64;
        let mut b = Buckets {
            change: [0; 511],
            lo: [0; 256],
            hi: [0; 256],
        };
        for (i, c) in b.change.iter_mut().enumerate() {
            *c = ((2 * (i as i64 - 255) * max + 255).div_euclid(510)) as i32;
        }
        for p in 0..256 {
            b.lo[p] = lo(p as u8, depth) as i32;
            b.hi[p] = if p == 255 {
                max as i32
            } else {
                lo(p as u8 + 1, depth) as i32 - 1
            };
        }
        b
    }

    #[inline(always)]
    fn transfer(&self, v16: u16, v8: u8, p8: u8) -> u16 {
        let out = v16 as i32 + self.change[(p8 as i32 - v8 as i32 + 255) as usize];
        out.clamp(self.lo[p8 as usize], self.hi[p8 as usize]) as u16
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_tables_and_the_16_bit_formula_give_transfer() {
        for depth in [10u8, 12, 14] {
            let b = Buckets::new(depth);
            for v in (0..=max_value(depth) as u16).step_by(7) {
                let v8 = to8(v, depth);
                for p8 in 0..=255u8 {
                    if p8 != v8 {
                        assert_eq!(b.transfer(v, v8, p8), transfer(v, v8, p8, depth));
                    }
                }
            }
        }
        for v in (0..=65535u16).step_by(3) {
            let v8 = to8(v, 16);
            for p8 in 0..=255u8 {
                let x = (v as i32 + 257 * (p8 as i32 - v8 as i32)).clamp(0, 65535) as u16;
                assert_eq!(x, transfer(v, v8, p8, 16), "{v} {p8}");
            }
        }
    }
}
