//! End-to-end through real processes and real shared memory: the test publishes frames, a
//! separate `perturbd` perturbs them, a separate `perturb-test-sink` receives them; `perturb ctl`
//! talks to the daemon. Every test runs in its own iceoryx2 namespace.

use perturb_core::cloud::{Datatype, PointField, PointLayout};
use perturb_core::formats::{pcd, picture};
use perturb_core::image::Image;
use perturb_core::synthetic;
use perturb_tests::{FrameRecord, Namespace, exe};
use perturb_wire::{FrameHeader, FramePublisher, Hop, Stamp, StreamQos, Transport};
use std::collections::BTreeSet;
use std::path::{Path, PathBuf};
use std::time::Duration;

const W: u32 = 320;
const H: u32 = 200;

fn qos() -> StreamQos {
    StreamQos {
        subscriber_buffer: 16,
        subscriber_borrowed: 4,
        ..StreamQos::default()
    }
}

/// A daemon configuration with a camera stream `cam` and a LiDAR stream `lidar`.
fn write_config(
    dir: &Path,
    cam: Option<(&str, u8, u64)>,
    lidar: Option<(&str, u8, u64)>,
) -> PathBuf {
    let p = |x: Option<(&str, u8, u64)>| match x {
        Some((id, s, seed)) => {
            format!("perturbation = {{ id = \"{id}\", severity = {s}, seed = {seed} }}\n")
        }
        None => String::new(),
    };
    let text = format!(
        "[daemon]\nstats_interval_s = 1\n\n\
         [[streams]]\nname = \"cam\"\nmodality = \"camera\"\n{}\
         qos = {{ subscriber_buffer = 16, subscriber_borrowed = 4 }}\n\n\
         [[streams]]\nname = \"lidar\"\nmodality = \"lidar\"\nsensor = \"vlp32c\"\n{}\
         qos = {{ subscriber_buffer = 16, subscriber_borrowed = 4 }}\n",
        p(cam),
        p(lidar)
    );
    let path = dir.join("perturbd.toml");
    std::fs::write(&path, text).unwrap();
    path
}

struct Publishers {
    cam: FramePublisher,
    lidar: FramePublisher,
    _t: Transport,
}

fn publishers(ns: &Namespace) -> Publishers {
    let t = Transport::open("test_pub", &ns.options).unwrap();
    let cam = t
        .publisher("cam/raw", &qos(), Hop::Ingress, 1 << 20)
        .unwrap();
    let lidar = t
        .publisher("lidar/raw", &qos(), Hop::Ingress, 1 << 20)
        .unwrap();
    assert!(cam.wait_for_subscribers(1, Duration::from_secs(10)));
    assert!(lidar.wait_for_subscribers(1, Duration::from_secs(10)));
    Publishers { cam, lidar, _t: t }
}

fn stamp(seq: u64) -> Stamp {
    Stamp {
        sec: 1_700_000_000 + seq as i32,
        nanosec: 123_456_789,
    }
}

fn camera_frame(seq: u64) -> Image {
    synthetic::street_image(W, H, seq)
}

fn publish_image(p: &mut FramePublisher, seq: u64) -> Image {
    let img = camera_frame(seq);
    let h = FrameHeader::for_image_view(seq, stamp(seq), "camera_front", &img.view()).unwrap();
    p.publish_image(h, &img.view()).unwrap();
    img
}

fn publish_cloud(p: &mut FramePublisher, seq: u64) -> perturb_core::cloud::Cloud {
    let c = synthetic::vlp32c_scan(seq);
    let h = FrameHeader::for_cloud_view(seq, stamp(seq), "velodyne", &c.view()).unwrap();
    p.publish_cloud(h, &c.view()).unwrap();
    c
}

/// `perturb apply` on `input`, returning the output path.
fn perturb_apply(ns: &Namespace, input: &Path, id: &str, sev: u8, seed: u64, seq: u64) -> PathBuf {
    let ext = input
        .file_name()
        .unwrap()
        .to_string_lossy()
        .split_once('.')
        .map(|(_, e)| e.to_string())
        .unwrap();
    let out = ns.dir.join(format!("applied_{id}_{seq}.{ext}"));
    let mut c = std::process::Command::new(exe("perturb"));
    c.args(["apply", "--id", id, "--severity", &sev.to_string()])
        .args(["--seed", &seed.to_string(), "--seq", &seq.to_string()])
        .arg(input)
        .arg("-o")
        .arg(&out);
    if ext == "pcd" {
        c.args(["--sensor", "vlp32c"]);
    }
    let o = c.output().unwrap();
    assert!(
        o.status.success(),
        "perturb apply failed: {}",
        String::from_utf8_lossy(&o.stderr)
    );
    out
}

