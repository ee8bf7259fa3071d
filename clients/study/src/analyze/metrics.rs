//! The metrics of one run and of its segments, from its time series (pure computation).

use super::load::{PoseSample, RunData};
use super::reference::{ReferenceRegion, positions, tracked_projections};
use super::trim::{Window, cut, window};
use super::{
    AnalyzeConfig, Condition, CteTo, Failure, JitterUnit, Metrics, ObjectsFrame, Outcome,
    RunResult, SegmentResult,
};
use crate::route::Route;

/// Mean, maximum and population standard deviation of the absolute changes between consecutive
/// steering commands (divided by the time between them with [`JitterUnit::Second`]); None with
/// fewer than two commands.
pub fn jitter_stats(steering: &[(f64, f64)], unit: JitterUnit) -> Option<(f64, f64, f64)> {
    let deltas: Vec<f64> = steering
        .windows(2)
        .filter_map(|w| {
            let d = (w[1].1 - w[0].1).abs();
            match unit {
                JitterUnit::Command => Some(d),
                JitterUnit::Second => {
                    let dt = w[1].0 - w[0].0;
                    (dt > 0.0).then(|| d / dt)
                }
            }
        })
        .collect();
    if deltas.is_empty() {
        return None;
    }
    let n = deltas.len() as f64;
    let mean = deltas.iter().sum::<f64>() / n;
    let max = deltas.iter().copied().fold(0.0, f64::max);
    let var = deltas.iter().map(|d| (d - mean).powi(2)).sum::<f64>() / n;
    Some((mean, max, var.sqrt()))
}

/// Per pose sample: route projection (tracked), its signed CTE (to the route or the reference
/// region), progress reached so far (monotone), and the distance driven so far.
struct Track {
    proj: Vec<crate::route::Projection>,
    cte: Vec<f64>,
    reached: Vec<f64>,
    driven: Vec<f64>,
}

fn track(route: Option<&Route>, region: Option<&ReferenceRegion>, poses: &[PoseSample]) -> Track {
    let mut driven = Vec::with_capacity(poses.len());
    let mut d = 0.0;
    for (i, p) in poses.iter().enumerate() {
        if i > 0 {
            let q = poses[i - 1].p;
            d += (p.p[0] - q[0]).hypot(p.p[1] - q[1]);
        }
        driven.push(d);
    }
    let Some(route) = route else {
        return Track {
            proj: Vec::new(),
            cte: Vec::new(),
            reached: Vec::new(),
            driven,
        };
    };
    let proj = tracked_projections(route, &positions(poses));
    let cte = proj
        .iter()
        .map(|p| region.map_or(p.offset, |r| r.cte(p)))
        .collect();
    let mut best: f64 = 0.0;
    let reached = proj
        .iter()
        .map(|p| {
            best = best.max(p.s);
            best
        })
        .collect();
    Track {
        proj,
        cte,
        reached,
        driven,
    }
}

/// What a run's per-pose series are, kept for comparisons over a part of the route.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct RunTrack {
    /// Pose times (seconds from the run's start).
    pub t: Vec<f64>,
    /// Route progress reached by each pose, metres (empty without a route).
    pub reached: Vec<f64>,
    /// Signed CTE of each pose, metres (empty without a route).
    pub cte: Vec<f64>,
    /// Steering commands (t, value).
    pub steering: Vec<(f64, f64)>,
    /// The end of the analysed part: the failure or the end of the run, seconds.
    pub end: f64,
}

