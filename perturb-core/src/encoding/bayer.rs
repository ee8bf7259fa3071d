//! Bayer mosaics: bilinear demosaicking to RGB, and back by each site's own colour.
//!
//! Demosaicking (the working view): a site keeps its own colour; a missing colour is the
//! rounded mean (halves up) of the nearest samples of that colour: at a red or blue site, green
//! from the four edge neighbours and the other of red/blue from the four diagonal ones; at a
//! green site, the colour of its row from the left and right neighbours and the colour of its
//! column from the ones above and below. At the borders the mosaic is mirrored about the edge
//! pixel (index -1 reads 1), which keeps the tile's colours in place. OpenCV's bilinear
//! `cvtColor(COLOR_Bayer*2BGR)` computes the same bytes everywhere but on the one-pixel border
//! (which OpenCV fills from the neighbouring row or column).
//!
//! Mosaicking (the write-back): each site takes its own colour channel of the perturbed pixel.
//! Since demosaicking keeps a site's own colour, a pixel the perturbation left alone gives the
//! input's sample back exactly.

use super::{Plane, par_rows_mut};
use crate::image::{ImageView, ImageViewMut};

/// The 2x2 tile of a Bayer mosaic, read row by row from the top-left pixel (`Rggb`: row 0 is
/// `R G R G ...`, row 1 `G B G B ...`), as in the ROS encoding names.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum BayerPattern {
    /// `R G / G B` (`bayer_rggb*`).
    Rggb,
    /// `B G / G R` (`bayer_bggr*`).
    Bggr,
    /// `G B / R G` (`bayer_gbrg*`).
    Gbrg,
    /// `G R / B G` (`bayer_grbg*`).
    Grbg,
}

/// Channel indices: red, green, blue.
const R: usize = 0;
const G: usize = 1;
const B: usize = 2;

impl BayerPattern {
    /// Every pattern.
    pub const ALL: [BayerPattern; 4] = [
        BayerPattern::Rggb,
        BayerPattern::Bggr,
        BayerPattern::Gbrg,
        BayerPattern::Grbg,
    ];

    /// The tile's colours (0 red, 1 green, 2 blue): `[row 0 [x even, x odd], row 1 [...]]`.
    pub const fn tile(self) -> [[usize; 2]; 2] {
        match self {
            BayerPattern::Rggb => [[R, G], [G, B]],
            BayerPattern::Bggr => [[B, G], [G, R]],
            BayerPattern::Gbrg => [[G, B], [R, G]],
            BayerPattern::Grbg => [[G, R], [B, G]],
        }
    }

    /// The colour (0 red, 1 green, 2 blue) of the sample at column `x`, row `y`.
    pub const fn channel(self, x: usize, y: usize) -> usize {
        self.tile()[y % 2][x % 2]
    }

    /// The OpenCV code cv_bridge converts this pattern with: OpenCV names a Bayer code after the
    /// second row's second and third pixels, so `bayer_rggb8` is `COLOR_BayerBG2BGR`.
    pub const fn opencv_to_bgr(self) -> &'static str {
        match self {
            BayerPattern::Rggb => "COLOR_BayerBG2BGR",
            BayerPattern::Bggr => "COLOR_BayerRG2BGR",
            BayerPattern::Gbrg => "COLOR_BayerGR2BGR",
            BayerPattern::Grbg => "COLOR_BayerGB2BGR",
        }
    }
}

#[inline(always)]
fn avg2(a: u8, b: u8) -> u8 {
    ((a as u16 + b as u16 + 1) >> 1) as u8
}

#[inline(always)]
fn avg4(a: u8, b: u8, c: u8, d: u8) -> u8 {
    ((a as u16 + b as u16 + c as u16 + d as u16 + 2) >> 2) as u8
}

/// The mirrored index of `i - 1` and `i + 1` in `0..n` (`n >= 2`).
#[inline(always)]
fn around(i: usize, n: usize) -> (usize, usize) {
    let before = if i == 0 { 1 } else { i - 1 };
    let after = if i + 1 == n { n - 2 } else { i + 1 };
    (before, after)
}

