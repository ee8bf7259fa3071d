//! `perturb analyze` as a user runs it: synthetic runs written as rosbag2 bags, the tables, the
//! JSON with its stable field names, the map, bad input, `analyze compare` and `analyze
//! transfer`.

mod common;
#[path = "../../study/tests/support/mod.rs"]
mod support;

use common::{ok, perturb, tmp};
use serde_json::Value;
use support::{Run, route_length, write_route};

fn s(p: &std::path::Path) -> &str {
    p.to_str().unwrap()
}

/// A collision at `at` seconds under L-A9 s2, 0.3 m off the route.
fn collision_run(name: &str, at: f64) -> Run {
    let mut r = Run::new(name, at + 1.0);
    r.offset = Box::new(|_, _| 0.3);
    r.collision_at = Some(at);
    r.cond = Some(Box::new(|_| Some(("L-A9", 2))));
    r
}

#[test]
fn analyze_writes_tables_json_with_stable_fields_and_a_map() {
    let d = tmp("analyze-out");
    let runs = d.join("runs");
    std::fs::create_dir_all(&runs).unwrap();
    let route = d.join("route.csv");
    write_route(&route);
    let mut nominal = Run::new("nominal", route_length() / 10.0 + 1.0);
    nominal.steer = Some(Box::new(|k| if k.is_multiple_of(2) { 0.1 } else { -0.1 }));
    nominal.write(&runs);
    collision_run("crash_a", 6.0).write(&runs);
    collision_run("crash_b", 6.3).write(&runs);
    let mut under = Run::new("understeer", 15.0);
    under.offset = Box::new(|s, _| if s < 105.0 { 0.0 } else { -(s - 105.0) * 0.5 });
    under.cond = Some(Box::new(|_| Some(("C-A1", 3))));
    under.write(&runs);
    let out = d.join("out");
    let json = ok(&[
        "analyze",
        s(&runs),
        "--route",
        s(&route),
        "--pose-topic",
        "/odom",
        "--steering-topic",
        "/cmd",
        "--collision-topic",
        "/collision",
        "--out",
        s(&out),
        "--json",
    ]);
    let v: Value = serde_json::from_str(&json).unwrap();
    let fields = [
        "completion",
        "failure",
        "cte_avg",
        "cte_max",
        "jitter_avg",
        "jitter_max",
        "jitter_std",
        "coverage_5m",
        "duration_s",
        "perturbation",
        "severity",
    ];
    let runs_json = v["runs"].as_array().unwrap();
    assert_eq!(runs_json.len(), 4);
    for r in runs_json.iter().chain(v["conditions"].as_array().unwrap()) {
        for f in fields {
            assert!(r.get(f).is_some(), "`{f}` missing in {r}");
        }
    }
    for r in runs_json {
        assert!(r.get("run").is_some_and(|n| n.is_string()), "{r}");
    }
    let by = |name: &str| runs_json.iter().find(|r| r["run"] == name).unwrap();
    assert_eq!(by("crash_a")["failure"], "collision");
    assert_eq!(by("crash_a")["perturbation"], "L-A9");
    assert_eq!(by("crash_a")["severity"], 2);
    assert_eq!(by("understeer")["failure"], "understeer");
    assert_eq!(by("nominal")["failure"], Value::Null);
    assert!((by("nominal")["jitter_avg"].as_f64().unwrap() - 0.2).abs() < 1e-6);
    assert!(
        v["conditions"]
            .as_array()
            .unwrap()
            .iter()
            .all(|c| c.get("failure_rate").is_some())
    );
    // The two collisions 3 m apart make one hotspot; the understeer is noise.
    let clusters = v["hotspots"]["clusters"].as_array().unwrap();
    assert_eq!(clusters.len(), 1, "{clusters:?}");
    assert_eq!(clusters[0]["failure"], "collision");
    assert_eq!(clusters[0]["size"], 2);
    assert_eq!(clusters[0]["perturbations"][0][0], "L-A9");
    for f in [
        "runs.md",
        "runs.csv",
        "segments.csv",
        "conditions.md",
        "conditions.csv",
        "perturbations.md",
        "perturbations.csv",
        "hotspots.md",
        "analysis.json",
    ] {
        assert!(out.join(f).exists(), "{f} missing");
    }
    let md = std::fs::read_to_string(out.join("perturbations.md")).unwrap();
    assert!(
        md.contains("| L-A9 | fog") || md.contains("| L-A9 |"),
        "{md}"
    );
    assert!(md.contains("[C,C]"), "{md}");
    // The map, an SVG drawn with plotters: axes in metres, the route, trajectories coloured by
    // family, the hotspot's outline and label, the legend and the scale bar.
    let svg = std::fs::read_to_string(out.join("map.svg")).unwrap();
    assert!(svg.starts_with("<svg") && svg.trim_end().ends_with("</svg>"));
    let texts = svg_texts(&svg);
    for t in [
        "x (m)",
        "y (m)",
        "H0",
        "Legend",
        "Scale",
        "collision (C)",
        "in no hotspot (noise)",
        "nominal",
    ] {
        assert!(
            texts.iter().any(|x| x == t),
            "text `{t}` missing: {texts:?}"
        );
    }
    assert!(
        texts
            .iter()
            .any(|t| t.ends_with(" m") && t[..t.len() - 2].parse::<f64>().is_ok()),
        "no scale bar length: {texts:?}"
    );
    let upper = svg.to_ascii_uppercase();
    for (colour, what) in [
        ("#CDCDCD", "route"),
        ("#808080", "nominal trajectory"),
        ("#0072B2", "first family colour"),
        ("#C80000", "hotspot outline"),
    ] {
        assert!(upper.contains(colour), "no {what} ({colour})");
    }
    // The default output: tables with headings.
    let text = ok(&[
        "analyze",
        s(&runs),
        "--route",
        s(&route),
        "--pose-topic",
        "/odom",
        "--collision-topic",
        "/collision",
    ]);
    for h in [
        "== runs",
        "== per (perturbation, severity)",
        "== per perturbation",
        "== failure hotspots",
    ] {
        assert!(text.contains(h), "{h} missing:\n{text}");
    }
}

