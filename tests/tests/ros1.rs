//! ROS 1 end to end, against a real `roscore` (on 127.0.0.1, a free port, a private ROS_HOME)
//! and Debian's rospy, rostopic and rosbag as the independent peers:
//!
//! - rospy publishers -> bridge (TCPROS ingress) -> perturbd -> bridge (TCPROS egress) -> rospy
//!   subscribers, every frame with its header exact and its data perturbed as the event channel
//!   says; `rostopic hz` and `rostopic echo -n1` on an egress topic; the bridge's ROS 1 bag read
//!   back by `rosbag info`, Python `rosbag` and `rosbags`;
//! - a bridge started before its master waits for it, and re-registers when it restarts;
//! - a bag written by `rosbag record` replays through perturbd, with `/clock`;
//! - the bridge's ROS 1 client against rospy: both directions, a wrong md5sum refused with an
//!   `error` header, seq gaps counted, subscribers and publishers that vanish.
//!
//! Missing ROS 1 packages skip these tests with a message, or fail them under
//! `PERTURB_REQUIRE_ORACLES=1` (CI).

use perturb_bridge::dds::{Qos, RosType, TopicSpec};
use perturb_bridge::ros1::{Node, Ros1Settings, TopicReader1};
use perturb_bridge::topic::TopicReader;
use perturb_core::formats::ros::{Header, ImageMsg};
use perturb_core::formats::ros1;
use perturb_tests::{
    Namespace, Ros1Master, events, exe, have_ros1, have_rosbags, largest_gap_ms, read_bag,
    ros_python, ros1_lines, ros1_peer, ros1_ready, start_bridge,
};
use serde_json::Value;
use std::process::{Child, Stdio};
use std::time::{Duration, Instant};

fn interrupt(c: &mut Child) -> bool {
    perturb_wire::process::interrupt(c, Duration::from_secs(15)).is_some_and(|s| s.success())
}

fn log_of(ns: &Namespace, name: &str) -> String {
    std::fs::read_to_string(ns.dir.join(name)).unwrap_or_default()
}

/// Waits until `f` holds or `timeout` passes.
fn wait_for(timeout: Duration, mut f: impl FnMut() -> bool) -> bool {
    let t = Instant::now();
    while t.elapsed() < timeout {
        if f() {
            return true;
        }
        std::thread::sleep(Duration::from_millis(100));
    }
    false
}

/// The topics the master lists with publishers / subscribers (`rostopic list -p` / `-s`).
fn rostopic_list(master: &Ros1Master, flag: &str) -> String {
    let o = master
        .command("rostopic")
        .args(["list", flag])
        .output()
        .unwrap();
    String::from_utf8_lossy(&o.stdout).into_owned()
}

fn headers_equal(got: &Value, sent: &Value) {
    for k in ["seq", "sec", "nsec", "frame_id", "width", "height"] {
        assert_eq!(
            got[k], sent[k],
            "header/geometry `{k}` must pass exactly: {got} vs {sent}"
        );
    }
}

