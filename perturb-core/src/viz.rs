//! Pictures for people: text labels, bird's-eye views of point clouds, and contact sheets.
//! Used by `perturb gallery` and the demo; pure pixel work on [`Image`]s.

use crate::cloud::{CloudView, names};
use crate::image::{Image, PixelFormat, resize_bilinear};
use crate::lidar::Box3;

/// 5x7 glyphs, one byte per row (bit 4 = leftmost pixel), for the characters labels use.
/// Lowercase letters are drawn as uppercase.
fn glyph(c: char) -> [u8; 7] {
    match c.to_ascii_uppercase() {
        'A' => [0x0E, 0x11, 0x11, 0x1F, 0x11, 0x11, 0x11],
        'B' => [0x1E, 0x11, 0x11, 0x1E, 0x11, 0x11, 0x1E],
        'C' => [0x0E, 0x11, 0x10, 0x10, 0x10, 0x11, 0x0E],
        'D' => [0x1C, 0x12, 0x11, 0x11, 0x11, 0x12, 0x1C],
        'E' => [0x1F, 0x10, 0x10, 0x1E, 0x10, 0x10, 0x1F],
        'F' => [0x1F, 0x10, 0x10, 0x1E, 0x10, 0x10, 0x10],
        'G' => [0x0E, 0x11, 0x10, 0x17, 0x11, 0x11, 0x0F],
        'H' => [0x11, 0x11, 0x11, 0x1F, 0x11, 0x11, 0x11],
        'I' => [0x0E, 0x04, 0x04, 0x04, 0x04, 0x04, 0x0E],
        'J' => [0x07, 0x02, 0x02, 0x02, 0x02, 0x12, 0x0C],
        'K' => [0x11, 0x12, 0x14, 0x18, 0x14, 0x12, 0x11],
        'L' => [0x10, 0x10, 0x10, 0x10, 0x10, 0x10, 0x1F],
        'M' => [0x11, 0x1B, 0x15, 0x15, 0x11, 0x11, 0x11],
        'N' => [0x11, 0x11, 0x19, 0x15, 0x13, 0x11, 0x11],
        'O' => [0x0E, 0x11, 0x11, 0x11, 0x11, 0x11, 0x0E],
        'P' => [0x1E, 0x11, 0x11, 0x1E, 0x10, 0x10, 0x10],
        'Q' => [0x0E, 0x11, 0x11, 0x11, 0x15, 0x12, 0x0D],
        'R' => [0x1E, 0x11, 0x11, 0x1E, 0x14, 0x12, 0x11],
        'S' => [0x0F, 0x10, 0x10, 0x0E, 0x01, 0x01, 0x1E],
        'T' => [0x1F, 0x04, 0x04, 0x04, 0x04, 0x04, 0x04],
        'U' => [0x11, 0x11, 0x11, 0x11, 0x11, 0x11, 0x0E],
        'V' => [0x11, 0x11, 0x11, 0x11, 0x11, 0x0A, 0x04],
        'W' => [0x11, 0x11, 0x11, 0x15, 0x15, 0x15, 0x0A],
        'X' => [0x11, 0x11, 0x0A, 0x04, 0x0A, 0x11, 0x11],
        'Y' => [0x11, 0x11, 0x11, 0x0A, 0x04, 0x04, 0x04],
        'Z' => [0x1F, 0x01, 0x02, 0x04, 0x08, 0x10, 0x1F],
        '0' => [0x0E, 0x11, 0x13, 0x15, 0x19, 0x11, 0x0E],
        '1' => [0x04, 0x0C, 0x04, 0x04, 0x04, 0x04, 0x0E],
        '2' => [0x0E, 0x11, 0x01, 0x02, 0x04, 0x08, 0x1F],
        '3' => [0x1F, 0x02, 0x04, 0x02, 0x01, 0x11, 0x0E],
        '4' => [0x02, 0x06, 0x0A, 0x12, 0x1F, 0x02, 0x02],
        '5' => [0x1F, 0x10, 0x1E, 0x01, 0x01, 0x11, 0x0E],
        '6' => [0x06, 0x08, 0x10, 0x1E, 0x11, 0x11, 0x0E],
        '7' => [0x1F, 0x01, 0x02, 0x04, 0x08, 0x08, 0x08],
        '8' => [0x0E, 0x11, 0x11, 0x0E, 0x11, 0x11, 0x0E],
        '9' => [0x0E, 0x11, 0x11, 0x0F, 0x01, 0x02, 0x0C],
        '-' => [0x00, 0x00, 0x00, 0x1F, 0x00, 0x00, 0x00],
        '_' => [0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x1F],
        '.' => [0x00, 0x00, 0x00, 0x00, 0x00, 0x0C, 0x0C],
        ',' => [0x00, 0x00, 0x00, 0x00, 0x0C, 0x04, 0x08],
        ':' => [0x00, 0x0C, 0x0C, 0x00, 0x0C, 0x0C, 0x00],
        '/' => [0x01, 0x01, 0x02, 0x04, 0x08, 0x10, 0x10],
        '(' => [0x02, 0x04, 0x08, 0x08, 0x08, 0x04, 0x02],
        ')' => [0x08, 0x04, 0x02, 0x02, 0x02, 0x04, 0x08],
        '%' => [0x18, 0x19, 0x02, 0x04, 0x08, 0x13, 0x03],
        '+' => [0x00, 0x04, 0x04, 0x1F, 0x04, 0x04, 0x00],
        '=' => [0x00, 0x00, 0x1F, 0x00, 0x1F, 0x00, 0x00],
        ' ' => [0; 7],
        _ => [0x1F, 0x11, 0x11, 0x11, 0x11, 0x11, 0x1F],
    }
}

