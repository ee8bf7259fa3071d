//! `perturb-e2e-bench`: measures the middleware through a real `perturbd` process.
//!
//! - `overhead`: one stream with the perturbation off; this process publishes frames on
//!   `<stream>/raw` and receives them on `<stream>/perturbed` (two iceoryx2 nodes, two threads),
//!   and reports each hop from the header's CLOCK_MONOTONIC stamps: publish -> daemon receive,
//!   daemon receive -> daemon publish (the daemon's copy into the output sample), daemon publish ->
//!   subscriber, and end to end. Images of 800x503 and 1920x1208 (rgb8) and a 120k-point KITTI
//!   cloud (or a synthetic VLP-32C scan when the data is absent).
//! - `load`: the daemon runs `config/load.toml` (5 cameras at 30 Hz, 3 LiDARs at 10 Hz, light
//!   perturbations); this process publishes every stream at its rate and receives every output
//!   for `--seconds`; reports frames, drops and the daemon's CPU use.
//!
//! ```sh
//! cargo build --release --workspace --bins
//! target/release/perturb-e2e-bench overhead --frames 300
//! target/release/perturb-e2e-bench load --seconds 60
//! ```

use anyhow::{Context, Result, bail};
use clap::{Parser, Subcommand};
use perturb_core::cloud::Cloud;
use perturb_core::image::Image;
use perturb_core::synthetic;
use perturb_tests::{Namespace, workspace};
use perturb_wire::{FrameHeader, Hop, Stamp, StreamQos, Transport, monotonic_ns};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::{Duration, Instant};

/// Measures the middleware through a real perturbd.
#[derive(Parser)]
struct Cli {
    #[command(subcommand)]
    cmd: Cmd,
}

#[derive(Subcommand)]
enum Cmd {
    /// Per-hop latency with the perturbation off.
    Overhead {
        /// Frames per payload.
        #[arg(long, default_value_t = 300)]
        frames: u64,
        /// Publishing rate (Hz).
        #[arg(long, default_value_t = 30.0)]
        hz: f64,
    },
    /// Sustained load with config/load.toml.
    Load {
        /// Seconds to run.
        #[arg(long, default_value_t = 60.0)]
        seconds: f64,
        /// The daemon configuration.
        #[arg(long)]
        config: Option<PathBuf>,
    },
}

enum Frame {
    Image(Image),
    Cloud(Cloud),
}

impl Frame {
    fn header(&self, seq: u64, name: &str) -> Result<FrameHeader> {
        let s = Stamp {
            sec: seq as i32,
            nanosec: 0,
        };
        Ok(match self {
            Frame::Image(i) => FrameHeader::for_image_view(seq, s, name, &i.view())?,
            Frame::Cloud(c) => FrameHeader::for_cloud_view(seq, s, name, &c.view())?,
        })
    }
    fn len(&self) -> usize {
        match self {
            Frame::Image(i) => i.data.len(),
            Frame::Cloud(c) => c.data.len(),
        }
    }
}

fn kitti_cloud() -> Cloud {
    let p = workspace().join("../shared/data/kitti/velodyne/000000.bin");
    match std::fs::read(&p)
        .ok()
        .and_then(|b| perturb_core::formats::kitti::decode_kitti(&b).ok())
    {
        Some(c) => c,
        None => {
            eprintln!("{} absent: using a synthetic VLP-32C scan", p.display());
            synthetic::vlp32c_scan(0)
        }
    }
}

fn percentile(v: &mut [f64], p: f64) -> f64 {
    perturb_core::percentile::of_f64(v, p)
}

/// CPU seconds (user + system) a process has used, from /proc.
// libc's sysconf.
#[allow(unsafe_code)]
fn cpu_seconds(pid: u32) -> Option<f64> {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).ok()?;
    let rest = &stat[stat.rfind(')')? + 2..];
    let f: Vec<&str> = rest.split_whitespace().collect();
    let ticks = f.get(11)?.parse::<f64>().ok()? + f.get(12)?.parse::<f64>().ok()?;
    // SAFETY: sysconf has no preconditions.
    let hz = unsafe { libc::sysconf(libc::_SC_CLK_TCK) } as f64;
    Some(ticks / hz)
}

fn write_config(dir: &Path, streams: &[(&str, &str)]) -> PathBuf {
    let mut s = String::from("[daemon]\nstats_interval_s = 0\n");
    for (name, modality) in streams {
        s += &format!(
            "\n[[streams]]\nname = \"{name}\"\nmodality = \"{modality}\"\nqos = {{ subscriber_buffer = 8 }}\n"
        );
        if *modality == "lidar" {
            s += "sensor = \"hdl64e\"\n";
        }
    }
    let p = dir.join("perturbd.toml");
    std::fs::write(&p, s).expect("config");
    p
}

