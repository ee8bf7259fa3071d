//! The `perturb` binary as a user runs it: real processes, real files, independent readers.

mod common;

use common::{fails, ok, perturb, shared, tmp};
use std::path::Path;

#[path = "../../../tests/support/python_oracle.rs"]
mod python_oracle;

/// [`python_oracle::python_oracle`] with the CLI tests' install hint.
fn python_oracle(module: &str, script: &str, args: &[&str]) -> Option<String> {
    python_oracle::python_oracle(
        module,
        "pip install rosbags mcap mcap-ros2-support",
        script,
        args,
    )
}

const ROSBAGS_COUNT: &str = r#"
import sys, json
from pathlib import Path
from rosbags.highlevel import AnyReader
from rosbags.typesys import Stores, get_typestore
with AnyReader([Path(sys.argv[1])], default_typestore=get_typestore(Stores.ROS2_HUMBLE)) as r:
    counts, events = {}, []
    for conn, t, raw in r.messages():
        m = r.deserialize(raw, conn.msgtype)
        counts[conn.topic] = counts.get(conn.topic, 0) + 1
        if conn.topic == '/perturb/events':
            events.append(json.loads(m.data))
        if conn.msgtype == 'sensor_msgs/msg/Image':
            counts['stamp'] = [m.header.stamp.sec, m.header.stamp.nanosec, m.header.frame_id]
    print(json.dumps({'counts': counts, 'events': events}))
"#;

#[test]
fn list_json_is_the_whole_catalogue() {
    let v: serde_json::Value = serde_json::from_str(&ok(&["list", "--json"])).unwrap();
    let arr = v.as_array().unwrap();
    assert_eq!(arr.len(), 73);
    for e in arr {
        for key in ["id", "name", "modality", "family", "severities"] {
            assert!(e.get(key).is_some(), "{key} missing in {e}");
        }
        let n = e["severities"].as_array().unwrap().len();
        assert_eq!(n, if e["modality"] == "camera" { 5 } else { 3 });
    }
    let approximate: Vec<&str> = arr
        .iter()
        .filter(|e| !e["calibration"].is_null())
        .map(|e| e["id"].as_str().unwrap())
        .collect();
    assert_eq!(approximate, ["C-B2", "C-B4", "C-D1", "C-D3"]);
    assert!(ok(&["list", "--modality", "lidar"]).contains("L-B6"));
    assert!(ok(&["list"]).contains("C-D3: a 2x enlargement"));
}

#[test]
fn bad_input_gets_a_clear_error_naming_what_and_where() {
    let d = tmp("errors");
    let bad_png = d.join("cut.png");
    std::fs::write(&bad_png, b"\x89PNG\r\n\x1a\nnot really").unwrap();
    let out = d.join("o.png");
    let e = fails(&[
        "apply",
        "--id",
        "C-A1",
        "--severity",
        "2",
        bad_png.to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
    ]);
    assert!(e.contains("cut.png") && e.contains("PNG"), "{e}");
    let bin = d.join("short.bin");
    std::fs::write(&bin, [0u8; 30]).unwrap();
    let e = fails(&[
        "apply",
        "--id",
        "L-B1",
        "--severity",
        "1",
        bin.to_str().unwrap(),
        "-o",
        d.join("o.bin").to_str().unwrap(),
    ]);
    assert!(
        e.contains("short.bin") && e.contains("multiple of 16"),
        "{e}"
    );
    let pcd = d.join("lie.pcd");
    std::fs::write(&pcd, "VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nWIDTH 10\nHEIGHT 1\nPOINTS 10\nDATA binary\n").unwrap();
    let e = fails(&[
        "apply",
        "--id",
        "L-B1",
        "--severity",
        "1",
        pcd.to_str().unwrap(),
        "-o",
        d.join("o.pcd").to_str().unwrap(),
    ]);
    assert!(e.contains("lie.pcd") && e.contains("truncated"), "{e}");
    let noxyz = d.join("noxyz.pcd");
    std::fs::write(&noxyz, "VERSION 0.7\nFIELDS a b\nSIZE 4 4\nTYPE F F\nWIDTH 1\nHEIGHT 1\nPOINTS 1\nDATA ascii\n1 2\n").unwrap();
    let e = fails(&[
        "apply",
        "--id",
        "L-C1",
        "--severity",
        "1",
        noxyz.to_str().unwrap(),
        "-o",
        d.join("o.pcd").to_str().unwrap(),
    ]);
    assert!(e.contains("`x`"), "{e}");
    assert!(
        fails(&[
            "apply",
            "--id",
            "C-Q7",
            "--severity",
            "1",
            "a.png",
            "-o",
            "b.png"
        ])
        .contains("unknown perturbation `C-Q7`")
    );
    assert!(
        fails(&[
            "apply",
            "--id",
            "L-B1",
            "--severity",
            "4",
            "a.bin",
            "-o",
            "b.bin"
        ])
        .contains("1..=3")
    );
    assert!(
        fails(&[
            "apply",
            "--id",
            "C-A1",
            "--severity",
            "1",
            "a.png",
            "-o",
            "b.jpg"
        ])
        .contains("format")
    );
}

