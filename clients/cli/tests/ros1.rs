//! `perturb info` and `perturb apply` on ROS 1 bags: the output stays a ROS 1 bag (header seq,
//! stamps and every other topic kept), read back here and, when Debian's ROS 1 packages are
//! installed, by Python `rosbag` (required under PERTURB_REQUIRE_ORACLES=1).

mod common;

use common::{ok, tmp};
use perturb_bag::ros1::{Ros1Compression, Ros1Writer, Ros1WriterOptions};
use perturb_bag::{Bag, Filter, SensorMessage};
use perturb_core::formats::ros::{Header, ImageMsg};
use perturb_core::formats::ros1;
use perturb_core::synthetic::street_image;
use std::ops::ControlFlow;
use std::process::Command;

#[test]
fn ros1_bag_info_and_apply_keep_the_ros1_format() {
    let dir = tmp("ros1-apply");
    let input = dir.join("in.bag");
    let mut w = Ros1Writer::create(
        &input,
        &Ros1WriterOptions {
            compression: Ros1Compression::Bz2,
            chunk_size: 4096,
        },
    )
    .unwrap();
    let cam = w
        .add_topic("/camera/image_raw", "sensor_msgs/Image")
        .unwrap();
    let note = w.add_topic("/note", "std_msgs/String").unwrap();
    let mut originals = Vec::new();
    for k in 0..4u32 {
        let img = street_image(48, 32, k as u64);
        let m = ImageMsg::from_view(
            Header {
                stamp_sec: 100 + k as i32,
                stamp_nanosec: 9,
                frame_id: "cam",
            },
            &img.view(),
        );
        w.write(cam, 1_000_000_000 * (k as u64 + 1), &m.encode_ros1(500 + k))
            .unwrap();
        originals.push(img.data.clone());
    }
    w.write(note, 9_000_000_000, &ros1::encode_string("kept"))
        .unwrap();
    w.finish().unwrap();

    let info = ok(&["info", input.to_str().unwrap()]);
    assert!(info.contains("ROS 1 bag"), "{info}");
    assert!(info.contains("image 48x32 rgb8"), "{info}");
    assert!(info.contains("5 messages read"), "{info}");

    let out = dir.join("out.bag");
    ok(&[
        "apply",
        "--id",
        "C-A1",
        "--severity",
        "3",
        "--seed",
        "2",
        input.to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
    ]);
    let bag = Bag::open(&out).unwrap();
    assert!(bag.is_ros1_bag(), "the output keeps the input's format");
    let mut k = 0;
    let mut events = 0;
    let mut note_seen = false;
    bag.for_each(&Filter::default(), |m| {
        match m.topic {
            "/camera/image_raw" => {
                let Some(Ok(SensorMessage::Image(i))) = m.decode() else {
                    panic!("an image")
                };
                assert_eq!(m.header_seq(), Some(500 + k as u32), "header seq kept");
                assert_eq!(i.header.stamp_sec, 100 + k as i32);
                assert_ne!(i.data, &originals[k][..], "perturbed");
                k += 1;
            }
            "/perturb/events" => {
                let s = ros1::decode_string(m.data).unwrap();
                assert!(s.contains("\"C-A1\""), "{s}");
                events += 1;
            }
            "/note" => {
                assert_eq!(ros1::decode_string(m.data).unwrap(), "kept");
                note_seen = true;
            }
            t => panic!("unexpected topic {t}"),
        }
        Ok(ControlFlow::Continue(()))
    })
    .unwrap();
    assert_eq!((k, events, note_seen), (4, 4, true));

    // Debian's Python rosbag reads it.
    let python = std::env::var("PERTURB_ROS_PYTHON").unwrap_or_else(|_| "/usr/bin/python3".into());
    let have = Command::new(&python)
        .args(["-c", "import rosbag, sensor_msgs.msg"])
        .output()
        .is_ok_and(|o| o.status.success());
    if !have {
        assert!(
            std::env::var("PERTURB_REQUIRE_ORACLES").ok().as_deref() != Some("1"),
            "Debian's ROS 1 packages (python3-rosbag, python3-sensor-msgs) are missing and PERTURB_REQUIRE_ORACLES=1"
        );
        eprintln!("SKIP: Debian's python3-rosbag is missing");
        return;
    }
    let o = Command::new(&python)
        .arg("-c")
        .arg("import sys, rosbag\nwith rosbag.Bag(sys.argv[1]) as b:\n    print(b.get_message_count(), sorted(b.get_type_and_topic_info().topics))")
        .arg(&out)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(
        text.starts_with("9 ['/camera/image_raw', '/note', '/perturb/events']"),
        "{text}"
    );
}
