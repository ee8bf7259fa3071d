//! Pattern family (C-E): graphic occlusions drawn over the image.
//!
//! Pixel sizes of the references (radii, spacings, amplitudes) are scaled with the frame (see
//! [`super::texture::size_scale`]: 1 at the paper's 800 x 503). The random patterns (splatter,
//! dotted lines, zigzag, cutout) are redrawn every frame from (seed, sequence number), as the
//! references redraw them on every call.

use super::ops::{copy_alpha, par_rows, wide_fn};
use super::texture::{fill_disc, fill_rect, fill_span, size_scale};
use super::{CameraBuilder, CameraPerturbation};
use crate::image::{ImageView, ImageViewMut};
use crate::rng::Rng;
use rayon::prelude::*;

fn copy(input: &ImageView<'_>, output: &mut ImageViewMut<'_>) {
    par_rows(input, output, |_, s, d| d.copy_from_slice(s));
}

/// C-E1 splatter: (number of blobs, maximum radius in pixels at 800 x 503), severities 1..5
/// (PerturbationDrive `splatter_mapping`: radius randint(5, max(6, 50 s)) for s = .1 .. .5).
pub const SPLATTER_LEVELS: [(usize, i64); 5] = [(5, 5), (10, 9), (15, 14), (20, 19), (25, 24)];

/// C-E1 splatter: dirt on the lens: black filled discs with centres uniform over the frame and
/// radii uniform in [5, r_max] (scaled with the frame).
pub struct Splatter {
    seed: u64,
    count: usize,
    r_max: i64,
}

/// Registry constructor of C-E1.
pub const SPLATTER: CameraBuilder = |s| {
    let (count, r_max) = SPLATTER_LEVELS[s.level()];
    Ok(Box::new(Splatter {
        seed: s.seed,
        count,
        r_max,
    }))
};

impl CameraPerturbation for Splatter {
    fn apply(&self, input: &ImageView<'_>, output: &mut ImageViewMut<'_>, seq: u64) {
        copy(input, output);
        let k = size_scale(input.width, input.height);
        let mut rng = Rng::for_frame(self.seed, seq, 0xE1);
        for _ in 0..self.count {
            let cx = rng.below(input.width.max(1) as u64) as i64;
            let cy = rng.below(input.height.max(1) as u64) as i64;
            let r = rng.range_inclusive(5, self.r_max);
            fill_disc(
                output,
                cx,
                cy,
                ((r as f32 * k).round() as i64).max(1),
                [0, 0, 0],
            );
        }
    }
}

/// C-E2 dotted_lines: (lines, dot spacing, dot radius) at 800 x 503, severities 1..5
/// (PerturbationDrive `dotted_lines_mapping`: spacing 45 40 35 30 25, radius 0 1 1 2 2).
///
/// Deviation: the reference draws `10 x scale_index` lines, none at severity 1; here the count is
/// 10 x severity (10 .. 50), so every severity draws something and the count rises with severity.
pub const DOTTED_LINES_LEVELS: [(usize, f32, i64); 5] = [
    (10, 45.0, 0),
    (20, 40.0, 1),
    (30, 35.0, 1),
    (40, 30.0, 2),
    (50, 25.0, 2),
];

/// C-E2 dotted_lines: straight dotted scratches: each line starts at a uniform point, runs in a
/// uniform random direction, and gets a black disc every `d` pixels until it leaves the frame.
pub struct DottedLines {
    seed: u64,
    lines: usize,
    spacing: f32,
    radius: i64,
}

/// Registry constructor of C-E2.
pub const DOTTED_LINES: CameraBuilder = |s| {
    let (lines, spacing, radius) = DOTTED_LINES_LEVELS[s.level()];
    Ok(Box::new(DottedLines {
        seed: s.seed,
        lines,
        spacing,
        radius,
    }))
};