/// Demosaics `src` (8-bit samples) in `pattern` into the rgb8 view `dst` (same size).
pub(super) fn demosaic(src: &Plane<'_>, pattern: BayerPattern, dst: &mut ImageViewMut<'_>) {
    let (w, h) = (src.len, src.height);
    if w == 0 || h == 0 {
        return;
    }
    let stride = dst.stride;
    par_rows_mut(dst.data_mut(), stride, w * 3, h, |y, o| {
        let (yu, yd) = around(y, h);
        let rows = [src.row(yu), src.row(y), src.row(yd)];
        let tile = pattern.tile()[y % 2];
        // This row's non-green colour and whether it sits at even columns.
        let (c, c_even) = if tile[0] == G {
            (tile[1], false)
        } else {
            (tile[0], true)
        };
        match (c, c_even) {
            (R, true) => row::<R, true>(rows, o),
            (R, false) => row::<R, false>(rows, o),
            (_, true) => row::<B, true>(rows, o),
            (_, false) => row::<B, false>(rows, o),
        }
    });
}

/// One output row: `rows` are the mosaic rows above, at and below it; colour `C` (red or blue)
/// sits at even columns when `C_EVEN`, green at the others.
#[inline(always)]
fn row<const C: usize, const C_EVEN: bool>([u, m, d]: [&[u8]; 3], out: &mut [u8]) {
    let w = m.len();
    // At a C site: C own, green from the edges, the other colour from the diagonals.
    // At a green site: green own, C from left and right, the other colour from above and below.
    let pixel = |x: usize, o: &mut [u8]| {
        let (l, r) = around(x, w);
        let c_site = x.is_multiple_of(2) == C_EVEN;
        if c_site {
            o[C] = m[x];
            o[G] = avg4(u[x], d[x], m[l], m[r]);
            o[2 - C] = avg4(u[l], u[r], d[l], d[r]);
        } else {
            o[G] = m[x];
            o[C] = avg2(m[l], m[r]);
            o[2 - C] = avg2(u[x], d[x]);
        }
    };
    // Columns 0, 1, w-2 and w-1 mirror at the edge; the pairs between them have every
    // neighbour in place.
    for x in [0, 1, w.saturating_sub(2), w - 1] {
        if x < w {
            pixel(x, &mut out[3 * x..3 * x + 3]);
        }
    }
    if w < 6 {
        return;
    }
    let inner = &mut out[6..3 * (w - 2)];
    for (i, o) in inner.chunks_exact_mut(6).enumerate() {
        let x = 2 + 2 * i; // even; x - 1 >= 1, x + 2 <= w - 2
        let (ul, uc, ur, ur2) = (u[x - 1], u[x], u[x + 1], u[x + 2]);
        let (ml, mc, mr, mr2) = (m[x - 1], m[x], m[x + 1], m[x + 2]);
        let (dl, dc, dr, dr2) = (d[x - 1], d[x], d[x + 1], d[x + 2]);
        let (even, odd) = o.split_at_mut(3);
        if C_EVEN {
            even[C] = mc;
            even[G] = avg4(uc, dc, ml, mr);
            even[2 - C] = avg4(ul, ur, dl, dr);
            odd[G] = mr;
            odd[C] = avg2(mc, mr2);
            odd[2 - C] = avg2(ur, dr);
        } else {
            even[G] = mc;
            even[C] = avg2(ml, mr);
            even[2 - C] = avg2(uc, dc);
            odd[C] = mr;
            odd[G] = avg4(ur, dr, mc, mr2);
            odd[2 - C] = avg4(uc, ur2, dc, dr2);
        }
    }
}

/// Writes each site's own colour of the rgb8 view `src` into the mosaic `out`, rows `step`
/// apart.
pub(super) fn mosaic(src: &ImageView<'_>, pattern: BayerPattern, out: &mut [u8], step: usize) {
    let (w, h) = (src.width as usize, src.height as usize);
    par_rows_mut(out, step, w, h, |y, o| {
        let [even, odd] = pattern.tile()[y % 2];
        let s = src.row(y);
        for (o, p) in o.chunks_exact_mut(2).zip(s.chunks_exact(6)) {
            o[0] = p[even];
            o[1] = p[3 + odd];
        }
    });
}