fn overhead(frames: u64, hz: f64) -> Result<()> {
    let ns = Namespace::new("overhead");
    let cfg = write_config(&ns.dir, &[("cam", "camera"), ("lidar", "lidar")]);
    let qos = StreamQos {
        subscriber_buffer: 8,
        ..StreamQos::default()
    };
    let mut daemon = ns.start_daemon(&cfg);
    let payloads = [
        (
            "800x503 rgb8",
            "cam",
            Frame::Image(synthetic::street_image(800, 503, 0)),
        ),
        (
            "1920x1208 rgb8",
            "cam",
            Frame::Image(synthetic::street_image(1920, 1208, 0)),
        ),
        ("KITTI cloud", "lidar", Frame::Cloud(kitti_cloud())),
    ];
    let t_pub = Transport::open("bench_pub", &ns.options)?;
    let t_sub = Transport::open("bench_sub", &ns.options)?;
    println!(
        "daemon hop with the perturbation off, {frames} frames at {hz} Hz each (ms, p50 / p99 / max)"
    );
    println!(
        "{:<28} {:>10} | {:>22} | {:>22} | {:>22} | {:>22}",
        "payload",
        "bytes",
        "publish->daemon rx",
        "daemon rx->tx",
        "daemon tx->subscriber",
        "end to end"
    );
    let mut seq = 0u64;
    for (label, stream, frame) in &payloads {
        let mut publisher =
            t_pub.publisher(&format!("{stream}/raw"), &qos, Hop::Ingress, frame.len())?;
        let sub = t_sub.subscriber(&format!("{stream}/perturbed"), &qos, None)?;
        if !publisher.wait_for_subscribers(1, Duration::from_secs(10)) {
            bail!("the daemon did not subscribe to {stream}/raw");
        }
        let (mut a, mut b, mut c, mut d) = (vec![], vec![], vec![], vec![]);
        let period = Duration::from_secs_f64(1.0 / hz);
        let mut lost = 0;
        for i in 0..frames + 10 {
            let start = Instant::now();
            let h = frame.header(seq, stream)?;
            match frame {
                Frame::Image(img) => publisher.publish_image(h, &img.view())?,
                Frame::Cloud(cl) => publisher.publish_cloud(h, &cl.view())?,
            };
            let mut got = None;
            while start.elapsed() < Duration::from_secs(2) {
                if let Some(f) = sub.wait(Duration::from_millis(500))?
                    && f.header().seq == seq
                {
                    got = Some((*f.header(), monotonic_ns()));
                    break;
                }
            }
            seq += 1;
            match got {
                Some((h, now)) if i >= 10 => {
                    let ms = |x: u64, y: u64| y.saturating_sub(x) as f64 / 1e6;
                    a.push(ms(h.t_ingress_ns, h.t_daemon_rx_ns));
                    b.push(ms(h.t_daemon_rx_ns, h.t_daemon_tx_ns));
                    c.push(ms(h.t_daemon_tx_ns, now));
                    d.push(ms(h.t_ingress_ns, now));
                }
                Some(_) => {}
                None => lost += 1,
            }
            if let Some(rest) = period.checked_sub(start.elapsed()) {
                std::thread::sleep(rest);
            }
        }
        let fmt = |v: &mut Vec<f64>| {
            let max = v.iter().cloned().fold(f64::NAN, f64::max);
            format!(
                "{:.3} / {:.3} / {:.3}",
                percentile(v, 0.5),
                percentile(v, 0.99),
                max
            )
        };
        println!(
            "{:<28} {:>10} | {:>22} | {:>22} | {:>22} | {:>22}{}",
            label,
            frame.len(),
            fmt(&mut a),
            fmt(&mut b),
            fmt(&mut c),
            fmt(&mut d),
            if lost > 0 {
                format!("  ({lost} lost)")
            } else {
                String::new()
            }
        );
    }
    daemon.stop();
    Ok(())
}

