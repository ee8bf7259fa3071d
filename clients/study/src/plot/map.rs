//! The trajectory map (paper, qualitative analysis): the route (and the reference region of
//! nominal drives) underneath, every run's trajectory up to its failure coloured by the family of
//! the perturbation active on it, a marker where each run failed (its shape by failure type;
//! semi-transparent when the failure is in no hotspot), and a red outline per hotspot labelled
//! `H0`, `H1`, ... Axes in metres (x and y at the same scale), a scale bar and a legend beside
//! the map.

use super::labels::{LabelPlacer, Rect, text_width};
use super::{NOMINAL, nice_length, plot_err, series_colour};
use crate::analyze::{Failure, ReferenceRegion, RunResult};
use crate::hotspots::{Hotspots, family_of};
use crate::route::Route;
use plotters::coord::Shift;
use plotters::prelude::*;
use std::collections::BTreeMap;

/// What the map shows.
#[derive(Clone, Debug)]
pub struct MapOptions {
    /// Picture width in pixels, legend included (the height follows the extent).
    pub width: u32,
    /// Title at the top.
    pub title: String,
}

impl Default for MapOptions {
    fn default() -> Self {
        MapOptions {
            width: 1200,
            title: "Trajectories by perturbation family, failures and hotspots".into(),
        }
    }
}

const ROUTE: RGBColor = RGBColor(205, 205, 205);
const BAND: RGBColor = RGBColor(120, 170, 220);
const HOT: RGBColor = RGBColor(200, 0, 0);
const INK: RGBColor = RGBColor(30, 30, 30);
const LEGEND_W: u32 = 270;
const TITLE_H: u32 = 34;
const MARGIN: u32 = 12;
const Y_LABELS: u32 = 64;
const X_LABELS: u32 = 46;
/// Marker radius, pixels.
const R: i32 = 6;

type Area<'a> = DrawingArea<SVGBackend<'a>, Shift>;

/// The failure types in legend order.
const FAILURES: [Failure; 8] = [
    Failure::Collision,
    Failure::Understeer,
    Failure::Oversteer,
    Failure::RoadDeparture,
    Failure::ErraticStart,
    Failure::Takeover,
    Failure::Timeout,
    Failure::Incomplete,
];

/// Draws one failure marker centred on (x, y) pixels: filled square (collision), triangle up
/// (understeer), triangle down (oversteer), hollow triangle (road departure), diamond
/// (erratic start), cross (takeover), ring (timeout, incomplete). Dark with a white halo for a
/// failure in a hotspot; semi-transparent grey with a dark outline for noise, so it stays
/// visible on the grey route.
fn marker(area: &Area<'_>, (x, y): (i32, i32), f: Failure, noise: bool) -> crate::Result<()> {
    let err = plot_err("the map's markers");
    let fill: RGBAColor = if noise {
        RGBColor(110, 110, 110).mix(0.5)
    } else {
        INK.to_rgba()
    };
    let halo = WHITE.stroke_width(if noise { 1 } else { 3 });
    let edge = INK.stroke_width(1);
    let r = R;
    let poly = |pts: Vec<(i32, i32)>, hollow: bool| -> crate::Result<()> {
        let abs: Vec<(i32, i32)> = pts.iter().map(|(dx, dy)| (x + dx, y + dy)).collect();
        let mut closed = abs.clone();
        closed.push(abs[0]);
        area.draw(&PathElement::new(closed.clone(), halo))
            .map_err(plot_err("the map's markers"))?;
        let body = if hollow {
            WHITE.filled()
        } else {
            fill.filled()
        };
        area.draw(&Polygon::new(abs, body))
            .map_err(plot_err("the map's markers"))?;
        area.draw(&PathElement::new(
            closed,
            if hollow { INK.stroke_width(2) } else { edge },
        ))
        .map_err(plot_err("the map's markers"))
    };
    match f {
        Failure::Collision => poly(vec![(-r, -r), (r, -r), (r, r), (-r, r)], false),
        Failure::Understeer => poly(vec![(0, -r - 1), (r + 1, r), (-r - 1, r)], false),
        Failure::Oversteer => poly(vec![(0, r + 1), (r + 1, -r), (-r - 1, -r)], false),
        Failure::RoadDeparture => poly(vec![(0, -r - 1), (r + 1, r), (-r - 1, r)], true),
        Failure::ErraticStart => poly(
            vec![(0, -r - 2), (r + 2, 0), (0, r + 2), (-r - 2, 0)],
            false,
        ),
        Failure::Takeover => {
            for (a, b) in [((-r, -r), (r, r)), ((-r, r), (r, -r))] {
                let seg = vec![(x + a.0, y + a.1), (x + b.0, y + b.1)];
                area.draw(&PathElement::new(seg.clone(), WHITE.stroke_width(5)))
                    .map_err(plot_err("the map's markers"))?;
                area.draw(&PathElement::new(
                    seg,
                    fill.stroke_width(if noise { 2 } else { 3 }),
                ))
                .map_err(plot_err("the map's markers"))?;
            }
            Ok(())
        }
        Failure::Timeout | Failure::Incomplete => {
            area.draw(&Circle::new((x, y), r + 1, WHITE.stroke_width(4)))
                .map_err(plot_err("the map's markers"))?;
            area.draw(&Circle::new(
                (x, y),
                r,
                fill.stroke_width(if noise { 2 } else { 3 }),
            ))
            .map_err(err)
        }
    }
}

