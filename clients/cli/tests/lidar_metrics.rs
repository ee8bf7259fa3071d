//! `perturb detect`, `perturb metrics lidar` and `perturb batch --lidar-metrics` as a user runs
//! them: constructed scans with hand-computed answers, and real KITTI scans.

use perturb_core::formats::kitti_labels::{KittiCalib, parse_labels};
mod common;

use common::{fails, ok, shared, tmp};
use std::path::{Path, PathBuf};

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// Writes a KITTI .bin (float32 x, y, z, reflectance).
fn write_kitti(path: &Path, pts: &[[f32; 3]]) {
    let mut bytes = Vec::with_capacity(pts.len() * 16);
    for p in pts {
        for v in [p[0], p[1], p[2], 0.5] {
            bytes.extend_from_slice(&v.to_le_bytes());
        }
    }
    std::fs::create_dir_all(path.parent().unwrap()).unwrap();
    std::fs::write(path, bytes).unwrap();
}

/// A flat ground at z = -1.8 (x 4..34, y -15..15, 0.3 m grid, offset off the voxel and cell
/// boundaries) and, for each centre, a hollow 4 x 2 x 1.2 m box (axis-aligned, faces sampled every
/// 0.1 m) standing 0.3 m above the ground, so no box point is within the ground tolerance.
fn ground(pts: &mut Vec<[f32; 3]>) {
    for i in 0..100 {
        for j in 0..100 {
            pts.push([4.07 + i as f32 * 0.3, -14.93 + j as f32 * 0.3, -1.8]);
        }
    }
}

fn block(c: [f32; 2]) -> Vec<[f32; 3]> {
    let mut v = Vec::new();
    for k in 0..=12 {
        let z = -1.5 + k as f32 * 0.1;
        for i in 0..=40 {
            let x = c[0] - 2.0 + i as f32 * 0.1;
            v.push([x, c[1] - 1.0, z]);
            v.push([x, c[1] + 1.0, z]);
        }
        for j in 1..20 {
            let y = c[1] - 1.0 + j as f32 * 0.1;
            v.push([c[0] - 2.0, y, z]);
            v.push([c[0] + 2.0, y, z]);
        }
    }
    v
}

fn scene(blocks: &[[f32; 2]]) -> Vec<[f32; 3]> {
    let mut pts = Vec::new();
    ground(&mut pts);
    for b in blocks {
        pts.extend(block(*b));
    }
    pts
}

const FRAME0: [[f32; 2]; 3] = [[12.03, -6.02], [20.01, 5.04], [28.02, -2.03]];
const FRAME1: [[f32; 2]; 2] = [[15.04, 7.01], [25.02, -8.03]];

fn detect_json(path: &Path) -> Vec<serde_json::Value> {
    let out = ok(&["detect", "--json", s(path)]);
    serde_json::from_str::<serde_json::Value>(&out)
        .expect("detect --json prints JSON")
        .as_array()
        .expect("an array")
        .clone()
}

