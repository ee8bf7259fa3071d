//! Every LiDAR perturbation at every severity on the real KITTI scan (about 115k
//! points) and on a VLP-32C-sized cloud (about 58k points), single-threaded. Object-level
//! perturbations run the detector on every cloud, as the daemon does.
//!
//! `cargo bench -p perturb-benches --bench lidar -- L-A9` runs one perturbation.

use criterion::{Criterion, criterion_group, criterion_main};
use perturb_benches::{kitti_scan, single_thread, vlp32c_sized_scan};
use perturb_core::perturber::LidarPerturber;
use perturb_core::registry::{Modality, of_modality};
use perturb_core::sensor_model::SensorModel;
use std::time::Duration;

fn bench(c: &mut Criterion) {
    let one = single_thread();
    for (label, cloud) in [
        ("kitti_120k", kitti_scan()),
        ("vlp32c_58k", vlp32c_sized_scan()),
    ] {
        let Some(cloud) = cloud else { return };
        let view = cloud.view();
        let mut group = c.benchmark_group(format!("lidar_{label}"));
        group
            .sample_size(10)
            .warm_up_time(Duration::from_millis(300))
            .measurement_time(Duration::from_secs(1));
        for e in of_modality(Modality::Lidar) {
            for s in e.severities() {
                // KITTI stores reflectance in 0..1: the HDL-64E model says so explicitly.
                let mut p =
                    LidarPerturber::new(e.id, s, 1, SensorModel::hdl64e()).expect("configure");
                let mut out = vec![0u8; p.max_output_bytes(&view)];
                let mut seq = 0u64;
                group.bench_function(format!("{}_{}/s{s}", e.id, e.name), |b| {
                    b.iter(|| {
                        seq += 1;
                        one.install(|| p.apply(&view, &mut out, seq, None))
                            .expect("apply")
                    })
                });
            }
        }
        group.finish();
    }
}

criterion_group!(benches, bench);
criterion_main!(benches);
