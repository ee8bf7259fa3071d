//! The trajectory map (paper, figure of the qualitative analysis): the route underneath, every
//! run's trajectory coloured by the perturbation family active on it, a marker where each run
//! failed (shape by failure type), and hotspot outlines (convex hull of a cluster's failures,
//! widened by a few pixels), with a legend.

use crate::analyze::{Failure, RunResult};
use crate::hotspots::{Hotspots, family_of};
use crate::route::Route;
use perturb_core::image::{Image, PixelFormat};
use perturb_core::viz::{draw_line, draw_text, put, text_width};
use std::collections::BTreeMap;

/// Colours of families, in order of first appearance (nominal is grey).
const PALETTE: [[u8; 3]; 10] = [
    [31, 119, 180],
    [255, 127, 14],
    [44, 160, 44],
    [214, 39, 40],
    [148, 103, 189],
    [140, 86, 75],
    [227, 119, 194],
    [188, 189, 34],
    [23, 190, 207],
    [0, 0, 0],
];
const GREY: [u8; 3] = [150, 150, 150];
const ROUTE: [u8; 3] = [215, 215, 215];

/// Maps world coordinates (x right, y up) into the picture.
struct View {
    min: [f64; 2],
    scale: f64,
    margin: f64,
    height: u32,
}

impl View {
    fn px(&self, p: [f64; 2]) -> (i32, i32) {
        let x = self.margin + (p[0] - self.min[0]) * self.scale;
        let y = self.height as f64 - self.margin - (p[1] - self.min[1]) * self.scale;
        (x.round() as i32, y.round() as i32)
    }
}

fn thick_line(img: &mut Image, a: (i32, i32), b: (i32, i32), w: i32, c: [u8; 3]) {
    for dx in -(w / 2)..=(w - 1) / 2 {
        for dy in -(w / 2)..=(w - 1) / 2 {
            draw_line(img, (a.0 + dx, a.1 + dy), (b.0 + dx, b.1 + dy), c);
        }
    }
}

fn disc(img: &mut Image, c: (i32, i32), r: i32, color: [u8; 3], blend: f32) {
    for dy in -r..=r {
        for dx in -r..=r {
            if dx * dx + dy * dy <= r * r {
                let (x, y) = (c.0 + dx, c.1 + dy);
                if x < 0 || y < 0 || x >= img.width as i32 || y >= img.height as i32 {
                    continue;
                }
                let i = y as usize * img.stride + x as usize * 3;
                for (k, c) in color.iter().enumerate() {
                    let old = img.data[i + k] as f32;
                    img.data[i + k] = (old + (*c as f32 - old) * blend).round() as u8;
                }
            }
        }
    }
}

/// A marker per failure type: collision a filled square, departures triangles, takeover a
/// cross, erratic start a diamond, timeout/incomplete a ring.
fn marker(img: &mut Image, c: (i32, i32), f: Failure, r: i32, faint: bool) {
    let col = if faint { [120, 120, 120] } else { [0, 0, 0] };
    let blend = if faint { 0.45 } else { 1.0 };
    match f {
        Failure::Collision => {
            for dy in -r..=r {
                for dx in -r..=r {
                    if faint {
                        disc(img, (c.0 + dx, c.1 + dy), 0, col, blend);
                    } else {
                        put(img, c.0 + dx, c.1 + dy, col);
                    }
                }
            }
        }
        Failure::Understeer | Failure::Oversteer | Failure::RoadDeparture => {
            let up = !matches!(f, Failure::Oversteer);
            for k in 0..=2 * r {
                let half = k / 2;
                let y = if up { c.1 - r + k } else { c.1 + r - k };
                for dx in -half..=half {
                    disc(img, (c.0 + dx, y), 0, col, blend);
                }
            }
            if f == Failure::RoadDeparture {
                disc(img, c, r / 3, [255, 255, 255], 1.0);
            }
        }
        Failure::Takeover => {
            thick_line(img, (c.0 - r, c.1 - r), (c.0 + r, c.1 + r), 2, col);
            thick_line(img, (c.0 - r, c.1 + r), (c.0 + r, c.1 - r), 2, col);
        }
        Failure::ErraticStart => {
            for dy in -r..=r {
                let w = r - dy.abs();
                for dx in -w..=w {
                    disc(img, (c.0 + dx, c.1 + dy), 0, col, blend);
                }
            }
        }
        Failure::Timeout | Failure::Incomplete => {
            disc(img, c, r, col, blend);
            disc(img, c, (r - 2).max(1), [255, 255, 255], 1.0);
        }
    }
}

