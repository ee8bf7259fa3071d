//! OpenCV's 8-bit HSV conversion and the value and saturation maps built on it.

use super::channels::{copy_alpha, merge_rgb, split_rgb_bytes, three_planes};
use super::rows::{par_rows, par_rows_with};
use super::simd::wide_fn;
use crate::image::{ImageView, ImageViewMut, PixelFormat};

/// OpenCV's 8-bit RGB to HSV (`COLOR_RGB2HSV`): H in 0..180, S and V in 0..255, with OpenCV's
/// fixed-point rounding, so a round trip reproduces the references' quantisation.
#[inline]
pub fn rgb_to_hsv(r: u8, g: u8, b: u8) -> (u8, u8, u8) {
    const SHIFT: i32 = 12;
    let (r, g, b) = (r as i32, g as i32, b as i32);
    let v = r.max(g).max(b);
    let vmin = r.min(g).min(b);
    let diff = v - vmin;
    let s = if v == 0 {
        0
    } else {
        let sdiv = ((255 << SHIFT) as f64 / v as f64).round() as i32;
        (diff * sdiv + (1 << (SHIFT - 1))) >> SHIFT
    };
    let mut h = if diff == 0 {
        0
    } else {
        let num = if v == r {
            g - b
        } else if v == g {
            b - r + 2 * diff
        } else {
            r - g + 4 * diff
        };
        let hdiv = ((180 << SHIFT) as f64 / (6.0 * diff as f64)).round() as i32;
        (num * hdiv + (1 << (SHIFT - 1))) >> SHIFT
    };
    if h < 0 {
        h += 180;
    }
    (h as u8, s as u8, v as u8)
}

/// OpenCV's 8-bit HSV to RGB (`COLOR_HSV2RGB`, H in 0..180): computed in float and rounded.
#[inline]
pub fn hsv_to_rgb(h: u8, s: u8, v: u8) -> (u8, u8, u8) {
    let (hf, sf, vf) = (h as f32 * (6.0 / 180.0), s as f32 / 255.0, v as f32 / 255.0);
    let (r, g, b) = if sf == 0.0 {
        (vf, vf, vf)
    } else {
        let mut hh = hf;
        let mut sector = hh.floor() as i32;
        hh -= sector as f32;
        if sector < 0 {
            sector += 6;
        }
        let sector = (sector % 6) as usize;
        let tab = [
            vf,
            vf * (1.0 - sf),
            vf * (1.0 - sf * hh),
            vf * (1.0 - sf * (1.0 - hh)),
        ];
        const SECTOR: [[usize; 3]; 6] = [
            [1, 3, 0],
            [1, 0, 2],
            [3, 0, 1],
            [0, 2, 1],
            [0, 1, 3],
            [2, 1, 0],
        ];
        let [bi, gi, ri] = SECTOR[sector];
        (tab[ri], tab[gi], tab[bi])
    };
    let q = |x: f32| (x * 255.0).round().clamp(0.0, 255.0) as u8;
    (q(r), q(g), q(b))
}

/// Applies `f(h, s, v) -> (h, s, v)` to every pixel through OpenCV-exact HSV conversions; alpha is
/// copied. For mono8 the single channel is treated as V with zero saturation.
pub fn map_hsv<F>(input: &ImageView<'_>, output: &mut ImageViewMut<'_>, f: F)
where
    F: Fn(u8, u8, u8) -> (u8, u8, u8) + Send + Sync,
{
    let format = input.format;
    let c = format.channels();
    let [ri, gi, bi] = format.rgb_offsets();
    par_rows(input, output, |_, src, dst| {
        for (p, q) in src.chunks_exact(c).zip(dst.chunks_exact_mut(c)) {
            if format.is_mono() {
                q[0] = f(0, 0, p[0]).2;
                continue;
            }
            let (h, s, v) = rgb_to_hsv(p[ri], p[gi], p[bi]);
            let (h, s, v) = f(h, s, v);
            let (r, g, b) = hsv_to_rgb(h, s, v);
            q[ri] = r;
            q[gi] = g;
            q[bi] = b;
            if let Some(a) = format.alpha_offset() {
                q[a] = p[a];
            }
        }
    });
}

/// `2^32 / v` for v in 1..=255 (0 for v = 0), rounded: replaces a division by an 8-bit value with
/// a multiplication.
pub fn reciprocals() -> &'static [u64; 256] {
    static R: std::sync::OnceLock<[u64; 256]> = std::sync::OnceLock::new();
    R.get_or_init(|| std::array::from_fn(|v| rounded_reciprocal(v as u64)))
}

