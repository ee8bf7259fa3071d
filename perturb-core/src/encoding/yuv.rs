//! YUV 4:2:2 (UYVY, YUYV) and RGB.
//!
//! To RGB: ITU-R BT.601 with limited ("studio") range, as cv_bridge converts these encodings
//! (OpenCV's `COLOR_YUV2BGR_UYVY` / `_YUY2`), in the same 20-bit fixed point, so the working view
//! is byte for byte OpenCV's:
//!
//! ```text
//! y = max(Y - 16, 0) * 1.164,  u = U - 128,  v = V - 128
//! R = y + 1.596 v,  G = y - 0.391 u - 0.813 v,  B = y + 2.018 u      (rounded, clamped to 0..=255)
//! ```
//!
//! Back from RGB: a pixel pair whose two working pixels the perturbation left alone keeps its
//! four input bytes. Otherwise each sample takes the input's value plus the perturbation's change
//! converted by the inverse of the matrix above (for each pixel `Δ = after - before` in RGB):
//!
//! ```text
//! Y' = Y + round(0.2570 ΔR + 0.5044 ΔG + 0.0977 ΔB)                     per pixel
//! U' = U + round(mean over the pair of (-0.1482 ΔR - 0.2910 ΔG + 0.4392 ΔB))
//! V' = V + round(mean over the pair of ( 0.4392 ΔR - 0.3679 ΔG - 0.0713 ΔB))
//! ```
//!
//! (16-bit fixed point, halves up, clamped to 0..=255). The Y of a pixel the perturbation left
//! alone is its input byte even when its pair partner changed; the pair's shared U and V then
//! move by half the partner's chroma change. Within the RGB cube the output decodes to the
//! perturbed pixel within rounding; where the input's YUV decodes outside the cube (clamped in
//! the working view), the output keeps that excess rather than snapping it to the cube.

use super::{Plane, par_rows_mut};
use crate::camera::ops::wide_fn;
use crate::image::{ImageView, ImageViewMut};

/// The byte order of a YUV 4:2:2 pixel pair.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum YuvOrder {
    /// `U0 Y0 V0 Y1` (ROS `yuv422`, fourcc UYVY).
    Uyvy,
    /// `Y0 U0 Y1 V0` (ROS `yuv422_yuy2`, fourcc YUYV / YUY2).
    Yuyv,
}

impl YuvOrder {
    /// Offsets of `Y0`, `U`, `Y1`, `V` within the four bytes of a pair.
    pub const fn offsets(self) -> [usize; 4] {
        match self {
            YuvOrder::Uyvy => [1, 0, 3, 2],
            YuvOrder::Yuyv => [0, 1, 2, 3],
        }
    }

    /// The OpenCV code cv_bridge converts this order with.
    pub const fn opencv_to_bgr(self) -> &'static str {
        match self {
            YuvOrder::Uyvy => "COLOR_YUV2BGR_UYVY",
            YuvOrder::Yuyv => "COLOR_YUV2BGR_YUY2",
        }
    }
}

/// The byte offsets of each order, for the const-generic row loops.
const UYVY: [usize; 4] = YuvOrder::Uyvy.offsets();
const YUYV: [usize; 4] = YuvOrder::Yuyv.offsets();

/// Fractional bits of the decoding constants.
const SHIFT: u32 = 20;
/// `round(c * 2^20)` of BT.601's limited-range decoding coefficients, with `c` to three
/// decimals as OpenCV has them: 1.164 (luma), 1.596 (V to R), -0.813 (V to G), -0.391 (U to G),
/// 2.018 (U to B).
pub const DECODE: [i32; 5] = [1_220_542, 1_673_527, -852_492, -409_993, 2_116_026];

/// `round(k * 2^16)` of the inverse of the decoding matrix (rows Y, U, V; columns R, G, B).
pub const ENCODE: [[i32; 3]; 3] = [
    [16_840, 33_058, 6_405],
    [-9_713, -19_068, 28_781],
    [28_781, -24_110, -4_671],
];

#[inline(always)]
fn clamp8(v: i32) -> u8 {
    v.clamp(0, 255) as u8
}

