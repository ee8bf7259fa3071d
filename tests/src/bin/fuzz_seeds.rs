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

/// The corpus being written: CORPUS/<target>/<name> files, counted.
struct Corpus<'a> {
    dir: &'a Path,
    written: usize,
}

impl Corpus<'_> {
    fn seed(&mut self, target: &str, name: &str, bytes: &[u8]) {
        let d = self.dir.join(target);
        std::fs::create_dir_all(&d).expect("corpus folder");
        std::fs::write(d.join(name), bytes).expect("seed file");
        self.written += 1;
    }
}

/// A sensor message cut down: (type tag, type name, CDR bytes, ROS 1 bytes); the tag is the
/// `ros_msgs` target's (0..=2 CDR, +3 the same type in ROS 1).
type Message = (u8, String, Vec<u8>, Vec<u8>);

/// The sensor messages of every bag in DATA, cut down.
fn messages(data: &Path) -> Vec<Message> {
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
    let mut out = Corpus {
        dir: corpus,
        written: 0,
    };
    images(data, &mut out);
    pcds(data, &mut out);
    kitti_scans(data, &mut out);
    let msgs = messages(data);
    for (i, (tag, _, cdr, ros1)) in msgs.iter().enumerate() {
        for (t, bytes) in [(*tag, cdr), (*tag + 3, ros1)] {
            let mut v = vec![t];
            v.extend_from_slice(bytes);
            out.seed("ros_msgs", &format!("msg{i}_{t}"), &v);
        }
    }
    let tmp = corpus.join("bags.tmp");
    small_mcap_bags(&msgs, &tmp, &mut out);
    small_ros1_bags(&msgs, &tmp, &mut out);
    let _ = std::fs::remove_dir_all(&tmp);
    real_bag_heads(data, &mut out);
    configs(repo, &mut out);
    println!("{} seed files in {}", out.written, corpus.display());
}

/// Every PNG in DATA, whole (`image`).
fn images(data: &Path, out: &mut Corpus) {
    let mut pngs = Vec::new();
    files(data, ".png", &mut pngs);
    for (i, p) in pngs.iter().enumerate() {
        out.seed("image", &format!("png{i}"), &std::fs::read(p).expect("png"));
    }
}

/// Every PCD in DATA (`pcd`), with an ASCII and a compressed copy of its first points, to reach
/// every data encoding.
fn pcds(data: &Path, out: &mut Corpus) {
    use perturb_core::formats::pcd::{PcdData, decode, encode};
    let mut pcds = Vec::new();
    files(data, ".pcd", &mut pcds);
    for (i, p) in pcds.iter().enumerate() {
        let b = std::fs::read(p).expect("pcd");
        out.seed("pcd", &format!("pcd{i}"), &b);
        let Ok(f) = decode(&b) else { continue };
        let v = f.cloud.view();
        let k = v.len().min(POINTS as usize);
        let step = v.layout().point_step as usize;
        let small = perturb_core::cloud::CloudView::new(
            v.layout_arc().clone(),
            &v.data()[..k * step],
            k as u32,
            1,
            k * step,
            true,
        )
        .expect("a prefix of a valid cloud");
        for (tag, d) in [
            ("ascii", PcdData::Ascii),
            ("lzf", PcdData::BinaryCompressed),
        ] {
            if let Ok(e) = encode(&small, d, f.viewpoint) {
                out.seed("pcd", &format!("pcd{i}_{tag}"), &e);
            }
        }
    }
}

/// The first points of every KITTI `.bin` scan in DATA (`kitti`).
fn kitti_scans(data: &Path, out: &mut Corpus) {
    let mut bins = Vec::new();
    files(data, ".bin", &mut bins);
    for (i, p) in bins.iter().enumerate() {
        let b = std::fs::read(p).expect("bin");
        let k = (b.len() / 16).min(POINTS as usize) * 16;
        out.seed("kitti", &format!("bin{i}"), &b[..k]);
    }
}

/// Small MCAP bags holding the real messages, one per chunk compression (`mcap`), written under
/// `tmp`.
fn small_mcap_bags(msgs: &[Message], tmp: &Path, out: &mut Corpus) {
    for (i, c) in [Compression::Zstd, Compression::Lz4, Compression::None]
        .into_iter()
        .enumerate()
    {
        let dir = tmp.join(format!("b{i}"));
        let _ = std::fs::remove_dir_all(&dir);
        let options = WriterOptions {
            compression: c,
            chunk_size: 4 << 10,
            ..Default::default()
        };
        let mut w = BagWriter::create(&dir, &options).expect("a bag writer");
        for (k, (_, ty, bytes, _)) in msgs.iter().enumerate() {
            if let Ok(t) = w.add_topic(&format!("/t{k}"), ty) {
                let _ = w.write(t, k as u64, k as u64, bytes);
            }
        }
        let Ok(path) = w.finish() else { continue };
        let mut mcaps = Vec::new();
        files(&path, ".mcap", &mut mcaps);
        for m in mcaps {
            let bytes = std::fs::read(m).expect("bag");
            out.seed("mcap", &format!("small{i}"), &bytes);
        }
    }
}

/// The same messages in small ROS 1 bags, one per chunk compression (`ros1bag`), written under
/// `tmp`. A few messages of each type keep a bag small (tens of kilobytes), so the fuzzer runs it
/// many times a second.
fn small_ros1_bags(msgs: &[Message], tmp: &Path, out: &mut Corpus) {
    let compressions = [
        Ros1Compression::None,
        Ros1Compression::Bz2,
        Ros1Compression::Lz4,
    ];
    for (i, c) in compressions.into_iter().enumerate() {
        let _ = std::fs::create_dir_all(tmp);
        let path = tmp.join(format!("r{i}.bag"));
        let _ = std::fs::remove_file(&path);
        let options = Ros1WriterOptions {
            compression: c,
            chunk_size: 4 << 10,
        };
        let mut w = Ros1Writer::create(&path, &options).expect("a ROS 1 bag writer");
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
            let bytes = std::fs::read(p).expect("bag");
            out.seed("ros1bag", &format!("small{i}"), &bytes);
        }
    }
}

/// The real MCAP bags in DATA cut to their first 64 KiB: header, schemas and first chunk (`mcap`).
fn real_bag_heads(data: &Path, out: &mut Corpus) {
    let mut bags = Vec::new();
    files(data, ".mcap", &mut bags);
    for (i, p) in bags.iter().enumerate() {
        let b = std::fs::read(p).expect("mcap");
        out.seed("mcap", &format!("real{i}"), &b[..b.len().min(64 << 10)]);
    }
}

/// The example configurations in REPO/config (`config`), each behind a byte saying whether it is
/// a bridge's (1) or the daemon's (0).
fn configs(repo: &Path, out: &mut Corpus) {
    let mut tomls = Vec::new();
    files(&repo.join("config"), ".toml", &mut tomls);
    for (i, p) in tomls.iter().enumerate() {
        let text = std::fs::read(p).expect("toml");
        let bridge = p
            .file_name()
            .is_some_and(|f| f.to_string_lossy().starts_with("bridge"));
        let mut v = vec![bridge as u8];
        v.extend_from_slice(&text);
        out.seed("config", &format!("toml{i}"), &v);
    }
}