#[test]
fn ros1_sensors_through_perturbd_to_rospy_exact_headers_and_a_bag1_recording() {
    if !have_ros1() || !have_rosbags() {
        return;
    }
    let ns = Namespace::new("ros1-e2e");
    let master = Ros1Master::start(&ns.dir);
    let daemon_cfg = ns.dir.join("perturbd.toml");
    std::fs::write(
        &daemon_cfg,
        "[[streams]]\nname = \"camera\"\nmodality = \"camera\"\n\
         perturbation = { id = \"C-A1\", severity = 3, seed = 4 }\n\n\
         [[streams]]\nname = \"lidar\"\nmodality = \"lidar\"\nsensor = \"vlp32c\"\n\
         perturbation = { id = \"L-C1\", severity = 2, seed = 4 }\n",
    )
    .unwrap();
    let bag = ns.dir.join("rec.bag");
    let bridge_cfg = ns.dir.join("bridge.toml");
    std::fs::write(
        &bridge_cfg,
        format!(
            "[bridge]\nname = \"ros1_e2e\"\n\n[ros1]\nhostname = \"127.0.0.1\"\n\n\
             [[ingress]]\ntopic = \"/sensors/camera/image_raw\"\ntype = \"image\"\nstream = \"camera\"\ntransport = \"ros1\"\n\n\
             [[ingress]]\ntopic = \"/sensors/lidar/points\"\ntype = \"pointcloud2\"\nstream = \"lidar\"\ntransport = \"ros1\"\n\n\
             [[egress]]\nstream = \"camera\"\ntopic = \"/perturbed/camera/image_raw\"\ntransport = \"ros1\"\n\n\
             [[egress]]\nstream = \"lidar\"\ntopic = \"/perturbed/lidar/points\"\ntransport = \"ros1\"\n\n\
             [record]\nout = \"{}\"\nformat = \"bag1\"\nstreams = [\"camera\", \"lidar\"]\n",
            bag.display()
        ),
    )
    .unwrap();
    let mut daemon = ns.start_daemon(&daemon_cfg);
    let mut bridge = start_bridge(&ns, Some(&master), &bridge_cfg, "bridge.log");
    // The bridge registers its four topics.
    assert!(
        wait_for(Duration::from_secs(20), || {
            let p = rostopic_list(&master, "-p");
            let s = rostopic_list(&master, "-s");
            p.contains("/perturbed/camera/image_raw") && s.contains("/sensors/lidar/points")
        }),
        "the bridge did not register with the master:\n{}",
        log_of(&ns, "bridge.log")
    );
    const N: usize = 10;
    let n = N.to_string();
    let mut sub_cam = ros1_peer(
        &master,
        &[
            "sub",
            "--topic",
            "/perturbed/camera/image_raw",
            "--type",
            "image",
            "--count",
            &n,
            "--timeout",
            "40",
            "--name",
            "cam",
        ],
    );
    let mut sub_lid = ros1_peer(
        &master,
        &[
            "sub",
            "--topic",
            "/perturbed/lidar/points",
            "--type",
            "cloud",
            "--count",
            &n,
            "--timeout",
            "40",
            "--name",
            "lid",
        ],
    );
    let r_cam = ros1_ready(&mut sub_cam);
    let r_lid = ros1_ready(&mut sub_lid);
    // The subscribers are connected to the bridge before anything is published.
    std::thread::sleep(Duration::from_secs(1));
    let mut pub_cam = ros1_peer(
        &master,
        &[
            "pub",
            "--topic",
            "/sensors/camera/image_raw",
            "--type",
            "image",
            "--count",
            &n,
            "--rate",
            "10",
            "--size",
            "96x64",
            "--frame-id",
            "camera_front",
            "--name",
            "cam",
        ],
    );
    let mut pub_lid = ros1_peer(
        &master,
        &[
            "pub",
            "--topic",
            "/sensors/lidar/points",
            "--type",
            "cloud",
            "--count",
            &n,
            "--rate",
            "10",
            "--points",
            "800",
            "--frame-id",
            "lidar_top",
            "--name",
            "lid",
            "--stamp-base",
            "1500000000",
        ],
    );
    let out_cam = pub_cam.stdout.take().unwrap();
    let out_lid = pub_lid.stdout.take().unwrap();
    let sent_cam = ros1_lines(std::io::BufReader::new(out_cam), &mut pub_cam);
    let sent_lid = ros1_lines(std::io::BufReader::new(out_lid), &mut pub_lid);
    let got_cam = ros1_lines(r_cam, &mut sub_cam);
    let got_lid = ros1_lines(r_lid, &mut sub_lid);
    assert_eq!(sent_cam.len(), N, "the camera publisher did not publish");
    assert_eq!(
        got_cam.len(),
        N,
        "camera frames lost:\n{}",
        log_of(&ns, "bridge.log")
    );
    assert_eq!(
        got_lid.len(),
        N,
        "cloud frames lost:\n{}",
        log_of(&ns, "bridge.log")
    );
    for (got, sent) in got_cam
        .iter()
        .zip(&sent_cam)
        .chain(got_lid.iter().zip(&sent_lid))
    {
        headers_equal(got, sent);
        assert_ne!(got["sha256"], sent["sha256"], "the frame was not perturbed");
    }
    assert_eq!(got_cam[0]["encoding"], "rgb8");
    assert_eq!(
        got_lid[0]["fields"],
        serde_json::json!(["x", "y", "z", "intensity"])
    );

    // rostopic hz and echo on an egress topic while frames flow at 10 Hz.
    let mut feed = ros1_peer(
        &master,
        &[
            "pub",
            "--topic",
            "/sensors/camera/image_raw",
            "--type",
            "image",
            "--count",
            "60",
            "--rate",
            "10",
            "--size",
            "96x64",
            "--frame-id",
            "camera_front",
            "--name",
            "feed",
            "--stamp-base",
            "1700000000",
        ],
    );
    let feed_out = feed.stdout.take().unwrap();
    let drain = std::thread::spawn(move || std::io::copy(&mut { feed_out }, &mut std::io::sink()));
    let echo = master
        .command("rostopic")
        .args(["echo", "-n1", "/perturbed/camera/image_raw/header"])
        .output()
        .unwrap();
    let echo = String::from_utf8_lossy(&echo.stdout).into_owned();
    assert!(
        echo.contains("frame_id: \"camera_front\"") || echo.contains("frame_id: camera_front"),
        "rostopic echo: {echo}"
    );
    assert!(echo.contains("secs: 17000000"), "rostopic echo: {echo}");
    let mut hz = master
        .command("rostopic")
        .args(["hz", "/perturbed/camera/image_raw"])
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    std::thread::sleep(Duration::from_secs(4));
    interrupt(&mut hz);
    let mut text = String::new();
    std::io::Read::read_to_string(&mut hz.stdout.take().unwrap(), &mut text).unwrap();
    let rates: Vec<f64> = text
        .lines()
        .filter_map(|l| l.trim().strip_prefix("average rate: "))
        .filter_map(|v| v.trim().parse().ok())
        .collect();
    let rate = *rates
        .last()
        .unwrap_or_else(|| panic!("rostopic hz printed no rate: {text}"));
    assert!(
        (8.0..=12.0).contains(&rate),
        "egress at {rate} Hz, published at 10 Hz:\n{text}"
    );
    let _ = feed.kill();
    let _ = feed.wait();
    let _ = drain.join();

    assert!(
        interrupt(&mut bridge),
        "the bridge did not stop cleanly:\n{}",
        log_of(&ns, "bridge.log")
    );
    let report = daemon.stop();
    for s in report["streams"].as_array().unwrap() {
        assert_eq!(s["invalid"], 0, "{s}");
    }

    // The ROS 1 bag: rosbag info, Python rosbag, rosbags.
    let info = master
        .command("rosbag")
        .arg("info")
        .arg(&bag)
        .output()
        .unwrap();
    let info_text = String::from_utf8_lossy(&info.stdout);
    assert!(
        info.status.success(),
        "rosbag info: {}",
        String::from_utf8_lossy(&info.stderr)
    );
    for t in [
        "/camera/raw",
        "/camera/perturbed",
        "/lidar/perturbed",
        "/perturb/events",
    ] {
        assert!(info_text.contains(t), "rosbag info lacks {t}:\n{info_text}");
    }
    let py = master
        .command(ros_python())
        .arg("-c")
        .arg(
            "import sys, rosbag\nwith rosbag.Bag(sys.argv[1]) as b:\n    for t, m, _ in b.read_messages(topics=['/camera/perturbed']):\n        print(m.header.seq, m.header.stamp.secs, m.width)",
        )
        .arg(&bag)
        .output()
        .unwrap();
    assert!(
        py.status.success(),
        "python rosbag: {}",
        String::from_utf8_lossy(&py.stderr)
    );
    let seqs: Vec<String> = String::from_utf8_lossy(&py.stdout)
        .lines()
        .map(str::to_string)
        .collect();
    let first = format!("{} {} 96", sent_cam[0]["seq"], sent_cam[0]["sec"]);
    assert_eq!(
        seqs.first(),
        Some(&first),
        "the bag's header seq is the ROS 1 seq: {seqs:?}"
    );
    let msgs = read_bag(&bag);
    let perturbed: Vec<&Value> = msgs
        .iter()
        .filter(|m| m["topic"] == "/camera/perturbed")
        .collect();
    assert!(
        perturbed.len() >= N,
        "rosbags read {} perturbed frames",
        perturbed.len()
    );
    let ev = events(&msgs);
    assert!(
        ev.iter()
            .any(|e| e["id"] == "C-A1" && e["severity"] == 3 && e["stream"] == "camera"),
        "{ev:?}"
    );
    assert!(
        ev.iter()
            .any(|e| e["id"] == "L-C1" && e["stream"] == "lidar"),
        "{ev:?}"
    );
    let first_ev = ev.iter().find(|e| e["stream"] == "camera").unwrap();
    assert_eq!(first_ev["seq"], sent_cam[0]["seq"]);
}

