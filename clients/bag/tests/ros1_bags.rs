//! ROS 1 bags and ROS 1 profile MCAP: bags written by Debian's Python `rosbag` (none, bz2, lz4)
//! read in log-time order, bags written here read by `rosbag` (Python), `rosbag info` and
//! `rosbags`, damaged and unindexed bags, and the real Ouster recording in `../shared/data`.
//! Missing ROS 1 packages skip the tests with a message, or fail them under
//! `PERTURB_REQUIRE_ORACLES=1` (CI).

use perturb_bag::ros1::{Ros1Compression, Ros1Writer, Ros1WriterOptions};
use perturb_bag::{AnyWriter, Bag, BagFormat, Filter, ReadOrder, SensorMessage};
use perturb_core::cloud::{Cloud, PointLayout};
use perturb_core::formats::ros::{Header, ImageMsg, PointCloud2Msg};
use perturb_core::formats::ros1;
use perturb_core::image::{Image, PixelFormat};
use sha2::{Digest, Sha256};
use std::ops::ControlFlow;
use std::path::{Path, PathBuf};
use std::process::Command;

const ROS1_PACKAGES: &str = "Debian's ROS 1 packages (apt-get install ros-core python3-rospy python3-rosbag python3-sensor-msgs python3-std-msgs)";

fn required() -> bool {
    std::env::var("PERTURB_REQUIRE_ORACLES").is_ok_and(|v| v == "1")
}

/// The Python with Debian's ROS 1 modules (not a virtualenv's).
fn ros_python() -> String {
    std::env::var("PERTURB_ROS_PYTHON").unwrap_or_else(|_| "/usr/bin/python3".into())
}

fn have_ros1() -> bool {
    let ok = Command::new(ros_python())
        .args(["-c", "import rosbag, sensor_msgs.msg, std_msgs.msg"])
        .output()
        .is_ok_and(|o| o.status.success());
    if !ok {
        assert!(
            !required(),
            "{ROS1_PACKAGES} are missing and PERTURB_REQUIRE_ORACLES=1"
        );
        eprintln!("SKIP: {ROS1_PACKAGES} are missing");
    }
    ok
}

fn have_rosbags() -> bool {
    let ok = Command::new("python3")
        .args(["-c", "import rosbags"])
        .output()
        .is_ok_and(|o| o.status.success());
    if !ok {
        assert!(
            !required(),
            "the python package rosbags is missing and PERTURB_REQUIRE_ORACLES=1"
        );
        eprintln!("SKIP: the python package rosbags is missing (pip install rosbags)");
    }
    ok
}

fn tmp(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("perturb-ros1-bag-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn script() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/ros1_bag.py")
}

fn sha(b: &[u8]) -> String {
    hex::encode(Sha256::digest(b))
}

/// Every message of a bag as Python `rosbag` reads it (first line: the summary).
fn python_read(bag: &Path) -> (serde_json::Value, Vec<serde_json::Value>) {
    let o = Command::new(ros_python())
        .arg(script())
        .arg("read")
        .arg(bag)
        .output()
        .unwrap();
    assert!(
        o.status.success(),
        "python rosbag could not read {}: {}",
        bag.display(),
        String::from_utf8_lossy(&o.stderr)
    );
    let mut lines = String::from_utf8_lossy(&o.stdout)
        .lines()
        .map(|l| serde_json::from_str::<serde_json::Value>(l).unwrap())
        .collect::<Vec<_>>();
    let summary = lines.remove(0);
    (summary, lines)
}

