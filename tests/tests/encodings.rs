//! Camera encodings (perturb-core's encoding table) against their real peers:
//!
//! - OpenCV (the Python package `opencv-python-headless`, `cv2`): the working views of Bayer and
//!   YUV 4:2:2 frames made from a KITTI frame, compared with `cvtColor` and the codes cv_bridge
//!   uses for each encoding (the figures are printed; run with `--nocapture` to see them);
//! - perturbd through real processes and shared memory: a `bayer_rggb8`, a `yuv422`, a
//!   big-endian `mono16` and a `bayer_grbg16` frame come out in their own encoding, size, step and
//!   bytes equal to the library's and to `perturb apply` on a bag of the same frames; frames with
//!   an odd Bayer width or an unsupported encoding are counted as invalid (the unsupported
//!   encoding logged once) and the stream carries on.

use perturb_bag::{AnyWriter, Bag, BagFormat, Filter, SensorMessage};
use perturb_core::encoding::{EncodedView, Encoding, Scratch, from_image};
use perturb_core::formats::picture;
use perturb_core::formats::ros::{Header, ImageMsg};
use perturb_core::image::{Image, PixelFormat};
use perturb_core::perturber::CameraPerturber;
use perturb_tests::{Namespace, exe, shared_data};
use perturb_wire::{FrameHeader, Hop, Stamp, StreamQos, Transport};
use std::ops::ControlFlow;
use std::process::Command;
use std::time::Duration;

#[path = "../support/python_oracle.rs"]
mod python_oracle;
use python_oracle::python_oracle;

/// KITTI 000000 (1224x370) cut to an even height, rgb8; `None` (skipped) without the data.
fn kitti() -> Option<Image> {
    let p = shared_data("kitti/image_2/000000.png")?;
    let img = picture::decode(&std::fs::read(p).unwrap()).unwrap();
    let img = img.convert(PixelFormat::Rgb8);
    let h = img.height & !1;
    Some(
        Image::from_vec(
            img.data[..img.stride * h as usize].to_vec(),
            img.width,
            h,
            img.stride,
            PixelFormat::Rgb8,
        )
        .unwrap(),
    )
}

/// Mean and largest absolute difference of two byte strings, and how many bytes differ.
fn diff(a: &[u8], b: &[u8]) -> (f64, u8, usize) {
    assert_eq!(a.len(), b.len());
    let (mut sum, mut max, mut n) = (0u64, 0u8, 0usize);
    for (x, y) in a.iter().zip(b) {
        let d = x.abs_diff(*y);
        sum += d as u64;
        max = max.max(d);
        n += (d > 0) as usize;
    }
    (sum as f64 / a.len().max(1) as f64, max, n)
}

/// The pixels of an rgb8 image `w` wide without its one-pixel border.
fn interior(rgb: &[u8], w: usize, h: usize) -> Vec<u8> {
    (1..h - 1)
        .flat_map(|y| rgb[(y * w + 1) * 3..(y * w + w - 1) * 3].to_vec())
        .collect()
}

fn bgr_to_rgb(bgr: &[u8]) -> Vec<u8> {
    bgr.chunks_exact(3)
        .flat_map(|p| [p[2], p[1], p[0]])
        .collect()
}

