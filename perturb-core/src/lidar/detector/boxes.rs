//! Box fitting and classification of the clusters: minimum-area rectangles (rotating calipers),
//! L-shape fitting (search-based, closeness criterion) and a class from the box's shape.

use super::ObjectClass;
use crate::math::Portable;

/// Axis-aligned rectangle: (centre, [extent x, extent y], heading 0).
pub fn axis_aligned(xy: &[[f32; 2]]) -> ([f32; 2], [f32; 2], f32) {
    let mut lo = [f32::INFINITY; 2];
    let mut hi = [f32::NEG_INFINITY; 2];
    for p in xy {
        for a in 0..2 {
            lo[a] = lo[a].min(p[a]);
            hi[a] = hi[a].max(p[a]);
        }
    }
    (
        [0.5 * (lo[0] + hi[0]), 0.5 * (lo[1] + hi[1])],
        [hi[0] - lo[0], hi[1] - lo[1]],
        0.0,
    )
}

#[inline]
fn cross(o: [f32; 2], a: [f32; 2], b: [f32; 2]) -> f64 {
    (a[0] as f64 - o[0] as f64) * (b[1] as f64 - o[1] as f64)
        - (a[1] as f64 - o[1] as f64) * (b[0] as f64 - o[0] as f64)
}

/// Convex hull of `pts` (sorted in place) into `hull`, counter-clockwise, without collinear points
/// (Andrew's monotone chain). Fewer than three distinct points give those points.
pub fn convex_hull(pts: &mut [[f32; 2]], hull: &mut Vec<[f32; 2]>) {
    hull.clear();
    // Akl-Toussaint: points strictly inside the octagon of the extreme points in x, y, x + y and
    // x - y cannot be on the hull; dropping them first leaves only a few to sort.
    let pts = if pts.len() > 64 {
        let mut e = [pts[0]; 8];
        let key = |p: &[f32; 2], k: usize| match k {
            0 => -p[0],          // min x
            1 => -(p[0] + p[1]), // min x + y
            2 => -p[1],          // min y
            3 => p[0] - p[1],    // max x - y
            4 => p[0],           // max x
            5 => p[0] + p[1],    // max x + y
            6 => p[1],           // max y
            _ => p[1] - p[0],    // max y - x
        };
        for p in pts.iter() {
            for (k, ek) in e.iter_mut().enumerate() {
                if key(p, k) > key(ek, k) {
                    *ek = *p;
                }
            }
        }
        let mut w = 0;
        for r in 0..pts.len() {
            let p = pts[r];
            let inside = (0..8).all(|k| {
                let (a, b) = (e[k], e[(k + 1) % 8]);
                a == b || cross(a, b, p) > 0.0
            });
            if !inside {
                pts[w] = p;
                w += 1;
            }
        }
        &mut pts[..w]
    } else {
        pts
    };
    pts.sort_unstable_by(|a, b| a[0].total_cmp(&b[0]).then(a[1].total_cmp(&b[1])));
    let mut uniq = pts.len();
    if uniq > 0 {
        // Dedup in place.
        let mut w = 1;
        for r in 1..pts.len() {
            if pts[r] != pts[w - 1] {
                pts[w] = pts[r];
                w += 1;
            }
        }
        uniq = w;
    }
    let pts = &pts[..uniq];
    if pts.len() < 3 {
        hull.extend_from_slice(pts);
        return;
    }
    for &p in pts {
        while hull.len() >= 2 && cross(hull[hull.len() - 2], hull[hull.len() - 1], p) <= 0.0 {
            hull.pop();
        }
        hull.push(p);
    }
    let lower = hull.len() + 1;
    for &p in pts.iter().rev().skip(1) {
        while hull.len() >= lower && cross(hull[hull.len() - 2], hull[hull.len() - 1], p) <= 0.0 {
            hull.pop();
        }
        hull.push(p);
    }
    hull.pop(); // the first point again
}