/// Convex hull (monotone chain), counter-clockwise.
fn hull(mut pts: Vec<(i32, i32)>) -> Vec<(i32, i32)> {
    pts.sort();
    pts.dedup();
    if pts.len() < 3 {
        return pts;
    }
    let cross = |o: (i32, i32), a: (i32, i32), b: (i32, i32)| {
        (a.0 - o.0) as i64 * (b.1 - o.1) as i64 - (a.1 - o.1) as i64 * (b.0 - o.0) as i64
    };
    let mut lower: Vec<(i32, i32)> = Vec::new();
    for &p in &pts {
        while lower.len() >= 2 && cross(lower[lower.len() - 2], lower[lower.len() - 1], p) <= 0 {
            lower.pop();
        }
        lower.push(p);
    }
    let mut upper: Vec<(i32, i32)> = Vec::new();
    for &p in pts.iter().rev() {
        while upper.len() >= 2 && cross(upper[upper.len() - 2], upper[upper.len() - 1], p) <= 0 {
            upper.pop();
        }
        upper.push(p);
    }
    lower.pop();
    upper.pop();
    lower.extend(upper);
    lower
}

/// The outline of a set of pixel positions: their convex hull grown by `pad` pixels (a circle
/// for one point).
fn outline(img: &mut Image, pts: &[(i32, i32)], pad: i32, color: [u8; 3]) {
    let mut grown = Vec::new();
    for &(x, y) in pts {
        for k in 0..16 {
            let a = k as f64 * std::f64::consts::TAU / 16.0;
            grown.push((
                x + (pad as f64 * a.cos()).round() as i32,
                y + (pad as f64 * a.sin()).round() as i32,
            ));
        }
    }
    let h = hull(grown);
    for i in 0..h.len() {
        thick_line(img, h[i], h[(i + 1) % h.len()], 2, color);
    }
}

/// What the map shows.
#[derive(Clone, Debug)]
pub struct MapOptions {
    /// Picture width in pixels (the height follows the extent, at most twice the width).
    pub width: u32,
    /// Title at the top.
    pub title: String,
}

impl Default for MapOptions {
    fn default() -> Self {
        MapOptions {
            width: 1200,
            title: "trajectories by perturbation family, failures and hotspots".into(),
        }
    }
}

/// Draws the map. Returns None when there is nothing to draw (no route and no trajectory).
pub fn trajectory_map(
    route: Option<&Route>,
    runs: &[RunResult],
    hotspots: &Hotspots,
    opts: &MapOptions,
) -> Option<Image> {
    let mut all: Vec<[f64; 2]> = route.map(|r| r.points.clone()).unwrap_or_default();
    all.extend(
        runs.iter()
            .flat_map(|r| r.trajectory.iter().map(|(p, _)| *p)),
    );
    if all.is_empty() {
        return None;
    }
    let (mut min, mut max) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
    for p in &all {
        for k in 0..2 {
            min[k] = min[k].min(p[k]);
            max[k] = max[k].max(p[k]);
        }
    }
    let span = [(max[0] - min[0]).max(1.0), (max[1] - min[1]).max(1.0)];
    let margin = 30.0;
    let width = opts.width.max(200);
    let scale = (width as f64 - 2.0 * margin) / span[0];
    let scale = scale.min((2.0 * width as f64 - 2.0 * margin) / span[1]);
    let height = (span[1] * scale + 2.0 * margin + LEGEND_H).ceil() as u32;
    let mut img = Image::new(width, height, PixelFormat::Rgb8);
    img.data.fill(255);
    let view = View {
        min,
        scale,
        margin,
        height: height - LEGEND_H as u32,
    };
    let mut colours = FamilyColours::default();
    if let Some(r) = route {
        for w in r.points.windows(2) {
            thick_line(&mut img, view.px(w[0]), view.px(w[1]), 7, ROUTE);
        }
    }
    for run in runs {
        for w in run.trajectory.windows(2) {
            let c = colours.of(&w[1].1.label());
            thick_line(&mut img, view.px(w[0].0), view.px(w[1].0), 2, c);
        }
    }
    draw_hotspots(&mut img, &view, hotspots);
    draw_legend(&mut img, opts, hotspots, &colours);
    Some(img)
}