/// Every message of a bag as this crate reads it, in the JSON shape of `ros1_bag.py read`.
fn our_read(bag: &Path, filter: &Filter) -> (Vec<serde_json::Value>, perturb_bag::ReadReport) {
    let bag = Bag::open(bag).unwrap();
    let mut out = Vec::new();
    let report = bag
        .for_each(filter, |m| {
            assert_eq!(m.encoding, "ros1");
            assert_eq!(m.schema_encoding, "ros1msg");
            let mut d =
                serde_json::json!({"topic": m.topic, "type": m.type_name, "time": m.log_time});
            match m.decode() {
                Some(Ok(SensorMessage::Image(i))) => {
                    d["seq"] = m.header_seq().unwrap().into();
                    d["sec"] = i.header.stamp_sec.into();
                    d["nsec"] = i.header.stamp_nanosec.into();
                    d["frame_id"] = i.header.frame_id.into();
                    d["sha256"] = sha(i.data).into();
                    d["width"] = i.width.into();
                    d["height"] = i.height.into();
                    d["encoding"] = i.encoding.into();
                    assert_eq!(i.encode_ros1(m.header_seq().unwrap()), m.data);
                }
                Some(Ok(SensorMessage::Cloud(c))) => {
                    d["seq"] = m.header_seq().unwrap().into();
                    d["sec"] = c.header.stamp_sec.into();
                    d["nsec"] = c.header.stamp_nanosec.into();
                    d["frame_id"] = c.header.frame_id.into();
                    d["sha256"] = sha(c.data).into();
                    d["width"] = c.width.into();
                    d["height"] = c.height.into();
                    d["fields"] = c
                        .fields
                        .iter()
                        .map(|f| f.name.clone())
                        .collect::<Vec<_>>()
                        .into();
                    d["is_dense"] = c.is_dense.into();
                    c.view().unwrap();
                }
                Some(Ok(SensorMessage::Compressed(_))) => unreachable!(),
                Some(Err(e)) => panic!("{e}"),
                None => {
                    assert_eq!(m.type_name, "std_msgs/String");
                    d["data"] = ros1::decode_string(m.data).unwrap().into();
                }
            }
            out.push(d);
            Ok(ControlFlow::Continue(()))
        })
        .unwrap();
    (out, report)
}

#[test]
fn ros1_bags_written_by_python_rosbag_read_in_log_time_order() {
    if !have_ros1() {
        return;
    }
    let dir = tmp("from-python");
    for compression in ["none", "bz2", "lz4"] {
        let path = dir.join(format!("{compression}.bag"));
        let st = Command::new(ros_python())
            .arg(script())
            .args([
                "write",
                path.to_str().unwrap(),
                "--compression",
                compression,
            ])
            .status()
            .unwrap();
        assert!(st.success());
        let (summary, want) = python_read(&path);
        assert_eq!(summary["messages"], 7);
        let bag = Bag::open(&path).unwrap();
        assert!(bag.is_ros1_bag() && bag.is_indexed());
        let topics = bag.topics().unwrap();
        let counts: Vec<_> = topics
            .iter()
            .map(|t| (t.topic.as_str(), t.type_name.as_str(), t.message_count))
            .collect();
        assert_eq!(
            counts,
            [
                ("/cam/image_raw", "sensor_msgs/Image", Some(3)),
                ("/lidar/points", "sensor_msgs/PointCloud2", Some(3)),
                ("/note", "std_msgs/String", Some(1)),
            ]
        );
        assert_eq!(topics[0].metadata["md5sum"], ros1::IMAGE.md5sum);
        assert!(String::from_utf8_lossy(&topics[1].schema).contains("MSG: sensor_msgs/PointField"));
        let (got, report) = our_read(&path, &Filter::default());
        assert_eq!(report.order, ReadOrder::LogTime);
        assert_eq!(report.damage, None);
        let want: Vec<_> = want
            .into_iter()
            .map(|mut w| {
                w.as_object_mut().unwrap().remove("md5");
                w
            })
            .collect();
        assert_eq!(
            got, want,
            "{compression}: every field as Python rosbag reads it"
        );
        // Topic and time filters.
        let only = Filter {
            topics: vec!["/lidar/points".into()],
            start: Some(1_600_000_000_200_000_000),
            end: Some(1_600_000_000_500_000_000),
        };
        let (got, _) = our_read(&path, &only);
        assert_eq!(got.len(), 1);
        assert_eq!(got[0]["seq"], 103);
    }
}

fn sample_image(k: u32) -> Image {
    let mut img = Image::new(6, 3, PixelFormat::Rgb8);
    img.data
        .iter_mut()
        .enumerate()
        .for_each(|(i, b)| *b = (i as u32 * 5 + k) as u8);
    img
}