/// `round(2^32 / v)` for `v >= 1` (halves up), 0 for `v = 0`: one entry of [`reciprocals`].
pub(super) const fn rounded_reciprocal(v: u64) -> u64 {
    match ((1u64 << 32) + v / 2).checked_div(v) {
        Some(r) => r,
        None => 0,
    }
}

/// Changes the HSV value of every pixel and keeps hue and saturation, in RGB directly: each colour
/// channel is scaled by `V' / V` (`V` = max of the channels). `vmap(y, x, v)` gives the new value.
/// This is what converting to HSV, changing V and converting back computes, without OpenCV's 8-bit
/// quantisation of hue (2 degree steps) and saturation on the way; results agree within ±1-2 levels.
/// Each channel is `round(p V' / V)` exactly (halves up), in 32-bit fixed point.
/// Alpha is copied; mono8 maps its single channel.
pub fn map_value<F>(input: &ImageView<'_>, output: &mut ImageViewMut<'_>, vmap: F)
where
    F: Fn(usize, usize, u8) -> u8 + Send + Sync,
{
    let format = input.format;
    let c = format.channels();
    let recip = reciprocals();
    par_rows(input, output, |y, src, dst| {
        if format.is_mono() {
            for (x, (s, d)) in src.iter().zip(dst.iter_mut()).enumerate() {
                *d = vmap(y, x, *s);
            }
            return;
        }
        match c {
            3 => value_row::<3, F>(src, dst, y, &vmap, recip),
            _ => value_row::<4, F>(src, dst, y, &vmap, recip),
        }
        copy_alpha(format, src, dst);
    });
}

/// One row of [`map_value`]. Per pixel the factor `k = nv / v` in 8.24 fixed point (and `z =
/// 0`), or `k = nv`, `z = 1` where v = 0 (black: every channel becomes nv); colour channel `p`
/// becomes `round((p + z) k / 2^24)`. A channel is at most v, so the product stays below 2^32;
/// the factor's error (under 2^-15 of a level) and the small bias cannot cross a rounding
/// boundary, which sits at least 1 / 510 of a level from any p nv / v: exact halves round up.
/// Every colour format keeps its three colour bytes first (alpha, if any, is byte 3), and the
/// formula is the same for each of them, so the channel order does not matter here.
fn value_row<const C: usize, F>(src: &[u8], dst: &mut [u8], y: usize, vmap: &F, recip: &[u64; 256])
where
    F: Fn(usize, usize, u8) -> u8,
{
    for (x, (p, q)) in src.chunks_exact(C).zip(dst.chunks_exact_mut(C)).enumerate() {
        let v = p[0].max(p[1]).max(p[2]);
        let nv = vmap(y, x, v) as u64;
        let (k, z) = if v == 0 {
            ((nv << 24) as u32, 1)
        } else {
            (((nv * recip[v as usize] + 255) >> 8) as u32, 0)
        };
        for ch in 0..3 {
            q[ch] = (((p[ch] as u32 + z) * k + (1 << 23) + (1 << 12)) >> 24) as u8;
        }
    }
}

/// Changes the HSV saturation of every pixel and keeps hue and value, in RGB directly: with
/// `S = round(255 (V - min) / V)` (OpenCV's 8-bit saturation) and `S' = smap(S)`, every channel's
/// distance below `V` is scaled by `S' / S`. Gray pixels stay gray. Mono8 is copied (it has no
/// saturation); callers refuse it where that makes the perturbation a no-op.
pub fn map_saturation(input: &ImageView<'_>, output: &mut ImageViewMut<'_>, smap: &[u8; 256]) {
    SaturationMap::new(smap).apply(input, output);
}

/// The saturation mapping of [`map_saturation`] prepared for use row by row.
pub struct SaturationMap {
    /// Per saturation S: the factor S' / S in 32.32 fixed point.
    gain: [i64; 256],
    /// `m` when the map is `S' = min(255, floor(S m))` (`m` finite, not negative): then the rows
    /// are computed in f64 over byte planes ([`saturation_planes`], the same bytes).
    factor: Option<f32>,
}

impl SaturationMap {
    /// Prepares the mapping `S -> smap[S]` of the HSV saturation.
    pub fn new(smap: &[u8; 256]) -> Self {
        let recip = reciprocals();
        let mut gain = [0i64; 256];
        for (s, g) in gain.iter_mut().enumerate().skip(1) {
            *g = smap[s] as i64 * recip[s] as i64;
        }
        SaturationMap { gain, factor: None }
    }

