//! The LiDAR weather models on real data: physics behaviour and the calibration of the
//! lightweight approximations.

mod common;

use perturb_core::cloud::Cloud;
use perturb_core::detector::{Detector, DetectorConfig};
use perturb_core::formats::kitti;
use perturb_core::lidar::weather::fast::{FastKind, FastWeather, visibility};
use perturb_core::lidar::weather::fog::{FogModel, FogOutcome, HAHNER_ALPHA};
use perturb_core::lidar::weather::lisa::{Lisa, Outcome};
use perturb_core::lidar::{Box3, Points};
use perturb_core::metrics::{DetectionMetrics, MatchConfig, detection_metrics};
use perturb_core::perturber::LidarPerturber;
use perturb_core::rng::Rng;
use perturb_core::sensor_model::SensorModel;

#[test]
#[ignore = "prints how much of KITTI 000000 the Hahner fog (L-A7) returns from its surface"]
fn hahner_fog_retention_on_kitti() {
    let Some(scan) = common::kitti_scan("hahner_fog_retention_on_kitti", 0) else {
        return;
    };
    let pts = Points::extract(&scan.view(), &SensorModel::hdl64e(), false).unwrap();
    let mut rng = Rng::for_setup(1, 7);
    for lvl in [0usize, 2, 4] {
        let m = FogModel::hahner(HAHNER_ALPHA[lvl]);
        let kept = (0..pts.len())
            .filter(|&i| {
                matches!(
                    m.simulate(
                        pts.range(i) as f64,
                        pts.intensity(i) as f64 * 255.0,
                        &mut rng
                    ),
                    FogOutcome::Attenuated(_)
                )
            })
            .count();
        println!(
            "L-A7 alpha {}: retention {:.4}",
            HAHNER_ALPHA[lvl],
            kept as f64 / pts.len() as f64
        );
    }
}

/// The shared KITTI scans (000000, 000001: full HDL-64E scans; 000008: camera view only).
fn kitti_scans(data: &std::path::Path) -> Vec<(&'static str, Cloud)> {
    [
        ("000000", "kitti/velodyne/000000.bin"),
        ("000001", "kitti/velodyne/000001.bin"),
        ("000008", "kitti_000008_mmdet3d/000008_velodyne_reduced.bin"),
    ]
    .into_iter()
    .map(|(name, f)| {
        let bytes = std::fs::read(data.join(f)).expect("read KITTI scan");
        (
            name,
            kitti::decode_kitti(&bytes).expect("decode KITTI scan"),
        )
    })
    .collect()
}

#[test]
fn fast_models_remove_the_expected_share_of_a_real_scan() {
    let Some(scan) = common::kitti_scan("fast_models_remove_the_expected_share_of_a_real_scan", 0)
    else {
        return;
    };
    let sensor = SensorModel::hdl64e();
    let pts = Points::extract(&scan.view(), &sensor, false).unwrap();
    let original: std::collections::HashSet<(u32, u32, u32)> = (0..pts.len())
        .map(|i| (pts.x[i].to_bits(), pts.y[i].to_bits(), pts.z[i].to_bits()))
        .collect();
    for (kind, id) in [
        (FastKind::Snow, "L-A4"),
        (FastKind::Rain, "L-A6"),
        (FastKind::Fog, "L-A9"),
    ] {
        let mut last = 1.0;
        for lvl in 0..3 {
            let alpha = FastWeather::for_severity(kind, lvl).alpha;
            let expected = FastWeather::new(kind, alpha).expected_retention(&pts);
            let out = LidarPerturber::new(id, lvl as u8 + 1, 5, sensor.clone())
                .unwrap()
                .apply_owned(&scan.view(), 0, None)
                .unwrap();
            let op = Points::extract(&out.view(), &sensor, false).unwrap();
            // Survivors keep their exact position; backscatter returns move in front of the target.
            let kept = (0..op.len())
                .filter(|&i| {
                    original.contains(&(op.x[i].to_bits(), op.y[i].to_bits(), op.z[i].to_bits()))
                })
                .count();
            let measured = kept as f64 / pts.len() as f64;
            eprintln!(
                "{id} s{}: {} {}, alpha {alpha:.5}/m, points kept {measured:.4} (expected {expected:.4})",
                lvl + 1,
                kind.quantity(),
                visibility(kind, lvl)
            );
            assert!(
                (measured - expected).abs() < 0.01,
                "{id} s{}: measured {measured} vs expected {expected}",
                lvl + 1
            );
            assert!(measured < last, "{id}: retention must fall with severity");
            last = measured;
        }
    }
}

