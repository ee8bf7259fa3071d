//! Every LiDAR perturbation at every severity on every real cloud of `../shared/data` (KITTI
//! HDL-64E scans, the reduced KITTI 000008, a KITTI scan turned into nuScenes' convention, the
//! nebula VLP-16 and VLP-32C PCDs, the Ouster OS1-64 cloud of the pointcloudset MCAP): no output
//! coordinate is NaN or infinite where the input had none, and no output intensity leaves the
//! sensor's scale `[0, full scale]` (issue 16: MultiCorrupt's fog wrote up to 2.8 x full scale).

mod common;

use perturb_core::cloud::{Cloud, names};
use perturb_core::formats::{kitti, pcd};
use perturb_core::perturber::LidarPerturber;
use perturb_core::registry::{Modality, of_modality};
use perturb_core::sensor_model::{Axes, Axis, SensorModel};
use rayon::prelude::*;

/// KITTI 000000 as nuScenes stores its clouds: x right, y forward, intensity 0..255, a ring.
fn nuscenes_like(kitti_scan: &Cloud, sensor: &SensorModel) -> Cloud {
    let layout = kitti::nuscenes_layout();
    let src = kitti_scan.view();
    let [rx, ry, rz] = src.layout().xyz_readers().unwrap();
    let ri = src.layout().reader_any(names::INTENSITY).unwrap();
    let mut data = Vec::with_capacity(src.len() * 20);
    for i in 0..src.len() {
        let p = src.point(i);
        let q = [rx.read_f32(p), ry.read_f32(p), rz.read_f32(p)];
        let s = sensor.axes.to_sensor(q);
        let ring = SensorModel::hdl32e().ring_of_elevation(q[2].atan2(q[0].hypot(q[1])));
        for v in [
            s[0],
            s[1],
            s[2],
            (ri.read_f32(p) * 255.0).round(),
            ring as f32,
        ] {
            data.extend_from_slice(&v.to_le_bytes());
        }
    }
    kitti::decode_nuscenes(&data).unwrap_or_else(|e| panic!("{e} ({layout:?})"))
}

