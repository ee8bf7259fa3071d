//! What a reviewer checks before trusting the closed-loop numbers, on synthetic runs with known
//! ground truth: which files are runs, unjudged runs kept apart from ok ones, runs trimmed to the
//! route, truncated ROS 1 bags salvaged like MCAP, the paper's reference region, RQ4's shared
//! non-failing portion, events recorded apart, and signals that fire on a value.

mod support;

use perturb_study::analyze::{
    Aggregate, AnalyzeConfig, CteTo, Failure, Outcome, RunResult, TopicField, analyze_dir,
    load_events_bags, reference_from_runs,
};
use std::path::Path;
use support::{Layout, Run, route_length, route_point, tmp, write_route};

fn close(a: Option<f64>, b: f64, tol: f64, what: &str) {
    let a = a.unwrap_or_else(|| panic!("{what}: no value, expected {b}"));
    assert!((a - b).abs() <= tol, "{what}: {a} != {b} (tolerance {tol})");
}

fn odom() -> Option<TopicField> {
    Some(TopicField {
        topic: "/odom".into(),
        field: None,
    })
}

fn with_route(dir: &Path) -> AnalyzeConfig {
    let route = dir.join("route.csv");
    write_route(&route);
    AnalyzeConfig {
        route: Some(perturb_study::route::load(&route).unwrap()),
        pose: odom(),
        ..AnalyzeConfig::default()
    }
}

fn run<'a>(runs: &'a [RunResult], name: &str) -> &'a RunResult {
    runs.iter().find(|r| r.run == name).unwrap_or_else(|| {
        panic!(
            "no run {name} in {:?}",
            runs.iter().map(|r| &r.run).collect::<Vec<_>>()
        )
    })
}

/// Before: a folder holding `.mcap` files was one rosbag2 bag (its files merged by time, the
/// `.bag` and the sub-folders beside them ignored). Now each file is a run, a rosbag2 folder is
/// one run, another folder is a group, and anything else is listed as skipped.
#[test]
fn every_bag_file_and_rosbag2_folder_is_its_own_run() {
    let dir = tmp("layout");
    let runs_dir = dir.join("runs");
    std::fs::create_dir_all(runs_dir.join("mud")).unwrap();
    Run::new("a", 4.0).write_as(&runs_dir, Layout::McapFile);
    Run::new("b", 6.0).write_as(&runs_dir, Layout::McapFile);
    Run::new("c", 5.0).write_as(&runs_dir, Layout::Ros1Bag);
    Run::new("d", 3.0).write_as(&runs_dir, Layout::Rosbag2);
    Run::new("e", 2.0).write_as(&runs_dir.join("mud"), Layout::McapFile);
    std::fs::write(runs_dir.join("notes.txt"), "drive log").unwrap();
    let cfg = AnalyzeConfig {
        pose: odom(),
        ..AnalyzeConfig::default()
    };
    let a = analyze_dir(&runs_dir, &cfg).unwrap();
    assert!(a.errors.is_empty(), "{:?}", a.errors);
    let names: Vec<&str> = a.runs.iter().map(|r| r.run.as_str()).collect();
    assert_eq!(names, ["a", "b", "c", "d", "mud/e"]);
    // Each run is as long as its own recording (the last pose at duration - 0.08 s).
    for (name, secs) in [
        ("a", 4.0),
        ("b", 6.0),
        ("c", 5.0),
        ("d", 3.0),
        ("mud/e", 2.0),
    ] {
        let r = run(&a.runs, name);
        assert!(
            (r.metrics.duration_s - secs).abs() < 0.11,
            "{name}: {} s",
            r.metrics.duration_s
        );
    }
    assert_eq!(run(&a.runs, "mud/e").group.as_deref(), Some("mud"));
    assert_eq!(a.skipped.len(), 1, "{:?}", a.skipped);
    assert!(a.skipped[0].path.ends_with("notes.txt"));
    assert_eq!(a.summary.skipped, 1);
    // A folder of MCAP files given as one bag is still a folder of runs.
    let b = analyze_dir(&runs_dir.join("mud"), &cfg).unwrap();
    assert_eq!(b.runs.len(), 1);
    let _ = std::fs::remove_dir_all(&dir);
}

