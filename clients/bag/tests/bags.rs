//! Reading the real rosbag2 MCAP bags in `../shared/data`, writing bags and reading them back,
//! damaged bags (ROS 1 bags: `ros1_bags.rs`).

use perturb_bag::{Bag, BagWriter, Compression, Filter, ReadOrder, SensorMessage, WriterOptions};
use perturb_core::cloud::{Cloud, PointLayout};
use perturb_core::formats::ros::{Header, ImageMsg, PointCloud2Msg};
use perturb_core::image::{Image, PixelFormat};
use std::ops::ControlFlow;
use std::path::PathBuf;

fn shared(test: &str) -> Option<PathBuf> {
    let dir = std::env::var_os("PERTURB_SHARED_DATA")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../../shared/data"));
    if dir.is_dir() {
        Some(dir)
    } else {
        eprintln!("skipping {test}: real data not found at {}", dir.display());
        None
    }
}

fn tmp(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("perturb-bag-test-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    d
}

#[test]
fn reads_the_kitti_bag_in_log_time_order_and_decodes_its_sensors() {
    let Some(data) = shared("reads_the_kitti_bag") else {
        return;
    };
    let bag = Bag::open(&data.join("ros2_mcap_kitti_000001")).unwrap();
    let topics = bag.topics().unwrap();
    assert_eq!(topics.len(), 4, "{topics:?}");
    let mut times = Vec::new();
    let (mut images, mut clouds, mut compressed) = (0, 0, 0);
    let report = bag
        .for_each(&Filter::default(), |m| {
            times.push(m.log_time);
            match m.decode() {
                Some(Ok(SensorMessage::Image(img))) => {
                    let v = img.view().unwrap();
                    assert_eq!(
                        (v.width, v.height, v.encoding.working_format()),
                        (1242, 375, PixelFormat::Rgb8)
                    );
                    images += 1;
                }
                Some(Ok(SensorMessage::Cloud(c))) => {
                    let v = c.view().unwrap();
                    assert_eq!(v.len(), 120_268);
                    assert!(v.layout().xyz_readers().is_ok());
                    // Decode and re-encode is byte-identical.
                    assert_eq!(c.encode(), m.data);
                    clouds += 1;
                }
                Some(Ok(SensorMessage::Compressed(c))) => {
                    assert!(c.format.contains("png"), "{}", c.format);
                    compressed += 1;
                }
                Some(Err(e)) => panic!("{e}"),
                None => assert_eq!(m.type_name, "sensor_msgs/msg/CameraInfo"),
            }
            Ok(ControlFlow::Continue(()))
        })
        .unwrap();
    assert_eq!((images, clouds, compressed), (1, 1, 1));
    assert_eq!(report.delivered, 4);
    assert_eq!(report.order, ReadOrder::LogTime);
    assert!(
        times.windows(2).all(|w| w[0] <= w[1]),
        "not in log-time order: {times:?}"
    );
}

fn write_sample(dir: &std::path::Path, compression: Compression) -> (Vec<Vec<u8>>, Vec<u64>) {
    write_sample_at(dir, compression, 0)
}

/// [`write_sample`] at a compression level (0: the codec's default).
fn write_sample_at(
    dir: &std::path::Path,
    compression: Compression,
    level: u32,
) -> (Vec<Vec<u8>>, Vec<u64>) {
    let mut w = BagWriter::create(
        dir,
        &WriterOptions {
            compression,
            level,
            chunk_size: 64 << 10,
        },
    )
    .unwrap();
    let cam = w
        .add_topic("/cam/image_raw", "sensor_msgs/msg/Image")
        .unwrap();
    let lid = w
        .add_topic("/lidar/points", "sensor_msgs/msg/PointCloud2")
        .unwrap();
    let mut payloads = Vec::new();
    let mut times = Vec::new();
    for k in 0..20u64 {
        let t = 1_000_000_000 + k * 50_000_000;
        let bytes = if k % 2 == 0 {
            let mut img = Image::new(64, 32, PixelFormat::Bgr8);
            img.data
                .iter_mut()
                .enumerate()
                .for_each(|(i, b)| *b = (i as u64 * 3 + k) as u8);
            let h = Header {
                stamp_sec: k as i32,
                stamp_nanosec: 7,
                frame_id: "cam",
            };
            let msg = ImageMsg::from_view(h, &img.view()).encode();
            w.write(cam, t, t, &msg).unwrap();
            msg
        } else {
            let c = Cloud::from_xyzi(&PointLayout::xyzir(), &[[k as f32, 1.0, 2.0, 3.0]; 100]);
            let h = Header {
                stamp_sec: k as i32,
                stamp_nanosec: 9,
                frame_id: "velodyne",
            };
            let msg = PointCloud2Msg::from_view(h, &c.view()).encode();
            w.write(lid, t, t, &msg).unwrap();
            msg
        };
        payloads.push(bytes);
        times.push(t);
    }
    w.finish().unwrap();
    (payloads, times)
}

#[test]
fn written_bags_read_back_identically_with_every_compression() {
    for compression in [Compression::None, Compression::Zstd, Compression::Lz4] {
        let dir = tmp(&format!("rt-{compression:?}"));
        let (payloads, times) = write_sample(&dir, compression);
        let yaml = std::fs::read_to_string(dir.join("metadata.yaml")).unwrap();
        assert!(
            yaml.contains("message_count: 20") && yaml.contains("storage_identifier: mcap"),
            "{yaml}"
        );
        let bag = Bag::open(&dir).unwrap();
        let mut got = Vec::new();
        bag.for_each(&Filter::default(), |m| {
            got.push((m.log_time, m.data.to_vec()));
            Ok(ControlFlow::Continue(()))
        })
        .unwrap();
        assert_eq!(got.len(), 20);
        for (k, (t, d)) in got.iter().enumerate() {
            assert_eq!(*t, times[k]);
            assert_eq!(*d, payloads[k], "{compression:?} message {k}");
        }
        let only = Filter {
            topics: vec!["/lidar/points".into()],
            ..Filter::default()
        };
        let mut n = 0;
        bag.for_each(&only, |m| {
            assert_eq!(m.topic, "/lidar/points");
            n += 1;
            Ok(ControlFlow::Continue(()))
        })
        .unwrap();
        assert_eq!(n, 10);
        if std::env::var_os("PERTURB_KEEP_TEST_BAGS").is_none() {
            let _ = std::fs::remove_dir_all(&dir);
        } else {
            eprintln!("kept {}", dir.display());
        }
    }
}

/// True if python3 has the PyPI `mcap` reader (with its zstd and lz4 codecs) and `rosbags`; a
/// skip with a message otherwise, a failure under `PERTURB_REQUIRE_ORACLES=1` (CI).
fn have_python_readers() -> bool {
    let ok = std::process::Command::new("python3")
        .args([
            "-c",
            "import mcap.reader, zstandard, lz4.frame, rosbags.rosbag2",
        ])
        .output()
        .is_ok_and(|o| o.status.success());
    if !ok {
        let what = "the python packages mcap and rosbags (pip install mcap rosbags)";
        assert!(
            std::env::var("PERTURB_REQUIRE_ORACLES").as_deref() != Ok("1"),
            "{what} are missing and PERTURB_REQUIRE_ORACLES=1"
        );
        eprintln!("SKIP: {what} are missing");
    }
    ok
}

#[test]
fn compressed_bags_read_back_with_the_mcap_package_and_rosbags() {
    use sha2::{Digest, Sha256};
    if !have_python_readers() {
        return;
    }
    let script = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/read_mcap.py");
    for (compression, level, name) in [
        (Compression::Zstd, 1, "zstd"),
        (Compression::Zstd, 0, "zstd"),
        (Compression::Zstd, 19, "zstd"),
        (Compression::Lz4, 0, "lz4"),
        (Compression::None, 0, ""),
    ] {
        let dir = tmp(&format!("py-{compression:?}-{level}"));
        let (payloads, times) = write_sample_at(&dir, compression, level);
        let o = std::process::Command::new("python3")
            .arg(&script)
            .arg(&dir)
            .output()
            .unwrap();
        assert!(
            o.status.success(),
            "{name} {level}: {}",
            String::from_utf8_lossy(&o.stderr)
        );
        let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
        assert_eq!(v["compression"], serde_json::json!([name]), "{level}: {v}");
        let want: Vec<serde_json::Value> = payloads
            .iter()
            .zip(&times)
            .enumerate()
            .map(|(k, (p, t))| {
                let topic = if k % 2 == 0 {
                    "/cam/image_raw"
                } else {
                    "/lidar/points"
                };
                serde_json::json!([topic, t, hex::encode(Sha256::digest(p))])
            })
            .collect();
        for reader in ["mcap", "rosbags"] {
            assert_eq!(
                v[reader].as_array().unwrap(),
                &want,
                "{name} level {level}: what {reader} read"
            );
        }
        let _ = std::fs::remove_dir_all(&dir);
    }
}

#[test]
fn a_truncated_bag_replays_what_can_be_read_and_reports_the_damage() {
    let dir = tmp("trunc");
    let (payloads, _) = write_sample(&dir, Compression::None);
    let file = dir.join(format!(
        "{}_0.mcap",
        dir.file_name().unwrap().to_str().unwrap()
    ));
    let bytes = std::fs::read(&file).unwrap();
    let cut = tmp("trunc-cut");
    std::fs::create_dir_all(&cut).unwrap();
    let cut_file = cut.join("cut.mcap");
    std::fs::write(&cut_file, &bytes[..bytes.len() * 6 / 10]).unwrap();
    let bag = Bag::open(&cut_file).unwrap();
    let mut got = 0usize;
    let report = bag
        .for_each(&Filter::default(), |m| {
            assert_eq!(m.data, payloads[got].as_slice());
            got += 1;
            Ok(ControlFlow::Continue(()))
        })
        .unwrap();
    assert!(got > 0 && got < 20, "delivered {got}: {report:?}");
    assert_eq!(report.order, ReadOrder::FileOrder);
    let damage = report.damage.expect("damage reported");
    assert!(damage.contains("cut.mcap"), "{damage}");
    // Not an MCAP at all.
    std::fs::write(&cut_file, b"definitely not a bag").unwrap();
    let err = Bag::open(&cut_file).unwrap_err().to_string();
    assert!(err.contains("magic") && err.contains("cut.mcap"), "{err}");
    let _ = std::fs::remove_dir_all(&dir);
    let _ = std::fs::remove_dir_all(&cut);
}

/// The (offset of the opcode, opcode, body range) of every top-level record of an MCAP file.
fn records(bytes: &[u8]) -> Vec<(usize, u8, std::ops::Range<usize>)> {
    let mut out = Vec::new();
    let mut pos = 8;
    while pos + 9 <= bytes.len() - 8 {
        let op = bytes[pos];
        let len = u64::from_le_bytes(bytes[pos + 1..pos + 9].try_into().unwrap()) as usize;
        out.push((pos, op, pos + 9..pos + 9 + len));
        pos += 9 + len;
    }
    out
}

#[test]
fn hostile_lengths_are_reported_as_damage_instead_of_being_allocated() {
    let dir = tmp("hostile");
    write_sample(&dir, Compression::Zstd);
    let file = dir.join(format!(
        "{}_0.mcap",
        dir.file_name().unwrap().to_str().unwrap()
    ));
    let good = std::fs::read(&file).unwrap();
    let recs = records(&good);
    let out = tmp("hostile-out");
    std::fs::create_dir_all(&out).unwrap();
    let read_all = |bytes: &[u8], name: &str| {
        let p = out.join(name);
        std::fs::write(&p, bytes).unwrap();
        let bag = Bag::open(&p)?;
        let mut n = 0;
        let report = bag.for_each(&Filter::default(), |_| {
            n += 1;
            Ok(ControlFlow::Continue(()))
        })?;
        Ok::<_, perturb_bag::BagError>((bag.is_indexed(), n, report))
    };
    let (indexed, n, report) = read_all(&good, "good.mcap").unwrap();
    assert!(indexed && n == 20 && report.damage.is_none(), "{report:?}");

    // The Header record's profile string claims 4 GiB: refused, naming the record.
    let mut b = good.clone();
    b[17..21].copy_from_slice(&4_294_967_054u32.to_le_bytes());
    let e = read_all(&b, "header.mcap").unwrap_err().to_string();
    assert!(
        e.contains("Header record profile")
            && e.contains("4294967054")
            && e.contains("header.mcap"),
        "{e}"
    );

    // A Channel record of the summary with a 4 GiB topic: the summary is not used, the data
    // section is read in file order instead, and a note says why.
    let summary_channel = recs
        .iter()
        .rev()
        .find(|r| r.1 == 0x04)
        .expect("a channel record in the summary");
    let mut b = good.clone();
    let at = summary_channel.2.start + 4;
    b[at..at + 4].copy_from_slice(&u32::MAX.to_le_bytes());
    let (indexed, n, report) = read_all(&b, "channel.mcap").unwrap();
    assert!(!indexed && n == 20 && report.damage.is_none(), "{report:?}");
    assert!(
        report
            .notes
            .iter()
            .any(|x| x.contains("Channel record topic")),
        "{report:?}"
    );

    // The same, with a Footer record whose length is not 20 (found by fuzzing: the `mcap` crate
    // still read the summary it points to, without the lengths checked): not used either.
    let n = b.len();
    b[n - 37 + 1..n - 37 + 9].copy_from_slice(&96u64.to_le_bytes());
    let (indexed, n, report) = read_all(&b, "footer.mcap").unwrap();
    assert!(!indexed && n == 20 && report.damage.is_none(), "{report:?}");
    assert!(
        report.notes.iter().any(|x| x.contains("Footer record")),
        "{report:?}"
    );

    // Every chunk (and its index) claims to decompress to 2^60 bytes: damage, no allocation.
    let mut b = good.clone();
    for r in recs.iter().filter(|r| r.1 == 0x06) {
        let at = r.2.start + 16;
        b[at..at + 8].copy_from_slice(&(1u64 << 60).to_le_bytes());
    }
    for r in recs.iter().filter(|r| r.1 == 0x08) {
        let at = r.2.end - 8;
        b[at..at + 8].copy_from_slice(&(1u64 << 60).to_le_bytes());
    }
    let (indexed, _, report) = read_all(&b, "chunk.mcap").unwrap();
    assert!(!indexed, "{report:?}");
    let damage = report.damage.expect("damage reported");
    assert!(damage.contains("chunk.mcap"), "{damage}");

    // An uncompressed chunk whose records run past its declared size (found by fuzzing: the
    // mcap crate's reader subtracted past zero), in a bag without summary: damage, no panic.
    let plain = tmp("hostile-plain");
    write_sample(&plain, Compression::None);
    let pfile = plain.join(format!(
        "{}_0.mcap",
        plain.file_name().unwrap().to_str().unwrap()
    ));
    let pgood = std::fs::read(&pfile).unwrap();
    let precs = records(&pgood);
    let chunk = precs.iter().find(|r| r.1 == 0x06).expect("a chunk");
    let data_end = precs
        .iter()
        .find(|r| r.1 == 0x0F)
        .expect("a Data End record");
    let mut b = pgood[..data_end.0].to_vec();
    let at = chunk.2.start + 8 + 8 + 8 + 4 + 4;
    let size = u64::from_le_bytes(b[at..at + 8].try_into().unwrap());
    b[at..at + 8].copy_from_slice(&(size - 5).to_le_bytes());
    let (indexed, _, report) = read_all(&b, "short_chunk.mcap").unwrap();
    assert!(!indexed);
    let damage = report.damage.expect("damage reported");
    assert!(damage.contains("short_chunk.mcap"), "{damage}");
    let _ = std::fs::remove_dir_all(&plain);

    // Cut right after the magic bytes, or right after the Header record: damaged, not empty.
    let e = read_all(&good[..8], "magic.mcap").unwrap_err().to_string();
    assert!(e.contains("right after the magic bytes"), "{e}");
    let header_end = recs[0].2.end;
    let (_, n, report) = read_all(&good[..header_end], "header_only.mcap").unwrap();
    assert_eq!(n, 0);
    let damage = report
        .damage
        .expect("a bag cut after its header is damaged");
    assert!(damage.contains("truncated"), "{damage}");
    let _ = std::fs::remove_dir_all(&dir);
    let _ = std::fs::remove_dir_all(&out);
}