#[test]
fn bad_runs_are_named_with_the_topic_or_field_and_the_others_analysed() {
    let d = tmp("analyze-bad");
    let runs = d.join("runs");
    std::fs::create_dir_all(&runs).unwrap();
    let route = d.join("route.csv");
    write_route(&route);
    Run::new("good", 5.0).write(&runs);
    let mut no_pose = Run::new("no_pose", 5.0);
    no_pose.no_pose = true;
    no_pose.steer = Some(Box::new(|_| 0.0));
    no_pose.write(&runs);
    let mut stamped = Run::new("pose_stamped", 5.0);
    stamped.pose_stamped = true;
    stamped.write(&runs);
    // PoseStamped runs publish on /pose: use the Odometry field path on a topic both have.
    let o = perturb(&[
        "analyze",
        s(&runs),
        "--route",
        s(&route),
        "--pose-topic",
        "/odom",
        "--pose-field",
        "pose.pose.position",
        "--json",
    ]);
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("run `no_pose`") && err.contains("/odom"),
        "{err}"
    );
    assert!(err.contains("run `pose_stamped`"), "{err}");
    assert!(err.contains("2 of 3 runs could not be analysed"), "{err}");
    let v: Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(v["runs"].as_array().unwrap().len(), 1);
    assert_eq!(v["runs"][0]["run"], "good");
    assert_eq!(v["errors"].as_array().unwrap().len(), 2);
    // On its own topic, the PoseStamped run lacks the Odometry path: the field is named.
    let o = perturb(&[
        "analyze",
        s(&runs.join("pose_stamped")),
        "--pose-topic",
        "/pose",
        "--pose-field",
        "pose.pose.position",
    ]);
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("run `pose_stamped`")
            && err.contains("topic `/pose`")
            && err.contains("pose.pose.position.x")
            && err.contains("geometry_msgs/Pose"),
        "{err}"
    );
    // An unknown steering field.
    let o = perturb(&[
        "analyze",
        s(&runs.join("good")),
        "--pose-topic",
        "/odom",
        "--steering-topic",
        "/odom",
        "--steering-field",
        "twist.twist.angular.zz",
    ]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        !o.status.success() && err.contains("twist.twist.angular.zz") && err.contains("`zz`"),
        "{err}"
    );
    // A route with one point.
    let one = d.join("one_point.csv");
    std::fs::write(&one, "x,y\n3,4\n").unwrap();
    let o = perturb(&[
        "analyze",
        s(&runs),
        "--route",
        s(&one),
        "--pose-topic",
        "/odom",
    ]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        !o.status.success() && err.contains("one_point.csv") && err.contains("at least 2"),
        "{err}"
    );
    // A route without a pose topic.
    let o = perturb(&["analyze", s(&runs), "--route", s(&route)]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success() && err.contains("--pose-topic"), "{err}");
}

