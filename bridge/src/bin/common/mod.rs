//! What the two latency benches (`dds_latency`, `ros1_latency`) share: the test frame, its
//! stamp, and the lines a child process prints.

use perturb_bridge::frame::OwnedPayload;
use std::io::{BufRead, BufReader, Read};

/// The frame a latency bench sends: a `w` x `h` synthetic street image, or a cloud of `n` points
/// (the synthetic VLP-32C scan's points repeated up to `n`).
pub fn test_frame(
    image: Option<(u32, u32)>,
    cloud: Option<usize>,
    frame_id: &str,
) -> Result<OwnedPayload, String> {
    Ok(match (image, cloud) {
        (_, Some(n)) => {
            let c = perturb_core::synthetic::vlp32c_scan(0);
            let step = c.layout.point_step as usize;
            let data: Vec<u8> = (0..n * step).map(|i| c.data[i % c.data.len()]).collect();
            OwnedPayload::Cloud {
                sec: 0,
                nanosec: 0,
                frame_id: frame_id.into(),
                cloud: perturb_core::cloud::Cloud::from_vec(
                    c.layout.clone(),
                    data,
                    n as u32,
                    1,
                    n * step,
                    true,
                )
                .map_err(|e| e.to_string())?,
            }
        }
        (Some((w, h)), None) => OwnedPayload::Image {
            sec: 0,
            nanosec: 0,
            frame_id: frame_id.into(),
            image: perturb_core::synthetic::street_image(w, h, 0),
        },
        (None, None) => return Err("give --image WxH or --cloud N".into()),
    })
}

/// Stamps `p` with `ns` (monotonic nanoseconds as sec + nanosec) and, if given, `frame_id`.
pub fn set_stamp(p: &mut OwnedPayload, ns: u64, frame_id: Option<&str>) {
    let (s, n) = ((ns / 1_000_000_000) as i32, (ns % 1_000_000_000) as u32);
    if let OwnedPayload::Image {
        sec,
        nanosec,
        frame_id: id,
        ..
    }
    | OwnedPayload::Cloud {
        sec,
        nanosec,
        frame_id: id,
        ..
    } = p
    {
        *sec = s;
        *nanosec = n;
        if let Some(f) = frame_id {
            *id = f.to_string();
        }
    }
}

/// The lines `out` prints, read on a thread of their own.
pub fn lines_of(out: impl Read + Send + 'static) -> crossbeam::channel::Receiver<String> {
    let (tx, rx) = crossbeam::channel::unbounded::<String>();
    std::thread::spawn(move || {
        for line in BufReader::new(out).lines().map_while(Result::ok) {
            if tx.send(line).is_err() {
                break;
            }
        }
    });
    rx
}
