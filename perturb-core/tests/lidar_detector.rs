//! The clustering detector on real labelled KITTI scans: 000008 (mmdetection3d's demo frame, camera
//! field of view only) and the full 360-degree scans 000000 and 000001.

mod common;

use perturb_core::detector::{BoxFit, Detector, DetectorConfig};
use perturb_core::formats::kitti;
use perturb_core::formats::kitti_labels::{KittiCalib, parse_labels};
use perturb_core::lidar::{Box3, Points};
use perturb_core::sensors::SensorModel;
use std::path::Path;

fn points_of(bin: &Path) -> Points {
    let cloud = kitti::decode_kitti(&std::fs::read(bin).expect("read scan")).expect("decode");
    Points::extract(&cloud.view(), &SensorModel::hdl64e(), false).expect("extract")
}

/// The labelled boxes (DontCare skipped) in the velodyne frame, with their class.
fn labels(label: &Path, calib: &Path) -> Vec<(String, Box3)> {
    labels_with_truncation(label, calib)
        .into_iter()
        .map(|(k, b, _)| (k, b))
        .collect()
}

fn labels_with_truncation(label: &Path, calib: &Path) -> Vec<(String, Box3, f32)> {
    let calib = KittiCalib::parse(&std::fs::read_to_string(calib).expect("calib")).expect("calib");
    parse_labels(&std::fs::read_to_string(label).expect("label"))
        .expect("label")
        .iter()
        .filter(|o| o.has_box())
        .map(|o| (o.kind.clone(), calib.to_velodyne(o), o.truncated))
        .collect()
}

/// Heading difference modulo pi (a detector cannot tell front from back), in degrees.
fn heading_error_deg(a: f32, b: f32) -> f32 {
    let d = (a - b).rem_euclid(std::f32::consts::PI);
    d.min(std::f32::consts::PI - d).to_degrees()
}

fn ground_dist(a: &Box3, b: &Box3) -> f32 {
    (a.center[0] - b.center[0]).hypot(a.center[1] - b.center[1])
}

/// The nearest detection to `label` in the ground plane and its distance.
fn nearest<'a>(label: &Box3, dets: &'a [Box3]) -> Option<(&'a Box3, f32)> {
    dets.iter()
        .map(|d| (d, ground_dist(d, label)))
        .min_by(|a, b| a.1.total_cmp(&b.1))
}

/// Raw points inside a labelled box that are more than 0.2 m above its bottom (so the road under
/// the object does not count) and below the detector's crop ceiling (`max_z`): the points the
/// detector can see of the object.
fn object_points(p: &Points, b: &Box3, c: &DetectorConfig) -> usize {
    let bottom = b.center[2] - b.size[2] / 2.0;
    (0..p.len())
        .filter(|&i| b.contains(p.xyz(i)) && p.z[i] > bottom + 0.2 && p.z[i] < c.max_z)
        .count()
}

#[test]
fn finds_the_four_cars_within_15_m_of_kitti_000008() {
    let Some(dir) = common::shared_data("finds_the_four_cars_within_15_m_of_kitti_000008") else {
        return;
    };
    let dir = dir.join("kitti_000008_mmdet3d");
    let p = points_of(&dir.join("000008_velodyne_reduced.bin"));
    let gt = labels_with_truncation(
        &dir.join("000008_label_2.txt"),
        &dir.join("000008_calib.txt"),
    );
    for fit in [BoxFit::MinArea, BoxFit::AxisAligned] {
        let dets = Detector::new(DetectorConfig {
            box_fit: fit,
            ..DetectorConfig::default()
        })
        .detect(&p);
        let near: Vec<(&Box3, f32)> = gt
            .iter()
            .filter(|(k, b, _)| k == "Car" && b.center[0].hypot(b.center[1]) < 15.0)
            .map(|(_, b, t)| (b, *t))
            .collect();
        assert_eq!(near.len(), 4, "the label file has 4 cars within 15 m");
        for (g, truncated) in near {
            let (d, err) = nearest(g, &dets).expect("some detection");
            eprintln!(
                "{fit:?}: car at ({:.2}, {:.2}) yaw {:.2}: detection ({:.2}, {:.2}) {:?} yaw {:.2}, error {err:.2} m",
                g.center[0], g.center[1], g.yaw, d.center[0], d.center[1], d.size, d.yaw
            );
            assert!(
                err < 1.5,
                "{fit:?}: car at {:?} missed ({err:.2} m)",
                g.center
            );
            // Minimum-area boxes follow the car's orientation when the whole car is in view (the
            // first car is 88 % outside the camera image, so its points are only its rear).
            if fit == BoxFit::MinArea && truncated < 0.5 {
                let e = heading_error_deg(d.yaw, g.yaw);
                assert!(e < 10.0, "car at {:?}: heading off by {e:.1} deg", g.center);
            }
        }
    }
}

#[test]
fn recall_on_kitti_000000_000001_and_000008() {
    let Some(data) = common::shared_data("recall_on_kitti_000000_000001_and_000008") else {
        return;
    };
    let config = DetectorConfig::default();
    let mut detector = Detector::new(config.clone());
    let (mut eligible, mut found) = (0, 0);
    let kitti = data.join("kitti");
    let k8 = data.join("kitti_000008_mmdet3d");
    let frames = [
        (
            "000000",
            kitti.join("velodyne/000000.bin"),
            kitti.join("label_2/000000.txt"),
            kitti.join("calib/000000.txt"),
        ),
        (
            "000001",
            kitti.join("velodyne/000001.bin"),
            kitti.join("label_2/000001.txt"),
            kitti.join("calib/000001.txt"),
        ),
        (
            "000008",
            k8.join("000008_velodyne_reduced.bin"),
            k8.join("000008_label_2.txt"),
            k8.join("000008_calib.txt"),
        ),
    ];
    for (idx, bin, label, calib) in &frames {
        let p = points_of(bin);
        let gt = labels(label, calib);
        let dets = detector.detect(&p);
        eprintln!("{idx}: {} points, {} detections", p.len(), dets.len());
        for (kind, g) in &gt {
            let n = object_points(&p, g, &config);
            let in_crop = g.center[0] >= config.min_x
                && g.center[0] < config.max_x
                && g.center[1] >= config.min_y
                && g.center[1] < config.max_y;
            let (err, size) =
                nearest(g, &dets).map_or((f32::INFINITY, [0.0; 3]), |(d, e)| (e, d.size));
            // "Enough": the centre is in the detector's crop and the scan has at least 20 points
            // of the object that the detector can see (above the box's bottom 0.2 m, below the
            // crop ceiling).
            let enough = in_crop && n >= 20;
            // Found: a detection centre within 1.5 m, or within half the object's length for
            // long objects (a truck seen from behind is detected by its visible part).
            let hit = err < 1.5f32.max(0.5 * g.size[0]);
            eprintln!(
                "{idx} {kind:<10} at ({:6.2}, {:6.2}) {n:5} points, in crop {in_crop}: nearest detection {err:.2} m {size:?}",
                g.center[0], g.center[1]
            );
            if enough {
                eligible += 1;
                found += hit as usize;
                assert!(
                    hit,
                    "{idx}: {kind} at {:?} with {n} points missed",
                    g.center
                );
            }
        }
    }
    eprintln!("recall {found}/{eligible}");
    assert!(eligible >= 5, "{eligible} eligible objects");
}