#[test]
fn ros1_bridge_waits_for_its_master_and_registers_again_after_a_restart() {
    if !have_ros1() {
        return;
    }
    let ns = Namespace::new("ros1-restart");
    let mut master = Ros1Master::new(&ns.dir);
    let cfg = ns.dir.join("bridge.toml");
    let report = ns.dir.join("report.json");
    std::fs::write(
        &cfg,
        format!(
            "[bridge]\nname = \"ros1_relay\"\nbus = \"local\"\nreport = \"{}\"\n\n\
             [[ingress]]\ntopic = \"/sensors/camera/image_raw\"\ntype = \"image\"\nstream = \"cam\"\ntransport = \"ros1\"\n\n\
             [[egress]]\nstream = \"cam\"\ntopic = \"/relayed/camera\"\ntransport = \"ros1\"\n",
            report.display()
        ),
    )
    .unwrap();
    // The bridge starts first and waits for its master.
    let mut bridge = start_bridge(&ns, Some(&master), &cfg, "bridge.log");
    assert!(wait_for(Duration::from_secs(15), || log_of(
        &ns,
        "bridge.log"
    )
    .contains("waiting for the ROS master")));
    assert!(
        bridge.try_wait().unwrap().is_none(),
        "the bridge gave up:\n{}",
        log_of(&ns, "bridge.log")
    );
    master.up();
    let registered = |m: &Ros1Master| rostopic_list(m, "-p").contains("/relayed/camera");
    assert!(
        wait_for(Duration::from_secs(15), || registered(&master)),
        "{}",
        log_of(&ns, "bridge.log")
    );
    let relay = |master: &Ros1Master,
                 name: &str,
                 base: &str,
                 subs: &mut Vec<Child>|
     -> (Vec<Value>, Vec<Value>) {
        let mut sub = ros1_peer(
            master,
            &[
                "sub",
                "--topic",
                "/relayed/camera",
                "--type",
                "image",
                "--count",
                "5",
                "--timeout",
                "30",
                "--name",
                name,
            ],
        );
        let r = ros1_ready(&mut sub);
        std::thread::sleep(Duration::from_millis(800));
        let mut p = ros1_peer(
            master,
            &[
                "pub",
                "--topic",
                "/sensors/camera/image_raw",
                "--type",
                "image",
                "--count",
                "5",
                "--rate",
                "10",
                "--name",
                name,
                "--stamp-base",
                base,
            ],
        );
        let out = p.stdout.take().unwrap();
        let sent = ros1_lines(std::io::BufReader::new(out), &mut p);
        let got = ros1_lines(r, &mut sub);
        subs.push(sub);
        (sent, got)
    };
    let mut done = Vec::new();
    let (sent, got) = relay(&master, "before", "1000", &mut done);
    assert_eq!(
        got.len(),
        5,
        "frames before the restart:\n{}",
        log_of(&ns, "bridge.log")
    );
    for (g, s) in got.iter().zip(&sent) {
        headers_equal(g, s);
        assert_eq!(g["sha256"], s["sha256"], "the local bus relays unperturbed");
    }
    // The master restarts with an empty registry; the bridge notices and registers again.
    master.down();
    master.up();
    assert!(
        wait_for(Duration::from_secs(20), || registered(&master)),
        "the bridge did not register again:\n{}",
        log_of(&ns, "bridge.log")
    );
    assert!(
        log_of(&ns, "bridge.log").contains("registering again")
            || log_of(&ns, "bridge.log").contains("lost the ROS master")
    );
    // New nodes, known only to the new master, reach the bridge and are reached by it.
    let (sent, got) = relay(&master, "after", "2000", &mut done);
    assert_eq!(
        got.len(),
        5,
        "frames after the restart:\n{}",
        log_of(&ns, "bridge.log")
    );
    for (g, s) in got.iter().zip(&sent) {
        headers_equal(g, s);
    }
    assert!(interrupt(&mut bridge), "{}", log_of(&ns, "bridge.log"));
    let rep: Value = serde_json::from_str(&std::fs::read_to_string(&report).unwrap()).unwrap();
    let ingress = rep
        .as_array()
        .unwrap()
        .iter()
        .find(|r| r["name"].as_str().unwrap().starts_with("ingress"))
        .unwrap();
    let egress = rep
        .as_array()
        .unwrap()
        .iter()
        .find(|r| r["name"].as_str().unwrap().starts_with("egress"))
        .unwrap();
    // Every frame published was relayed or counted as lost.
    assert_eq!(
        ingress["received"].as_u64().unwrap() + ingress["lost"].as_u64().unwrap(),
        10,
        "{ingress}"
    );
    assert_eq!(egress["forwarded"], 10, "{egress}");
}

