//! The whole pipeline across processes: `perturb-bridge` (bag replay or synthetic sensors) ->
//! iceoryx2 -> `perturbd` -> iceoryx2 -> `perturb-bridge` recorder -> rosbag2 MCAP, read back by
//! the independent `rosbags` package.

use perturb_tests::{Namespace, events, exe, have_rosbags, read_bag};
use serde_json::Value;
use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};
use std::time::Duration;

fn run_bridge(ns: &Namespace, config: &Path) {
    let o = ns
        .command(exe("perturb-bridge"))
        .arg("--config")
        .arg(config)
        .args(["--linger", "3"])
        .output()
        .unwrap();
    assert!(
        o.status.success(),
        "perturb-bridge failed: {}",
        String::from_utf8_lossy(&o.stderr)
    );
}

fn kitti_bag() -> Option<PathBuf> {
    perturb_tests::shared_data("ros2_mcap_kitti_000001")
}

#[test]
fn a_replayed_bag_goes_through_perturbd_and_is_recorded_with_its_perturbations() {
    let Some(bag) = kitti_bag() else { return };
    if !have_rosbags() {
        return;
    }
    let ns = Namespace::new("hil");
    let daemon_cfg = ns.dir.join("perturbd.toml");
    std::fs::write(
        &daemon_cfg,
        "[[streams]]\nname = \"camera_front\"\nmodality = \"camera\"\n\
         perturbation = { id = \"C-C7\", severity = 2, seed = 5 }\n\n\
         [[streams]]\nname = \"lidar_top\"\nmodality = \"lidar\"\nsensor = \"hdl64e\"\n\
         perturbation = { id = \"L-B1\", severity = 2, seed = 5 }\n",
    )
    .unwrap();
    let out = ns.dir.join("recording");
    let bridge_cfg = ns.dir.join("bridge.toml");
    std::fs::write(
        &bridge_cfg,
        format!(
            "[bridge]\nname = \"hil\"\n\n[replay]\nbag = \"{}\"\nrate = 1.0\n\
             [replay.topics]\n\"/kitti/camera_color_left/image_raw\" = \"camera_front\"\n\
             \"/kitti/velo/pointcloud\" = \"lidar_top\"\n\n\
             [record]\nout = \"{}\"\nstreams = [\"camera_front\", \"lidar_top\"]\nraw = true\nperturbed = true\n",
            bag.display(),
            out.display()
        ),
    )
    .unwrap();
    let mut daemon = ns.start_daemon(&daemon_cfg);
    run_bridge(&ns, &bridge_cfg);
    let report = daemon.stop();

    let original = read_bag(&bag);
    let recorded = read_bag(&out);
    let by_topic = |msgs: &[Value], t: &str| -> Vec<Value> {
        msgs.iter().filter(|m| m["topic"] == t).cloned().collect()
    };
    for (src, stream) in [
        ("/kitti/camera_color_left/image_raw", "camera_front"),
        ("/kitti/velo/pointcloud", "lidar_top"),
    ] {
        let orig = by_topic(&original, src);
        let raw = by_topic(&recorded, &format!("/{stream}/raw"));
        let pert = by_topic(&recorded, &format!("/{stream}/perturbed"));
        assert_eq!(
            raw.len(),
            orig.len(),
            "{stream}: raw frames missing: {recorded:?}"
        );
        assert_eq!(pert.len(), orig.len(), "{stream}: perturbed frames missing");
        for ((o, r), p) in orig.iter().zip(&raw).zip(&pert) {
            for k in ["sec", "nanosec", "frame_id"] {
                assert_eq!(o[k], r[k], "{stream}: raw header {k}");
                assert_eq!(o[k], p[k], "{stream}: perturbed header {k}");
            }
            assert_eq!(o["sha256"], r["sha256"], "{stream}: the raw frame changed");
            assert_ne!(
                o["sha256"], p["sha256"],
                "{stream}: the frame was not perturbed"
            );
        }
    }
    let ev = events(&recorded);
    let mut seen = BTreeMap::new();
    for e in &ev {
        seen.insert(
            e["stream"].as_str().unwrap().to_string(),
            (e["id"].clone(), e["severity"].clone()),
        );
    }
    assert_eq!(seen["camera_front"], (Value::from("C-C7"), Value::from(2)));
    assert_eq!(seen["lidar_top"], (Value::from("L-B1"), Value::from(2)));
    for s in report["streams"].as_array().unwrap() {
        assert_eq!(s["dropped"], 0, "{s}");
        assert_eq!(s["invalid"], 0, "{s}");
    }
}

