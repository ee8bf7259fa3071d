//! Reference-specific properties of the object-level LiDAR perturbations (L-D local, L-E affine,
//! L-F2 moving object, L-F3 ghost points) with given boxes and with the built-in detector's boxes,
//! and of beam reduction on a 32-beam cloud with a ring field.

#![allow(clippy::needless_range_loop)] // parallel arrays indexed by point

mod common;

use perturb_core::cloud::{Cloud, Datatype, PointField, PointLayout};
use perturb_core::detector::{Detector, DetectorConfig};
use perturb_core::lidar::{Box3, Points};
use perturb_core::perturber::LidarPerturber;
use perturb_core::rng::Rng;
use perturb_core::sensor_model::SensorModel;

/// x, y, z, intensity (float32) and a uint32 tag holding the input index of each point.
fn tagged_layout() -> PointLayout {
    PointLayout::new(
        vec![
            PointField::new("x", 0, Datatype::Float32),
            PointField::new("y", 4, Datatype::Float32),
            PointField::new("z", 8, Datatype::Float32),
            PointField::new("intensity", 12, Datatype::Float32),
            PointField::new("tag", 16, Datatype::Uint32),
        ],
        20,
        false,
    )
    .unwrap()
}

fn boxes() -> Vec<Box3> {
    vec![
        Box3 {
            center: [10.0, 3.0, -1.0],
            size: [4.2, 1.8, 1.5],
            yaw: 0.0,
        },
        Box3 {
            center: [15.0, -5.0, -1.1],
            size: [4.5, 2.0, 1.4],
            yaw: 0.6,
        },
        Box3 {
            center: [-8.0, 6.0, -0.9],
            size: [0.8, 0.7, 1.7],
            yaw: -1.2,
        },
    ]
}

/// Ground points everywhere plus points filling each box, with intensity and a tag.
fn scene() -> Cloud {
    let mut rng = Rng::for_setup(5, 5);
    let mut pts = Vec::new();
    for i in 0..120 {
        for j in 0..120 {
            pts.push([i as f32 * 0.5 - 30.0, j as f32 * 0.5 - 30.0, -1.75, 20.0]);
        }
    }
    for b in boxes() {
        let (s, c) = b.yaw.sin_cos();
        for _ in 0..1500 {
            let u = (rng.f32() - 0.5) * b.size[0];
            let v = (rng.f32() - 0.5) * b.size[1];
            let w = (rng.f32() - 0.5) * b.size[2];
            pts.push([
                b.center[0] + u * c - v * s,
                b.center[1] + u * s + v * c,
                b.center[2] + w,
                50.0 + 200.0 * rng.f32(),
            ]);
        }
    }
    let layout = tagged_layout();
    let mut cloud = Cloud::from_xyzi(&layout, &pts);
    let tag = layout.reader("tag").unwrap();
    for (i, p) in cloud.data.chunks_exact_mut(20).enumerate() {
        tag.write_f64(p, i as f64);
    }
    cloud
}

fn run(id: &str, sev: u8, cloud: &Cloud, seq: u64, b: Option<&[Box3]>) -> Cloud {
    LidarPerturber::new(id, sev, 11, SensorModel::vlp32c())
        .unwrap()
        .apply_owned(&cloud.view(), seq, b)
        .unwrap()
}

fn pts(c: &Cloud) -> Points {
    Points::extract(&c.view(), &SensorModel::vlp32c(), false).unwrap()
}

fn tags(c: &Cloud) -> Vec<usize> {
    let t = c.layout.reader("tag").unwrap();
    (0..c.len())
        .map(|k| t.read_f64(c.view().point(k)) as usize)
        .collect()
}

/// Index of the first box containing each input point (the perturbations' rule).
fn box_of(p: &Points, b: &[Box3]) -> Vec<Option<usize>> {
    (0..p.len())
        .map(|i| b.iter().position(|bx| bx.contains(p.xyz(i))))
        .collect()
}

