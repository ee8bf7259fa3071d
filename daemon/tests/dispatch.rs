//! `[daemon] dispatch` through a real perturbd: the same frames of several streams, published
//! together round after round, come out with the same bytes whether the daemon dispatches them
//! to one shared pool as they come, or earliest deadline first through the gate (a worker per
//! frame, or every worker on one frame at a time), and none is lost.

use perturb_core::synthetic;
use perturb_wire::{
    FrameHeader, FramePublisher, FrameSubscriber, Hop, Stamp, StreamQos, Transport,
    TransportOptions,
};
use std::collections::BTreeMap;
use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

/// (stream, perturbation id, severity); the last one is a LiDAR.
const STREAMS: [(&str, &str, u8); 4] = [
    ("cam0", "C-B4", 5),
    ("cam1", "C-B4", 2),
    ("cam2", "C-A1", 3),
    ("lidar", "L-D1", 3),
];
const ROUNDS: u64 = 6;
const SEED: u64 = 9;
/// Worker threads of the daemon (so the thread count of a frame differs between the policies
/// on any machine).
const WORKERS: &str = "3";

fn qos() -> StreamQos {
    StreamQos {
        subscriber_buffer: 16,
        subscriber_borrowed: 4,
        ..StreamQos::default()
    }
}

fn is_lidar(stream: &str) -> bool {
    stream.starts_with("lidar")
}

fn config(daemon: &str) -> String {
    let mut s = format!("[daemon]\nstats_interval_s = 0\n{daemon}\n");
    for (name, id, severity) in STREAMS {
        let modality = if is_lidar(name) { "lidar" } else { "camera" };
        s += &format!(
            "\n[[streams]]\nname = \"{name}\"\nmodality = \"{modality}\"\n\
             perturbation = {{ id = \"{id}\", severity = {severity}, seed = {SEED} }}\n\
             qos = {{ subscriber_buffer = 16, subscriber_borrowed = 4 }}\n"
        );
        if is_lidar(name) {
            s += "sensor = \"vlp32c\"\n";
        }
    }
    s
}

/// A perturbd child, interrupted on drop.
struct Daemon(Option<Child>);

impl Daemon {
    fn stop(&mut self) {
        if let Some(mut c) = self.0.take() {
            let st = perturb_wire::process::interrupt(&mut c, Duration::from_secs(20));
            assert!(
                st.is_some_and(|s| s.success()),
                "perturbd did not stop cleanly: {st:?}"
            );
        }
    }
}

impl Drop for Daemon {
    fn drop(&mut self) {
        if let Some(mut c) = self.0.take() {
            let _ = perturb_wire::process::interrupt(&mut c, Duration::from_secs(5));
        }
    }
}

/// What came out for one frame: the perturbation its header says was applied (id, severity,
/// seed), its width and height, and its bytes.
type Output = (Option<(String, u8, u64)>, u32, u32, Vec<u8>);

/// One daemon run: its outputs by (stream, seq), its report and its log.
struct Run {
    out: BTreeMap<(String, u64), Output>,
    report: serde_json::Value,
    log: String,
}

fn raw_image(stream: usize, seq: u64) -> perturb_core::image::Image {
    synthetic::street_image(320, 200, seq * 10 + stream as u64)
}

fn publish(p: &mut FramePublisher, stream: usize, seq: u64) {
    let stamp = Stamp {
        sec: 1_700_000_000 + seq as i32,
        nanosec: 0,
    };
    let name = STREAMS[stream].0;
    if is_lidar(name) {
        let c = synthetic::vlp32c_scan(seq);
        let h = FrameHeader::for_cloud_view(seq, stamp, name, &c.view()).unwrap();
        p.publish_cloud(h, &c.view()).unwrap();
    } else {
        let img = raw_image(stream, seq);
        let h = FrameHeader::for_image_view(seq, stamp, name, &img.view()).unwrap();
        p.publish_image(h, &img.view()).unwrap();
    }
}

