//! MCAP replay and record through the bridge binary, checked by independent readers: a real
//! rosbag2 bag from ../shared/data replayed and recorded, the recording read back by the Python
//! `rosbags` package; damaged and ROS 1 bags; the replay engine's topic selection, start offset
//! and looping.

mod common;

use common::*;
use perturb_bag::{Bag, BagWriter, Filter, SensorMessage, WriterOptions};
use perturb_bridge::adapter::Control;
use perturb_bridge::config::ReplaySection;
use perturb_bridge::frame::Payload;
use perturb_bridge::replay::Replay;
use perturb_core::formats::ros::{Header, ImageMsg};
use perturb_core::synthetic::street_image;
use sha2::{Digest, Sha256};
use std::collections::BTreeMap;
use std::ops::ControlFlow;
use std::path::Path;
use std::process::Command;
use std::sync::Arc;
use std::sync::atomic::AtomicBool;

fn sha(b: &[u8]) -> String {
    hex::encode(Sha256::digest(b))
}

fn rosbags_read(bag: &Path) -> Option<Vec<serde_json::Value>> {
    if !need(
        has_python_module("rosbags"),
        "the Python module rosbags (pip install rosbags)",
    ) {
        return None;
    }
    let out = Command::new(python())
        .arg(concat!(env!("CARGO_MANIFEST_DIR"), "/tests/read_bag.py"))
        .arg(bag)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "rosbags could not read {}: {}",
        bag.display(),
        String::from_utf8_lossy(&out.stderr)
    );
    Some(
        String::from_utf8_lossy(&out.stdout)
            .lines()
            .map(|l| serde_json::from_str(l).unwrap())
            .collect(),
    )
}

#[test]
fn kitti_bag_replayed_and_recorded_reads_back_in_rosbags() {
    let Some(src) = shared_data("ros2_mcap_kitti_000001") else {
        return;
    };
    let dir = scratch("kitti-replay");
    let out = dir.join("rec");
    let run = Command::new(bridge_exe())
        .args(["--linger", "1", "replay"])
        .arg(&src)
        .args(["--bus", "local", "--rate", "0", "--record"])
        .arg(&out)
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&run.stdout);
    assert!(
        run.status.success(),
        "{stdout}\n{}",
        String::from_utf8_lossy(&run.stderr)
    );
    // What the source bag holds, decoded by perturb-bag.
    let mut want: BTreeMap<String, (i32, u32, String, Option<String>)> = BTreeMap::new();
    Bag::open(&src)
        .unwrap()
        .for_each(&Filter::default(), |m| {
            let entry = match m.decode() {
                Some(Ok(SensorMessage::Image(i))) => (
                    i.header.stamp_sec,
                    i.header.stamp_nanosec,
                    i.header.frame_id.to_string(),
                    Some(sha(i.data)),
                ),
                Some(Ok(SensorMessage::Cloud(c))) => (
                    c.header.stamp_sec,
                    c.header.stamp_nanosec,
                    c.header.frame_id.to_string(),
                    Some(sha(c.data)),
                ),
                Some(Ok(SensorMessage::Compressed(c))) => (
                    c.header.stamp_sec,
                    c.header.stamp_nanosec,
                    c.header.frame_id.to_string(),
                    None,
                ),
                _ => return Ok(ControlFlow::Continue(())),
            };
            want.insert(format!("/{}/raw", m.topic.trim_start_matches('/')), entry);
            Ok(ControlFlow::Continue(()))
        })
        .unwrap();
    assert_eq!(want.len(), 3, "image, compressed image and cloud topics");
    let Some(lines) = rosbags_read(&out) else {
        return;
    };
    let msgs: Vec<_> = lines.iter().filter(|l| l.get("topic").is_some()).collect();
    assert_eq!(msgs.len(), 3, "every frame recorded once: {msgs:?}");
    for m in msgs {
        let topic = m["topic"].as_str().unwrap();
        let (sec, nanosec, frame_id, data) = want
            .get(topic)
            .unwrap_or_else(|| panic!("unexpected topic {topic}"));
        assert_eq!(m["sec"].as_i64().unwrap(), *sec as i64, "{topic}");
        assert_eq!(m["nanosec"].as_u64().unwrap(), *nanosec as u64, "{topic}");
        assert_eq!(m["frame_id"].as_str().unwrap(), frame_id, "{topic}");
        if let Some(d) = data {
            assert_eq!(m["sha256"].as_str().unwrap(), d, "{topic}: data bit-exact");
        } else {
            // The compressed PNG was decoded to a raw Image.
            assert_eq!(m["type"], "sensor_msgs/msg/Image");
            assert!(m["width"].as_u64().unwrap() > 1000);
        }
    }
    // The CameraInfo topic is not a sensor frame: counted as skipped.
    assert!(stdout.contains("replay"), "{stdout}");
}