/// Width in pixels of `text` drawn at `scale`.
pub fn text_width(text: &str, scale: u32) -> u32 {
    text.chars().count() as u32 * 6 * scale
}

/// Draws `text` with its top-left corner at (x, y), `scale` pixels per font pixel, in `color`
/// (rgb); pixels outside the image are skipped. Works on any format (mono8 gets the luma).
pub fn draw_text(img: &mut Image, x: i32, y: i32, text: &str, scale: u32, color: [u8; 3]) {
    for (k, c) in text.chars().enumerate() {
        let g = glyph(c);
        let gx = x + (k as u32 * 6 * scale) as i32;
        for (row, bits) in g.iter().enumerate() {
            for col in 0..5 {
                if bits & (0x10 >> col) == 0 {
                    continue;
                }
                for dy in 0..scale {
                    for dx in 0..scale {
                        put(
                            img,
                            gx + (col * scale + dx) as i32,
                            y + (row as u32 * scale + dy) as i32,
                            color,
                        );
                    }
                }
            }
        }
    }
}

/// Sets one pixel (rgb colour) if it is inside the image.
#[inline]
pub fn put(img: &mut Image, x: i32, y: i32, color: [u8; 3]) {
    if x < 0 || y < 0 || x >= img.width as i32 || y >= img.height as i32 {
        return;
    }
    let c = img.format.channels();
    let i = y as usize * img.stride + x as usize * c;
    if img.format.is_mono() {
        img.data[i] = crate::image::luma(color[0], color[1], color[2]);
        return;
    }
    let [r, g, b] = img.format.rgb_offsets();
    img.data[i + r] = color[0];
    img.data[i + g] = color[1];
    img.data[i + b] = color[2];
    if let Some(a) = img.format.alpha_offset() {
        img.data[i + a] = 255;
    }
}

/// A line from (x0, y0) to (x1, y1) (Bresenham).
pub fn draw_line(
    img: &mut Image,
    (mut x0, mut y0): (i32, i32),
    (x1, y1): (i32, i32),
    color: [u8; 3],
) {
    let (dx, dy) = ((x1 - x0).abs(), -(y1 - y0).abs());
    let (sx, sy) = (if x0 < x1 { 1 } else { -1 }, if y0 < y1 { 1 } else { -1 });
    let mut err = dx + dy;
    loop {
        put(img, x0, y0, color);
        if x0 == x1 && y0 == y1 {
            break;
        }
        let e2 = 2 * err;
        if e2 >= dy {
            err += dy;
            x0 += sx;
        }
        if e2 <= dx {
            err += dx;
            y0 += sy;
        }
    }
}