#[test]
fn compare_puts_two_sets_side_by_side_per_condition() {
    let d = tmp("analyze-compare");
    let route = d.join("route.csv");
    write_route(&route);
    for (set, crash) in [("ft", false), ("base", true)] {
        for cond in ["nominal", "mud"] {
            let dir = d.join(set).join(cond);
            std::fs::create_dir_all(&dir).unwrap();
            for k in 0..2 {
                let mut r = Run::new(&format!("run{k}"), route_length() / 10.0 + 1.0);
                r.offset = Box::new(move |_, _| if cond == "mud" { 0.6 } else { 0.2 });
                if crash && cond == "mud" {
                    r.collision_at = Some(5.0 + k as f64);
                } else {
                    r.collision_at = Some(1e9);
                }
                r.write(&dir);
            }
        }
    }
    let csv = ok(&[
        "analyze",
        "compare",
        "--set",
        &format!("FT={}", s(&d.join("ft"))),
        "--set",
        &format!("Non-FT={}", s(&d.join("base"))),
        "--route",
        s(&route),
        "--pose-topic",
        "/odom",
        "--collision-topic",
        "/collision",
        "--format",
        "csv",
    ]);
    let rows: Vec<Vec<&str>> = csv
        .lines()
        .skip(1)
        .map(|l| l.split(',').collect())
        .collect();
    let keys: Vec<(&str, &str)> = rows.iter().map(|r| (r[0], r[1])).collect();
    assert_eq!(
        keys,
        [
            ("nominal", "FT"),
            ("nominal", "Non-FT"),
            ("mud", "FT"),
            ("mud", "Non-FT")
        ],
        "{csv}"
    );
    assert_eq!(rows[2][4], "ok;ok");
    assert_eq!(rows[3][4], "C;C");
    // CTE over the shared non-failing portion (the default): 0.6 m in mud for both.
    for r in &rows[2..] {
        assert!((r[5].parse::<f64>().unwrap() - 0.6).abs() < 0.01, "{r:?}");
    }
}

#[test]
fn transfer_from_the_command_line() {
    let d = tmp("analyze-transfer");
    let off = d.join("off.csv");
    std::fs::write(
        &off,
        "id,severity,mse\nC-A1,1,0.1\nC-A1,2,0.3\nC-A1,3,0.2\nC-B1,1,0.5\nC-B1,2,0.9\nC-B1,3,0.4\n",
    )
    .unwrap();
    let cl = d.join("cl.csv");
    std::fs::write(
        &cl,
        "perturbation,severity,failure_rate,cte_avg\nC-A1,1,0,0.5\nC-A1,2,0.5,0.7\nC-A1,3,0,0.6\nC-B1,1,0.5,0.8\nC-B1,2,1,1.2\nC-B1,3,0.5,0.75\nnominal,-,0,0.4\n",
    )
    .unwrap();
    let json = ok(&[
        "analyze",
        "transfer",
        "--offline",
        s(&off),
        "--closed-loop",
        s(&cl),
        "--resamples",
        "200",
        "--top-k",
        "2",
        "--format",
        "json",
    ]);
    let v: Value = serde_json::from_str(&json).unwrap();
    assert_eq!(v["matched"], 6);
    let rows = v["rows"].as_array().unwrap();
    assert_eq!(rows.len(), 2);
    // mse and cte_avg have the same order: rho = 1; the top 2 coincide.
    let cte = rows.iter().find(|r| r["closed_loop"] == "cte_avg").unwrap();
    assert_eq!(cte["rho"].as_f64(), Some(1.0));
    assert_eq!(cte["top_k_overlap"].as_f64(), Some(1.0));
    assert_eq!(
        cte["top_offline"],
        serde_json::json!(["C-B1 s2", "C-B1 s1"])
    );
    let table = ok(&[
        "analyze",
        "transfer",
        "--offline",
        s(&off),
        "--closed-loop",
        s(&cl),
        "--resamples",
        "100",
    ]);
    assert!(
        table.contains("ci95_low") && table.contains("top5_overlap"),
        "{table}"
    );
}