/// Writes 5 images, then 4 clouds whose times fall between the images' (so chunks overlap in
/// time; each topic is in time order, as a recorder writes it), then one string; returns the
/// expected messages in log-time order.
fn write_ours(path: &Path, compression: Ros1Compression) -> Vec<(String, u64, Vec<u8>)> {
    let mut w = Ros1Writer::create(
        path,
        &Ros1WriterOptions {
            compression,
            chunk_size: 700,
        },
    )
    .unwrap();
    let cam = w
        .add_topic("/cam/image_raw", "sensor_msgs/msg/Image")
        .unwrap();
    let lid = w
        .add_topic("/lidar/points", "sensor_msgs/PointCloud2")
        .unwrap();
    let note = w.add_topic("/note", "std_msgs/String").unwrap();
    let mut want = Vec::new();
    for k in [0u32, 2, 4, 6, 8, 1, 3, 5, 7] {
        let t = 1_700_000_000_000_000_000 + k as u64 * 50_000_000;
        let (topic, ch, bytes) = if k % 2 == 0 {
            let img = sample_image(k);
            let h = Header {
                stamp_sec: k as i32,
                stamp_nanosec: 11,
                frame_id: "cam",
            };
            (
                "/cam/image_raw",
                cam,
                ImageMsg::from_view(h, &img.view()).encode_ros1(k),
            )
        } else {
            let c = Cloud::from_xyzi(&PointLayout::xyzi_f32(), &[[k as f32, 1.0, 2.0, 3.0]; 7]);
            let h = Header {
                stamp_sec: k as i32,
                stamp_nanosec: 13,
                frame_id: "lidar",
            };
            (
                "/lidar/points",
                lid,
                PointCloud2Msg::from_view(h, &c.view()).encode_ros1(k),
            )
        };
        w.write(ch, t, &bytes).unwrap();
        want.push((topic.to_string(), t, bytes));
    }
    let s = ros1::encode_string("the end");
    w.write(note, 1_800_000_000_000_000_000, &s).unwrap();
    want.push(("/note".into(), 1_800_000_000_000_000_000, s));
    assert!(path.with_extension("bag.active").exists() || !path.exists());
    w.finish().unwrap();
    want.sort_by_key(|m| m.1);
    want
}

#[test]
fn ros1_bags_written_here_read_back_and_pass_rosbag_and_rosbags() {
    let dir = tmp("ours");
    let ros1 = have_ros1();
    let rosbags = have_rosbags();
    for compression in [
        Ros1Compression::None,
        Ros1Compression::Bz2,
        Ros1Compression::Lz4,
    ] {
        let path = dir.join(format!("{compression:?}.bag"));
        let want = write_ours(&path, compression);
        assert!(!dir.join(format!("{compression:?}.bag.active")).exists());
        // This crate, across chunks whose times interleave.
        let bag = Bag::open(&path).unwrap();
        let mut got = Vec::new();
        let report = bag
            .for_each(&Filter::default(), |m| {
                got.push((m.topic.to_string(), m.log_time, m.data.to_vec()));
                Ok(ControlFlow::Continue(()))
            })
            .unwrap();
        assert_eq!(report.order, ReadOrder::LogTime);
        assert_eq!(got, want, "{compression:?}");
        if ros1 {
            let (summary, msgs) = python_read(&path);
            assert_eq!(summary["messages"], 10);
            let times: Vec<u64> = msgs.iter().map(|m| m["time"].as_u64().unwrap()).collect();
            assert_eq!(times, want.iter().map(|w| w.1).collect::<Vec<_>>());
            for (m, (_, _, bytes)) in msgs.iter().zip(&want) {
                if m["topic"] == "/cam/image_raw" {
                    let (seq, img) = ImageMsg::decode_ros1(bytes).unwrap();
                    assert_eq!(m["seq"], seq);
                    assert_eq!(m["sha256"], sha(img.data));
                    assert_eq!(m["md5"], ros1::IMAGE.md5sum);
                }
            }
            assert_eq!(msgs[9]["data"], "the end");
            let info = Command::new("rosbag")
                .arg("info")
                .arg(&path)
                .output()
                .unwrap();
            let text = String::from_utf8_lossy(&info.stdout);
            assert!(
                info.status.success(),
                "rosbag info: {}",
                String::from_utf8_lossy(&info.stderr)
            );
            let field = |name: &str| {
                text.lines()
                    .find_map(|l| l.strip_prefix(name))
                    .map(|v| v.trim().to_string())
                    .unwrap_or_default()
            };
            assert_eq!(field("messages:"), "10", "{text}");
            let name = match compression {
                Ros1Compression::None => "none",
                Ros1Compression::Bz2 => "bz2",
                Ros1Compression::Lz4 => "lz4",
            };
            assert!(field("compression:").starts_with(name), "{text}");
            assert!(
                text.contains("sensor_msgs/PointCloud2 [1158d486dd51d683ce2f1be655c3c181]"),
                "{text}"
            );
        }
        if rosbags {
            let o = Command::new("python3")
                .arg("-c")
                .arg(
                    "import sys\nfrom rosbags.rosbag1 import Reader\nfrom rosbags.typesys import Stores, get_typestore\n\
                     ts = get_typestore(Stores.ROS1_NOETIC)\n\
                     with Reader(sys.argv[1]) as r:\n\
                     \tfor c, t, raw in r.messages():\n\
                     \t\tm = ts.deserialize_ros1(raw, c.msgtype)\n\
                     \t\tprint(c.topic, t, getattr(m, 'header', None) and m.header.seq)",
                )
                .arg(&path)
                .output()
                .unwrap();
            assert!(
                o.status.success(),
                "rosbags: {}",
                String::from_utf8_lossy(&o.stderr)
            );
            let lines: Vec<String> = String::from_utf8_lossy(&o.stdout)
                .lines()
                .map(str::to_string)
                .collect();
            assert_eq!(lines.len(), 10);
            assert_eq!(lines[0], format!("/cam/image_raw {} 0", want[0].1));
        }
    }
}