#[test]
fn apply_is_deterministic_and_depends_on_seq() {
    let Some(data) = shared("apply_is_deterministic") else {
        return;
    };
    let d = tmp("det");
    let img = data.join("kitti/image_2/000001.png");
    let run = |name: &str, seq: &str| {
        let o = d.join(name);
        ok(&[
            "apply",
            "--id",
            "C-A1",
            "--severity",
            "3",
            "--seed",
            "9",
            "--seq",
            seq,
            img.to_str().unwrap(),
            "-o",
            o.to_str().unwrap(),
        ]);
        std::fs::read(o).unwrap()
    };
    let (a, b, c) = (run("a.png", "4"), run("b.png", "4"), run("c.png", "5"));
    assert_eq!(a, b);
    assert_ne!(a, c);
    let info = ok(&["info", d.join("a.png").to_str().unwrap()]);
    assert!(info.contains("1242x375 rgb8"), "{info}");
    // A PCD keeps its fields and data encoding.
    let pcd = data.join("rosbag2_nebula/vlp16/1673400472138016708.pcd");
    let o = d.join("n.pcd");
    ok(&[
        "apply",
        "--id",
        "L-C1",
        "--severity",
        "2",
        pcd.to_str().unwrap(),
        "-o",
        o.to_str().unwrap(),
    ]);
    let (before, after) = (
        ok(&["info", pcd.to_str().unwrap()]),
        ok(&["info", o.to_str().unwrap()]),
    );
    assert_eq!(before, after, "same layout, count and encoding");
}

#[test]
fn a_perturbed_bag_is_read_by_rosbags_with_headers_and_events() {
    let Some(data) = shared("a_perturbed_bag") else {
        return;
    };
    let d = tmp("bag");
    let out = d.join("out");
    ok(&[
        "apply",
        "--id",
        "C-F5",
        "--severity",
        "4",
        "--seed",
        "3",
        data.join("ros2_mcap_kitti_000001").to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
    ]);
    let info = ok(&["info", out.to_str().unwrap()]);
    assert!(info.contains("/perturb/events"), "{info}");
    let Some(json) = python_oracle("rosbags", ROSBAGS_COUNT, &[out.to_str().unwrap()]) else {
        return;
    };
    let v: serde_json::Value = serde_json::from_str(&json).unwrap();
    assert_eq!(v["counts"]["/kitti/velo/pointcloud"], 1);
    assert_eq!(
        v["counts"]["/perturb/events"], 2,
        "image_raw and its compressed twin"
    );
    let ev = &v["events"][0];
    assert_eq!(
        (
            ev["id"].as_str(),
            ev["severity"].as_u64(),
            ev["seed"].as_u64()
        ),
        (Some("C-F5"), Some(4), Some(3))
    );
    // The header stamp of the recorded image is the original one.
    let orig = python_oracle(
        "rosbags",
        ROSBAGS_COUNT,
        &[data.join("ros2_mcap_kitti_000001").to_str().unwrap()],
    )
    .unwrap();
    let o: serde_json::Value = serde_json::from_str(&orig).unwrap();
    assert_eq!(v["counts"]["stamp"], o["counts"]["stamp"]);
}

