//! Every camera perturbation at every severity, on the real KITTI frame scaled to
//! 800x503 and 1920x1208, single-threaded, plus the two-thread figure at 1920x1208.
//!
//! `cargo bench -p perturb-benches --bench camera -- C-A1` runs one perturbation.

use criterion::{Criterion, criterion_group, criterion_main};
use perturb_benches::{kitti_frame, single_thread};
use perturb_core::image::Image;
use perturb_core::perturber::CameraPerturber;
use perturb_core::registry::{Modality, of_modality};
use std::time::Duration;

fn bench(c: &mut Criterion) {
    let one = single_thread();
    let two = rayon::ThreadPoolBuilder::new()
        .num_threads(2)
        .build()
        .expect("pool");
    for (w, h) in [(800u32, 503u32), (1920, 1208)] {
        let Some(frame) = kitti_frame(w, h) else {
            return;
        };
        let mut group = c.benchmark_group(format!("camera_{w}x{h}"));
        group
            .sample_size(10)
            .warm_up_time(Duration::from_millis(300))
            .measurement_time(Duration::from_secs(1));
        for e in of_modality(Modality::Camera) {
            for s in e.severities() {
                let mut p = CameraPerturber::new(e.id, s, 1).expect("configure");
                let mut out = Image::with_geometry(frame.geometry());
                p.prepare(frame.geometry()).expect("prepare");
                let mut seq = 0u64;
                group.bench_function(format!("{}_{}/s{s}/1t", e.id, e.name), |b| {
                    b.iter(|| {
                        seq += 1;
                        one.install(|| p.apply(&frame.view(), &mut out.view_mut(), seq))
                            .expect("apply")
                    })
                });
                if w == 1920 {
                    group.bench_function(format!("{}_{}/s{s}/2t", e.id, e.name), |b| {
                        b.iter(|| {
                            seq += 1;
                            two.install(|| p.apply(&frame.view(), &mut out.view_mut(), seq))
                                .expect("apply")
                        })
                    });
                }
            }
        }
        group.finish();
    }
}

criterion_group!(benches, bench);
criterion_main!(benches);