/// A piecewise-linear approximation of the "turbo" colour map, `t` in 0..1.
pub fn colormap(t: f32) -> [u8; 3] {
    const STOPS: [[f32; 3]; 6] = [
        [48.0, 18.0, 59.0],
        [70.0, 134.0, 251.0],
        [27.0, 229.0, 181.0],
        [164.0, 252.0, 60.0],
        [251.0, 185.0, 56.0],
        [180.0, 28.0, 4.0],
    ];
    let t = t.clamp(0.0, 1.0) * (STOPS.len() - 1) as f32;
    let i = (t as usize).min(STOPS.len() - 2);
    let f = t - i as f32;
    let mix = |k| (STOPS[i][k] * (1.0 - f) + STOPS[i + 1][k] * f) as u8;
    [mix(0), mix(1), mix(2)]
}

/// What colours the points of a bird's-eye view.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ColorBy {
    /// Height z from -2.5 m to 1.5 m.
    Height,
    /// Intensity from 0 to the given full scale.
    Intensity,
}

/// A bird's-eye view of `cloud`, `size` x `size` pixels covering ±`range` metres around the sensor,
/// x forward (up in the picture), y left; points coloured by height or intensity, `boxes` drawn as
/// white outlines, a grey ring every 10 m.
pub fn bird_eye_view(
    cloud: &CloudView<'_>,
    size: u32,
    range: f32,
    color_by: ColorBy,
    intensity_max: f32,
    boxes: &[Box3],
) -> Image {
    let mut img = Image::new(size, size, PixelFormat::Rgb8);
    let scale = size as f32 / (2.0 * range);
    let c = size as f32 / 2.0;
    let to_px = |x: f32, y: f32| ((c - y * scale) as i32, (c - x * scale) as i32);
    for r in (10..range as i32 + 1).step_by(10) {
        let steps = (r as f32 * scale * 6.3) as i32 + 8;
        for k in 0..steps {
            let a = k as f32 / steps as f32 * std::f32::consts::TAU;
            let (u, v) = to_px(
                r as f32 * crate::math::cosf(a),
                r as f32 * crate::math::sinf(a),
            );
            put(&mut img, u, v, [45, 45, 45]);
        }
    }
    let Ok([rx, ry, rz]) = cloud.layout().xyz_readers() else {
        return img;
    };
    let ri = cloud.layout().reader_any(names::INTENSITY);
    for i in 0..cloud.len() {
        let p = cloud.point(i);
        let (x, y, z) = (rx.read_f32(p), ry.read_f32(p), rz.read_f32(p));
        if !(x.is_finite() && y.is_finite() && z.is_finite()) {
            continue;
        }
        let t = match (color_by, ri) {
            (ColorBy::Intensity, Some(ri)) => ri.read_f32(p) / intensity_max.max(1e-6),
            _ => (z + 2.5) / 4.0,
        };
        let (u, v) = to_px(x, y);
        put(&mut img, u, v, colormap(t));
    }
    for b in boxes {
        let (s, co) = crate::math::sincosf(b.yaw);
        let (hl, hw) = (b.size[0] / 2.0, b.size[1] / 2.0);
        let corners: Vec<(i32, i32)> = [(hl, hw), (hl, -hw), (-hl, -hw), (-hl, hw)]
            .iter()
            .map(|(dx, dy)| {
                to_px(
                    b.center[0] + dx * co - dy * s,
                    b.center[1] + dx * s + dy * co,
                )
            })
            .collect();
        for k in 0..4 {
            draw_line(&mut img, corners[k], corners[(k + 1) % 4], [255, 255, 255]);
        }
    }
    let (u, v) = to_px(0.0, 0.0);
    for d in -2..=2 {
        put(&mut img, u + d, v, [255, 60, 60]);
        put(&mut img, u, v + d, [255, 60, 60]);
    }
    img
}

/// One labelled cell of a contact sheet.
pub struct Cell {
    /// The picture (any size and format; it is scaled to the cell).
    pub image: Image,
    /// The label drawn above it.
    pub label: String,
}