/// The smallest-area rectangle enclosing a convex polygon (rotating calipers: one side of the
/// optimum lies on a hull edge). Returns (centre, [length, width], heading) with length >= width
/// and the heading, the direction of the length, in (-pi/2, pi/2].
pub fn min_area_rect(hull: &[[f32; 2]]) -> ([f32; 2], [f32; 2], f32) {
    match hull.len() {
        0 => return ([0.0; 2], [0.0; 2], 0.0),
        1 => return (hull[0], [0.0; 2], 0.0),
        _ => {}
    }
    let o = hull[0];
    let rel: Vec<[f64; 2]> = hull
        .iter()
        .map(|p| [(p[0] - o[0]) as f64, (p[1] - o[1]) as f64])
        .collect();
    let n = rel.len();
    let mut best: Option<(f64, [f64; 2], [f64; 4])> = None; // (area, unit u, [umin, umax, vmin, vmax])
    for k in 0..n {
        let a = rel[k];
        let b = rel[(k + 1) % n];
        let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
        let len = (dx * dx + dy * dy).sqrt();
        if len <= 0.0 {
            continue;
        }
        let u = [dx / len, dy / len];
        let mut e = [
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::INFINITY,
            f64::NEG_INFINITY,
        ];
        for p in &rel {
            let pu = p[0] * u[0] + p[1] * u[1];
            let pv = -p[0] * u[1] + p[1] * u[0];
            e[0] = e[0].min(pu);
            e[1] = e[1].max(pu);
            e[2] = e[2].min(pv);
            e[3] = e[3].max(pv);
        }
        let area = (e[1] - e[0]) * (e[3] - e[2]);
        if best.as_ref().is_none_or(|b| area < b.0 - 1e-12) {
            best = Some((area, u, e));
        }
    }
    let Some((_, mut u, e)) = best else {
        return (o, [0.0; 2], 0.0);
    };
    let (cu, cv) = (0.5 * (e[0] + e[1]), 0.5 * (e[2] + e[3]));
    let center = [
        o[0] as f64 + cu * u[0] - cv * u[1],
        o[1] as f64 + cu * u[1] + cv * u[0],
    ];
    let (mut l, mut w) = (e[1] - e[0], e[3] - e[2]);
    if w > l {
        std::mem::swap(&mut l, &mut w);
        u = [-u[1], u[0]];
    }
    let mut yaw = u[1].patan2(u[0]);
    if yaw > std::f64::consts::FRAC_PI_2 {
        yaw -= std::f64::consts::PI;
    } else if yaw <= -std::f64::consts::FRAC_PI_2 {
        yaw += std::f64::consts::PI;
    }
    (
        [center[0] as f32, center[1] as f32],
        [l as f32, w as f32],
        yaw as f32,
    )
}

/// Points used for the L-shape search at most (a regular subsample of larger clusters; the final
/// extents use every point).
const L_SHAPE_SAMPLES: usize = 384;
/// Coarse step of the L-shape search, in fine steps.
const L_SHAPE_COARSE: usize = 4;

/// The rectangle of `xy` oriented by L-shape fitting (Zhang et al., "Efficient L-Shape Fitting
/// for Vehicle Detection Using Laser Scanners", IV 2017, closeness criterion): for every
/// orientation `theta` in [0, 90) degrees in `step_deg` steps, the points are projected on the
/// two rectangle axes; on each axis the edge the points lie closer to (the visible face) is kept,
/// each point scores `1 / max(d, 0.01 m)` with `d` its distance to the nearer of the two kept
/// edges, and the orientation with the highest total wins. A car seen at a corner (an L of points)
/// or from one side (a line) gets the heading of its faces, where the minimum-area rectangle of
/// the same points may cut diagonally across. Returns (centre, [length, width], heading) like
/// [`min_area_rect`], enclosing every point.
pub fn l_shape_rect(xy: &[[f32; 2]], step_deg: f32) -> ([f32; 2], [f32; 2], f32) {
    if xy.len() < 3 {
        return normalise(axis_aligned(xy));
    }
    rect_at(xy, l_shape_heading(xy, step_deg))
}