#[test]
fn batch_writes_every_set_and_resumes() {
    let Some(data) = shared("batch_writes_every_set") else {
        return;
    };
    let d = tmp("batch");
    let input = d.join("in");
    std::fs::create_dir_all(&input).unwrap();
    for f in ["000000.png", "000001.png"] {
        std::fs::copy(data.join("kitti/image_2").join(f), input.join(f)).unwrap();
    }
    let out = d.join("out");
    ok(&[
        "batch",
        input.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--id",
        "C-A1",
        "--quiet",
        "--seed",
        "2",
    ]);
    for s in 1..=5 {
        let set = out.join(format!("C-A1_gaussian_noise/s{s}"));
        assert!(
            set.join(".done").exists() && set.join("000001.png").exists(),
            "{}",
            set.display()
        );
    }
    // Every batch output is what `perturb apply` gives for that file's sequence number.
    let single = d.join("single.png");
    ok(&[
        "apply",
        "--id",
        "C-A1",
        "--severity",
        "3",
        "--seed",
        "2",
        "--seq",
        "1",
        input.join("000001.png").to_str().unwrap(),
        "-o",
        single.to_str().unwrap(),
    ]);
    assert_eq!(
        std::fs::read(&single).unwrap(),
        std::fs::read(out.join("C-A1_gaussian_noise/s3/000001.png")).unwrap()
    );
    // Resume: a finished set is skipped, an unfinished one is completed.
    std::fs::remove_file(out.join("C-A1_gaussian_noise/s2/.done")).unwrap();
    std::fs::remove_file(out.join("C-A1_gaussian_noise/s2/000000.png")).unwrap();
    let o = perturb(&[
        "batch",
        input.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--id",
        "C-A1",
        "--quiet",
        "--seed",
        "2",
    ]);
    assert!(String::from_utf8_lossy(&o.stderr).contains("4 of 5 sets already done"));
    assert!(out.join("C-A1_gaussian_noise/s2/000000.png").exists());
}

#[test]
fn gallery_and_augment() {
    let Some(data) = shared("gallery_and_augment") else {
        return;
    };
    let d = tmp("gal");
    let g = d.join("g.png");
    ok(&[
        "gallery",
        data.join("kitti/image_2/000000.png").to_str().unwrap(),
        "-o",
        g.to_str().unwrap(),
        "--id",
        "C-A1",
        "--id",
        "C-F5",
        "--cell-width",
        "100",
    ]);
    let info = ok(&["info", g.to_str().unwrap()]);
    // 2 rows of clean + 5 severities, 100 px cells: 6 x 104 + 4 wide.
    assert!(info.starts_with("image 628x"), "{info}");
    let bev = d.join("b.png");
    ok(&[
        "gallery",
        data.join("kitti/velodyne/000000.bin").to_str().unwrap(),
        "-o",
        bev.to_str().unwrap(),
        "--id",
        "L-B6",
        "--cell-width",
        "120",
    ]);
    assert!(ok(&["info", bev.to_str().unwrap()]).starts_with("image 500x"));

    let input = d.join("train");
    std::fs::create_dir_all(&input).unwrap();
    for f in ["000000.png", "000001.png"] {
        std::fs::copy(data.join("kitti/image_2").join(f), input.join(f)).unwrap();
    }
    let (a1, a2) = (d.join("aug1"), d.join("aug2"));
    for a in [&a1, &a2] {
        ok(&[
            "augment",
            input.to_str().unwrap(),
            "--out",
            a.to_str().unwrap(),
            "--id",
            "C-A1",
            "--id",
            "C-F5",
            "--seed",
            "11",
        ]);
    }
    let manifest = std::fs::read_to_string(a1.join("augment_manifest.csv")).unwrap();
    assert_eq!(
        manifest,
        std::fs::read_to_string(a2.join("augment_manifest.csv")).unwrap()
    );
    for line in manifest.lines().skip(1) {
        let f: Vec<&str> = line.split(',').collect();
        assert_eq!(
            std::fs::read(a1.join(f[1])).unwrap(),
            std::fs::read(a2.join(f[1])).unwrap()
        );
        // Regenerated from the manifest alone.
        let again = d.join("again.png");
        ok(&[
            "apply",
            "--id",
            f[2],
            "--severity",
            f[4],
            "--seed",
            f[5],
            "--seq",
            f[6],
            input.join(f[0]).to_str().unwrap(),
            "-o",
            again.to_str().unwrap(),
        ]);
        assert_eq!(
            std::fs::read(&again).unwrap(),
            std::fs::read(a1.join(f[1])).unwrap(),
            "{line}"
        );
        assert!(a1.join(f[0]).exists(), "clean copy beside the variant");
    }
}

