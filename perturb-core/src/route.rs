//! A route, a polyline in the map frame, with arc length, signed lateral offset and curvature;
//! and geofences, polygons in the same frame. The closed-loop study measures cross-track error
//! along a route and campaigns trigger perturbations by arc length or by geofence, with the same
//! projection.

/// A reference route.
#[derive(Clone, Debug, PartialEq)]
pub struct Route {
    /// The vertices, consecutive duplicates removed.
    pub points: Vec<[f64; 2]>,
    /// Arc length at each vertex, metres (`cum[0] == 0`).
    pub cum: Vec<f64>,
}

/// Where a position lies relative to the route.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Projection {
    /// Arc length of the closest point, metres.
    pub s: f64,
    /// Signed lateral distance, metres: positive to the left of the direction of travel.
    pub offset: f64,
    /// Index of the segment of the closest point.
    pub segment: usize,
}

/// How far behind and ahead of the previous projection a tracked projection searches, metres.
const TRACK_BACK: f64 = 15.0;
const TRACK_AHEAD: f64 = 40.0;

impl Route {
    /// A route through `points`; at least two distinct points.
    pub fn new(points: Vec<[f64; 2]>) -> std::result::Result<Route, String> {
        let mut pts: Vec<[f64; 2]> = Vec::with_capacity(points.len());
        for p in points {
            if !(p[0].is_finite() && p[1].is_finite()) {
                return Err(format!("point ({}, {}) is not finite", p[0], p[1]));
            }
            if pts.last() != Some(&p) {
                pts.push(p);
            }
        }
        if pts.len() < 2 {
            return Err(format!(
                "a route needs at least 2 distinct points, found {}",
                pts.len()
            ));
        }
        let mut cum = vec![0.0];
        for w in pts.windows(2) {
            let d = crate::math::hypot(w[1][0] - w[0][0], w[1][1] - w[0][1]);
            cum.push(cum.last().expect("one") + d);
        }
        Ok(Route { points: pts, cum })
    }

    /// A route from the text of a CSV of points (see [`parse_xy_csv`]).
    pub fn from_csv_text(text: &str) -> Result<Route, String> {
        Route::new(parse_xy_csv(text)?)
    }

    /// Total length, metres.
    pub fn length(&self) -> f64 {
        *self.cum.last().expect("two points")
    }

    /// (arc length, signed lateral offset, distance) of `p` against segment `i`. Before the
    /// route's start and beyond its end the offset is the perpendicular distance to the first
    /// or last segment's line (a vehicle 20 m before the start on the route's line is on it,
    /// not 20 m off it); the distance, which picks the nearest segment, is the true one.
    fn project_segment(&self, i: usize, p: [f64; 2]) -> (f64, f64, f64) {
        let (a, b) = (self.points[i], self.points[i + 1]);
        let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
        let len2 = dx * dx + dy * dy;
        let raw = ((p[0] - a[0]) * dx + (p[1] - a[1]) * dy) / len2;
        let t = raw.clamp(0.0, 1.0);
        let (cx, cy) = (a[0] + t * dx, a[1] + t * dy);
        let dist = crate::math::hypot(p[0] - cx, p[1] - cy);
        let len = len2.sqrt();
        let cross = (dx * (p[1] - a[1]) - dy * (p[0] - a[0])) / len;
        let side = if cross >= 0.0 { 1.0 } else { -1.0 };
        let outside = (i == 0 && raw < 0.0) || (i + 2 == self.points.len() && raw > 1.0);
        let offset = if outside { cross } else { dist * side };
        (self.cum[i] + t * len, offset, dist)
    }

    fn best_in(&self, range: std::ops::Range<usize>, p: [f64; 2]) -> Projection {
        let mut best = (
            f64::INFINITY,
            Projection {
                s: 0.0,
                offset: 0.0,
                segment: 0,
            },
        );
        for i in range {
            let (s, offset, dist) = self.project_segment(i, p);
            if dist < best.0 {
                best = (
                    dist,
                    Projection {
                        s,
                        offset,
                        segment: i,
                    },
                );
            }
        }
        best.1
    }

    /// The closest point of the whole route.
    pub fn project(&self, p: [f64; 2]) -> Projection {
        self.best_in(0..self.points.len() - 1, p)
    }

    /// The closest point within a window around the previous projection's arc length `prev_s`
    /// (15 m behind to 40 m ahead), so a route that passes near itself is followed in order.
    pub fn project_near(&self, p: [f64; 2], prev_s: f64) -> Projection {
        let lo = self.segment_at(prev_s - TRACK_BACK);
        let hi = self.segment_at(prev_s + TRACK_AHEAD);
        self.best_in(lo..hi + 1, p)
    }

    /// The index of the segment containing arc length `s` (clamped to the route).
    pub fn segment_at(&self, s: f64) -> usize {
        let n = self.points.len() - 1;
        match self.cum.binary_search_by(|c| c.total_cmp(&s)) {
            Ok(i) => i.min(n - 1),
            Err(i) => i.saturating_sub(1).min(n - 1),
        }
    }