/// The closeness criterion of [`l_shape_heading`] at orientation `theta` (`c1`, `c2`: scratch of
/// the sample's length).
fn closeness(sample: &[[f32; 2]], theta: f32, c1: &mut [f32], c2: &mut [f32]) -> f32 {
    let (s, c) = theta.psin_cos();
    let mut e = [
        f32::INFINITY,
        f32::NEG_INFINITY,
        f32::INFINITY,
        f32::NEG_INFINITY,
    ];
    for (j, p) in sample.iter().enumerate() {
        c1[j] = p[0] * c + p[1] * s;
        c2[j] = -p[0] * s + p[1] * c;
        e[0] = e[0].min(c1[j]);
        e[1] = e[1].max(c1[j]);
        e[2] = e[2].min(c2[j]);
        e[3] = e[3].max(c2[j]);
    }
    // The face of each axis the points lie closer to (smaller sum of squared distances); the
    // four sums in one pass, each in point order.
    let (mut dl1, mut dh1, mut dl2, mut dh2) = (0f32, 0f32, 0f32, 0f32);
    for (&a, &b) in c1.iter().zip(c2.iter()) {
        dl1 += (a - e[0]) * (a - e[0]);
        dh1 += (e[1] - a) * (e[1] - a);
        dl2 += (b - e[2]) * (b - e[2]);
        dh2 += (e[3] - b) * (e[3] - b);
    }
    let f1 = if dl1 <= dh1 { e[0] } else { e[1] };
    let f2 = if dl2 <= dh2 { e[2] } else { e[3] };
    c1.iter()
        .zip(c2.iter())
        .map(|(a, b)| 1.0 / (a - f1).abs().min((b - f2).abs()).max(0.01))
        .sum()
}

/// The heading of [`l_shape_rect`]: the orientation in [0, pi/2) that maximises the closeness
/// criterion (0 for fewer than three points).
pub fn l_shape_heading(xy: &[[f32; 2]], step_deg: f32) -> f32 {
    if xy.len() < 3 {
        return 0.0;
    }
    // Relative to the first point, for precision.
    let o = xy[0];
    let stride = xy.len().div_ceil(L_SHAPE_SAMPLES);
    let sample: Vec<[f32; 2]> = xy
        .iter()
        .step_by(stride)
        .map(|p| [p[0] - o[0], p[1] - o[1]])
        .collect();
    let step = step_deg.clamp(0.1, 45.0).to_radians();
    let steps = (std::f32::consts::FRAC_PI_2 / step).round().max(1.0) as usize;
    let mut c1 = vec![0f32; sample.len()];
    let mut c2 = vec![0f32; sample.len()];
    let mut score_at = |k: usize| closeness(&sample, k as f32 * step, &mut c1, &mut c2);
    // Coarse to fine: every COARSE-th step of the quarter turn, then the steps around the best
    // coarse one (the criterion varies slowly between neighbouring orientations).
    let coarse = L_SHAPE_COARSE.min(steps);
    let (mut best, mut best_k) = (f32::NEG_INFINITY, 0usize);
    for k in (0..steps).step_by(coarse) {
        let v = score_at(k);
        if v > best {
            (best, best_k) = (v, k);
        }
    }
    let centre = best_k;
    for d in 1..coarse {
        for k in [(centre + d) % steps, (centre + steps - d) % steps] {
            let v = score_at(k);
            if v > best || (v == best && k < best_k) {
                (best, best_k) = (v, k);
            }
        }
    }
    best_k as f32 * step
}

/// The smallest rectangle with heading `yaw` enclosing `xy`: (centre, [length, width], heading)
/// as [`normalise`] puts it.
pub fn rect_at(xy: &[[f32; 2]], yaw: f32) -> ([f32; 2], [f32; 2], f32) {
    let Some(&o) = xy.first() else {
        return ([0.0; 2], [0.0; 2], 0.0);
    };
    let (s, c) = (yaw as f64).psin_cos();
    let mut e = [
        f64::INFINITY,
        f64::NEG_INFINITY,
        f64::INFINITY,
        f64::NEG_INFINITY,
    ];
    for p in xy {
        let (x, y) = ((p[0] - o[0]) as f64, (p[1] - o[1]) as f64);
        let u = x * c + y * s;
        let v = -x * s + y * c;
        e[0] = e[0].min(u);
        e[1] = e[1].max(u);
        e[2] = e[2].min(v);
        e[3] = e[3].max(v);
    }
    let (cu, cv) = (0.5 * (e[0] + e[1]), 0.5 * (e[2] + e[3]));
    let center = [o[0] as f64 + cu * c - cv * s, o[1] as f64 + cu * s + cv * c];
    normalise((
        [center[0] as f32, center[1] as f32],
        [(e[1] - e[0]) as f32, (e[3] - e[2]) as f32],
        yaw,
    ))
}

