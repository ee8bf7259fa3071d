//! Reference-specific properties of the sensor, noise and motion LiDAR perturbations, on real
//! KITTI scans where the property depends on real geometry.

mod common;

use perturb_core::cloud::{Cloud, PointLayout};
use perturb_core::lidar::Points;
use perturb_core::lidar::motion::MISALIGNMENT_LEVELS;
use perturb_core::perturber::LidarPerturber;
use perturb_core::sensor_model::SensorModel;

fn run(id: &str, s: u8, cloud: &Cloud, seq: u64, sensor: &SensorModel) -> Cloud {
    LidarPerturber::new(id, s, 3, sensor.clone())
        .unwrap()
        .apply_owned(&cloud.view(), seq, None)
        .unwrap()
}

fn pts(c: &Cloud, sensor: &SensorModel, ring: bool) -> Points {
    Points::extract(&c.view(), sensor, ring).unwrap()
}

/// A cloud of `n` points spread over a grid, with intensity.
fn grid(n: usize) -> Cloud {
    let p: Vec<[f32; 4]> = (0..n)
        .map(|i| {
            [
                (i % 100) as f32 * 0.5 + 2.0,
                (i / 100) as f32 * 0.5 - 20.0,
                -1.5,
                0.3,
            ]
        })
        .collect();
    Cloud::from_xyzi(&PointLayout::xyzi_f32(), &p)
}

#[test]
fn retention_counts_are_exact_and_fall_with_severity() {
    let c = grid(10_000);
    let s = SensorModel::hdl64e();
    let mut last = usize::MAX;
    for (sev, keep) in [(1u8, 3000usize), (2, 2000), (3, 1000)] {
        let n = run("L-B2", sev, &c, 0, &s).len();
        assert_eq!(n, keep, "L-B2 s{sev}");
        assert!(n < last);
        last = n;
    }
    for (sev, frac) in [(1u8, 0.06), (2, 0.18), (3, 0.30)] {
        assert_eq!(
            run("L-B1", sev, &c, 0, &s).len(),
            10_000 - (10_000.0 * frac) as usize,
            "L-B1 s{sev}"
        );
    }
    // Cutout: k holes of int(0.02 N) points each.
    for (sev, k) in [(1u8, 2usize), (2, 5), (3, 10)] {
        assert_eq!(
            run("L-B4", sev, &c, 0, &s).len(),
            10_000 - k * 200,
            "L-B4 s{sev}"
        );
    }
}

#[test]
fn cutout_removes_compact_patches() {
    let c = grid(10_000);
    let s = SensorModel::hdl64e();
    let out = pts(&run("L-B4", 1, &c, 5, &s), &s, false);
    let kept: std::collections::HashSet<(i64, i64)> = (0..out.len())
        .map(|i| {
            (
                (out.x[i] * 2.0).round() as i64,
                (out.y[i] * 2.0).round() as i64,
            )
        })
        .collect();
    let orig = pts(&c, &s, false);
    let gone: Vec<(f32, f32)> = (0..orig.len())
        .filter(|&i| {
            !kept.contains(&(
                (orig.x[i] * 2.0).round() as i64,
                (orig.y[i] * 2.0).round() as i64,
            ))
        })
        .map(|i| (orig.x[i], orig.y[i]))
        .collect();
    assert_eq!(gone.len(), 400);
    // Holes are compact: a removed point has removed neighbours (on this 0.5 m grid up to 12 within
    // 1 m). Random deletion of 4% of the points would leave about 0.5 removed neighbours per point.
    let crowded = gone
        .iter()
        .filter(|p| {
            gone.iter()
                .filter(|q| ((p.0 - q.0).powi(2) + (p.1 - q.1).powi(2)).sqrt() <= 1.01)
                .count()
                > 4
        })
        .count();
    assert!(
        crowded as f64 > 0.9 * gone.len() as f64,
        "{crowded} of 400 removed points sit in a patch"
    );
}

#[test]
fn beam_reduction_keeps_exactly_the_configured_rings() {
    let Some(scan) = common::kitti_scan("beam_reduction_keeps_exactly_the_configured_rings", 0)
    else {
        return;
    };
    let s = SensorModel::hdl64e();
    let before = pts(&scan, &s, true);
    let rings_before: std::collections::BTreeSet<u16> =
        before.ring.as_ref().unwrap().iter().copied().collect();
    assert!(
        rings_before.len() > 50,
        "derived rings cover the sensor: {}",
        rings_before.len()
    );
    for (sev, step) in [(1u8, 2u16), (2, 4), (3, 8)] {
        let out = run("L-B3", sev, &scan, 0, &s);
        let after = pts(&out, &s, true);
        let rings: std::collections::BTreeSet<u16> =
            after.ring.as_ref().unwrap().iter().copied().collect();
        assert!(rings.iter().all(|r| r % step == 1), "s{sev}: {rings:?}");
        let expected = before
            .ring
            .as_ref()
            .unwrap()
            .iter()
            .filter(|r| *r % step == 1)
            .count();
        assert_eq!(out.len(), expected, "s{sev}");
    }
}