#[test]
fn detect_finds_constructed_blocks_with_the_documented_json_shape() {
    let t = tmp("detect-synthetic");
    let scan = t.join("scan.bin");
    write_kitti(&scan, &scene(&FRAME0));
    let dets = detect_json(&scan);
    assert_eq!(dets.len(), 3, "{dets:?}");
    // The detector's order is not specified: match each block to its nearest detection.
    for c in FRAME0 {
        let d = dets
            .iter()
            .min_by(|a, b| {
                let da = (a["center"][0].as_f64().unwrap() - c[0] as f64)
                    .hypot(a["center"][1].as_f64().unwrap() - c[1] as f64);
                let db = (b["center"][0].as_f64().unwrap() - c[0] as f64)
                    .hypot(b["center"][1].as_f64().unwrap() - c[1] as f64);
                da.total_cmp(&db)
            })
            .unwrap();
        let center: Vec<f64> = d["center"]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_f64().unwrap())
            .collect();
        let size: Vec<f64> = d["size"]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_f64().unwrap())
            .collect();
        assert_eq!((center.len(), size.len()), (3, 3));
        assert!((center[0] - c[0] as f64).abs() < 0.01 && (center[1] - c[1] as f64).abs() < 0.01);
        // A box standing on the ground reaches down to it (its tolerance, 0.15 m, above the
        // ground at -1.8): from -1.65 to the block's top at -0.3.
        assert!((center[2] - -0.975).abs() < 0.01, "z centre {}", center[2]);
        assert!((size[0] - 4.0).abs() < 0.01 && (size[1] - 2.0).abs() < 0.01);
        assert!((size[2] - 1.35).abs() < 0.01, "height {}", size[2]);
        // An axis-aligned block: heading 0 (or pi/2 would swap length and width).
        assert!(d["yaw"].as_f64().unwrap().abs() < 1e-3, "{d}");
        // Every face point is inside its box: 13 layers x (2 x 41 + 2 x 19) points.
        assert_eq!(d["points"].as_u64(), Some(13 * (2 * 41 + 2 * 19)), "{d}");
    }
    // The table names the file and counts the detections.
    let table = ok(&["detect", s(&scan)]);
    assert!(table.contains("3 detections"), "{table}");
    assert_eq!(table.lines().count(), 2 + 3, "{table}");
}

#[test]
fn detect_errors_name_the_file() {
    let t = tmp("detect-errors");
    let missing = t.join("nope.bin");
    let err = fails(&["detect", s(&missing)]);
    assert!(err.contains("nope.bin"), "{err}");
    let bad = t.join("garbage.bin");
    std::fs::write(&bad, [1u8, 2, 3, 4, 5]).unwrap();
    let err = fails(&["detect", s(&bad)]);
    assert!(err.contains("garbage.bin"), "{err}");
    let txt = t.join("notes.txt");
    std::fs::write(&txt, "hello").unwrap();
    let err = fails(&["detect", s(&txt)]);
    assert!(err.contains("notes.txt"), "{err}");
}

/// Clean: two frames with 3 and 2 blocks (5 baseline detections). Set s1: everything shifted by
/// 0.5 m in x (a multiple of the voxel size, so the clusters are the same points). Set s2: frame
/// 0 without its second block. Hand-computed: s1 retention 1, ATE 0.5; s2 retention 4/5, ATE 0;
/// summary avg (1 + 0.8) / 2 = 0.9, min 0.8, max ATE 0.5.
fn constructed_sets(t: &Path) -> (PathBuf, PathBuf) {
    let clean = t.join("clean");
    let root = t.join("perturbed");
    let f0 = scene(&FRAME0);
    let f1 = scene(&FRAME1);
    write_kitti(&clean.join("000000.bin"), &f0);
    write_kitti(&clean.join("000001.bin"), &f1);
    let shift =
        |v: &[[f32; 3]]| -> Vec<[f32; 3]> { v.iter().map(|p| [p[0] + 0.5, p[1], p[2]]).collect() };
    let s1 = root.join("L-B1_density_decrease/s1");
    write_kitti(&s1.join("000000.bin"), &shift(&f0));
    write_kitti(&s1.join("000001.bin"), &shift(&f1));
    std::fs::write(s1.join(".done"), "{}").unwrap();
    let s2 = root.join("L-B1_density_decrease/s2");
    write_kitti(&s2.join("000000.bin"), &scene(&[FRAME0[0], FRAME0[2]]));
    write_kitti(&s2.join("000001.bin"), &f1);
    std::fs::write(s2.join(".done"), "{}").unwrap();
    // An unfinished set is skipped, a camera set and a stray folder are ignored.
    let s3 = root.join("L-B1_density_decrease/s3");
    write_kitti(&s3.join("000000.bin"), &f0);
    std::fs::create_dir_all(root.join("C-A1_gaussian_noise/s1")).unwrap();
    std::fs::create_dir_all(root.join("notes")).unwrap();
    (clean, root)
}