/// The same rectangle with the length the longer side and the heading, its direction, in
/// (-pi/2, pi/2].
pub fn normalise((center, size, yaw): ([f32; 2], [f32; 2], f32)) -> ([f32; 2], [f32; 2], f32) {
    use std::f32::consts::{FRAC_PI_2, PI};
    let (mut l, mut w, mut yaw) = (size[0], size[1], yaw);
    if w > l {
        std::mem::swap(&mut l, &mut w);
        yaw += FRAC_PI_2;
    }
    yaw = yaw.rem_euclid(PI);
    if yaw > FRAC_PI_2 {
        yaw -= PI;
    }
    (center, [l, w], yaw)
}

/// The shape of a cluster that its class is decided from.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Shape {
    /// Footprint: the longer side, metres.
    pub length: f32,
    /// Footprint: the shorter side, metres.
    pub width: f32,
    /// Height of the highest point above the ground, metres.
    pub top: f32,
    /// Height of the lowest point above the ground, metres.
    pub bottom: f32,
    /// Share of the lower body's points (see [`faces`]) deeper than [`INTERIOR_DEPTH`] behind
    /// both sensor-facing faces: near 0 for an opaque body (a vehicle), larger for vegetation,
    /// bicycle racks and other things the beams pass into.
    pub interior: f32,
    /// Share of the lower body's points within [`FACE_DEPTH`] of a sensor-facing face.
    pub on_faces: f32,
    /// How far apart neighbouring beams are in height at the cluster's range (metres, 0 without
    /// a sensor model): its measured top and bottom may miss the object's by that much.
    pub uncertainty: f32,
    /// The median scanline residual of its points (metres, see
    /// [`super::beams::scanline_roughness`]); computed only for clusters a vehicle's shape,
    /// `None` otherwise or when too few points tell.
    pub roughness: Option<f32>,
    /// Its highest return is on the sensor's highest beam: its real top may be higher.
    pub cut_off: bool,
}

/// How far from a visible face a point may lie and still count as on it, metres.
pub const FACE_DEPTH: f32 = 0.2;

/// Points deeper than this behind both visible faces are inside the object, metres.
pub const INTERIOR_DEPTH: f32 = 0.4;

/// For the points `xy` in the box (centre, [length, width], heading): the share within
/// [`FACE_DEPTH`] of the two faces that look towards the sensor at the origin, and the share
/// deeper than [`INTERIOR_DEPTH`] behind both. Each face is placed at the 5th percentile of the
/// points' depth from its side (not at the outermost point), so a few stray returns (a mirror,
/// spray) do not move it.
pub fn faces(xy: &[[f32; 2]], center: [f32; 2], yaw: f32) -> (f32, f32) {
    faces_with(xy, center, yaw, &mut FacesScratch::default())
}

/// Scratch arrays of [`faces_with`]: the points' depths behind each face, and a copy for the
/// percentile.
#[derive(Clone, Debug, Default)]
pub struct FacesScratch {
    du: Vec<f32>,
    dv: Vec<f32>,
    t: Vec<f32>,
}

