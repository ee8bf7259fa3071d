//! `perturb demo`: the whole pipeline on this machine. Starts `perturbd` and `perturb-bridge` as
//! child processes in an iceoryx2 namespace of their own, feeds the synthetic camera and VLP-32C
//! (or a replayed bag) through the daemon, switches perturbations while it runs, records the raw
//! and perturbed streams with the perturbation events, stops everything cleanly and prints the
//! per-hop latency table.

use anyhow::{Context, Result, bail};
use perturb_core::registry::{self, Modality};
use perturb_wire::TransportOptions;
use perturb_wire::control::{ControlClient, ControlRequest};
use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
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
    /// Replay this rosbag2 MCAP bag (looped, original timing) instead of the synthetic sensors:
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
    let perturbd = sibling("perturbd")?;
    let bridge = sibling("perturb-bridge")?;
    std::fs::create_dir_all(&a.out)
        .with_context(|| format!("cannot create {}", a.out.display()))?;
    let out = a.out.canonicalize()?;
    let stamp = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| d.as_secs())
        .unwrap_or(0);
    let recording = out.join(format!("recording-{stamp}"));
    let streams = streams_of(&a)?;
    let daemon_cfg = out.join("perturbd.toml");
    let bridge_cfg = out.join("bridge.toml");
    std::fs::write(&daemon_cfg, daemon_config(&streams, &a.sensor))?;
    std::fs::write(&bridge_cfg, bridge_config(&a, &streams, &recording)?)?;

    let ns = TransportOptions {
        prefix: Some(format!("perturb_demo_{}_", std::process::id())),
        root: Some(std::env::temp_dir().join(format!("perturb-demo-{}", std::process::id()))),
        iceoryx2_config: None,
    };
    let _cleanup = NamespaceCleanup(ns.clone());
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
    let mut daemon = Proc::spawn(
        "perturbd",
        Command::new(&perturbd)
            .arg("--config")
            .arg(&daemon_cfg)
            .arg("--report")
            .arg(out.join("perturbd-report.json")),
        &ns,
        &out.join("perturbd.log"),
    )?;
    let transport = perturb_wire::Transport::open("perturb_demo", &ns)?;
    let client = wait_for_daemon(&transport, &mut daemon)?;
    let mut bridge_proc = Proc::spawn(
        "perturb-bridge",
        Command::new(&bridge)
            .arg("--config")
            .arg(&bridge_cfg)
            .arg("--report")
            .arg(out.join("bridge-report.json")),
        &ns,
        &out.join("bridge.log"),
    )?;

    let start = Instant::now();
    let mut step = 0usize;
    let mut next_switch = Duration::ZERO;
    while start.elapsed().as_secs_f64() < a.seconds {
        if let Some(st) = bridge_proc.child.try_wait()? {
            bail!(
                "perturb-bridge stopped early ({st}); see {}",
                out.join("bridge.log").display()
            );
        }
        if let Some(st) = daemon.child.try_wait()? {
            bail!(
                "perturbd stopped early ({st}); see {}",
                out.join("perturbd.log").display()
            );
        }
        if start.elapsed() >= next_switch {
            let (cam, cs, lid, ls) = CYCLE[step % CYCLE.len()];
            let mut said = Vec::new();
            for (name, modality) in &streams {
                let (id, sev) = match modality {
                    Modality::Camera => (cam, cs),
                    Modality::Lidar => (lid, ls),
                };
                let r = client.request(
                    &ControlRequest::Set {
                        stream: name.clone(),
                        id: id.into(),
                        severity: sev,
                        seed: Some(1),
                    },
                    Duration::from_secs(3),
                )?;
                if !r.ok {
                    bail!(
                        "perturbd refused {id} on {name}: {}",
                        r.message.unwrap_or_default()
                    );
                }
                let e = registry::find(id)?;
                said.push(format!("{name}: {id} {} s{sev}", e.name));
            }
            println!("  t={:>5.1}s  {}", start.elapsed().as_secs_f64(), said.join(" | "));
            step += 1;
            next_switch += Duration::from_secs_f64(a.switch_every.max(0.5));
        }
        std::thread::sleep(Duration::from_millis(50));
    }
    bridge_proc.stop(Duration::from_secs(30))?;
    daemon.stop(Duration::from_secs(15))?;
    print_table(&out)?;
    println!(
        "\nperturbed frames: {} (rosbag2 MCAP: /<stream>/raw, /<stream>/perturbed, /perturb/events)",
        recording.display()
    );
    println!(
        "configurations, logs and JSON reports: {}",
        out.display()
    );
    Ok(())
}

/// A binary next to this one.
fn sibling(name: &str) -> Result<PathBuf> {
    let me = std::env::current_exe()?;
    let p = me.with_file_name(name);
    if p.exists() {
        Ok(p)
    } else {
        bail!(
            "{} is missing: the demo starts it as a child process; build every binary with \
             `cargo build --release --workspace --bins` (or use `perturb demo --offline`)",
            p.display()
        )
    }
}

/// The streams of the run: (name, modality).
fn streams_of(a: &Args) -> Result<Vec<(String, Modality)>> {
    let Some(bag) = &a.bag else {
        return Ok(vec![
            ("camera_front".into(), Modality::Camera),
            ("lidar_top".into(), Modality::Lidar),
        ]);
    };
    let b = perturb_bag::Bag::open(bag)?;
    let mut v = Vec::new();
    for t in b.topics()? {
        let m = match t.type_name.as_str() {
            "sensor_msgs/msg/Image" | "sensor_msgs/msg/CompressedImage" => Modality::Camera,
            "sensor_msgs/msg/PointCloud2" => Modality::Lidar,
            _ => continue,
        };
        v.push((stream_name(&t.topic), m));
    }
    if v.is_empty() {
        bail!(
            "{}: no Image, CompressedImage or PointCloud2 topic to replay",
            bag.display()
        );
    }
    Ok(v)
}

