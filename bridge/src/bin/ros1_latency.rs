//! Measures the ROS 1 egress latency of the bridge's TCPROS publisher on this machine, against a
//! real ROS 1 subscriber: Debian's roscpp (`tests/support/ros1_cpp_sub.cpp`, built once with g++,
//! `tcp_nodelay`), rospy (`tests/tests/ros1_peer.py sub`, with Autoware Mini's `buff_size` 2**26
//! and `tcp_nodelay`), or the bridge's own subscriber in a second process.
//!
//! ```sh
//! cargo run --release -p perturb-bridge --bin ros1_latency -- --subscriber roscpp --image 1920x1208 --path both
//! cargo run --release -p perturb-bridge --bin ros1_latency -- --subscriber rospy --image 1920x1208
//! cargo run --release -p perturb-bridge --bin ros1_latency -- --subscriber bridge --cloud 120000
//! ```
//!
//! `--path` chooses how the publisher sends the frame's data: `copy` serializes the whole message
//! into one buffer (`Publisher::publish`), `shared` writes the header and tail around the data
//! where it lies with one vectored write (`Publisher::publish_shared`, the egress path for frames
//! in shared memory), `both` alternates the two frame by frame and reports each.
//!
//! It starts Debian's `rosmaster --core` on a free loopback port (private ROS_HOME), publishes
//! `--count` frames at `--rate` Hz, and writes `CLOCK_MONOTONIC` at the moment it calls
//! `publish` into the header stamp; the subscriber subtracts it from the time its callback gets
//! the message (deserialized, data in hand). A figure covers the bridge's serialization and
//! copy, the TCP loopback and the subscriber's read and deserialization: the egress hop of a
//! frame that left the daemon.

mod common;
#[path = "common/roscpp.rs"]
mod roscpp;

use perturb_bridge::dds::{Qos, Received, RosType, TopicSpec};
use perturb_bridge::frame::{OwnedPayload, Payload, monotonic_ns};
use perturb_bridge::ros1::{Node, Ros1Settings, SharedData, TopicReader1};
use perturb_bridge::stats::summarize;
use perturb_bridge::topic::TopicReader;
use std::collections::HashMap;
use std::process::{Child, Command, Stdio};
use std::sync::Arc;
use std::time::{Duration, Instant};

struct Args {
    subscriber: String,
    role_reader: bool,
    image: Option<(u32, u32)>,
    cloud: Option<usize>,
    count: usize,
    rate: f64,
    master: Option<String>,
    path: String,
}

fn parse() -> Result<Args, String> {
    let mut a = Args {
        subscriber: "rospy".into(),
        role_reader: false,
        image: None,
        cloud: None,
        count: 100,
        rate: 10.0,
        master: None,
        path: "shared".into(),
    };
    let mut it = std::env::args().skip(1);
    while let Some(k) = it.next() {
        let mut v = || it.next().ok_or(format!("{k} needs a value"));
        match k.as_str() {
            "--subscriber" => a.subscriber = v()?,
            "--role-reader" => a.role_reader = true,
            "--master" => a.master = Some(v()?),
            "--image" => {
                let s = v()?;
                a.image = Some(
                    s.split_once('x')
                        .and_then(|(w, h)| Some((w.parse().ok()?, h.parse().ok()?)))
                        .ok_or(format!("--image {s}: expected WxH"))?,
                );
            }
            "--cloud" => a.cloud = Some(v()?.parse().map_err(|e| format!("--cloud: {e}"))?),
            "--count" => a.count = v()?.parse().map_err(|e| format!("--count: {e}"))?,
            "--rate" => a.rate = v()?.parse().map_err(|e| format!("--rate: {e}"))?,
            "--path" => {
                a.path = v()?;
                if !["copy", "shared", "both"].contains(&a.path.as_str()) {
                    return Err(format!("--path {}: copy, shared or both", a.path));
                }
            }
            "-h" | "--help" => {
                println!(
                    "ros1_latency [--subscriber roscpp|rospy|bridge] (--image WxH | --cloud POINTS) [--count N] [--rate HZ] [--path copy|shared|both]"
                );
                std::process::exit(0);
            }
            o => return Err(format!("unknown argument {o}")),
        }
    }
    if a.image.is_none() && a.cloud.is_none() {
        a.image = Some((1920, 1208));
    }
    Ok(a)
}