/// The chroma terms of a pair, for red, green and blue (with the rounding half).
#[inline(always)]
fn chroma_terms(u: u8, v: u8) -> [i32; 3] {
    let [_, cvr, cvg, cug, cub] = DECODE;
    let half = 1 << (SHIFT - 1);
    let (u, v) = (u as i32 - 128, v as i32 - 128);
    [half + cvr * v, half + cvg * v + cug * u, half + cub * u]
}

/// The luma term of a pixel.
#[inline(always)]
fn luma_term(y: u8) -> i32 {
    (y as i32 - 16).max(0) * DECODE[0]
}

/// One channel from a pixel's luma term and the pair's chroma term.
#[inline(always)]
fn channel(luma: i32, chroma: i32) -> u8 {
    clamp8((luma + chroma) >> SHIFT)
}

/// The RGB of one pair: `[y0, u, y1, v]` bytes to two pixels.
#[inline(always)]
pub fn pair_to_rgb([y0, u, y1, v]: [u8; 4]) -> [[u8; 3]; 2] {
    let c = chroma_terms(u, v);
    [y0, y1].map(|y| {
        let l = luma_term(y);
        c.map(|c| channel(l, c))
    })
}

/// The changes of Y, U and V (2^16 units) for a pixel that went from `before` to `after`.
#[inline(always)]
fn changes(before: [u8; 3], after: [u8; 3]) -> [i32; 3] {
    let d = [0, 1, 2].map(|c| after[c] as i32 - before[c] as i32);
    ENCODE.map(|k| k[0] * d[0] + k[1] * d[1] + k[2] * d[2])
}

/// A luma sample plus its rounded change.
#[inline(always)]
fn plus_luma(y: u8, e: i32) -> u8 {
    clamp8(y as i32 + ((e + (1 << 15)) >> 16))
}

/// A chroma sample plus the rounded mean of its pair's two changes.
#[inline(always)]
fn plus_chroma(c: u8, e0: i32, e1: i32) -> u8 {
    clamp8(c as i32 + ((e0 + e1 + (1 << 16)) >> 17))
}

/// The pair `q` (`[y0, u, y1, v]`) after its pixels changed from `before` to `after`.
#[inline(always)]
pub fn pair_back([y0, u, y1, v]: [u8; 4], before: [[u8; 3]; 2], after: [[u8; 3]; 2]) -> [u8; 4] {
    let [a, b] = [0, 1].map(|i| changes(before[i], after[i]));
    [
        plus_luma(y0, a[0]),
        plus_chroma(u, a[1], b[1]),
        plus_luma(y1, b[0]),
        plus_chroma(v, a[2], b[2]),
    ]
}

/// Pairs per block of the row kernels: the arithmetic of a block runs in vector lanes, the
/// bytes are taken apart and put back around it.
const BLOCK: usize = 16;

wide_fn! {
    /// One row to RGB, the byte offsets of `Y0 U Y1 V` known at compile time: blocks of
    /// [`BLOCK`] pairs into three planes, interleaved after; the rest pair by pair.
    fn row_to_rgb<const Y0: usize, const U: usize, const Y1: usize, const V: usize>(
        src: &[u8],
        out: &mut [u8],
    ) {
        let blocks = src.chunks_exact(4 * BLOCK).zip(out.chunks_exact_mut(6 * BLOCK));
        for (q, o) in blocks {
            let mut px = [[0u8; 2 * BLOCK]; 3];
            for i in 0..BLOCK {
                let chroma = chroma_terms(q[4 * i + U], q[4 * i + V]);
                let (la, lb) = (luma_term(q[4 * i + Y0]), luma_term(q[4 * i + Y1]));
                for (plane, c) in px.iter_mut().zip(chroma) {
                    plane[2 * i] = channel(la, c);
                    plane[2 * i + 1] = channel(lb, c);
                }
            }
            for p in 0..2 * BLOCK {
                o[3 * p] = px[0][p];
                o[3 * p + 1] = px[1][p];
                o[3 * p + 2] = px[2][p];
            }
        }
        let done = src.len() / (4 * BLOCK) * (4 * BLOCK);
        let rest = src[done..].chunks_exact(4).zip(out[done / 4 * 6..].chunks_exact_mut(6));
        for (q, o) in rest {
            let [a, b] = pair_to_rgb([q[Y0], q[U], q[Y1], q[V]]);
            o.copy_from_slice(&[a[0], a[1], a[2], b[0], b[1], b[2]]);
        }
    }
}