fn load(seconds: f64, config: Option<PathBuf>) -> Result<()> {
    let ns = Namespace::new("load");
    let cfg_path = config.unwrap_or_else(|| workspace().join("config/load.toml"));
    let cfg = perturbd::Config::load(&cfg_path).map_err(|e| anyhow::anyhow!("{e}"))?;
    let mut daemon = ns.start_daemon(&cfg_path);
    let pid = daemon.pid().context("daemon pid")?;
    let stop = Arc::new(AtomicBool::new(false));
    let mut threads = Vec::new();
    let received = Arc::new(AtomicU64::new(0));
    let published = Arc::new(AtomicU64::new(0));
    for s in &cfg.streams {
        let (frame, hz) = match s.modality {
            perturb_core::registry::Modality::Camera => {
                (Frame::Image(synthetic::street_image(800, 503, 0)), 30.0)
            }
            perturb_core::registry::Modality::Lidar => (Frame::Cloud(kitti_cloud()), 10.0),
        };
        let (opts, stop, received, published) = (
            ns.options.clone(),
            stop.clone(),
            received.clone(),
            published.clone(),
        );
        let s = s.clone();
        threads.push(std::thread::spawn(move || -> Result<()> {
            let t = Transport::open(&format!("load_{}", s.name), &opts)?;
            let mut p = t.publisher(&s.input_service(), &s.qos, Hop::Ingress, frame.len())?;
            let sub = t.subscriber(&s.output_service(), &s.qos, None)?;
            if !p.wait_for_subscribers(1, Duration::from_secs(10)) {
                bail!("{}: the daemon did not subscribe", s.name);
            }
            let period = Duration::from_secs_f64(1.0 / hz);
            let start = Instant::now();
            let mut seq = 0u64;
            while !stop.load(Ordering::Relaxed) {
                let due = start + period * seq as u32;
                let now = Instant::now();
                if now >= due {
                    let h = frame.header(seq, &s.name)?;
                    match &frame {
                        Frame::Image(img) => p.publish_image(h, &img.view())?,
                        Frame::Cloud(cl) => p.publish_cloud(h, &cl.view())?,
                    };
                    published.fetch_add(1, Ordering::Relaxed);
                    seq += 1;
                }
                let wait = (start + period * seq as u32).saturating_duration_since(Instant::now());
                if let Some(_f) = sub.wait(wait.min(Duration::from_millis(50)))? {
                    received.fetch_add(1, Ordering::Relaxed);
                    while sub.receive()?.is_some() {
                        received.fetch_add(1, Ordering::Relaxed);
                    }
                }
            }
            // Collect what is still in flight.
            let end = Instant::now();
            while end.elapsed() < Duration::from_millis(500) {
                if sub.wait(Duration::from_millis(100))?.is_some() {
                    received.fetch_add(1, Ordering::Relaxed);
                }
            }
            Ok(())
        }));
    }
    let cpu0 = cpu_seconds(pid).unwrap_or(f64::NAN);
    let me0 = cpu_seconds(std::process::id()).unwrap_or(f64::NAN);
    let t0 = Instant::now();
    std::thread::sleep(Duration::from_secs_f64(seconds));
    let cpu1 = cpu_seconds(pid).unwrap_or(f64::NAN);
    let me1 = cpu_seconds(std::process::id()).unwrap_or(f64::NAN);
    let wall = t0.elapsed().as_secs_f64();
    stop.store(true, Ordering::Relaxed);
    for t in threads {
        t.join()
            .map_err(|_| anyhow::anyhow!("a publisher panicked"))??;
    }
    let report = daemon.stop();
    println!(
        "sustained load: {} streams for {wall:.0} s through one perturbd ({})",
        cfg.streams.len(),
        cfg_path.display()
    );
    println!(
        "{:<10} {:>7} {:>7} {:>7} {:>7} {:>8} {:>7} | {:>20} {:>20}",
        "stream",
        "in",
        "out",
        "dropped",
        "invalid",
        "overbudg",
        "active",
        "perturb p50/p99 ms",
        "in->out p50/p99 ms"
    );
    let (mut drops, mut outs) = (0, 0);
    for s in report["streams"].as_array().into_iter().flatten() {
        let l = &s["latency"];
        let g = |k: &str, p: &str| l[k][p].as_f64().unwrap_or(f64::NAN) / 1000.0;
        drops += s["dropped"].as_u64().unwrap_or(0);
        outs += s["frames_out"].as_u64().unwrap_or(0);
        println!(
            "{:<10} {:>7} {:>7} {:>7} {:>7} {:>8} {:>7} | {:>20} {:>20}",
            s["name"].as_str().unwrap_or("?"),
            s["frames_in"].as_u64().unwrap_or(0),
            s["frames_out"].as_u64().unwrap_or(0),
            s["dropped"].as_u64().unwrap_or(0),
            s["invalid"].as_u64().unwrap_or(0),
            s["over_budget"].as_u64().unwrap_or(0),
            s["id"].as_str().unwrap_or("off"),
            format!(
                "{:.2} / {:.2}",
                g("perturb", "p50_us"),
                g("perturb", "p99_us")
            ),
            format!(
                "{:.2} / {:.2}",
                g("ingress_to_tx", "p50_us"),
                g("ingress_to_tx", "p99_us")
            ),
        );
    }
    println!(
        "published {}, received {}, daemon published {outs}, dropped {drops}",
        published.load(Ordering::Relaxed),
        received.load(Ordering::Relaxed)
    );
    println!(
        "CPU: perturbd {:.0}% of one core ({:.1} s in {wall:.0} s); publishers+subscribers {:.0}%; machine has {} cores",
        100.0 * (cpu1 - cpu0) / wall,
        cpu1 - cpu0,
        100.0 * (me1 - me0) / wall,
        std::thread::available_parallelism().map_or(0, |n| n.get())
    );
    Ok(())
}

fn main() -> Result<()> {
    match Cli::parse().cmd {
        Cmd::Overhead { frames, hz } => overhead(frames, hz),
        Cmd::Load { seconds, config } => load(seconds, config),
    }
}