    /// The point at arc length `s` (clamped).
    pub fn point_at(&self, s: f64) -> [f64; 2] {
        let i = self.segment_at(s);
        let (a, b) = (self.points[i], self.points[i + 1]);
        let len = self.cum[i + 1] - self.cum[i];
        let t = ((s - self.cum[i]) / len).clamp(0.0, 1.0);
        [a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1])]
    }

    /// Heading of the route at arc length `s`, radians.
    pub fn heading_at(&self, s: f64) -> f64 {
        let i = self.segment_at(s);
        let (a, b) = (self.points[i], self.points[i + 1]);
        crate::math::atan2(b[1] - a[1], b[0] - a[0])
    }

    /// Signed curvature around arc length `s` (1/m, positive turning left): the change of
    /// heading between `s - window` and `s + window` over the distance between them.
    pub fn curvature_at(&self, s: f64, window: f64) -> f64 {
        let (a, b) = ((s - window).max(0.0), (s + window).min(self.length()));
        if b - a <= f64::EPSILON {
            return 0.0;
        }
        let mut d = self.heading_at(b) - self.heading_at(a);
        while d > std::f64::consts::PI {
            d -= 2.0 * std::f64::consts::PI;
        }
        while d < -std::f64::consts::PI {
            d += 2.0 * std::f64::consts::PI;
        }
        d / (b - a)
    }
}

/// Parses points from the text of a CSV with columns `x,y` (a header naming them, in any
/// position, or no header and x, y as the first two columns). Lines starting with `#` are
/// comments. The error names the line.
pub fn parse_xy_csv(text: &str) -> Result<Vec<[f64; 2]>, String> {
    let mut cols = (0, 1);
    let mut points = Vec::new();
    let mut first = true;
    for (n, line) in text.lines().enumerate() {
        let line = line.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let cells: Vec<&str> = line.split(',').map(str::trim).collect();
        if first {
            first = false;
            if cells.iter().any(|c| c.parse::<f64>().is_err()) {
                let find = |name: &str| cells.iter().position(|c| c.eq_ignore_ascii_case(name));
                match (find("x"), find("y")) {
                    (Some(x), Some(y)) => {
                        cols = (x, y);
                        continue;
                    }
                    _ => {
                        return Err(format!(
                            "line {}: expected a header with columns `x` and `y`, found `{line}`",
                            n + 1
                        ));
                    }
                }
            }
        }
        let get = |i: usize| -> Result<f64, String> {
            let c = cells.get(i).ok_or_else(|| {
                format!("line {}: column {} is missing in `{line}`", n + 1, i + 1)
            })?;
            c.parse::<f64>()
                .map_err(|_| format!("line {}: `{c}` is not a number", n + 1))
        };
        points.push([get(cols.0)?, get(cols.1)?]);
    }
    Ok(points)
}

/// A geofence: a simple polygon in the map frame (at least 3 distinct vertices, given in order;
/// the last joins the first).
#[derive(Clone, Debug, PartialEq)]
pub struct Polygon {
    /// The vertices.
    pub points: Vec<[f64; 2]>,
}

impl Polygon {
    /// A polygon through `points`: at least 3 distinct, finite vertices.
    pub fn new(points: Vec<[f64; 2]>) -> Result<Polygon, String> {
        if let Some(p) = points
            .iter()
            .find(|p| !(p[0].is_finite() && p[1].is_finite()))
        {
            return Err(format!("vertex ({}, {}) is not finite", p[0], p[1]));
        }
        let mut distinct = points.clone();
        distinct.sort_by(|a, b| a[0].total_cmp(&b[0]).then(a[1].total_cmp(&b[1])));
        distinct.dedup();
        if distinct.len() < 3 {
            return Err(format!(
                "a polygon needs at least 3 distinct vertices, found {}",
                distinct.len()
            ));
        }
        Ok(Polygon { points })
    }

    /// True if `p` is inside (even-odd rule; a point on an edge counts as inside).
    pub fn contains(&self, p: [f64; 2]) -> bool {
        let n = self.points.len();
        let mut inside = false;
        for i in 0..n {
            let (a, b) = (self.points[i], self.points[(i + 1) % n]);
            if on_segment(a, b, p) {
                return true;
            }
            if (a[1] > p[1]) != (b[1] > p[1]) {
                let x = a[0] + (p[1] - a[1]) * (b[0] - a[0]) / (b[1] - a[1]);
                if p[0] < x {
                    inside = !inside;
                }
            }
        }
        inside
    }

    /// True if the two polygons share any point (an edge crossing, or one inside the other).
    pub fn overlaps(&self, other: &Polygon) -> bool {
        let edges = |q: &Polygon| {
            let n = q.points.len();
            (0..n)
                .map(|i| (q.points[i], q.points[(i + 1) % n]))
                .collect::<Vec<_>>()
        };
        let (ea, eb) = (edges(self), edges(other));
        ea.iter()
            .any(|&(a, b)| eb.iter().any(|&(c, d)| segments_meet(a, b, c, d)))
            || self.contains(other.points[0])
            || other.contains(self.points[0])
    }
}