#[test]
fn working_views_match_opencv_with_cv_bridges_codes_on_a_kitti_frame() {
    let Some(img) = kitti() else { return };
    let (w, h) = (img.width as usize, img.height as usize);
    let ns = Namespace::new("enc-opencv");
    let d = &ns.dir;
    std::fs::write(d.join("frame.rgb"), &img.data).unwrap();
    let tiles = ["rggb", "bggr", "gbrg", "grbg"];
    let mut mosaics = Vec::new();
    for t in tiles {
        let e = Encoding::find(&format!("bayer_{t}8")).unwrap();
        let m = from_image(&img.view(), e, w, false).unwrap();
        std::fs::write(d.join(format!("bayer_{t}8.raw")), &m).unwrap();
        mosaics.push((e, m));
    }
    // A 16-bit mosaic with detail below the 8-bit step: v16 = 257 v8 + a ripple of +-100.
    let m16: Vec<u16> = mosaics[0]
        .1
        .iter()
        .enumerate()
        .map(|(i, &v)| (v as i32 * 257 + ((i * 37) % 201) as i32 - 100).clamp(0, 65535) as u16)
        .collect();
    let m16_bytes: Vec<u8> = m16.iter().flat_map(|v| v.to_le_bytes()).collect();
    std::fs::write(d.join("bayer_rggb16.raw"), &m16_bytes).unwrap();
    let (ws, hs) = (w.to_string(), h.to_string());
    let Some(version) = python_oracle(
        "cv2, numpy",
        "pip install opencv-python-headless numpy",
        include_str!("encodings_opencv.py"),
        &[d.to_str().unwrap(), &ws, &hs],
    ) else {
        return;
    };
    let version = version.trim().to_string();
    let read = |name: &str| std::fs::read(d.join(name)).unwrap();
    let mut scratch = Scratch::new();

    // Bayer, 8 bit: bilinear demosaicking, the same bytes as OpenCV but on the one-pixel border.
    for ((e, m), t) in mosaics.iter().zip(tiles) {
        let v = EncodedView::new(m, w as u32, h as u32, w, e, false).unwrap();
        let mine = scratch.to_working(&v).data().to_vec();
        let cv = bgr_to_rgb(&read(&format!("cv_bayer_{t}8.bgr")));
        let all = diff(&mine, &cv);
        let inner = diff(&interior(&mine, w, h), &interior(&cv, w, h));
        let truth = diff(&mine, &img.data);
        eprintln!(
            "{e} vs OpenCV {version} {}: interior mean {:.4} max {} ({} bytes differ); whole frame mean {:.4} max {}; vs the KITTI frame mean {:.2}",
            e.opencv_to_bgr().unwrap(),
            inner.0,
            inner.1,
            inner.2,
            all.0,
            all.1,
            truth.0
        );
        assert_eq!(inner.1, 0, "{e}: the interior differs from OpenCV's");
        assert!(all.0 < 0.1, "{e}: border differences too large: {all:?}");
        // A wrong tile convention would mix red and blue: far from the true colours.
        assert!(truth.0 < 8.0, "{e}: {truth:?}");
    }
    // The same mosaic read with another pattern's code is far off (the comparison can fail).
    let wrong =
        EncodedView::new(&mosaics[0].1, w as u32, h as u32, w, mosaics[1].0, false).unwrap();
    let wrong = scratch.to_working(&wrong).data().to_vec();
    assert!(diff(&wrong, &img.data).0 > 15.0);

    // Bayer, 16 bit: OpenCV demosaics the 16-bit samples, the working view the 8-bit ones.
    let e16 = Encoding::find("bayer_rggb16").unwrap();
    let v = EncodedView::new(&m16_bytes, w as u32, h as u32, 2 * w, e16, false).unwrap();
    let mine = scratch.to_working(&v).data().to_vec();
    let cv16: Vec<u8> = read("cv_bayer_rggb16.bgr")
        .chunks_exact(2)
        .map(|b| ((u16::from_le_bytes([b[0], b[1]]) as u32 + 128) / 257) as u8)
        .collect();
    let cv = bgr_to_rgb(&cv16);
    let inner = diff(&interior(&mine, w, h), &interior(&cv, w, h));
    eprintln!(
        "{e16} vs OpenCV's 16-bit demosaic read at 8 bits: interior mean {:.4} max {} ({} of {} bytes differ)",
        inner.0,
        inner.1,
        inner.2,
        (w - 2) * (h - 2) * 3
    );
    assert!(inner.1 <= 1, "{e16}: {inner:?}");

    // YUV 4:2:2: decoding OpenCV's own YUV bytes gives OpenCV's RGB exactly; encoding the frame
    // (the write-back onto black) is compared with OpenCV's RGB2YUV.
    for (name, enc) in [("uyvy", "yuv422"), ("yuy2", "yuv422_yuy2")] {
        let e = Encoding::find(enc).unwrap();
        let yuv = read(&format!("cv_{name}.yuv"));
        let v = EncodedView::new(&yuv, w as u32, h as u32, 2 * w, e, false).unwrap();
        let mine = scratch.to_working(&v).data().to_vec();
        let cv = read(&format!("cv_{name}.rgb"));
        let dec = diff(&mine, &cv);
        let ours = from_image(&img.view(), e, 2 * w, false).unwrap();
        let enc_diff = diff(&ours, &yuv);
        eprintln!(
            "{e} vs OpenCV {version} {}: decoding mean {:.4} max {}; encoding vs RGB2YUV mean {:.4} max {} ({} of {} bytes differ)",
            e.opencv_to_bgr().unwrap(),
            dec.0,
            dec.1,
            enc_diff.0,
            enc_diff.1,
            enc_diff.2,
            yuv.len()
        );
        assert_eq!(dec.1, 0, "{e}: decoding differs from OpenCV's");
        assert!(enc_diff.1 <= 2 && enc_diff.0 < 0.5, "{e}: {enc_diff:?}");
    }
}