#[test]
fn fog_fast_survival_follows_exp_minus_alpha_d() {
    use perturb_core::cloud::PointLayout;
    // 20 000 points at each of 10 ranges; the highest severity's alpha.
    let ranges = [
        5.0f32, 10.0, 20.0, 30.0, 40.0, 60.0, 80.0, 100.0, 120.0, 150.0,
    ];
    let pts: Vec<[f32; 4]> = ranges
        .iter()
        .flat_map(|&r| {
            (0..20_000).map(move |k| {
                let a = k as f32 * 0.0003;
                [r * a.cos(), r * a.sin(), 0.0, 0.5]
            })
        })
        .collect();
    let cloud = Cloud::from_xyzi(&PointLayout::xyzi_f32(), &pts);
    let sensor = SensorModel::hdl64e();
    let p = LidarPerturber::new("L-A9", 3, 11, sensor.clone()).unwrap();
    let alpha = FastWeather::for_severity(FastKind::Fog, 2).alpha;
    let mut p = p;
    let out = p.apply_owned(&cloud.view(), 0, None).unwrap();
    let o = Points::extract(&out.view(), &sensor, false).unwrap();
    let orig = Points::extract(&cloud.view(), &sensor, false).unwrap();
    let survivors: std::collections::HashSet<(u32, u32)> = (0..o.len())
        .map(|i| (o.x[i].to_bits(), o.y[i].to_bits()))
        .collect();
    for (b, &r) in ranges.iter().enumerate() {
        // Survivors keep their exact position; backscatter returns move in front of the target.
        let kept = (b * 20_000..(b + 1) * 20_000)
            .filter(|&i| survivors.contains(&(orig.x[i].to_bits(), orig.y[i].to_bits())))
            .count() as f64
            / 20_000.0;
        let want = (-alpha * r as f64).exp();
        assert!(
            (kept - want).abs() < 0.01,
            "range {r}: survival {kept} vs exp(-alpha d) = {want}"
        );
    }
    let near = (0..o.len())
        .filter(|&i| o.range(i) >= 2.0 && o.range(i) <= 7.0)
        .count();
    assert!(near > 1000, "backscatter returns in the near field: {near}");
}

#[test]
fn lisa_returns_follow_the_model() {
    use perturb_core::lidar::LidarSetup;
    use perturb_core::lidar::weather::lisa::Precipitation;
    let setup = LidarSetup {
        severity: 3,
        seed: 2,
        sensor: SensorModel::vlp32c(),
    };
    let lisa = Lisa::new(Precipitation::Snow, &setup);
    let m = *lisa.medium();
    let rho_max = (m.fresnel / (0.9 / (120.0f64 * 120.0))).sqrt();
    let mut rng = Rng::for_setup(3, 3);
    let (mut scattered, mut kept) = (0, 0);
    for k in 0..20_000 {
        let r = 2.0 + (k % 100) as f64; // 2..101 m
        match lisa.simulate(r, 0.3, &mut rng) {
            Outcome::Scattered { range, .. } => {
                scattered += 1;
                assert!(
                    range <= rho_max + 1e-9 && range < r,
                    "no particle return beyond rho_max = {rho_max}"
                );
            }
            Outcome::Kept { intensity, .. } => {
                kept += 1;
                assert!(
                    (intensity - 0.3 * (-2.0 * m.alpha * r).exp()).abs() < 1e-12,
                    "two-way attenuation"
                );
            }
            Outcome::Lost => {}
        }
    }
    assert!(
        kept > scattered && scattered > 0,
        "kept {kept}, scattered {scattered}"
    );
}

/// Detection retention of `id` at severities 1..3 over `scans`, averaged over `seeds`
/// (pooled over the scans per seed, as `perturb metrics lidar` pools them).
fn mean_retention(id: &str, scans: &[(&str, Cloud, Vec<Box3>)], seeds: &[u64]) -> [f64; 3] {
    use rayon::prelude::*;
    let sensor = SensorModel::hdl64e();
    let runs: Vec<(usize, f64)> = (0..3usize)
        .flat_map(|lvl| seeds.iter().map(move |&s| (lvl, s)))
        .collect::<Vec<_>>()
        .into_par_iter()
        .map(|(lvl, seed)| {
            let mut det = Detector::new(DetectorConfig::default());
            let mut total = DetectionMetrics {
                retention: 1.0,
                ..DetectionMetrics::default()
            };
            let mut p = LidarPerturber::new(id, lvl as u8 + 1, seed, sensor.clone()).unwrap();
            for (seq, (_, cloud, base)) in scans.iter().enumerate() {
                let out = p.apply_owned(&cloud.view(), seq as u64, None).unwrap();
                let pts = Points::extract(&out.view(), &sensor, false).unwrap();
                total.add(&detection_metrics(
                    base,
                    &det.detect(&pts),
                    &MatchConfig::default(),
                ));
            }
            (lvl, total.retention)
        })
        .collect();
    std::array::from_fn(|lvl| {
        let v: Vec<f64> = runs.iter().filter(|r| r.0 == lvl).map(|r| r.1).collect();
        v.iter().sum::<f64>() / v.len() as f64
    })
}

