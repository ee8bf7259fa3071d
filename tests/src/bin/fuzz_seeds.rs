//! `perturb-fuzz-seeds DATA CORPUS REPO`: builds the seed corpus of the fuzz targets in
//! `tests/fuzz` (see `tests/fuzz/run`) at run time, from the real recordings in DATA (`../shared/data`) and the example configurations in REPO/config,
//! into CORPUS/<target>/. Large inputs are cut down to what a fuzzer can mutate quickly (a few
//! rows of an image, a few hundred points of a cloud, a small bag rewritten from the real one's
//! messages) so the corpus stays a few hundred kilobytes. Nothing here is committed.

use perturb_bag::ros1::{Ros1Compression, Ros1Writer, Ros1WriterOptions};
use perturb_bag::{Bag, BagWriter, Compression, Filter, SensorMessage, WriterOptions};
use perturb_core::formats::ros::{ImageMsg, PointCloud2Msg};
use std::ops::ControlFlow;
use std::path::{Path, PathBuf};

/// Rows kept of an image, points kept of a cloud.
const ROWS: u32 = 6;
const POINTS: u32 = 300;

fn files(dir: &Path, ext: &str, out: &mut Vec<PathBuf>) {
    let Ok(rd) = std::fs::read_dir(dir) else {
        return;
    };
    for e in rd.flatten() {
        let p = e.path();
        if p.is_dir() {
            files(&p, ext, out);
        } else if p.to_string_lossy().ends_with(ext) {
            out.push(p);
        }
    }
}

fn put(corpus: &Path, target: &str, name: &str, bytes: &[u8]) {
    let d = corpus.join(target);
    std::fs::create_dir_all(&d).expect("corpus folder");
    std::fs::write(d.join(name), bytes).expect("seed file");
}

/// The sensor messages of every bag in DATA, cut down: (type tag, type name, CDR bytes, ROS 1
/// bytes); the tag is the `ros_msgs` target's (0..=2 CDR, +3 the same type in ROS 1).
fn messages(data: &Path) -> Vec<(u8, String, Vec<u8>, Vec<u8>)> {
    let mut bags = Vec::new();
    files(data, ".mcap", &mut bags);
    files(data, ".bag", &mut bags);
    let mut out = Vec::new();
    for b in bags {
        let Ok(bag) = Bag::open(&b) else { continue };
        let _ = bag.for_each(&Filter::default(), |m| {
            match m.decode() {
                Some(Ok(SensorMessage::Image(i))) => {
                    let rows = i.height.min(ROWS);
                    let n = (rows as usize * i.step as usize).min(i.data.len());
                    let small = ImageMsg {
                        height: rows,
                        data: &i.data[..n],
                        ..i
                    };
                    out.push((
                        0,
                        m.type_name.to_string(),
                        small.encode(),
                        small.encode_ros1(1),
                    ));
                }
                Some(Ok(SensorMessage::Compressed(c))) => {
                    out.push((1, m.type_name.to_string(), c.encode(), c.encode_ros1(1)));
                }
                Some(Ok(SensorMessage::Cloud(c))) => {
                    let w = c.width.min(POINTS);
                    let n = (w as usize * c.point_step as usize).min(c.data.len());
                    let small = PointCloud2Msg {
                        height: 1,
                        width: w,
                        row_step: w * c.point_step,
                        data: &c.data[..n],
                        ..c.clone()
                    };
                    out.push((
                        2,
                        m.type_name.to_string(),
                        small.encode(),
                        small.encode_ros1(1),
                    ));
                }
                _ => {}
            }
            Ok(ControlFlow::Continue(()))
        });
    }
    out
}