fn seqs(r: &[FrameRecord]) -> BTreeSet<u64> {
    r.iter().map(|r| r.seq).collect()
}

fn stream<'a>(stats: &'a serde_json::Value, name: &str) -> &'a serde_json::Value {
    stats
        .as_array()
        .unwrap()
        .iter()
        .find(|s| s["name"] == name)
        .unwrap_or_else(|| panic!("no stream {name} in {stats}"))
}

fn u(v: &serde_json::Value, k: &str) -> u64 {
    v[k].as_u64()
        .unwrap_or_else(|| panic!("{k} missing in {v}"))
}

#[test]
fn frames_arrive_perturbed_identical_to_perturb_apply_and_every_seq_is_accounted_for() {
    let ns = Namespace::new("apply");
    let cfg = write_config(&ns.dir, Some(("C-A1", 3, 7)), Some(("L-C1", 2, 11)));
    let mut daemon = ns.start_daemon(&cfg);
    let cam_sink = ns.start_sink(&cfg, "cam", &ns.dir.join("cam"), &["--idle", "3"]);
    let lidar_sink = ns.start_sink(&cfg, "lidar", &ns.dir.join("lidar"), &["--idle", "3"]);
    let mut p = publishers(&ns);
    let (n_cam, n_lidar) = (12u64, 4u64);
    for seq in 0..n_cam {
        publish_image(&mut p.cam, seq);
        if seq % 3 == 0 {
            publish_cloud(&mut p.lidar, seq / 3);
        }
        std::thread::sleep(Duration::from_millis(40));
    }
    let cam = cam_sink.wait_for(n_cam as usize, Duration::from_secs(20));
    let lidar = lidar_sink.wait_for(n_lidar as usize, Duration::from_secs(20));
    let report = daemon.stop();
    let streams = &report["streams"];

    // Every sequence number is received or counted as dropped or invalid.
    for (name, recs, n) in [("cam", &cam, n_cam), ("lidar", &lidar, n_lidar)] {
        let s = stream(streams, name);
        let got = seqs(recs);
        assert!(got.iter().all(|&q| q < n), "{name}: unknown seqs {got:?}");
        assert_eq!(got.len(), recs.len(), "{name}: a frame arrived twice");
        assert_eq!(
            got.len() as u64 + u(s, "dropped") + u(s, "invalid"),
            n,
            "{name}: frames not accounted for; received {got:?}, daemon {s}"
        );
        assert_eq!(u(s, "frames_out"), got.len() as u64, "{name}: {s}");
    }
    assert!(cam.len() >= 10, "too few camera frames: {}", cam.len());
    assert!(lidar.len() >= 3, "too few LiDAR frames: {}", lidar.len());

    // Headers preserved, perturbation recorded, payload identical to `perturb apply`.
    for r in cam.iter().take(3) {
        assert_eq!(r.stamp, (stamp(r.seq).sec, stamp(r.seq).nanosec));
        assert_eq!(r.frame_id, "camera_front");
        assert_eq!(r.applied, Some(("C-A1".into(), 3, 7)));
        assert!(
            r.hops.0 > 0 && r.hops.0 <= r.hops.1 && r.hops.1 <= r.hops.2,
            "{r:?}"
        );
        let raw = camera_frame(r.seq);
        let input = ns.dir.join(format!("cam_{}.png", r.seq));
        std::fs::write(&input, picture::encode_png(&raw.view()).unwrap()).unwrap();
        let applied = perturb_apply(&ns, &input, "C-A1", 3, 7, r.seq);
        let expect = picture::decode(&std::fs::read(applied).unwrap()).unwrap();
        let got = cam_sink.payload(r.seq);
        assert_eq!((r.width, r.height, r.encoding.as_str()), (W, H, "rgb8"));
        assert_ne!(got, raw.data, "frame {} not perturbed", r.seq);
        assert!(
            got == expect.data,
            "frame {}: daemon and perturb apply differ",
            r.seq
        );
    }
    for r in lidar.iter().take(2) {
        assert_eq!(r.frame_id, "velodyne");
        assert_eq!(r.applied, Some(("L-C1".into(), 2, 11)));
        let raw = synthetic::vlp32c_scan(r.seq);
        let input = ns.dir.join(format!("lidar_{}.pcd", r.seq));
        let bytes = pcd::encode(
            &raw.view(),
            pcd::PcdData::Binary,
            [0., 0., 0., 1., 0., 0., 0.],
        );
        std::fs::write(&input, bytes.unwrap()).unwrap();
        let applied = perturb_apply(&ns, &input, "L-C1", 2, 11, r.seq);
        let expect = pcd::decode(&std::fs::read(applied).unwrap()).unwrap();
        let got = lidar_sink.payload(r.seq);
        assert_ne!(got, raw.data, "cloud {} not perturbed", r.seq);
        // PCD has no padding: compare field by field, point by point.
        let (src, dst) = (&raw.layout, &expect.cloud.layout);
        let n = got.len() / src.point_step as usize;
        assert_eq!(
            n,
            expect.cloud.data.len() / dst.point_step as usize,
            "cloud {}",
            r.seq
        );
        for f in &dst.fields {
            let g = src.fields.iter().find(|g| g.name == f.name).unwrap();
            let len = f.byte_len();
            for i in 0..n {
                let a = i * src.point_step as usize + g.offset as usize;
                let b = i * dst.point_step as usize + f.offset as usize;
                assert_eq!(
                    got[a..a + len],
                    expect.cloud.data[b..b + len],
                    "cloud {}: field {} of point {i} differs between the daemon and perturb apply",
                    r.seq,
                    f.name
                );
            }
        }
    }
}

