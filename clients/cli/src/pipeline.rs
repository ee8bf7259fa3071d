//! Running the live pipeline from the `perturb` tool (`perturb demo`, `perturb bench --hil`):
//! `perturbd` and `perturb-bridge` as child processes in an iceoryx2 namespace private to this run,
//! fed by the synthetic sensors or a replayed bag, controlled over the daemon's control channel,
//! stopped cleanly (SIGINT) at the end.

use anyhow::{Context, Result, bail};
use perturb_core::registry::Modality;
use perturb_wire::control::{ControlClient, ControlRequest};
use perturb_wire::{Transport, TransportOptions};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

/// Where the frames come from.
pub enum Source {
    /// The synthetic street-scene camera (`camera_front`) and VLP-32C (`lidar_top`, 10 Hz).
    Synthetic {
        /// Camera width.
        width: u32,
        /// Camera height.
        height: u32,
        /// Camera rate (Hz).
        camera_hz: f64,
    },
    /// A rosbag2 MCAP bag, looped with its original timing; one stream per sensor topic.
    Bag(PathBuf),
}

/// What to run.
pub struct Options {
    /// Folder for the generated configurations, the logs and the JSON reports.
    pub out: PathBuf,
    /// The source.
    pub source: Source,
    /// Sensor model of the LiDAR streams.
    pub sensor: String,
    /// Record the raw and perturbed streams and the events into this bag directory.
    pub record: Option<PathBuf>,
}

/// A running pipeline. Dropping it kills the children; [`Pipeline::stop`] stops them cleanly.
pub struct Pipeline {
    daemon: Proc,
    bridge: Proc,
    client: ControlClient,
    /// This process's iceoryx2 node in the run's namespace (to subscribe to the streams).
    pub transport: Transport,
    /// The streams: (name, modality).
    pub streams: Vec<(String, Modality)>,
    /// The folder of the configurations, logs and reports.
    pub out: PathBuf,
    _cleanup: NamespaceCleanup,
}

impl Pipeline {
    /// Writes the configurations and starts `perturbd`, then `perturb-bridge` once the daemon
    /// answers.
    pub fn start(o: &Options) -> Result<Self> {
        let perturbd = sibling("perturbd")?;
        let bridge = sibling("perturb-bridge")?;
        std::fs::create_dir_all(&o.out)
            .with_context(|| format!("cannot create {}", o.out.display()))?;
        let out = o.out.canonicalize()?;
        let streams = streams_of(&o.source)?;
        let daemon_cfg = out.join("perturbd.toml");
        let bridge_cfg = out.join("bridge.toml");
        std::fs::write(&daemon_cfg, daemon_config(&streams, &o.sensor))?;
        std::fs::write(
            &bridge_cfg,
            bridge_config(&o.source, &streams, o.record.as_deref())?,
        )?;
        let pid = std::process::id();
        let ns = TransportOptions {
            prefix: Some(format!("perturb_run_{pid}_")),
            root: Some(std::env::temp_dir().join(format!("perturb-run-{pid}"))),
            iceoryx2_config: None,
        };
        let cleanup = NamespaceCleanup(ns.clone());
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
        let transport = Transport::open("perturb_tool", &ns)?;
        let client = wait_for_daemon(&transport, &mut daemon)?;
        let bridge = Proc::spawn(
            "perturb-bridge",
            Command::new(&bridge)
                .arg("--config")
                .arg(&bridge_cfg)
                .arg("--report")
                .arg(out.join("bridge-report.json")),
            &ns,
            &out.join("bridge.log"),
        )?;
        Ok(Pipeline {
            daemon,
            bridge,
            client,
            transport,
            streams,
            out,
            _cleanup: cleanup,
        })
    }

    /// Activates `id` at `severity` on `stream` from its next frame.
    pub fn set(&self, stream: &str, id: &str, severity: u8, seed: u64) -> Result<()> {
        let r = self.client.request(
            &ControlRequest::Set {
                stream: stream.into(),
                id: id.into(),
                severity,
                seed: Some(seed),
            },
            Duration::from_secs(5),
        )?;
        if !r.ok {
            bail!(
                "perturbd refused {id} on {stream}: {}",
                r.message.unwrap_or_default()
            );
        }
        Ok(())
    }

