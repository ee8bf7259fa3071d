//! `perturb demo`: the whole pipeline on this machine. Starts `perturbd` and `perturb-bridge` as
//! child processes in an iceoryx2 namespace of their own, feeds the synthetic camera and VLP-32C
//! (or a replayed bag) through the daemon, switches perturbations while it runs, records the raw
//! and perturbed streams with the perturbation events, stops everything cleanly and prints the
//! per-hop latency table.

use crate::pipeline::{Options, Pipeline, Source};
use anyhow::{Context, Result};
use perturb_core::registry::{self, Modality};
use serde_json::Value;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

/// Arguments of `perturb demo`.
#[derive(clap::Args)]
#[command(after_help = "Examples:
  perturb demo --out demo-out                       # synthetic sensors, 12 s
  perturb demo --bag ../shared/data/ros2_mcap_kitti_000001 --sensor hdl64e --seconds 20
  perturb demo --offline --out demo-out             # every perturbation once, no daemon

The demo needs the perturbd and perturb-bridge binaries next to perturb
(cargo build --release --workspace --bins). Everything it writes goes to --out: the
configurations it generated, the daemon's and the bridge's logs and JSON reports, and the
recording (a rosbag2 MCAP bag with /<stream>/raw, /<stream>/perturbed and /perturb/events).")]
pub struct Args {
    /// Where the recording, the configurations, the logs and the reports are written.
    #[arg(long, default_value = "demo-out")]
    out: PathBuf,
    /// How long the pipeline runs, in seconds.
    #[arg(long, default_value_t = 12.0)]
    seconds: f64,
    /// Replay this bag (rosbag2 MCAP, ROS 1 `.bag` or ROS 1 MCAP; looped, original timing) instead
    /// of the synthetic sensors:
    /// the hardware-in-the-loop path.
    #[arg(long)]
    bag: Option<PathBuf>,
    /// Sensor model of the bag's LiDAR streams (vlp32c, vlp16, hdl32e, hdl64e for KITTI).
    #[arg(long, default_value = "vlp32c")]
    sensor: String,
    /// Synthetic camera width.
    #[arg(long, default_value_t = 800)]
    width: u32,
    /// Synthetic camera height.
    #[arg(long, default_value_t = 503)]
    height: u32,
    /// Synthetic camera rate (Hz).
    #[arg(long, default_value_t = 30.0)]
    camera_hz: f64,
    /// Seconds each perturbation stays active before the next one.
    #[arg(long, default_value_t = 3.0)]
    switch_every: f64,
    /// No daemon: apply every perturbation once to a synthetic frame and scan in this process
    /// and write the results as PNG and PCD files.
    #[arg(long)]
    offline: bool,
}

/// What the demo cycles through: (camera, LiDAR) perturbations and severities.
const CYCLE: [(&str, u8, &str, u8); 4] = [
    ("C-C7", 3, "L-A9", 2),
    ("C-C3", 3, "L-C1", 2),
    ("C-B3", 3, "L-B3", 2),
    ("C-A1", 3, "L-A4", 2),
];