#[test]
fn steering_metrics_match_hand_computed_values() {
    let d = tmp("steer");
    std::fs::write(
        d.join("base.csv"),
        "frame,steering\n0,0.0\n1,0.1\n2,0.2\n3,0.1\n",
    )
    .unwrap();
    let pred = d.join("pred");
    std::fs::create_dir_all(pred.join("C-A1_gaussian_noise")).unwrap();
    std::fs::write(
        pred.join("C-A1_gaussian_noise/s1.csv"),
        "0,0.1\n1,0.1\n2,-0.1\n3,0.1\n",
    )
    .unwrap();
    std::fs::write(
        pred.join("C-A1_gaussian_noise/s2.csv"),
        "0,0.0\n1,0.1\n2,0.2\n3,0.1\n",
    )
    .unwrap();
    let json = ok(&[
        "metrics",
        "steering",
        "--baseline",
        d.join("base.csv").to_str().unwrap(),
        "--predictions",
        pred.to_str().unwrap(),
        "--format",
        "json",
    ]);
    let v: serde_json::Value = serde_json::from_str(&json).unwrap();
    let p = &v["per_perturbation"][0];
    assert_eq!(p["id"], "C-A1");
    assert!(
        (p["avg_mse"].as_f64().unwrap() - 0.0125).abs() < 1e-12,
        "{p}"
    );
    assert!((p["max_mse"].as_f64().unwrap() - 0.025).abs() < 1e-12);
    assert!((p["max_abs_deviation"].as_f64().unwrap() - 0.3).abs() < 1e-12);
    std::fs::write(pred.join("C-A1_gaussian_noise/s3.csv"), "0,0.0\n1,oops\n").unwrap();
    let e = fails(&[
        "metrics",
        "steering",
        "--baseline",
        d.join("base.csv").to_str().unwrap(),
        "--predictions",
        pred.to_str().unwrap(),
    ]);
    assert!(e.contains("s3.csv:2") && e.contains("oops"), "{e}");
}

#[test]
fn bench_json_has_the_documented_fields() {
    let Some(data) = shared("bench_json") else {
        return;
    };
    let img = data.join("kitti/image_2/000000.png");
    let json = ok(&[
        "bench",
        "--modality",
        "camera",
        "--input",
        img.to_str().unwrap(),
        "--width",
        "200",
        "--height",
        "120",
        "--frames",
        "2",
        "--id",
        "C-F5",
        "--json",
    ]);
    let v: serde_json::Value = serde_json::from_str(&json).unwrap();
    let rows = v.as_array().unwrap();
    assert_eq!(rows.len(), 5);
    for r in rows {
        for key in ["id", "severity", "median_ms", "max_ms", "fits_budget"] {
            assert!(r.get(key).is_some(), "{key} missing: {r}");
        }
    }
    let scan = data.join("kitti/velodyne/000000.bin");
    let json = ok(&[
        "bench",
        "--modality",
        "lidar",
        "--input",
        scan.to_str().unwrap(),
        "--frames",
        "1",
        "--id",
        "L-B1",
        "--json",
    ]);
    assert_eq!(
        serde_json::from_str::<serde_json::Value>(&json)
            .unwrap()
            .as_array()
            .unwrap()
            .len(),
        3
    );
}