    /// The mapping `S' = min(255, floor(S m))` (the saturation scaled by `m`, truncated as an 8-bit
    /// write).
    pub fn scaled(m: f32) -> Self {
        let smap = std::array::from_fn(|s| (s as f32 * m).min(255.0) as u8);
        SaturationMap {
            factor: (m.is_finite() && m >= 0.0).then_some(m),
            ..Self::new(&smap)
        }
    }

    /// Maps every pixel of `input` into `output` (mono8 is copied, alpha is copied).
    pub fn apply(&self, input: &ImageView<'_>, output: &mut ImageViewMut<'_>) {
        let format = input.format;
        par_rows_with(input, output, Vec::new, |planes, _, src, dst| {
            self.row_in(format, src, dst, planes)
        });
    }

    /// [`Self::row`] with a scratch buffer for the byte planes of a scaling map (the faster path;
    /// `planes` grows to three bytes per pixel and can be reused from row to row).
    pub fn row_in(&self, format: PixelFormat, src: &[u8], dst: &mut [u8], planes: &mut Vec<u8>) {
        match self.factor {
            Some(m) if !format.is_mono() => {
                planes.resize(3 * (src.len() / format.channels()), 0);
                saturation_planar(m, format, src, planes, dst);
            }
            _ => self.row(format, src, dst),
        }
    }

    /// Maps one row of `format` pixels from `src` into `dst` (mono8 is copied, alpha is copied).
    pub fn row(&self, format: PixelFormat, src: &[u8], dst: &mut [u8]) {
        let rgb = format.rgb_offsets();
        match format.channels() {
            _ if format.is_mono() => dst.copy_from_slice(src),
            3 => saturation_row::<3>(src, dst, rgb, reciprocals(), &self.gain),
            4 => {
                saturation_row::<4>(src, dst, rgb, reciprocals(), &self.gain);
                copy_alpha(format, src, dst);
            }
            _ => unreachable!("colour formats have 3 or 4 channels"),
        }
    }
}

/// 2^32 as f64.
const TWO_32: f64 = 4_294_967_296.0;

/// [`reciprocals`]`[v]`, `round(2^32 / v)`, for a whole `v` in 1..=255, in f64: the quotient of
/// `2^32 + floor(v / 2)` by `v` is at least `1 / v` from a whole number unless it is one, far more
/// than its rounding error (under 2^-20), so its floor is the integer quotient.
#[inline(always)]
fn reciprocal(v: f64) -> f64 {
    ((TWO_32 + (v * 0.5).floor()) / v).floor()
}

/// `(x + 2^31) >> 32` for a whole `x` below 2^52, in f64 (every step exact).
#[inline(always)]
fn shift_round(x: f64) -> f64 {
    ((x + 2_147_483_648.0) * (1.0 / TWO_32)).floor()
}

/// A whole float in `[0, 255]` as a byte: adding 2^52 leaves the value in the low bits.
#[inline(always)]
fn whole_byte(x: f64) -> u8 {
    (x + 4_503_599_627_370_496.0).to_bits() as u8
}

wide_fn! {
    /// [`SaturationMap::row_in`]: RGB and BGR rows' whole 32-pixel blocks straight from row to
    /// row by the AVX2 kernel ([`super::hsv_avx2`], which treats the channels alike), the rest of
    /// the row split into the three byte planes of `planes`, scaled by the kernel's planes form
    /// and [`saturation_planes`], merged back; alpha copied. (The split and the merge are stride-3
    /// loops, which vectorise far better in the AVX2 copy.)
    fn saturation_planar(m: f32, format: PixelFormat, src: &[u8], planes: &mut [u8], dst: &mut [u8]) {
        let direct = match format {
            PixelFormat::Rgb8 | PixelFormat::Bgr8 => super::hsv_avx2::saturation_rgb(m, src, dst),
            _ => 0,
        };
        let (rest_src, rest_dst) = (&src[3 * direct..], &mut dst[3 * direct..]);
        let w = planes.len() / 3 - direct;
        let [r, g, b] = three_planes(planes, w);
        split_rgb_bytes(rest_src, format, [&mut *r, &mut *g, &mut *b]);
        let done = super::hsv_avx2::saturation_planes(m, r, g, b);
        saturation_planes(m, &mut r[done..], &mut g[done..], &mut b[done..]);
        merge_rgb(format, [&*r, &*g, &*b], rest_dst);
        copy_alpha(format, src, dst);
    }
}