#[test]
fn every_perturbation_keeps_positions_finite_and_intensity_within_the_scale() {
    let Some(data) = common::shared_data(
        "every_perturbation_keeps_positions_finite_and_intensity_within_the_scale",
    ) else {
        return;
    };
    let read = |p: &str| std::fs::read(data.join(p)).unwrap();
    let mut clouds: Vec<(String, Cloud, SensorModel)> = Vec::new();
    for f in ["kitti/velodyne/000000.bin", "kitti/velodyne/000001.bin"] {
        clouds.push((
            f.into(),
            kitti::decode_kitti(&read(f)).unwrap(),
            SensorModel::hdl64e(),
        ));
    }
    let k8 = "kitti_000008_mmdet3d/000008_velodyne_reduced.bin";
    clouds.push((
        k8.into(),
        kitti::decode_kitti(&read(k8)).unwrap(),
        SensorModel::hdl64e(),
    ));
    let nus = SensorModel::nuscenes();
    clouds.push((
        "KITTI 000000 in nuScenes' convention".into(),
        nuscenes_like(&clouds[0].1, &nus),
        nus,
    ));
    for (f, m) in [
        (
            "rosbag2_nebula/vlp16/1673400472138016708.pcd",
            SensorModel::vlp16(),
        ),
        (
            "rosbag2_nebula/vlp32c/1713492677464078412.pcd",
            SensorModel::vlp32c(),
        ),
    ] {
        clouds.push((f.into(), pcd::decode(&read(f)).unwrap().cloud, m));
    }
    // Ouster's `os1_lidar` frame has +x towards the connector, behind the sensor: -x forward.
    let (ouster, frame) = common::ros1_cloud(&data.join("mcap_ouster_os1_pointcloudset/test.mcap"));
    assert_eq!(frame, "os1_lidar");
    let ouster_model = SensorModel::vlp32c().with_axes(Axes::new(Axis::NegX, Axis::PosZ).unwrap());
    clouds.push((
        "Ouster OS1-64 (pointcloudset MCAP)".into(),
        ouster,
        ouster_model,
    ));

    let entries: Vec<_> = of_modality(Modality::Lidar).collect();
    assert!(entries.len() >= 31);
    let failures: Vec<String> = clouds
        .par_iter()
        .flat_map_iter(|(name, cloud, sensor)| {
            let view = cloud.view();
            let layout = view.layout();
            let [rx, ry, rz] = layout.xyz_readers().unwrap();
            let ri = layout.reader_any(names::INTENSITY);
            let finite_in = (0..view.len()).all(|i| {
                let p = view.point(i);
                [rx, ry, rz].iter().all(|r| r.read_f64(p).is_finite())
            });
            // Ouster reports photon counts (up to about 850 here), beyond any model's 0..255:
            // there the bound is the input's own maximum (nothing may brighten a return).
            let in_max = ri.map_or(0.0, |r| {
                (0..view.len())
                    .map(|i| r.read_f64(view.point(i)))
                    .fold(0.0, f64::max)
            });
            let full = sensor.intensity_max as f64;
            let bound = full.max(in_max);
            let mut bad = Vec::new();
            for e in &entries {
                for s in 1..=3u8 {
                    let mut p = LidarPerturber::new(e.id, s, 11, sensor.clone()).unwrap();
                    let out = p.apply_owned(&view, 3, None).unwrap();
                    let ov = out.view();
                    for i in 0..ov.len() {
                        let q = ov.point(i);
                        if finite_in && ![rx, ry, rz].iter().all(|r| r.read_f64(q).is_finite()) {
                            bad.push(format!("{name}: {} s{s}: point {i} not finite", e.id));
                            break;
                        }
                        if let Some(r) = ri {
                            let v = r.read_f64(q);
                            if !(0.0..=bound).contains(&v) {
                                bad.push(format!(
                                    "{name}: {} s{s}: intensity {v} outside [0, {bound}]",
                                    e.id
                                ));
                                break;
                            }
                        }
                    }
                }
            }
            eprintln!(
                "{name}: {} points, intensity full scale {full}, input max {in_max}",
                view.len()
            );
            bad
        })
        .collect();
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

#[test]
fn real_clouds_in_the_wrong_format_are_not_read_silently() {
    let Some(data) = common::shared_data("real_clouds_in_the_wrong_format_are_not_read_silently")
    else {
        return;
    };
    // A real KITTI scan raises no doubt.
    let bytes = std::fs::read(data.join("kitti/velodyne/000000.bin")).expect("read KITTI scan");
    assert_eq!(kitti::kitti_doubts(&bytes), Vec::<String>::new());
    let scan = kitti::decode_kitti(&bytes).unwrap();
    // The same scan as a nuScenes .pcd.bin (five floats, HDL-32E rings): 115 384 points of 20
    // bytes are also a whole number of 16-byte KITTI points, and reading them as KITTI warns.
    let nus = nuscenes_like(&scan, &SensorModel::nuscenes());
    let nus_bytes = nus.view().data().to_vec();
    assert_eq!(nus_bytes.len() % 16, 0);
    let doubts = kitti::kitti_doubts(&nus_bytes);
    assert!(
        doubts.len() == 1 && doubts[0].contains("nuScenes"),
        "{doubts:?}"
    );
    // One point fewer: a multiple of 20 bytes but not of 16 is an error that names nuScenes.
    let err = kitti::decode_kitti(&nus_bytes[..nus_bytes.len() - 20])
        .unwrap_err()
        .to_string();
    assert!(err.contains("nuScenes"), "{err}");
    // A real VLP-16 PCD (binary, 32-byte points) with one more point than POINTS announces.
    let pcd_path = data.join("rosbag2_nebula/vlp16/1673400472138016708.pcd");
    let mut pcd_bytes = std::fs::read(&pcd_path).expect("read nebula PCD");
    assert!(pcd::decode(&pcd_bytes).is_ok());
    let last: Vec<u8> = pcd_bytes[pcd_bytes.len() - 32..].to_vec();
    pcd_bytes.extend_from_slice(&last);
    let Err(err) = pcd::decode(&pcd_bytes) else {
        panic!("a PCD with one point more than POINTS was read without an error");
    };
    eprintln!("{err}");
}