#[test]
fn metrics_lidar_hand_computed_retention_and_ate() {
    let t = tmp("metrics-constructed");
    let (clean, root) = constructed_sets(&t);
    let json = ok(&[
        "metrics",
        "lidar",
        "--clean",
        s(&clean),
        "--perturbed",
        s(&root),
        "--format",
        "json",
        "--quiet",
    ]);
    let v: serde_json::Value = serde_json::from_str(&json).unwrap();
    assert_eq!(v["frames"], 2);
    assert_eq!(v["baseline_detections"], 5);
    let rows = v["per_severity"].as_array().unwrap();
    assert_eq!(rows.len(), 2, "s3 has no .done marker: {rows:?}");
    let r1 = &rows[0];
    assert_eq!(
        (r1["id"].as_str(), r1["severity"].as_u64()),
        (Some("L-B1"), Some(1))
    );
    assert_eq!(
        (r1["baseline"].as_u64(), r1["retained"].as_u64()),
        (Some(5), Some(5))
    );
    assert_eq!(r1["retention"].as_f64(), Some(1.0));
    let ate = r1["ate"].as_f64().unwrap();
    assert!((ate - 0.5).abs() < 1e-3, "ATE {ate}");
    let r2 = &rows[1];
    assert_eq!(
        (r2["baseline"].as_u64(), r2["retained"].as_u64()),
        (Some(5), Some(4))
    );
    assert!((r2["retention"].as_f64().unwrap() - 0.8).abs() < 1e-12);
    assert!(r2["ate"].as_f64().unwrap().abs() < 1e-6);
    let p = &v["per_perturbation"][0];
    assert_eq!(p["id"], "L-B1");
    assert!(
        (p["avg_retention"].as_f64().unwrap() - 0.9).abs() < 1e-12,
        "{p}"
    );
    assert!(
        (p["min_retention"].as_f64().unwrap() - 0.8).abs() < 1e-12,
        "{p}"
    );
    assert!((p["max_ate"].as_f64().unwrap() - 0.5).abs() < 1e-3, "{p}");

    // The same numbers with one thread, and in the other formats.
    let one = ok(&[
        "metrics",
        "lidar",
        "--clean",
        s(&clean),
        "--perturbed",
        s(&root),
        "--format",
        "json",
        "--quiet",
        "--threads",
        "1",
    ]);
    assert_eq!(one, json, "results depend on the thread count");
    let csv = ok(&[
        "metrics",
        "lidar",
        "--clean",
        s(&clean),
        "--perturbed",
        s(&root),
        "--format",
        "csv",
        "--quiet",
    ]);
    let lines: Vec<&str> = csv.lines().collect();
    assert_eq!(
        lines[0],
        "id,name,severity,frames,baseline,retained,retention,ate_m"
    );
    assert!(
        lines[1].starts_with("L-B1,density_decrease,1,2,5,5,1,0.5"),
        "{csv}"
    );
    assert!(
        lines[2].starts_with("L-B1,density_decrease,2,2,5,4,0.8,0"),
        "{csv}"
    );
    let table = ok(&[
        "metrics",
        "lidar",
        "--clean",
        s(&clean),
        "--perturbed",
        s(&root),
        "--quiet",
    ]);
    assert!(
        table.contains("L-B1") && table.contains("0.900") && table.contains("0.800"),
        "{table}"
    );
    let md = ok(&[
        "metrics",
        "lidar",
        "--clean",
        s(&clean),
        "--perturbed",
        s(&root),
        "--format",
        "markdown",
        "--quiet",
    ]);
    assert!(
        md.contains("| L-B1 | density_decrease | 0.900 | 0.800 | 0.500 |"),
        "{md}"
    );

    // A tighter match radius than the shift loses every match of s1.
    let tight = ok(&[
        "metrics",
        "lidar",
        "--clean",
        s(&clean),
        "--perturbed",
        s(&root),
        "--format",
        "csv",
        "--quiet",
        "--match-distance",
        "0.4",
    ]);
    assert!(
        tight
            .lines()
            .nth(1)
            .unwrap()
            .starts_with("L-B1,density_decrease,1,2,5,0,0,"),
        "{tight}"
    );
}

