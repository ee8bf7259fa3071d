//! DDS interoperability with an independent implementation: Eclipse Cyclone DDS from the PyPI
//! package `cyclonedds` (tests/dds_peer.py), with ROS 2 naming and sensor-data QoS, both
//! directions, for each of the bridge's backends. Skips with a message when the Python module
//! (or, for the cyclone backend, libddsc) is missing, unless PERTURB_REQUIRE_ORACLES=1.

mod common;

use common::*;
use perturb_bag::{Bag, BagWriter, Filter, SensorMessage, WriterOptions};
use perturb_core::formats::ros::{Header, ImageMsg, PointCloud2Msg};
use perturb_core::synthetic::{street_image, vlp32c_scan};
use sha2::{Digest, Sha256};
use std::collections::BTreeMap;
use std::io::{BufRead, BufReader};
use std::ops::ControlFlow;
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::Duration;

fn sha(b: &[u8]) -> String {
    hex::encode(Sha256::digest(b))
}

fn peer_available() -> bool {
    need(
        has_python_module("cyclonedds"),
        "the Python module cyclonedds (pip install cyclonedds)",
    )
}

fn backend_available(backend: &str) -> bool {
    backend != "cyclone"
        || need(
            has_libddsc(),
            "Cyclone DDS 0.10 libddsc (apt-get install cyclonedds-dev)",
        )
}

/// A bag with one small image and one small cloud with distinctive headers.
fn write_source_bag(dir: &Path) -> (ImageExpect, ImageExpect) {
    let mut w = BagWriter::create(dir, &WriterOptions::default()).unwrap();
    let ci = w
        .add_topic("/cam/image_raw", "sensor_msgs/msg/Image")
        .unwrap();
    let cc = w
        .add_topic("/lidar/points", "sensor_msgs/msg/PointCloud2")
        .unwrap();
    let img = street_image(80, 50, 3);
    let im = ImageMsg::from_view(
        Header {
            stamp_sec: 1_600_000_123,
            stamp_nanosec: 987_654_321,
            frame_id: "cam_optical",
        },
        &img.view(),
    );
    w.write(ci, 1_000, 1_000, &im.encode()).unwrap();
    let mut scan = vlp32c_scan(1);
    scan.data.truncate(2000 * 32);
    let scan = perturb_core::cloud::Cloud::from_vec(
        scan.layout.clone(),
        scan.data,
        2000,
        1,
        2000 * 32,
        true,
    )
    .unwrap();
    let cm = PointCloud2Msg::from_view(
        Header {
            stamp_sec: -5,
            stamp_nanosec: 1,
            frame_id: "velodyne_top",
        },
        &scan.view(),
    );
    w.write(cc, 2_000, 2_000, &cm.encode()).unwrap();
    w.finish().unwrap();
    (
        ImageExpect {
            sec: 1_600_000_123,
            nanosec: 987_654_321,
            frame_id: "cam_optical".into(),
            sha: sha(im.data),
        },
        ImageExpect {
            sec: -5,
            nanosec: 1,
            frame_id: "velodyne_top".into(),
            sha: sha(cm.data),
        },
    )
}

#[derive(Debug, PartialEq)]
struct ImageExpect {
    sec: i64,
    nanosec: u64,
    frame_id: String,
    sha: String,
}

fn listen(topic: &str, ty: &str, count: usize, domain: u16) -> std::process::Child {
    Command::new(python())
        .arg(concat!(env!("CARGO_MANIFEST_DIR"), "/tests/dds_peer.py"))
        .args([
            "listen",
            "--topic",
            topic,
            "--type",
            ty,
            "--count",
            &count.to_string(),
        ])
        .args(["--timeout", "40", "--domain", &domain.to_string()])
        .args(["--interface", "lo"])
        .stdout(Stdio::piped())
        .stderr(Stdio::inherit())
        .spawn()
        .expect("start the python peer")
}

