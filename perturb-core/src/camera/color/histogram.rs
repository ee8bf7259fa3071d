//! Histogram equalisation (C-F3) with OpenCV's CLAHE.

use crate::camera::ops::{byte, map_value, wide_fn};
use crate::camera::{CameraBuilder, CameraPerturbation};
use crate::image::{ImageView, ImageViewMut};
use rayon::prelude::*;

/// C-F3 histogram_equalization: CLAHE clip limit, severities 1..5 (PerturbationDrive
/// `histogram_equalisation`, `cv2.createCLAHE(clipLimit, (8, 8))` on the HSV value channel).
pub const CLAHE_CLIP: [f64; 5] = [1.0, 3.0, 5.0, 7.0, 10.0];

/// Contrast-limited adaptive histogram equalisation of an 8-bit plane, as OpenCV's CLAHE: the plane
/// is padded by reflection to a multiple of the 8 x 8 tile grid, each tile's histogram is clipped at
/// `max(clip x tile pixels / 256, 1)` with the excess spread evenly (the remainder one count at a
/// time at a regular step), its cumulative histogram scaled to 0..255 is the tile's table, and every
/// pixel blends the tables of its four nearest tile centres bilinearly. Matches
/// `cv2.createCLAHE(clip, (8, 8)).apply` to within one level (checked on real frames).
pub fn clahe(plane: &[u8], w: usize, h: usize, clip: f64, tiles: usize) -> Vec<u8> {
    // OpenCV pads only when a side is not a multiple of the grid, and then pads both sides by
    // `tiles - n % tiles`, a whole extra tile for a side that was already a multiple.
    let (pw, ph) = if w.is_multiple_of(tiles) && h.is_multiple_of(tiles) {
        (w, h)
    } else {
        (w + tiles - w % tiles, h + tiles - h % tiles)
    };
    let (tw, th) = ((pw / tiles).max(1), (ph / tiles).max(1));
    let at = |x: usize, y: usize| plane[reflect_index(y, h) * w + reflect_index(x, w)];
    let area = (tw * th) as f64;
    let limit = ((clip * area / 256.0) as usize).max(1);
    let scale = 255.0 / area;
    let luts: Vec<[u8; 256]> = (0..tiles * tiles)
        .into_par_iter()
        .map(|t| {
            let (tx, ty) = (t % tiles, t / tiles);
            let mut hist = [0usize; 256];
            for y in ty * th..(ty + 1) * th {
                for x in tx * tw..(tx + 1) * tw {
                    hist[at(x, y) as usize] += 1;
                }
            }
            let mut clipped = 0;
            for b in hist.iter_mut() {
                if *b > limit {
                    clipped += *b - limit;
                    *b = limit;
                }
            }
            let batch = clipped / 256;
            let mut residual = clipped - batch * 256;
            for b in hist.iter_mut() {
                *b += batch;
            }
            if let Some(step) = 256usize.checked_div(residual) {
                let step = step.max(1);
                let mut i = 0;
                while i < 256 && residual > 0 {
                    hist[i] += 1;
                    residual -= 1;
                    i += step;
                }
            }
            let mut lut = [0u8; 256];
            let mut sum = 0usize;
            for (v, b) in hist.iter().enumerate() {
                sum += b;
                lut[v] = (sum as f64 * scale).round().min(255.0) as u8;
            }
            lut
        })
        .collect();
    let (inv_tw, inv_th) = (1.0 / tw as f32, 1.0 / th as f32);
    let coord = |p: usize, inv: f32| {
        let f = p as f32 * inv - 0.5;
        let t1 = f.floor() as i64;
        let a = f - t1 as f32;
        let (t1c, t2c) = (
            t1.clamp(0, tiles as i64 - 1) as usize,
            (t1 + 1).clamp(0, tiles as i64 - 1) as usize,
        );
        (t1c, t2c, a)
    };
    let xs: Vec<(usize, usize, f32)> = (0..w).map(|x| coord(x, inv_tw)).collect();
    // Runs of columns that blend the same pair of tile columns: the four tables are picked once
    // per run, not per pixel.
    let mut runs: Vec<(usize, usize, usize, usize)> = Vec::new();
    for (x, &(tx1, tx2, _)) in xs.iter().enumerate() {
        match runs.last_mut() {
            Some(run) if (run.2, run.3) == (tx1, tx2) => run.1 = x + 1,
            _ => runs.push((x, x + 1, tx1, tx2)),
        }
    }
    let mut out = vec![0u8; w * h];
    out.par_chunks_mut(w.max(1)).enumerate().for_each_init(
        || vec![0f32; w],
        |vals, (y, row)| {
            let (ty1, ty2, ya) = coord(y, inv_th);
            let src = &plane[y * w..(y + 1) * w];
            // The table lookups pixel by pixel into floats, then the rounding to bytes in
            // one vectorised pass (a float-to-byte cast per pixel does not vectorise).
            for &(x0, x1, tx1, tx2) in &runs {
                let lut = |tx: usize, ty: usize| &luts[ty * tiles + tx];
                let (a, b) = (lut(tx1, ty1), lut(tx2, ty1));
                let (c, d) = (lut(tx1, ty2), lut(tx2, ty2));
                for ((o, &v), &(_, _, xa)) in
                    vals[x0..x1].iter_mut().zip(&src[x0..x1]).zip(&xs[x0..x1])
                {
                    let v = v as usize;
                    let top = a[v] as f32 * (1.0 - xa) + b[v] as f32 * xa;
                    let bot = c[v] as f32 * (1.0 - xa) + d[v] as f32 * xa;
                    *o = top * (1.0 - ya) + bot * ya;
                }
            }
            round_bytes(vals, row);
        },
    );
    out
}

wide_fn! {
    /// `dst = clamp(round(src))` (half away from zero), NaN to 0.
    fn round_bytes(src: &[f32], dst: &mut [u8]) {
        for (d, s) in dst.iter_mut().zip(src) {
            *d = byte(s.round());
        }
    }
}

/// Reflect-101 for indices past the end only (padding to whole tiles is on the bottom and right).
fn reflect_index(i: usize, n: usize) -> usize {
    crate::camera::ops::reflect101(i as i64, n)
}

/// C-F3 histogram_equalization: CLAHE (see [`clahe`]) on the HSV value channel, hue and saturation
/// kept (the channels are rescaled to the new value, see [`crate::camera::ops::map_value`]): local contrast
/// is boosted, noise in dark flat areas too. Works on mono8 (the single channel is the value).
pub struct HistogramEqualization {
    clip: f64,
}

/// Registry constructor of C-F3.
pub const HISTOGRAM_EQUALIZATION: CameraBuilder = |s| {
    Ok(Box::new(HistogramEqualization {
        clip: CLAHE_CLIP[s.level()],
    }))
};

impl CameraPerturbation for HistogramEqualization {
    fn apply(&self, input: &ImageView<'_>, output: &mut ImageViewMut<'_>, _seq: u64) {
        let (w, h, c) = (
            input.width as usize,
            input.height as usize,
            input.format.channels(),
        );
        let [ri, gi, bi] = input.format.rgb_offsets();
        let mut v = vec![0u8; w * h];
        v.par_chunks_mut(w.max(1)).enumerate().for_each(|(y, row)| {
            for (d, p) in row.iter_mut().zip(input.row(y).chunks_exact(c)) {
                *d = p[ri].max(p[gi]).max(p[bi]);
            }
        });
        let eq = clahe(&v, w, h, self.clip, 8);
        map_value(input, output, |y, x, _| eq[y * w + x]);
    }
}