/// A ROS 1 master restart mid-stream, with rospy and roscpp sensor publishers that (as ROS 1
/// nodes do) never register with the new master: the bridge registers again, keeps its working
/// links to both publishers and to its subscribers, and picks up a publisher that appears after
/// the restart. Every frame arrives or is counted (bridge report, `perturb ctl stats`).
#[test]
fn ros1_links_outlive_a_master_restart_with_rospy_and_roscpp_publishers() {
    if !have_ros1() {
        return;
    }
    let Some(cpp_pub) = perturb_tests::roscpp_publisher() else {
        return;
    };
    let ns = Namespace::new("ros1-master-restart");
    let mut master = Ros1Master::start(&ns.dir);
    let daemon_cfg = ns.dir.join("perturbd.toml");
    std::fs::write(
        &daemon_cfg,
        "[[streams]]\nname = \"cam_py\"\nmodality = \"camera\"\n\n\
         [[streams]]\nname = \"cam_cpp\"\nmodality = \"camera\"\n",
    )
    .unwrap();
    let report = ns.dir.join("report.json");
    let bridge_cfg = ns.dir.join("bridge.toml");
    std::fs::write(
        &bridge_cfg,
        format!(
            "[bridge]\nname = \"ros1_restart\"\nreport = \"{}\"\n\n[ros1]\nhostname = \"127.0.0.1\"\n\n\
             [[ingress]]\ntopic = \"/sensors/py/image_raw\"\ntype = \"image\"\nstream = \"cam_py\"\ntransport = \"ros1\"\n\n\
             [[ingress]]\ntopic = \"/sensors/cpp/image_raw\"\ntype = \"image\"\nstream = \"cam_cpp\"\ntransport = \"ros1\"\n\n\
             [[egress]]\nstream = \"cam_py\"\ntopic = \"/relayed/py\"\ntransport = \"ros1\"\n\n\
             [[egress]]\nstream = \"cam_cpp\"\ntopic = \"/relayed/cpp\"\ntransport = \"ros1\"\n",
            report.display()
        ),
    )
    .unwrap();
    let mut daemon = ns.start_daemon(&daemon_cfg);
    let mut bridge = start_bridge(&ns, Some(&master), &bridge_cfg, "bridge.log");
    assert!(
        wait_for(Duration::from_secs(20), || rostopic_list(&master, "-p")
            .contains("/relayed/cpp")),
        "the bridge did not register:\n{}",
        log_of(&ns, "bridge.log")
    );
    // 8 s at 20 Hz from each publisher; the master restarts after about 3 s; a late publisher
    // adds 10 frames on the rospy topic after the restart.
    const N: usize = 160;
    const LATE: usize = 10;
    let sub = |topic: &str, count: usize, name: &str| {
        let mut c = ros1_peer(
            &master,
            &[
                "sub",
                "--topic",
                topic,
                "--type",
                "image",
                "--count",
                &count.to_string(),
                "--timeout",
                "60",
                "--name",
                name,
            ],
        );
        let r = ros1_ready(&mut c);
        (c, r)
    };
    let (mut sub_py, r_py) = sub("/relayed/py", N + LATE, "py");
    let (mut sub_cpp, r_cpp) = sub("/relayed/cpp", N, "cpp");
    std::thread::sleep(Duration::from_secs(1));
    let mut pub_py = ros1_peer(
        &master,
        &[
            "pub",
            "--topic",
            "/sensors/py/image_raw",
            "--type",
            "image",
            "--count",
            &N.to_string(),
            "--rate",
            "20",
            "--size",
            "64x48",
            "--name",
            "py",
        ],
    );
    let mut pub_cpp = master
        .command(&cpp_pub)
        .args([
            "/sensors/cpp/image_raw",
            &N.to_string(),
            "20",
            "64",
            "48",
            "rgb8",
            "1000",
        ])
        .stdout(Stdio::piped())
        .stderr(Stdio::inherit())
        .spawn()
        .expect("starting the roscpp publisher");
    std::thread::sleep(Duration::from_secs(3));
    let down = Instant::now();
    master.down();
    master.up();
    let back = Instant::now();
    assert!(
        wait_for(Duration::from_secs(20), || rostopic_list(&master, "-p")
            .contains("/relayed/py")),
        "the bridge did not register with the new master:\n{}",
        log_of(&ns, "bridge.log")
    );
    let registered_after = back.elapsed();
    let mut late = ros1_peer(
        &master,
        &[
            "pub",
            "--topic",
            "/sensors/py/image_raw",
            "--type",
            "image",
            "--count",
            &LATE.to_string(),
            "--rate",
            "20",
            "--size",
            "64x48",
            "--name",
            "late",
            "--stamp-base",
            "1900000000",
        ],
    );
    let sent_py = ros1_lines(
        std::io::BufReader::new(pub_py.stdout.take().unwrap()),
        &mut pub_py,
    );
    let sent_cpp = ros1_lines(
        std::io::BufReader::new(pub_cpp.stdout.take().unwrap()),
        &mut pub_cpp,
    );
    let sent_late = ros1_lines(
        std::io::BufReader::new(late.stdout.take().unwrap()),
        &mut late,
    );
    let got_py = ros1_lines(r_py, &mut sub_py);
    let got_cpp = ros1_lines(r_cpp, &mut sub_cpp);
    let log = log_of(&ns, "bridge.log");
    assert_eq!(
        (sent_py.len(), sent_cpp.len(), sent_late.len()),
        (N, N, LATE)
    );
    assert_eq!(
        got_cpp.len(),
        N,
        "roscpp frames lost across the restart:\n{log}"
    );
    assert_eq!(
        got_py.len(),
        N + LATE,
        "rospy frames lost across the restart:\n{log}"
    );
    // The rospy and roscpp links carried frames through the master's absence.
    let (gap_py, gap_cpp) = (largest_gap_ms(&got_py[..N]), largest_gap_ms(&got_cpp));
    eprintln!(
        "master down for {:.1} s, bridge registered {:.2} s after the new master listened; \
         largest gap between frames: rospy {gap_py:.0} ms, roscpp {gap_cpp:.0} ms",
        (back - down).as_secs_f64(),
        registered_after.as_secs_f64()
    );
    assert!(
        gap_py < 2000.0 && gap_cpp < 2000.0,
        "frames stopped: {gap_py} / {gap_cpp} ms"
    );
    assert!(interrupt(&mut bridge), "{}", log_of(&ns, "bridge.log"));
    let stats = ns.stats();
    let d = daemon.stop();
    let rep: Value = serde_json::from_str(&std::fs::read_to_string(&report).unwrap()).unwrap();
    for (stream, topic, n) in [
        ("cam_py", "/sensors/py/image_raw", N + LATE),
        ("cam_cpp", "/sensors/cpp/image_raw", N),
    ] {
        let ingress = rep
            .as_array()
            .unwrap()
            .iter()
            .find(|r| r["name"].as_str().unwrap().contains(topic))
            .unwrap();
        assert_eq!(ingress["received"], n as u64, "{ingress}");
        assert_eq!(ingress["lost"], 0, "{ingress}");
        let s = stats
            .as_array()
            .unwrap()
            .iter()
            .find(|s| s["name"] == stream)
            .unwrap_or_else(|| panic!("no stream {stream} in {stats}"));
        assert_eq!(s["frames_in"], n as u64, "{stream}: {s}\n{d}");
    }
}