/// Asserts that every point outside the boxes is in the output, byte-identical, in input order,
/// and returns, per output point, its source index.
fn outside_untouched(id: &str, input: &Cloud, out: &Cloud, inbox: &[Option<usize>]) -> Vec<usize> {
    let src = tags(out);
    let mut outside_seen = 0;
    let mut last = None;
    for (k, &i) in src.iter().enumerate() {
        if inbox[i].is_none() {
            assert_eq!(
                out.view().point(k),
                input.view().point(i),
                "{id}: out-of-box point {i} changed"
            );
            assert!(last < Some(i), "{id}: order changed");
            last = Some(i);
            outside_seen += 1;
        }
    }
    let outside = inbox.iter().filter(|b| b.is_none()).count();
    assert_eq!(outside_seen, outside, "{id}: out-of-box points lost");
    src
}

#[test]
fn local_perturbations_change_only_in_box_points() {
    let c = scene();
    let b = boxes();
    let p = pts(&c);
    let inbox = box_of(&p, &b);
    let per_box: Vec<usize> = (0..b.len())
        .map(|k| inbox.iter().filter(|v| **v == Some(k)).count())
        .collect();
    assert!(per_box.iter().all(|n| *n > 1000), "{per_box:?}");
    for id in [
        "L-D1", "L-D2", "L-D3", "L-D4", "L-D5", "L-E1", "L-E2", "L-E3", "L-F2", "L-F3",
    ] {
        for sev in 1..=3 {
            let out = run(id, sev, &c, 3, Some(&b));
            let src = outside_untouched(id, &c, &out, &inbox);
            assert!(
                src.iter().any(|&i| inbox[i].is_some()) || id == "L-D2",
                "{id}: some object point survives"
            );
        }
    }
}

#[test]
fn local_density_and_cutout_remove_exact_counts_and_fall_with_severity() {
    let c = scene();
    let b = boxes();
    let p = pts(&c);
    let inbox = box_of(&p, &b);
    let n_b: Vec<usize> = (0..b.len())
        .map(|k| inbox.iter().filter(|v| **v == Some(k)).count())
        .collect();
    for (id, fracs) in [("L-D1", [0.1, 0.3, 0.5]), ("L-D2", [0.3, 0.5, 0.7])] {
        let mut last = usize::MAX;
        for (s, f) in fracs.iter().enumerate() {
            let out = run(id, s as u8 + 1, &c, 1, Some(&b));
            let removed: usize = n_b.iter().map(|n| (f * *n as f64) as usize).sum();
            assert_eq!(out.len(), c.len() - removed, "{id} s{}", s + 1);
            assert!(out.len() < last);
            last = out.len();
        }
    }
    // Cutout removes a compact part of each object: the removed points of the first box lie
    // within a ball much smaller than the box around their centroid.
    let out = run("L-D2", 1, &c, 1, Some(&b));
    let kept: std::collections::HashSet<usize> = tags(&out).into_iter().collect();
    let gone: Vec<[f32; 3]> = (0..p.len())
        .filter(|i| inbox[*i] == Some(0) && !kept.contains(i))
        .map(|i| p.xyz(i))
        .collect();
    let m = gone
        .iter()
        .fold([0f32; 3], |a, q| [a[0] + q[0], a[1] + q[1], a[2] + q[2]]);
    let m = m.map(|v| v / gone.len() as f32);
    let spread = gone
        .iter()
        .map(|q| ((q[0] - m[0]).powi(2) + (q[1] - m[1]).powi(2) + (q[2] - m[2]).powi(2)).sqrt())
        .fold(0f32, f32::max);
    // 30 % of a uniformly filled 4.2 x 1.8 x 1.5 box, nearest to one point: far less than the
    // box's half diagonal (2.4 m) around its own centroid... and no deleted point is outside
    // the ball of the cut's radius around the seed, checked through the spread.
    assert!(spread < 2.0, "cutout spread {spread}");
}