/// CTE (average, maximum of |CTE|) and jitter (average, maximum, standard deviation) of a run
/// over the part before it first gets `until_m` metres along the route (and before its
/// failure); None where there is no sample.
pub fn window_until(tr: &RunTrack, until_m: f64, unit: JitterUnit) -> WindowMetrics {
    // The last pose not beyond `until_m` ends the part.
    let stop = match tr.reached.iter().position(|&s| s > until_m) {
        Some(0) => 0.0,
        Some(i) => tr.t[i - 1],
        None => tr.end,
    }
    .min(tr.end);
    let e: Vec<f64> =
        tr.t.iter()
            .zip(&tr.cte)
            .filter(|(t, _)| **t <= stop)
            .map(|(_, c)| c.abs())
            .collect();
    let steer: Vec<(f64, f64)> = tr
        .steering
        .iter()
        .copied()
        .filter(|(t, _)| *t <= stop)
        .collect();
    let j = jitter_stats(&steer, unit);
    WindowMetrics {
        until_s: stop,
        cte_avg: (!e.is_empty()).then(|| e.iter().sum::<f64>() / e.len() as f64),
        cte_max: e.iter().copied().reduce(f64::max),
        jitter_avg: j.map(|j| j.0),
        jitter_max: j.map(|j| j.1),
        jitter_std: j.map(|j| j.2),
    }
}

/// The trajectory metrics of a part of a run ([`window_until`]).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct WindowMetrics {
    /// Where the part ends, seconds.
    pub until_s: f64,
    /// Mean |CTE|.
    pub cte_avg: Option<f64>,
    /// Max |CTE|.
    pub cte_max: Option<f64>,
    /// Mean jitter.
    pub jitter_avg: Option<f64>,
    /// Max jitter.
    pub jitter_max: Option<f64>,
    /// Jitter standard deviation.
    pub jitter_std: Option<f64>,
}

/// The pose at time t (linear between samples, clamped at the ends).
fn pose_at(poses: &[PoseSample], t: f64) -> ([f64; 2], Option<f64>) {
    let i = poses.partition_point(|p| p.t <= t);
    if i == 0 {
        return (poses[0].p, poses[0].yaw);
    }
    if i == poses.len() {
        let l = poses[i - 1];
        return (l.p, l.yaw);
    }
    let (a, b) = (poses[i - 1], poses[i]);
    let f = if b.t > a.t {
        (t - a.t) / (b.t - a.t)
    } else {
        0.0
    };
    let p = [
        a.p[0] + f * (b.p[0] - a.p[0]),
        a.p[1] + f * (b.p[1] - a.p[1]),
    ];
    (p, if f < 0.5 { a.yaw } else { b.yaw })
}

/// Heading at time t: the pose's orientation, or the direction of travel around it.
fn heading_at(poses: &[PoseSample], t: f64) -> f64 {
    let (_, yaw) = pose_at(poses, t);
    if let Some(y) = yaw {
        return y;
    }
    let i = poses.partition_point(|p| p.t <= t).min(poses.len() - 1);
    // The nearest pair of samples at least 0.2 m apart.
    let (mut a, mut b) = (i.saturating_sub(1), i);
    while b + 1 < poses.len() && dist(poses[a].p, poses[b].p) < 0.2 {
        b += 1;
    }
    while a > 0 && dist(poses[a].p, poses[b].p) < 0.2 {
        a -= 1;
    }
    let (pa, pb) = (poses[a].p, poses[b].p);
    (pb[1] - pa[1]).atan2(pb[0] - pa[0])
}

fn dist(a: [f64; 2], b: [f64; 2]) -> f64 {
    (a[0] - b[0]).hypot(a[1] - b[1])
}

/// Detected objects at one message, in the pose frame.
fn objects_in_map(d: &RunData, t: f64, objs: &[[f64; 2]]) -> Vec<[f64; 2]> {
    match d.objects_frame {
        ObjectsFrame::Map => objs.to_vec(),
        ObjectsFrame::Ego => {
            let (p, _) = pose_at(&d.poses, t);
            let h = heading_at(&d.poses, t);
            let (s, c) = h.sin_cos();
            objs.iter()
                .map(|o| [p[0] + c * o[0] - s * o[1], p[1] + s * o[0] + c * o[1]])
                .collect()
        }
    }
}