#[test]
fn every_weather_model_answers_its_severity_and_fast_ones_degrade_more() {
    // Issue 33: the physics rain and snow's retention stayed flat within +-0.03 and moved up and
    // down with the seed. Detection retention (every box the detector finds on the clean scan,
    // matched within 2 m on the perturbed one, pooled over the shared KITTI scans, as `perturb
    // metrics lidar` computes it), averaged over seeds 0..4, must not rise from severity 1 to 3;
    // and from one severity to the next, except where the model's reference says why it
    // does not (docs/lidar.md, "Weather and severity"): L-A1's light snow has more (small)
    // flakes than its heavy snow (Marshall-Gunn), L-A3's flake count falls as the rate rises
    // (Hahner's sampling, LiDAR_snow_sim issue 26), L-A5's extinction grows by 8e-4 / m from s2
    // to s3. The lightweight models degrade detection more than their physics counterparts at
    // every severity (the paper's RQ1 ranking).
    let Some(data) =
        common::shared_data("every_weather_model_answers_its_severity_and_fast_ones_degrade_more")
    else {
        return;
    };
    let sensor = SensorModel::hdl64e();
    let mut det = Detector::new(DetectorConfig::default());
    let scans: Vec<(&str, Cloud, Vec<Box3>)> = kitti_scans(&data)
        .into_iter()
        .map(|(name, c)| {
            let boxes = det.detect(&Points::extract(&c.view(), &sensor, false).unwrap());
            (name, c, boxes)
        })
        .collect();
    let seeds = [0, 1, 2, 3, 4];
    let fmt = |r: &[f64; 3]| format!("{:.3} / {:.3} / {:.3}", r[0], r[1], r[2]);
    let ids = [
        "L-A1", "L-A2", "L-A3", "L-A4", "L-A5", "L-A6", "L-A7", "L-A8", "L-A9", "L-A10",
    ];
    let table: std::collections::BTreeMap<&str, [f64; 3]> = ids
        .iter()
        .map(|&id| (id, mean_retention(id, &scans, &seeds)))
        .collect();
    let mut failures = Vec::new();
    for (&id, r) in &table {
        eprintln!("| {id} | {} |", fmt(r));
        if r[2] > r[0] {
            failures.push(format!("{id}: retention rises from s1 to s3: {}", fmt(r)));
        }
        let explained = matches!(id, "L-A1" | "L-A3" | "L-A5");
        if !explained && (r[1] > r[0] || r[2] > r[1]) {
            failures.push(format!("{id}: retention is not monotonic: {}", fmt(r)));
        }
    }
    for (fast, physics) in [
        ("L-A4", &["L-A1"][..]),
        ("L-A6", &["L-A5"][..]),
        ("L-A9", &["L-A7", "L-A8"][..]),
    ] {
        let f = table[fast];
        if !(f[0] > f[1] && f[1] > f[2]) {
            failures.push(format!(
                "{fast} does not fall strictly with severity: {}",
                fmt(&f)
            ));
        }
        for ph in physics {
            let r = table[ph];
            for l in 0..3 {
                if f[l] >= r[l] {
                    failures.push(format!(
                        "{fast} s{}: retention {:.3} not below {ph}'s {:.3}",
                        l + 1,
                        f[l],
                        r[l]
                    ));
                }
            }
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

#[test]
fn hahner_snow_drops_beams_without_a_return() {
    // Issue 33: L-A2 and L-A3 kept beams with no return as zero-intensity points at exactly
    // 0.10 m from the sensor (35-403 per KITTI frame). No flake closer than LISA's and Hahner's
    // 0.9 m blind zone returns anything, so no output point may lie nearer than the nearest
    // input point.
    let Some(data) = common::shared_data("hahner_snow_drops_beams_without_a_return") else {
        return;
    };
    let sensor = SensorModel::hdl64e();
    for (name, scan) in kitti_scans(&data) {
        let input = Points::extract(&scan.view(), &sensor, false).unwrap();
        let nearest_in = (0..input.len())
            .map(|i| input.range(i))
            .fold(f32::INFINITY, f32::min);
        for id in ["L-A2", "L-A3"] {
            for severity in 1..=3 {
                let mut p = LidarPerturber::new(id, severity, 3, sensor.clone()).unwrap();
                let out = p.apply_owned(&scan.view(), 0, None).unwrap();
                let o = Points::extract(&out.view(), &sensor, false).unwrap();
                let too_near = (0..o.len())
                    .filter(|&i| o.range(i) < nearest_in.min(0.9))
                    .count();
                assert_eq!(
                    too_near, 0,
                    "{name} {id} s{severity}: {too_near} points nearer than any input point"
                );
            }
        }
    }
}