impl CameraPerturbation for DottedLines {
    fn apply(&self, input: &ImageView<'_>, output: &mut ImageViewMut<'_>, seq: u64) {
        copy(input, output);
        let (w, h) = (input.width as f32, input.height as f32);
        let k = size_scale(input.width, input.height);
        let (step, r) = (
            (self.spacing * k).max(1.0),
            (self.radius as f32 * k).round() as i64,
        );
        let mut rng = Rng::for_frame(self.seed, seq, 0xE2);
        for _ in 0..self.lines {
            let (mut x, mut y) = (rng.f32() * w, rng.f32() * h);
            let (dx, dy) = (rng.f32() * 2.0 - 1.0, rng.f32() * 2.0 - 1.0);
            let n = (dx * dx + dy * dy).sqrt().max(1e-6);
            let (dx, dy) = (dx / n * step, dy / n * step);
            while x >= 0.0 && y >= 0.0 && x < w && y < h {
                fill_disc(output, x as i64, y as i64, r, [0, 0, 0]);
                x += dx;
                y += dy;
            }
        }
    }
}

/// C-E3 zigzag: (lines, amplitude at 800 x 503, angular frequency), severities 1..5
/// (PerturbationDrive `zigzag_mapping`).
pub const ZIGZAG_LEVELS: [(usize, f32, f32); 5] = [
    (1, 2.0, 1.0),
    (2, 4.0, 2.0),
    (3, 6.0, 3.0),
    (4, 8.0, 4.0),
    (6, 12.0, 6.0),
];

/// C-E3 zigzag: wavy black scratches: from a uniform start in a uniform direction, step k moves by
/// the unit direction plus `A sin(f k)` across it (k an integer step, radians), one black pixel
/// (scaled to a square of the frame's size factor) per step until the line leaves the frame.
pub struct Zigzag {
    seed: u64,
    lines: usize,
    amplitude: f32,
    freq: f32,
}

/// Registry constructor of C-E3.
pub const ZIGZAG: CameraBuilder = |s| {
    let (lines, amplitude, freq) = ZIGZAG_LEVELS[s.level()];
    Ok(Box::new(Zigzag {
        seed: s.seed,
        lines,
        amplitude,
        freq,
    }))
};

impl CameraPerturbation for Zigzag {
    fn apply(&self, input: &ImageView<'_>, output: &mut ImageViewMut<'_>, seq: u64) {
        copy(input, output);
        let (w, h) = (input.width as f32, input.height as f32);
        let k = size_scale(input.width, input.height);
        let thick = (k.round() as i64).max(1);
        let mut rng = Rng::for_frame(self.seed, seq, 0xE3);
        for _ in 0..self.lines {
            let (x0, y0) = (rng.f32() * w, rng.f32() * h);
            let a = rng.f32() * std::f32::consts::TAU;
            let (ux, uy) = (crate::math::cosf(a), crate::math::sinf(a));
            let max_steps = (2.0 * (w + h) / k.max(0.25)) as usize + 1;
            for step in 0..max_steps {
                let t = step as f32 * k;
                let off = self.amplitude * k * crate::math::sinf(self.freq * step as f32);
                let (x, y) = (x0 + ux * t - uy * off, y0 + uy * t + ux * off);
                if x < 0.0 || y < 0.0 || x >= w || y >= h {
                    break;
                }
                fill_rect(
                    output,
                    x as i64,
                    y as i64,
                    x as i64 + thick,
                    y as i64 + thick,
                    [0, 0, 0],
                );
            }
        }
    }
}

/// C-E4 canny_edges: (low, high) hysteresis thresholds, severities 1..5 (PerturbationDrive
/// `canny_edges_mapping`); higher thresholds find fewer edges, as in the reference.
pub const CANNY_LEVELS: [(i32, i32); 5] = [(51, 151), (60, 160), (75, 175), (90, 190), (120, 220)];