/// Runs perturbd with `daemon` in its `[daemon]` table; each round publishes one frame on every
/// stream at once and waits for all of them to come out (so the daemon's queues never
/// overflow: a loss is the daemon's).
fn run(tag: &str, daemon: &str) -> Run {
    let options = TransportOptions::isolated(tag);
    let dir = std::env::temp_dir().join(format!("perturbd-{tag}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let cfg = dir.join("perturbd.toml");
    std::fs::write(&cfg, config(daemon)).unwrap();
    let (report, log) = (dir.join("report.json"), dir.join("perturbd.log"));
    let child = Command::new(env!("CARGO_BIN_EXE_perturbd"))
        .arg("--config")
        .arg(&cfg)
        .arg("--report")
        .arg(&report)
        .arg("--fresh")
        .envs(options.to_env())
        .env("RAYON_NUM_THREADS", WORKERS)
        .stdout(Stdio::null())
        .stderr(std::fs::File::create(&log).unwrap())
        .spawn()
        .expect("starting perturbd");
    let mut d = Daemon(Some(child));
    let log_text = |p: &Path| std::fs::read_to_string(p).unwrap_or_default();

    let t = Transport::open("dispatch_test", &options).unwrap();
    let mut ports: Vec<(FramePublisher, FrameSubscriber)> = STREAMS
        .iter()
        .map(|(name, _, _)| {
            let s = t.subscriber(&format!("{name}/perturbed"), &qos(), None);
            let p = t.publisher(&format!("{name}/raw"), &qos(), Hop::Ingress, 1 << 20);
            (p.unwrap(), s.unwrap())
        })
        .collect();
    for (p, _) in &ports {
        assert!(
            p.wait_for_subscribers(1, Duration::from_secs(30)),
            "perturbd did not subscribe:\n{}",
            log_text(&log)
        );
    }
    let mut out = BTreeMap::new();
    for seq in 0..ROUNDS {
        for (k, (p, _)) in ports.iter_mut().enumerate() {
            publish(p, k, seq);
        }
        for (k, (_, s)) in ports.iter().enumerate() {
            let name = STREAMS[k].0;
            let start = Instant::now();
            let f = loop {
                if let Some(f) = s.wait(Duration::from_millis(100)).unwrap() {
                    break f;
                }
                // A guard against a hang, not a timing requirement.
                assert!(
                    start.elapsed() < Duration::from_secs(60),
                    "{name} frame {seq} never came out:\n{}",
                    log_text(&log)
                );
            };
            let h = f.header();
            assert_eq!(h.seq, seq, "{name}: frames out of order");
            let applied = h.applied().map(|a| (a.id.to_string(), a.severity, a.seed));
            let o = (applied, h.width, h.height, f.data().unwrap().to_vec());
            out.insert((name.to_string(), seq), o);
        }
    }
    d.stop();
    let report: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(&report)
            .unwrap_or_else(|e| panic!("no report ({e}):\n{}", log_text(&log))),
    )
    .unwrap();
    let log = plain(&log_text(&log));
    drop(ports);
    drop(t);
    let _ = options.remove_namespace_files();
    let _ = std::fs::remove_dir_all(&dir);
    Run { out, report, log }
}

/// `text` without its terminal colour codes (`ESC [ ... m`).
fn plain(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    let mut chars = text.chars();
    while let Some(c) = chars.next() {
        if c == '\u{1b}' {
            chars.by_ref().find(|&c| c == 'm');
        } else {
            out.push(c);
        }
    }
    out
}

/// Every frame of `run` came out perturbed and the daemon counted none lost.
fn check_complete(what: &str, run: &Run) {
    assert_eq!(
        run.out.len() as u64,
        ROUNDS * STREAMS.len() as u64,
        "{what}"
    );
    for (k, (name, id, severity)) in STREAMS.iter().enumerate() {
        for seq in 0..ROUNDS {
            let (applied, _, _, bytes) = &run.out[&(name.to_string(), seq)];
            assert_eq!(
                applied,
                &Some((id.to_string(), *severity, SEED)),
                "{what}: {name} {seq}"
            );
            if !is_lidar(name) {
                assert_ne!(
                    bytes,
                    &raw_image(k, seq).data,
                    "{what}: {name} {seq} unchanged"
                );
            }
        }
        let s = run.report["streams"]
            .as_array()
            .unwrap()
            .iter()
            .find(|s| s["name"] == *name)
            .unwrap();
        for (key, want) in [
            ("frames_in", ROUNDS),
            ("frames_out", ROUNDS),
            ("dropped", 0),
            ("invalid", 0),
            ("perturb_failed", 0),
        ] {
            assert_eq!(s[key].as_u64(), Some(want), "{what}: {name}.{key} in {s}");
        }
    }
}

#[test]
fn deadline_dispatch_gives_every_frame_the_bytes_of_shared_dispatch_and_loses_none() {
    let shared = run("dsp_shared", "dispatch = \"shared\"");
    check_complete("shared", &shared);
    assert!(shared.log.contains("shared pool"), "{}", shared.log);
    // The L-D1 clouds lost points to the perturbation (its detector found the objects).
    let lidar = STREAMS[3].0;
    assert!(
        (0..ROUNDS).any(|seq| {
            let raw = synthetic::vlp32c_scan(seq).data.len();
            shared.out[&(lidar.to_string(), seq)].3.len() < raw
        }),
        "L-D1 removed no point from any cloud"
    );
    let per_worker = run("dsp_slots", "dispatch = \"deadline\"");
    let all_workers = run("dsp_one", "dispatch = \"deadline\"\ndispatch_slots = 1");
    for (what, r, slots, threads) in [
        ("deadline", &per_worker, WORKERS, "1"),
        ("deadline, 1 slot", &all_workers, "1", WORKERS),
    ] {
        check_complete(what, r);
        assert!(
            r.log.contains("earliest deadline first")
                && r.log.contains(&format!("slots={slots}"))
                && r.log.contains(&format!("threads_per_slot={threads}")),
            "{what}: the gate is not in use:\n{}",
            r.log
        );
        for (key, want) in &shared.out {
            let got = &r.out[key];
            assert!(
                got == want,
                "{what}: {key:?} differs from shared dispatch ({} against {} bytes)",
                got.3.len(),
                want.3.len()
            );
        }
    }
}