/// A run whose failure cannot be judged is `unjudged`, with the reason, never `ok`: the run
/// that leaves the road by 3 m passes as ok without a route before the change.
#[test]
fn runs_that_cannot_be_judged_are_unjudged_not_ok() {
    let dir = tmp("unjudged");
    let runs_dir = dir.join("runs");
    std::fs::create_dir_all(&runs_dir).unwrap();
    let dur = route_length() / 10.0 + 1.0;
    let mut off = Run::new("off_road", dur);
    off.offset = Box::new(|s, _| if s < 30.0 { 0.0 } else { 3.0 });
    off.write(&runs_dir);
    Run::new("clean", dur).write(&runs_dir);
    let no_route = AnalyzeConfig {
        pose: odom(),
        ..AnalyzeConfig::default()
    };
    let a = analyze_dir(&runs_dir, &no_route).unwrap();
    for r in &a.runs {
        assert_eq!(r.metrics.outcome, Outcome::Unjudged, "{}", r.run);
        assert_eq!(r.metrics.failure, None);
        assert!(
            r.metrics
                .unjudged_reason
                .as_deref()
                .is_some_and(|w| w.contains("no route")),
            "{:?}",
            r.metrics.unjudged_reason
        );
        for s in &r.segments {
            assert_eq!(s.metrics.outcome, Outcome::Unjudged);
        }
    }
    assert_eq!((a.summary.ok, a.summary.unjudged), (0, 2));
    let nominal = &a.perturbations[0];
    assert_eq!(nominal.metrics.unjudged, 2);
    assert_eq!(nominal.metrics.failure_rate, None, "nothing judged");
    assert_eq!(nominal.metrics.outcomes, [Outcome::Unjudged; 2]);
    let json = serde_json::to_value(&a).unwrap();
    assert_eq!(json["runs"][0]["outcome"], "unjudged");
    assert_eq!(
        json["perturbations"][0]["failure_rate"],
        serde_json::Value::Null
    );
    let table = perturb_study::analyze::render_perturbations(
        &a.perturbations,
        perturb_study::Format::Table,
    );
    assert!(table.contains("[?,?]"), "{table}");
    // Without a pose topic, the same.
    let a = analyze_dir(&runs_dir, &AnalyzeConfig::default()).unwrap();
    assert!(a.runs.iter().all(|r| {
        r.metrics.outcome == Outcome::Unjudged
            && r.metrics
                .unjudged_reason
                .as_deref()
                .unwrap()
                .contains("pose")
    }));
    // With the route, judged: one departure, one ok.
    let a = analyze_dir(&runs_dir, &with_route(&dir)).unwrap();
    assert_eq!(
        run(&a.runs, "off_road").metrics.failure,
        Some(Failure::RoadDeparture)
    );
    assert_eq!(run(&a.runs, "off_road").metrics.outcome, Outcome::Failed);
    assert_eq!(run(&a.runs, "clean").metrics.outcome, Outcome::Ok);
    assert_eq!(
        (a.summary.ok, a.summary.failed, a.summary.unjudged),
        (1, 1, 0)
    );
    close(
        a.perturbations[0].metrics.failure_rate,
        0.5,
        1e-12,
        "failure rate",
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// An 80 m route (x from 20 to 100 on the test track's first straight) while the recording
/// starts 20 m before it and goes on 120 m past its end (round the turn and north): before the
/// change the run was a road departure at t = 0 (20 m from the route's first point), and the CTE
/// went on counting after the goal (100 m on the northern straight). Trimmed, the run starts at
/// the route's start and ends at the goal.
#[test]
fn runs_are_trimmed_to_the_route() {
    let dir = tmp("trim");
    let runs_dir = dir.join("runs");
    std::fs::create_dir_all(&runs_dir).unwrap();
    let route_csv = dir.join("short.csv");
    std::fs::write(&route_csv, "x,y\n20,0\n60,0\n100,0\n").unwrap();
    let mut r = Run::new("long", 22.0);
    r.offset = Box::new(|_, _| 0.4);
    r.write(&runs_dir);
    let mut cfg = AnalyzeConfig {
        route: Some(perturb_study::route::load(&route_csv).unwrap()),
        pose: odom(),
        ..AnalyzeConfig::default()
    };
    let a = analyze_dir(&runs_dir, &cfg).unwrap();
    let got = &a.runs[0];
    assert_eq!(got.metrics.failure, None, "{got:?}");
    assert_eq!(got.metrics.outcome, Outcome::Ok);
    close(got.metrics.completion, 1.0, 1e-12, "completion");
    close(got.metrics.cte_avg, 0.4, 1e-9, "cte_avg");
    close(got.metrics.cte_max, 0.4, 1e-9, "cte_max");
    // At 10 m/s: within 3 m of (20, 0) from x = 17.1 (t = 1.72 s; the pose 0.4 m aside), the
    // goal within 3 m of (100, 0) at x = 97.2 (t = 9.72 s).
    let [start, end] = got.trimmed.expect("trimmed");
    close(Some(start), 1.72, 1e-9, "start");
    close(Some(end), 9.72, 1e-9, "end");
    close(Some(got.metrics.duration_s), 8.0, 1e-9, "duration");
    assert!(
        got.notes.iter().any(|n| n.contains("trimmed to the route")),
        "{:?}",
        got.notes
    );
    // Without trimming, the CTE counts the whole recording: after the goal it grows to 100 m
    // on the northern straight (the offset beyond the route's end is measured from the line of
    // its last segment; before its start, from the line of its first, so no departure at 0 s).
    cfg.trim_to_route = false;
    let a = analyze_dir(&runs_dir, &cfg).unwrap();
    assert_eq!(a.runs[0].metrics.failure, None);
    assert!(
        a.runs[0].metrics.cte_max.unwrap() > 90.0,
        "{:?}",
        a.runs[0].metrics
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// Before: "no pose topic (its topics: )" for a ROS 1 bag cut short, nothing recovered. Now the
/// messages before the cut are read, with the same note as a cut MCAP file.
#[test]
fn a_truncated_ros1_bag_is_read_up_to_the_damage_like_mcap() {
    let dir = tmp("truncated");
    let runs_dir = dir.join("runs");
    std::fs::create_dir_all(&runs_dir).unwrap();
    let mut r = Run::new("cut", 10.0);
    r.offset = Box::new(|_, _| 0.3);
    r.steer = Some(Box::new(|k| if k.is_multiple_of(2) { 0.1 } else { -0.1 }));
    let (bag, _) = r.write_as(&runs_dir, Layout::Ros1Bag);
    let (mcap, _) = r.write_as(&runs_dir, Layout::McapFile);
    for f in [&bag, &mcap] {
        let bytes = std::fs::read(f).unwrap();
        // Cut inside the data: 60% of the file (no index, the last chunk cut).
        std::fs::write(f, &bytes[..bytes.len() * 6 / 10]).unwrap();
    }
    // Two runs named `cut`: one folder each.
    let bag_dir = dir.join("bag");
    let mcap_dir = dir.join("mcap");
    std::fs::create_dir_all(&bag_dir).unwrap();
    std::fs::create_dir_all(&mcap_dir).unwrap();
    std::fs::rename(&bag, bag_dir.join("cut.bag")).unwrap();
    std::fs::rename(&mcap, mcap_dir.join("cut.mcap")).unwrap();
    let mut cfg = with_route(&dir);
    cfg.steering = Some(TopicField {
        topic: "/cmd".into(),
        field: None,
    });
    for d in [&bag_dir, &mcap_dir] {
        let a = analyze_dir(d, &cfg).unwrap();
        assert!(a.errors.is_empty(), "{}: {:?}", d.display(), a.errors);
        let got = &a.runs[0];
        assert!(
            got.notes
                .iter()
                .any(|n| n.contains("the bag is damaged; read up to the damage")),
            "{}: {:?}",
            d.display(),
            got.notes
        );
        // Several seconds of driving recovered, at the recorded offset and steering.
        assert!(
            got.metrics.duration_s > 3.0,
            "{}: {}",
            d.display(),
            got.metrics.duration_s
        );
        assert!(got.metrics.duration_s < 9.0);
        assert_eq!(got.metrics.failure, Some(Failure::Incomplete));
        close(got.metrics.jitter_avg, 0.2, 1e-6, "jitter");
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// Three nominal drives with a known lateral spread that varies along the route, c_k + 0.2
/// sin(s / 8) with c = -0.5, 0, 0.4: the region at arc length s is [-0.5 + w(s), 0.4 + w(s)].
/// A run inside it has CTE 0; a run 0.6 m left of its left edge has CTE 0.6 everywhere.
#[test]
fn cte_against_the_reference_region_of_three_nominal_drives() {
    let dir = tmp("region");
    let nominal_dir = dir.join("nominal");
    let runs_dir = dir.join("runs");
    std::fs::create_dir_all(&nominal_dir).unwrap();
    std::fs::create_dir_all(&runs_dir).unwrap();
    let w = |s: f64| 0.2 * (s / 8.0).sin();
    let dur = route_length() / 10.0 + 1.0;
    for (k, c) in [-0.5, 0.0, 0.4].into_iter().enumerate() {
        let mut r = Run::new(&format!("nominal{k}"), dur);
        r.offset = Box::new(move |s, _| c + w(s));
        r.write(&nominal_dir);
    }
    let mut inside = Run::new("inside", dur);
    inside.offset = Box::new(move |s, _| 0.1 + w(s));
    inside.write(&runs_dir);
    let mut outside = Run::new("outside", dur);
    outside.offset = Box::new(move |s, _| 1.0 + w(s));
    outside.write(&runs_dir);
    let mut right = Run::new("right", dur);
    right.offset = Box::new(move |s, _| -0.9 + w(s));
    right.write(&runs_dir);
    let mut cfg = with_route(&dir);
    let set = reference_from_runs(&nominal_dir, &cfg, 1.0).unwrap();
    assert!(!set.derived_route);
    assert_eq!(set.region.runs.len(), 3);
    // The band at a few arc lengths, against its construction (the route polyline's chords on
    // the turn move the offsets by up to a few millimetres).
    for s in [10.0, 55.5, 110.0, 170.0] {
        let (lo, hi) = set.region.band_at(s);
        assert!(
            (lo - (-0.5 + w(s))).abs() < 0.01 && (hi - (0.4 + w(s))).abs() < 0.01,
            "{s}: {lo} {hi}"
        );
    }
    cfg.route = Some(set.route.clone());
    cfg.reference = Some(set.region.clone());
    let a = analyze_dir(&runs_dir, &cfg).unwrap();
    close(
        run(&a.runs, "inside").metrics.cte_max,
        0.0,
        1e-9,
        "inside max",
    );
    close(
        run(&a.runs, "outside").metrics.cte_avg,
        0.6,
        0.01,
        "outside avg",
    );
    close(
        run(&a.runs, "outside").metrics.cte_max,
        0.6,
        0.01,
        "outside max",
    );
    close(
        run(&a.runs, "right").metrics.cte_avg,
        0.4,
        0.01,
        "right avg",
    );
    assert!(
        a.summary
            .cte_reference
            .contains("reference region (3 nominal drives)")
    );
    // The same runs against the route polyline (the former definition, now an option).
    cfg.cte_to = CteTo::Route;
    let b = analyze_dir(&runs_dir, &cfg).unwrap();
    let mean_abs = |c: f64| {
        let n = 2000;
        (0..n)
            .map(|i| (c + w(route_length() * i as f64 / n as f64)).abs())
            .sum::<f64>()
            / n as f64
    };
    close(
        run(&b.runs, "outside").metrics.cte_avg,
        mean_abs(1.0),
        0.02,
        "outside to the route",
    );
    // Without a route, the drives' centre line is the route: the same CTE.
    let mut no_route = AnalyzeConfig {
        pose: odom(),
        ..AnalyzeConfig::default()
    };
    let set = reference_from_runs(&nominal_dir, &no_route, 1.0).unwrap();
    assert!(set.derived_route);
    close(
        Some(set.route.length()),
        route_length(),
        1.5,
        "centre line length",
    );
    no_route.route = Some(set.route);
    no_route.reference = Some(set.region);
    let c = analyze_dir(&runs_dir, &no_route).unwrap();
    close(
        run(&c.runs, "outside").metrics.cte_avg,
        0.6,
        0.02,
        "outside, derived route",
    );
    // Inside the band everywhere but at the very first pose, 0.27 m along, before the first
    // arc length all three drives passed (the band there is that of 1 m along).
    let ins = run(&c.runs, "inside");
    let outside_band = ins.track.cte.iter().filter(|c| c.abs() > 1e-9).count();
    assert!(outside_band <= 1, "{:?}", ins.track.cte);
    close(ins.metrics.cte_max, 0.0, 0.05, "inside, derived route");
    close(ins.metrics.cte_avg, 0.0, 0.001, "inside, derived route");
    assert_eq!(run(&c.runs, "inside").metrics.outcome, Outcome::Ok);
    let _ = std::fs::remove_dir_all(&dir);
}

/// RQ4: in `mud`, the fine-tuned run completes 0.3 m off the route; the baseline run is 0.3 m
/// off up to 60 m, then 1.2 m off, and collides at 80 m. The shared non-failing portion ends
/// 5 m (d) before the earliest failure: at 75 m. Over it the fine-tuned CTE is 0.3; the
/// baseline's is the mean over its poses up to 75 m.
#[test]
fn compare_restricts_trajectory_metrics_to_the_shared_non_failing_portion() {
    let dir = tmp("shared");
    let dur = route_length() / 10.0 + 1.0;
    let ft = dir.join("ft").join("mud");
    let base = dir.join("base").join("mud");
    std::fs::create_dir_all(&ft).unwrap();
    std::fs::create_dir_all(&base).unwrap();
    let mut a = Run::new("run1", dur);
    a.offset = Box::new(|_, _| 0.3);
    a.steer = Some(Box::new(|k| if k.is_multiple_of(2) { 0.1 } else { -0.1 }));
    a.collision_at = Some(1e9);
    a.write(&ft);
    let mut b = Run::new("run1", dur);
    b.offset = Box::new(|s, _| if s < 60.0 { 0.3 } else { 1.2 });
    b.steer = Some(Box::new(|k| {
        if k < 60 {
            0.0
        } else if k.is_multiple_of(2) {
            0.4
        } else {
            -0.4
        }
    }));
    b.collision_at = Some(8.0);
    b.write(&base);
    let mut cfg = with_route(&dir);
    cfg.steering = Some(TopicField {
        topic: "/cmd".into(),
        field: None,
    });
    cfg.collision = Some(TopicField {
        topic: "/collision".into(),
        field: None,
    });
    cfg.aggregate = Aggregate::Shared;
    let sets = vec![
        (
            "FT".to_string(),
            analyze_dir(&dir.join("ft"), &cfg).unwrap(),
        ),
        (
            "Non-FT".to_string(),
            analyze_dir(&dir.join("base"), &cfg).unwrap(),
        ),
    ];
    let rows = perturb_study::compare::compare(&sets, &cfg);
    assert_eq!(rows.len(), 2);
    // The collision at 8 s: the last pose before it is at 7.92 s, 79.2 m along.
    let until = 79.2 - 5.0;
    for r in &rows {
        close(r.shared_until_m, until, 1e-6, "shared portion");
    }
    close(
        rows[0].metrics.cte_avg,
        0.3,
        1e-9,
        "FT cte over the shared portion",
    );
    // Baseline poses at 10 m/s from 0.2 m: s = 0.2 + k, up to s <= 74.2.
    let offsets: Vec<f64> = (0..)
        .map(|k| 0.2 + k as f64)
        .take_while(|s| *s <= until)
        .map(|s| if s < 60.0 { 0.3 } else { 1.2 })
        .collect();
    let want = offsets.iter().sum::<f64>() / offsets.len() as f64;
    close(
        rows[1].metrics.cte_avg,
        want,
        1e-9,
        "Non-FT cte over the shared portion",
    );
    close(rows[1].metrics.cte_max, 1.2, 1e-9, "Non-FT cte max");
    // Jitter over the commands up to the end of the shared portion (t <= 7.42 s): 0 for the
    // first 60 commands, then 0.8 per change.
    let cmds: Vec<f64> = (0..)
        .map(|k: usize| (k, k as f64 / 10.0 + 0.05))
        .take_while(|(_, t)| *t <= until / 10.0 + 0.02)
        .map(|(k, _)| {
            if k < 60 {
                0.0
            } else if k.is_multiple_of(2) {
                0.4
            } else {
                -0.4
            }
        })
        .collect();
    let d: Vec<f64> = cmds.windows(2).map(|w| (w[1] - w[0]).abs()).collect();
    let jit = d.iter().sum::<f64>() / d.len() as f64;
    close(
        rows[1].metrics.jitter_avg,
        jit,
        1e-6,
        "Non-FT jitter over the shared portion",
    );
    // Each to its own failure (--aggregate all): the baseline's CTE also covers 75 to 79.2 m,
    // less the last 5 m before its failure.
    cfg.aggregate = Aggregate::All;
    let rows = perturb_study::compare::compare(&sets, &cfg);
    assert_eq!(rows[0].shared_until_m, None);
    close(
        rows[0].metrics.cte_avg,
        0.3,
        0.001,
        "FT over the whole route",
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// On the vehicle the ADS's topics and the perturbation events come from two recorders: the
/// events bag (perturb-bridge record) is matched to the run by log time.
#[test]
fn events_recorded_apart_are_matched_to_the_run_by_time() {
    let dir = tmp("events-apart");
    let runs_dir = dir.join("runs");
    let events_dir = dir.join("events");
    std::fs::create_dir_all(&runs_dir).unwrap();
    std::fs::create_dir_all(&events_dir).unwrap();
    let cond = |t: f64| if t < 4.0 { None } else { Some(("C-B1", 3)) };
    // The vehicle's bag: poses only, from 0.02 s to 9 s; the events recorder ran from 0 s to
    // 12 s.
    let mut vehicle = Run::new("vehicle", 9.0);
    vehicle.cond = None;
    vehicle.write(&runs_dir);
    let mut events = Run::new("events", 12.0);
    events.no_pose = true;
    events.cond = Some(Box::new(cond));
    events.write(&events_dir);
    let ext = load_events_bags(&events_dir, perturb_bag::events::EVENTS_TOPIC).unwrap();
    assert_eq!(ext.events.len(), 121);
    let cfg = AnalyzeConfig {
        pose: odom(),
        external_events: Some(std::sync::Arc::new(ext)),
        ..AnalyzeConfig::default()
    };
    let a = analyze_dir(&runs_dir, &cfg).unwrap();
    let r = &a.runs[0];
    let segs: Vec<(&str, f64)> = r
        .segments
        .iter()
        .map(|s| (s.perturbation.as_str(), s.start_s))
        .collect();
    // The vehicle bag's first message is its first pose at 0.02 s; the switch at 4.0 s.
    assert_eq!(segs.len(), 2, "{segs:?}");
    assert_eq!(segs[0].0, "nominal");
    assert_eq!(segs[1].0, "C-B1");
    close(Some(segs[1].1), 4.0 - 0.02, 1e-9, "switch time");
    assert!(
        r.notes.iter().any(|n| n.contains("recorded apart")),
        "{:?}",
        r.notes
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// A takeover given as a value the field changes to (Autoware Mini's drive mode turning
/// manual): the first message equal to it after one that was not; a signal already at that
/// value from the first message does not fire.
#[test]
fn a_signal_with_a_value_fires_when_the_field_changes_to_it() {
    let dir = tmp("signal-value");
    let runs_dir = dir.join("runs");
    std::fs::create_dir_all(&runs_dir).unwrap();
    let mut r = Run::new("takeover", 12.0);
    r.collision_at = Some(6.0);
    r.write(&runs_dir);
    let (p, _) = route_point(0.0);
    assert_eq!(p, [0.0, 0.0]);
    let mut cfg = with_route(&dir);
    cfg.takeover = Some(TopicField {
        topic: "/collision".into(),
        field: None,
    });
    cfg.takeover_value = Some("true".into());
    let a = analyze_dir(&runs_dir, &cfg).unwrap();
    assert_eq!(a.runs[0].metrics.failure, Some(Failure::Takeover));
    close(a.runs[0].failure_time_s, 6.0, 1e-9, "takeover time");
    // `false` is the value from the first message on: never a change to it.
    cfg.takeover_value = Some("false".into());
    let a = analyze_dir(&runs_dir, &cfg).unwrap();
    assert_ne!(a.runs[0].metrics.failure, Some(Failure::Takeover));
    let _ = std::fs::remove_dir_all(&dir);
}

/// The events of the bridge's safety envelope and campaigns (records of version 2): segments
/// follow the campaign step; frames that went out raw because perturbd was late or down keep the
/// run under its perturbation (counted in a note), a gap record's loss is noted, kill and arm
/// records change nothing by themselves (the frames after them say what the ADS got).
#[test]
fn version_2_events_group_segments_by_step_and_count_fallbacks_and_gaps() {
    use perturb_bag::events::{EventKind, EventRecord};
    let dir = tmp("events-v2");
    let runs_dir = dir.join("runs");
    std::fs::create_dir_all(&runs_dir).unwrap();
    let mut r = Run::new("campaign", 8.0);
    // C-A1 s2 from 2 s to 6 s: campaign step 1 until 4 s, step 2 after; raw at 3.0-3.2 s
    // (late); a gap of 7 frames (daemon down) at 5 s; the kill switch at 6 s.
    r.cond = Some(Box::new(|t| (2.0..6.0).contains(&t).then_some(("C-A1", 2))));
    r.records = Some(Box::new(|k, t, mut ev: EventRecord| {
        if ev.applied {
            ev.step = Some(if t < 4.0 { 1 } else { 2 });
        }
        let mut out = Vec::new();
        if (3.0..3.25).contains(&t) {
            ev.id = None;
            ev.severity = None;
            ev.seed = None;
            ev.applied = false;
            ev.reason = Some("late".into());
            ev.step = None;
        }
        if k == 50 {
            out.push(EventRecord::gap(
                "camera",
                "/camera/image",
                50,
                "daemon_down",
                7,
                0,
            ));
        }
        if k == 60 {
            out.push(EventRecord::kill(true, "takeover", 0));
            assert_eq!(out[0].kind, EventKind::Kill);
        }
        if t >= 6.0 {
            ev.reason = Some("killed".into());
        }
        out.push(ev);
        out
    }));
    r.write(&runs_dir);
    let cfg = AnalyzeConfig {
        pose: odom(),
        ..AnalyzeConfig::default()
    };
    let a = analyze_dir(&runs_dir, &cfg).unwrap();
    assert!(a.errors.is_empty(), "{:?}", a.errors);
    let run = run(&a.runs, "campaign");
    let segs: Vec<(String, Option<u8>, Option<u16>, f64)> = run
        .segments
        .iter()
        .map(|s| (s.perturbation.clone(), s.severity, s.step, s.start_s))
        .collect();
    let want = [
        ("nominal", None, None, 0.0),
        ("C-A1", Some(2), Some(1), 2.0),
        ("C-A1", Some(2), Some(2), 4.0),
        ("nominal", None, None, 6.0),
    ];
    assert_eq!(segs.len(), want.len(), "{segs:?}");
    for (got, want) in segs.iter().zip(want) {
        assert_eq!(
            (got.0.as_str(), got.1, got.2),
            (want.0, want.1, want.2),
            "{segs:?}"
        );
        assert!((got.3 - want.3).abs() < 0.11, "{segs:?}");
    }
    let notes = run.notes.join("\n");
    assert!(notes.contains("3 late"), "{notes}");
    assert!(notes.contains("7 daemon_down"), "{notes}");
}