#[test]
fn control_changes_apply_from_the_next_frame_and_bad_requests_are_refused() {
    let ns = Namespace::new("control");
    let cfg = write_config(&ns.dir, None, None);
    let _daemon = ns.start_daemon(&cfg);
    let sink = ns.start_sink(&cfg, "cam", &ns.dir.join("cam"), &["--idle", "20"]);
    let mut p = publishers(&ns);
    let mut step = |seq: u64| -> (Image, Vec<u8>, FrameRecord) {
        let img = publish_image(&mut p.cam, seq);
        let recs = sink.wait_for(seq as usize + 1, Duration::from_secs(10));
        let r = recs
            .iter()
            .find(|r| r.seq == seq)
            .unwrap_or_else(|| panic!("frame {seq} did not arrive: {recs:?}"))
            .clone();
        (img, sink.payload(seq), r)
    };

    // Off: forwarded unchanged.
    let (raw, got, r) = step(0);
    assert_eq!(r.applied, None);
    assert!(got == raw.data, "frame 0 changed with the perturbation off");

    let o = ns.ctl(&["set", "cam", "C-F5", "--severity", "1", "--seed", "3"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(String::from_utf8_lossy(&o.stdout).contains("C-F5"));
    let (raw, got, r) = step(1);
    assert_eq!(r.applied, Some(("C-F5".into(), 1, 3)));
    assert!(got != raw.data, "frame 1 not perturbed after `set`");

    let status = ns.ctl(&["status", "--json"]);
    let status: serde_json::Value = serde_json::from_slice(&status.stdout).unwrap();
    let cam = stream(&status, "cam");
    assert_eq!(cam["id"], "C-F5");
    assert_eq!(cam["severity"], 1);
    assert_eq!(cam["modality"], "camera");
    assert!(stream(&status, "lidar")["id"].is_null());

    let o = ns.ctl(&["off", "cam"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let (raw, got, r) = step(2);
    assert_eq!(r.applied, None);
    assert!(got == raw.data, "frame 2 changed after `off`");

    for (args, says) in [
        (&["set", "nosuch", "C-A1", "--severity", "1"][..], "nosuch"),
        (&["set", "cam", "C-Z9", "--severity", "1"][..], "C-Z9"),
        (&["set", "cam", "L-B1", "--severity", "1"][..], "camera"),
        (&["set", "cam", "C-A1", "--severity", "9"][..], "severity"),
        (&["off", "nosuch"][..], "nosuch"),
    ] {
        let o = ns.ctl(args);
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(!o.status.success(), "{args:?} was accepted");
        assert!(
            err.contains(says),
            "{args:?}: error does not mention `{says}`: {err}"
        );
    }
    // The refused requests changed nothing.
    let (raw, got, r) = step(3);
    assert_eq!(r.applied, None);
    assert!(got == raw.data);
}

#[test]
fn a_daemon_killed_mid_stream_is_replaced_and_every_frame_is_still_accounted_for() {
    let ns = Namespace::new("restart");
    let cfg = write_config(&ns.dir, Some(("C-F5", 1, 1)), None);
    let mut daemon = ns.start_daemon(&cfg);
    let sink = ns.start_sink(&cfg, "cam", &ns.dir.join("cam"), &["--idle", "30"]);
    let mut p = publishers(&ns);
    let mut seq = 0u64;
    let publish_until = |p: &mut Publishers, n: usize, seq: &mut u64| {
        for _ in 0..200 {
            publish_image(&mut p.cam, *seq);
            *seq += 1;
            std::thread::sleep(Duration::from_millis(30));
            if sink.records().len() >= n {
                return;
            }
        }
        panic!("only {} frames arrived", sink.records().len());
    };
    publish_until(&mut p, 5, &mut seq);
    // Frames sent in a burst right before the kill: some are still queued in the daemon.
    for _ in 0..3 {
        publish_image(&mut p.cam, seq);
        seq += 1;
    }
    daemon.kill9();
    // The publisher and the sink stay up; frames published now have no daemon to go through.
    let down = 5;
    for _ in 0..down {
        publish_image(&mut p.cam, seq);
        seq += 1;
        std::thread::sleep(Duration::from_millis(30));
    }
    let before = seq;
    let _daemon2 = ns.start_daemon(&cfg);
    let had = sink.records().len();
    publish_until(&mut p, had + 5, &mut seq);
    let published = seq;
    let recs = sink.records();
    let after: Vec<&FrameRecord> = recs.iter().filter(|r| r.seq >= before).collect();
    assert!(after.len() >= 5, "the stream did not recover: {recs:?}");
    assert!(
        after
            .iter()
            .all(|r| r.applied == Some(("C-F5".into(), 1, 1)))
    );

    // Every frame published went out, or is counted as dropped or invalid, across the restart:
    // the new daemon carries the killed one's counters on and counts what it missed.
    let accounted = |s: &serde_json::Value| {
        let c = stream(s, "cam");
        u(c, "frames_out") + u(c, "dropped") + u(c, "invalid")
    };
    let mut s = ns.stats();
    for _ in 0..100 {
        if accounted(&s) >= published {
            break;
        }
        std::thread::sleep(Duration::from_millis(50));
        s = ns.stats();
    }
    let cam = stream(&s, "cam");
    assert_eq!(accounted(&s), published, "{cam}\n{}", _daemon2.log_text());
    // Counted as lost because the daemon was down, not blamed on the sensor.
    assert!(
        u(cam, "dropped_down") >= down && cam["lost"]["daemon_down"].as_u64().unwrap() >= down,
        "the frames published while no daemon ran are not counted: {cam}"
    );
    assert_eq!(
        u(cam, "dropped_upstream"),
        0,
        "the sensor lost nothing: {cam}"
    );
    let recs = sink.wait_for(u(cam, "frames_out") as usize, Duration::from_secs(10));
    assert_eq!(
        recs.len() as u64,
        u(cam, "frames_out"),
        "frames_out counts frames of both daemons: {cam}"
    );
    assert_eq!(seqs(&recs).len(), recs.len(), "a frame arrived twice");
    // The restart is logged in a few readable lines (it used to print a 6 kB one-line iceoryx2
    // dump of the dead node's resources).
    let log = _daemon2.log_text();
    let longest = log.lines().map(str::len).max().unwrap_or(0);
    assert!(
        longest < 600,
        "a {longest}-byte log line on restart:\n{log}"
    );
}

#[test]
fn a_perturbation_set_at_runtime_survives_a_restart_unless_fresh() {
    let ns = Namespace::new("runtime_state");
    let cfg = write_config(&ns.dir, Some(("C-A1", 2, 5)), None);
    let status = |ns: &Namespace| {
        let o = ns.ctl(&["status", "--json"]);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
        let c = stream(&v, "cam").clone();
        (c["id"].clone(), c["severity"].clone(), c["seed"].clone())
    };
    let mut d = ns.start_daemon(&cfg);
    let o = ns.ctl(&["set", "cam", "C-F5", "--severity", "1", "--seed", "3"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let o = ns.ctl(&["off", "lidar"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    d.kill9();

    let mut d = ns.start_daemon(&cfg);
    assert_eq!(status(&ns), ("C-F5".into(), 1.into(), 3.into()));
    assert!(
        d.log_text()
            .contains("restored the perturbation set at runtime"),
        "the restore is not logged:\n{}",
        d.log_text()
    );
    d.stop();

    // A clean stop keeps it too; --fresh starts from the configuration.
    let mut d = ns.start_daemon(&cfg);
    assert_eq!(status(&ns), ("C-F5".into(), 1.into(), 3.into()));
    d.stop();
    let mut d = ns.start_daemon_with(&cfg, &["--fresh"]);
    assert_eq!(status(&ns), ("C-A1".into(), 2.into(), 5.into()));
    d.kill9();

    // An edited configuration wins over an older runtime state.
    let mut d = ns.start_daemon(&cfg);
    let o = ns.ctl(&["set", "cam", "C-F5", "--severity", "2"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    d.kill9();
    let cfg = write_config(&ns.dir, Some(("C-C7", 3, 9)), None);
    let _d = ns.start_daemon(&cfg);
    assert_eq!(status(&ns), ("C-C7".into(), 3.into(), 9.into()));
}

#[test]
fn invalid_frames_are_counted_and_skipped_and_the_stream_goes_on() {
    let ns = Namespace::new("invalid");
    let cfg = write_config(&ns.dir, Some(("C-A1", 1, 1)), Some(("L-C1", 1, 1)));
    let _daemon = ns.start_daemon(&cfg);
    let cam_sink = ns.start_sink(&cfg, "cam", &ns.dir.join("cam"), &["--idle", "3"]);
    let lidar_sink = ns.start_sink(&cfg, "lidar", &ns.dir.join("lidar"), &["--idle", "3"]);
    let mut p = publishers(&ns);

    publish_image(&mut p.cam, 0);
    // The header claims a full frame, the payload is 100 bytes.
    let img = camera_frame(1);
    let h = FrameHeader::for_image_view(1, stamp(1), "camera_front", &img.view()).unwrap();
    p.cam.publish_raw(h, &img.data[..100]).unwrap();
    // An encoding the encoding table does not have (NV21, 4:2:0).
    let mut h = FrameHeader::image(2, stamp(2), "camera_front", W, H, W * 2, "nv21").unwrap();
    h.data_len = (W * 2 * H) as u64;
    p.cam
        .publish_raw(h, &vec![0u8; (W * 2 * H) as usize])
        .unwrap();
    publish_image(&mut p.cam, 3);

    publish_cloud(&mut p.lidar, 0);
    // A cloud without x/y/z.
    let layout = PointLayout::new(
        vec![
            PointField::new("a", 0, Datatype::Float32),
            PointField::new("b", 4, Datatype::Float32),
        ],
        8,
        false,
    )
    .unwrap();
    let h = FrameHeader::cloud(1, stamp(1), "velodyne", &layout, 10, 1, 80, true).unwrap();
    p.lidar.publish_raw(h, &[0u8; 80]).unwrap();
    publish_cloud(&mut p.lidar, 2);

    let cam = cam_sink.finish();
    let lidar = lidar_sink.finish();
    assert_eq!(seqs(&cam), BTreeSet::from([0, 3]), "{cam:?}");
    assert_eq!(seqs(&lidar), BTreeSet::from([0, 2]), "{lidar:?}");
    let s = ns.stats();
    assert_eq!(u(stream(&s, "cam"), "invalid"), 2, "{s}");
    assert_eq!(u(stream(&s, "lidar"), "invalid"), 1, "{s}");
    assert_eq!(u(stream(&s, "cam"), "dropped"), 0, "{s}");
}

#[test]
fn a_bad_configuration_is_refused_naming_the_key() {
    let ns = Namespace::new("badcfg");
    let path = ns.dir.join("bad.toml");
    std::fs::write(
        &path,
        "[[streams]]\nname = \"cam\"\nmodality = \"camera\"\n\
         perturbation = { id = \"C-A1\", severity = 9, seed = 1 }\n",
    )
    .unwrap();
    let o = ns
        .command(exe("perturbd"))
        .arg("--config")
        .arg(&path)
        .arg("--check")
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success());
    assert!(
        err.contains("bad.toml") && err.contains("severity"),
        "{err}"
    );

    for shipped in [
        "minimal.toml",
        "vehicle.toml",
        "e2e.toml",
        "load.toml",
        "autoware-mini-perturbd.toml",
    ] {
        let p = perturb_tests::workspace().join("config").join(shipped);
        let o = ns
            .command(exe("perturbd"))
            .arg("--config")
            .arg(&p)
            .arg("--check")
            .output()
            .unwrap();
        assert!(
            o.status.success(),
            "{shipped}: {}",
            String::from_utf8_lossy(&o.stderr)
        );
    }
}