/// Converts the YUV 4:2:2 rows of `src` into the rgb8 view `dst`.
pub(super) fn to_rgb(src: &Plane<'_>, order: YuvOrder, dst: &mut ImageViewMut<'_>) {
    let (stride, len) = (dst.stride, dst.width as usize * 3);
    par_rows_mut(
        dst.data_mut(),
        stride,
        len,
        src.height,
        |y, o| match order {
            YuvOrder::Uyvy => {
                row_to_rgb::<{ UYVY[0] }, { UYVY[1] }, { UYVY[2] }, { UYVY[3] }>(src.row(y), o)
            }
            YuvOrder::Yuyv => {
                row_to_rgb::<{ YUYV[0] }, { YUYV[1] }, { YUYV[2] }, { YUYV[3] }>(src.row(y), o)
            }
        },
    );
}

wide_fn! {
    /// One row back to YUV, the byte offsets of `Y0 U Y1 V` known at compile time: per block of
    /// [`BLOCK`] pairs the changes of Y, U and V of every pixel (in 2^16 units), then each
    /// sample is its input value plus its rounded change ([`pair_back`] pair by pair). A pixel
    /// whose working value did not change adds zero: no branch is needed for the bytes the
    /// perturbation left alone.
    fn row_back<const Y0: usize, const U: usize, const Y1: usize, const V: usize>(
        src: &[u8],
        before: &[u8],
        after: &[u8],
        out: &mut [u8],
    ) {
        let pairs = src.chunks_exact(4 * BLOCK).zip(out.chunks_exact_mut(4 * BLOCK));
        let rgb = before.chunks_exact(6 * BLOCK).zip(after.chunks_exact(6 * BLOCK));
        for ((s, o), (b, a)) in pairs.zip(rgb) {
            let mut e = [[0i32; 2 * BLOCK]; 3];
            for p in 0..2 * BLOCK {
                let px = |v: &[u8]| [v[3 * p], v[3 * p + 1], v[3 * p + 2]];
                let c = changes(px(b), px(a));
                for (ek, c) in e.iter_mut().zip(c) {
                    ek[p] = c;
                }
            }
            let [ey, eu, ev] = &e;
            for i in 0..BLOCK {
                o[4 * i + Y0] = plus_luma(s[4 * i + Y0], ey[2 * i]);
                o[4 * i + Y1] = plus_luma(s[4 * i + Y1], ey[2 * i + 1]);
                o[4 * i + U] = plus_chroma(s[4 * i + U], eu[2 * i], eu[2 * i + 1]);
                o[4 * i + V] = plus_chroma(s[4 * i + V], ev[2 * i], ev[2 * i + 1]);
            }
        }
        let done = src.len() / (4 * BLOCK) * (4 * BLOCK);
        let pairs = src[done..].chunks_exact(4).zip(out[done..].chunks_exact_mut(4));
        let at = done / 4 * 6;
        let rgb = before[at..].chunks_exact(6).zip(after[at..].chunks_exact(6));
        for ((s, o), (b, a)) in pairs.zip(rgb) {
            let px = |p: &[u8]| [[p[0], p[1], p[2]], [p[3], p[4], p[5]]];
            let q = pair_back([s[Y0], s[U], s[Y1], s[V]], px(b), px(a));
            (o[Y0], o[U], o[Y1], o[V]) = (q[0], q[1], q[2], q[3]);
        }
    }
}

/// Writes the perturbed rgb8 view `after` back into YUV 4:2:2 rows of `out` (`step` apart),
/// from the input rows `src` and their working view `before`.
pub(super) fn write_back(
    src: &Plane<'_>,
    order: YuvOrder,
    before: &ImageView<'_>,
    after: &ImageView<'_>,
    out: &mut [u8],
    step: usize,
) {
    par_rows_mut(out, step, src.len, src.height, |y, o| {
        let (s, b, a) = (src.row(y), before.row(y), after.row(y));
        match order {
            YuvOrder::Uyvy => {
                row_back::<{ UYVY[0] }, { UYVY[1] }, { UYVY[2] }, { UYVY[3] }>(s, b, a, o)
            }
            YuvOrder::Yuyv => {
                row_back::<{ YUYV[0] }, { YUYV[1] }, { YUYV[2] }, { YUYV[3] }>(s, b, a, o)
            }
        }
    });
}
