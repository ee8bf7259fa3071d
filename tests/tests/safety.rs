//! The safety envelope, end to end through real processes: synthetic camera and LiDAR ->
//! perturb-bridge -> perturbd -> perturb-bridge -> a rospy subscriber (camera) and an independent
//! Cyclone DDS subscriber (LiDAR) standing in for the ADS, with faults injected by signals:
//!
//! - `kill -9` of perturbd and a restart, then a SIGSTOP/SIGCONT of it: the ADS side receives
//!   every frame the sensors sent, raw in place of the perturbed ones while the daemon is down or
//!   stalled, and every such frame is counted by its reason in the bridge's report, in
//!   `perturb ctl stats` and on the events topic;
//! - the kill switch from a ROS 1 topic (`std_msgs/Bool`): raw frames from the next frame on,
//!   latched in the daemon across its restart, released by `perturb ctl arm`; and the dead man
//!   (the topic's publisher goes away);
//! - a campaign with route and geofence steps, driven by a pose topic: each step fires where it
//!   says, and the frames' events carry the step.
//!
//! The measured figures are printed (`--nocapture`); the assertions are on counts and order,
//! with time bounds far from the measured values (the ADS never waits seconds).

use perturb_tests::{
    Namespace, Ros1Master, collect_lines, dds_peer, have_python_modules, have_ros1, kill_all,
    largest_gap_ms, ros1_peer, ros1_ready, signal, start_bridge, stdout_of,
};
use serde_json::Value;
use std::path::Path;
use std::process::Child;
use std::time::{Duration, Instant};

fn interrupt(c: &mut Child) -> bool {
    perturb_wire::process::interrupt(c, Duration::from_secs(15)).is_some_and(|s| s.success())
}

fn log(ns: &Namespace, name: &str) -> String {
    std::fs::read_to_string(ns.dir.join(name)).unwrap_or_default()
}

/// The report entry of the adapter whose name contains `part`.
fn adapter<'a>(report: &'a Value, part: &str) -> &'a Value {
    report
        .as_array()
        .expect("a report array")
        .iter()
        .find(|r| r["name"].as_str().is_some_and(|n| n.contains(part)))
        .unwrap_or_else(|| panic!("no adapter `{part}` in {report}"))
}

fn stream<'a>(stats: &'a Value, name: &str) -> &'a Value {
    stats
        .as_array()
        .unwrap()
        .iter()
        .find(|s| s["name"] == name)
        .unwrap_or_else(|| panic!("no stream {name} in {stats}"))
}

/// The events records a rospy subscriber of `/perturb/events` printed.
fn records(lines: &[Value]) -> Vec<Value> {
    lines
        .iter()
        .filter_map(|l| serde_json::from_str(l["data"].as_str()?).ok())
        .collect()
}

fn have_everything() -> bool {
    have_ros1() && have_python_modules("python3", &["cyclonedds"], "pip install cyclonedds") && {
        let ok = perturb_bridge::dds::cyclone::available().is_ok();
        if !ok {
            assert!(
                std::env::var("PERTURB_REQUIRE_ORACLES").ok().as_deref() != Some("1"),
                "libddsc (apt-get install libddsc0debian) is missing and PERTURB_REQUIRE_ORACLES=1"
            );
            eprintln!("SKIP: libddsc is missing");
        }
        ok
    }
}

fn write(path: &Path, text: &str) {
    std::fs::write(path, text).unwrap();
}

/// Sequence numbers a subscriber received, in arrival order.
fn seqs(lines: &[Value]) -> Vec<u64> {
    lines.iter().filter_map(|l| l["seq"].as_u64()).collect()
}

/// Starts the ADS side's subscribers: rospy on the camera topic and the events topic, Cyclone
/// DDS on the LiDAR topic; returns them with their line collectors. `hash`: the subscribers
/// print the sha256 of each frame's data.
fn ads_side_with(
    master: &Ros1Master,
    domain: u16,
    hash: bool,
) -> (Vec<Child>, Vec<std::thread::JoinHandle<Vec<Value>>>) {
    let mut children = Vec::new();
    let mut lines = Vec::new();
    for (topic, ty, name) in [
        ("/ads/camera", "image", "cam"),
        ("/perturb/events", "string", "ev"),
    ] {
        let mut args = vec![
            "sub",
            "--topic",
            topic,
            "--type",
            ty,
            "--count",
            "1000000",
            "--timeout",
            "120",
            "--name",
            name,
        ];
        if !hash {
            args.push("--no-hash");
        }
        let mut c = ros1_peer(master, &args);
        lines.push(collect_lines(ros1_ready(&mut c)));
        children.push(c);
    }
    let dom = domain.to_string();
    let mut lid = dds_peer(&[
        "listen",
        "--topic",
        "/ads/lidar",
        "--type",
        "cloud",
        "--count",
        "1000000",
        "--timeout",
        "120",
        "--domain",
        &dom,
    ]);
    lines.push(collect_lines(stdout_of(&mut lid)));
    children.push(lid);
    (children, lines)
}

