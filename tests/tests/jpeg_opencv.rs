//! C-A4 (JPEG compression) against its reference, OpenCV's `imencode(".jpg", quality)` +
//! `imdecode` (the Python package `opencv-python-headless`, `cv2`, libjpeg-turbo inside): the same
//! bytes at every severity on the KITTI frames and on odd sizes, for the frame handed to OpenCV in
//! its true colours (BGR order); rgb8, bgr8, bgra8 (alpha kept) and mono8 (a grayscale JPEG, as
//! OpenCV writes a one-channel Mat). And `perturb apply` writes the library's bytes.

use perturb_core::camera::noise::JPEG_QUALITY;
use perturb_core::formats::picture;
use perturb_core::image::{Image, PixelFormat};
use perturb_core::perturber::CameraPerturber;
use perturb_tests::{Namespace, exe, shared_data};
use std::process::Command;

#[path = "../support/python_oracle.rs"]
mod python_oracle;
use python_oracle::python_oracle;

/// The top-left `w x h` of `img` (rgb8).
fn crop(img: &Image, w: u32, h: u32) -> Image {
    let c = img.format.channels();
    let data = (0..h as usize)
        .flat_map(|y| img.view().row(y)[..w as usize * c].to_vec())
        .collect();
    Image::from_vec(data, w, h, w as usize * c, img.format).unwrap()
}

/// C-A4 at `severity` from the library.
fn ours(img: &Image, severity: u8) -> Image {
    CameraPerturber::new("C-A4", severity, 0)
        .unwrap()
        .apply_owned(&img.view(), 0)
        .unwrap()
}

/// How many bytes differ and by how much at most.
fn differ(a: &[u8], b: &[u8]) -> (usize, u8) {
    assert_eq!(a.len(), b.len());
    a.iter()
        .zip(b)
        .filter(|(x, y)| x != y)
        .fold((0, 0), |(n, m), (x, y)| (n + 1, m.max(x.abs_diff(*y))))
}

/// The colour bytes of `img` in rgb8 order (alpha dropped).
fn rgb_of(img: &Image) -> Vec<u8> {
    img.convert(PixelFormat::Rgb8).data
}

#[test]
fn jpeg_compression_gives_opencvs_bytes_on_kitti_frames_and_odd_sizes() {
    let Some(dir) = shared_data("kitti/image_2") else {
        return;
    };
    let mut names: Vec<_> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "png"))
        .collect();
    names.sort();
    names.truncate(3);
    assert!(!names.is_empty(), "no PNG in {}", dir.display());
    let frames: Vec<Image> = names
        .iter()
        .map(|p| picture::decode(&std::fs::read(p).unwrap()).unwrap())
        .map(|i| i.convert(PixelFormat::Rgb8))
        .collect();
    // name, frame (rgb8 or mono8)
    let mut cases: Vec<(String, Image)> = Vec::new();
    for (i, f) in frames.iter().enumerate() {
        cases.push((format!("kitti{i}"), f.clone()));
    }
    let first = &frames[0];
    for (w, h) in [(1, 1), (7, 5), (17, 9), (61, 37), (333, 16), (1223, 369)] {
        cases.push((format!("crop{w}x{h}"), crop(first, w, h)));
    }
    cases.push(("mono".into(), first.convert(PixelFormat::Mono8)));
    cases.push((
        "mono61x37".into(),
        crop(first, 61, 37).convert(PixelFormat::Mono8),
    ));

    let ns = Namespace::new("jpeg-opencv");
    let d = &ns.dir;
    let mut list = String::new();
    for (name, img) in &cases {
        std::fs::write(d.join(format!("{name}.raw")), &img.data).unwrap();
        let c = img.format.channels();
        list += &format!("{name} {} {} {c}\n", img.width, img.height);
    }
    std::fs::write(d.join("frames.txt"), list).unwrap();
    let qualities: Vec<String> = JPEG_QUALITY.iter().map(|q| q.to_string()).collect();
    std::fs::write(d.join("qualities.txt"), qualities.join(" ")).unwrap();
    let Some(version) = python_oracle(
        "cv2, numpy",
        "pip install opencv-python-headless numpy",
        include_str!("jpeg_opencv.py"),
        &[d.to_str().unwrap()],
    ) else {
        return;
    };
    let version = version.trim();

    let mut failures = Vec::new();
    for (name, img) in &cases {
        for (s, q) in (1..=5u8).zip(JPEG_QUALITY) {
            let cv = std::fs::read(d.join(format!("{name}.q{q}.cv"))).unwrap();
            let mine = ours(img, s);
            let (n, max) = differ(&mine.data, &cv);
            if n > 0 {
                failures.push(format!(
                    "{name} {}x{} {} s{s} (q{q}): {n} of {} bytes differ, by up to {max}",
                    img.width,
                    img.height,
                    img.format,
                    cv.len()
                ));
            }
            // The same frame in the other colour layouts gives the same colours.
            if img.format == PixelFormat::Rgb8 && name.starts_with("kitti0") {
                for format in [PixelFormat::Bgr8, PixelFormat::Bgra8] {
                    let mut other = img.convert(format);
                    if let Some(a) = format.alpha_offset() {
                        for (i, p) in other.data.chunks_exact_mut(4).enumerate() {
                            p[a] = (i * 13 % 256) as u8;
                        }
                    }
                    let out = ours(&other, s);
                    let (n, max) = differ(&rgb_of(&out), &cv);
                    if n > 0 {
                        failures.push(format!(
                            "{name} as {format} s{s}: {n} bytes differ by up to {max}"
                        ));
                    }
                    if let Some(a) = format.alpha_offset() {
                        let alpha = |i: &Image| {
                            i.data
                                .iter()
                                .skip(a)
                                .step_by(4)
                                .copied()
                                .collect::<Vec<_>>()
                        };
                        assert_eq!(alpha(&out), alpha(&other), "{format} s{s}: alpha changed");
                    }
                }
            }
        }
    }
    assert!(
        failures.is_empty(),
        "C-A4 differs from OpenCV {version}'s imencode + imdecode:\n{}",
        failures.join("\n")
    );
    eprintln!(
        "C-A4 = OpenCV {version} imencode + imdecode on {} frames x 5 severities",
        cases.len()
    );

    // The CLI writes the library's bytes (an odd-sized PNG in, a PNG out).
    let odd = crop(first, 1223, 369);
    let input = d.join("odd.png");
    std::fs::write(&input, picture::encode_png(&odd.view()).unwrap()).unwrap();
    let out = d.join("odd_s3.png");
    let o = Command::new(exe("perturb"))
        .args(["apply", "--id", "C-A4", "--severity", "3"])
        .arg(&input)
        .arg("-o")
        .arg(&out)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let cli = picture::decode(&std::fs::read(&out).unwrap()).unwrap();
    assert_eq!(
        rgb_of(&cli),
        ours(&odd, 3).data,
        "perturb apply and the library differ"
    );
}