/// The condition segments of a run: (start, end, condition), contiguous, covering [0, end];
/// segments shorter than `min_s` are merged into the next one.
pub(crate) fn segments(d: &RunData, min_s: f64) -> Vec<(f64, f64, Condition)> {
    let end = d.end.max(d.poses.last().map_or(0.0, |p| p.t));
    let mut segs: Vec<(f64, f64, Condition)> = Vec::new();
    if d.events.is_empty() {
        return vec![(0.0, end, Condition::default())];
    }
    for (i, (t, c)) in d.events.iter().enumerate() {
        let start = if i == 0 { 0.0 } else { *t };
        let stop = d.events.get(i + 1).map_or(end, |n| n.0);
        segs.push((start, stop, c.clone()));
    }
    // Merge short segments into the next one (the last into the previous one).
    let mut i = 0;
    while i < segs.len() {
        if segs.len() > 1 && segs[i].1 - segs[i].0 < min_s {
            if i + 1 < segs.len() {
                segs[i + 1].0 = segs[i].0;
            } else {
                segs[i - 1].1 = segs[i].1;
            }
            segs.remove(i);
            continue;
        }
        i += 1;
    }
    // Merge neighbours that ended up with the same condition.
    let mut out: Vec<(f64, f64, Condition)> = Vec::new();
    for s in segs {
        match out.last_mut() {
            Some(l) if l.2 == s.2 => l.1 = s.1,
            _ => out.push(s),
        }
    }
    out
}

/// The failure of a run (time, type), if any.
fn failure(
    d: &RunData,
    tr: &Track,
    route: Option<&Route>,
    cfg: &AnalyzeConfig,
) -> Option<(f64, Failure)> {
    let goal = route.and_then(|r| {
        let target = r.length() - cfg.goal_tolerance_m;
        tr.reached
            .iter()
            .position(|&s| s >= target)
            .map(|i| d.poses[i].t)
    });
    let route = route.filter(|_| !d.poses.is_empty());
    let mut candidates: Vec<(f64, Failure)> = Vec::new();
    if let Some(t) = d.collision {
        candidates.push((t, Failure::Collision));
    }
    if let Some(t) = d.takeover {
        candidates.push((t, Failure::Takeover));
    }
    if let Some(route) = route
        && let Some(i) = tr.cte.iter().position(|c| c.abs() > cfg.cte_threshold)
    {
        let p = tr.proj[i];
        let k = route.curvature_at(p.s, cfg.curvature_window_m);
        let kind = if k.abs() < cfg.turn_curvature {
            Failure::RoadDeparture
        } else if k.signum() == tr.cte[i].signum() {
            Failure::Oversteer
        } else {
            Failure::Understeer
        };
        candidates.push((d.poses[i].t, kind));
    }
    if let Some(limit) = cfg.timeout_s
        && route.is_some()
        && goal.is_none_or(|g| g > limit)
        && d.end > limit
    {
        candidates.push((limit, Failure::Timeout));
    }
    // Earliest first; at the same time in the order of the enum (collision first).
    candidates.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
    let mut first = candidates
        .into_iter()
        .find(|(t, _)| goal.is_none_or(|g| *t < g));
    if first.is_none() && route.is_some() && goal.is_none() {
        first = Some((d.end, Failure::Incomplete));
    }
    let (t, kind) = first?;
    // An erratic start: no real progress, after a large oscillation before the failure.
    if matches!(
        kind,
        Failure::RoadDeparture
            | Failure::Understeer
            | Failure::Oversteer
            | Failure::Timeout
            | Failure::Incomplete
    ) && let Some(route) = route
    {
        let _ = route;
        let i = d.poses.partition_point(|p| p.t <= t).saturating_sub(1);
        let progress = tr.reached[i] - tr.reached[0];
        let oscillated = d
            .steering
            .windows(2)
            .take_while(|w| w[1].0 <= t)
            .any(|w| (w[1].1 - w[0].1).abs() > cfg.erratic_threshold);
        if progress < cfg.erratic_distance_m && oscillated {
            return Some((t, Failure::ErraticStart));
        }
    }
    Some((t, kind))
}