#[test]
fn noise_statistics_match_the_parameters() {
    let c = grid(40_000);
    let s = SensorModel::vlp32c();
    let orig = pts(&c, &s, false);
    let deltas = |id: &str, sev: u8| {
        let o = pts(&run(id, sev, &c, 1, &s), &s, false);
        (0..o.len())
            .flat_map(|i| [o.x[i] - orig.x[i], o.y[i] - orig.y[i], o.z[i] - orig.z[i]])
            .collect::<Vec<f32>>()
    };
    for (sev, sigma) in [(1u8, 0.02f32), (2, 0.06), (3, 0.10)] {
        let d = deltas("L-C1", sev);
        let sd = (d.iter().map(|v| v * v).sum::<f32>() / d.len() as f32).sqrt();
        assert!((sd - sigma).abs() / sigma < 0.03, "L-C1 s{sev}: {sd}");
        let d = deltas("L-C2", sev);
        assert!(d.iter().all(|v| v.abs() <= sigma + 1e-5), "L-C2 bound");
        let sd = (d.iter().map(|v| v * v).sum::<f32>() / d.len() as f32).sqrt();
        assert!(
            (sd - sigma / 3f32.sqrt()).abs() / sigma < 0.03,
            "L-C2 s{sev}: {sd}"
        );
    }
    for (sev, div) in [(1u8, 30usize), (2, 20), (3, 10)] {
        let d = deltas("L-C3", sev);
        let moved = d
            .chunks(3)
            .filter(|p| p.iter().any(|v| v.abs() > 1e-6))
            .count();
        assert_eq!(moved, 40_000 / div, "L-C3 s{sev}");
        assert!(
            d.iter()
                .all(|v| v.abs() < 1e-6 || (v.abs() - 0.1).abs() < 1e-5)
        );
    }
    for (id, sev, frac, sigma) in [("L-B5", 3u8, 0.02, 3.0f32), ("L-A10", 2, 0.03, 2.0)] {
        let d = deltas(id, sev);
        let moved: Vec<&[f32]> = d
            .chunks(3)
            .filter(|p| p.iter().any(|v| v.abs() > 0.0))
            .collect();
        assert_eq!(moved.len(), (40_000.0 * frac) as usize, "{id}");
        let sd = (moved
            .iter()
            .flat_map(|p| p.iter())
            .map(|v| v * v)
            .sum::<f32>()
            / (3 * moved.len()) as f32)
            .sqrt();
        assert!((sd - sigma).abs() / sigma < 0.1, "{id}: {sd}");
    }
}

#[test]
fn motion_blur_is_a_global_shift_plus_small_jitter() {
    let c = grid(20_000);
    let s = SensorModel::vlp32c();
    let orig = pts(&c, &s, false);
    for (sev, scale) in [(1u8, 0.06f32), (3, 0.13)] {
        let o = pts(&run("L-F1", sev, &c, 2, &s), &s, false);
        let dx: Vec<f32> = (0..o.len()).map(|i| o.x[i] - orig.x[i]).collect();
        let mean = dx.iter().sum::<f32>() / dx.len() as f32;
        let sd = (dx.iter().map(|v| (v - mean).powi(2)).sum::<f32>() / dx.len() as f32).sqrt();
        assert!(
            (sd - 0.15 * scale).abs() / (0.15 * scale) < 0.05,
            "s{sev} jitter {sd}"
        );
        assert!(dx.iter().all(|v| (v - mean).abs() <= 3.0 * scale + 1e-4));
    }
}

#[test]
fn misalignment_is_the_reference_transform_on_a_fraction_of_the_clouds() {
    let c = grid(1_000);
    let s = SensorModel::vlp32c();
    let orig = pts(&c, &s, false);
    for (sev, (p, deg)) in MISALIGNMENT_LEVELS.iter().enumerate() {
        // MultiCorrupt's transform_points, written out: M = Rx Ry Rz with its own sign
        // convention, applied as xyz . M^T (so p' = M p), then + [2, 0, 0].
        let (s_, c_) = (deg.to_radians().sin(), deg.to_radians().cos());
        let rx = [[1.0, 0.0, 0.0], [0.0, c_, s_], [0.0, -s_, c_]];
        let ry = [[c_, 0.0, -s_], [0.0, 1.0, 0.0], [s_, 0.0, c_]];
        let rz = [[c_, s_, 0.0], [-s_, c_, 0.0], [0.0, 0.0, 1.0]];
        let mul = |a: [[f64; 3]; 3], b: [[f64; 3]; 3]| {
            let mut o = [[0.0f64; 3]; 3];
            for i in 0..3 {
                for j in 0..3 {
                    o[i][j] = (0..3).map(|k| a[i][k] * b[k][j]).sum();
                }
            }
            o
        };
        let r = mul(mul(rx, ry), rz).map(|row| row.map(|v| v as f32));
        let mut hits = 0;
        for seq in 0..400 {
            let out = run("L-F4", sev as u8 + 1, &c, seq, &s);
            if out.data == c.data {
                continue;
            }
            hits += 1;
            if hits > 3 {
                continue;
            }
            let o = pts(&out, &s, false);
            for i in (0..o.len()).step_by(97) {
                let q = orig.xyz(i);
                let want = [0, 1, 2]
                    .map(|k| r[k][0] * q[0] + r[k][1] * q[1] + r[k][2] * q[2] + [2.0, 0.0, 0.0][k]);
                assert!(
                    (0..3).all(|k| (o.xyz(i)[k] - want[k]).abs() < 1e-4),
                    "s{}",
                    sev + 1
                );
            }
        }
        let frac = hits as f64 / 400.0;
        assert!(
            (frac - p).abs() < 0.08,
            "s{}: {frac} of clouds misaligned, want {p}",
            sev + 1
        );
    }
}