fn ads_side(
    master: &Ros1Master,
    domain: u16,
) -> (Vec<Child>, Vec<std::thread::JoinHandle<Vec<Value>>>) {
    ads_side_with(master, domain, false)
}

fn ads_side_hashed(
    master: &Ros1Master,
    domain: u16,
) -> (Vec<Child>, Vec<std::thread::JoinHandle<Vec<Value>>>) {
    ads_side_with(master, domain, true)
}

/// The bridge of these tests: synthetic camera (320x200, 30 Hz) and VLP-32C (10 Hz), the camera
/// to ROS 1, the LiDAR to ROS 2 (Cyclone DDS), events on ROS 1; `extra` appended.
fn bridge_config(ns: &Namespace, domain: u16, extra: &str) -> std::path::PathBuf {
    let cfg = ns.dir.join("bridge.toml");
    write(
        &cfg,
        &format!(
            "[bridge]\nname = \"safety\"\nreport = \"{}\"\n\n[ros1]\nhostname = \"127.0.0.1\"\n\n\
             [dds]\nbackend = \"cyclone\"\ndomain_id = {domain}\ninterfaces = [\"lo\"]\n\n\
             [[synthetic.camera]]\nstream = \"cam\"\nwidth = 320\nheight = 200\nrate_hz = 30\nprerender = 8\n\n\
             [[synthetic.lidar]]\nstream = \"lid\"\nrate_hz = 10\nprerender = 4\n\n\
             [[egress]]\nstream = \"cam\"\ntopic = \"/ads/camera\"\ntransport = \"ros1\"\n\n\
             [[egress]]\nstream = \"lid\"\ntopic = \"/ads/lidar\"\ntransport = \"dds\"\n\n\
             [events]\ntopic = \"/perturb/events\"\ntransport = \"ros1\"\n{extra}",
            ns.dir.join("bridge-report.json").display()
        ),
    );
    cfg
}

const DAEMON: &str = "[[streams]]\nname = \"cam\"\nmodality = \"camera\"\n\
     perturbation = { id = \"C-A1\", severity = 2, seed = 1 }\n\n\
     [[streams]]\nname = \"lid\"\nmodality = \"lidar\"\nsensor = \"vlp32c\"\n\
     perturbation = { id = \"L-B1\", severity = 1, seed = 1 }\n";

fn domain_of(offset: u16) -> u16 {
    (std::process::id() % 50) as u16 * 4 + 21 + offset
}

/// Every sequence number from the first received to the last, once and in order.
fn contiguous(name: &str, s: &[u64]) {
    assert!(!s.is_empty(), "{name}: nothing received");
    for w in s.windows(2) {
        assert_eq!(
            w[1],
            w[0] + 1,
            "{name}: frames missing or out of order between {} and {}",
            w[0],
            w[1]
        );
    }
}