/// Height of the legend below the map, pixels.
const LEGEND_H: f64 = 120.0;

/// A colour per perturbation family, in order of appearance; nominal is grey.
#[derive(Default)]
struct FamilyColours {
    colours: BTreeMap<String, [u8; 3]>,
    order: Vec<String>,
}

impl FamilyColours {
    /// The colour of the family of condition `label`.
    fn of(&mut self, label: &str) -> [u8; 3] {
        let fam = family_of(label);
        if fam == "nominal" {
            return GREY;
        }
        if !self.colours.contains_key(&fam) {
            let c = PALETTE[self.order.len() % PALETTE.len()];
            self.colours.insert(fam.clone(), c);
            self.order.push(fam.clone());
        }
        self.colours[&fam]
    }
}

/// The hotspots' outlines and names, and a marker per failure (grey when in no hotspot).
fn draw_hotspots(img: &mut Image, view: &View, hotspots: &Hotspots) {
    for (i, c) in hotspots.clusters.iter().enumerate() {
        let pts: Vec<(i32, i32)> = hotspots
            .failures
            .iter()
            .filter(|f| f.cluster == Some(i))
            .map(|f| view.px(f.position))
            .collect();
        outline(img, &pts, 12, [200, 0, 0]);
        let (x, y) = view.px(c.centre);
        draw_text(img, x + 14, y - 18, &format!("H{i}"), 2, [200, 0, 0]);
    }
    for f in &hotspots.failures {
        marker(img, view.px(f.position), f.failure, 5, f.cluster.is_none());
    }
}

/// The title, then below the map: the families' colours, the failure markers and how the
/// hotspots were found.
fn draw_legend(img: &mut Image, opts: &MapOptions, hotspots: &Hotspots, colours: &FamilyColours) {
    let (width, height) = (img.width, img.height);
    let mut y = (height - LEGEND_H as u32 + 10) as i32;
    draw_text(img, 10, 6, &opts.title, 2, [0, 0, 0]);
    let mut x = 10;
    let mut entries: Vec<(String, [u8; 3])> = vec![("nominal".into(), GREY)];
    entries.extend(
        colours
            .order
            .iter()
            .map(|f| (f.clone(), colours.colours[f])),
    );
    for (name, c) in entries {
        let w = text_width(&name, 1) as i32 + 30;
        if x + w > width as i32 - 10 {
            x = 10;
            y += 14;
        }
        thick_line(img, (x, y + 3), (x + 16, y + 3), 3, c);
        draw_text(img, x + 20, y, &name, 1, [0, 0, 0]);
        x += w;
    }
    y += 22;
    x = 10;
    for f in [
        Failure::Collision,
        Failure::Understeer,
        Failure::Oversteer,
        Failure::RoadDeparture,
        Failure::ErraticStart,
        Failure::Takeover,
        Failure::Timeout,
    ] {
        let name = f.name();
        marker(img, (x + 5, y + 3), f, 5, false);
        draw_text(img, x + 14, y, name, 1, [0, 0, 0]);
        x += text_width(name, 1) as i32 + 30;
    }
    y += 18;
    draw_text(
        img,
        10,
        y,
        &format!(
            "grey markers: failures in no hotspot, red outlines: hotspots (dbscan eps {} m, {} points)",
            hotspots.eps_m, hotspots.min_points
        ),
        1,
        [0, 0, 0],
    );
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hull_of_a_square_with_an_inner_point() {
        let h = hull(vec![(0, 0), (10, 0), (10, 10), (0, 10), (5, 5)]);
        assert_eq!(h.len(), 4);
        assert!(!h.contains(&(5, 5)));
    }
}