fn peer_lines(child: std::process::Child) -> Vec<serde_json::Value> {
    let out = child.wait_with_output().unwrap();
    String::from_utf8_lossy(&out.stdout)
        .lines()
        .filter_map(|l| serde_json::from_str::<serde_json::Value>(l).ok())
        .filter(|v| v.get("ready").is_none())
        .collect()
}

fn egress(backend: &str, offset: u16) {
    if !peer_available() || !backend_available(backend) {
        return;
    }
    let dir = scratch(&format!("egress-{backend}"));
    let (img, cloud) = write_source_bag(&dir.join("src"));
    let domain = domain(offset);
    let cfg = dir.join("bridge.toml");
    std::fs::write(
        &cfg,
        format!(
            r#"[bridge]
bus = "local"
[dds]
backend = "{backend}"
domain_id = {domain}
interfaces = ["lo"]
[replay]
bag = "src"
loop = true
rate = 1.0
[[egress]]
stream = "cam/image_raw"
topic = "/perturbed/cam"
[[egress]]
stream = "lidar/points"
topic = "/perturbed/lidar"
"#
        ),
    )
    .unwrap();
    let pi = listen("/perturbed/cam", "image", 3, domain);
    let pc = listen("/perturbed/lidar", "cloud", 3, domain);
    let mut bridge = Command::new(bridge_exe())
        .args(["--config", cfg.to_str().unwrap()])
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let images = peer_lines(pi);
    let clouds = peer_lines(pc);
    let status = interrupt(&mut bridge, Duration::from_secs(10));
    assert!(
        status.is_some_and(|s| s.success()),
        "bridge did not stop cleanly: {status:?}"
    );
    let mut log = String::new();
    std::io::Read::read_to_string(&mut bridge.stderr.take().unwrap(), &mut log).unwrap();
    assert!(
        !log.contains("does not offer"),
        "matching QoS reported: {log}"
    );
    assert!(images.len() >= 3, "peer got {} images", images.len());
    assert!(clouds.len() >= 3, "peer got {} clouds", clouds.len());
    for (got, want) in [(&images[0], &img), (&clouds[0], &cloud)] {
        let g = ImageExpect {
            sec: got["sec"].as_i64().unwrap(),
            nanosec: got["nanosec"].as_u64().unwrap(),
            frame_id: got["frame_id"].as_str().unwrap().into(),
            sha: got["sha256"].as_str().unwrap().into(),
        };
        assert_eq!(&g, want, "header and data must pass bit-exact");
    }
    assert_eq!(images[0]["width"], 80);
    assert_eq!(images[0]["encoding"], "rgb8");
    assert_eq!(clouds[0]["width"], 2000);
    assert_eq!(clouds[0]["fields"].as_array().unwrap().len(), 6);
}