/// Lays out `rows` of cells into one rgb8 sheet: every cell `cell_w` pixels wide (height from the
/// first cell's aspect ratio), a label strip above each, a title on top.
pub fn contact_sheet(title: &str, rows: &[Vec<Cell>], cell_w: u32) -> Image {
    let aspect = rows.iter().flatten().next().map_or(0.75, |c| {
        c.image.height as f32 / c.image.width.max(1) as f32
    });
    let cell_h = ((cell_w as f32 * aspect) as u32).max(1);
    let (label_h, pad, title_h) = (14u32, 4u32, 24u32);
    let cols = rows.iter().map(Vec::len).max().unwrap_or(0) as u32;
    let width = cols * (cell_w + pad) + pad;
    let height = title_h + rows.len() as u32 * (cell_h + label_h + pad) + pad;
    let mut sheet = Image::new(width.max(1), height.max(1), PixelFormat::Rgb8);
    sheet.data.fill(24);
    draw_text(&mut sheet, pad as i32, 6, title, 2, [240, 240, 240]);
    for (r, row) in rows.iter().enumerate() {
        let y0 = title_h + r as u32 * (cell_h + label_h + pad);
        for (k, cell) in row.iter().enumerate() {
            let x0 = pad + k as u32 * (cell_w + pad);
            draw_text(
                &mut sheet,
                x0 as i32,
                y0 as i32 + 3,
                &cell.label,
                1,
                [230, 230, 120],
            );
            let rgb = cell.image.convert(PixelFormat::Rgb8);
            let small = resize_bilinear(&rgb.view(), cell_w, cell_h);
            for y in 0..cell_h as usize {
                let dst = (y0 + label_h) as usize + y;
                let start = dst * sheet.stride + x0 as usize * 3;
                sheet.data[start..start + cell_w as usize * 3].copy_from_slice(small.view().row(y));
            }
        }
    }
    sheet
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cloud::{Cloud, PointLayout};

    #[test]
    fn text_is_drawn_where_asked() {
        let mut img = Image::new(40, 10, PixelFormat::Rgb8);
        draw_text(&mut img, 1, 1, "C-A1", 1, [255, 0, 0]);
        let lit = img.data.chunks_exact(3).filter(|p| p[0] == 255).count();
        assert!(lit > 20, "{lit}");
        assert_eq!(text_width("C-A1", 2), 48);
        // Nothing outside the 4 glyph cells.
        assert!(
            img.data
                .chunks_exact(3)
                .skip(30)
                .step_by(40)
                .all(|p| p[0] == 0 || p[0] == 255)
        );
    }

    #[test]
    fn bev_puts_points_and_boxes_in_the_right_place() {
        let c = Cloud::from_xyzi(
            &PointLayout::xyzi_f32(),
            &[[10.0, 0.0, 0.0, 0.5], [0.0, 10.0, 0.0, 0.5]],
        );
        let b = Box3 {
            center: [-10.0, 0.0, 0.0],
            size: [4.0, 2.0, 1.5],
            yaw: 0.0,
        };
        let img = bird_eye_view(&c.view(), 200, 20.0, ColorBy::Height, 1.0, &[b]);
        let px = |u: usize, v: usize| &img.data[v * 600 + u * 3..v * 600 + u * 3 + 3];
        assert_ne!(px(100, 50), [0, 0, 0], "x forward is up");
        assert_ne!(px(50, 100), [0, 0, 0], "y left is left");
        assert_eq!(px(95, 140), [255, 255, 255], "box corner drawn");
    }

    #[test]
    fn sheet_has_the_expected_size_and_is_not_blank() {
        let cell = |v: u8| Cell {
            image: Image::from_vec(vec![v; 40 * 30 * 3], 40, 30, 120, PixelFormat::Rgb8).unwrap(),
            label: "X".into(),
        };
        let sheet = contact_sheet("T", &[vec![cell(10), cell(200)], vec![cell(90)]], 80);
        assert_eq!(sheet.width, 2 * 84 + 4);
        assert_eq!(sheet.height, 24 + 2 * (60 + 14 + 4) + 4);
        assert!(sheet.data.contains(&200));
    }
}