#[test]
fn ros1_bags_unindexed_or_truncated_read_up_to_the_damage() {
    let dir = tmp("damage");
    let path = dir.join("good.bag");
    let want = write_ours(&path, Ros1Compression::Lz4);
    let bytes = std::fs::read(&path).unwrap();
    // A recorder killed before closing leaves index_pos = 0: file order, with a note.
    let mut unindexed = bytes.clone();
    let at = unindexed
        .windows(10)
        .position(|w| w == b"index_pos=")
        .unwrap()
        + 10;
    unindexed[at..at + 8].fill(0);
    let up = dir.join("unindexed.bag");
    std::fs::write(&up, &unindexed).unwrap();
    let bag = Bag::open(&up).unwrap();
    assert!(!bag.is_indexed());
    assert_eq!(bag.topics().unwrap().len(), 3);
    let mut got = Vec::new();
    let report = bag
        .for_each(&Filter::default(), |m| {
            got.push(m.log_time);
            Ok(ControlFlow::Continue(()))
        })
        .unwrap();
    assert_eq!(report.order, ReadOrder::FileOrder);
    assert_eq!(got.len(), 10, "every message, in file order");
    assert_ne!(got, want.iter().map(|w| w.1).collect::<Vec<_>>());
    assert!(
        report.notes.iter().any(|n| n.contains("unindexed")),
        "{:?}",
        report.notes
    );
    // Cut in the middle: the messages before the cut, and the damage named.
    let cut = dir.join("cut.bag");
    std::fs::write(&cut, &bytes[..bytes.len() / 2]).unwrap();
    let bag = Bag::open(&cut).unwrap();
    let mut n = 0;
    let report = bag
        .for_each(&Filter::default(), |_| {
            n += 1;
            Ok(ControlFlow::Continue(()))
        })
        .unwrap();
    assert!(n > 0 && n < 10, "{n}");
    let damage = report.damage.expect("damage reported");
    assert!(
        damage.contains("cut.bag") && damage.contains("past the end"),
        "{damage}"
    );
    // Not a bag of a version this crate reads.
    std::fs::write(&cut, b"#ROSBAG V1.2\nold").unwrap();
    let err = Bag::open(&cut).unwrap_err().to_string();
    assert!(err.contains("V1.2") && err.contains("cut.bag"), "{err}");
}