#[test]
fn the_ads_keeps_receiving_every_frame_through_a_daemon_crash_and_stall() {
    if !have_everything() {
        return;
    }
    let ns = Namespace::new("safety-faults");
    let master = Ros1Master::start(&ns.dir);
    let domain = domain_of(0);
    let daemon_cfg = ns.dir.join("perturbd.toml");
    write(&daemon_cfg, DAEMON);
    let bridge_cfg = bridge_config(&ns, domain, "");
    let mut daemon = ns.start_daemon(&daemon_cfg);
    let (mut peers, lines) = ads_side(&master, domain);
    let mut bridge = start_bridge(&ns, Some(&master), &bridge_cfg, "bridge.log");
    std::thread::sleep(Duration::from_secs(4));
    // perturbd crashes; it is back 2 s later.
    let t_kill = Instant::now();
    daemon.kill9();
    std::thread::sleep(Duration::from_secs(2));
    let mut daemon2 = ns.start_daemon(&daemon_cfg);
    let restart = t_kill.elapsed();
    std::thread::sleep(Duration::from_secs(3));
    // perturbd freezes for 2 s.
    let pid = daemon2.pid().expect("the daemon runs");
    signal(pid, libc::SIGSTOP);
    std::thread::sleep(Duration::from_secs(2));
    signal(pid, libc::SIGCONT);
    std::thread::sleep(Duration::from_secs(2));
    let stats = ns.stats();
    assert!(interrupt(&mut bridge), "{}", log(&ns, "bridge.log"));
    std::thread::sleep(Duration::from_millis(500));
    kill_all(&mut peers);
    let mut got = lines.into_iter().map(|h| h.join().unwrap());
    let (cam, ev, lid) = (
        got.next().unwrap(),
        got.next().unwrap(),
        got.next().unwrap(),
    );
    let _ = daemon2.stop();
    let rep: Value =
        serde_json::from_str(&std::fs::read_to_string(ns.dir.join("bridge-report.json")).unwrap())
            .unwrap();
    let bridge_log = log(&ns, "bridge.log");
    let eg_cam = adapter(&rep, "egress cam/perturbed");
    let eg_lid = adapter(&rep, "egress lid/perturbed");
    let src_cam = adapter(&rep, "synthetic camera");

    // The ADS got every frame from its first on, once, in order, at the sensors' rate.
    contiguous("camera", &seqs(&cam));
    let cam_seqs = seqs(&cam);
    assert_eq!(
        eg_cam["forwarded"].as_u64().unwrap(),
        src_cam["forwarded"].as_u64().unwrap(),
        "the egress published as many frames as the camera sent: {eg_cam}\n{src_cam}"
    );
    // Frames sent before rospy's link was up are nobody's loss (how many depends on how fast
    // this machine starts rospy); from its first frame on, every one but the last few in flight
    // when the test stops.
    let first = cam_seqs[0];
    assert!(
        first <= 30,
        "rospy's first frame was seq {first}: the link took over a second"
    );
    assert!(
        cam_seqs.len() as u64 + first + 3 >= src_cam["forwarded"].as_u64().unwrap(),
        "frames missing at the rospy subscriber after its first (seq {first}): {} of {}",
        cam_seqs.len(),
        src_cam["forwarded"]
    );
    assert!(
        lid.len() >= 100,
        "LiDAR frames at the DDS subscriber: {}",
        lid.len()
    );
    let (gap_cam, gap_lid) = (largest_gap_ms(&cam), largest_gap_ms(&lid));
    eprintln!(
        "camera: {} frames at the ADS, largest gap {gap_cam:.1} ms; LiDAR: {} frames, largest gap {gap_lid:.1} ms; \
         perturbd answering again {:.2} s after kill -9",
        cam.len(),
        lid.len(),
        restart.as_secs_f64()
    );
    assert!(
        gap_cam < 1000.0 && gap_lid < 1000.0,
        "the ADS went blind: {gap_cam} / {gap_lid} ms"
    );

    // Every raw frame published in place of a perturbed one is counted by its reason.
    for eg in [eg_cam, eg_lid] {
        let f = &eg["fallback_raw"];
        assert!(
            f["daemon_down"].as_u64().unwrap() > 0,
            "no daemon_down fallback: {eg}\n{bridge_log}"
        );
        assert!(
            f["late"].as_u64().unwrap() > 0,
            "no late fallback (SIGSTOP): {eg}"
        );
        assert_eq!(eg["lost_by_cause"]["daemon_down"], 0, "{eg}");
    }
    // The daemon counts what it missed: while it was down, and while it was stopped.
    let s = stream(&stats, "cam");
    assert!(s["lost"]["daemon_down"].as_u64().unwrap() > 0, "{s}");
    assert!(s["lost"]["daemon_late"].as_u64().unwrap() > 0, "{s}");
    assert_eq!(s["lost"]["upstream"], 0, "no sensor loss: {s}");

    // The events say, frame by frame, what the ADS got: perturbed, or raw and why.
    let recs = records(&ev);
    let cam_recs: Vec<&Value> = recs
        .iter()
        .filter(|r| r["kind"] == "frame" && r["stream"] == "cam")
        .collect();
    for reason in ["daemon_down", "late"] {
        assert!(
            cam_recs
                .iter()
                .any(|r| r["applied"] == false && r["reason"] == reason),
            "no `{reason}` frame record"
        );
    }
    assert!(
        cam_recs
            .iter()
            .any(|r| r["applied"] == true && r["id"] == "C-A1")
    );
    let fallback_records = cam_recs.iter().filter(|r| r["applied"] == false).count() as u64;
    let counted = eg_cam["fallback_raw"]["daemon_down"].as_u64().unwrap()
        + eg_cam["fallback_raw"]["late"].as_u64().unwrap();
    assert_eq!(fallback_records, counted, "events and report agree");
    assert_eq!(recs[0]["version"], 2);
    valid_against_the_schema(&ns, &recs);
}

