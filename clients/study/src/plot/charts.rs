//! The report's charts, each an SVG document: latency per perturbation against the real-time
//! budget, the offline metrics per severity (one panel per family, a line per perturbation),
//! transfer scatter plots, and the small trend and completion bars of the paper's tables.

use super::labels::{LabelPlacer, Rect, text_width};
use super::{FAIL_RED, OK_GREEN, UNJUDGED_GREY, plot_err, series_colour};
use crate::analyze::Outcome;
use plotters::prelude::*;

const INK: RGBColor = RGBColor(30, 30, 30);

/// One perturbation's latency: mean over its severities of the mean per-frame latency, and the
/// largest per-frame latency at any severity, milliseconds.
#[derive(Clone, Debug, PartialEq)]
pub struct LatencyBar {
    /// Perturbation ID.
    pub id: String,
    /// Average latency, ms.
    pub avg_ms: f64,
    /// Maximum latency, ms.
    pub max_ms: f64,
}

/// Horizontal bars of average latency (a tick at the maximum) per perturbation on a log axis,
/// with the budget as a red line; bars over the budget in red.
pub fn latency_bars(title: &str, rows: &[LatencyBar], budget_ms: f64) -> crate::Result<String> {
    let e = || plot_err("the latency chart");
    let n = rows.len().max(1);
    let (w, h) = (760u32, (80 + 20 * n as u32).max(150));
    let lo = rows
        .iter()
        .map(|r| r.avg_ms.min(r.max_ms))
        .filter(|v| *v > 0.0)
        .fold(budget_ms, f64::min)
        .max(1e-3)
        / 2.0;
    let hi = rows.iter().map(|r| r.max_ms).fold(budget_ms, f64::max) * 2.0;
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (w, h)).into_drawing_area();
        root.fill(&WHITE).map_err(e())?;
        let mut chart = ChartBuilder::on(&root)
            .caption(title, ("sans-serif", 16))
            .margin(8)
            .x_label_area_size(38)
            .y_label_area_size(70)
            .build_cartesian_2d((lo..hi).log_scale(), 0f64..n as f64)
            .map_err(e())?;
        let ids: Vec<String> = rows.iter().map(|r| r.id.clone()).collect();
        let ylab = move |v: &f64| {
            let k = v.floor() as usize;
            if (v - k as f64 - 0.5).abs() < 0.26 {
                ids.get(n - 1 - k.min(n - 1)).cloned().unwrap_or_default()
            } else {
                String::new()
            }
        };
        chart
            .configure_mesh()
            .x_desc("latency per frame (ms, log scale)")
            .y_labels(2 * n + 1)
            .y_label_formatter(&ylab)
            .x_label_formatter(&|v| format!("{v}"))
            .disable_y_mesh()
            .label_style(("sans-serif", 13))
            .axis_desc_style(("sans-serif", 14))
            .draw()
            .map_err(e())?;
        for (i, r) in rows.iter().enumerate() {
            let y = (n - 1 - i) as f64;
            let over = r.avg_ms > budget_ms;
            let c = if over {
                FAIL_RED
            } else {
                RGBColor(70, 120, 180)
            };
            chart
                .draw_series(std::iter::once(Rectangle::new(
                    [(lo, y + 0.15), (r.avg_ms.max(lo), y + 0.85)],
                    c.filled(),
                )))
                .map_err(e())?;
            chart
                .draw_series(std::iter::once(PathElement::new(
                    vec![(r.max_ms.max(lo), y + 0.05), (r.max_ms.max(lo), y + 0.95)],
                    INK.stroke_width(2),
                )))
                .map_err(e())?;
        }
        chart
            .draw_series(std::iter::once(PathElement::new(
                vec![(budget_ms, 0.0), (budget_ms, n as f64)],
                FAIL_RED.stroke_width(2),
            )))
            .map_err(e())?;
        root.present().map_err(e())?;
    }
    Ok(svg)
}

/// One line of a severity-curves panel: a perturbation's metric at each severity.
#[derive(Clone, Debug, PartialEq)]
pub struct Curve {
    /// Perturbation ID (the legend).
    pub id: String,
    /// (severity, value), in severity order.
    pub points: Vec<(u8, f64)>,
}

