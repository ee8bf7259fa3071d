//! Measures DDS latency between two processes on this machine for the bridge's backends:
//! a writer (this process) and a reader (a child process of the same binary), each on its own
//! participant, with sensor-data QoS unless `--reliable`.
//!
//! ```sh
//! cargo run --release -p perturb-bridge --bin dds_latency -- --writer rustdds --reader cyclone --image 1920x1208
//! cargo run --release -p perturb-bridge --bin dds_latency -- --writer cyclone --reader cyclone --cloud 120000
//! ```
//!
//! The writer puts `CLOCK_MONOTONIC` at the moment it calls `write` into the header stamp; the
//! reader subtracts it from the time its callback sees the message (decoded, data in hand). So a
//! figure covers serialisation, the UDP loopback, reassembly and the reader's hand-over: the
//! egress latency of the writer's backend towards the reader's, or the ingress latency of the
//! reader's backend from the writer's. Lost samples (best effort) are counted.
//!
//! Both participants use only the loopback interface unless `--interface` says otherwise
//! (`--interface default` leaves the choice to the DDS implementation).

mod common;

use perturb_bridge::dds::{self, BackendKind, Qos, Received, Reliability, RosType, TopicSpec};
use perturb_bridge::frame::monotonic_ns;
use perturb_bridge::stats::summarize;
use std::io::Write;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

struct Args {
    writer: BackendKind,
    reader: BackendKind,
    role_reader: bool,
    image: Option<(u32, u32)>,
    cloud: Option<usize>,
    count: usize,
    rate: f64,
    reliable: bool,
    domain: u16,
    interfaces: Vec<String>,
}

fn parse() -> Result<Args, String> {
    let mut a = Args {
        writer: BackendKind::Rustdds,
        reader: BackendKind::Rustdds,
        role_reader: false,
        image: None,
        cloud: None,
        count: 100,
        rate: 10.0,
        reliable: false,
        domain: 42,
        interfaces: Vec::new(),
    };
    let mut it = std::env::args().skip(1);
    while let Some(k) = it.next() {
        let mut v = || it.next().ok_or(format!("{k} needs a value"));
        match k.as_str() {
            "--writer" => a.writer = v()?.parse()?,
            "--reader" => a.reader = v()?.parse()?,
            "--role-reader" => a.role_reader = true,
            "--image" => {
                let s = v()?;
                let (w, h) = s
                    .split_once('x')
                    .and_then(|(w, h)| Some((w.parse().ok()?, h.parse().ok()?)))
                    .ok_or(format!("--image {s}: expected WxH"))?;
                a.image = Some((w, h));
            }
            "--cloud" => a.cloud = Some(v()?.parse().map_err(|e| format!("--cloud: {e}"))?),
            "--count" => a.count = v()?.parse().map_err(|e| format!("--count: {e}"))?,
            "--rate" => a.rate = v()?.parse().map_err(|e| format!("--rate: {e}"))?,
            "--domain" => a.domain = v()?.parse().map_err(|e| format!("--domain: {e}"))?,
            "--reliable" => a.reliable = true,
            "--interface" => a.interfaces.push(v()?),
            "-h" | "--help" => {
                println!(
                    "dds_latency --writer rustdds|cyclone --reader rustdds|cyclone (--image WxH | --cloud POINTS) [--count N] [--rate HZ] [--reliable] [--domain D] [--interface lo|default|NAME|ADDR ...]"
                );
                std::process::exit(0);
            }
            o => return Err(format!("unknown argument {o}")),
        }
    }
    if a.image.is_none() && a.cloud.is_none() {
        a.image = Some((1920, 1208));
    }
    if a.interfaces.is_empty() {
        a.interfaces.push("lo".into());
    }
    a.interfaces.retain(|i| i != "default");
    Ok(a)
}

fn spec(a: &Args) -> TopicSpec {
    TopicSpec {
        topic: "/perturb/latency".into(),
        ros_type: if a.cloud.is_some() {
            RosType::PointCloud2
        } else {
            RosType::Image
        },
        qos: Qos {
            reliability: if a.reliable {
                Reliability::Reliable
            } else {
                Reliability::BestEffort
            },
            ..Qos::SENSOR_DATA
        },
    }
}

fn participant(a: &Args, backend: BackendKind) -> dds::ParticipantConfig {
    dds::ParticipantConfig {
        backend,
        domain_id: a.domain,
        interfaces: a.interfaces.clone(),
    }
}

