//! The closed-loop analysis on synthetic runs written as rosbag2 MCAP bags: every metric against
//! the value the run was built to have.

mod support;

use perturb_study::analyze::{
    Aggregate, AnalyzeConfig, Failure, ObjectsConfig, ObjectsFrame, RunResult, TopicField,
    analyze_dir,
};
use support::{Run, route_length, tmp, write_route};

fn close(a: Option<f64>, b: f64, tol: f64, what: &str) {
    let a = a.unwrap_or_else(|| panic!("{what}: no value, expected {b}"));
    assert!((a - b).abs() <= tol, "{what}: {a} != {b} (tolerance {tol})");
}

fn cfg(dir: &std::path::Path) -> AnalyzeConfig {
    let route = dir.join("route.csv");
    write_route(&route);
    AnalyzeConfig {
        route: Some(perturb_study::route::load(&route).unwrap()),
        pose: Some(TopicField {
            topic: "/odom".into(),
            field: None,
        }),
        steering: Some(TopicField {
            topic: "/cmd".into(),
            field: Some("drive.steering_angle".into()),
        }),
        collision: Some(TopicField {
            topic: "/collision".into(),
            field: None,
        }),
        ..AnalyzeConfig::default()
    }
}

fn run<'a>(runs: &'a [RunResult], name: &str) -> &'a RunResult {
    runs.iter()
        .find(|r| r.run == name)
        .unwrap_or_else(|| panic!("no run {name}"))
}

/// The pattern of steering changes: +0.1, -0.2, +0.3, -0.2 (absolute 0.1, 0.2, 0.3, 0.2: mean
/// 0.2, max 0.3, population std sqrt(0.005)).
fn pattern(k: usize) -> f64 {
    const STEPS: [f64; 4] = [0.1, -0.2, 0.3, -0.2];
    (0..k).map(|i| STEPS[i % 4]).sum()
}

/// Chord error of the 1 m polyline on the 20 m turn, plus float32 steering.
const TOL: f64 = 0.01;

