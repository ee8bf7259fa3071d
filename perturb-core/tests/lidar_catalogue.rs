//! Properties every LiDAR perturbation must have, at every severity: determinism,
//! layout preserved in odd layouts (unaligned, big-endian, float64), untouched fields passed through,
//! empty and single-point clouds, and a change on a real KITTI scan.

#[macro_use]
mod common;

use perturb_core::cloud::{Cloud, CloudView, Datatype, PointField, PointLayout};
use perturb_core::lidar::Box3;
use perturb_core::perturber::LidarPerturber;
use perturb_core::registry::{Entry, Modality};

use perturb_core::rng::Rng;
use perturb_core::sensor_model::SensorModel;

/// A point layout as awkward as real drivers make them: big-endian, unaligned, a float64 z, a
/// uint16 ring and a float64 time at offset 18 of a 26-byte point... plus a uint8 intensity.
fn odd_layout() -> PointLayout {
    PointLayout::new(
        vec![
            PointField::new("x", 0, Datatype::Float32),
            PointField::new("y", 4, Datatype::Float32),
            PointField::new("z", 8, Datatype::Float32),
            PointField::new("intensity", 12, Datatype::Uint8),
            PointField::new("ring", 13, Datatype::Uint16),
            PointField::new("pad", 15, Datatype::Uint8),
            PointField::new("tag", 16, Datatype::Uint16),
            PointField::new("time", 18, Datatype::Float64),
        ],
        26,
        true,
    )
    .unwrap()
}

/// A street-like synthetic scan: ground rings, a wall, and two car-sized blocks, with ring and time.
fn synthetic_scan(layout: &PointLayout, n_az: usize) -> Cloud {
    let sensor = SensorModel::vlp32c();
    let mut pts = Vec::new();
    let mut rings = Vec::new();
    let mut rng = Rng::for_setup(1, 1);
    for (ring, elev) in sensor.elevations_deg.iter().enumerate() {
        for a in 0..n_az {
            let az = a as f32 / n_az as f32 * std::f32::consts::TAU;
            let dir = [
                elev.to_radians().cos() * az.cos(),
                elev.to_radians().cos() * az.sin(),
                elev.to_radians().sin(),
            ];
            // Ground at z = -1.9, a wall at x = 30, blocks at (8, 3) and (12, -4).
            let mut t = if dir[2] < -1e-3 { 1.9 / -dir[2] } else { 60.0 };
            if dir[0] > 1e-3 {
                t = t.min(30.0 / dir[0]);
            }
            for (cx, cy) in [(8.0f32, 3.0f32), (12.0, -4.0)] {
                let tt = cx / dir[0].max(1e-3) - 1.0;
                if tt > 0.0 && tt < t {
                    let (px, py, pz) = (dir[0] * tt, dir[1] * tt, dir[2] * tt);
                    if (px - cx).abs() < 2.0 && (py - cy).abs() < 0.9 && pz > -1.9 && pz < -0.4 {
                        t = tt;
                    }
                }
            }
            if t < 60.0 {
                pts.push([
                    dir[0] * t,
                    dir[1] * t,
                    dir[2] * t,
                    10.0 + (rng.f32() * 200.0).round(),
                ]);
                rings.push(ring as f64);
            }
        }
    }
    let mut c = Cloud::from_xyzi(layout, &pts);
    let step = layout.point_step as usize;
    let ring = layout.reader("ring");
    let time = layout.reader_any(&["time", "t"]);
    let tag = layout.reader("tag");
    for (i, p) in c.data.chunks_exact_mut(step).enumerate() {
        if let Some(r) = ring {
            r.write_f64(p, rings[i]);
        }
        if let Some(t) = time {
            t.write_f64(p, i as f64 * 1e-6);
        }
        if let Some(t) = tag {
            t.write_f64(p, (i % 60000) as f64);
        }
    }
    c
}

fn boxes() -> Vec<Box3> {
    vec![
        Box3 {
            center: [8.0, 3.0, -1.15],
            size: [4.0, 1.8, 1.5],
            yaw: 0.0,
        },
        Box3 {
            center: [12.0, -4.0, -1.15],
            size: [4.0, 1.8, 1.5],
            yaw: 0.0,
        },
    ]
}

fn apply(p: &mut LidarPerturber, c: &CloudView<'_>, seq: u64) -> Cloud {
    let b = boxes();
    p.apply_owned(c, seq, Some(&b))
        .unwrap_or_else(|e| panic!("{}: {e}", p.spec().entry.id))
}