    /// Switches `stream`'s perturbation off.
    pub fn off(&self, stream: &str) -> Result<()> {
        let r = self.client.request(
            &ControlRequest::Off {
                stream: stream.into(),
            },
            Duration::from_secs(5),
        )?;
        if !r.ok {
            bail!("perturbd: {}", r.message.unwrap_or_default());
        }
        Ok(())
    }

    /// Every stream's counters and latencies (`perturb ctl stats`).
    pub fn stats(&self) -> Result<Vec<perturb_wire::control::StreamReport>> {
        let r = self
            .client
            .request(&ControlRequest::Stats, Duration::from_secs(5))?;
        if !r.ok {
            bail!("perturbd: {}", r.message.unwrap_or_default());
        }
        Ok(r.streams.unwrap_or_default())
    }

    /// An error if a child stopped.
    pub fn check_running(&mut self) -> Result<()> {
        for p in [&mut self.daemon, &mut self.bridge] {
            if let Some(st) = p.child.try_wait()? {
                bail!("{} stopped early ({st}); see {}", p.name, p.log.display());
            }
        }
        Ok(())
    }

    /// Stops the bridge, then the daemon (both write their reports).
    pub fn stop(mut self) -> Result<()> {
        self.bridge.stop(Duration::from_secs(30))?;
        self.daemon.stop(Duration::from_secs(15))
    }
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

/// The streams of a source: (name, modality).
fn streams_of(source: &Source) -> Result<Vec<(String, Modality)>> {
    let Source::Bag(bag) = source else {
        return Ok(vec![
            ("camera_front".into(), Modality::Camera),
            ("lidar_top".into(), Modality::Lidar),
        ]);
    };
    let b = perturb_bag::Bag::open(bag)?;
    let mut v = Vec::new();
    for t in b.topics()? {
        let m = match perturb_bag::SensorType::of(&t.type_name) {
            Some(perturb_bag::SensorType::Image | perturb_bag::SensorType::CompressedImage) => {
                Modality::Camera
            }
            Some(perturb_bag::SensorType::PointCloud2) => Modality::Lidar,
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
        "# Written by `perturb`, which switches perturbations at run time.\n\
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

fn bridge_config(
    source: &Source,
    streams: &[(String, Modality)],
    recording: Option<&Path>,
) -> Result<String> {
    let mut s = String::from(
        "# Written by `perturb`.\n[bridge]\nname = \"perturb_run\"\n\
         qos = { subscriber_buffer = 4 }\n",
    );
    match source {
        Source::Bag(bag) => {
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
        Source::Synthetic {
            width,
            height,
            camera_hz,
        } => {
            s += &format!(
                "\n[[synthetic.camera]]\nstream = \"camera_front\"\nwidth = {width}\nheight = {height}\n\
                 rate_hz = {camera_hz}\nframe_id = \"camera_front\"\nprerender = 30\n\n\
                 [[synthetic.lidar]]\nstream = \"lidar_top\"\nrate_hz = 10.0\n\
                 frame_id = \"velodyne\"\nprerender = 10\n"
            );
        }
    }
    if let Some(rec) = recording {
        let names: Vec<String> = streams.iter().map(|(n, _)| format!("\"{n}\"")).collect();
        s += &format!(
            "\n[record]\nout = \"{}\"\nstreams = [{}]\nraw = true\nperturbed = true\n",
            rec.display(),
            names.join(", ")
        );
    }
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
            bail!(
                "perturbd exited at start ({st}); see {}",
                daemon.log.display()
            );
        }
        if start.elapsed() > Duration::from_secs(30) {
            bail!(
                "perturbd did not answer within 30 s; see {}",
                daemon.log.display()
            );
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
        match perturb_wire::process::interrupt(&mut self.child, grace) {
            Some(st) if !st.success() => {
                eprintln!(
                    "warning: {} exited with {st}; see {}",
                    self.name,
                    self.log.display()
                );
                Ok(())
            }
            Some(_) => Ok(()),
            None => bail!("{} did not stop within {grace:?}; killed", self.name),
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