/// `/kitti/velo/pointcloud` -> `kitti_velo_pointcloud`.
fn stream_name(topic: &str) -> String {
    topic
        .trim_start_matches('/')
        .chars()
        .map(|c| if c.is_ascii_alphanumeric() { c } else { '_' })
        .collect()
}

fn daemon_config(streams: &[(String, Modality)], sensor: &str) -> String {
    let mut s = String::from(
        "# Written by `perturb demo`. The demo switches perturbations at run time.\n\
         [daemon]\nstats_interval_s = 5\n",
    );
    for (name, m) in streams {
        s += &format!("\n[[streams]]\nname = \"{name}\"\n");
        match m {
            Modality::Camera => s += "modality = \"camera\"\n",
            Modality::Lidar => s += &format!("modality = \"lidar\"\nsensor = \"{sensor}\"\n"),
        }
        s += "qos = { subscriber_buffer = 4 }\n";
    }
    s
}

fn bridge_config(a: &Args, streams: &[(String, Modality)], recording: &Path) -> Result<String> {
    let mut s = String::from(
        "# Written by `perturb demo`.\n[bridge]\nname = \"perturb_demo\"\n\
         qos = { subscriber_buffer = 4 }\n",
    );
    let names: Vec<String> = streams.iter().map(|(n, _)| format!("\"{n}\"")).collect();
    match &a.bag {
        Some(bag) => {
            let bag = bag
                .canonicalize()
                .with_context(|| format!("{}", bag.display()))?;
            s += &format!(
                "\n[replay]\nbag = \"{}\"\nrate = 1.0\nloop = true\n[replay.topics]\n",
                bag.display()
            );
            for t in perturb_bag::Bag::open(&bag)?.topics()? {
                let name = stream_name(&t.topic);
                if streams.iter().any(|(n, _)| *n == name) {
                    s += &format!("\"{}\" = \"{name}\"\n", t.topic);
                }
            }
        }
        None => {
            s += &format!(
                "\n[[synthetic.camera]]\nstream = \"camera_front\"\nwidth = {}\nheight = {}\n\
                 rate_hz = {}\nframe_id = \"camera_front\"\nprerender = 30\n\n\
                 [[synthetic.lidar]]\nstream = \"lidar_top\"\nrate_hz = 10.0\n\
                 frame_id = \"velodyne\"\nprerender = 10\n",
                a.width, a.height, a.camera_hz
            );
        }
    }
    s += &format!(
        "\n[record]\nout = \"{}\"\nstreams = [{}]\nraw = true\nperturbed = true\n",
        recording.display(),
        names.join(", ")
    );
    Ok(s)
}

fn wait_for_daemon(t: &perturb_wire::Transport, daemon: &mut Proc) -> Result<ControlClient> {
    let start = Instant::now();
    loop {
        if let Ok(c) = ControlClient::connect(t, perturb_wire::names::CONTROL)
            && c.request(&ControlRequest::Status, Duration::from_millis(500))
                .is_ok_and(|r| r.ok)
        {
            return Ok(c);
        }
        if let Some(st) = daemon.child.try_wait()? {
            bail!("perturbd exited at start ({st}); see {}", daemon.log.display());
        }
        if start.elapsed() > Duration::from_secs(30) {
            bail!("perturbd did not answer within 30 s; see {}", daemon.log.display());
        }
        std::thread::sleep(Duration::from_millis(100));
    }
}

/// A child process with its log file.
struct Proc {
    name: &'static str,
    child: Child,
    log: PathBuf,
}

impl Proc {
    fn spawn(
        name: &'static str,
        cmd: &mut Command,
        ns: &TransportOptions,
        log: &Path,
    ) -> Result<Self> {
        let file = std::fs::File::create(log)?;
        for (k, v) in ns.to_env() {
            cmd.env(k, v);
        }
        let child = cmd
            .stdout(file.try_clone()?)
            .stderr(file)
            .stdin(Stdio::null())
            .spawn()
            .with_context(|| format!("cannot start {name}"))?;
        Ok(Proc {
            name,
            child,
            log: log.to_path_buf(),
        })
    }

    /// SIGINT, then waits up to `grace` before SIGKILL.
    fn stop(&mut self, grace: Duration) -> Result<()> {
        // SAFETY: kill(2) on our own child's pid.
        unsafe {
            libc::kill(self.child.id() as i32, libc::SIGINT);
        }
        let start = Instant::now();
        loop {
            if let Some(st) = self.child.try_wait()? {
                if !st.success() {
                    eprintln!(
                        "warning: {} exited with {st}; see {}",
                        self.name,
                        self.log.display()
                    );
                }
                return Ok(());
            }
            if start.elapsed() > grace {
                let _ = self.child.kill();
                let _ = self.child.wait();
                bail!("{} did not stop within {grace:?}; killed", self.name);
            }
            std::thread::sleep(Duration::from_millis(20));
        }
    }
}

impl Drop for Proc {
    fn drop(&mut self) {
        if let Ok(None) = self.child.try_wait() {
            let _ = self.child.kill();
            let _ = self.child.wait();
        }
    }
}

struct NamespaceCleanup(TransportOptions);

impl Drop for NamespaceCleanup {
    fn drop(&mut self) {
        let _ = self.0.remove_namespace_files();
    }
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
        "stream", "in", "out", "drop", "inval", "source->daemon", "perturb", "daemon->sink", "total"
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
            pair(f(&hops, &["total", "p50_ms"]), f(&hops, &["total", "p99_ms"])),
        );
    }
    Ok(())
}