/// A run recorded as a ROS 1 bag by an independent writer (Debian's Python `rosbag`): a vehicle
/// driving a straight 100 m route at 10 m/s, 0.5 m left of it while nominal and 1.0 m under C-C7
/// severity 3 from t = 5 s on, with the events in `/perturb/events` as `rosbag` writes strings.
#[test]
fn analyze_reads_a_ros1_bag_run_written_by_rosbag() {
    let python = std::env::var("PERTURB_ROS_PYTHON").unwrap_or_else(|_| "/usr/bin/python3".into());
    let have = std::process::Command::new(&python)
        .args(["-c", "import rosbag, geometry_msgs.msg, std_msgs.msg"])
        .status()
        .is_ok_and(|s| s.success());
    if !have {
        let what = "Debian's ROS 1 Python packages (apt-get install python3-rosbag python3-geometry-msgs python3-std-msgs)";
        assert!(
            std::env::var("PERTURB_REQUIRE_ORACLES").as_deref() != Ok("1"),
            "{what} are missing and PERTURB_REQUIRE_ORACLES=1"
        );
        eprintln!("SKIP: {what} are missing");
        return;
    }
    let d = tmp("analyze-ros1");
    let runs = d.join("runs");
    std::fs::create_dir_all(&runs).unwrap();
    let bag = runs.join("drive.bag");
    let script = r#"
import json, sys, rosbag, rospy
from geometry_msgs.msg import PoseStamped
from std_msgs.msg import String
t0 = 1_700_000_000
with rosbag.Bag(sys.argv[1], 'w') as b:
    for k in range(101):
        t = k / 10.0
        stamp = rospy.Time.from_sec(t0 + t)
        p = PoseStamped()
        p.header.seq = k
        p.header.stamp = stamp
        p.header.frame_id = 'map'
        p.pose.position.x = 10.0 * t
        p.pose.position.y = 0.5 if t < 5.0 else 1.0
        p.pose.orientation.w = 1.0
        b.write('/pose', p, stamp)
        perturbed = t >= 5.0
        ev = dict(topic='/camera/image_raw', stream='camera', seq=k, stamp_sec=t0, stamp_nanosec=0,
                  frame_id='camera', id='C-C7' if perturbed else None,
                  severity=3 if perturbed else None, seed=1 if perturbed else None)
        b.write('/perturb/events', String(data=json.dumps(ev)), stamp)
"#;
    let st = std::process::Command::new(&python)
        .args(["-c", script, s(&bag)])
        .status()
        .unwrap();
    assert!(st.success(), "the rosbag writer failed");
    let route = d.join("route.csv");
    std::fs::write(&route, "x,y\n0,0\n50,0\n100,0\n").unwrap();
    let json = ok(&[
        "analyze",
        s(&runs),
        "--route",
        s(&route),
        "--pose-topic",
        "/pose",
        "--json",
    ]);
    let v: Value = serde_json::from_str(&json).unwrap();
    let runs_json = v["runs"].as_array().unwrap();
    assert_eq!(runs_json.len(), 1, "{json}");
    assert_eq!(runs_json[0]["run"], "drive");
    assert!(
        (runs_json[0]["completion"].as_f64().unwrap() - 1.0).abs() < 0.02,
        "{}",
        runs_json[0]
    );
    let conds = v["conditions"].as_array().unwrap();
    let cond = |id: Value| {
        conds
            .iter()
            .find(|c| c["perturbation"] == id)
            .unwrap_or_else(|| panic!("no condition {id} in {conds:?}"))
    };
    let nominal = cond(Value::from("nominal"));
    let rain = cond(Value::from("C-C7"));
    assert_eq!(rain["severity"], 3);
    assert!(
        (nominal["cte_avg"].as_f64().unwrap() - 0.5).abs() < 1e-6,
        "{nominal}"
    );
    assert!(
        (rain["cte_avg"].as_f64().unwrap() - 1.0).abs() < 1e-6,
        "{rain}"
    );
    assert!(
        (rain["cte_max"].as_f64().unwrap() - 1.0).abs() < 1e-6,
        "{rain}"
    );
}