/// Edges of an 8-bit grey plane as `cv2.Canny(gray, low, high)` finds them: 3x3 Sobel gradients
/// (replicated borders), L1 magnitude |gx| + |gy|, non-maximum suppression across the gradient
/// direction quantised to 0, 45, 90, 135 degrees, hysteresis: pixels above `high` start edges that
/// grow through 8-connected pixels above `low`. No smoothing first (OpenCV's Canny has none).
pub fn canny(gray: &[u8], w: usize, h: usize, low: i32, high: i32) -> Vec<bool> {
    if w == 0 || h == 0 {
        return Vec::new();
    }
    let (edge, pw) = canny_padded(gray, w, h, low, high);
    edge.chunks_exact(pw)
        .skip(1)
        .take(h)
        .flat_map(|row| &row[1..=w])
        .copied()
        .collect()
}

/// [`canny`] on planes padded by one pixel on every side (magnitude 0, never an edge), so that no
/// neighbour access needs a bounds test: returns the `(w + 2) x (h + 2)` edge map and its width.
/// `w` and `h` must not be 0.
fn canny_padded(gray: &[u8], w: usize, h: usize, low: i32, high: i32) -> (Vec<bool>, usize) {
    let pw = w + 2;
    // Sobel, row by row: with S = up + 2 mid + down and D = down - up per column (rows clamped),
    // gx = S[x + 1] - S[x - 1] and gy = D[x - 1] + 2 D[x] + D[x + 1] (columns clamped). Each pixel
    // keeps its L1 magnitude (at most 2040, 11 bits) and the direction its non-maximum test looks
    // along (bits 12-13): 0 horizontal, 1 vertical, 2 and 3 the diagonals.
    let mut grad = vec![0u16; pw * (h + 2)];
    grad.par_chunks_mut(pw)
        .enumerate()
        .skip(1)
        .take(h)
        .for_each(|(py, out)| {
            let y = py - 1;
            let row = |y: usize| &gray[y * w..(y + 1) * w];
            let (up, mid, down) = (row(y.saturating_sub(1)), row(y), row((y + 1).min(h - 1)));
            sobel_row([up, mid, down], &mut out[1..=w]);
        });
    // Non-maximum suppression, row by row: 0 not an edge, 1 weak candidate, 2 strong. A pixel is
    // a maximum when its magnitude exceeds the neighbour before it along its direction and is not
    // below the one after it. All four directions' tests run on every pixel from shifted rows and
    // the pixel's own direction picks one: no branches and no gathers, so the loop vectorises.
    let mut state = vec![0u8; pw * (h + 2)];
    let (low, high) = (low.clamp(-1, 0xFFF) as i16, high.clamp(-1, 0xFFF) as i16);
    let seeds: Vec<Vec<usize>> = state
        .par_chunks_mut(pw)
        .enumerate()
        .skip(1)
        .take(h)
        .map(|(py, out)| {
            let row = |py: usize| &grad[py * pw..(py + 1) * pw];
            suppress_row(
                [row(py - 1), row(py), row(py + 1)],
                low,
                high,
                &mut out[1..=w],
            );
            let strong = out.iter().enumerate().filter(|(_, s)| **s == 2);
            strong.map(|(x, _)| py * pw + x).collect()
        })
        .collect();
    // Hysteresis: the weak candidates 8-connected to a strong pixel (the closure does not depend
    // on the order the seeds are taken in). The padding is never a candidate, so the walk needs no
    // bounds tests.
    let around = [pw + 1, pw, pw - 1, 1];
    let mut stack: Vec<usize> = seeds.concat();
    let mut edge = vec![false; pw * (h + 2)];
    while let Some(k) = stack.pop() {
        if edge[k] {
            continue;
        }
        edge[k] = true;
        for n in around.iter().flat_map(|&o| [k - o, k + o]) {
            if state[n] > 0 && !edge[n] {
                stack.push(n);
            }
        }
    }
    (edge, pw)
}

