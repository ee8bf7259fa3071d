//! The LiDAR weather models on real data: physics behaviour and the calibration of the
//! lightweight approximations.

mod common;

use perturb_core::lidar::Points;
use perturb_core::lidar::weather::fast::{FAST_CALIBRATION, FastKind, FastWeather};
use perturb_core::lidar::weather::fog::{
    FogModel, FogOutcome, HAHNER_ALPHA, MULTICORRUPT_ALPHA_BETA,
};
use perturb_core::lidar::weather::lisa::{Lisa, Outcome};
use perturb_core::perturber::LidarPerturber;
use perturb_core::rng::Rng;
use perturb_core::sensors::SensorModel;

/// The physics counterpart's retention caused by the weather: the share of the points the model
/// returns from their surface in clear weather that it still returns at each severity, measured on
/// `points`. (LISA's detection floor drops returns with near-zero reflectance even in clear air,
/// about 10% of KITTI's points; that loss is not the weather's and is factored out.)
fn physics_retention(kind: FastKind, points: &Points, sensor: &SensorModel) -> [f64; 3] {
    let p_min = 0.9 / (120.0f64 * 120.0);
    let clear = match kind {
        FastKind::Fog => points.len(),
        _ => (0..points.len())
            .filter(|&i| {
                let r = points.range(i) as f64;
                r <= 0.9 || (points.intensity(i) / points.intensity_max) as f64 / (r * r) >= p_min
            })
            .count(),
    };
    std::array::from_fn(|lvl| {
        let sev = lvl as u8 + 1;
        let n = clear as f64;
        let mut rng = Rng::for_setup(1, 7);
        let kept = match kind {
            FastKind::Fog => {
                let (alpha, beta) = MULTICORRUPT_ALPHA_BETA[lvl];
                let m = FogModel::multicorrupt(alpha, beta);
                (0..points.len())
                    .filter(|&i| {
                        let i255 = points.intensity(i) as f64 / points.intensity_max as f64 * 255.0;
                        matches!(
                            m.simulate(points.range(i) as f64, i255, &mut rng),
                            FogOutcome::Attenuated(_)
                        )
                    })
                    .count()
            }
            FastKind::Rain | FastKind::Snow => {
                let id = if kind == FastKind::Rain {
                    "L-A5"
                } else {
                    "L-A1"
                };
                let setup = perturb_core::lidar::LidarSetup {
                    severity: sev,
                    seed: 1,
                    sensor: sensor.clone(),
                };
                let lisa = lisa_of(id, &setup);
                (0..points.len())
                    .filter(|&i| {
                        let inten = (points.intensity(i) / points.intensity_max) as f64;
                        matches!(
                            lisa.simulate(points.range(i) as f64, inten, &mut rng),
                            Outcome::Kept { .. }
                        )
                    })
                    .count()
            }
        };
        kept as f64 / n
    })
}

fn lisa_of(id: &str, setup: &perturb_core::lidar::LidarSetup) -> Lisa {
    use perturb_core::lidar::weather::lisa::Precipitation;
    Lisa::new(
        if id == "L-A5" {
            Precipitation::Rain
        } else {
            Precipitation::Snow
        },
        setup,
    )
}

#[test]
#[ignore = "prints the calibration of the lightweight models; run with --ignored --nocapture"]
fn calibrate_fast_models() {
    let Some(scan) = common::kitti_scan("calibrate_fast_models", 0) else {
        return;
    };
    let sensor = SensorModel::hdl64e();
    let pts = Points::extract(&scan.view(), &sensor, false).unwrap();
    for kind in [FastKind::Snow, FastKind::Rain, FastKind::Fog] {
        let phys = physics_retention(kind, &pts, &sensor);
        let row: Vec<String> = phys
            .iter()
            .map(|&target| {
                let a = FastWeather::fit_alpha(kind, &pts, target);
                format!(
                    "({a:.6}, {target:.4}, {:.4})",
                    FastWeather::new(kind, a).expected_retention(&pts)
                )
            })
            .collect();
        println!("(FastKind::{kind:?}, [{}]),", row.join(", "));
    }
}

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

#[test]
fn fast_retention_tracks_physics() {
    let Some(scan) = common::kitti_scan("fast_retention_tracks_physics", 0) else {
        return;
    };
    let sensor = SensorModel::hdl64e();
    let pts = Points::extract(&scan.view(), &sensor, false).unwrap();
    for (kind, table) in FAST_CALIBRATION {
        let phys = physics_retention(kind, &pts, &sensor);
        for lvl in 0..3 {
            let (alpha, recorded, _) = table[lvl];
            let fast = FastWeather::new(kind, alpha).expected_retention(&pts);
            assert!(
                (phys[lvl] - recorded).abs() < 0.02,
                "{kind:?} s{}: physics retention {} drifted from the recorded {recorded}",
                lvl + 1,
                phys[lvl]
            );
            assert!(
                (fast - phys[lvl]).abs() < 0.02,
                "{kind:?} s{}: fast {fast} vs physics {}",
                lvl + 1,
                phys[lvl]
            );
            // And the perturbation really keeps about that share of the points.
            let id = match kind {
                FastKind::Snow => "L-A4",
                FastKind::Rain => "L-A6",
                FastKind::Fog => "L-A9",
            };
            let out = LidarPerturber::new(id, lvl as u8 + 1, 5, sensor.clone())
                .unwrap()
                .apply_owned(&scan.view(), 0, None)
                .unwrap();
            let op = Points::extract(&out.view(), &sensor, false).unwrap();
            let original: std::collections::HashSet<(u32, u32, u32)> = (0..pts.len())
                .map(|i| (pts.x[i].to_bits(), pts.y[i].to_bits(), pts.z[i].to_bits()))
                .collect();
            let kept = (0..op.len())
                .filter(|&i| {
                    original.contains(&(op.x[i].to_bits(), op.y[i].to_bits(), op.z[i].to_bits()))
                })
                .count();
            let measured = kept as f64 / pts.len() as f64;
            assert!(
                (measured - fast).abs() < 0.01,
                "{id} s{}: measured {measured} vs expected {fast}",
                lvl + 1
            );
        }
    }
}

#[test]
fn fog_fast_survival_follows_exp_minus_alpha_d() {
    use perturb_core::cloud::{Cloud, PointLayout};
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
    let alpha = FAST_CALIBRATION
        .iter()
        .find(|(k, _)| *k == FastKind::Fog)
        .unwrap()
        .1[2]
        .0;
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