/// A bag of `n` small images 100 ms apart with stamps (1000 + i, i).
fn image_bag(dir: &Path, n: u32) -> Vec<u8> {
    let opts = WriterOptions {
        compression: perturb_bag::Compression::None,
        chunk_size: 4096,
        ..Default::default()
    };
    let mut w = BagWriter::create(dir, &opts).unwrap();
    let ch = w.add_topic("/cam", "sensor_msgs/msg/Image").unwrap();
    let other = w.add_topic("/other", "sensor_msgs/msg/Image").unwrap();
    let img = street_image(16, 8, 0);
    for i in 0..n {
        let m = ImageMsg::from_view(
            Header {
                stamp_sec: 1000 + i as i32,
                stamp_nanosec: i,
                frame_id: "cam",
            },
            &img.view(),
        );
        let t = 1_000_000_000 + i as u64 * 100_000_000;
        w.write(ch, t, t, &m.encode()).unwrap();
        w.write(other, t + 1, t + 1, &m.encode()).unwrap();
    }
    w.finish().unwrap();
    std::fs::read(dir.join(format!(
        "{}_0.mcap",
        dir.file_name().unwrap().to_str().unwrap()
    )))
    .unwrap()
}

#[test]
fn replay_engine_selects_topics_skips_the_offset_and_loops() {
    let dir = scratch("engine");
    image_bag(&dir.join("b"), 5);
    let replay = Replay::open(ReplaySection {
        bag: dir.join("b"),
        rate: 0.0,
        start_offset: 0.25,
        looped: true,
        topics: [("/cam".to_string(), "camera".to_string())].into(),
    })
    .unwrap();
    let stop = Arc::new(AtomicBool::new(false));
    let ctl = Control::new(stop, None);
    let mut seen = Vec::new();
    let rep = replay
        .run(&ctl, "test", &mut |stream, meta, p| {
            assert_eq!(stream, "camera");
            let Payload::Image(m) = p else { panic!() };
            seen.push((meta.seq, m.header.stamp_sec));
            if seen.len() == 6 {
                ctl.stop_all();
            }
            Ok(())
        })
        .unwrap();
    // Offset 0.25 s skips the messages at 0, 0.1 and 0.2 s: stamps 1003, 1004, then again.
    let stamps: Vec<i32> = seen.iter().map(|s| s.1).collect();
    assert_eq!(stamps, [1003, 1004, 1003, 1004, 1003, 1004]);
    let seqs: Vec<u64> = seen.iter().map(|s| s.0).collect();
    assert_eq!(
        seqs,
        [0, 1, 2, 3, 4, 5],
        "sequence numbers keep counting across loops"
    );
    assert!(rep.damage.is_empty());
}

/// A looping replay of a bag whose messages share one instant passes ten times a second; it
/// used to log every pass (9 lines a second). The first pass is logged, then once a minute.
#[test]
fn a_looping_replay_of_a_one_instant_bag_does_not_flood_the_log() {
    let dir = scratch("one-instant");
    let bag = dir.join("b");
    let mut w = BagWriter::create(
        &bag,
        &WriterOptions {
            compression: perturb_bag::Compression::None,
            chunk_size: 4096,
            ..Default::default()
        },
    )
    .unwrap();
    let ch = w.add_topic("/cam", "sensor_msgs/msg/Image").unwrap();
    let img = street_image(16, 8, 0);
    let m = ImageMsg::from_view(
        Header {
            stamp_sec: 1,
            stamp_nanosec: 0,
            frame_id: "cam",
        },
        &img.view(),
    );
    w.write(ch, 1_000, 1_000, &m.encode()).unwrap();
    w.finish().unwrap();
    let mut child = Command::new(bridge_exe())
        .args(["replay", "--bus", "local", "--loop"])
        .arg(&bag)
        .env("RUST_LOG", "info")
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    std::thread::sleep(std::time::Duration::from_secs(3));
    interrupt(&mut child, std::time::Duration::from_secs(10)).expect("stops on SIGINT");
    let out = child.wait_with_output().unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    let stderr = String::from_utf8_lossy(&out.stderr);
    let loops = stderr.matches("looping").count();
    assert!(
        stdout.contains("stopped: SIGINT/SIGTERM"),
        "{stdout}{stderr}"
    );
    assert_eq!(loops, 1, "one line for the first pass: {stderr}");
    let _ = std::fs::remove_dir_all(&dir);
}