#[test]
fn ros1_rosbag_record_bag_replays_through_perturbd_with_clock() {
    if !have_ros1() || !have_rosbags() {
        return;
    }
    let ns = Namespace::new("ros1-replay");
    let master = Ros1Master::start(&ns.dir);
    // rosbag record (C++) records what a rospy publisher sends.
    let rec = ns.dir.join("recorded.bag");
    let mut recorder = master
        .command("rosbag")
        .args(["record", "-O"])
        .arg(&rec)
        .args(["/sensors/camera/image_raw", "/sensors/lidar/points"])
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let mut p1 = ros1_peer(
        &master,
        &[
            "pub",
            "--topic",
            "/sensors/camera/image_raw",
            "--type",
            "image",
            "--count",
            "6",
            "--rate",
            "10",
            "--name",
            "c",
        ],
    );
    let mut p2 = ros1_peer(
        &master,
        &[
            "pub",
            "--topic",
            "/sensors/lidar/points",
            "--type",
            "cloud",
            "--count",
            "6",
            "--rate",
            "10",
            "--name",
            "l",
        ],
    );
    let o1 = p1.stdout.take().unwrap();
    let o2 = p2.stdout.take().unwrap();
    let sent_cam = ros1_lines(std::io::BufReader::new(o1), &mut p1);
    let sent_lid = ros1_lines(std::io::BufReader::new(o2), &mut p2);
    assert_eq!((sent_cam.len(), sent_lid.len()), (6, 6));
    std::thread::sleep(Duration::from_millis(500));
    interrupt(&mut recorder);
    assert!(
        wait_for(Duration::from_secs(10), || rec.exists()),
        "rosbag record wrote no bag"
    );

    let daemon_cfg = ns.dir.join("perturbd.toml");
    std::fs::write(
        &daemon_cfg,
        "[[streams]]\nname = \"cam\"\nmodality = \"camera\"\nperturbation = { id = \"C-A1\", severity = 2, seed = 9 }\n\n\
         [[streams]]\nname = \"lid\"\nmodality = \"lidar\"\nsensor = \"vlp32c\"\nperturbation = { id = \"L-C1\", severity = 1, seed = 9 }\n",
    )
    .unwrap();
    let out = ns.dir.join("replayed");
    let cfg = ns.dir.join("bridge.toml");
    std::fs::write(
        &cfg,
        format!(
            "[bridge]\nname = \"ros1_replay\"\n\n[ros1]\nclock = true\n\n\
             [replay]\nbag = \"{}\"\nrate = 1.0\n[replay.topics]\n\"/sensors/camera/image_raw\" = \"cam\"\n\"/sensors/lidar/points\" = \"lid\"\n\n\
             [record]\nout = \"{}\"\nstreams = [\"cam\", \"lid\"]\n",
            rec.display(),
            out.display()
        ),
    )
    .unwrap();
    let mut daemon = ns.start_daemon(&daemon_cfg);
    let mut clock = ros1_peer(
        &master,
        &[
            "sub",
            "--topic",
            "/clock",
            "--type",
            "clock",
            "--count",
            "5",
            "--timeout",
            "30",
            "--name",
            "clock",
        ],
    );
    let clock_r = ros1_ready(&mut clock);
    let mut bridge = start_bridge(&ns, Some(&master), &cfg, "bridge.log");
    let ticks = ros1_lines(clock_r, &mut clock);
    let st = bridge.wait().unwrap();
    assert!(st.success(), "{}", log_of(&ns, "bridge.log"));
    daemon.stop();
    assert!(ticks.len() >= 5, "/clock: {ticks:?}");
    let t0 = ticks[0]["clock_ns"].as_u64().unwrap();
    assert!(
        ticks
            .windows(2)
            .all(|w| w[1]["clock_ns"].as_u64() >= w[0]["clock_ns"].as_u64())
    );
    // The recorded (arrival) times are wall-clock times of this run.
    let now = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .unwrap()
        .as_nanos() as u64;
    assert!(
        now - t0 < 120_000_000_000,
        "/clock is the bag's time: {t0} vs now {now}"
    );
    let msgs = read_bag(&out);
    for (stream, sent) in [("cam", &sent_cam), ("lid", &sent_lid)] {
        let raw: Vec<&Value> = msgs
            .iter()
            .filter(|m| m["topic"] == format!("/{stream}/raw"))
            .collect();
        let pert: Vec<&Value> = msgs
            .iter()
            .filter(|m| m["topic"] == format!("/{stream}/perturbed"))
            .collect();
        assert_eq!(raw.len(), 6, "{stream}");
        assert_eq!(pert.len(), 6, "{stream}");
        for ((r, p), s) in raw.iter().zip(&pert).zip(sent.iter()) {
            assert_eq!(r["sec"], s["sec"]);
            assert_eq!(p["nanosec"], s["nsec"]);
            assert_eq!(r["sha256"], s["sha256"], "{stream}: the raw frame changed");
            assert_ne!(p["sha256"], s["sha256"], "{stream}: not perturbed");
        }
    }
}

fn settings(master: &Ros1Master, name: &str) -> Ros1Settings {
    Ros1Settings::resolve(Some(&master.uri), Some("127.0.0.1"), name).unwrap()
}

#[test]
fn ros1_client_against_rospy_both_ways_refusals_gaps_and_vanishing_peers() {
    if !have_ros1() {
        return;
    }
    let ns = Namespace::new("ros1-client");
    let master = Ros1Master::start(&ns.dir);
    let node = Node::start(&settings(&master, "perturb_client_test")).unwrap();
    // Our publisher -> a rospy subscriber.
    let mut publisher = node.advertise("/ours/image", ros1::IMAGE).unwrap();
    let mut sub = ros1_peer(
        &master,
        &[
            "sub",
            "--topic",
            "/ours/image",
            "--type",
            "image",
            "--count",
            "3",
            "--timeout",
            "20",
            "--name",
            "o",
        ],
    );
    let r = ros1_ready(&mut sub);
    assert!(wait_for(Duration::from_secs(15), || publisher
        .subscribers()
        == 1));
    let pixels: Vec<u8> = (0..4 * 3 * 3).map(|i| i as u8).collect();
    for k in 0..3u32 {
        let m = ImageMsg {
            header: Header {
                stamp_sec: 10 + k as i32,
                stamp_nanosec: 5,
                frame_id: "cam",
            },
            height: 3,
            width: 4,
            encoding: "rgb8",
            is_bigendian: 0,
            step: 12,
            data: &pixels,
        };
        let parts = m.ros1_parts(100 + k);
        assert_eq!(
            publisher.publish(&[&parts.head, parts.data, &parts.tail]),
            1
        );
        std::thread::sleep(Duration::from_millis(50));
    }
    let got = ros1_lines(r, &mut sub);
    assert_eq!(got.len(), 3);
    assert_eq!(
        (got[2]["seq"].as_u64(), got[2]["sec"].as_u64()),
        (Some(102), Some(12)),
        "our seq reaches rospy"
    );
    // The subscriber left: the link goes, publishing carries on.
    assert!(wait_for(Duration::from_secs(10), || {
        publisher.publish(&[&[0u8; 4][..]]);
        publisher.subscribers() == 0
    }));

    // A rospy publisher -> our subscriber, with rospy's seq.
    let spec = TopicSpec {
        topic: "/theirs/points".into(),
        ros_type: RosType::PointCloud2,
        qos: Qos::default(),
    };
    let mut reader = TopicReader1::new(&node, &spec).unwrap();
    let mut p = ros1_peer(
        &master,
        &[
            "pub",
            "--topic",
            "/theirs/points",
            "--type",
            "cloud",
            "--count",
            "4",
            "--rate",
            "20",
            "--points",
            "50",
            "--name",
            "t",
        ],
    );
    let out = p.stdout.take().unwrap();
    let mut got = Vec::new();
    let t = Instant::now();
    while got.len() < 4 && t.elapsed() < Duration::from_secs(20) {
        reader
            .take(Duration::from_millis(100), &mut |seq, r| {
                let perturb_bridge::dds::Received::Cloud(c) = r.unwrap() else {
                    panic!("not a cloud")
                };
                got.push((seq.unwrap().seq, c.width, c.header.stamp_sec));
            })
            .unwrap();
    }
    let sent = ros1_lines(std::io::BufReader::new(out), &mut p);
    assert_eq!(got.len(), 4, "our subscriber got {got:?}");
    for (g, s) in got.iter().zip(&sent) {
        assert_eq!(g.0 as u64, s["seq"].as_u64().unwrap());
        assert_eq!(g.2 as u64, s["sec"].as_u64().unwrap());
        assert_eq!(g.1, 50);
    }
    assert_eq!(reader.lost(), 0);

    // A wrong type: rospy subscribes to our image topic as a String and is refused with an
    // `error` header; a rospy String publisher on a topic we read as Image is refused by it.
    let publisher2 = node.advertise("/ours/typed", ros1::IMAGE).unwrap();
    let mut wrong = master
        .command(ros_python())
        .arg("-c")
        .arg("import rospy, time\nfrom std_msgs.msg import String\nrospy.init_node('wrong', anonymous=True)\nrospy.Subscriber('/ours/typed', String, lambda m: None)\ntime.sleep(4)\n")
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    std::thread::sleep(Duration::from_secs(3));
    assert_eq!(
        publisher2.subscribers(),
        0,
        "a subscriber of another type was accepted"
    );
    let _ = wrong.wait();
    let spec = TopicSpec {
        topic: "/theirs/typed".into(),
        ros_type: RosType::Image,
        qos: Qos::default(),
    };
    let mut typed = TopicReader1::new(&node, &spec).unwrap();
    let mut sp = ros1_peer(
        &master,
        &[
            "pub",
            "--topic",
            "/theirs/typed",
            "--type",
            "string",
            "--count",
            "3",
            "--rate",
            "10",
            "--wait-subscribers",
            "0",
            "--linger",
            "2",
            "--name",
            "s",
        ],
    );
    let mut n = 0;
    let t = Instant::now();
    while t.elapsed() < Duration::from_secs(3) {
        n += typed
            .take(Duration::from_millis(100), &mut |_, _| {})
            .unwrap();
    }
    let _ = sp.wait();
    assert_eq!(n, 0, "messages of another type were read");

    // Gaps in a publisher's seq are counted as lost.
    let spec = TopicSpec {
        topic: "/gaps".into(),
        ros_type: RosType::Image,
        qos: Qos::default(),
    };
    let mut gaps = TopicReader1::new(&node, &spec).unwrap();
    let other = Node::start(&settings(&master, "perturb_gap_publisher")).unwrap();
    let mut gp = other.advertise("/gaps", ros1::IMAGE).unwrap();
    assert!(wait_for(Duration::from_secs(15), || gp.subscribers() == 1));
    let mut seen = Vec::new();
    for s in [0u32, 1, 2, 5, 6, 9] {
        let m = ImageMsg {
            header: Header {
                stamp_sec: 1,
                stamp_nanosec: 0,
                frame_id: "f",
            },
            height: 1,
            width: 1,
            encoding: "mono8",
            is_bigendian: 0,
            step: 1,
            data: &[7],
        };
        let parts = m.ros1_parts(s);
        gp.publish(&[&parts.head, parts.data, &parts.tail]);
        let t = Instant::now();
        while t.elapsed() < Duration::from_secs(5) {
            if gaps
                .take(Duration::from_millis(50), &mut |seq, _| {
                    seen.push(seq.unwrap().seq)
                })
                .unwrap()
                > 0
            {
                break;
            }
        }
    }
    assert_eq!(seen, [0, 1, 2, 5, 6, 9]);
    assert_eq!(gaps.lost(), 4, "seq 3, 4, 7, 8 are lost");
    // The publisher's node goes away: the reader carries on with nothing to read.
    drop(gp);
    drop(other);
    assert_eq!(
        gaps.take(Duration::from_millis(300), &mut |_, _| {})
            .unwrap(),
        0
    );
}