/// Convex hull (monotone chain) of pixel points, counter-clockwise.
fn hull(mut pts: Vec<(f64, f64)>) -> Vec<(f64, f64)> {
    pts.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.total_cmp(&b.1)));
    pts.dedup();
    if pts.len() < 3 {
        return pts;
    }
    let cross = |o: (f64, f64), a: (f64, f64), b: (f64, f64)| {
        (a.0 - o.0) * (b.1 - o.1) - (a.1 - o.1) * (b.0 - o.0)
    };
    let half = |iter: &mut dyn Iterator<Item = (f64, f64)>| {
        let mut h: Vec<(f64, f64)> = Vec::new();
        for p in iter {
            while h.len() >= 2 && cross(h[h.len() - 2], h[h.len() - 1], p) <= 0.0 {
                h.pop();
            }
            h.push(p);
        }
        h.pop();
        h
    };
    let mut lower = half(&mut pts.iter().copied());
    let upper = half(&mut pts.iter().rev().copied());
    lower.extend(upper);
    lower
}

/// A colour per perturbation family, in order of first appearance; nominal is grey.
#[derive(Default)]
struct FamilyColours {
    order: Vec<String>,
    colours: BTreeMap<String, RGBColor>,
}

impl FamilyColours {
    fn of(&mut self, label: &str) -> RGBColor {
        let fam = family_of(label);
        if fam == "nominal" {
            return NOMINAL;
        }
        if let Some(c) = self.colours.get(&fam) {
            return *c;
        }
        let c = series_colour(self.order.len());
        self.colours.insert(fam.clone(), c);
        self.order.push(fam);
        c
    }
}

/// Points at least `min` apart (the first and last kept): a trajectory at 100 Hz need not be
/// drawn point by point.
fn thin(points: &[([f64; 2], String)], min: f64) -> Vec<([f64; 2], String)> {
    let mut out: Vec<([f64; 2], String)> = Vec::new();
    for (i, (p, c)) in points.iter().enumerate() {
        let keep = match out.last() {
            None => true,
            Some((q, qc)) => {
                qc != c || i + 1 == points.len() || (p[0] - q[0]).hypot(p[1] - q[1]) >= min
            }
        };
        if keep {
            out.push((*p, c.clone()));
        }
    }
    out
}