/// Every chunk of a ROS 1 bag claims to decompress to almost 4 GiB (its `size` field): the
/// reader reports the damage, naming the chunk, before allocating anything (the same guard as
/// the MCAP reader's), whether it reads through the index, in file order or from memory.
#[test]
fn ros1_bag_chunk_sizes_are_checked_before_anything_is_allocated() {
    let dir = tmp("hostile");
    let path = dir.join("good.bag");
    write_ours(&path, Ros1Compression::Lz4);
    let mut bytes = std::fs::read(&path).unwrap();
    // The `size=` field of every chunk header: u32 length 9, `size=`, u32 value.
    let field = b"\x09\x00\x00\x00size=";
    let mut hits = 0;
    let mut i = 0;
    while let Some(p) = bytes[i..].windows(field.len()).position(|w| w == field) {
        let at = i + p + field.len();
        bytes[at..at + 4].copy_from_slice(&0xFFFF_FFF0u32.to_le_bytes());
        hits += 1;
        i = at + 4;
    }
    assert!(hits >= 2, "the sample bag has several chunks ({hits})");
    let mut unindexed = bytes.clone();
    let at = unindexed
        .windows(10)
        .position(|w| w == b"index_pos=")
        .unwrap()
        + 10;
    unindexed[at..at + 8].fill(0);
    for (name, b) in [("indexed.bag", &bytes), ("unindexed.bag", &unindexed)] {
        let p = dir.join(name);
        std::fs::write(&p, b).unwrap();
        for bag in [
            Bag::open(&p).unwrap(),
            Bag::from_bytes(&p, b.to_vec()).unwrap(),
        ] {
            let mut n = 0;
            let report = bag
                .for_each(&Filter::default(), |_| {
                    n += 1;
                    Ok(ControlFlow::Continue(()))
                })
                .unwrap();
            assert_eq!(n, 0, "{name}");
            let damage = report.damage.expect("damage reported");
            assert!(
                damage.contains(name)
                    && damage.contains("4294967280 bytes once decompressed")
                    && damage.contains("chunk at byte"),
                "{damage}"
            );
        }
    }
}

#[test]
fn ros1_any_writer_picks_the_format_of_the_path() {
    let dir = tmp("any");
    assert_eq!(BagFormat::of_path(Path::new("x.bag")), BagFormat::Ros1);
    assert_eq!(BagFormat::of_path(Path::new("x")), BagFormat::Rosbag2);
    let path = dir.join("a.bag");
    let mut w = AnyWriter::create(&path, BagFormat::Ros1, Some("bz2")).unwrap();
    let ch = w.add_topic("/s", "std_msgs/msg/String").unwrap();
    w.write(ch, 5, 5, &ros1::encode_string("x")).unwrap();
    assert_eq!(w.finish().unwrap(), path);
    let bag = Bag::open(&path).unwrap();
    let t = &bag.topics().unwrap()[0];
    assert_eq!(
        (t.type_name.as_str(), t.message_encoding.as_str()),
        ("std_msgs/String", "ros1")
    );
    let err = AnyWriter::create(&dir.join("b.bag"), BagFormat::Ros1, Some("zstd")).unwrap_err();
    assert!(err.to_string().contains("zstd"), "{err}");
}

#[test]
fn ros1_profile_mcap_ouster_clouds_decode() {
    let p = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../../shared/data/mcap_ouster_os1_pointcloudset/test.mcap");
    if !p.exists() {
        assert!(
            std::env::var("CI").ok().as_deref() != Some("true"),
            "{} is missing under CI=true",
            p.display()
        );
        eprintln!("SKIP: {} is absent", p.display());
        return;
    }
    let bag = Bag::open(&p).unwrap();
    assert!(!bag.is_ros1_bag());
    let topics = bag.topics().unwrap();
    let points = topics
        .iter()
        .find(|t| t.topic == "/os1_cloud_node/points")
        .unwrap();
    assert_eq!(
        (
            points.type_name.as_str(),
            points.message_encoding.as_str(),
            points.message_count
        ),
        ("sensor_msgs/PointCloud2", "ros1", Some(2))
    );
    let mut clouds = Vec::new();
    let mut images = 0;
    let mut last = 0;
    bag.for_each(&Filter::default(), |m| {
        assert!(m.log_time >= last, "log-time order");
        last = m.log_time;
        match m.decode() {
            Some(Ok(SensorMessage::Cloud(c))) => {
                assert!(m.is_ros1());
                let v = c.view().unwrap();
                assert_eq!((c.width, c.height, c.point_step), (2048, 64, 48));
                assert!(v.layout().xyz_readers().is_ok());
                assert_eq!(
                    c.encode_ros1(m.header_seq().unwrap()),
                    m.data,
                    "byte-identical"
                );
                clouds.push(m.header_seq().unwrap());
            }
            Some(Ok(SensorMessage::Image(i))) => {
                i.view().unwrap();
                images += 1;
            }
            Some(Ok(_)) => {}
            Some(Err(e)) => panic!("{e}"),
            None => {}
        }
        Ok(ControlFlow::Continue(()))
    })
    .unwrap();
    assert_eq!(clouds.len(), 2);
    assert_eq!(images, 6);
}