/// A rospy subscriber stopped (SIGSTOP) while 1 MB images are published: its queue of two
/// drops the oldest messages, and what it got plus what the publisher counts as dropped is
/// every message published, also after the subscriber has left (its count was lost with its
/// link before).
#[test]
// libc's kill and kill(0) liveness check.
#[allow(unsafe_code)]
fn ros1_slow_subscriber_drops_are_counted_and_add_up() {
    if !have_ros1() {
        return;
    }
    let ns = Namespace::new("ros1-slow");
    let master = Ros1Master::start(&ns.dir);
    let node = Node::start(&settings(&master, "perturb_slow_test")).unwrap();
    let mut publisher = node.advertise("/slow/image", ros1::IMAGE).unwrap();
    let mut sub = ros1_peer(
        &master,
        &[
            "sub",
            "--topic",
            "/slow/image",
            "--type",
            "image",
            "--count",
            "1000",
            "--timeout",
            "12",
            "--no-hash",
            "--name",
            "slow",
        ],
    );
    let r = ros1_ready(&mut sub);
    assert!(wait_for(Duration::from_secs(15), || publisher
        .subscribers()
        == 1));
    // SAFETY: signalling our own child process by pid.
    unsafe { libc::kill(sub.id() as i32, libc::SIGSTOP) };
    let pixels = vec![7u8; 1000 * 1000];
    const SENT: u64 = 40;
    for k in 0..SENT as u32 {
        let m = ImageMsg {
            header: Header {
                stamp_sec: k as i32,
                stamp_nanosec: 0,
                frame_id: "cam",
            },
            height: 1000,
            width: 1000,
            encoding: "mono8",
            is_bigendian: 0,
            step: 1000,
            data: &pixels,
        };
        let parts = m.ros1_parts(k);
        assert_eq!(
            publisher.publish(&[&parts.head, parts.data, &parts.tail]),
            1
        );
        std::thread::sleep(Duration::from_millis(5));
    }
    std::thread::sleep(Duration::from_secs(1));
    assert!(
        publisher.dropped() > 0,
        "a stopped subscriber dropped nothing"
    );
    // SAFETY: as above.
    unsafe { libc::kill(sub.id() as i32, libc::SIGCONT) };
    let got = ros1_lines(r, &mut sub).len() as u64;
    let dropped = publisher.dropped();
    assert!(got > 0 && dropped > 0, "got {got}, dropped {dropped}");
    assert_eq!(
        got + dropped,
        SENT,
        "delivered {got} + dropped {dropped} != published {SENT}"
    );
    // The subscriber has exited; the link goes at the next writes, and its count stays.
    assert!(wait_for(Duration::from_secs(10), || {
        publisher.publish(&[&[0u8; 4][..]]);
        publisher.subscribers() == 0
    }));
    assert!(
        publisher.dropped() >= dropped,
        "the drops of a subscriber that left are forgotten: {} < {dropped}",
        publisher.dropped()
    );
}

/// Image data counted while alive (a shared-memory sample held by the publisher's queues).
struct CountedData {
    bytes: Vec<u8>,
    live: std::sync::Arc<std::sync::atomic::AtomicUsize>,
}

impl perturb_bridge::ros1::publisher::SharedData for CountedData {
    fn data(&self) -> &[u8] {
        &self.bytes
    }
}

impl Drop for CountedData {
    fn drop(&mut self) {
        self.live.fetch_sub(1, std::sync::atomic::Ordering::SeqCst);
    }
}