/// A clean SIGINT of a bridge with RustDDS participants (pinned to loopback) logs no ERROR
/// line: tearing RustDDS down used to log 14-26 of them (leaving multicast groups, removing
/// writers from closed channels), which hid real errors.
#[test]
fn a_clean_sigint_with_rustdds_logs_no_error() {
    let dir = scratch("rustdds-sigint");
    let cfg = dir.join("b.toml");
    std::fs::write(
        &cfg,
        format!(
            "[bridge]\nbus = \"local\"\n[dds]\nbackend = \"rustdds\"\ndomain_id = {}\ninterfaces = [\"lo\"]\n\
             [[ingress]]\ntopic = \"/in/img\"\ntype = \"image\"\nstream = \"cam\"\n\
             [[egress]]\nstream = \"cam\"\ntopic = \"/out/img\"\n",
            domain(2)
        ),
    )
    .unwrap();
    let mut child = Command::new(bridge_exe())
        .arg("--config")
        .arg(&cfg)
        .env_remove("RUST_LOG")
        .stdout(std::process::Stdio::piped())
        // A file: RustDDS warns a lot, which would fill a pipe nobody reads yet.
        .stderr(std::fs::File::create(dir.join("stderr")).unwrap())
        .spawn()
        .unwrap();
    std::thread::sleep(std::time::Duration::from_secs(3));
    interrupt(&mut child, std::time::Duration::from_secs(15)).expect("stops on SIGINT");
    let out = child.wait_with_output().unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    let stderr = std::fs::read_to_string(dir.join("stderr")).unwrap();
    assert!(
        stdout.contains("stopped: SIGINT/SIGTERM"),
        "{stdout}{stderr}"
    );
    assert!(!stderr.contains("ERROR"), "{stderr}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn truncated_bag_replays_what_can_be_read_and_reports_the_damage() {
    let dir = scratch("damaged");
    let bytes = image_bag(&dir.join("b"), 40);
    // Cut the file in the middle of its chunks (drops the summary too).
    let cut = dir.join("cut.mcap");
    std::fs::write(&cut, &bytes[..bytes.len() * 2 / 3]).unwrap();
    let out = Command::new(bridge_exe())
        .args(["--linger", "0.5", "replay"])
        .arg(&cut)
        .args(["--bus", "local", "--rate", "0", "--record"])
        .arg(dir.join("rec"))
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{stdout}\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(stdout.contains("damage:"), "damage reported: {stdout}");
    let mut n = 0;
    Bag::open(&dir.join("rec"))
        .unwrap()
        .for_each(&Filter::default(), |_| {
            n += 1;
            Ok(ControlFlow::Continue(()))
        })
        .unwrap();
    assert!(
        n > 10 && n < 80,
        "replayed the readable part: {n} of 80 messages"
    );
}

#[test]
fn ros1_profile_mcap_replays_as_a_bag_player() {
    let Some(src) = shared_data("mcap_ouster_os1_pointcloudset/test.mcap") else {
        return;
    };
    let dir = scratch("ros1-mcap");
    let rec = dir.join("rec");
    let out = Command::new(bridge_exe())
        .arg("replay")
        .arg(&src)
        .args(["--bus", "local", "--rate", "0", "--record"])
        .arg(&rec)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let bag = Bag::open(&rec).unwrap();
    let mut clouds = 0;
    let mut images = 0;
    bag.for_each(&Filter::default(), |m| {
        match m.decode() {
            Some(Ok(SensorMessage::Cloud(c))) => {
                assert_eq!(
                    (m.topic, c.width, c.height),
                    ("/os1_cloud_node/points/raw", 2048, 64)
                );
                clouds += 1;
            }
            Some(Ok(SensorMessage::Image(_))) => images += 1,
            _ => {}
        }
        Ok(ControlFlow::Continue(()))
    })
    .unwrap();
    assert_eq!(
        (clouds, images),
        (2, 6),
        "every sensor message of the ROS 1 MCAP replayed"
    );
}

#[test]
fn not_a_bag_and_unknown_topics_name_the_problem() {
    let dir = scratch("notbag");
    let f = dir.join("x.mcap");
    std::fs::write(&f, b"hello").unwrap();
    let out = Command::new(bridge_exe())
        .arg("replay")
        .arg(&f)
        .args(["--bus", "local"])
        .output()
        .unwrap();
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("MCAP"));
    image_bag(&dir.join("b"), 2);
    let out = Command::new(bridge_exe())
        .arg("replay")
        .arg(dir.join("b"))
        .args(["--bus", "local", "--topic", "/nope"])
        .output()
        .unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("no topic `/nope`") && err.contains("/cam"),
        "{err}"
    );
}