fn deterministic_layout_preserving_and_passing_fields_through(e: &Entry) {
    let layout = odd_layout();
    let cloud = synthetic_scan(&layout, 360);
    let view = cloud.view();
    let one = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .unwrap();
    let two = rayon::ThreadPoolBuilder::new()
        .num_threads(2)
        .build()
        .unwrap();
    let tag = layout.reader("tag").unwrap();
    let time = layout.reader("time").unwrap();
    for s in e.severities() {
        let mut p = LidarPerturber::new(e.id, s, 99, SensorModel::vlp32c()).unwrap();
        let a = one.install(|| apply(&mut p, &view, 4));
        let b = two.install(|| apply(&mut p, &view, 4));
        assert_eq!(
            a, b,
            "{} s{s}: output depends on thread count or call history",
            e.id
        );
        assert_eq!(*a.layout, layout, "{} s{s}: layout changed", e.id);
        assert!(
            p.max_output_bytes(&view) >= a.data.len(),
            "{} s{s}: max_output_bytes is not an upper bound",
            e.id
        );
        // Every output point's untouched fields come from one input point.
        for k in 0..a.len() {
            let q = a.view().point(k);
            let i = tag.read_f64(q) as usize;
            assert!(i < cloud.len(), "{} s{s}: tag field corrupted", e.id);
            let t = time.read_f64(q);
            assert!(
                (t - i as f64 * 1e-6).abs() < 1e-12,
                "{} s{s}: time field does not travel with its point",
                e.id
            );
        }
    }
}

fn empty_and_single_point_clouds(e: &Entry) {
    let layout = odd_layout();
    let empty = Cloud::zeroed(std::sync::Arc::new(layout.clone()), 0);
    let single = Cloud::from_xyzi(&layout, &[[5.0, 1.0, -1.0, 40.0]]);
    for s in e.severities() {
        let mut p = LidarPerturber::new(e.id, s, 1, SensorModel::vlp32c()).unwrap();
        let out = apply(&mut p, &empty.view(), 0);
        assert_eq!(*out.layout, layout);
        let out = apply(&mut p, &single.view(), 0);
        assert!(
            out.len() <= p.max_output_bytes(&single.view()) / 26,
            "{} s{s}",
            e.id
        );
    }
}

fn changes_a_real_kitti_scan_at_every_severity(e: &Entry) {
    let Some(scan) = common::kitti_scan("changes_a_real_kitti_scan_at_every_severity", 0) else {
        return;
    };
    let view = scan.view();
    let sensor = SensorModel::hdl64e();
    for s in e.severities() {
        let mut p = LidarPerturber::new(e.id, s, 7, sensor.clone()).unwrap();
        let boxes = boxes();
        // Some perturbations act on a random subset of clouds (L-F4): one of 16 frames must change.
        let changed =
            (0..16).any(|seq| p.apply_owned(&view, seq, Some(&boxes)).unwrap().data != scan.data);
        assert!(changed, "{} s{s}: the scan is unchanged in 16 frames", e.id);
    }
}

per_entry! {
    Modality::Lidar,
    [
        deterministic_layout_preserving_and_passing_fields_through,
        empty_and_single_point_clouds,
        changes_a_real_kitti_scan_at_every_severity,
    ],
    {
        l_a1 => "L-A1",
        l_a2 => "L-A2",
        l_a3 => "L-A3",
        l_a4 => "L-A4",
        l_a5 => "L-A5",
        l_a6 => "L-A6",
        l_a7 => "L-A7",
        l_a8 => "L-A8",
        l_a9 => "L-A9",
        l_a10 => "L-A10",
        l_b1 => "L-B1",
        l_b2 => "L-B2",
        l_b3 => "L-B3",
        l_b4 => "L-B4",
        l_b5 => "L-B5",
        l_b6 => "L-B6",
        l_c1 => "L-C1",
        l_c2 => "L-C2",
        l_c3 => "L-C3",
        l_d1 => "L-D1",
        l_d2 => "L-D2",
        l_d3 => "L-D3",
        l_d4 => "L-D4",
        l_d5 => "L-D5",
        l_e1 => "L-E1",
        l_e2 => "L-E2",
        l_e3 => "L-E3",
        l_f1 => "L-F1",
        l_f2 => "L-F2",
        l_f3 => "L-F3",
        l_f4 => "L-F4",
    }
}