/// Frames published without a copy (their data written from where it lies, as the egress does
/// from shared memory) reach rospy byte for byte and are handed back once written; with the
/// subscriber stopped the publisher never keeps more than `SHARED_IN_FLIGHT` of them (it copies
/// the rest), and what arrives plus what is counted dropped is every frame.
#[test]
// libc's kill.
#[allow(unsafe_code)]
fn ros1_frames_published_from_shared_data_arrive_exact_and_are_handed_back() {
    use perturb_bridge::ros1::publisher::SHARED_IN_FLIGHT;
    use std::sync::atomic::{AtomicUsize, Ordering};
    if !have_ros1() {
        return;
    }
    let ns = Namespace::new("ros1-shared");
    let master = Ros1Master::start(&ns.dir);
    let node = Node::start(&settings(&master, "perturb_shared_test")).unwrap();
    let mut publisher = node.advertise("/shared/image", ros1::IMAGE).unwrap();
    let mut sub = ros1_peer(
        &master,
        &[
            "sub",
            "--topic",
            "/shared/image",
            "--type",
            "image",
            "--count",
            "1000",
            "--timeout",
            "15",
            "--name",
            "shared",
        ],
    );
    let r = ros1_ready(&mut sub);
    assert!(wait_for(Duration::from_secs(15), || publisher
        .subscribers()
        == 1));
    let live = std::sync::Arc::new(AtomicUsize::new(0));
    let (w, h) = (640u32, 480u32);
    let mut expected = Vec::new();
    let mut send = |publisher: &mut perturb_bridge::ros1::Publisher, k: u32| {
        let bytes: Vec<u8> = (0..w * h).map(|i| ((i * 7 + k * 13) % 251) as u8).collect();
        expected.push(format!(
            "{:x}",
            <sha2::Sha256 as sha2::Digest>::digest(&bytes)
        ));
        let m = ImageMsg {
            header: Header {
                stamp_sec: k as i32,
                stamp_nanosec: 0,
                frame_id: "cam",
            },
            height: h,
            width: w,
            encoding: "mono8",
            is_bigendian: 0,
            step: w,
            data: &[],
        };
        let parts = m.ros1_parts(k);
        // The head ends with the data's length prefix: 0 for the empty data; patch it.
        let mut head = parts.head.clone();
        let n = head.len();
        head[n - 4..].copy_from_slice(&(bytes.len() as u32).to_le_bytes());
        live.fetch_add(1, Ordering::SeqCst);
        let data = Box::new(CountedData {
            bytes,
            live: live.clone(),
        });
        assert_eq!(publisher.publish_shared(&head, data, &parts.tail), 1);
    };
    // A subscriber that keeps up: every frame shared, none copied.
    for k in 0..10 {
        send(&mut publisher, k);
        std::thread::sleep(Duration::from_millis(60));
    }
    assert!(wait_for(Duration::from_secs(5), || live
        .load(Ordering::SeqCst)
        == 0));
    assert_eq!(
        publisher.copied(),
        0,
        "frames copied for a subscriber that kept up"
    );
    // SAFETY: signalling our own child process by pid.
    unsafe { libc::kill(sub.id() as i32, libc::SIGSTOP) };
    const SENT: u32 = 40;
    for k in 10..SENT {
        send(&mut publisher, k);
        let held = live.load(Ordering::SeqCst);
        assert!(
            held <= SHARED_IN_FLIGHT,
            "{held} shared frames held at frame {k}"
        );
        std::thread::sleep(Duration::from_millis(5));
    }
    assert!(
        publisher.copied() > 0,
        "a stopped subscriber got every frame shared"
    );
    // SAFETY: as above.
    unsafe { libc::kill(sub.id() as i32, libc::SIGCONT) };
    let got = ros1_lines(r, &mut sub);
    let dropped = publisher.dropped();
    assert_eq!(
        got.len() as u64 + dropped,
        u64::from(SENT),
        "delivered {} + dropped {dropped}",
        got.len()
    );
    for m in &got {
        let k = m["sec"].as_u64().unwrap() as usize;
        assert_eq!(
            m["sha256"].as_str(),
            Some(expected[k].as_str()),
            "frame {k}"
        );
    }
    assert!(got.iter().filter(|m| m["sec"].as_u64() < Some(10)).count() == 10);
    assert!(wait_for(Duration::from_secs(5), || live
        .load(Ordering::SeqCst)
        == 0));
}

#[test]
fn ros1_profile_mcap_ouster_replays_through_perturbd() {
    let bag =
        perturb_tests::workspace().join("../shared/data/mcap_ouster_os1_pointcloudset/test.mcap");
    if !bag.exists() {
        assert!(
            std::env::var("CI").ok().as_deref() != Some("true"),
            "{} is missing under CI=true",
            bag.display()
        );
        eprintln!("SKIP: {} is absent", bag.display());
        return;
    }
    if !have_rosbags() {
        return;
    }
    let ns = Namespace::new("ros1-mcap");
    let daemon_cfg = ns.dir.join("perturbd.toml");
    std::fs::write(
        &daemon_cfg,
        "[[streams]]\nname = \"os1\"\nmodality = \"lidar\"\nsensor = \"hdl64e\"\nperturbation = { id = \"L-C1\", severity = 2, seed = 3 }\n",
    )
    .unwrap();
    let mut daemon = ns.start_daemon(&daemon_cfg);
    let out = ns.dir.join("out.bag");
    let o = ns
        .command(exe("perturb-bridge"))
        .arg("replay")
        .arg(&bag)
        .args([
            "--rate",
            "0",
            "--topic",
            "/os1_cloud_node/points=os1",
            "--record",
        ])
        .arg(&out)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    daemon.stop();
    let msgs = read_bag(&out);
    let raw: Vec<&Value> = msgs.iter().filter(|m| m["topic"] == "/os1/raw").collect();
    let pert: Vec<&Value> = msgs
        .iter()
        .filter(|m| m["topic"] == "/os1/perturbed")
        .collect();
    assert_eq!((raw.len(), pert.len()), (2, 2), "{msgs:?}");
    for (r, p) in raw.iter().zip(&pert) {
        assert_eq!(
            (r["width"].as_u64(), r["height"].as_u64()),
            (Some(2048), Some(64))
        );
        for k in ["sec", "nanosec", "frame_id"] {
            assert_eq!(r[k], p[k], "{k}");
        }
        assert_ne!(r["sha256"], p["sha256"], "not perturbed");
    }
}