#[test]
fn example_configs_are_valid() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../config");
    let mut n = 0;
    for e in std::fs::read_dir(&dir).unwrap() {
        let p = e.unwrap().path();
        let name = p.file_name().unwrap().to_string_lossy().to_string();
        if (name.starts_with("bridge-") && name.ends_with(".toml")) || name == "autoware-mini.toml"
        {
            perturb_bridge::config::Config::load(&p).unwrap_or_else(|e| panic!("{e}"));
            n += 1;
        }
    }
    assert!(n >= 3);
}

#[test]
fn a_recorder_without_a_source_of_its_own_runs_until_stopped_and_says_why() {
    let dir = scratch("record-only");
    let mut child = Command::new(bridge_exe())
        .args([
            "record",
            "--bus",
            "local",
            "--stream",
            "camera_front=image",
            "--out",
        ])
        .arg(dir.join("rec"))
        .args(["--max-frames", "100"])
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    // Nothing feeds the stream in this process: the sources are other processes that may start
    // later. The recorder must wait for them (it used to stop after the 2 s linger).
    std::thread::sleep(std::time::Duration::from_secs(4));
    assert!(
        child.try_wait().unwrap().is_none(),
        "the recorder stopped on its own without a frame"
    );
    let st = interrupt(&mut child, std::time::Duration::from_secs(10)).expect("stops on SIGINT");
    let out = child.wait_with_output().unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        st.success(),
        "{stdout}{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(stdout.contains("stopped: SIGINT/SIGTERM"), "{stdout}");

    // With --seconds it stops by itself, and says so.
    let out = Command::new(bridge_exe())
        .args([
            "record",
            "--bus",
            "local",
            "--stream",
            "camera_front=image",
            "--out",
        ])
        .arg(dir.join("rec2"))
        .args(["--seconds", "1"])
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{stdout}");
    assert!(
        stdout.contains("recorded for the 1 s asked for"),
        "{stdout}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// A large synthetic camera pre-renders for seconds; a SIGINT meanwhile stops the bridge at
/// once (it used to be ignored until every frame was rendered).
#[test]
fn a_synthetic_source_heeds_sigint_while_it_pre_renders() {
    let mut child = Command::new(bridge_exe())
        .args([
            "synthetic",
            "--bus",
            "local",
            "--lidar",
            "",
            "--size",
            "4096x4096",
        ])
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    // 21 frames of 4096x4096 (what fits in the pre-render bound) take well over 10 s here.
    std::thread::sleep(std::time::Duration::from_millis(1500));
    let st = interrupt(&mut child, std::time::Duration::from_secs(5))
        .expect("the bridge stops within 5 s of SIGINT while pre-rendering");
    let out = child.wait_with_output().unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        st.success(),
        "{stdout}{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(stdout.contains("stopped: SIGINT/SIGTERM"), "{stdout}");
}

#[test]
fn check_resolves_what_the_run_would_resolve() {
    let dir = scratch("check-resolves");
    std::fs::create_dir_all(&dir).unwrap();
    let check = |name: &str, text: &str| {
        let p = dir.join(name);
        std::fs::write(&p, text).unwrap();
        let o = Command::new(bridge_exe())
            .arg("--config")
            .arg(&p)
            .arg("--check")
            .output()
            .unwrap();
        (
            o.status.success(),
            String::from_utf8_lossy(&o.stderr).to_string(),
        )
    };
    let (ok, err) = check(
        "missing.toml",
        "[bridge]\nbus = \"local\"\n[replay]\nbag = \"no_such.mcap\"\n",
    );
    assert!(
        !ok && err.contains("replay.bag") && err.contains("no_such.mcap"),
        "{err}"
    );
    let (ok, err) = check(
        "kind.toml",
        "[bridge]\nbus = \"local\"\n[dds]\ninterfaces = [\"lo\"]\n\
         [[synthetic.camera]]\nstream = \"cam\"\nwidth = 64\nheight = 48\n\
         [[egress]]\nstream = \"cam\"\ntopic = \"/cam\"\nkind = \"cloud\"\n",
    );
    assert!(
        !ok && err.contains("egress[0].kind") && err.contains("cam"),
        "{err}"
    );
    let (ok, err) = check(
        "record.toml",
        "[bridge]\nbus = \"local\"\n[record]\nout = \"rec\"\nstreams = [\"nobody\"]\n",
    );
    assert!(
        !ok && err.contains("record.streams[0]") && err.contains("nobody"),
        "{err}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}