#[test]
fn local_noise_statistics() {
    let c = scene();
    let b = boxes();
    let p = pts(&c);
    let inbox = box_of(&p, &b);
    let n_in = inbox.iter().filter(|v| v.is_some()).count();
    let deltas = |id: &str, sev: u8| {
        let o = pts(&run(id, sev, &c, 2, Some(&b)));
        (0..o.len())
            .filter(|i| inbox[*i].is_some())
            .map(|i| [o.x[i] - p.x[i], o.y[i] - p.y[i], o.z[i] - p.z[i]])
            .collect::<Vec<[f32; 3]>>()
    };
    for (sev, sigma) in [(1u8, 0.02f32), (2, 0.06), (3, 0.10)] {
        let d: Vec<f32> = deltas("L-D3", sev).into_iter().flatten().collect();
        let sd = (d.iter().map(|v| v * v).sum::<f32>() / d.len() as f32).sqrt();
        assert!((sd - sigma).abs() / sigma < 0.05, "L-D3 s{sev}: {sd}");
        let d: Vec<f32> = deltas("L-D4", sev).into_iter().flatten().collect();
        assert!(d.iter().all(|v| v.abs() <= sigma + 1e-5));
        let sd = (d.iter().map(|v| v * v).sum::<f32>() / d.len() as f32).sqrt();
        assert!(
            (sd - sigma / 3f32.sqrt()).abs() / sigma < 0.05,
            "L-D4 s{sev}: {sd}"
        );
    }
    for (sev, div) in [(1u8, 30usize), (2, 20), (3, 10)] {
        let d = deltas("L-D5", sev);
        let moved: Vec<&[f32; 3]> = d.iter().filter(|q| q.iter().any(|v| *v != 0.0)).collect();
        let n_b: Vec<usize> = (0..b.len())
            .map(|k| inbox.iter().filter(|v| **v == Some(k)).count())
            .collect();
        assert_eq!(moved.len(), n_b.iter().map(|n| n / div).sum::<usize>());
        assert!(
            moved
                .iter()
                .all(|q| q.iter().all(|v| (v.abs() - 0.1).abs() < 1e-5))
        );
        assert!(moved.len() < n_in / 5);
    }
}

/// True if `p` is inside `b` up to `tol` metres.
fn inside(b: &Box3, p: [f32; 3], tol: f32) -> bool {
    let grown = Box3 {
        size: b.size.map(|v| v + 2.0 * tol),
        ..*b
    };
    grown.contains(p)
}

#[test]
fn affine_perturbations_keep_points_in_their_box_and_move_them() {
    let c = scene();
    let b = boxes();
    let p = pts(&c);
    let inbox = box_of(&p, &b);
    for id in ["L-E1", "L-E2", "L-E3"] {
        for sev in 1..=3u8 {
            let mut moved_any = false;
            for seq in 0..4 {
                let o = pts(&run(id, sev, &c, seq, Some(&b)));
                assert_eq!(o.len(), p.len());
                for i in 0..p.len() {
                    if let Some(k) = inbox[i] {
                        assert!(
                            inside(&b[k], o.xyz(i), 1e-4),
                            "{id} s{sev}: point {i} left box {k}: {:?}",
                            o.xyz(i)
                        );
                        moved_any |= o.xyz(i) != p.xyz(i);
                    }
                }
            }
            assert!(moved_any, "{id} s{sev} moved nothing");
        }
    }
    // Rotation: the in-box points of the long box turn by about c degrees (levels 1, 3, 5 =
    // 1, 5, 9 degrees): the principal direction of the footprint changes by that much.
    let axis = |q: &Points, k: usize| {
        let idx: Vec<usize> = (0..p.len()).filter(|i| inbox[*i] == Some(k)).collect();
        let n = idx.len() as f64;
        let mx = idx.iter().map(|&i| q.x[i] as f64).sum::<f64>() / n;
        let my = idx.iter().map(|&i| q.y[i] as f64).sum::<f64>() / n;
        let (mut sxx, mut syy, mut sxy) = (0.0, 0.0, 0.0);
        for &i in &idx {
            let (dx, dy) = (q.x[i] as f64 - mx, q.y[i] as f64 - my);
            sxx += dx * dx;
            syy += dy * dy;
            sxy += dx * dy;
        }
        0.5 * (2.0 * sxy).atan2(sxx - syy)
    };
    for (sev, deg) in [(1u8, 1.0f64), (3, 9.0)] {
        let o = pts(&run("L-E3", sev, &c, 0, Some(&b)));
        let turn = (axis(&o, 0) - axis(&p, 0)).to_degrees().abs();
        eprintln!("rotation s{sev}: principal axis turned {turn:.2} deg");
        // normalize_gt narrows the object along the box axes, which turns the principal axis
        // back a little: between half and all of the drawn angle (c +- 1 degree).
        assert!(
            turn > 0.3 * (deg - 1.0).max(0.5) && turn < deg + 1.0,
            "s{sev}: {turn}"
        );
    }
}