#[test]
fn every_metric_of_synthetic_runs_matches_its_construction() {
    let dir = tmp("metrics");
    let runs_dir = dir.join("runs");
    std::fs::create_dir_all(&runs_dir).unwrap();
    let l = route_length();

    // Nominal: the whole route 0.5 m left of it, steering alternating +-0.05.
    let mut nominal = Run::new("nominal", l / 10.0 + 2.0);
    nominal.offset = Box::new(|_, _| 0.5);
    nominal.steer = Some(Box::new(|k| if k.is_multiple_of(2) { 0.05 } else { -0.05 }));
    let (_, nominal_last) = nominal.write(&runs_dir);

    // C-A1 s3: 1.0 m off for the first half, 1.5 m for the second; the steering pattern over
    // 4 * 50 changes.
    let mut offset = Run::new("offset", l / 10.0 + 2.0);
    offset.offset = Box::new(move |s, _| if s < l / 2.0 { 1.0 } else { 1.5 });
    offset.steer = Some(Box::new(pattern));
    offset.steer_count = Some(201);
    offset.cond = Some(Box::new(|_| Some(("C-A1", 3))));
    offset.write(&runs_dir);
    let offset_goal = support::goal_time(&offset, 3.0);
    let offsets: Vec<f64> = offset
        .pose_times()
        .iter()
        .filter(|t| **t <= offset_goal)
        .map(|t| {
            if (offset.s_of_t)(*t) < l / 2.0 {
                1.0
            } else {
                1.5
            }
        })
        .collect();
    let offset_mean = offsets.iter().sum::<f64>() / offsets.len() as f64;

    // C-C7 s2: stops halfway and stands until the recording ends at 40 s.
    let mut stop = Run::new("stopped", 40.0);
    stop.s_of_t = Box::new(move |t| (10.0 * t).min(l / 2.0));
    stop.offset = Box::new(|_, _| 0.3);
    stop.cond = Some(Box::new(|_| Some(("C-C7", 2))));
    let (_, stop_last) = stop.write(&runs_dir);

    // L-A9 s2: collision flag at 8 s; 0.3 m off, 1.5 m off over the last 5 m before it.
    let mut coll = Run::new("collision", 10.0);
    coll.offset = Box::new(|s, _| if s < 75.0 { 0.3 } else { 1.5 });
    coll.collision_at = Some(8.0);
    coll.cond = Some(Box::new(|_| Some(("L-A9", 2))));
    coll.write(&runs_dir);

    // Departures: out of the turn to the right (understeer), into it (oversteer), and drifting
    // off the first straight (road departure).
    let mut under = Run::new("understeer", 15.0);
    under.offset = Box::new(|s, _| if s < 105.0 { 0.0 } else { -(s - 105.0) * 0.5 });
    under.write(&runs_dir);
    let mut over = Run::new("oversteer", 15.0);
    over.offset = Box::new(|s, _| if s < 105.0 { 0.0 } else { (s - 105.0) * 0.5 });
    over.write(&runs_dir);
    let mut drift = Run::new("drift", 10.0);
    drift.offset = Box::new(|s, _| if s < 20.0 { 0.0 } else { (s - 20.0) * 0.1 });
    drift.write(&runs_dir);

    // Erratic start: steering +-0.5, barely moving, recording ends after 5 s.
    let mut erratic = Run::new("erratic", 5.0);
    erratic.s_of_t = Box::new(|t| 0.1 * t);
    erratic.steer = Some(Box::new(|k| if k.is_multiple_of(2) { 0.5 } else { -0.5 }));
    erratic.write(&runs_dir);

    let mut c = cfg(&dir);
    c.timeout_s = Some(30.0);
    let a = analyze_dir(&runs_dir, &c).unwrap();
    assert!(a.errors.is_empty(), "{:?}", a.errors);
    assert_eq!(a.runs.len(), 8);

    let r = run(&a.runs, "nominal");
    assert_eq!((r.perturbation.as_str(), r.severity), ("nominal", None));
    assert_eq!(r.metrics.failure, None);
    close(r.metrics.completion, 1.0, 1e-9, "nominal completion");
    close(r.metrics.cte_avg, 0.5, TOL, "nominal cte_avg");
    close(r.metrics.cte_max, 0.5, TOL, "nominal cte_max");
    close(r.metrics.jitter_avg, 0.1, 1e-6, "nominal jitter_avg");
    close(r.metrics.jitter_max, 0.1, 1e-6, "nominal jitter_max");
    close(r.metrics.jitter_std, 0.0, 1e-6, "nominal jitter_std");
    // Trimmed to the route: it ends at the goal, not at the end of the recording.
    assert!(nominal_last > support::goal_time(&nominal, 3.0) + 1.0);
    close(
        Some(r.metrics.duration_s),
        support::goal_time(&nominal, 3.0),
        1e-6,
        "nominal duration (to the goal)",
    );
    assert_eq!(r.metrics.coverage_5m, None);

    let r = run(&a.runs, "offset");
    assert_eq!((r.perturbation.as_str(), r.severity), ("C-A1", Some(3)));
    close(r.metrics.cte_avg, offset_mean, TOL, "offset cte_avg");
    close(r.metrics.cte_max, 1.5, TOL, "offset cte_max");
    close(r.metrics.jitter_avg, 0.2, 1e-6, "offset jitter_avg");
    close(r.metrics.jitter_max, 0.3, 1e-6, "offset jitter_max");
    close(
        r.metrics.jitter_std,
        0.005f64.sqrt(),
        1e-6,
        "offset jitter_std",
    );

    let r = run(&a.runs, "stopped");
    assert_eq!(r.metrics.failure, Some(Failure::Timeout));
    close(r.metrics.completion, 0.5, 0.002, "stopped completion");
    close(Some(r.metrics.duration_s), 30.0, 1e-9, "stopped duration");
    close(r.metrics.cte_avg, 0.3, TOL, "stopped cte_avg");

    let r = run(&a.runs, "collision");
    assert_eq!(r.metrics.failure, Some(Failure::Collision));
    close(r.failure_time_s, 8.0, 1e-9, "collision time");
    // The last pose before 8 s is at 7.92 s, 79.2 m along.
    // (The polyline's chords make the route about 1 cm shorter than the arc.)
    close(r.metrics.completion, 79.2 / l, 1e-4, "collision completion");
    // The 1.5 m of the last 5 m before the collision are left out.
    close(r.metrics.cte_max, 0.3, TOL, "collision cte_max");
    close(r.metrics.cte_avg, 0.3, TOL, "collision cte_avg");
    let p = r.failure_position.unwrap();
    assert!(
        (p[0] - 80.0).abs() < 0.8 && (p[1] - 1.5).abs() < 0.01,
        "{p:?}"
    );

    let r = run(&a.runs, "understeer");
    assert_eq!(r.metrics.failure, Some(Failure::Understeer));
    // First pose beyond 2 m: 109.2 m along (offset 2.1).
    close(
        r.metrics.completion,
        109.2 / l,
        0.001,
        "understeer completion",
    );
    assert_eq!(
        run(&a.runs, "oversteer").metrics.failure,
        Some(Failure::Oversteer)
    );
    let r = run(&a.runs, "drift");
    assert_eq!(r.metrics.failure, Some(Failure::RoadDeparture));
    close(
        r.failure_time_s,
        4.02,
        1e-9,
        "drift failure time (40.2 m, 2.02 m off)",
    );
    // It drove 40 m: the CTE covers the first 35 m (0 m off, then the drift up to 1.5 m).
    close(r.metrics.cte_max, 1.52, TOL, "drift cte_max at 35.2 m");

    let r = run(&a.runs, "erratic");
    assert_eq!(r.metrics.failure, Some(Failure::ErraticStart));
    assert_eq!(r.metrics.cte_avg, None, "not enough trajectory for a CTE");

    // Without a timeout the stopped run is incomplete at the end of the recording.
    let mut c2 = cfg(&dir);
    c2.timeout_s = None;
    let a2 = analyze_dir(&runs_dir, &c2).unwrap();
    let r = run(&a2.runs, "stopped");
    assert_eq!(r.metrics.failure, Some(Failure::Incomplete));
    close(
        Some(r.metrics.duration_s),
        stop_last,
        1e-6,
        "stopped duration",
    );

    // Per (perturbation, severity) and per perturbation.
    let nominal_row = &a.perturbations[0];
    assert_eq!(nominal_row.perturbation, "nominal");
    // nominal, understeer, oversteer, drift, erratic: 4 of 5 fail.
    assert_eq!(nominal_row.metrics.runs, 5);
    close(
        nominal_row.metrics.failure_rate,
        0.8,
        1e-12,
        "nominal failure rate",
    );
    // Trajectory metrics over the non-failing run only.
    close(nominal_row.metrics.cte_avg, 0.5, TOL, "nominal row cte");
    let c_a1 = a
        .conditions
        .iter()
        .find(|c| c.perturbation == "C-A1")
        .unwrap();
    assert_eq!(c_a1.severity, Some(3));
    assert_eq!(c_a1.metrics.failure, None);
    let l_a9 = a
        .perturbations
        .iter()
        .find(|c| c.perturbation == "L-A9")
        .unwrap();
    assert_eq!(l_a9.metrics.failure, Some(Failure::Collision));
    assert_eq!(l_a9.metrics.cte_avg, None, "only failing runs");
    assert_eq!(l_a9.family, "weather");
    // With every run aggregated, the failing ones count up to their failure.
    let mut c3 = cfg(&dir);
    c3.aggregate = Aggregate::All;
    c3.timeout_s = Some(30.0);
    let a3 = analyze_dir(&runs_dir, &c3).unwrap();
    let l_a9 = a3
        .perturbations
        .iter()
        .find(|c| c.perturbation == "L-A9")
        .unwrap();
    close(l_a9.metrics.cte_avg, 0.3, TOL, "L-A9 cte, all runs");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn events_switching_mid_run_split_it_into_segments() {
    let dir = tmp("switch");
    let runs_dir = dir.join("runs");
    std::fs::create_dir_all(&runs_dir).unwrap();
    let l = route_length();
    let cond = |t: f64| -> Option<(&'static str, u8)> {
        if t < 5.0 {
            None
        } else if t < 12.0 {
            Some(("C-B1", 4))
        } else {
            Some(("C-B1", 2))
        }
    };
    let mut r = Run::new("switching", l / 10.0 + 2.0);
    r.cond = Some(Box::new(cond));
    // Offset and steering amplitude by condition: 0.2 / 0.8 / 0.4 m, +-0.05 / 0.15 / 0.1.
    r.offset = Box::new(move |_, t| match cond(t) {
        None => 0.2,
        Some((_, 4)) => 0.8,
        _ => 0.4,
    });
    r.steer = Some(Box::new(move |k| {
        let t = k as f64 / 10.0 + support::STEER_SHIFT;
        let a = match cond(t) {
            None => 0.05,
            Some((_, 4)) => 0.15,
            _ => 0.1,
        };
        if k.is_multiple_of(2) { a } else { -a }
    }));
    let (_, last) = r.write(&runs_dir);
    let a = analyze_dir(&runs_dir, &cfg(&dir)).unwrap();
    assert!(a.errors.is_empty(), "{:?}", a.errors);
    let run = &a.runs[0];
    assert_eq!((run.perturbation.as_str(), run.severity), ("mixed", None));
    let segs = &run.segments;
    let got: Vec<(&str, Option<u8>)> = segs
        .iter()
        .map(|s| (s.perturbation.as_str(), s.severity))
        .collect();
    assert_eq!(
        got,
        [("nominal", None), ("C-B1", Some(4)), ("C-B1", Some(2))]
    );
    let bounds: Vec<(f64, f64)> = segs.iter().map(|s| (s.start_s, s.end_s)).collect();
    assert_eq!(bounds[0], (0.0, 5.0));
    assert_eq!(bounds[1], (5.0, 12.0));
    // The run is trimmed at the goal: the first pose within 3 m of the route's end.
    let goal = support::goal_time(&r, 3.0);
    assert!(last > goal + 1.0, "the recording goes on after the goal");
    assert!((bounds[2].0 - 12.0).abs() < 1e-9 && (bounds[2].1 - goal).abs() < 1e-6);
    for (s, (cte, jitter)) in segs.iter().zip([(0.2, 0.1), (0.8, 0.3), (0.4, 0.2)]) {
        close(
            s.metrics.cte_avg,
            cte,
            TOL,
            &format!("{} cte", s.perturbation),
        );
        close(
            s.metrics.cte_max,
            cte,
            TOL,
            &format!("{} cte max", s.perturbation),
        );
        close(
            s.metrics.jitter_avg,
            jitter,
            1e-6,
            &format!("{} jitter", s.perturbation),
        );
        close(
            s.metrics.jitter_max,
            jitter,
            1e-6,
            &format!("{} jitter max", s.perturbation),
        );
        assert_eq!(s.metrics.failure, None);
    }
    // Completion at each segment's end: the last pose before 5 s is 49.2 m along, before 12 s
    // 119.2 m, and the route is completed.
    close(
        segs[0].metrics.completion,
        49.2 / l,
        1e-3,
        "completion at 5 s",
    );
    close(
        segs[1].metrics.completion,
        119.2 / l,
        2e-3,
        "completion at 12 s",
    );
    close(
        segs[2].metrics.completion,
        1.0,
        1e-9,
        "completion at the end",
    );
    close(segs[1].route_start, 50.2 / l, 1e-3, "route at 5 s");
    // The conditions table has one row per (perturbation, severity).
    let rows: Vec<(&str, Option<u8>)> = a
        .conditions
        .iter()
        .map(|c| (c.perturbation.as_str(), c.severity))
        .collect();
    assert_eq!(
        rows,
        [("nominal", None), ("C-B1", Some(2)), ("C-B1", Some(4))]
    );
    // One perturbation row for C-B1, its runs highest severity first.
    let p = a
        .perturbations
        .iter()
        .find(|p| p.perturbation == "C-B1")
        .unwrap();
    assert_eq!(p.severities, vec![4, 2]);
    assert_eq!(p.metrics.runs, 2);
    close(
        p.metrics.cte_avg,
        0.6,
        TOL,
        "C-B1 mean of the segments' CTE",
    );
    close(p.metrics.cte_max, 0.8, TOL, "C-B1 max CTE");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn near_field_coverage_counts_known_vehicles_detected_within_5_m() {
    let dir = tmp("coverage");
    let runs_dir = dir.join("runs");
    std::fs::create_dir_all(&runs_dir).unwrap();
    let car = [50.0, -3.0];
    // Detections in the vehicle frame (heading 0 on the first straight): the car, and a far
    // false positive; the perturbed run loses the car in every 4th message.
    let seen = move |drop: bool| {
        move |k: usize, _t: f64, ego: [f64; 2]| {
            let mut v = vec![[80.0, 10.0]];
            if !(drop && k.is_multiple_of(4)) {
                v.push([car[0] - ego[0], car[1] - ego[1]]);
            }
            v
        }
    };
    let mut nominal = Run::new("lidar_nominal", 9.0);
    nominal.objects = Some(Box::new(seen(false)));
    nominal.write(&runs_dir);
    let mut pert = Run::new("lidar_beam_loss", 9.0);
    pert.objects = Some(Box::new(seen(true)));
    pert.cond = Some(Box::new(|_| Some(("L-B1", 1))));
    pert.write(&runs_dir);
    // Expected: messages with the car within 5 m of the vehicle (|dx| <= 4 at 3 m aside).
    let (mut expected, mut detected) = (0, 0);
    for k in 0..90usize {
        let t = k as f64 / 10.0 + support::OBJECTS_SHIFT;
        let x = 10.0 * t;
        if (x - car[0]).hypot(car[1]) <= 5.0 {
            expected += 1;
            if !k.is_multiple_of(4) {
                detected += 1;
            }
        }
    }
    assert!(expected >= 6, "{expected}");
    let want = detected as f64 / expected as f64;
    let mut c = cfg(&dir);
    c.steering = None;
    c.objects = Some(ObjectsConfig {
        topic: "/objects".into(),
        array: None,
        position: None,
        frame: ObjectsFrame::Ego,
    });
    // Known vehicles given.
    c.vehicles = Some(vec![car]);
    let a = analyze_dir(&runs_dir, &c).unwrap();
    assert!(a.errors.is_empty(), "{:?}", a.errors);
    close(
        run(&a.runs, "lidar_nominal").metrics.coverage_5m,
        1.0,
        1e-12,
        "nominal",
    );
    close(
        run(&a.runs, "lidar_beam_loss").metrics.coverage_5m,
        want,
        1e-12,
        "beam loss",
    );
    // Known vehicles taken from the nominal run's detections: the same numbers.
    c.vehicles = None;
    let a = analyze_dir(&runs_dir, &c).unwrap();
    close(
        run(&a.runs, "lidar_beam_loss").metrics.coverage_5m,
        want,
        1e-12,
        "from nominal",
    );
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_bad_run_is_reported_by_name_and_the_others_are_analysed() {
    let dir = tmp("bad");
    let runs_dir = dir.join("runs");
    std::fs::create_dir_all(&runs_dir).unwrap();
    Run::new("good", 5.0).write(&runs_dir);
    let mut no_pose = Run::new("no_pose", 5.0);
    no_pose.no_pose = true;
    no_pose.steer = Some(Box::new(|_| 0.0));
    no_pose.write(&runs_dir);
    let mut bad_steer = Run::new("bad_field", 5.0);
    bad_steer.steer = Some(Box::new(|_| 0.0));
    bad_steer.write(&runs_dir);
    let mut c = cfg(&dir);
    c.steering = Some(TopicField {
        topic: "/cmd".into(),
        field: Some("drive.steering_angel".into()),
    });
    let a = analyze_dir(&runs_dir, &c).unwrap();
    assert_eq!(a.runs.len(), 1);
    assert_eq!(a.runs[0].run, "good");
    let err = |name: &str| {
        a.errors
            .iter()
            .find(|e| e.run == name)
            .unwrap_or_else(|| panic!("no error for {name}: {:?}", a.errors))
            .error
            .clone()
    };
    let e = err("no_pose");
    assert!(e.contains("run `no_pose`") && e.contains("/odom"), "{e}");
    let e = err("bad_field");
    assert!(
        e.contains("run `bad_field`")
            && e.contains("/cmd")
            && e.contains("drive.steering_angel")
            && e.contains("steering_angle"),
        "{e}"
    );
    // A one-point route is refused with the file named.
    let one = dir.join("one.csv");
    std::fs::write(&one, "x,y\n1,2\n").unwrap();
    let e = perturb_study::route::load(&one).unwrap_err().to_string();
    assert!(e.contains("one.csv") && e.contains("at least 2"), "{e}");
    let _ = std::fs::remove_dir_all(&dir);
}