#[test]
fn bench_fit_threads_adds_the_threads_column() {
    let Some(data) = shared("bench_fit_threads") else {
        return;
    };
    let img = data.join("kitti/image_2/000000.png");
    let args = |budget: &'static str, format: &'static str| {
        vec![
            "bench".to_string(),
            "--modality".into(),
            "camera".into(),
            "--input".into(),
            img.to_str().unwrap().into(),
            "--width".into(),
            "200".into(),
            "--height".into(),
            "120".into(),
            "--frames".into(),
            "2".into(),
            "--id".into(),
            "C-F7".into(),
            "--fit-threads".into(),
            "--budget-ms".into(),
            budget.into(),
            "--format".into(),
            format.into(),
        ]
    };
    let run = |v: Vec<String>| ok(&v.iter().map(String::as_str).collect::<Vec<_>>());
    // A generous budget: every severity fits on one thread.
    let md = run(args("10000", "markdown"));
    assert!(md.contains("threads to fit"), "{md}");
    let row = md.lines().find(|l| l.starts_with("| C-F7")).unwrap();
    assert!(row.trim_end().ends_with("| 1 |"), "{row}");
    // No budget a frame can meet: none of the rows fits, and the CSV says what more threads
    // give (a count, an estimate `~n`, or `-` when the serial part alone is too slow).
    let csv = run(args("0.000001", "csv"));
    assert!(
        csv.lines().next().unwrap().ends_with(",threads_to_fit"),
        "{csv}"
    );
    for l in csv.lines().skip(1) {
        let cell = l.rsplit(',').next().unwrap();
        assert!(
            cell == "-"
                || cell
                    .trim_start_matches('~')
                    .parse::<usize>()
                    .is_ok_and(|n| n > 1),
            "{l}"
        );
    }
}

#[test]
fn demo_writes_outputs() {
    let d = tmp("demo");
    let out = ok(&[
        "demo",
        "--offline",
        "--out",
        d.to_str().unwrap(),
        "--width",
        "160",
        "--height",
        "100",
    ]);
    assert!(out.contains("C-A1"), "{out}");
    assert!(Path::new(&d.join("clean.png")).exists() && d.join("clean.pcd").exists());
}

#[test]
fn a_bag_with_a_4_gib_string_length_is_reported_under_a_memory_limit() {
    use perturb_bag::{BagWriter, Compression, WriterOptions};
    let dir = tmp("hostile_bag");
    let bag = dir.join("bag");
    let mut w = BagWriter::create(
        &bag,
        &WriterOptions {
            compression: Compression::Zstd,
            chunk_size: 64 << 10,
            ..Default::default()
        },
    )
    .unwrap();
    let t = w
        .add_topic("/lidar/points", "sensor_msgs/msg/PointCloud2")
        .unwrap();
    let c = perturb_core::cloud::Cloud::from_xyzi(
        &perturb_core::cloud::PointLayout::xyzir(),
        &[[1.0, 2.0, 3.0, 4.0]; 10],
    );
    let h = perturb_core::formats::ros::Header {
        stamp_sec: 1,
        stamp_nanosec: 2,
        frame_id: "velodyne",
    };
    let msg = perturb_core::formats::ros::PointCloud2Msg::from_view(h, &c.view()).encode();
    w.write(t, 1, 1, &msg).unwrap();
    w.finish().unwrap();
    let file = std::fs::read_dir(&bag)
        .unwrap()
        .map(|e| e.unwrap().path())
        .find(|p| p.extension().is_some_and(|x| x == "mcap"))
        .unwrap();
    let mut bytes = std::fs::read(&file).unwrap();
    // The Header record's profile string length (right after the magic, opcode and length).
    bytes[17..21].copy_from_slice(&4_294_967_054u32.to_le_bytes());
    let bad = dir.join("bad.mcap");
    std::fs::write(&bad, &bytes).unwrap();
    let o = std::process::Command::new("sh")
        .arg("-c")
        .arg(format!(
            "ulimit -v 1500000 && exec '{}' info '{}'",
            env!("CARGO_BIN_EXE_perturb"),
            bad.display()
        ))
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "not a clean error: {err}");
    assert!(
        err.contains("Header record profile") && err.contains("bad.mcap"),
        "{err}"
    );
}