const TOPIC: &str = "/perturb_latency/frames";

fn ros_type(a: &Args) -> RosType {
    if a.cloud.is_some() {
        RosType::PointCloud2
    } else {
        RosType::Image
    }
}

/// The bridge's own subscriber: prints `arrival_ns stamp_ns` per message.
fn reader(a: &Args) -> Result<(), String> {
    let master = a.master.clone().ok_or("--master is needed")?;
    let settings =
        Ros1Settings::resolve(Some(&master), Some("127.0.0.1"), "perturb_latency_reader")?;
    let node = Node::start(&settings).map_err(|e| e.to_string())?;
    let spec = TopicSpec {
        topic: TOPIC.into(),
        ros_type: ros_type(a),
        qos: Qos::default(),
    };
    let mut r = TopicReader1::new(&node, &spec).map_err(|e| e.to_string())?;
    println!("ready");
    let end = Instant::now() + Duration::from_secs(600);
    while Instant::now() < end {
        r.take(Duration::from_millis(200), &mut |_, m| {
            let now = monotonic_ns();
            let h = match m {
                Ok(Received::Image(i)) => i.header,
                Ok(Received::Cloud(c)) => c.header,
                _ => return,
            };
            let stamp = h.stamp_sec as u32 as u64 * 1_000_000_000 + h.stamp_nanosec as u64;
            println!("{now} {stamp}");
        })
        .map_err(|e| e.to_string())?;
    }
    Ok(())
}

fn start_master(home: &std::path::Path) -> Result<(Child, String), String> {
    let port = std::net::TcpListener::bind("127.0.0.1:0")
        .and_then(|l| l.local_addr())
        .map_err(|e| e.to_string())?
        .port();
    let child = Command::new("rosmaster")
        .args(["--core", "-p", &port.to_string()])
        .env("ROS_HOME", home)
        .env("ROS_HOSTNAME", "127.0.0.1")
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .map_err(|e| format!("starting rosmaster (apt-get install ros-core): {e}"))?;
    let t = Instant::now();
    while std::net::TcpStream::connect(("127.0.0.1", port)).is_err() {
        if t.elapsed() > Duration::from_secs(20) {
            return Err("rosmaster did not start".into());
        }
        std::thread::sleep(Duration::from_millis(100));
    }
    Ok((child, format!("http://127.0.0.1:{port}/")))
}