fn cross(o: [f64; 2], a: [f64; 2], b: [f64; 2]) -> f64 {
    (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])
}

fn on_segment(a: [f64; 2], b: [f64; 2], p: [f64; 2]) -> bool {
    cross(a, b, p).abs() <= 1e-12 * (1.0 + (b[0] - a[0]).abs() + (b[1] - a[1]).abs())
        && p[0] >= a[0].min(b[0])
        && p[0] <= a[0].max(b[0])
        && p[1] >= a[1].min(b[1])
        && p[1] <= a[1].max(b[1])
}

fn segments_meet(a: [f64; 2], b: [f64; 2], c: [f64; 2], d: [f64; 2]) -> bool {
    let (d1, d2) = (cross(c, d, a), cross(c, d, b));
    let (d3, d4) = (cross(a, b, c), cross(a, b, d));
    if ((d1 > 0.0 && d2 < 0.0) || (d1 < 0.0 && d2 > 0.0))
        && ((d3 > 0.0 && d4 < 0.0) || (d3 < 0.0 && d4 > 0.0))
    {
        return true;
    }
    on_segment(c, d, a) || on_segment(c, d, b) || on_segment(a, b, c) || on_segment(a, b, d)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn polygons_contain_and_overlap() {
        let sq = Polygon::new(vec![[0.0, 0.0], [10.0, 0.0], [10.0, 10.0], [0.0, 10.0]]).unwrap();
        assert!(sq.contains([5.0, 5.0]) && sq.contains([10.0, 3.0]));
        assert!(!sq.contains([10.5, 3.0]) && !sq.contains([-1.0, 5.0]));
        let inner = Polygon::new(vec![[2.0, 2.0], [3.0, 2.0], [3.0, 3.0]]).unwrap();
        let apart = Polygon::new(vec![[20.0, 0.0], [30.0, 0.0], [25.0, 5.0]]).unwrap();
        let crossing = Polygon::new(vec![[5.0, 5.0], [15.0, 5.0], [15.0, 15.0]]).unwrap();
        assert!(sq.overlaps(&inner) && inner.overlaps(&sq));
        assert!(sq.overlaps(&crossing));
        assert!(!sq.overlaps(&apart));
        assert!(Polygon::new(vec![[0.0, 0.0], [1.0, 1.0], [0.0, 0.0]]).is_err());
        let e = parse_xy_csv("x,y\n1,2\n3,oops\n").unwrap_err();
        assert!(e.contains("line 3"), "{e}");
        assert_eq!(
            parse_xy_csv("# route\n1,2\n3,4\n").unwrap(),
            vec![[1.0, 2.0], [3.0, 4.0]]
        );
    }

    #[test]
    fn projects_with_signed_offsets_and_curvature() {
        let r = Route::new(vec![[0.0, 0.0], [10.0, 0.0], [10.0, 10.0]]).unwrap();
        assert_eq!(r.length(), 20.0);
        let p = r.project([4.0, 1.5]);
        assert_eq!((p.s, p.offset, p.segment), (4.0, 1.5, 0));
        let p = r.project([11.0, 5.0]); // right of the second segment (heading +y)
        assert_eq!((p.s, p.offset), (15.0, -1.0));
        assert!(r.curvature_at(10.0, 2.0) > 0.3); // a left turn
        assert_eq!(r.curvature_at(3.0, 2.0), 0.0);
        assert_eq!(r.point_at(12.5), [10.0, 2.5]);
        assert!(Route::new(vec![[1.0, 1.0], [1.0, 1.0]]).is_err());
    }

    #[test]
    fn before_the_start_and_past_the_end_the_offset_is_to_the_end_segments_line() {
        let r = Route::new(vec![[0.0, 0.0], [10.0, 0.0], [20.0, 0.0]]).unwrap();
        let p = r.project([-20.0, 0.0]);
        assert_eq!(
            (p.s, p.offset),
            (0.0, 0.0),
            "on the route's line, 20 m before it"
        );
        assert_eq!(r.project([-20.0, 1.5]).offset, 1.5);
        assert_eq!(r.project([35.0, -2.0]).offset, -2.0);
    }

    #[test]
    fn tracking_follows_a_route_that_passes_near_itself() {
        // Out along y = 0, back along y = 1 (a hairpin): the global projection of a point on
        // the way back near the start would jump; tracking keeps the order.
        let r = Route::new(vec![[0.0, 0.0], [100.0, 0.0], [100.0, 1.0], [0.0, 1.0]]).unwrap();
        let global = r.project([5.0, 0.4]);
        assert!(global.s < 10.0);
        let tracked = r.project_near([5.0, 0.4], 190.0);
        assert!((tracked.s - 196.0).abs() < 1e-9, "{tracked:?}");
    }
}