/// The text contents of an SVG's `<text>` elements, trimmed.
fn svg_texts(svg: &str) -> Vec<String> {
    svg.split("<text")
        .skip(1)
        .filter_map(|t| {
            let body = &t[t.find('>')? + 1..];
            Some(body[..body.find("</text>")?].trim().to_string())
        })
        .collect()
}

/// Before: without a route, a run that left the road by 3 m was `[ok]` with failure rate 0.00.
/// Now it is unjudged in every output, counted apart, with the reason; with the route it is a
/// road departure.
#[test]
fn runs_that_cannot_be_judged_are_unjudged_in_every_output() {
    let d = tmp("analyze-unjudged");
    let runs = d.join("runs");
    std::fs::create_dir_all(&runs).unwrap();
    let mut off = Run::new("off_road", route_length() / 10.0 + 1.0);
    off.offset = Box::new(|s, _| if s < 30.0 { 0.0 } else { 3.0 });
    off.write(&runs);
    let o = perturb(&["analyze", s(&runs), "--pose-topic", "/odom"]);
    assert!(o.status.success());
    let out = String::from_utf8_lossy(&o.stdout);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(out.contains("unjudged") && out.contains("[?]"), "{out}");
    assert!(!out.contains("[ok]"), "{out}");
    assert!(
        err.contains("1 run analysed: 0 ok, 0 failed, 1 unjudged") && err.contains("no route"),
        "{err}"
    );
    let json = ok(&["analyze", s(&runs), "--pose-topic", "/odom", "--json"]);
    let v: Value = serde_json::from_str(&json).unwrap();
    assert_eq!(v["runs"][0]["outcome"], "unjudged");
    assert_eq!(v["perturbations"][0]["failure_rate"], Value::Null);
    assert_eq!(v["summary"]["unjudged"], 1);
    let route = d.join("route.csv");
    write_route(&route);
    let json = ok(&[
        "analyze",
        s(&runs),
        "--pose-topic",
        "/odom",
        "--route",
        s(&route),
        "--json",
    ]);
    let v: Value = serde_json::from_str(&json).unwrap();
    assert_eq!(v["runs"][0]["outcome"], "failed");
    assert_eq!(v["runs"][0]["failure"], "road_departure");
}

/// Transfer over 2 pairs says so instead of printing CI [1.00, 1.00]; --latency leaves out the
/// pairs over their budget.
#[test]
fn transfer_names_too_few_pairs_and_leaves_out_infeasible_ones() {
    let d = tmp("analyze-transfer-few");
    let off = d.join("off.csv");
    std::fs::write(
        &off,
        "id,severity,mse\nC-A1,1,0.1\nC-A1,2,0.3\nC-B1,1,0.5\n",
    )
    .unwrap();
    let cl = d.join("cl.csv");
    std::fs::write(
        &cl,
        "perturbation,severity,cte_avg\nC-A1,1,0.5\nC-A1,2,0.7\nC-B1,1,0.9\n",
    )
    .unwrap();
    let bench = d.join("bench.csv");
    std::fs::write(
        &bench,
        "id,severity,mean_ms,max_ms,budget_ms\nC-A1,1,5,6,33\nC-A1,2,6,7,33\nC-B1,1,40,50,33\n",
    )
    .unwrap();
    let o = perturb(&[
        "analyze",
        "transfer",
        "--offline",
        s(&off),
        "--closed-loop",
        s(&cl),
        "--latency",
        s(&bench),
        "--resamples",
        "100",
    ]);
    assert!(o.status.success());
    let out = String::from_utf8_lossy(&o.stdout);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("1 (perturbation, severity) pair(s) left out") && err.contains("C-B1 s1"),
        "{err}"
    );
    assert!(
        err.contains("2 (perturbation, severity) pairs in both tables"),
        "{err}"
    );
    assert!(
        out.contains("note: mse vs cte_avg: only 2 matched pairs: fewer than 5"),
        "{out}"
    );
    let row = out.lines().find(|l| l.starts_with("mse")).unwrap();
    assert!(!row.contains("1.00  1.00"), "a CI over 2 pairs: {row}");
}