/// [`faces`] with its arrays kept in `sc` (the same result).
pub fn faces_with(
    xy: &[[f32; 2]],
    center: [f32; 2],
    yaw: f32,
    sc: &mut FacesScratch,
) -> (f32, f32) {
    if xy.is_empty() {
        return (0.0, 0.0);
    }
    let (s, c) = yaw.psin_cos();
    // The sensor in the box frame: the visible face of each axis is the one on its side.
    let su = -(center[0] * c + center[1] * s);
    let sv = -(-center[0] * s + center[1] * c);
    // Depth of every point behind each visible face's side (larger = further from the sensor).
    let FacesScratch { du, dv, t } = sc;
    du.clear();
    dv.clear();
    for p in xy {
        let (dx, dy) = (p[0] - center[0], p[1] - center[1]);
        du.push(-(dx * c + dy * s) * su.signum());
        dv.push(-(-dx * s + dy * c) * sv.signum());
    }
    let q = (xy.len() - 1) / 20;
    let mut face = |d: &[f32]| {
        t.clear();
        t.extend_from_slice(d);
        *t.select_nth_unstable_by(q, f32::total_cmp).1
    };
    let (fu, fv) = (face(du), face(dv));
    let (mut on, mut inside) = (0usize, 0usize);
    for (u, v) in du.iter().zip(dv.iter()) {
        let (a, b) = (u - fu, v - fv);
        on += (a <= FACE_DEPTH || b <= FACE_DEPTH) as usize;
        inside += (a > INTERIOR_DEPTH && b > INTERIOR_DEPTH) as usize;
    }
    let n = xy.len() as f32;
    (on as f32 / n, inside as f32 / n)
}

/// Size classes of road users, metres, and the opacity of a vehicle's body. Vehicles: cars, vans,
/// trucks and buses (a long articulated bus is 18.75 m long, the widest road vehicles 2.55 m);
/// pedestrian and cyclist sized: at most 2.2 m long and 0.75 m wide, 0.9 to 2.3 m high (checked
/// first: a cluster that small is a person or a cyclist rather than a glimpse of a car).
pub mod limits {
    /// A vehicle's highest visible point is at least this high (a car's bonnet or boot lid is
    /// about 0.9 to 1 m above the road, its roof 1.3 to 1.9 m; a partly hidden or distant car may
    /// show only its lower body).
    pub const VEHICLE_MIN_TOP: f32 = 0.9;
    /// A car (or a low van) is at most this high and at most [`CAR_MAX_WIDTH`] wide; higher
    /// vehicles (vans, trucks, buses) are also longer and wider.
    pub const CAR_MAX_TOP: f32 = 2.3;
    /// A vehicle higher than a car is at least this long ...
    pub const TALL_MIN_LENGTH: f32 = 4.5;
    /// ... and shows at least this much width.
    pub const TALL_MIN_WIDTH: f32 = 1.5;
    /// ... and no vehicle is higher (a double-deck bus is about 4.4 m).
    pub const VEHICLE_MAX_TOP: f32 = 4.5;
    /// The visible part of a vehicle is at least this long (its rear or front seen alone).
    pub const VEHICLE_MIN_LENGTH: f32 = 1.2;
    /// A vehicle shows at least this much depth: a single flat face is as likely a wall, a fence
    /// or a hedge.
    pub const VEHICLE_MIN_WIDTH: f32 = 0.5;
    /// A vehicle whose visible part is longer than a car is wide (so its length shows) shows at
    /// least this much depth.
    pub const VEHICLE_SIDE_MIN_WIDTH: f32 = 0.7;
    /// A car or van is at most this wide (2.0 m, plus mirrors and margin); wider vehicles are
    /// trucks or buses, long and tall.
    pub const CAR_MAX_WIDTH: f32 = 2.2;
    /// No road user is longer (a long articulated bus, 18.75 m, with margin); the detector splits
    /// or drops longer clusters.
    pub const MAX_LENGTH: f32 = 20.0;
    /// No vehicle is wider (2.55 m, the widest road vehicle, plus mirrors and margin).
    pub const VEHICLE_MAX_WIDTH: f32 = 3.2;
    /// A vehicle longer than a van is a truck or a bus ...
    pub const LONG: f32 = 7.0;
    /// ... at least this high.
    pub const LONG_MIN_TOP: f32 = 2.8;
    /// A vehicle's lowest visible point (its wheels, its bumper) is at most this high above the
    /// ground; higher clusters hang in the air (branches, signs) or stand behind something.
    pub const VEHICLE_MAX_BOTTOM: f32 = 0.4;
    /// A vehicle's body is opaque: at most this share of its lower body's returns lie inside it.
    pub const VEHICLE_MAX_INTERIOR: f32 = 0.15;
    /// A vehicle's panels are smooth: the median scanline residual of its returns (the sensor's
    /// range noise on a smooth surface, 1 to 3 cm) is at most this, metres; foliage scatters 5
    /// to 15 cm.
    pub const VEHICLE_MAX_ROUGHNESS: f32 = 0.025;
    /// Pedestrians and cyclists are at most this long (a bicycle is about 1.8 m) ...
    pub const PERSON_MAX_LENGTH: f32 = 2.2;
    /// ... this wide (shoulders about 0.5 m, a cyclist's handlebars 0.6 to 0.7 m) ...
    pub const PERSON_MAX_WIDTH: f32 = 0.75;
    /// ... and their top between these heights.
    pub const PERSON_MIN_TOP: f32 = 0.9;
    /// See [`PERSON_MIN_TOP`].
    pub const PERSON_MAX_TOP: f32 = 2.3;
}