#[test]
fn moving_object_shifts_along_the_heading() {
    let c = scene();
    let b = boxes();
    let p = pts(&c);
    let inbox = box_of(&p, &b);
    for (sev, shift) in [(1u8, 0.2f32), (2, 0.6), (3, 1.0)] {
        let o = pts(&run("L-F2", sev, &c, 0, Some(&b)));
        let mut counts = [0usize; 3];
        for i in 0..p.len() {
            let Some(k) = inbox[i] else { continue };
            let (s, co) = b[k].yaw.sin_cos();
            let d = [o.x[i] - p.x[i], o.y[i] - p.y[i], o.z[i] - p.z[i]];
            let along = d[0] * co + d[1] * s;
            let across = -d[0] * s + d[1] * co;
            assert!(
                across.abs() < 1e-4 && d[2] == 0.0,
                "s{sev}: off-heading shift {d:?}"
            );
            let class = [0.0, shift / 2.0, shift]
                .iter()
                .position(|v| (along - v).abs() < 1e-4)
                .unwrap_or_else(|| panic!("s{sev}: shift {along}"));
            counts[class] += 1;
        }
        // About a third of each object moves by c/2, two thirds by c, one point stays per box.
        let total: usize = counts.iter().sum();
        assert!(counts[0] >= b.len() && counts[0] < 10, "{counts:?}");
        assert!(
            (counts[1] as f64 / total as f64 - 1.0 / 3.0).abs() < 0.05,
            "{counts:?}"
        );
    }
}

#[test]
fn ghost_points_count_position_and_intensity() {
    let c = scene();
    let b = boxes();
    let p = pts(&c);
    let inbox = box_of(&p, &b);
    let n_in = inbox.iter().filter(|v| v.is_some()).count();
    for (sev, copies, spacing) in [(1u8, 1usize, 0.5f32), (2, 2, 0.75), (3, 3, 1.0)] {
        let mut pert = LidarPerturber::new("L-F3", sev, 1, SensorModel::vlp32c()).unwrap();
        let out = pert.apply_owned(&c.view(), 0, Some(&b)).unwrap();
        assert_eq!(out.len(), c.len() + copies * n_in, "s{sev}");
        assert!(pert.max_output_bytes(&c.view()) >= out.data.len());
        let o = pts(&out);
        let src = tags(&out);
        // The originals come first, unchanged.
        assert_eq!(&out.data[..c.data.len()], &c.data[..]);
        let mut per_copy = vec![0usize; copies + 1];
        for k in c.len()..out.len() {
            let i = src[k];
            let bx = &b[inbox[i].expect("ghosts come from object points")];
            let (s, co) = bx.yaw.sin_cos();
            let d = [o.x[k] - p.x[i], o.y[k] - p.y[i], o.z[k] - p.z[i]];
            let along = -(d[0] * co + d[1] * s);
            let j = (along / spacing).round() as usize;
            assert!(j >= 1 && j <= copies && (along - j as f32 * spacing).abs() < 1e-4);
            assert!((-d[0] * s + d[1] * co).abs() < 1e-4 && d[2] == 0.0);
            let want = p.intensity(i) * 0.5f32.powi(j as i32);
            assert!(
                (o.intensity(k) - want).abs() < 1e-4,
                "intensity {} vs {want}",
                o.intensity(k)
            );
            per_copy[j] += 1;
        }
        assert!(per_copy[1..].iter().all(|n| *n == n_in), "{per_copy:?}");
    }
}