/// Draws the map as an SVG document. None when there is nothing to draw (no route and no
/// trajectory).
pub fn trajectory_map(
    route: Option<&Route>,
    region: Option<&ReferenceRegion>,
    runs: &[RunResult],
    hotspots: &Hotspots,
    opts: &MapOptions,
) -> crate::Result<Option<String>> {
    let band = match (route, region) {
        (Some(r), Some(g)) => Some(g.edges(r)),
        _ => None,
    };
    let mut all: Vec<[f64; 2]> = route.map(|r| r.points.clone()).unwrap_or_default();
    all.extend(
        runs.iter()
            .flat_map(|r| r.trajectory.iter().map(|(p, _)| *p)),
    );
    all.extend(hotspots.failures.iter().map(|f| f.position));
    if let Some((l, r)) = &band {
        all.extend(l.iter().chain(r.iter()));
    }
    if all.is_empty() {
        return Ok(None);
    }
    let (mut min, mut max) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
    for p in &all {
        for k in 0..2 {
            min[k] = min[k].min(p[k]);
            max[k] = max[k].max(p[k]);
        }
    }
    // Room around the data, and at least 20 m of extent.
    for k in 0..2 {
        let pad = ((max[k] - min[k]) * 0.05).max(5.0);
        let mid = (max[k] + min[k]) / 2.0;
        let half = ((max[k] - min[k]) / 2.0 + pad).max(10.0);
        min[k] = mid - half;
        max[k] = mid + half;
    }
    let width = opts.width.max(500);
    let map_w = width - LEGEND_W;
    let plot_w = (map_w - 2 * MARGIN - Y_LABELS) as f64;
    let mut scale = plot_w / (max[0] - min[0]); // pixels per metre
    let mut plot_h = (max[1] - min[1]) * scale;
    if plot_h > 1.5 * plot_w {
        plot_h = 1.5 * plot_w;
        scale = plot_h / (max[1] - min[1]);
    }
    let legend_h = 120.0 + 20.0 * (FAILURES.len() as f64 + 12.0);
    plot_h = plot_h.max(0.35 * plot_w).max(legend_h);
    // Same metres per pixel on both axes: widen the shorter extent.
    for (k, px) in [(0usize, plot_w), (1, plot_h)] {
        let need = px / scale;
        let mid = (max[k] + min[k]) / 2.0;
        min[k] = mid - need / 2.0;
        max[k] = mid + need / 2.0;
    }
    let height = (plot_h.ceil() as u32) + 2 * MARGIN + X_LABELS + TITLE_H;
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (width, height)).into_drawing_area();
        let e = plot_err("the trajectory map");
        root.fill(&WHITE).map_err(plot_err("the trajectory map"))?;
        root.draw(&Text::new(
            opts.title.clone(),
            (MARGIN as i32, 8),
            ("sans-serif", 24).into_font().color(&INK),
        ))
        .map_err(plot_err("the trajectory map"))?;
        let body = root.margin(TITLE_H, 0, 0, 0);
        let (map_area, legend_area) = body.split_horizontally(map_w);
        let mut chart = ChartBuilder::on(&map_area)
            .margin(MARGIN)
            .x_label_area_size(X_LABELS)
            .y_label_area_size(Y_LABELS)
            .build_cartesian_2d(min[0]..max[0], min[1]..max[1])
            .map_err(plot_err("the trajectory map"))?;
        chart
            .configure_mesh()
            .x_desc("x (m)")
            .y_desc("y (m)")
            .label_style(("sans-serif", 16))
            .axis_desc_style(("sans-serif", 17))
            .max_light_lines(1)
            .light_line_style(RGBColor(246, 246, 246))
            .bold_line_style(RGBColor(226, 226, 226))
            .x_label_formatter(&|v| format!("{v:.0}"))
            .y_label_formatter(&|v| format!("{v:.0}"))
            .draw()
            .map_err(plot_err("the trajectory map"))?;
        let xy = |p: &[f64; 2]| (p[0], p[1]);
        if let Some((left, right)) = &band {
            let mut ring: Vec<(f64, f64)> = left.iter().map(xy).collect();
            ring.extend(right.iter().rev().map(xy));
            chart
                .draw_series(std::iter::once(Polygon::new(ring, BAND.mix(0.35).filled())))
                .map_err(plot_err("the trajectory map"))?;
        }
        if let Some(r) = route {
            chart
                .draw_series(std::iter::once(PathElement::new(
                    r.points.iter().map(xy).collect::<Vec<_>>(),
                    ROUTE.stroke_width(7),
                )))
                .map_err(plot_err("the trajectory map"))?;
        }
        let mut colours = FamilyColours::default();
        for run in runs {
            let labelled: Vec<([f64; 2], String)> = run
                .trajectory
                .iter()
                .map(|(p, c)| (*p, c.label()))
                .collect();
            let pts = thin(&labelled, 1.0 / scale);
            // One polyline per stretch of constant condition.
            let mut k = 0;
            while k + 1 < pts.len() {
                let label = pts[k + 1].1.clone();
                let mut line = vec![xy(&pts[k].0)];
                while k + 1 < pts.len() && pts[k + 1].1 == label {
                    k += 1;
                    line.push(xy(&pts[k].0));
                }
                let c = colours.of(&label);
                chart
                    .draw_series(std::iter::once(PathElement::new(line, c.stroke_width(2))))
                    .map_err(plot_err("the trajectory map"))?;
            }
        }
        // Overlays in pixels: hotspot outlines, markers, labels.
        let px = |p: [f64; 2]| {
            let (x, y) = chart.backend_coord(&(p[0], p[1]));
            (x as f64, y as f64)
        };
        let (ox, oy) = map_area.get_base_pixel();
        let plot_box = {
            let (x0, y0) = px([min[0], max[1]]);
            let (x1, y1) = px([max[0], min[1]]);
            Rect {
                x: x0,
                y: y0,
                w: x1 - x0,
                h: y1 - y0,
            }
        };
        let mut placer = LabelPlacer::new(plot_box);
        for f in &hotspots.failures {
            let (x, y) = px(f.position);
            placer.block(Rect::centred(
                x,
                y,
                2.0 * R as f64 + 4.0,
                2.0 * R as f64 + 4.0,
            ));
        }
        let to_root = |(x, y): (f64, f64)| ((x - ox as f64) as i32, (y - oy as f64) as i32);
        let pad = 14.0;
        let mut outlines = Vec::new();
        for (i, _) in hotspots.clusters.iter().enumerate() {
            let mut grown = Vec::new();
            for f in hotspots.failures.iter().filter(|f| f.cluster == Some(i)) {
                let (x, y) = px(f.position);
                for k in 0..16 {
                    let a = k as f64 * std::f64::consts::TAU / 16.0;
                    grown.push((x + pad * a.cos(), y + pad * a.sin()));
                }
            }
            let h = hull(grown);
            if h.is_empty() {
                continue;
            }
            let mut ring: Vec<(i32, i32)> = h.iter().map(|p| to_root(*p)).collect();
            ring.push(ring[0]);
            map_area
                .draw(&PathElement::new(ring, HOT.stroke_width(2)))
                .map_err(plot_err("the trajectory map"))?;
            outlines.push((i, h));
        }
        for f in &hotspots.failures {
            let (x, y) = px(f.position);
            marker(&map_area, to_root((x, y)), f.failure, f.cluster.is_none())?;
        }
        for (i, h) in &outlines {
            let name = format!("H{i}");
            let (w, ht) = (text_width(&name, 15.5) + 8.0, 21.0);
            let (cx, cy) = (
                h.iter().map(|p| p.0).sum::<f64>() / h.len() as f64,
                h.iter().map(|p| p.1).sum::<f64>() / h.len() as f64,
            );
            let reach = h
                .iter()
                .map(|p| (p.0 - cx).hypot(p.1 - cy))
                .fold(0.0, f64::max);
            let Some(r) = placer.place(cx, cy, w, ht, reach + 4.0) else {
                continue;
            };
            let (lx, ly) = r.centre();
            // A leader line from the outline to a label placed away from it.
            let near = h
                .iter()
                .copied()
                .min_by(|a, b| {
                    (a.0 - lx)
                        .hypot(a.1 - ly)
                        .total_cmp(&(b.0 - lx).hypot(b.1 - ly))
                })
                .expect("a hull point");
            map_area
                .draw(&PathElement::new(
                    vec![to_root(near), to_root((lx, ly))],
                    HOT.stroke_width(1),
                ))
                .map_err(plot_err("the trajectory map"))?;
            map_area
                .draw(&Rectangle::new(
                    [to_root((r.x, r.y)), to_root((r.x + r.w, r.y + r.h))],
                    WHITE.mix(0.92).filled(),
                ))
                .map_err(plot_err("the trajectory map"))?;
            map_area
                .draw(&Rectangle::new(
                    [to_root((r.x, r.y)), to_root((r.x + r.w, r.y + r.h))],
                    HOT.stroke_width(1),
                ))
                .map_err(plot_err("the trajectory map"))?;
            map_area
                .draw(&Text::new(
                    name,
                    to_root((r.x + 4.0, r.y + 2.0)),
                    ("sans-serif", 19).into_font().color(&HOT),
                ))
                .map_err(plot_err("the trajectory map"))?;
        }
        legend(&legend_area, &colours, hotspots, scale, band.is_some())?;
        root.present().map_err(e)?;
    }
    Ok(Some(svg))
}