fn ingress(backend: &str, offset: u16) {
    if !peer_available() || !backend_available(backend) {
        return;
    }
    let dir = scratch(&format!("ingress-{backend}"));
    let domain = domain(offset);
    let cfg = dir.join("bridge.toml");
    std::fs::write(
        &cfg,
        format!(
            r#"[bridge]
bus = "local"
[dds]
backend = "{backend}"
domain_id = {domain}
interfaces = ["lo"]
[[ingress]]
topic = "/sensing/camera/image_raw"
type = "image"
stream = "camera"
[[ingress]]
topic = "/sensing/lidar/points"
type = "pointcloud2"
stream = "lidar"
[[ingress]]
topic = "/sensing/camera/image_raw/compressed"
type = "compressed_image"
stream = "camera_png"
[record]
out = "rec"
streams = ["camera", "lidar", "camera_png"]
perturbed = false
"#
        ),
    )
    .unwrap();
    let report = dir.join("report.json");
    let mut bridge = Command::new(bridge_exe())
        .args([
            "--config",
            cfg.to_str().unwrap(),
            "--report",
            report.to_str().unwrap(),
        ])
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    // Wait until the bridge runs (its readers exist) before the peer publishes.
    let stderr = bridge.stderr.take().unwrap();
    let (tx, rx) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        for l in BufReader::new(stderr).lines().map_while(Result::ok) {
            eprintln!("bridge: {l}");
            if l.contains("bridge running") {
                let _ = tx.send(());
            }
        }
    });
    rx.recv_timeout(Duration::from_secs(60))
        .expect("bridge started");
    let publish = |ty: &str, topic: &str, extra: &[&str]| {
        Command::new(python())
            .arg(concat!(env!("CARGO_MANIFEST_DIR"), "/tests/dds_peer.py"))
            .args(["publish", "--topic", topic, "--type", ty, "--count", "6"])
            .args(["--domain", &domain.to_string(), "--rate", "5"])
            .args(["--interface", "lo"])
            .args(extra)
            .stdout(Stdio::piped())
            .spawn()
            .unwrap()
    };
    // Every odd image claims a row more than it carries, every odd PNG is truncated: the bridge
    // must log, count and carry on.
    let pi = publish(
        "image",
        "/sensing/camera/image_raw",
        &["--width", "40", "--height", "30", "--lie"],
    );
    let pc = publish("cloud", "/sensing/lidar/points", &["--points", "500"]);
    let pz = publish(
        "compressed_image",
        "/sensing/camera/image_raw/compressed",
        &["--width", "24", "--height", "16", "--lie"],
    );
    let sent_i = peer_lines(pi);
    let sent_c = peer_lines(pc);
    let sent_z = peer_lines(pz);
    std::thread::sleep(Duration::from_millis(500));
    let status = interrupt(&mut bridge, Duration::from_secs(10));
    assert!(
        status.is_some_and(|s| s.success()),
        "bridge did not stop cleanly: {status:?}"
    );
    assert_eq!(sent_i.len(), 6);
    assert_eq!(sent_c.len(), 6);
    assert_eq!(sent_z.len(), 6);
    // The well-formed samples the peer sent, by stamp (PNGs: the sha256 of their pixels).
    let mut want: BTreeMap<(String, i64, u64), String> = BTreeMap::new();
    for (topic, lines, key) in [
        ("/camera/raw", &sent_i, "sha256"),
        ("/lidar/raw", &sent_c, "sha256"),
        ("/camera_png/raw", &sent_z, "pixels_sha256"),
    ] {
        for l in lines.iter().filter(|l| l["lie"] == false) {
            want.insert(
                (
                    topic.to_string(),
                    l["sec"].as_i64().unwrap(),
                    l["nanosec"].as_u64().unwrap(),
                ),
                l[key].as_str().unwrap().to_string(),
            );
        }
    }
    let bag = Bag::open(&dir.join("rec")).unwrap();
    let mut got = BTreeMap::<String, usize>::new();
    bag.for_each(&Filter::default(), |m| {
        let (h, data) = match m.decode() {
            Some(Ok(SensorMessage::Image(i))) if m.topic == "/camera/raw" => {
                assert_eq!((i.width, i.height, i.encoding), (40, 30, "rgb8"));
                (i.header, i.data)
            }
            Some(Ok(SensorMessage::Image(i))) => {
                assert_eq!(
                    (i.width, i.height, i.encoding),
                    (24, 16, "rgb8"),
                    "decoded PNG"
                );
                (i.header, i.data)
            }
            Some(Ok(SensorMessage::Cloud(c))) => {
                assert_eq!(c.fields.len(), 4);
                (c.header, c.data)
            }
            other => panic!("unexpected message on {}: {other:?}", m.topic),
        };
        assert_eq!(h.frame_id, "peer_frame");
        let key = (
            m.topic.to_string(),
            h.stamp_sec as i64,
            h.stamp_nanosec as u64,
        );
        assert_eq!(
            want.get(&key),
            Some(&sha(data)),
            "{key:?}: stamp and data bit-exact"
        );
        *got.entry(m.topic.to_string()).or_default() += 1;
        Ok(ControlFlow::Continue(()))
    })
    .unwrap();
    // Best effort on a loaded machine may lose a sample; most must arrive.
    assert!(got.get("/camera/raw").copied().unwrap_or(0) >= 2, "{got:?}");
    assert!(
        got.get("/camera_png/raw").copied().unwrap_or(0) >= 2,
        "{got:?}"
    );
    assert!(got.get("/lidar/raw").copied().unwrap_or(0) >= 4, "{got:?}");
    // The malformed samples were counted, not forwarded.
    let rep: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&report).unwrap()).unwrap();
    let bad = |name: &str| {
        rep.as_array()
            .unwrap()
            .iter()
            .find(|a| a["name"].as_str().unwrap().contains(name))
            .map(|a| a["bad"].as_u64().unwrap())
            .unwrap()
    };
    assert!(bad("/sensing/camera/image_raw ->") >= 1, "{rep}");
    assert!(bad("/sensing/camera/image_raw/compressed") >= 1, "{rep}");
    assert_eq!(bad("/sensing/lidar/points"), 0);
}