/// A ROS 1 bag with bz2 chunks (as `rosbag record --bz2` writes it, here by Debian's Python
/// `rosbag`) replays with its messages decompressed ahead of the clock by a reader thread; where
/// the machine cannot decompress as fast as the bag plays, the replay says so with the measured
/// lag instead of silently stretching the timing.
#[test]
fn a_bz2_bag_replays_read_ahead_and_a_replay_that_cannot_keep_up_says_by_how_much() {
    if !have_ros1() {
        return;
    }
    let ns = Namespace::new("bz2-replay");
    let bag = ns.dir.join("bz2.bag");
    // 3 s of 320x240 rgb8 at 30 Hz, noisy rows (bz2 works hard on them).
    let script = format!(
        "import rosbag, rospy, random\n\
         from sensor_msgs.msg import Image\n\
         random.seed(1)\n\
         rows = [bytes(random.getrandbits(8) for _ in range(320 * 3)) for _ in range(64)]\n\
         with rosbag.Bag('{}', 'w', compression='bz2') as b:\n\
         \x20   for k in range(90):\n\
         \x20       m = Image(height=240, width=320, encoding='rgb8', step=960)\n\
         \x20       m.data = b''.join(rows[(k + i) % 64] for i in range(240))\n\
         \x20       t = rospy.Time(1000 + k // 30, (k % 30) * 33333333)\n\
         \x20       m.header.stamp = t\n\
         \x20       b.write('/cam/image_raw', m, t)\n",
        bag.display()
    );
    let o = std::process::Command::new(ros_python())
        .args(["-c", &script])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let replay = |rate: &str| {
        let report = ns.dir.join(format!("report-{rate}.json"));
        let t = Instant::now();
        let o = ns
            .command(exe("perturb-bridge"))
            .args(["--linger", "0", "--report"])
            .arg(&report)
            .arg("replay")
            .arg(&bag)
            .args(["--bus", "local", "--rate", rate])
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        let took = t.elapsed().as_secs_f64();
        let rep: Value = serde_json::from_str(&std::fs::read_to_string(&report).unwrap()).unwrap();
        let r = rep
            .as_array()
            .unwrap()
            .iter()
            .find(|a| a["name"].as_str().unwrap().starts_with("replay"))
            .unwrap()
            .clone();
        (took, r, String::from_utf8_lossy(&o.stderr).into_owned())
    };
    let (took, r, _) = replay("1");
    assert_eq!(r["forwarded"], 90, "{r}");
    eprintln!(
        "bz2 bag of 3.0 s replayed at rate 1 in {took:.2} s; notes: {}",
        r["notes"]
    );
    // A hundred times as fast as recorded: no machine decompresses 3000 bz2 frames a second.
    let (_, r, log) = replay("100");
    let notes = r["notes"].to_string();
    assert!(
        notes.contains("largest lag") && log.contains("behind the bag's timing"),
        "the replay fell behind without a word: {r}\n{log}"
    );
    assert_eq!(r["forwarded"], 90, "{r}");
}

/// The perturbation log on the vehicle's bus: a run recorded the usual way (Debian's `rosbag
/// record` of the ADS's topics and `/perturb/events`, which the bridge publishes on ROS 1) is
/// one bag that `perturb analyze` reads: its segments are the perturbations perturbd applied.
#[test]
fn ros1_events_on_the_bus_recorded_by_rosbag_are_what_perturb_analyze_reads() {
    if !have_ros1() {
        return;
    }
    let ns = Namespace::new("ros1-events");
    let master = Ros1Master::start(&ns.dir);
    let daemon_cfg = ns.dir.join("perturbd.toml");
    std::fs::write(
        &daemon_cfg,
        "[[streams]]\nname = \"cam\"\nmodality = \"camera\"\n",
    )
    .unwrap();
    let bridge_cfg = ns.dir.join("bridge.toml");
    std::fs::write(
        &bridge_cfg,
        "[bridge]\nname = \"events_bridge\"\n\n[ros1]\nhostname = \"127.0.0.1\"\n\n\
         [[ingress]]\ntopic = \"/sensors/cam\"\ntype = \"image\"\nstream = \"cam\"\ntransport = \"ros1\"\n\n\
         [[egress]]\nstream = \"cam\"\ntopic = \"/ads/camera\"\ntransport = \"ros1\"\n\n\
         [events]\ntopic = \"/perturb/events\"\n",
    )
    .unwrap();
    let _daemon = ns.start_daemon(&daemon_cfg);
    let mut bridge = start_bridge(&ns, Some(&master), &bridge_cfg, "bridge.log");
    assert!(
        wait_for(Duration::from_secs(20), || rostopic_list(&master, "-p")
            .contains("/perturb/events")),
        "{}",
        log_of(&ns, "bridge.log")
    );
    let bag = ns.dir.join("run.bag");
    let mut rec = master
        .command("rosbag")
        .args(["record", "-O"])
        .arg(&bag)
        .args(["/ads/camera", "/perturb/events", "/odom"])
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    std::thread::sleep(Duration::from_secs(2));
    let mut pose = ros1_peer(
        &master,
        &[
            "pub",
            "--topic",
            "/odom",
            "--type",
            "pose",
            "--count",
            "90",
            "--rate",
            "10",
            "--path",
            "0,0,1,0",
            "--name",
            "odom",
            "--wait-subscribers",
            "1",
        ],
    );
    let mut cam = ros1_peer(
        &master,
        &[
            "pub",
            "--topic",
            "/sensors/cam",
            "--type",
            "image",
            "--count",
            "90",
            "--rate",
            "10",
            "--size",
            "64x48",
            "--name",
            "cam",
            "--no-hash",
        ],
    );
    let ctl = |args: &[&str]| {
        let o = ns.ctl(args);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    };
    std::thread::sleep(Duration::from_secs(2));
    ctl(&["set", "cam", "C-A1", "--severity", "2", "--seed", "3"]);
    std::thread::sleep(Duration::from_secs(3));
    ctl(&["set", "cam", "C-F5", "--severity", "1"]);
    std::thread::sleep(Duration::from_secs(2));
    ctl(&["off", "cam"]);
    let sent = ros1_lines(
        std::io::BufReader::new(cam.stdout.take().unwrap()),
        &mut cam,
    );
    let _ = ros1_lines(
        std::io::BufReader::new(pose.stdout.take().unwrap()),
        &mut pose,
    );
    assert_eq!(sent.len(), 90);
    std::thread::sleep(Duration::from_millis(500));
    // rosbag's Python wrapper may exit non-zero on SIGINT under load (its child had it too);
    // what counts is that it stopped and its bag is read below.
    assert!(
        perturb_wire::process::interrupt(&mut rec, Duration::from_secs(15)).is_some(),
        "rosbag record did not stop"
    );
    assert!(interrupt(&mut bridge), "{}", log_of(&ns, "bridge.log"));
    let out = ns.dir.join("study");
    let o = ns
        .command(exe("perturb"))
        .arg("analyze")
        .arg(&bag)
        .args(["--pose-topic", "/odom", "--json", "--out"])
        .arg(&out)
        .output()
        .unwrap();
    assert!(
        o.status.success(),
        "perturb analyze: {}",
        String::from_utf8_lossy(&o.stderr)
    );
    let segments = std::fs::read_to_string(out.join("segments.csv")).unwrap();
    let conditions: Vec<String> = segments
        .lines()
        .skip(1)
        .map(|l| {
            let cells: Vec<&str> = l.split(',').collect();
            format!("{} {}", cells[1], cells[2])
        })
        .collect();
    assert_eq!(
        conditions,
        ["nominal -", "C-A1 2", "C-F5 1", "nominal -"],
        "segments:\n{segments}"
    );
}