wide_fn! {
    /// [`SaturationMap`] with the factor `m` over three byte planes of a row, in place: the
    /// fixed-point arithmetic of [`saturation_row`] carried out in f64, where every product and
    /// sum is a whole number below 2^52 and so exact (the reciprocals and the gain `S' 2^32 / S`
    /// computed, not looked up), giving the same bytes; a test compares the two on every colour.
    fn saturation_planes(m: f32, r: &mut [u8], g: &mut [u8], b: &mut [u8]) {
        for ((r, g), b) in r.iter_mut().zip(g.iter_mut()).zip(b.iter_mut()) {
            let v8 = (*r).max(*g).max(*b);
            let v = v8 as f64;
            let diff = (v8 - (*r).min(*g).min(*b)) as f64;
            // S = round(255 diff / V) at least 1; V = 0 has diff = 0 and S = 1 (any gain).
            let s = shift_round(diff * 255.0 * reciprocal(v.max(1.0))).clamp(1.0, 255.0);
            // S' as the table's f32 arithmetic computes it, then the gain S' round(2^32 / S).
            let s2 = (s as f32 * m).min(255.0).floor() as f64;
            let k = s2 * reciprocal(s);
            *r = whole_byte((v - shift_round((v - *r as f64) * k)).clamp(0.0, 255.0));
            *g = whole_byte((v - shift_round((v - *g as f64) * k)).clamp(0.0, 255.0));
            *b = whole_byte((v - shift_round((v - *b as f64) * k)).clamp(0.0, 255.0));
        }
    }
}