wide_fn! {
    /// One row of [`canny_padded`]'s Sobel pass from the grey rows above, at and below: per
    /// pixel the L1 magnitude and the direction code in bits 12-13.
    fn sobel_row(rows: [&[u8]; 3], out: &mut [u16]) {
        let (tg22, tg67) = (0.414_213_56f64, 2.414_213_56f64);
        let [up, mid, down] = rows;
        let w = out.len();
        let mut s = vec![0i16; w + 2];
        let mut d = vec![0i16; w + 2];
        for (x, ((&u, &m), &n)) in up.iter().zip(mid).zip(down).enumerate() {
            s[x + 1] = u as i16 + 2 * m as i16 + n as i16;
            d[x + 1] = n as i16 - u as i16;
        }
        (s[0], s[w + 1], d[0], d[w + 1]) = (s[1], s[w], d[1], d[w]);
        for (x, g) in out.iter_mut().enumerate() {
            let gx = s[x + 2] - s[x];
            let gy = d[x] + 2 * d[x + 1] + d[x + 2];
            // Branch-free: the direction is stored for every pixel and read only above `low`.
            let (ax, ay) = (gx.abs() as f64, gy.abs() as f64);
            let near_horizontal = (ay <= ax * tg22) as u16;
            let near_vertical = (ay >= ax * tg67) as u16;
            let diagonal = 3 - ((gx > 0) == (gy > 0)) as u16;
            let dir = (diagonal - near_vertical * (diagonal - 1)) * (1 - near_horizontal);
            *g = (gx.abs() + gy.abs()) as u16 | dir << 12;
        }
    }
}

wide_fn! {
    /// One row of [`canny_padded`]'s non-maximum suppression from the padded gradient rows
    /// above, at and below (`out` is the row's interior, one shorter than the rows at each end).
    fn suppress_row(rows: [&[u16]; 3], low: i16, high: i16, out: &mut [u8]) {
        let [up, cur, down] = rows;
        let m = |g: u16| (g & 0xFFF) as i16;
        for (x, o) in out.iter_mut().enumerate() {
            let g = cur[x + 1];
            let (v, dir) = (m(g), g >> 12);
            let horizontal = (v > m(cur[x])) & (v >= m(cur[x + 2]));
            let vertical = (v > m(up[x + 1])) & (v >= m(down[x + 1]));
            let falling = (v > m(up[x])) & (v >= m(down[x + 2]));
            let rising = (v > m(up[x + 2])) & (v >= m(down[x]));
            let is_max = (horizontal & (dir == 0))
                | (vertical & (dir == 1))
                | (falling & (dir == 2))
                | (rising & (dir == 3));
            *o = (is_max & (v > low)) as u8 * (1 + (v > high) as u8);
        }
    }
}

/// C-E4 canny_edges: the frame dimmed to 70 % with red (255, 0, 0) Canny edges added at 30 %:
/// `out = 0.7 I + 0.3 E` (`cv2.addWeighted`), E red on edges and black elsewhere, edges of the
/// BT.601 grey image. As the paper notes, the whole image is dimmed and higher severities show
/// fewer edges.
pub struct CannyEdges {
    low: i32,
    high: i32,
}

/// Registry constructor of C-E4.
pub const CANNY: CameraBuilder = |s| {
    let (low, high) = CANNY_LEVELS[s.level()];
    Ok(Box::new(CannyEdges { low, high }))
};

