//! `perturb demo`: the README's first command, run for a few seconds; the recording it leaves is
//! read back by `rosbags`.

use perturb_tests::{events, exe, have_rosbags, read_bag, shared_data};
use serde_json::Value;
use std::collections::BTreeSet;
use std::process::Command;

#[test]
fn the_demo_runs_the_pipeline_and_leaves_a_readable_recording_with_switching_perturbations() {
    let out = std::env::temp_dir().join(format!("perturb-demo-test-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&out);
    let o = Command::new(exe("perturb"))
        .args([
            "demo",
            "--seconds",
            "5",
            "--switch-every",
            "2",
            "--width",
            "320",
            "--height",
            "200",
        ])
        .arg("--out")
        .arg(&out)
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(
        o.status.success(),
        "demo failed:\n{stdout}\n{}",
        String::from_utf8_lossy(&o.stderr)
    );
    for col in [
        "source->daemon",
        "perturb",
        "daemon->sink",
        "camera_front",
        "lidar_top",
    ] {
        assert!(stdout.contains(col), "the table lacks {col}:\n{stdout}");
    }
    let recording = std::fs::read_dir(&out)
        .unwrap()
        .flatten()
        .map(|e| e.path())
        .find(|p| {
            p.file_name()
                .unwrap()
                .to_string_lossy()
                .starts_with("recording-")
        })
        .expect("a recording");
    assert!(stdout.contains(&recording.display().to_string()));

    if !have_rosbags() {
        return;
    }
    let msgs = read_bag(&recording);
    let count = |t: &str| msgs.iter().filter(|m| m["topic"] == t).count();
    assert!(count("/camera_front/perturbed") >= 30, "few camera frames");
    assert!(count("/lidar_top/perturbed") >= 10, "few LiDAR frames");
    assert!(count("/camera_front/raw") >= count("/camera_front/perturbed"));
    let ids: BTreeSet<String> = events(&msgs)
        .iter()
        .filter_map(|e| Some(e["id"].as_str()?.to_string()))
        .collect();
    assert!(
        ids.len() >= 4,
        "the demo did not switch perturbations: {ids:?}"
    );
    let _ = std::fs::remove_dir_all(&out);
}

#[test]
fn the_hil_feasibility_sweep_times_every_severity_in_the_live_pipeline() {
    let Some(bag) = shared_data("ros2_mcap_kitti_000001") else {
        return;
    };
    let o = Command::new(exe("perturb"))
        .args([
            "bench",
            "--modality",
            "lidar",
            "--sensor",
            "hdl64e",
            "--json",
        ])
        .args(["--window", "1", "--id", "L-B1", "--hil"])
        .arg(&bag)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let rows: Vec<Value> = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(rows.len(), 3, "one row per severity: {rows:?}");
    for (i, r) in rows.iter().enumerate() {
        assert_eq!(r["id"], "L-B1");
        assert_eq!(r["severity"], i as u64 + 1);
        assert!(r["frames"].as_u64().unwrap() >= 3, "{r}");
        let (mean, max) = (
            r["mean_ms"].as_f64().unwrap(),
            r["max_ms"].as_f64().unwrap(),
        );
        assert!(mean > 0.0 && mean <= max, "{r}");
        assert!(r["node_overhead_ms"].as_f64().unwrap() > 0.0, "{r}");
        assert_eq!(r["fits_budget"], max <= 200.0);
    }
}

/// `perturb demo --bag` on a ROS 1 bag written by an independent writer (`rosbags-convert`, lz4
/// chunks, from the shared KITTI rosbag2 bag): every stream of the bag goes through perturbd, none
/// is dropped.
#[test]
fn the_demo_replays_a_ros1_bag_written_by_rosbags() {
    let Some(src) = shared_data("ros2_mcap_kitti_000001") else {
        return;
    };
    if !have_rosbags() {
        return;
    }
    let dir = std::env::temp_dir().join(format!("perturb-demo-ros1-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let bag = dir.join("kitti.bag");
    let conv = Command::new("python3")
        .args(["-m", "rosbags.convert", "--src"])
        .arg(&src)
        .arg("--dst")
        .arg(&bag)
        .args(["--compress", "lz4"])
        .output()
        .unwrap();
    assert!(
        conv.status.success(),
        "rosbags-convert failed: {}",
        String::from_utf8_lossy(&conv.stderr)
    );
    let o = Command::new(exe("perturb"))
        .args(["demo", "--sensor", "hdl64e", "--seconds", "3", "--bag"])
        .arg(&bag)
        .arg("--out")
        .arg(dir.join("out"))
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(
        o.status.success(),
        "demo failed:\n{stdout}\n{}",
        String::from_utf8_lossy(&o.stderr)
    );
    for stream in [
        "kitti_camera_color_left_image_raw ",
        "kitti_camera_color_left_image_raw_compressed ",
        "kitti_velo_pointcloud ",
    ] {
        let row = stdout
            .lines()
            .find(|l| l.starts_with(stream))
            .unwrap_or_else(|| panic!("no row for {stream}:\n{stdout}"));
        let n: Vec<u64> = row
            .split_whitespace()
            .skip(1)
            .take(4)
            .map(|v| v.parse().unwrap())
            .collect();
        assert!(n[0] >= 3, "{stream}: too few frames in:\n{stdout}");
        assert_eq!(n[0], n[1], "{stream}: frames in != out:\n{stdout}");
        assert_eq!(n[2], 0, "{stream}: frames dropped:\n{stdout}");
    }
    let _ = std::fs::remove_dir_all(&dir);
}