fn reader(a: &Args) -> Result<(), String> {
    let backend =
        dds::backend(&participant(a, a.reader), "latency_reader").map_err(|e| e.to_string())?;
    let mut r = backend.reader(&spec(a)).map_err(|e| e.to_string())?;
    let out = std::io::stdout();
    println!("ready");
    out.lock().flush().ok();
    let deadline = Instant::now() + Duration::from_secs(600);
    while Instant::now() < deadline {
        let mut lines = Vec::new();
        r.take(Duration::from_millis(200), &mut |m| {
            let now = monotonic_ns();
            let h = match &m {
                Ok(Received::Image(i)) => i.header,
                Ok(Received::Cloud(c)) => c.header,
                _ => return,
            };
            let sent = h.stamp_sec as u64 * 1_000_000_000 + h.stamp_nanosec as u64;
            lines.push(format!("{} {}", h.frame_id, now.saturating_sub(sent)));
        })
        .map_err(|e| e.to_string())?;
        let mut o = out.lock();
        for l in lines {
            let _ = writeln!(o, "{l}");
        }
        let _ = o.flush();
    }
    Ok(())
}

fn writer(a: &Args) -> Result<(), String> {
    let (mut child, rx) = spawn_reader()?;
    let backend =
        dds::backend(&participant(a, a.writer), "latency_writer").map_err(|e| e.to_string())?;
    let mut w = backend.writer(&spec(a)).map_err(|e| e.to_string())?;
    let mut frame = common::test_frame(a.image, a.cloud, "warmup")?;
    let bytes = frame.payload().encode().len();
    // Discovery: send warm-up frames until the reader sees one.
    let t = Instant::now();
    loop {
        common::set_stamp(&mut frame, monotonic_ns(), Some("warmup"));
        w.write(&frame.payload()).map_err(|e| e.to_string())?;
        if let Ok(l) = rx.recv_timeout(Duration::from_millis(300))
            && l.starts_with("warmup")
        {
            break;
        }
        if t.elapsed() > Duration::from_secs(30) {
            let _ = child.kill();
            return Err("the reader never matched".into());
        }
    }
    std::thread::sleep(Duration::from_millis(500));
    while rx.try_recv().is_ok() {}
    let period = Duration::from_secs_f64(1.0 / a.rate);
    let start = Instant::now();
    let mut write_ns = Vec::new();
    for i in 0..a.count {
        let due = start + period.mul_f64(i as f64);
        if let Some(d) = due.checked_duration_since(Instant::now()) {
            std::thread::sleep(d);
        }
        let t0 = monotonic_ns();
        common::set_stamp(&mut frame, t0, Some("m"));
        w.write(&frame.payload()).map_err(|e| e.to_string())?;
        write_ns.push(monotonic_ns() - t0);
    }
    let lat = latencies(&rx, a.count);
    let _ = child.kill();
    let _ = child.wait();
    let s = summarize(&lat);
    let wsum = summarize(&write_ns);
    println!(
        "{:<8} -> {:<8} {:>10} B  {:>4}/{:<4} received  latency p50 {:>7.2} ms  p99 {:>7.2} ms  max {:>7.2} ms  (write() call p50 {:.2} ms)",
        format!("{:?}", a.writer).to_lowercase(),
        format!("{:?}", a.reader).to_lowercase(),
        bytes,
        lat.len(),
        a.count,
        s.p50_ms,
        s.p99_ms,
        s.max_ms,
        wsum.p50_ms
    );
    Ok(())
}

/// This program again as the reader (a second process), once it says it has started; its
/// printed lines arrive on the receiver.
fn spawn_reader() -> Result<(Child, crossbeam::channel::Receiver<String>), String> {
    let exe = std::env::current_exe().map_err(|e| e.to_string())?;
    let mut child_args: Vec<String> = std::env::args().skip(1).collect();
    child_args.push("--role-reader".into());
    let mut child = Command::new(exe)
        .args(&child_args)
        .stdout(Stdio::piped())
        .spawn()
        .map_err(|e| e.to_string())?;
    let rx = common::lines_of(child.stdout.take().ok_or("no child stdout")?);
    rx.recv_timeout(Duration::from_secs(30))
        .map_err(|_| "reader did not start")?;
    Ok((child, rx))
}

/// The latencies (ns) the reader reported for the measured frames, waiting up to 3 s for them.
fn latencies(rx: &crossbeam::channel::Receiver<String>, count: usize) -> Vec<u64> {
    let mut lat = Vec::new();
    let end = Instant::now() + Duration::from_secs(3);
    while lat.len() < count {
        match rx.recv_deadline(end) {
            Ok(l) => {
                if let Some(v) = l.strip_prefix("m ").and_then(|v| v.parse::<u64>().ok()) {
                    lat.push(v);
                }
            }
            Err(_) => break,
        }
    }
    lat
}

fn main() {
    let r = parse().and_then(|a| {
        if a.role_reader {
            reader(&a)
        } else {
            writer(&a)
        }
    });
    if let Err(e) = r {
        eprintln!("error: {e}");
        std::process::exit(1);
    }
}
