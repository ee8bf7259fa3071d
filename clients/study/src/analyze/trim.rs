//! Trimming a run to the route (`--trim-to-route`, on by default with a route): a recording
//! often starts before the route (the vehicle driven to the start by hand) and goes on after
//! its end. The run starts where the vehicle first comes within the goal tolerance of the
//! route's start and ends at the goal (the first pose within the goal tolerance of the route's
//! end, the progress tracked along the route from the start); what lies outside is not analysed.

use super::load::RunData;
use super::reference::tracked_projections;
use crate::route::Route;

/// Where a run lies on the route.
#[derive(Clone, Debug, PartialEq)]
pub(crate) enum Window {
    /// Analyse [start, end] (seconds from the first message), with a remark when trimmed.
    On {
        start: f64,
        end: f64,
        note: Option<String>,
    },
    /// The vehicle never came near the route: nothing can be judged.
    Off(String),
}

fn dist(a: [f64; 2], b: [f64; 2]) -> f64 {
    (a[0] - b[0]).hypot(a[1] - b[1])
}

/// The window of `d` on `route`: from the first pose within `tol` of the route's start (or,
/// for a vehicle that joins the route part-way, its first pose within `lateral` of it) to the
/// goal (or the end of the recording).
pub(crate) fn window(d: &RunData, route: &Route, tol: f64, lateral: f64) -> Window {
    if d.poses.is_empty() {
        return Window::Off("no pose".into());
    }
    let start_pt = route.points[0];
    let (i0, joined) = match d.poses.iter().position(|p| dist(p.p, start_pt) <= tol) {
        Some(i) => (i, None),
        None => {
            let proj = tracked_projections(route, &super::reference::positions(&d.poses));
            match proj.iter().position(|p| p.offset.abs() <= lateral) {
                Some(i) => (i, Some(proj[i].s)),
                None => {
                    let closest = d
                        .poses
                        .iter()
                        .map(|p| route.project(p.p).offset.abs())
                        .fold(f64::INFINITY, f64::min);
                    return Window::Off(format!(
                        "never on the route (closest {closest:.1} m from it, {lateral} m needed)"
                    ));
                }
            }
        }
    };
    // A vehicle at the start from its first pose keeps the messages before that pose.
    let start = if i0 == 0 { 0.0 } else { d.poses[i0].t };
    let after: Vec<[f64; 2]> = d.poses[i0..].iter().map(|p| p.p).collect();
    let proj = tracked_projections(route, &after);
    let target = route.length() - tol;
    let mut best = f64::NEG_INFINITY;
    let goal = proj.iter().position(|p| {
        best = best.max(p.s);
        best >= target
    });
    let end = goal.map_or(d.end, |k| d.poses[i0 + k].t);
    let mut parts = Vec::new();
    if let Some(s) = joined {
        parts.push(format!(
            "never within {tol} m of the route's start: analysed from {start:.1} s, where it joins the route {s:.1} m along"
        ));
    } else if i0 > 0 {
        parts.push(format!(
            "the first {start:.1} s before the route's start are left out"
        ));
    }
    if goal.is_some() && end < d.end {
        parts.push(format!(
            "the {:.1} s after the goal (at {end:.1} s) are left out",
            d.end - end
        ));
    }
    Window::On {
        start,
        end,
        note: (!parts.is_empty()).then(|| format!("trimmed to the route: {}", parts.join("; "))),
    }
}

/// The part [a, b] of a run, with times shifted so that `a` is 0: samples outside are dropped,
/// a signal outside does not count, and the condition at `a` becomes the first event.
pub(crate) fn cut(d: &RunData, a: f64, b: f64) -> RunData {
    let inside = |t: f64| t >= a && t <= b;
    let shift = |t: f64| t - a;
    let mut events = Vec::new();
    if let Some(k) = d.events.iter().rposition(|(t, _)| *t <= a) {
        events.push((0.0, d.events[k].1.clone()));
    }
    events.extend(
        d.events
            .iter()
            .filter(|(t, _)| *t > a && *t <= b)
            .map(|(t, c)| (shift(*t), c.clone())),
    );
    let mut out = RunData {
        name: d.name.clone(),
        group: d.group.clone(),
        t0_ns: d.t0_ns + (a * 1e9).round() as u64,
        end: b - a,
        poses: d
            .poses
            .iter()
            .filter(|p| inside(p.t))
            .map(|p| super::load::PoseSample {
                t: shift(p.t),
                ..*p
            })
            .collect(),
        steering: d
            .steering
            .iter()
            .filter(|s| inside(s.0))
            .map(|s| (shift(s.0), s.1))
            .collect(),
        objects: d
            .objects
            .iter()
            .filter(|o| inside(o.0))
            .map(|o| (shift(o.0), o.1.clone()))
            .collect(),
        objects_frame: d.objects_frame,
        takeover: d.takeover.filter(|t| inside(*t)).map(shift),
        collision: d.collision.filter(|t| inside(*t)).map(shift),
        events,
        notes: d.notes.clone(),
    };
    for (what, at) in [("takeover", d.takeover), ("collision", d.collision)] {
        if let Some(t) = at.filter(|t| !inside(*t)) {
            out.notes.push(format!(
                "a {what} signal at {t:.1} s lies outside the part on the route and does not count"
            ));
        }
    }
    out
}