fn writer(a: &Args) -> Result<(), String> {
    let home = std::env::temp_dir().join(format!("perturb-ros1-latency-{}", std::process::id()));
    std::fs::create_dir_all(&home).map_err(|e| e.to_string())?;
    let (mut master, uri) = start_master(&home)?;
    let settings = Ros1Settings::resolve(Some(&uri), Some("127.0.0.1"), "perturb_latency_writer")?;
    let node = Node::start(&settings).map_err(|e| e.to_string())?;
    let ty = perturb_bridge::ros1::msg_type(ros_type(a));
    let mut publisher = node.advertise(TOPIC, ty).map_err(|e| e.to_string())?;
    let mut child = spawn_subscriber(a, &uri, &home)?;
    let rx = common::lines_of(child.stdout.take().ok_or("no stdout")?);
    let t = Instant::now();
    while publisher.subscribers() == 0 {
        if t.elapsed() > Duration::from_secs(30) {
            let _ = child.kill();
            return Err("the subscriber never connected".into());
        }
        std::thread::sleep(Duration::from_millis(50));
    }
    let frame_id = if a.cloud.is_some() { "lidar" } else { "camera" };
    let mut frame = common::test_frame(a.image, a.cloud, frame_id)?;
    let bytes = frame.payload().data().len();
    // The frame's data as a sample in shared memory would hold it: sent from where it lies on
    // the shared path.
    let sample: Arc<[u8]> = frame.payload().data().into();
    let shared_at = |k: usize| match a.path.as_str() {
        "copy" => false,
        "shared" => true,
        _ => k % 2 == 1,
    };
    // Warm-up: 10 frames, not counted.
    for k in 0..10 {
        publish(&mut publisher, &mut frame, shared_at(k).then_some(&sample));
        std::thread::sleep(Duration::from_millis(100));
    }
    std::thread::sleep(Duration::from_millis(500));
    while rx.try_recv().is_ok() {}
    let copied_before = publisher.copied();
    let period = Duration::from_secs_f64(1.0 / a.rate);
    let start = Instant::now();
    let mut sent: HashMap<bool, Vec<u64>> = HashMap::new();
    let mut path_of = HashMap::new();
    for k in 0..a.count {
        let due = start + period * k as u32;
        if let Some(d) = due.checked_duration_since(Instant::now()) {
            std::thread::sleep(d);
        }
        let t0 = monotonic_ns();
        let stamp = publish(&mut publisher, &mut frame, shared_at(k).then_some(&sample));
        sent.entry(shared_at(k))
            .or_default()
            .push(monotonic_ns() - t0);
        path_of.insert(stamp, shared_at(k));
    }
    std::thread::sleep(Duration::from_secs(2));
    let mut lat: HashMap<bool, Vec<u64>> = HashMap::new();
    for (stamp, l) in latencies(&rx, a.subscriber == "rospy") {
        if let Some(&shared) = path_of.get(&stamp) {
            lat.entry(shared).or_default().push(l);
        }
    }
    let copied = publisher.copied() - copied_before;
    let _ = child.kill();
    let _ = child.wait();
    drop(publisher);
    drop(node);
    let _ = master.kill();
    let _ = master.wait();
    let _ = std::fs::remove_dir_all(&home);
    let what = match (a.image, a.cloud) {
        (_, Some(n)) => format!("{n}-point cloud"),
        (Some((w, h)), None) => format!("{w}x{h} rgb8"),
        (None, None) => "frame".into(),
    };
    for shared in [false, true] {
        let Some(sent) = sent.get(&shared) else {
            continue;
        };
        let got = lat.get(&shared).cloned().unwrap_or_default();
        let s = summarize(&got);
        let p = summarize(sent);
        println!(
            "bridge -> {} | {what} ({:.1} MB) | path {} | {} of {} received | p50 {:.2} ms | p99 {:.2} ms | max {:.2} ms | publish call p50 {:.2} ms{}",
            a.subscriber,
            bytes as f64 / 1e6,
            if shared { "shared" } else { "copy" },
            got.len(),
            sent.len(),
            s.p50_ms,
            s.p99_ms,
            s.max_ms,
            p.p50_ms,
            if shared {
                format!(" | {copied} sent as copies (subscriber behind)")
            } else {
                String::new()
            }
        );
    }
    Ok(())
}

/// A frame's data held as a shared-memory sample is: reference-counted, never copied.
struct SampleData(Arc<[u8]>);

impl SharedData for SampleData {
    fn data(&self) -> &[u8] {
        &self.0
    }
}

/// Stamps `f` with the time now and publishes it (its header and tail around its data): copied
/// into one buffer, or with `sample` (the same bytes as `f`'s data) sent from where it lies.
/// Returns the stamp (ns) as the subscriber reads it back.
fn publish(
    p: &mut perturb_bridge::ros1::Publisher,
    f: &mut OwnedPayload,
    sample: Option<&Arc<[u8]>>,
) -> u64 {
    let now = monotonic_ns();
    common::set_stamp(f, now, None);
    let payload = f.payload();
    let parts = match &payload {
        Payload::Image(m) => m.ros1_parts(0),
        Payload::Cloud(m) => m.ros1_parts(0),
    };
    match sample {
        Some(s) => p.publish_shared(&parts.head, Box::new(SampleData(s.clone())), &parts.tail),
        None => p.publish(&[&parts.head, parts.data, &parts.tail]),
    };
    (now / 1_000_000_000) as i32 as u32 as u64 * 1_000_000_000 + now % 1_000_000_000
}