/// The metrics over [a, b) of the run; `fail` is the run's failure if it lies in this window.
#[allow(clippy::too_many_arguments)]
fn window_metrics(
    d: &RunData,
    tr: &Track,
    route: Option<&Route>,
    cfg: &AnalyzeConfig,
    vehicles: Option<&[[f64; 2]]>,
    a: f64,
    b: f64,
    fail: Option<(f64, Failure)>,
    closed: bool,
) -> Metrics {
    let route = route.filter(|_| !d.poses.is_empty());
    let closed = closed || fail.is_some_and(|(t, _)| t <= b);
    let b = fail.map_or(b, |(t, _)| t.min(b));
    let inside = |t: f64| t >= a && (t < b || (closed && t <= b));
    let idx: Vec<usize> = (0..d.poses.len())
        .filter(|&i| inside(d.poses[i].t))
        .collect();
    let last_i = d.poses.partition_point(|p| p.t <= b).saturating_sub(1);
    // A run that reached the goal (within the goal tolerance of the end) completed the route.
    let completion = route.map(|r| {
        if tr.reached[last_i] >= r.length() - cfg.goal_tolerance_m {
            1.0
        } else {
            (tr.reached[last_i] / r.length()).clamp(0.0, 1.0)
        }
    });
    // CTE over the valid part.
    let (mut cte_avg, mut cte_max) = (None, None);
    if route.is_some() && !idx.is_empty() {
        let mut valid: Vec<usize> = idx.clone();
        let mut ok = true;
        if fail.is_some() {
            let cut = tr.driven[last_i] - cfg.cte_exclude_m;
            valid.retain(|&i| tr.driven[i] <= cut);
            let long_enough = valid
                .last()
                .is_some_and(|&l| tr.driven[l] - tr.driven[idx[0]] >= cfg.cte_exclude_m + 1.0);
            ok = long_enough && completion.is_some_and(|c| c >= cfg.cte_min_completion);
        }
        if ok && !valid.is_empty() {
            let e: Vec<f64> = valid.iter().map(|&i| tr.cte[i].abs()).collect();
            cte_avg = Some(e.iter().sum::<f64>() / e.len() as f64);
            cte_max = Some(e.iter().copied().fold(0.0, f64::max));
        }
    }
    let steer: Vec<(f64, f64)> = d
        .steering
        .iter()
        .copied()
        .filter(|(t, _)| inside(*t))
        .collect();
    let jitter = jitter_stats(&steer, cfg.jitter_unit);
    let coverage_5m = vehicles.filter(|_| !d.poses.is_empty()).and_then(|veh| {
        let (mut expected, mut seen) = (0usize, 0usize);
        for (t, objs) in d.objects.iter().filter(|(t, _)| inside(*t)) {
            let (p, _) = pose_at(&d.poses, *t);
            let near: Vec<&[f64; 2]> = veh
                .iter()
                .filter(|v| dist(**v, p) <= cfg.near_field_m)
                .collect();
            if near.is_empty() {
                continue;
            }
            let dets = objects_in_map(d, *t, objs);
            for v in near {
                expected += 1;
                if dets.iter().any(|o| dist(*o, *v) <= cfg.match_distance_m) {
                    seen += 1;
                }
            }
        }
        (expected > 0).then(|| seen as f64 / expected as f64)
    });
    Metrics {
        outcome: Outcome::Unjudged,
        unjudged_reason: None,
        completion,
        failure: fail.map(|f| f.1),
        cte_avg,
        cte_max,
        jitter_avg: jitter.map(|j| j.0),
        jitter_max: jitter.map(|j| j.1),
        jitter_std: jitter.map(|j| j.2),
        coverage_5m,
        duration_s: (b - a).max(0.0),
    }
}

/// Sets the outcome of `m`: failed with a failure, ok when the run could be judged, unjudged
/// (with the reason) otherwise.
fn judge(m: &mut Metrics, unjudged: &Option<String>) {
    (m.outcome, m.unjudged_reason) = match (m.failure, unjudged) {
        (Some(_), _) => (Outcome::Failed, None),
        (None, None) => (Outcome::Ok, None),
        (None, Some(why)) => (Outcome::Unjudged, Some(why.clone())),
    };
}