/// The class of a cluster from its shape (see [`limits`]); `capped` says that the cluster
/// reaches the detector's height limit (so its real top is unknown: a tree, a building). The
/// height limits allow for the beam spacing at the cluster's range ([`Shape::uncertainty`]): a
/// sparse sensor's highest beam on a car may pass a beam gap below its roof, its lowest above the
/// bumper.
pub fn classify(s: &Shape, capped: bool) -> ObjectClass {
    use limits::*;
    if capped {
        return ObjectClass::Other;
    }
    let u = s.uncertainty.max(0.0);
    let stands = s.bottom - 0.5 * u <= VEHICLE_MAX_BOTTOM;
    // A flat face is as likely a wall's or a fence's; one as long as a car is a wall's or a
    // fence's: a car seen from the side shows depth (its roof line, mirrors, the far side
    // through its windows).
    let deep_enough = s.width >= VEHICLE_MIN_WIDTH
        && (s.length <= CAR_MAX_WIDTH || s.width >= VEHICLE_SIDE_MIN_WIDTH);
    let car_sized = s.top <= CAR_MAX_TOP && s.width <= CAR_MAX_WIDTH && s.length <= LONG;
    let van_or_truck = s.top > CAR_MAX_TOP
        && s.top <= VEHICLE_MAX_TOP
        && s.length >= TALL_MIN_LENGTH
        && s.width >= TALL_MIN_WIDTH
        && s.width <= VEHICLE_MAX_WIDTH
        && (s.length <= LONG || s.top >= LONG_MIN_TOP);
    let vehicle = (car_sized || van_or_truck)
        && s.length >= VEHICLE_MIN_LENGTH
        && s.length <= MAX_LENGTH
        && deep_enough
        && s.top + u >= VEHICLE_MIN_TOP
        && stands
        && s.interior <= VEHICLE_MAX_INTERIOR;
    let smooth = s.roughness.is_some_and(|r| r <= VEHICLE_MAX_ROUGHNESS);
    // A smooth face longer than a person is wide is a vehicle's (a car's rear seen alone is
    // pedestrian-sized in its other dimensions; a cyclist seen from the side is not smooth).
    if vehicle && smooth {
        return ObjectClass::Vehicle;
    }
    if s.length <= PERSON_MAX_LENGTH
        && s.width <= PERSON_MAX_WIDTH
        && s.top + u >= PERSON_MIN_TOP
        && s.top <= PERSON_MAX_TOP
        && stands
    {
        return ObjectClass::Pedestrian;
    }
    if vehicle && s.roughness.is_none() {
        return ObjectClass::Vehicle;
    }
    ObjectClass::Other
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rect_points(center: [f32; 2], l: f32, w: f32, yaw: f32, fill: bool) -> Vec<[f32; 2]> {
        let (s, c) = yaw.psin_cos();
        let mut xy = Vec::new();
        let (nl, nw) = ((l * 10.0) as i32, (w * 10.0) as i32);
        for i in 0..=nl {
            for j in 0..=nw {
                let edge = i == 0 || j == 0 || i == nl || j == nw;
                if fill || edge {
                    let (u, v) = (i as f32 * 0.1 - l / 2.0, j as f32 * 0.1 - w / 2.0);
                    xy.push([center[0] + u * c - v * s, center[1] + u * s + v * c]);
                }
            }
        }
        xy
    }

    fn heading_error(a: f32, b: f32) -> f32 {
        let d = (a - b).rem_euclid(std::f32::consts::PI);
        d.min(std::f32::consts::PI - d)
    }

    #[test]
    fn min_area_rect_recovers_a_rotated_rectangle() {
        for deg in [-80.0f32, -45.0, -10.0, 0.0, 17.0, 30.0, 60.0, 89.0] {
            let yaw = deg.to_radians();
            let mut xy = rect_points([12.0, -3.0], 4.2, 1.8, yaw, true);
            let mut hull = Vec::new();
            convex_hull(&mut xy, &mut hull);
            let (center, size, got) = min_area_rect(&hull);
            assert!((center[0] - 12.0).abs() < 1e-3 && (center[1] + 3.0).abs() < 1e-3);
            assert!((size[0] - 4.2).abs() < 1e-3 && (size[1] - 1.8).abs() < 1e-3);
            assert!(
                heading_error(got, yaw) < 1e-3,
                "{deg}: got {}",
                got.to_degrees()
            );
        }
    }

    #[test]
    fn l_shape_follows_the_visible_faces() {
        // A 4.5 x 1.8 m car seen from the sensor at the origin: only the two faces towards the
        // sensor return points (an L), at several headings.
        for deg in [-70.0f32, -30.0, -5.0, 10.0, 40.0, 80.0] {
            let yaw = deg.to_radians();
            let center = [15.0f32, 4.0];
            let all = rect_points(center, 4.5, 1.8, yaw, false);
            // Keep the perimeter points nearer the sensor than the car's centre, beyond a margin.
            let d0 = center[0].phypot(center[1]);
            let seen: Vec<[f32; 2]> = all
                .into_iter()
                .filter(|p| p[0].phypot(p[1]) < d0 - 0.2)
                .collect();
            let (_, size, got) = l_shape_rect(&seen, 1.0);
            assert!(
                heading_error(got, yaw).to_degrees() < 1.5,
                "{deg}: got {}",
                got.to_degrees()
            );
            assert!(size[0] <= 4.5 + 1e-3 && size[1] <= 1.8 + 1e-3);
            assert!(got > -std::f32::consts::FRAC_PI_2 && got <= std::f32::consts::FRAC_PI_2);
        }
        // Every point is inside the box.
        let xy = rect_points([3.0, -7.0], 3.0, 1.2, 0.3, true);
        let (c, size, yaw) = l_shape_rect(&xy, 1.0);
        let (s, co) = yaw.psin_cos();
        for p in &xy {
            let (dx, dy) = (p[0] - c[0], p[1] - c[1]);
            assert!((dx * co + dy * s).abs() <= size[0] / 2.0 + 1e-4);
            assert!((-dx * s + dy * co).abs() <= size[1] / 2.0 + 1e-4);
        }
    }

    #[test]
    fn normalise_puts_the_length_first_and_the_heading_in_range() {
        let (_, size, yaw) = normalise(([0.0; 2], [1.0, 3.0], 0.2));
        assert_eq!(size, [3.0, 1.0]);
        assert!((yaw - (0.2 + std::f32::consts::FRAC_PI_2 - std::f32::consts::PI)).abs() < 1e-6);
        let (_, _, yaw) = normalise(([0.0; 2], [3.0, 1.0], -2.0));
        assert!((yaw - (-2.0 + std::f32::consts::PI)).abs() < 1e-6);
    }

    #[test]
    fn classes_from_shapes() {
        let s = |length, width, top, bottom, interior| Shape {
            length,
            width,
            top,
            bottom,
            interior,
            on_faces: 1.0,
            uncertainty: 0.0,
            roughness: None,
            cut_off: false,
        };
        let c = |sh: Shape| classify(&sh, false);
        assert_eq!(c(s(4.4, 1.8, 1.5, 0.2, 0.0)), ObjectClass::Vehicle); // a car
        assert_eq!(c(s(1.7, 0.9, 1.4, 0.3, 0.02)), ObjectClass::Vehicle); // its rear corner
        assert_eq!(c(s(6.0, 2.0, 2.7, 0.3, 0.0)), ObjectClass::Vehicle); // a van
        assert_eq!(c(s(6.0, 2.5, 1.7, 0.2, 0.0)), ObjectClass::Other); // wide but low: a hedge
        assert_eq!(c(s(12.0, 2.5, 3.6, 0.3, 0.0)), ObjectClass::Vehicle); // a truck
        assert_eq!(c(s(4.4, 1.8, 1.5, 0.2, 0.3)), ObjectClass::Other); // a hedge: not opaque
        assert_eq!(c(s(4.4, 0.3, 1.5, 0.2, 0.0)), ObjectClass::Other); // one flat face
        assert_eq!(c(s(3.0, 2.8, 1.5, 0.2, 0.0)), ObjectClass::Other); // too wide for a car
        assert_eq!(c(s(15.0, 2.5, 2.0, 0.2, 0.0)), ObjectClass::Other); // long but low
        assert_eq!(c(s(3.0, 1.0, 2.8, 0.2, 0.0)), ObjectClass::Other); // tall and small
        assert_eq!(c(s(0.6, 0.5, 1.75, 0.1, 0.0)), ObjectClass::Pedestrian);
        assert_eq!(c(s(1.8, 0.6, 1.7, 0.2, 0.0)), ObjectClass::Pedestrian); // a cyclist
        assert_eq!(c(s(15.0, 0.3, 1.2, 0.2, 0.0)), ObjectClass::Other); // a fence
        assert_eq!(c(s(2.0, 1.5, 0.6, 0.2, 0.0)), ObjectClass::Other); // a low hedge
        assert_eq!(c(s(3.0, 2.0, 2.9, 1.5, 0.0)), ObjectClass::Other); // a tree crown
        assert_eq!(c(s(0.3, 0.3, 3.0, 0.1, 0.0)), ObjectClass::Other); // a pole
        assert_eq!(
            classify(&s(4.4, 1.8, 1.5, 0.2, 0.0), true),
            ObjectClass::Other
        ); // capped
    }

    #[test]
    fn hull_prefilter_keeps_the_exact_hull() {
        let mut rng = crate::rng::Rng::for_setup(7, 7);
        for n in [65usize, 200, 3000] {
            let pts: Vec<[f32; 2]> = (0..n)
                .map(|_| [rng.uniform(-3.0, 5.0) as f32, rng.uniform(-1.0, 1.0) as f32])
                .collect();
            let mut hull = Vec::new();
            convex_hull(&mut pts.clone(), &mut hull);
            // Every point is inside or on the hull, and every hull vertex is an input point.
            for p in &pts {
                for k in 0..hull.len() {
                    assert!(cross(hull[k], hull[(k + 1) % hull.len()], *p) >= -1e-9);
                }
            }
            assert!(hull.iter().all(|h| pts.contains(h)));
            // Strict convexity (no collinear vertices).
            for k in 0..hull.len() {
                let (a, b, c) = (
                    hull[k],
                    hull[(k + 1) % hull.len()],
                    hull[(k + 2) % hull.len()],
                );
                assert!(cross(a, b, c) > 0.0);
            }
        }
    }

    #[test]
    fn degenerate_hulls() {
        let mut hull = Vec::new();
        convex_hull(&mut [], &mut hull);
        assert!(hull.is_empty());
        assert_eq!(min_area_rect(&hull).1, [0.0, 0.0]);
        convex_hull(&mut [[1.0, 1.0], [1.0, 1.0]], &mut hull);
        assert_eq!(hull, vec![[1.0, 1.0]]);
        // Collinear points: a zero-width box along the line.
        convex_hull(&mut [[0.0, 0.0], [1.0, 1.0], [2.0, 2.0]], &mut hull);
        let (c, s, yaw) = min_area_rect(&hull);
        assert!(
            (c[0] - 1.0).abs() < 1e-6 && (s[0] - 8f32.sqrt()).abs() < 1e-5 && s[1].abs() < 1e-6
        );
        assert!((yaw - std::f32::consts::FRAC_PI_4).abs() < 1e-5);
        assert_eq!(l_shape_rect(&[[1.0, 2.0]], 1.0).1, [0.0, 0.0]);
    }
}