#[test]
fn metrics_lidar_errors_are_clear() {
    let t = tmp("metrics-errors");
    let (clean, root) = constructed_sets(&t);
    // A file missing from a finished set.
    std::fs::remove_file(root.join("L-B1_density_decrease/s2/000001.bin")).unwrap();
    let err = fails(&[
        "metrics",
        "lidar",
        "--clean",
        s(&clean),
        "--perturbed",
        s(&root),
        "--quiet",
    ]);
    assert!(
        err.contains("000001.bin") && err.contains("missing"),
        "{err}"
    );
    // No --clean and no batch.json.
    let err = fails(&["metrics", "lidar", "--perturbed", s(&root), "--quiet"]);
    assert!(
        err.contains("batch.json") && err.contains("--clean"),
        "{err}"
    );
    // No set at all.
    let empty = t.join("empty");
    std::fs::create_dir_all(&empty).unwrap();
    let err = fails(&[
        "metrics",
        "lidar",
        "--clean",
        s(&clean),
        "--perturbed",
        s(&empty),
        "--quiet",
    ]);
    assert!(err.contains("no finished LiDAR set"), "{err}");
    // --id keeps only the sets of those perturbations.
    let err = fails(&[
        "metrics",
        "lidar",
        "--clean",
        s(&clean),
        "--perturbed",
        s(&root),
        "--id",
        "beam_reduction",
        "--quiet",
    ]);
    assert!(err.contains("no finished LiDAR set"), "{err}");
}

fn floats(v: &serde_json::Value) -> Vec<f32> {
    v.as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_f64().unwrap() as f32)
        .collect()
}

#[test]
fn detect_finds_the_labelled_cars_of_kitti_000008() {
    let Some(data) = shared("detect_finds_the_labelled_cars_of_kitti_000008") else {
        return;
    };
    let dir = data.join("kitti_000008_mmdet3d");
    let bin = dir.join("000008_velodyne_reduced.bin");
    let dets = detect_json(&bin);
    assert!(!dets.is_empty());
    for d in &dets {
        assert_eq!(floats(&d["center"]).len(), 3);
        let size = floats(&d["size"]);
        assert!(size.len() == 3 && size.iter().all(|v| v.is_finite() && *v >= 0.0));
        assert!(size[0] >= size[1], "length is the longer side: {d}");
        let yaw = d["yaw"].as_f64().unwrap();
        assert!(
            yaw > -std::f64::consts::FRAC_PI_2 - 1e-6 && yaw <= std::f64::consts::FRAC_PI_2 + 1e-6
        );
        assert!(d["points"].as_u64().unwrap() >= 1, "{d}");
    }
    let calib =
        KittiCalib::parse(&std::fs::read_to_string(dir.join("000008_calib.txt")).unwrap()).unwrap();
    let cars: Vec<_> =
        parse_labels(&std::fs::read_to_string(dir.join("000008_label_2.txt")).unwrap())
            .unwrap()
            .iter()
            .filter(|o| o.has_box() && o.kind == "Car")
            .map(|o| calib.to_velodyne(o))
            .filter(|b| b.center[0].hypot(b.center[1]) < 15.0)
            .collect();
    assert_eq!(cars.len(), 4, "the label file has 4 cars within 15 m");
    for car in &cars {
        let err = dets
            .iter()
            .map(|d| {
                let c = floats(&d["center"]);
                (c[0] - car.center[0]).hypot(c[1] - car.center[1])
            })
            .fold(f32::INFINITY, f32::min);
        eprintln!(
            "car at ({:.2}, {:.2}): nearest detection {err:.2} m",
            car.center[0], car.center[1]
        );
        assert!(err < 1.5, "car at {:?} missed ({err:.2} m)", car.center);
    }
}