/// `perturb bench --capacity`: every stream of a perturbd configuration timed, its load and the
/// counts a host sustains following the printed model.
#[test]
fn bench_capacity_follows_its_model_for_every_stream() {
    let Some(data) = shared("bench_capacity") else {
        return;
    };
    let dir = std::env::temp_dir().join(format!("perturb-capacity-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let cfg = dir.join("perturbd.toml");
    std::fs::write(
        &cfg,
        "[[streams]]\nname = \"cam\"\nmodality = \"camera\"\nperturbation = { id = \"C-F5\", severity = 1 }\n\
         [[streams]]\nname = \"raw\"\nmodality = \"camera\"\n\
         [[streams]]\nname = \"lid\"\nmodality = \"lidar\"\nsensor = \"hdl64e\"\nperturbation = { id = \"L-B1\", severity = 2 }\n",
    )
    .unwrap();
    let run = |extra: &[&str]| {
        std::process::Command::new(env!("CARGO_BIN_EXE_perturb"))
            .args(["bench", "--capacity", cfg.to_str().unwrap()])
            .args(["--width", "200", "--height", "120", "--frames", "3"])
            .args(extra)
            .env("PERTURB_SHARED_DATA", &data)
            .output()
            .unwrap()
    };
    let o = run(&["--json", "--camera-hz", "20", "--headroom", "0.5"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let streams = v["streams"].as_array().unwrap();
    let names: Vec<&str> = streams
        .iter()
        .map(|s| s["name"].as_str().unwrap())
        .collect();
    assert_eq!(names, ["cam", "raw", "lid"]);
    assert_eq!(streams[1]["perturbation"], "off");
    assert_eq!(streams[0]["frame"], "200x120");
    let mut total = 0.0;
    for s in streams {
        let (p50, rate) = (
            s["cost_p50_ms"].as_f64().unwrap(),
            s["rate_hz"].as_f64().unwrap(),
        );
        assert!(
            p50 > 0.0 && p50 <= s["cost_p99_ms"].as_f64().unwrap(),
            "{s}"
        );
        // The transport: two copies of the frame on the host, by default.
        let transport = s["transport_ms"].as_f64().unwrap();
        assert!(transport > 0.0, "{s}");
        let load = s["load_cores"].as_f64().unwrap();
        assert!(
            (load - (p50 + transport) * rate / 1000.0).abs() < 1e-12,
            "{s}"
        );
        total += load;
        for pair in s["alone"].as_array().unwrap() {
            let (n, k) = (pair[0].as_u64().unwrap(), pair[1].as_u64().unwrap());
            assert_eq!(k, (n as f64 * 0.5 / load + 1e-9).floor() as u64, "{s}");
        }
    }
    assert_eq!(streams[0]["rate_hz"], 20.0);
    assert_eq!(streams[2]["rate_hz"], 10.0);
    assert!((v["load_cores"].as_f64().unwrap() - total).abs() < 1e-12);
    let copies = v["copies"].as_array().unwrap();
    assert_eq!(copies.len(), 5);
    let k1 = copies[0][1].as_u64().unwrap();
    assert_eq!(k1, (0.5 / total + 1e-9).floor() as u64);
    // The table says what the model assumes.
    let o = run(&[]);
    let table = String::from_utf8_lossy(&o.stdout);
    assert!(table.contains("model: one worker pool"), "{table}");
    let o = run(&["--headroom", "1.5"]);
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("--headroom 1.5"));
    // Cores kept for other work come off every count; no transport copies, no transport.
    let o = run(&[
        "--json",
        "--headroom",
        "0.5",
        "--reserve-cores",
        "1",
        "--transport-copies",
        "0",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let total = v["load_cores"].as_f64().unwrap();
    for s in v["streams"].as_array().unwrap() {
        assert_eq!(s["transport_ms"].as_f64(), Some(0.0), "{s}");
    }
    let copies = v["copies"].as_array().unwrap();
    assert_eq!(copies[0][1].as_u64(), Some(0), "one core, one reserved");
    assert_eq!(
        copies[1][1].as_u64().unwrap(),
        (0.5 / total + 1e-9).floor() as u64,
        "two cores hold what one did"
    );
    let o = run(&["--reserve-cores=-1"]);
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("--reserve-cores -1"));
    let _ = std::fs::remove_dir_all(&dir);
}