#[test]
fn synthetic_sensors_through_perturbd_every_frame_recorded_and_control_changes_recorded() {
    if !have_rosbags() {
        return;
    }
    let ns = Namespace::new("synthetic");
    let daemon_cfg = ns.dir.join("perturbd.toml");
    std::fs::write(
        &daemon_cfg,
        "[[streams]]\nname = \"cam\"\nmodality = \"camera\"\nqos = { subscriber_buffer = 8 }\n\
         perturbation = { id = \"C-A1\", severity = 1, seed = 2 }\n\n\
         [[streams]]\nname = \"lidar\"\nmodality = \"lidar\"\nsensor = \"vlp32c\"\nqos = { subscriber_buffer = 8 }\n",
    )
    .unwrap();
    let out = ns.dir.join("recording");
    let bridge_cfg = ns.dir.join("bridge.toml");
    let n_cam = 40;
    std::fs::write(
        &bridge_cfg,
        format!(
            "[bridge]\nname = \"synth\"\nqos = {{ subscriber_buffer = 8 }}\n\n\
             [[synthetic.camera]]\nstream = \"cam\"\nwidth = 400\nheight = 250\nrate_hz = 20.0\ncount = {n_cam}\n\n\
             [[synthetic.lidar]]\nstream = \"lidar\"\nrate_hz = 10.0\ncount = 10\n\n\
             [record]\nout = \"{}\"\nstreams = [\"cam\", \"lidar\"]\nraw = false\nperturbed = true\n",
            out.display()
        ),
    )
    .unwrap();
    let mut daemon = ns.start_daemon(&daemon_cfg);
    let mut bridge = ns
        .command(exe("perturb-bridge"))
        .arg("--config")
        .arg(&bridge_cfg)
        .args(["--linger", "3"])
        .spawn()
        .unwrap();
    // Switch the camera to another perturbation mid-run.
    std::thread::sleep(Duration::from_millis(1000));
    let o = ns.ctl(&["set", "cam", "C-F5", "--severity", "1"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(bridge.wait().unwrap().success());
    let report = daemon.stop();

    let recorded = read_bag(&out);
    let cam: Vec<&Value> = recorded
        .iter()
        .filter(|m| m["topic"] == "/cam/perturbed")
        .collect();
    let lidar = recorded
        .iter()
        .filter(|m| m["topic"] == "/lidar/perturbed")
        .count();
    let cam_stats = report["streams"]
        .as_array()
        .unwrap()
        .iter()
        .find(|s| s["name"] == "cam")
        .unwrap();
    assert_eq!(cam_stats["dropped"], 0, "{cam_stats}");
    assert_eq!(cam.len(), n_cam, "camera frames missing from the recording");
    assert_eq!(lidar, 10, "LiDAR frames missing from the recording");
    let ev = events(&recorded);
    let cam_ev: Vec<&Value> = ev.iter().filter(|e| e["stream"] == "cam").collect();
    assert_eq!(cam_ev.len(), n_cam);
    let seqs: BTreeSet<u64> = cam_ev.iter().map(|e| e["seq"].as_u64().unwrap()).collect();
    assert_eq!(seqs.len(), n_cam, "duplicate or missing sequence numbers");
    let ids: Vec<&str> = cam_ev.iter().map(|e| e["id"].as_str().unwrap()).collect();
    let switch = ids
        .iter()
        .position(|&i| i == "C-F5")
        .expect("the switch was not recorded");
    assert!(
        switch > 0 && ids[..switch].iter().all(|&i| i == "C-A1"),
        "{ids:?}"
    );
    assert!(ids[switch..].iter().all(|&i| i == "C-F5"), "{ids:?}");
    assert!(
        ev.iter()
            .filter(|e| e["stream"] == "lidar")
            .all(|e| e["id"].is_null())
    );
}