/// Real scans through `perturb batch --lidar-metrics` (L-B1, density decrease, severities 1..3),
/// then `perturb metrics lidar` on the same output with the clean data taken from batch.json.
#[test]
fn batch_lidar_metrics_on_kitti_scans() {
    let Some(data) = shared("batch_lidar_metrics_on_kitti_scans") else {
        return;
    };
    let t = tmp("batch-kitti");
    let clean = t.join("clean");
    std::fs::create_dir_all(&clean).unwrap();
    for f in ["000000.bin", "000001.bin"] {
        std::fs::copy(data.join("kitti/velodyne").join(f), clean.join(f)).unwrap();
    }
    let out = t.join("out");
    let table = ok(&[
        "batch",
        s(&clean),
        "--out",
        s(&out),
        "--id",
        "L-B1",
        "--lidar-metrics",
        "--quiet",
    ]);
    eprintln!("{table}");
    assert!(table.contains("L-B1"), "{table}");
    let md = std::fs::read_to_string(out.join("lidar_metrics.md")).unwrap();
    assert!(md.contains("| L-B1 | density_decrease |"), "{md}");
    let v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("lidar_metrics.json")).unwrap())
            .unwrap();
    assert_eq!(v["frames"], 2);
    assert!(v["baseline_detections"].as_u64().unwrap() >= 20, "{v}");
    let rows = v["per_severity"].as_array().unwrap();
    assert_eq!(rows.len(), 3);
    let ret: Vec<f64> = rows
        .iter()
        .map(|r| r["retention"].as_f64().unwrap())
        .collect();
    for (r, row) in ret.iter().zip(rows) {
        assert!((0.0..=1.0).contains(r), "{row}");
        let ate = row["ate"].as_f64().unwrap();
        assert!((0.0..=2.0).contains(&ate), "{row}");
    }
    // Thinning removes more points at higher severity: retention does not rise much.
    assert!(ret[2] <= ret[0] + 0.05, "{ret:?}");
    assert!(
        ret[0] > 0.5,
        "a mild density decrease keeps most detections: {ret:?}"
    );
    let p = &v["per_perturbation"][0];
    let min = ret.iter().copied().fold(f64::INFINITY, f64::min);
    assert_eq!(p["min_retention"].as_f64(), Some(min));
    assert!((p["avg_retention"].as_f64().unwrap() - ret.iter().sum::<f64>() / 3.0).abs() < 1e-12);

    // `perturb metrics lidar` finds the clean data in batch.json and gives the same numbers.
    let json = ok(&[
        "metrics",
        "lidar",
        "--perturbed",
        s(&out),
        "--format",
        "json",
        "--quiet",
    ]);
    let w: serde_json::Value = serde_json::from_str(&json).unwrap();
    assert_eq!(w["per_severity"], v["per_severity"]);
    assert_eq!(w["per_perturbation"], v["per_perturbation"]);
}

/// A bag through `perturb batch --lidar-metrics`: the clouds are matched by topic and index.
#[test]
fn batch_lidar_metrics_on_a_bag() {
    let Some(data) = shared("batch_lidar_metrics_on_a_bag") else {
        return;
    };
    let bag = data.join("ros2_mcap_kitti_000001");
    let t = tmp("batch-bag");
    let out = t.join("out");
    ok(&[
        "batch",
        s(&bag),
        "--out",
        s(&out),
        "--id",
        "L-B1",
        "--severity",
        "1",
        "--lidar-metrics",
        "--quiet",
    ]);
    let v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("lidar_metrics.json")).unwrap())
            .unwrap();
    assert_eq!(v["frames"], 1, "one PointCloud2 message: {v}");
    assert!(v["baseline_detections"].as_u64().unwrap() >= 10, "{v}");
    let r = v["per_severity"][0]["retention"].as_f64().unwrap();
    assert!((0.5..=1.0).contains(&r), "{v}");
}