/// Analyses one run: trimming to the route, failure, run metrics and segment metrics.
pub fn analyze_run(d: &RunData, cfg: &AnalyzeConfig, vehicles: Option<&[[f64; 2]]>) -> RunResult {
    let mut route = cfg.route.as_ref();
    let region = cfg
        .reference
        .as_ref()
        .filter(|_| cfg.cte_to == CteTo::Region);
    // Why failures cannot be judged, if they cannot.
    let mut unjudged: Option<String> = match (route, &cfg.pose) {
        (_, None) => Some(
            "no pose topic (--pose-topic): completion and lane or road departures cannot be judged"
                .into(),
        ),
        (None, _) => Some(
            "no route (--route or --reference-runs): completion and lane or road departures cannot be judged"
                .into(),
        ),
        _ => None,
    };
    let mut trimmed = None;
    let mut trim_note = None;
    let owned;
    let d = match route {
        Some(r) if cfg.trim_to_route && !d.poses.is_empty() => {
            match window(d, r, cfg.goal_tolerance_m, cfg.cte_threshold) {
                Window::On { start, end, note } => {
                    trim_note = note;
                    if start > 0.0 || end < d.end {
                        trimmed = Some([start, end]);
                        owned = cut(d, start, end);
                        &owned
                    } else {
                        d
                    }
                }
                Window::Off(why) => {
                    unjudged = Some(why);
                    route = None;
                    d
                }
            }
        }
        _ => d,
    };
    let tr = track(route, region, &d.poses);
    let fail = failure(d, &tr, route, cfg);
    let end = d.end.max(d.poses.last().map_or(0.0, |p| p.t));
    let segs = segments(d, cfg.min_segment_s);
    let mut metrics = window_metrics(d, &tr, route, cfg, vehicles, 0.0, end, fail, true);
    judge(&mut metrics, &unjudged);
    let mut segments = Vec::new();
    for (k, (a, b, c)) in segs.iter().enumerate() {
        if fail.is_some_and(|(t, _)| t < *a) {
            break; // nothing after the failure
        }
        let last = k + 1 == segs.len();
        let in_seg = fail.filter(|(t, _)| *t >= *a && (*t < *b || last));
        let mut m = window_metrics(d, &tr, route, cfg, vehicles, *a, *b, in_seg, last);
        judge(&mut m, &unjudged);
        let first_i = d
            .poses
            .partition_point(|p| p.t < *a)
            .min(d.poses.len().saturating_sub(1));
        segments.push(SegmentResult {
            run: d.name.clone(),
            group: d.group.clone(),
            perturbation: c.label(),
            severity: c.severity(),
            step: c.step(),
            start_s: *a,
            end_s: a + m.duration_s,
            route_start: route
                .filter(|_| !d.poses.is_empty())
                .map(|r| (tr.reached[first_i] / r.length()).clamp(0.0, 1.0)),
            metrics: m,
            condition: c.clone(),
        });
    }
    let (perturbation, severity) = match segs.as_slice() {
        [(_, _, c)] => (c.label(), c.severity()),
        _ => ("mixed".to_string(), None),
    };
    let cond_at = |t: f64| {
        segs.iter()
            .find(|(a, b, _)| t >= *a && t <= *b)
            .map(|s| s.2.clone())
            .unwrap_or_default()
    };
    let trajectory = d
        .poses
        .iter()
        .take_while(|p| fail.is_none_or(|(t, _)| p.t <= t))
        .map(|p| (p.p, cond_at(p.t)))
        .collect();
    let stop = fail.map_or(end, |f| f.0);
    let n = d.poses.partition_point(|p| p.t <= stop);
    let run_track = RunTrack {
        t: d.poses[..n].iter().map(|p| p.t).collect(),
        reached: tr.reached.iter().take(n).copied().collect(),
        cte: tr.cte.iter().take(n).copied().collect(),
        steering: d
            .steering
            .iter()
            .copied()
            .filter(|(t, _)| *t <= stop)
            .collect(),
        end: stop,
    };
    let mut notes = d.notes.clone();
    notes.extend(trim_note);
    if cfg.objects.is_some() && vehicles.is_none() {
        notes.push(
            "no coverage: no known vehicles (give --vehicles, or record nominal runs with detections)"
                .into(),
        );
    }
    RunResult {
        run: d.name.clone(),
        group: d.group.clone(),
        perturbation,
        severity,
        metrics,
        failure_time_s: fail.map(|f| f.0),
        failure_position: fail
            .filter(|_| !d.poses.is_empty())
            .map(|(t, _)| pose_at(&d.poses, t).0),
        trimmed,
        notes,
        segments,
        trajectory,
        track: run_track,
    }
}