impl CameraPerturbation for CannyEdges {
    fn apply(&self, input: &ImageView<'_>, output: &mut ImageViewMut<'_>, _seq: u64) {
        let (w, h) = (input.width as usize, input.height as usize);
        let f = input.format;
        let c = f.channels();
        let ri = f.rgb_offsets()[0];
        let mut gray = vec![0u8; w * h];
        gray.par_chunks_mut(w.max(1))
            .enumerate()
            .for_each(|(y, row)| {
                crate::image::luma_row(input.row(y), f, row);
            });
        let (edges, pw) = if w == 0 || h == 0 {
            (Vec::new(), 0)
        } else {
            canny_padded(&gray, w, h, self.low, self.high)
        };
        let dim: [u8; 256] = std::array::from_fn(|v| (0.7 * v as f64).round_ties_even() as u8);
        let red: [u8; 256] = std::array::from_fn(|v| {
            (0.7 * v as f64 + 0.3 * 255.0).round_ties_even().min(255.0) as u8
        });
        // On mono8 the red edge colour is its luma, 76.
        let red_grey: [u8; 256] =
            std::array::from_fn(|v| (0.7 * v as f64 + 0.3 * 76.0).round_ties_even() as u8);
        // Every channel dimmed; on edge pixels the red channel (the single channel of mono8)
        // gets the edge colour instead; alpha is copied.
        let (edge_lut, edge_ch) = if f.is_mono() {
            (&red_grey, 0)
        } else {
            (&red, ri)
        };
        par_rows(input, output, |y, src, dst| {
            for (q, p) in dst.iter_mut().zip(src) {
                *q = dim[*p as usize];
            }
            let row_edges = &edges[(y + 1) * pw + 1..(y + 1) * pw + 1 + w];
            for (x, _) in row_edges.iter().enumerate().filter(|(_, e)| **e) {
                dst[x * c + edge_ch] = edge_lut[src[x * c + edge_ch] as usize];
            }
            copy_alpha(f, src, dst);
        });
    }
}

/// C-E5 cutout: number of black rectangles, severities 1..5 (PerturbationDrive `cutout_filter`).
pub const CUTOUT_COUNT: [usize; 5] = [1, 2, 4, 6, 10];

/// C-E5 cutout: `n` black rectangles, each with height uniform in [0.05 H, 0.2 H), width uniform
/// in [0.05 W, 0.2 W) and a uniform position that keeps it inside the frame.
pub struct Cutout {
    seed: u64,
    count: usize,
}

/// Registry constructor of C-E5.
pub const CUTOUT: CameraBuilder = |s| {
    Ok(Box::new(Cutout {
        seed: s.seed,
        count: CUTOUT_COUNT[s.level()],
    }))
};

impl Cutout {
    /// The rectangles (x, y, w, h) of frame `seq` for a `w` x `h` frame.
    pub fn rects(&self, w: u32, h: u32, seq: u64) -> Vec<(i64, i64, i64, i64)> {
        let mut rng = Rng::for_frame(self.seed, seq, 0xE5);
        let (w, h) = (w as i64, h as i64);
        (0..self.count)
            .map(|_| {
                let rh = rng
                    .range_inclusive(
                        (h as f64 * 0.05) as i64,
                        ((h as f64 * 0.2) as i64 - 1).max((h as f64 * 0.05) as i64),
                    )
                    .max(1);
                let rw = rng
                    .range_inclusive(
                        (w as f64 * 0.05) as i64,
                        ((w as f64 * 0.2) as i64 - 1).max((w as f64 * 0.05) as i64),
                    )
                    .max(1);
                let y = rng.range_inclusive(0, (h - rh).max(0));
                let x = rng.range_inclusive(0, (w - rw).max(0));
                (x, y, rw, rh)
            })
            .collect()
    }
}

impl CameraPerturbation for Cutout {
    fn apply(&self, input: &ImageView<'_>, output: &mut ImageViewMut<'_>, seq: u64) {
        // One pass: each row copied, then the rectangles crossing it blacked out while it is
        // in cache (the bytes of copying the frame and filling each rectangle in turn).
        let rects = self.rects(input.width, input.height, seq);
        let format = input.format;
        par_rows(input, output, |y, s, d| {
            d.copy_from_slice(s);
            let y = y as i64;
            for &(x, ry, w, h) in &rects {
                if (ry..ry + h).contains(&y) {
                    fill_span(format, d, x, x + w, [0, 0, 0]);
                }
            }
        });
    }
}