/// Runs `perturb demo`.
pub fn run(a: Args) -> Result<()> {
    if a.offline {
        return crate::demo_offline::run(&a.out, a.width, a.height);
    }
    let stamp = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| d.as_secs())
        .unwrap_or(0);
    std::fs::create_dir_all(&a.out)
        .with_context(|| format!("cannot create {}", a.out.display()))?;
    let recording = a.out.canonicalize()?.join(format!("recording-{stamp}"));
    let source = match &a.bag {
        Some(b) => Source::Bag(b.clone()),
        None => Source::Synthetic {
            width: a.width,
            height: a.height,
            camera_hz: a.camera_hz,
        },
    };
    println!(
        "perturb demo: {} -> iceoryx2 -> perturbd -> recorder, for {:.0} s",
        match &a.bag {
            Some(b) => format!("bag {} (looped)", b.display()),
            None => format!(
                "synthetic camera {}x{} at {} Hz + VLP-32C at 10 Hz",
                a.width, a.height, a.camera_hz
            ),
        },
        a.seconds
    );
    let mut p = Pipeline::start(&Options {
        out: a.out.clone(),
        source,
        sensor: a.sensor.clone(),
        record: Some(recording.clone()),
    })?;
    let start = Instant::now();
    let mut step = 0usize;
    let mut next_switch = Duration::ZERO;
    while start.elapsed().as_secs_f64() < a.seconds {
        p.check_running()?;
        if start.elapsed() >= next_switch {
            let (cam, cs, lid, ls) = CYCLE[step % CYCLE.len()];
            let mut said = Vec::new();
            for (name, modality) in &p.streams {
                let (id, sev) = match modality {
                    Modality::Camera => (cam, cs),
                    Modality::Lidar => (lid, ls),
                };
                p.set(name, id, sev, 1)?;
                said.push(format!("{name}: {id} {} s{sev}", registry::find(id)?.name));
            }
            println!(
                "  t={:>5.1}s  {}",
                start.elapsed().as_secs_f64(),
                said.join(" | ")
            );
            step += 1;
            next_switch += Duration::from_secs_f64(a.switch_every.max(0.5));
        }
        std::thread::sleep(Duration::from_millis(50));
    }
    let out = p.out.clone();
    p.stop()?;
    print_table(&out)?;
    println!(
        "\nperturbed frames: {} (rosbag2 MCAP: /<stream>/raw, /<stream>/perturbed, /perturb/events)",
        recording.display()
    );
    println!("configurations, logs and JSON reports: {}", out.display());
    Ok(())
}

fn f(v: &Value, path: &[&str]) -> f64 {
    let mut v = v;
    for p in path {
        v = &v[*p];
    }
    v.as_f64().unwrap_or(f64::NAN)
}

/// The per-hop latency table from the daemon's and the bridge's reports.
fn print_table(out: &Path) -> Result<()> {
    let read = |p: PathBuf| -> Result<Value> {
        let text =
            std::fs::read_to_string(&p).with_context(|| format!("cannot read {}", p.display()))?;
        Ok(serde_json::from_str(&text)?)
    };
    let daemon = read(out.join("perturbd-report.json"))?;
    let bridge = read(out.join("bridge-report.json"))?;
    println!(
        "\n{:<44} {:>6} {:>6} {:>5} {:>5} | {:>17} {:>17} {:>17} {:>17}",
        "stream",
        "in",
        "out",
        "drop",
        "inval",
        "source->daemon",
        "perturb",
        "daemon->sink",
        "total"
    );
    println!(
        "{:<44} {:>6} {:>6} {:>5} {:>5} | {:>17} {:>17} {:>17} {:>17}",
        "", "", "", "", "", "p50/p99 ms", "p50/p99 ms", "p50/p99 ms", "p50/p99 ms"
    );
    let empty = Vec::new();
    for s in daemon["streams"].as_array().unwrap_or(&empty) {
        let name = s["name"].as_str().unwrap_or("?");
        let hops = bridge
            .as_array()
            .unwrap_or(&empty)
            .iter()
            .find_map(|r| {
                let h = &r["hops"][format!("{name}/perturbed")];
                (!h.is_null()).then(|| h.clone())
            })
            .unwrap_or(Value::Null);
        let pair = |a: f64, b: f64| {
            if a.is_nan() {
                "-".to_string()
            } else {
                format!("{a:.2}/{b:.2}")
            }
        };
        let us = |k: &str, p: &str| f(s, &["latency", k, p]) / 1000.0;
        println!(
            "{:<44} {:>6} {:>6} {:>5} {:>5} | {:>17} {:>17} {:>17} {:>17}",
            name,
            s["frames_in"].as_u64().unwrap_or(0),
            s["frames_out"].as_u64().unwrap_or(0),
            s["dropped"].as_u64().unwrap_or(0),
            s["invalid"].as_u64().unwrap_or(0),
            pair(us("ingress_to_rx", "p50_us"), us("ingress_to_rx", "p99_us")),
            pair(us("perturb", "p50_us"), us("perturb", "p99_us")),
            pair(
                f(&hops, &["to_sink", "p50_ms"]),
                f(&hops, &["to_sink", "p99_ms"])
            ),
            pair(
                f(&hops, &["total", "p50_ms"]),
                f(&hops, &["total", "p99_ms"])
            ),
        );
    }
    Ok(())
}