/// One panel per family, a line with markers per perturbation: `metric` against severity.
pub fn severity_curves(metric: &str, panels: &[(String, Vec<Curve>)]) -> crate::Result<String> {
    let e = || plot_err("the severity curves");
    let cols = 3usize;
    let rows = panels.len().div_ceil(cols).max(1);
    let (pw, ph) = (330u32, 260u32);
    let (w, h) = (pw * cols as u32, ph * rows as u32);
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (w, h)).into_drawing_area();
        root.fill(&WHITE).map_err(e())?;
        let areas = root.split_evenly((rows, cols));
        for ((family, curves), area) in panels.iter().zip(areas.iter()) {
            let max_sev = curves
                .iter()
                .flat_map(|c| c.points.iter().map(|p| p.0))
                .max()
                .unwrap_or(5)
                .max(2);
            let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
            for c in curves {
                for p in &c.points {
                    lo = lo.min(p.1);
                    hi = hi.max(p.1);
                }
            }
            if !lo.is_finite() {
                (lo, hi) = (0.0, 1.0);
            }
            let pad = ((hi - lo) * 0.08).max(1e-6);
            let (lo, hi) = (lo.min(0.0).min(lo - pad), hi + pad);
            let mut chart = ChartBuilder::on(area)
                .caption(family, ("sans-serif", 17))
                .margin(6)
                .margin_right(40)
                .x_label_area_size(34)
                .y_label_area_size(58)
                .build_cartesian_2d(0.7f64..max_sev as f64 + 0.3, lo..hi)
                .map_err(e())?;
            chart
                .configure_mesh()
                .x_desc("severity")
                .y_desc(metric)
                .x_labels(max_sev as usize)
                .x_label_formatter(&|v| format!("{v:.0}"))
                .label_style(("sans-serif", 13))
                .axis_desc_style(("sans-serif", 14))
                .max_light_lines(1)
                .light_line_style(RGBColor(244, 244, 244))
                .draw()
                .map_err(e())?;
            let mut ends = Vec::new();
            for (k, c) in curves.iter().enumerate() {
                let col = series_colour(k);
                let pts: Vec<(f64, f64)> = c.points.iter().map(|p| (p.0 as f64, p.1)).collect();
                chart
                    .draw_series(LineSeries::new(pts.clone(), col.stroke_width(2)))
                    .map_err(e())?;
                chart
                    .draw_series(pts.iter().map(|p| Circle::new(*p, 3, col.filled())))
                    .map_err(e())?;
                if let Some(last) = pts.last() {
                    ends.push((chart.backend_coord(last), c.id.clone(), col));
                }
            }
            // Each line labelled at its last point, the labels kept apart.
            let (ox, oy) = area.get_base_pixel();
            let (aw, ah) = area.dim_in_pixel();
            let mut placer = LabelPlacer::new(Rect {
                x: ox as f64,
                y: oy as f64 + 18.0,
                w: aw as f64,
                h: ah as f64 - 48.0,
            });
            for ((x, y), _, _) in &ends {
                placer.block(Rect::centred(*x as f64, *y as f64, 8.0, 8.0));
            }
            for ((x, y), id, col) in ends {
                let w = text_width(&id, 12.0) + 4.0;
                if let Some(r) = placer.place(x as f64, y as f64, w, 15.0, 4.0) {
                    area.draw(&Text::new(
                        id,
                        ((r.x - ox as f64) as i32 + 2, (r.y - oy as f64) as i32 + 1),
                        ("sans-serif", 15).into_font().color(&col),
                    ))
                    .map_err(e())?;
                }
            }
        }
        root.present().map_err(e())?;
    }
    Ok(svg)
}

/// One point of a transfer scatter plot.
#[derive(Clone, Debug, PartialEq)]
pub struct ScatterPoint {
    /// Offline value.
    pub x: f64,
    /// Closed-loop value.
    pub y: f64,
    /// Among the top-k of the offline ranking.
    pub top_offline: bool,
    /// Among the top-k of the closed-loop ranking.
    pub top_closed_loop: bool,
}