/// The subscriber measured: rospy (`tests/tests/ros1_peer.py`) or this program as the reader.
fn spawn_subscriber(a: &Args, uri: &str, home: &std::path::Path) -> Result<Child, String> {
    let kind = if a.cloud.is_some() { "cloud" } else { "image" };
    match a.subscriber.as_str() {
        "rospy" => {
            Command::new(std::env::var("PERTURB_ROS_PYTHON").unwrap_or("/usr/bin/python3".into()))
                .arg(concat!(
                    env!("CARGO_MANIFEST_DIR"),
                    "/../tests/tests/ros1_peer.py"
                ))
                .args([
                    "sub",
                    "--topic",
                    TOPIC,
                    "--type",
                    kind,
                    "--count",
                    &(a.count + 1000).to_string(),
                ])
                .args(["--timeout", "600", "--no-hash"])
                .env("ROS_MASTER_URI", uri)
                .env("ROS_HOSTNAME", "127.0.0.1")
                .env("ROS_HOME", home)
                .stdout(Stdio::piped())
                .stderr(Stdio::inherit())
                .spawn()
                .map_err(|e| e.to_string())
        }
        "roscpp" => {
            let src = concat!(
                env!("CARGO_MANIFEST_DIR"),
                "/../tests/support/ros1_cpp_sub.cpp"
            );
            // target/<profile>/ros1_latency -> target/roscpp/
            let exe = std::env::current_exe().map_err(|e| e.to_string())?;
            let out = exe
                .parent()
                .and_then(std::path::Path::parent)
                .ok_or("no target directory")?
                .join("roscpp");
            let bin = roscpp::build(std::path::Path::new(src), &out).map_err(|e| {
                format!("building the roscpp subscriber (apt-get install g++ libroscpp-dev libsensor-msgs-dev): {e}")
            })?;
            Command::new(bin)
                .args([TOPIC, kind])
                .env("ROS_MASTER_URI", uri)
                .env("ROS_HOSTNAME", "127.0.0.1")
                .env("ROS_HOME", home)
                .stdout(Stdio::piped())
                .stderr(Stdio::inherit())
                .spawn()
                .map_err(|e| e.to_string())
        }
        "bridge" => Command::new(std::env::current_exe().map_err(|e| e.to_string())?)
            .args(["--role-reader", "--master", uri])
            .args(if a.cloud.is_some() {
                ["--cloud", "1"]
            } else {
                ["--image", "1x1"]
            })
            .stdout(Stdio::piped())
            .stderr(Stdio::inherit())
            .spawn()
            .map_err(|e| e.to_string()),
        o => Err(format!("--subscriber {o}: roscpp, rospy or bridge")),
    }
}

/// The stamps and latencies (ns) the subscriber printed: rospy's JSON lines (arrival time and
/// stamp), or the `arrival stamp` lines of roscpp and the reader.
fn latencies(rx: &crossbeam::channel::Receiver<String>, rospy: bool) -> Vec<(u64, u64)> {
    let mut lat = Vec::new();
    while let Ok(l) = rx.try_recv() {
        if rospy {
            let v: serde_json::Value = match serde_json::from_str(&l) {
                Ok(v) => v,
                Err(_) => continue,
            };
            if let (Some(t), Some(s), Some(n)) = (
                v["t_arrival_ns"].as_u64(),
                v["sec"].as_u64(),
                v["nsec"].as_u64(),
            ) {
                let stamp = s * 1_000_000_000 + n;
                lat.push((stamp, t.saturating_sub(stamp)));
            }
        } else if let Some((t, s)) = l.split_once(' ')
            && let (Ok(t), Ok(s)) = (t.parse::<u64>(), s.parse::<u64>())
        {
            lat.push((s, t.saturating_sub(s)));
        }
    }
    lat
}

fn main() {
    let r = parse().and_then(|a| {
        if a.role_reader {
            reader(&a)
        } else {
            writer(&a)
        }
    });
    if let Err(e) = r {
        eprintln!("error: {e}");
        std::process::exit(1);
    }
}