/// One row of [`map_saturation`] for pixels of `C` bytes with colour bytes at `rgb`.
#[inline(always)]
fn saturation_row<const C: usize>(
    src: &[u8],
    dst: &mut [u8],
    [ri, gi, bi]: [usize; 3],
    recip: &[u64; 256],
    gain: &[i64; 256],
) {
    for (p, q) in src.chunks_exact(C).zip(dst.chunks_exact_mut(C)) {
        let (r, g, b) = (p[ri] as i64, p[gi] as i64, p[bi] as i64);
        let v = r.max(g).max(b);
        let diff = v - r.min(g).min(b);
        // S = round(255 diff / V), then c' = V - (V - c) S' / S, with
        // reciprocal tables.
        // When diff = 0 every channel equals V and the gain does not matter.
        let s = ((diff * 255 * recip[v as usize] as i64 + (1 << 31)) >> 32).clamp(1, 255);
        let k = gain[s as usize];
        for (ch, val) in [(ri, r), (gi, g), (bi, b)] {
            q[ch] = (v - (((v - val) * k + (1 << 31)) >> 32)).clamp(0, 255) as u8;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::image::Image;

    /// The float planes and the AVX2 kernel (planes and row to row) against the fixed-point
    /// row on every RGB colour, for the saturation factors of C-F6 and C-F8 and the ends of the
    /// accepted range. Without AVX2 the kernel writes nothing (checked too).
    #[test]
    fn float_saturation_planes_give_the_fixed_point_bytes_on_every_colour() {
        let factors = crate::camera::color::SATURATION_INCREASE
            .into_iter()
            .chain(crate::camera::color::SATURATION_DECREASE)
            .chain([0.0, 0.5, 1.0, 2.0, 7.5, 300.0]);
        let _dispatch = super::super::dispatch_lock();
        let wide = super::super::wide_available();
        let mut planes = [[0u8; 256]; 3];
        let mut kernel = [[0u8; 256]; 3];
        let mut src = vec![0u8; 3 * 256];
        let mut want = vec![0u8; 3 * 256];
        let mut direct = vec![0u8; 3 * 256];
        for m in factors {
            let map = SaturationMap::scaled(m);
            assert_eq!(map.factor, Some(m));
            for hi in 0..=255u8 {
                for mid in 0..=255u8 {
                    // Each 32-pixel block puts the largest channel in another place.
                    for lo in 0..=255u8 {
                        let i = lo as usize;
                        let mut p = [hi, mid, lo];
                        p.rotate_left(i / 32 % 3);
                        for k in 0..3 {
                            (planes[k][i], kernel[k][i]) = (p[k], p[k]);
                        }
                        src[3 * i..3 * i + 3].copy_from_slice(&p);
                    }
                    map.row(PixelFormat::Rgb8, &src, &mut want);
                    let [r, g, b] = &mut planes;
                    saturation_planes(m, r, g, b);
                    let [kr, kg, kb] = &mut kernel;
                    let done = super::super::hsv_avx2::saturation_planes(m, kr, kg, kb);
                    assert_eq!(done, if wide { 256 } else { 0 });
                    let rows = super::super::hsv_avx2::saturation_rgb(m, &src, &mut direct);
                    assert_eq!(rows, done);
                    for i in 0..256 {
                        let want = &want[3 * i..3 * i + 3];
                        let p = &src[3 * i..3 * i + 3];
                        let at = |x: &[[u8; 256]; 3]| [x[0][i], x[1][i], x[2][i]];
                        assert_eq!(at(&planes), want, "m {m}: rgb {p:?}");
                        if wide {
                            assert_eq!(at(&kernel), want, "kernel, m {m}: rgb {p:?}");
                            assert_eq!(&direct[3 * i..3 * i + 3], want, "row: m {m}: rgb {p:?}");
                        }
                    }
                }
            }
        }
        assert_eq!(SaturationMap::scaled(-1.0).factor, None);
    }

    #[test]
    fn ties_up_marks_where_the_rounded_reciprocal_is_not_below_the_quotient() {
        let recip = reciprocals();
        let bit = |n: usize| super::super::hsv_avx2::TIES_UP[n / 32] >> (n % 32) & 1;
        for (n, &r) in recip.iter().enumerate().skip(1) {
            assert_eq!(bit(n) == 1, r * n as u64 >= 1 << 32, "n {n}");
        }
        // Powers of two divide 2^32 exactly; 3's reciprocal rounds down, 6's up.
        assert_eq!([1, 2, 3, 6, 128].map(bit), [1, 1, 0, 1, 1]);
    }

    #[test]
    fn map_value_scales_channels_with_exact_rounding() {
        // Every (channel, value) pair with channel <= value, against the rational
        // round(p nv / v) with halves up, for a value map that hits many ratios.
        let pixels: Vec<[u8; 3]> = (1..=255u8)
            .flat_map(|v| (0..=v).map(move |p| [v, p, p / 2]))
            .chain([[0, 0, 0]])
            .collect();
        let w = pixels.len() as u32;
        let mut img = Image::new(w, 1, PixelFormat::Rgb8);
        img.data = pixels.concat();
        let nv = |v: u8| (v as u32 * 37 % 256) as u8;
        let mut out = Image::new(w, 1, PixelFormat::Rgb8);
        map_value(&img.view(), &mut out.view_mut(), |_, _, v| nv(v));
        for (p, q) in img.data.chunks_exact(3).zip(out.data.chunks_exact(3)) {
            let v = p[0] as u32;
            for ch in 0..3 {
                let want = if v == 0 {
                    nv(0) as u32
                } else {
                    (2 * p[ch] as u32 * nv(p[0]) as u32 + v) / (2 * v)
                };
                assert_eq!(q[ch] as u32, want, "pixel {p:?} channel {ch}");
            }
        }
        // Every other format gives the same pixels, alpha copied.
        for format in PixelFormat::ALL.into_iter().filter(|f| !f.is_mono()) {
            // The image in `format` with alpha 77.
            let in_format = |img: &Image| {
                let mut i = img.convert(format);
                if let Some(a) = format.alpha_offset() {
                    let c = format.channels();
                    i.data.iter_mut().skip(a).step_by(c).for_each(|v| *v = 77);
                }
                i
            };
            let src = in_format(&img);
            let mut got = Image::new(w, 1, format);
            map_value(&src.view(), &mut got.view_mut(), |_, _, v| nv(v));
            assert_eq!(got, in_format(&out), "{format:?}");
        }
    }

    #[test]
    fn hsv_matches_opencv_reference_values() {
        // Expected values worked by hand from OpenCV's fixed-point formulas (hsv_shift 12).
        assert_eq!(rgb_to_hsv(255, 0, 0), (0, 255, 255));
        assert_eq!(rgb_to_hsv(0, 255, 0), (60, 255, 255));
        assert_eq!(rgb_to_hsv(0, 0, 255), (120, 255, 255));
        assert_eq!(rgb_to_hsv(200, 100, 50), (10, 191, 200));
        assert_eq!(rgb_to_hsv(10, 20, 30), (105, 170, 30));
        assert_eq!(hsv_to_rgb(10, 191, 200), (200, 100, 50));
        assert_eq!(hsv_to_rgb(0, 0, 77), (77, 77, 77));
        // Round trips stay within the 8-bit quantisation.
        for (r, g, b) in [
            (12u8, 200u8, 90u8),
            (250, 250, 1),
            (3, 4, 5),
            (128, 64, 255),
        ] {
            let (h, s, v) = rgb_to_hsv(r, g, b);
            let (r2, g2, b2) = hsv_to_rgb(h, s, v);
            for (a, b) in [(r, r2), (g, g2), (b, b2)] {
                assert!(
                    (a as i32 - b as i32).abs() <= 4,
                    "{r} {g} {b} -> {r2} {g2} {b2}"
                );
            }
        }
    }
}