/// A scatter plot of matched (perturbation, severity) pairs: offline metric against closed-loop
/// metric; the offline top-k ringed, the closed-loop top-k filled red.
pub fn transfer_scatter(
    title: &str,
    x_name: &str,
    y_name: &str,
    points: &[ScatterPoint],
) -> crate::Result<String> {
    let e = || plot_err("a transfer scatter plot");
    let (w, h) = (360u32, 300u32);
    let range = |v: &mut dyn Iterator<Item = f64>| {
        let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
        for x in v {
            lo = lo.min(x);
            hi = hi.max(x);
        }
        if !lo.is_finite() {
            return (0.0, 1.0);
        }
        let pad = ((hi - lo) * 0.08).max(1e-3);
        (lo - pad, hi + pad)
    };
    let (x0, x1) = range(&mut points.iter().map(|p| p.x));
    let (y0, y1) = range(&mut points.iter().map(|p| p.y));
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (w, h)).into_drawing_area();
        root.fill(&WHITE).map_err(e())?;
        let mut chart = ChartBuilder::on(&root)
            .caption(title, ("sans-serif", 16))
            .margin(8)
            .x_label_area_size(40)
            .y_label_area_size(58)
            .build_cartesian_2d(x0..x1, y0..y1)
            .map_err(e())?;
        chart
            .configure_mesh()
            .x_desc(x_name)
            .y_desc(y_name)
            .label_style(("sans-serif", 13))
            .axis_desc_style(("sans-serif", 14))
            .max_light_lines(1)
            .light_line_style(RGBColor(244, 244, 244))
            .draw()
            .map_err(e())?;
        for p in points {
            let fill = if p.top_closed_loop {
                FAIL_RED.filled()
            } else {
                RGBColor(70, 120, 180).mix(0.8).filled()
            };
            chart
                .draw_series(std::iter::once(Circle::new((p.x, p.y), 4, fill)))
                .map_err(e())?;
            if p.top_offline {
                chart
                    .draw_series(std::iter::once(Circle::new(
                        (p.x, p.y),
                        7,
                        INK.stroke_width(1),
                    )))
                    .map_err(e())?;
            }
        }
        root.present().map_err(e())?;
    }
    Ok(svg)
}

/// A small bar per severity (the paper's trend bars), heights relative to `max`.
pub fn trend_bars(values: &[(u8, f64)], max: f64) -> crate::Result<String> {
    let e = || plot_err("a trend bar");
    let n = values.len().max(1) as u32;
    let (w, h) = (8 * n + 2, 18u32);
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (w, h)).into_drawing_area();
        for (k, (_, v)) in values.iter().enumerate() {
            let frac = if max > 0.0 {
                (v / max).clamp(0.0, 1.0)
            } else {
                0.0
            };
            let top = h as i32 - 1 - ((h as f64 - 2.0) * frac).round() as i32;
            let x = 1 + 8 * k as i32;
            root.draw(&Rectangle::new(
                [(x, top), (x + 6, h as i32 - 1)],
                RGBColor(70, 120, 180).filled(),
            ))
            .map_err(e())?;
        }
        root.draw(&PathElement::new(
            vec![(0, h as i32 - 1), (w as i32, h as i32 - 1)],
            INK.stroke_width(1),
        ))
        .map_err(e())?;
        root.present().map_err(e())?;
    }
    Ok(svg)
}

/// The completion of each run as a bar (the paper's RQ3 bars): green when it did not fail, red
/// when it failed, grey when it was not judged; an absent completion draws an empty slot.
pub fn completion_bars(runs: &[(Option<f64>, Outcome)]) -> crate::Result<String> {
    let e = || plot_err("a completion bar");
    let n = runs.len().max(1) as u32;
    let (w, h) = (10 * n + 2, 20u32);
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (w, h)).into_drawing_area();
        for (k, (c, o)) in runs.iter().enumerate() {
            let x = 1 + 10 * k as i32;
            let col = match o {
                Outcome::Ok => OK_GREEN,
                Outcome::Failed => FAIL_RED,
                Outcome::Unjudged => UNJUDGED_GREY,
            };
            match c {
                Some(c) => {
                    let top = h as i32 - 1 - ((h as f64 - 2.0) * c.clamp(0.0, 1.0)).round() as i32;
                    root.draw(&Rectangle::new(
                        [(x, top), (x + 8, h as i32 - 1)],
                        col.filled(),
                    ))
                    .map_err(e())?;
                }
                None => {
                    root.draw(&Rectangle::new(
                        [(x, 1), (x + 8, h as i32 - 1)],
                        col.stroke_width(1),
                    ))
                    .map_err(e())?;
                }
            }
        }
        for y in [0, h as i32 - 1] {
            root.draw(&PathElement::new(
                vec![(0, y), (w as i32, y)],
                INK.stroke_width(1),
            ))
            .map_err(e())?;
        }
        root.present().map_err(e())?;
    }
    Ok(svg)
}