fn main() {
    let args: Vec<PathBuf> = std::env::args_os().skip(1).map(PathBuf::from).collect();
    let [data, corpus, repo] = args.as_slice() else {
        eprintln!("usage: perturb-fuzz-seeds DATA CORPUS REPO");
        std::process::exit(2);
    };
    let mut n = 0;
    let mut seed = |target: &str, name: &str, bytes: &[u8]| {
        put(corpus, target, name, bytes);
        n += 1;
    };
    let mut pngs = Vec::new();
    files(data, ".png", &mut pngs);
    for (i, p) in pngs.iter().enumerate() {
        seed("image", &format!("png{i}"), &std::fs::read(p).expect("png"));
    }
    let mut pcds = Vec::new();
    files(data, ".pcd", &mut pcds);
    for (i, p) in pcds.iter().enumerate() {
        let b = std::fs::read(p).expect("pcd");
        seed("pcd", &format!("pcd{i}"), &b);
        // An ASCII and a compressed copy of the first points, to reach every data encoding.
        if let Ok(f) = perturb_core::formats::pcd::decode(&b) {
            let v = f.cloud.view();
            let k = v.len().min(POINTS as usize);
            let small = perturb_core::cloud::CloudView::new(
                v.layout_arc().clone(),
                &v.data()[..k * v.layout().point_step as usize],
                k as u32,
                1,
                k * v.layout().point_step as usize,
                true,
            )
            .expect("a prefix of a valid cloud");
            for (tag, d) in [
                ("ascii", perturb_core::formats::pcd::PcdData::Ascii),
                ("lzf", perturb_core::formats::pcd::PcdData::BinaryCompressed),
            ] {
                if let Ok(e) = perturb_core::formats::pcd::encode(&small, d, f.viewpoint) {
                    seed("pcd", &format!("pcd{i}_{tag}"), &e);
                }
            }
        }
    }
    let mut bins = Vec::new();
    files(data, ".bin", &mut bins);
    for (i, p) in bins.iter().enumerate() {
        let b = std::fs::read(p).expect("bin");
        let k = (b.len() / 16).min(POINTS as usize) * 16;
        seed("kitti", &format!("bin{i}"), &b[..k]);
    }
    let msgs = messages(data);
    for (i, (tag, _, cdr, ros1)) in msgs.iter().enumerate() {
        for (t, bytes) in [(*tag, cdr), (*tag + 3, ros1)] {
            let mut v = vec![t];
            v.extend_from_slice(bytes);
            seed("ros_msgs", &format!("msg{i}_{t}"), &v);
        }
    }
    // Small bags holding the real messages, one per chunk compression, plus the real bags cut
    // to their first 64 KiB (their header, schemas and first chunk).
    let tmp = corpus.join("bags.tmp");
    for (i, c) in [Compression::Zstd, Compression::Lz4, Compression::None]
        .into_iter()
        .enumerate()
    {
        let dir = tmp.join(format!("b{i}"));
        let _ = std::fs::remove_dir_all(&dir);
        let mut w = BagWriter::create(
            &dir,
            &WriterOptions {
                compression: c,
                chunk_size: 4 << 10,
            },
        )
        .expect("a bag writer");
        for (k, (_, ty, bytes, _)) in msgs.iter().enumerate() {
            if let Ok(t) = w.add_topic(&format!("/t{k}"), ty) {
                let _ = w.write(t, k as u64, k as u64, bytes);
            }
        }
        if let Ok(path) = w.finish() {
            let mut mcaps = Vec::new();
            files(&path, ".mcap", &mut mcaps);
            for m in mcaps {
                seed(
                    "mcap",
                    &format!("small{i}"),
                    &std::fs::read(m).expect("bag"),
                );
            }
        }
    }
    // The same messages in small ROS 1 bags, one per chunk compression.
    for (i, c) in [
        Ros1Compression::None,
        Ros1Compression::Bz2,
        Ros1Compression::Lz4,
    ]
    .into_iter()
    .enumerate()
    {
        let _ = std::fs::create_dir_all(&tmp);
        let path = tmp.join(format!("r{i}.bag"));
        let _ = std::fs::remove_file(&path);
        let mut w = Ros1Writer::create(
            &path,
            &Ros1WriterOptions {
                compression: c,
                chunk_size: 4 << 10,
            },
        )
        .expect("a ROS 1 bag writer");
        // A few messages of each type keep the bag small (tens of kilobytes), so the fuzzer
        // runs it many times a second.
        let mut per_type = [0usize; 3];
        for (k, (tag, ty, _, bytes)) in msgs.iter().enumerate() {
            let n = &mut per_type[*tag as usize];
            if *n >= 2 {
                continue;
            }
            *n += 1;
            if let Ok(t) = w.add_topic(&format!("/t{k}"), ty) {
                let _ = w.write(t, 1 + k as u64, bytes);
            }
        }
        if let Ok(p) = w.finish() {
            seed(
                "ros1bag",
                &format!("small{i}"),
                &std::fs::read(p).expect("bag"),
            );
        }
    }
    let _ = std::fs::remove_dir_all(&tmp);
    let mut bags = Vec::new();
    files(data, ".mcap", &mut bags);
    for (i, p) in bags.iter().enumerate() {
        let b = std::fs::read(p).expect("mcap");
        seed("mcap", &format!("real{i}"), &b[..b.len().min(64 << 10)]);
    }
    let mut tomls = Vec::new();
    files(&repo.join("config"), ".toml", &mut tomls);
    for (i, p) in tomls.iter().enumerate() {
        let text = std::fs::read(p).expect("toml");
        let bridge = p
            .file_name()
            .is_some_and(|f| f.to_string_lossy().starts_with("bridge"));
        let mut v = vec![bridge as u8];
        v.extend_from_slice(&text);
        seed("config", &format!("toml{i}"), &v);
    }
    println!("{n} seed files in {}", corpus.display());
}