/// A reliable reader on a best-effort egress is never matched by DDS and gets nothing; the
/// bridge says so once (log and report), naming the policy and the fix.
fn reliable_reader_on_best_effort_egress(backend: &str, offset: u16) {
    if !peer_available() || !backend_available(backend) {
        return;
    }
    let dir = scratch(&format!("qos-{backend}"));
    write_source_bag(&dir.join("src"));
    let domain = domain(offset);
    let cfg = dir.join("bridge.toml");
    std::fs::write(
        &cfg,
        format!(
            r#"[bridge]
bus = "local"
[dds]
backend = "{backend}"
domain_id = {domain}
interfaces = ["lo"]
[replay]
bag = "src"
loop = true
rate = 1.0
[[egress]]
stream = "cam/image_raw"
topic = "/perturbed/cam"
"#
        ),
    )
    .unwrap();
    let report = dir.join("report.json");
    let mut bridge = Command::new(bridge_exe())
        .args(["--config", cfg.to_str().unwrap()])
        .args(["--report", report.to_str().unwrap()])
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let peer = Command::new(python())
        .arg(concat!(env!("CARGO_MANIFEST_DIR"), "/tests/dds_peer.py"))
        .args(["listen", "--topic", "/perturbed/cam", "--type", "image"])
        .args(["--count", "1", "--timeout", "4", "--reliable"])
        .args(["--domain", &domain.to_string(), "--interface", "lo"])
        .stdout(Stdio::piped())
        .spawn()
        .unwrap();
    let got = peer_lines(peer);
    let status = interrupt(&mut bridge, Duration::from_secs(10));
    assert!(status.is_some_and(|s| s.success()), "{status:?}");
    let mut log = String::new();
    std::io::Read::read_to_string(&mut bridge.stderr.take().unwrap(), &mut log).unwrap();
    assert!(got.is_empty(), "DDS matched a reliable reader: {got:?}");
    let said = log
        .matches("asked for a QoS this egress does not offer")
        .count();
    assert_eq!(said, 1, "said {said} times:\n{log}");
    assert!(log.contains("RELIABILITY"), "{log}");
    let rep: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&report).unwrap()).unwrap();
    let egress = rep
        .as_array()
        .unwrap()
        .iter()
        .find(|a| a["name"].as_str().unwrap().starts_with("egress"))
        .unwrap();
    let notes = egress["notes"].to_string();
    assert!(notes.contains("reliability = \\\"reliable\\\""), "{notes}");
}

#[test]
fn rustdds_egress_names_a_reliable_reader_it_cannot_serve() {
    reliable_reader_on_best_effort_egress("rustdds", 4);
}

#[test]
fn cyclone_egress_names_a_reliable_reader_it_cannot_serve() {
    reliable_reader_on_best_effort_egress("cyclone", 5);
}

#[test]
fn rustdds_egress_to_cyclone_peer() {
    egress("rustdds", 0);
}

#[test]
fn cyclone_egress_to_cyclone_peer() {
    egress("cyclone", 1);
}

#[test]
fn cyclone_peer_to_rustdds_ingress() {
    ingress("rustdds", 2);
}

#[test]
fn cyclone_peer_to_cyclone_ingress() {
    ingress("cyclone", 3);
}