/// The legend beside the map: route and reference band, the families' colours, the failure
/// markers, hotspots and noise, and the scale bar.
fn legend(
    area: &Area<'_>,
    colours: &FamilyColours,
    hotspots: &Hotspots,
    scale: f64,
    band: bool,
) -> crate::Result<()> {
    let e = || plot_err("the map's legend");
    let font = ("sans-serif", 16).into_font().color(&INK);
    let head = ("sans-serif", 18).into_font().color(&INK);
    let (x0, mut y) = (14, MARGIN as i32 + 4);
    let line = |y: i32, c: RGBAColor, w: u32| {
        area.draw(&PathElement::new(
            vec![(x0, y + 7), (x0 + 26, y + 7)],
            c.stroke_width(w),
        ))
    };
    area.draw(&Text::new("Legend", (x0, y), head.clone()))
        .map_err(e())?;
    y += 22;
    line(y, ROUTE.to_rgba(), 7).map_err(e())?;
    area.draw(&Text::new("route", (x0 + 34, y), font.clone()))
        .map_err(e())?;
    y += 20;
    if band {
        area.draw(&Rectangle::new(
            [(x0, y + 1), (x0 + 26, y + 13)],
            BAND.mix(0.35).filled(),
        ))
        .map_err(e())?;
        area.draw(&Text::new(
            "reference region (nominal drives)",
            (x0 + 34, y),
            font.clone(),
        ))
        .map_err(e())?;
        y += 20;
    }
    let mut fams: Vec<(String, RGBColor)> = vec![("nominal".into(), NOMINAL)];
    fams.extend(
        colours
            .order
            .iter()
            .map(|f| (f.clone(), colours.colours[f])),
    );
    for (name, c) in fams {
        line(y, c.to_rgba(), 3).map_err(e())?;
        area.draw(&Text::new(name, (x0 + 34, y), font.clone()))
            .map_err(e())?;
        y += 20;
    }
    y += 8;
    area.draw(&Text::new("Failures", (x0, y), head.clone()))
        .map_err(e())?;
    y += 22;
    for f in FAILURES {
        marker(area, (x0 + 12, y + 7), f, false)?;
        area.draw(&Text::new(
            format!("{} ({})", f.name().replace('_', " "), f.letter()),
            (x0 + 34, y),
            font.clone(),
        ))
        .map_err(e())?;
        y += 20;
    }
    marker(area, (x0 + 12, y + 7), Failure::Collision, true)?;
    area.draw(&Text::new(
        "in no hotspot (noise)",
        (x0 + 34, y),
        font.clone(),
    ))
    .map_err(e())?;
    y += 20;
    area.draw(&Rectangle::new(
        [(x0 + 2, y + 1), (x0 + 24, y + 13)],
        HOT.stroke_width(2),
    ))
    .map_err(e())?;
    area.draw(&Text::new(
        format!(
            "hotspot (DBSCAN {} m, {} pts)",
            hotspots.eps_m, hotspots.min_points
        ),
        (x0 + 34, y),
        font.clone(),
    ))
    .map_err(e())?;
    y += 30;
    // Scale bar: a round length of about 120 pixels.
    let metres = nice_length(150.0 / scale);
    let len = (metres * scale).round() as i32;
    area.draw(&Text::new("Scale", (x0, y), head)).map_err(e())?;
    y += 24;
    for seg in [
        vec![(x0, y), (x0 + len, y)],
        vec![(x0, y - 5), (x0, y + 5)],
        vec![(x0 + len, y - 5), (x0 + len, y + 5)],
    ] {
        area.draw(&PathElement::new(seg, INK.stroke_width(2)))
            .map_err(e())?;
    }
    area.draw(&Text::new(
        format!("{} m", fmt_metres(metres)),
        (x0 + len + 8, y - 8),
        font,
    ))
    .map_err(e())?;
    Ok(())
}

fn fmt_metres(m: f64) -> String {
    if m >= 1.0 {
        format!("{m:.0}")
    } else {
        format!("{m}")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hull_of_a_square_with_an_inner_point() {
        let h = hull(vec![
            (0.0, 0.0),
            (10.0, 0.0),
            (10.0, 10.0),
            (0.0, 10.0),
            (5.0, 5.0),
        ]);
        assert_eq!(h.len(), 4);
        assert!(!h.contains(&(5.0, 5.0)));
    }
}