const ID: (&str, u8, u64) = ("C-A1", 3, 7);

/// A frame of the daemon test: (seq, encoding, step, is_bigendian, width, data).
type TestFrame = (u64, &'static str, usize, u8, u32, Vec<u8>);

/// The frames of the daemon test.
fn frames(img: &Image) -> Vec<TestFrame> {
    let w = img.width;
    let mono = img.convert(PixelFormat::Mono8);
    let make = |img: &Image, enc: &str, pad: usize, be: bool| {
        let e = Encoding::find(enc).unwrap();
        let step = e.row_bytes(w) + pad;
        (step, from_image(&img.view(), e, step, be).unwrap())
    };
    let (s0, bayer) = make(img, "bayer_rggb8", 6, false);
    let (s1, yuv) = make(img, "yuv422", 4, false);
    let (s2, mono16) = make(&mono, "mono16", 2, true);
    let (s6, grbg16) = make(img, "bayer_grbg16", 0, false);
    vec![
        (0, "bayer_rggb8", s0, 0, w, bayer.clone()),
        (1, "yuv422", s1, 0, w, yuv),
        (2, "mono16", s2, 1, w, mono16),
        // An odd Bayer width, then an encoding the table does not have (twice): invalid.
        (3, "bayer_rggb8", s0, 0, w - 1, bayer.clone()),
        (4, "nv21", s0, 0, w, bayer.clone()),
        (5, "nv21", s0, 0, w, bayer),
        (6, "bayer_grbg16", s6, 0, w, grbg16),
    ]
}

#[test]
fn bayer_yuv_and_big_endian_mono16_frames_come_out_of_perturbd_in_their_own_encoding() {
    let Some(img) = kitti() else { return };
    let h = img.height;
    let ns = Namespace::new("encodings");
    let cfg = ns.dir.join("perturbd.toml");
    std::fs::write(
        &cfg,
        format!(
            "[[streams]]\nname = \"cam\"\nmodality = \"camera\"\n\
             perturbation = {{ id = \"{}\", severity = {}, seed = {} }}\n\
             qos = {{ subscriber_buffer = 16, subscriber_borrowed = 4 }}\n",
            ID.0, ID.1, ID.2
        ),
    )
    .unwrap();
    let mut daemon = ns.start_daemon(&cfg);
    let sink = ns.start_sink(&cfg, "cam", &ns.dir.join("cam"), &["--idle", "5"]);
    let t = Transport::open("test_pub", &ns.options).unwrap();
    let qos = StreamQos {
        subscriber_buffer: 16,
        subscriber_borrowed: 4,
        ..StreamQos::default()
    };
    let mut p = t.publisher("cam/raw", &qos, Hop::Ingress, 4 << 20).unwrap();
    assert!(p.wait_for_subscribers(1, Duration::from_secs(10)));
    let frames = frames(&img);
    for (seq, enc, step, be, w, data) in &frames {
        let stamp = Stamp {
            sec: 1_700_000_000,
            nanosec: *seq as u32,
        };
        let mut hd = FrameHeader::image(*seq, stamp, "camera", *w, h, *step as u32, enc).unwrap();
        hd.is_bigendian = *be;
        p.publish_raw(hd, data).unwrap();
        std::thread::sleep(Duration::from_millis(100));
    }
    let good = [0u64, 1, 2, 6];
    let recs = sink.wait_for(good.len(), Duration::from_secs(20));
    let report = daemon.stop();
    let log = daemon.log_text();
    let s = report["streams"]
        .as_array()
        .unwrap()
        .iter()
        .find(|s| s["name"] == "cam")
        .unwrap()
        .clone();
    let got: Vec<u64> = recs.iter().map(|r| r.seq).collect();
    assert_eq!(got, good, "received {recs:?}\n{log}");
    assert_eq!(s["invalid"], 3, "{s}");
    assert_eq!(s["frames_out"], 4, "{s}");
    // The odd width is named; the unsupported encoding is logged once for its two frames.
    let odd = format!("width {} is odd", img.width - 1);
    assert!(log.contains(&odd), "{log}");
    assert_eq!(
        log.matches("unsupported pixel encoding `nv21`").count(),
        1,
        "{log}"
    );

    // perturb apply on a bag of the same frames (their index on the topic is their seq).
    let bag = ns.dir.join("in_bag");
    let mut wr = AnyWriter::create(&bag, BagFormat::Rosbag2, None).unwrap();
    let ch = wr
        .add_topic("/camera/image_raw", "sensor_msgs/msg/Image")
        .unwrap();
    for (seq, enc, step, be, w, data) in frames.iter().filter(|f| good[..3].contains(&f.0)) {
        let m = ImageMsg {
            header: Header {
                stamp_sec: 1_700_000_000,
                stamp_nanosec: *seq as u32,
                frame_id: "camera",
            },
            height: h,
            width: *w,
            encoding: enc,
            is_bigendian: *be,
            step: *step as u32,
            data,
        };
        wr.write(ch, 1 + seq, 1 + seq, &m.encode()).unwrap();
    }
    wr.finish().unwrap();
    // perturb info names each image's encoding (the last one read on the topic: mono16).
    let o = Command::new(exe("perturb"))
        .arg("info")
        .arg(&bag)
        .output()
        .unwrap();
    let info = String::from_utf8_lossy(&o.stdout);
    assert!(
        o.status.success(),
        "perturb info: {}",
        String::from_utf8_lossy(&o.stderr)
    );
    assert!(
        info.contains("mono16: grey, 16 bits, big-endian") && info.contains("mono8 view"),
        "{info}"
    );
    let applied = ns.dir.join("out_bag");
    let o = Command::new(exe("perturb"))
        .args(["apply", "--id", ID.0, "--severity", &ID.1.to_string()])
        .args(["--seed", &ID.2.to_string(), "--seq", "0"])
        .arg(&bag)
        .arg("-o")
        .arg(&applied)
        .output()
        .unwrap();
    assert!(
        o.status.success(),
        "perturb apply: {}",
        String::from_utf8_lossy(&o.stderr)
    );
    let mut from_bag = Vec::new();
    Bag::open(&applied)
        .unwrap()
        .for_each(&Filter::default(), |m| {
            if let Some(Ok(SensorMessage::Image(i))) = m.decode() {
                from_bag.push((
                    i.encoding.to_string(),
                    i.step,
                    i.is_bigendian,
                    i.data.to_vec(),
                ));
            }
            Ok(ControlFlow::Continue(()))
        })
        .unwrap();
    assert_eq!(from_bag.len(), 3);

    for r in &recs {
        let (_, enc, step, be, w, data) = frames.iter().find(|f| f.0 == r.seq).unwrap();
        assert_eq!(r.encoding, *enc);
        assert_eq!((r.width, r.height, r.data_len), (*w, h, data.len() as u64));
        assert_eq!(r.applied, Some((ID.0.to_string(), ID.1, ID.2)));
        let out = sink.payload(r.seq);
        let view = EncodedView::from_ros(data, *w, h, *step, enc, *be).unwrap();
        let mut lib = vec![0u8; data.len()];
        CameraPerturber::new(ID.0, ID.1, ID.2)
            .unwrap()
            .apply_encoded(&view, &mut lib, r.seq, &mut Scratch::new())
            .unwrap();
        assert_ne!(&out, data, "{enc}: not perturbed");
        assert!(out == lib, "{enc}: perturbd and the library differ");
        // Row padding is the input's.
        let row = view.row_bytes();
        for y in 0..h as usize {
            assert_eq!(
                out[y * step + row..(y + 1) * step],
                data[y * step + row..(y + 1) * step]
            );
        }
        if let Some(b) = from_bag.get(r.seq as usize) {
            assert_eq!((b.0.as_str(), b.1 as usize, b.2), (*enc, *step, *be));
            assert!(
                b.3 == out,
                "{enc}: perturb apply on the bag and perturbd differ"
            );
        }
    }
}

#[test]
fn perturb_bench_times_the_conversion_pair_beside_the_perturbation() {
    let Some(png) = shared_data("kitti/image_2/000000.png") else {
        return;
    };
    let o = Command::new(exe("perturb"))
        .args(["bench", "--modality", "camera", "--encoding", "bayer_rggb8"])
        .args([
            "--encoding",
            "yuv422",
            "--id",
            "C-C4",
            "--width",
            "64",
            "--height",
            "48",
        ])
        .args(["--frames", "2", "--json", "--input"])
        .arg(&png)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let rows: Vec<serde_json::Value> = serde_json::from_slice(&o.stdout).unwrap();
    // Five severities per encoding, each with the pair's medians and the whole frame's.
    assert_eq!(rows.len(), 10, "{rows:?}");
    for r in &rows {
        for k in [
            "pair_ms",
            "to_working_ms",
            "write_back_ms",
            "perturbation_ms",
            "median_ms",
        ] {
            assert!(r[k].as_f64().is_some_and(|v| v >= 0.0), "{k} in {r}");
        }
    }
    assert_eq!(rows[0]["encoding"], "bayer_rggb8");
    assert_eq!(rows[9]["encoding"], "yuv422");
}