/// Known vehicles taken from the nominal segments: every detection within the near field of
/// the vehicle, in the pose frame, clustered (DBSCAN, eps = the match distance, 3 points); each
/// cluster's centre is a vehicle. None when there is no such detection.
pub fn vehicles_from_nominal(runs: &[RunData], cfg: &AnalyzeConfig) -> Option<Vec<[f64; 2]>> {
    let mut pts = Vec::new();
    for d in runs {
        for (a, b, c) in segments(d, cfg.min_segment_s) {
            if !c.is_nominal() {
                continue;
            }
            if d.poses.is_empty() {
                continue;
            }
            for (t, objs) in d.objects.iter().filter(|(t, _)| *t >= a && *t < b) {
                let (p, _) = pose_at(&d.poses, *t);
                for o in objects_in_map(d, *t, objs) {
                    if dist(o, p) <= cfg.near_field_m {
                        pts.push(o);
                    }
                }
            }
        }
    }
    if pts.is_empty() {
        return None;
    }
    let labels = crate::stats::dbscan(&pts, cfg.match_distance_m, 3);
    let n = labels.iter().flatten().max().map_or(0, |m| m + 1);
    let centres: Vec<[f64; 2]> = (0..n)
        .map(|k| {
            let members: Vec<&[f64; 2]> = pts
                .iter()
                .zip(&labels)
                .filter(|(_, l)| **l == Some(k))
                .map(|(p, _)| p)
                .collect();
            let m = members.len() as f64;
            [
                members.iter().map(|p| p[0]).sum::<f64>() / m,
                members.iter().map(|p| p[1]).sum::<f64>() / m,
            ]
        })
        .collect();
    (!centres.is_empty()).then_some(centres)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn jitter_of_a_known_signal() {
        // Changes 0.1, 0.3, 0.2: mean 0.2, max 0.3, population std sqrt(2/3)/10.
        let s = [(0.0, 0.0), (0.1, 0.1), (0.2, -0.2), (0.4, 0.0)];
        let (m, x, sd) = jitter_stats(&s, JitterUnit::Command).unwrap();
        assert!((m - 0.2).abs() < 1e-12 && (x - 0.3).abs() < 1e-12);
        assert!((sd - (2.0f64 / 3.0).sqrt() / 10.0).abs() < 1e-12);
        let (m, _, _) = jitter_stats(&s, JitterUnit::Second).unwrap();
        assert!((m - (1.0 + 3.0 + 1.0) / 3.0).abs() < 1e-9);
        assert!(jitter_stats(&s[..1], JitterUnit::Command).is_none());
    }

    #[test]
    fn short_segments_merge_into_the_next() {
        let c = |id: &str| Condition(vec![(id.to_string(), 1)], Vec::new());
        let d = RunData {
            end: 10.0,
            poses: vec![PoseSample {
                t: 0.0,
                p: [0.0, 0.0],
                yaw: None,
            }],
            events: vec![
                (0.01, c("C-A1")),
                (
                    5.0,
                    Condition(vec![("C-A1".into(), 1), ("L-A1".into(), 1)], Vec::new()),
                ),
                (5.1, c("L-A1")),
            ],
            ..RunData::default()
        };
        let s = segments(&d, 0.5);
        assert_eq!(s.len(), 2, "{s:?}");
        assert_eq!((s[0].0, s[0].1), (0.0, 5.0));
        assert_eq!((s[1].0, s[1].1, s[1].2.label()), (5.0, 10.0, "L-A1".into()));
    }
}