/// Every record validates against docs/events.schema.json (the PyPI `jsonschema` package).
fn valid_against_the_schema(ns: &Namespace, recs: &[Value]) {
    if !have_python_modules("python3", &["jsonschema"], "pip install jsonschema") {
        return;
    }
    let file = ns.dir.join("records.json");
    std::fs::write(&file, serde_json::to_string(recs).unwrap()).unwrap();
    let schema = perturb_tests::workspace().join("docs/events.schema.json");
    let o = std::process::Command::new("python3")
        .args([
            "-c",
            "import json, sys, jsonschema\n\
             schema = json.load(open(sys.argv[1]))\n\
             v = jsonschema.Draft202012Validator(schema)\n\
             bad = [(r, e.message) for r in json.load(open(sys.argv[2])) for e in v.iter_errors(r)]\n\
             print(bad[:3]); sys.exit(1 if bad else 0)",
        ])
        .arg(&schema)
        .arg(&file)
        .output()
        .unwrap();
    assert!(
        o.status.success(),
        "records that do not match docs/events.schema.json: {}{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    );
}

/// sha256 of every raw frame the bridge recorded, by (stream topic, stamp).
fn raw_hashes(bag: &Path) -> std::collections::HashMap<(String, i64, i64), String> {
    perturb_tests::read_bag(bag)
        .into_iter()
        .filter_map(|m| {
            Some((
                (
                    m["topic"].as_str()?.to_string(),
                    m["sec"].as_i64()?,
                    m["nanosec"].as_i64()?,
                ),
                m["sha256"].as_str()?.to_string(),
            ))
        })
        .collect()
}

fn ctl_status(ns: &Namespace) -> String {
    let o = ns.ctl(&["status"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    String::from_utf8_lossy(&o.stdout).into_owned()
}

#[test]
fn the_kill_switch_returns_every_stream_to_raw_at_once_and_holds_until_armed() {
    if !have_everything() || !perturb_tests::have_rosbags() {
        return;
    }
    let ns = Namespace::new("safety-kill");
    let master = Ros1Master::start(&ns.dir);
    let domain = domain_of(1);
    let daemon_cfg = ns.dir.join("perturbd.toml");
    write(&daemon_cfg, DAEMON);
    let rec = ns.dir.join("raw");
    let bridge_cfg = bridge_config(
        &ns,
        domain,
        &format!(
            "\n[kill]\ntopic = \"/vehicle/takeover\"\ntransport = \"ros1\"\ndeadman_s = 1.0\n\n\
             [record]\nout = \"{}\"\nstreams = [\"cam\", \"lid\"]\nraw = true\nperturbed = false\n",
            rec.display()
        ),
    );
    let mut daemon = ns.start_daemon(&daemon_cfg);
    let (mut peers, lines) = ads_side_hashed(&master, domain);
    let mut bridge = start_bridge(&ns, Some(&master), &bridge_cfg, "bridge.log");
    std::thread::sleep(Duration::from_secs(2));
    // The takeover topic: false for 2 s, then true (the safety driver took over).
    let mut p1 = ros1_peer(
        &master,
        &[
            "pub",
            "--topic",
            "/vehicle/takeover",
            "--type",
            "bool",
            "--count",
            "40",
            "--rate",
            "10",
            "--switch-at",
            "20",
            "--name",
            "takeover",
        ],
    );
    let sent = perturb_tests::ros1_lines(stdout_of(&mut p1), &mut p1);
    let t_kill = sent[20]["t_pub_ns"].as_u64().unwrap();
    assert_eq!(sent[20]["data"], true);
    std::thread::sleep(Duration::from_millis(500));
    let st = ctl_status(&ns);
    assert!(st.contains("KILL SWITCH ENGAGED"), "{st}");
    // A daemon restarted after a crash keeps the latch.
    daemon.kill9();
    let mut daemon = ns.start_daemon(&daemon_cfg);
    let st = ctl_status(&ns);
    assert!(
        st.contains("KILL SWITCH ENGAGED"),
        "after the restart: {st}"
    );
    std::thread::sleep(Duration::from_secs(1));
    // The topic clears (false), then a person arms: perturbations resume.
    let mut p2 = ros1_peer(
        &master,
        &[
            "pub",
            "--topic",
            "/vehicle/takeover",
            "--type",
            "bool",
            "--count",
            "30",
            "--rate",
            "10",
            "--switch-at",
            "1000",
            "--name",
            "clear",
        ],
    );
    let p2_out = collect_lines(stdout_of(&mut p2));
    std::thread::sleep(Duration::from_millis(1200));
    let o = ns.ctl(&["arm"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let t_arm = perturb_wire::monotonic_ns();
    let _ = p2.wait();
    // Its last message: the dead man engages when it goes away, a little later.
    let t_p2_end = p2_out
        .join()
        .unwrap()
        .last()
        .and_then(|l| l["t_pub_ns"].as_u64())
        .expect("the clearing publisher published");
    // The clearing publisher went away: the dead man kills again.
    assert!(
        wait_until(Duration::from_secs(5), || ctl_status(&ns)
            .contains("dead man")),
        "the dead man did not engage: {}\n{}",
        ctl_status(&ns),
        log(&ns, "bridge.log")
    );
    assert!(interrupt(&mut bridge), "{}", log(&ns, "bridge.log"));
    std::thread::sleep(Duration::from_millis(500));
    kill_all(&mut peers);
    let mut got = lines.into_iter().map(|h| h.join().unwrap());
    let (cam, ev, lid) = (
        got.next().unwrap(),
        got.next().unwrap(),
        got.next().unwrap(),
    );
    let _ = daemon.stop();
    let raw = raw_hashes(&rec);
    let is_raw = |topic: &str, f: &Value| {
        let k = (
            topic.to_string(),
            f["sec"].as_i64().or(f["sec"].as_i64()).unwrap(),
            f["nsec"].as_i64().or(f["nanosec"].as_i64()).unwrap(),
        );
        let r = raw
            .get(&k)
            .unwrap_or_else(|| panic!("frame {k:?} not recorded raw"));
        r == f["sha256"].as_str().unwrap()
    };
    let ms = 1_000_000u64;
    for (name, topic, frames) in [("camera", "/cam/raw", &cam), ("LiDAR", "/lid/raw", &lid)] {
        let t = |f: &Value| f["t_arrival_ns"].as_u64().unwrap();
        assert!(
            frames
                .iter()
                .filter(|f| t(f) < t_kill)
                .all(|f| !is_raw(topic, f)),
            "{name}: a raw frame before the kill"
        );
        // The kill holds from the first raw frame after which nothing perturbed arrives until
        // the arm. (A frame perturbed just before the kill can still come out raw on its own
        // deadline, `late`, and be followed by perturbed ones: that raw frame is not the kill.)
        let last_perturbed = frames
            .iter()
            .filter(|f| t(f) >= t_kill && t(f) < t_arm && !is_raw(topic, f))
            .map(t)
            .max();
        let first_raw = frames
            .iter()
            .find(|f| {
                t(f) >= t_kill && is_raw(topic, f) && last_perturbed.is_none_or(|lp| t(f) > lp)
            })
            .expect("a raw frame after the kill");
        eprintln!(
            "{name}: first raw frame {:.1} ms after the kill message",
            (t(first_raw) - t_kill) as f64 / 1e6
        );
        assert!(
            t(first_raw) - t_kill < 1000 * ms,
            "{name}: too slow to go raw"
        );
        // Raw from then on until the arm, perturbed after it while the topic said false.
        let killed: Vec<&Value> = frames
            .iter()
            .filter(|f| t(f) > t(first_raw) && t(f) < t_arm)
            .collect();
        assert!(
            killed.len() > 10 && killed.iter().all(|f| is_raw(topic, f)),
            "{name}: not raw while killed"
        );
        // The bridge's latch follows the daemon's within its status poll (250 ms).
        let armed: Vec<&Value> = frames
            .iter()
            .filter(|f| t(f) > t_arm + 600 * ms && t(f) < t_p2_end)
            .collect();
        let raw_after = armed.iter().filter(|f| is_raw(topic, f)).count();
        assert!(
            !armed.is_empty() && raw_after == 0,
            "{name}: {raw_after} of {} frames raw after the arm",
            armed.len()
        );
    }
    let recs = records(&ev);
    let kinds: Vec<&str> = recs
        .iter()
        .filter(|r| r["kind"] == "kill" || r["kind"] == "arm")
        .map(|r| r["kind"].as_str().unwrap())
        .collect();
    assert_eq!(kinds, ["kill", "arm", "kill"], "{recs:?}");
    valid_against_the_schema(&ns, &recs);
    assert!(
        recs.iter()
            .any(|r| r["reason"] == "killed" && r["applied"] == false)
    );
}

/// Polls `f` until it holds or `timeout` passes.
fn wait_until(timeout: Duration, mut f: impl FnMut() -> bool) -> bool {
    let t = Instant::now();
    while t.elapsed() < timeout {
        if f() {
            return true;
        }
        std::thread::sleep(Duration::from_millis(100));
    }
    false
}

#[test]
fn a_campaign_switches_steps_where_the_vehicle_is_and_the_events_carry_the_step() {
    if !have_everything() {
        return;
    }
    let ns = Namespace::new("safety-camp");
    let master = Ros1Master::start(&ns.dir);
    let domain = domain_of(2);
    write(&ns.dir.join("route.csv"), "x,y\n0,0\n100,0\n200,0\n");
    write(
        &ns.dir.join("campaign.toml"),
        "name = \"test drive\"\n[route]\ncsv = \"route.csv\"\n\n\
         [[steps]]\nname = \"noise on the straight\"\nstreams = [\"cam\"]\nid = \"C-A1\"\nseverity = 2\nseed = 5\n\
         trigger = { route = [50.0, 100.0] }\n\n\
         [[steps]]\nname = \"beam loss in the box\"\nstreams = [\"lid\"]\nid = \"L-B1\"\nseverity = 1\nseed = 5\n\
         trigger = { geofence = [[120.0, -5.0], [140.0, -5.0], [140.0, 5.0], [120.0, 5.0]] }\n",
    );
    let daemon_cfg = ns.dir.join("perturbd.toml");
    write(
        &daemon_cfg,
        "[daemon]\ncampaign = \"campaign.toml\"\n\n\
         [[streams]]\nname = \"cam\"\nmodality = \"camera\"\n\n\
         [[streams]]\nname = \"lid\"\nmodality = \"lidar\"\nsensor = \"vlp32c\"\n",
    );
    let bridge_cfg = bridge_config(
        &ns,
        domain,
        "\n[pose]\ntopic = \"/localization/current_pose\"\ntransport = \"ros1\"\n",
    );
    let mut daemon = ns.start_daemon(&daemon_cfg);
    let (mut peers, lines) = ads_side(&master, domain);
    let mut bridge = start_bridge(&ns, Some(&master), &bridge_cfg, "bridge.log");
    std::thread::sleep(Duration::from_secs(2));
    // The vehicle drives along the route at 40 m/s: 2 m per pose, 20 poses a second.
    let mut pose = ros1_peer(
        &master,
        &[
            "pub",
            "--topic",
            "/localization/current_pose",
            "--type",
            "pose",
            "--count",
            "100",
            "--rate",
            "20",
            "--path",
            "0,0,2,0",
            "--name",
            "pose",
        ],
    );
    let poses = perturb_tests::ros1_lines(stdout_of(&mut pose), &mut pose);
    std::thread::sleep(Duration::from_millis(300));
    let status = ctl_status(&ns);
    assert!(interrupt(&mut bridge), "{}", log(&ns, "bridge.log"));
    std::thread::sleep(Duration::from_millis(500));
    kill_all(&mut peers);
    let mut got = lines.into_iter().map(|h| h.join().unwrap());
    let (cam, ev, lid) = (
        got.next().unwrap(),
        got.next().unwrap(),
        got.next().unwrap(),
    );
    let _ = daemon.stop();
    assert!(status.contains("campaign `test drive`"), "{status}");
    let recs = records(&ev);
    // When the pose at x crossed the ADS's side: each frame's arrival, by its stamp.
    let t_pose = |x: f64| {
        poses
            .iter()
            .find(|p| p["x"].as_f64().unwrap() >= x)
            .and_then(|p| p["t_pub_ns"].as_u64())
            .unwrap()
    };
    for (stream, frames, step, on_x, off_x, nsec_key) in [
        ("cam", &cam, 1, 50.0, 100.0, "nsec"),
        ("lid", &lid, 2, 120.0, 140.0, "nanosec"),
    ] {
        let arrival = |r: &Value| {
            frames
                .iter()
                .find(|f| f["sec"] == r["stamp_sec"] && f[nsec_key] == r["stamp_nanosec"])
                .and_then(|f| f["t_arrival_ns"].as_u64())
        };
        let stepped: Vec<u64> = recs
            .iter()
            .filter(|r| r["kind"] == "frame" && r["stream"] == stream && r["step"] == step)
            .filter_map(arrival)
            .collect();
        assert!(
            stepped.len() >= 3,
            "{stream}: {} frames of step {step}",
            stepped.len()
        );
        let (first, last) = (stepped[0], *stepped.last().unwrap());
        let (on, next_pose) = (t_pose(on_x), t_pose(on_x + 2.0));
        let (off, after_off) = (t_pose(off_x), t_pose(off_x + 2.0));
        let period = if stream == "cam" { 34 } else { 101 } * 1_000_000;
        eprintln!(
            "{stream}: step {step} on {:.1} ms after the pose at x = {on_x} m, off {:.1} ms after the pose at x = {off_x} m",
            (first as f64 - on as f64) / 1e6,
            (last as f64 - off as f64) / 1e6
        );
        assert!(first >= on, "{stream}: step {step} before its position");
        assert!(
            first <= next_pose + period + 50_000_000,
            "{stream}: step {step} more than one pose message late"
        );
        assert!(
            last <= after_off + 50_000_000,
            "{stream}: step {step} after its end"
        );
        // Outside the step: no perturbation.
        assert!(
            recs.iter()
                .filter(|r| r["kind"] == "frame" && r["stream"] == stream && r["applied"] == true)
                .all(|r| r["step"] == step),
            "{stream}: perturbed outside its step"
        );
    }
}

/// The kill switch from a ROS 2 topic (`std_msgs/msg/Bool` published by the independent Cyclone
/// DDS peer): the bridge reads it over its RustDDS participant of small topics and engages the
/// daemon's latch.
#[test]
fn a_ros2_kill_topic_engages_the_daemons_latch() {
    if !have_everything() {
        return;
    }
    let ns = Namespace::new("safety-kill2");
    let domain = domain_of(3);
    let daemon_cfg = ns.dir.join("perturbd.toml");
    write(&daemon_cfg, DAEMON);
    let cfg = ns.dir.join("bridge.toml");
    write(
        &cfg,
        &format!(
            "[bridge]\nname = \"kill2\"\n\n[dds]\ndomain_id = {domain}\ninterfaces = [\"lo\"]\n\n\
             [[synthetic.camera]]\nstream = \"cam\"\nwidth = 160\nheight = 100\nrate_hz = 30\nprerender = 2\n\n\
             [[egress]]\nstream = \"cam\"\ntopic = \"/ads/camera\"\n\n\
             [kill]\ntopic = \"/vehicle/takeover\"\n"
        ),
    );
    let _daemon = ns.start_daemon(&daemon_cfg);
    let mut bridge = start_bridge(&ns, None, &cfg, "bridge.log");
    std::thread::sleep(Duration::from_secs(2));
    assert!(
        !ctl_status(&ns).contains("KILL SWITCH"),
        "killed before the topic said so"
    );
    let dom = domain.to_string();
    let mut p = dds_peer(&[
        "publish",
        "--topic",
        "/vehicle/takeover",
        "--type",
        "bool",
        "--count",
        "5",
        "--rate",
        "10",
        "--value",
        "1",
        "--domain",
        &dom,
    ]);
    let _ = p.wait();
    assert!(
        wait_until(Duration::from_secs(10), || ctl_status(&ns)
            .contains("KILL SWITCH ENGAGED")),
        "the daemon was not killed: {}\n{}",
        ctl_status(&ns),
        log(&ns, "bridge.log")
    );
    assert!(
        ctl_status(&ns).contains("/vehicle/takeover"),
        "{}",
        ctl_status(&ns)
    );
    assert!(interrupt(&mut bridge), "{}", log(&ns, "bridge.log"));
}