/// C-E6 object_overlay: the divisor c of the object's width H / c, severities 1..5
/// (PerturbationDrive `object_overlay`).
pub const OVERLAY_DIVISOR: [f32; 5] = [10.0, 5.0, 3.0, 2.0, 1.5];

/// C-E6 object_overlay: an opaque object stuck on the lens or the scene, centred: a procedural
/// sticker (white with a black border, a red stripe and the word PERTURB in block letters; no
/// third-party logo is shipped), `H / c` wide and half as tall, pasted opaque as the reference
/// pastes its logo. Deviation: the reference mixes up the axes when sizing its logo (height from the
/// width); here the sticker keeps its own aspect ratio. Deterministic.
pub struct ObjectOverlay {
    divisor: f32,
}

/// Registry constructor of C-E6.
pub const OBJECT_OVERLAY: CameraBuilder = |s| {
    Ok(Box::new(ObjectOverlay {
        divisor: OVERLAY_DIVISOR[s.level()],
    }))
};

impl CameraPerturbation for ObjectOverlay {
    fn apply(&self, input: &ImageView<'_>, output: &mut ImageViewMut<'_>, _seq: u64) {
        copy(input, output);
        let (w, h) = (input.width as i64, input.height as i64);
        let ow = ((h as f32 / self.divisor) as i64).clamp(1, w);
        let oh = (ow / 2).max(1);
        let (x0, y0) = ((w - ow) / 2, (h - oh) / 2);
        let border = (ow / 40).max(1);
        fill_rect(output, x0, y0, x0 + ow, y0 + oh, [10, 10, 10]);
        fill_rect(
            output,
            x0 + border,
            y0 + border,
            x0 + ow - border,
            y0 + oh - border,
            [245, 245, 240],
        );
        fill_rect(
            output,
            x0 + border,
            y0 + oh * 2 / 3,
            x0 + ow - border,
            y0 + oh * 5 / 6,
            [200, 20, 30],
        );
        // Block letters: a 5x7 font scaled to fit the upper part.
        let text = "PERTURB";
        let scale = ((ow - 4 * border) / (text.len() as i64 * 6)).max(1);
        let tx = x0 + (ow - text.len() as i64 * 6 * scale) / 2;
        let ty = y0 + border * 2 + ((oh * 2 / 3 - 3 * border) - 7 * scale).max(0) / 2;
        let mut glyphs = crate::image::Image::new(
            (text.len() as i64 * 6) as u32,
            7,
            crate::image::PixelFormat::Mono8,
        );
        crate::viz::draw_text(&mut glyphs, 0, 0, text, 1, [255, 255, 255]);
        for gy in 0..7i64 {
            for gx in 0..glyphs.width as i64 {
                if glyphs.data[(gy * glyphs.width as i64 + gx) as usize] > 0 {
                    fill_rect(
                        output,
                        tx + gx * scale,
                        ty + gy * scale,
                        tx + (gx + 1) * scale,
                        ty + (gy + 1) * scale,
                        [15, 15, 15],
                    );
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    use crate::image::{Image, PixelFormat};

    fn run(b: CameraBuilder, sev: u8, img: &Image, seq: u64) -> Image {
        crate::camera::apply_once(b, sev, 9, img, seq)
    }

    fn bright(w: u32, h: u32) -> Image {
        let mut i = Image::new(w, h, PixelFormat::Rgb8);
        i.data.fill(200);
        i
    }

    /// Connected black regions (4-connectivity).
    fn black_regions(img: &Image) -> usize {
        let (w, h) = (img.width as usize, img.height as usize);
        let black: Vec<bool> = img.data.chunks_exact(3).map(|p| p == [0, 0, 0]).collect();
        let mut seen = vec![false; w * h];
        let mut n = 0;
        for s in 0..w * h {
            if !black[s] || seen[s] {
                continue;
            }
            n += 1;
            let mut st = vec![s];
            while let Some(k) = st.pop() {
                if seen[k] {
                    continue;
                }
                seen[k] = true;
                let (x, y) = (k % w, k / w);
                for (nx, ny) in [
                    (x.wrapping_sub(1), y),
                    (x + 1, y),
                    (x, y.wrapping_sub(1)),
                    (x, y + 1),
                ] {
                    if nx < w && ny < h && black[ny * w + nx] && !seen[ny * w + nx] {
                        st.push(ny * w + nx);
                    }
                }
            }
        }
        n
    }

    #[test]
    fn cutout_blacks_out_the_configured_rectangles() {
        let img = bright(800, 503);
        for s in 1..=5u8 {
            let p = Cutout {
                seed: 9,
                count: CUTOUT_COUNT[s as usize - 1],
            };
            let rects = p.rects(800, 503, 4);
            let out = run(CUTOUT, s, &img, 4);
            let black = out.data.chunks_exact(3).filter(|p| *p == [0, 0, 0]).count();
            // Rectangles may overlap: the black area is at most their sum, at least the largest.
            let areas: Vec<i64> = rects.iter().map(|r| r.2 * r.3).collect();
            assert!(
                black as i64 <= areas.iter().sum::<i64>()
                    && black as i64 >= *areas.iter().max().unwrap()
            );
            for (x, y, w, h) in &rects {
                assert!(*w >= 40 && *w < 160 && *h >= 25 && *h < 101, "{w}x{h}");
                assert!(x + w <= 800 && y + h <= 503);
            }
            if s == 1 {
                assert_eq!(black_regions(&out), 1);
            }
        }
    }

    #[test]
    fn splatter_draws_the_configured_number_of_blobs() {
        let out = run(SPLATTER, 1, &bright(800, 503), 2);
        // 5 discs of radius 5: regions can merge when discs overlap, rarely.
        let n = black_regions(&out);
        assert!((4..=5).contains(&n), "{n}");
    }

    #[test]
    fn canny_finds_a_square_and_fewer_edges_at_higher_thresholds() {
        let mut g = vec![20u8; 64 * 64];
        for y in 16..48 {
            for x in 16..48 {
                g[y * 64 + x] = 220;
            }
        }
        let e = canny(&g, 64, 64, 51, 151);
        let count = e.iter().filter(|&&b| b).count();
        assert!(
            (100..=140).contains(&count),
            "{count} edge pixels around a 32x32 square"
        );
        assert!(
            !e[32 * 64 + 32] && !e[2 * 64 + 2],
            "no edges inside or far outside"
        );
        let img = crate::synthetic::street_image(200, 120, 0);
        let edges = |s| {
            run(CANNY, s, &img, 0)
                .data
                .chunks_exact(3)
                .filter(|p| p[0] > p[1] + 40)
                .count()
        };
        assert!(edges(1) > edges(5), "{} {}", edges(1), edges(5));
    }

    #[test]
    fn dotted_lines_and_zigzag_draw_more_with_severity() {
        let img = bright(400, 250);
        for b in [DOTTED_LINES, ZIGZAG] {
            let black = |s| {
                run(b, s, &img, 1)
                    .data
                    .chunks_exact(3)
                    .filter(|p| *p == [0, 0, 0])
                    .count()
            };
            assert!(black(1) > 0, "severity 1 draws something");
            assert!(black(5) > black(1));
        }
    }

    #[test]
    fn overlay_grows_with_severity_and_is_centred() {
        let img = bright(400, 250);
        let covered = |s| {
            run(OBJECT_OVERLAY, s, &img, 0)
                .data
                .chunks_exact(3)
                .filter(|p| *p != [200, 200, 200])
                .count()
        };
        let c: Vec<usize> = (1..=5).map(covered).collect();
        assert!(c.windows(2).all(|w| w[0] < w[1]), "{c:?}");
        let out = run(OBJECT_OVERLAY, 5, &img, 0);
        assert_ne!(&out.data[(125 * 400 + 200) * 3..][..3], &[200, 200, 200]);
    }
}