#[test]
fn detector_boxes_are_used_when_none_are_given() {
    let Some(scan) = common::kitti_scan("detector_boxes_are_used_when_none_are_given", 0) else {
        return;
    };
    let sensor = SensorModel::hdl64e();
    let p = Points::extract(&scan.view(), &sensor, false).unwrap();
    // The perturbations use every box of the default configuration (every class).
    let boxes = Detector::new(DetectorConfig::default()).detect(&p);
    assert!(boxes.len() > 20);
    let inbox = box_of(&p, &boxes);
    for id in ["L-D3", "L-E1", "L-E3", "L-F2"] {
        let mut pert = LidarPerturber::new(id, 3, 5, sensor.clone()).unwrap();
        let auto = pert.apply_owned(&scan.view(), 9, None).unwrap();
        assert_eq!(
            pert.last_boxes(),
            &boxes[..],
            "{id}: boxes from the unperturbed cloud"
        );
        let given = pert.apply_owned(&scan.view(), 9, Some(&boxes)).unwrap();
        assert_eq!(auto, given, "{id}");
        let o = Points::extract(&auto.view(), &sensor, false).unwrap();
        let mut changed = 0;
        for i in 0..p.len() {
            if o.xyz(i) != p.xyz(i) {
                assert!(inbox[i].is_some(), "{id}: out-of-box point {i} moved");
                changed += 1;
            }
            if id.starts_with("L-E")
                && let Some(k) = inbox[i]
            {
                assert!(
                    inside(&boxes[k], o.xyz(i), 1e-4),
                    "{id}: point {i} left its box"
                );
            }
        }
        assert!(changed > 1000, "{id}: {changed} points changed");
    }
}

#[test]
fn beam_reduction_keeps_the_multicorrupt_rings_of_a_32_beam_cloud() {
    // A VLP-32C-like cloud with a ring field: 32 rings x 100 points.
    let layout = PointLayout::xyzir();
    let mut pts = Vec::new();
    for ring in 0..32 {
        for a in 0..100 {
            let az = a as f32 * 0.0628;
            pts.push([10.0 * az.cos(), 10.0 * az.sin(), -1.0, ring as f32]);
        }
    }
    let mut c = Cloud::from_xyzi(&layout, &pts);
    let r = layout.reader("ring").unwrap();
    for (i, p) in c.data.chunks_exact_mut(18).enumerate() {
        r.write_f64(p, (i / 100) as f64);
    }
    let lists: [&[u16]; 3] = [
        &[1, 3, 5, 7, 9, 11, 13, 15, 17, 19, 21, 23, 25, 27, 29, 31],
        &[1, 5, 9, 13, 17, 21, 25, 29],
        &[1, 9, 17, 25],
    ];
    for (s, list) in lists.iter().enumerate() {
        let out = LidarPerturber::new("L-B3", s as u8 + 1, 0, SensorModel::vlp32c())
            .unwrap()
            .apply_owned(&c.view(), 0, None)
            .unwrap();
        let rings: std::collections::BTreeSet<u16> = (0..out.len())
            .map(|k| r.read_f64(out.view().point(k)) as u16)
            .collect();
        assert_eq!(rings.into_iter().collect::<Vec<_>>(), list.to_vec());
        assert_eq!(out.len(), 100 * list.len());
    }
}
