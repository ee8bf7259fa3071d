//! `perturb-bridge`: ROS 2 (DDS) and ROS 1 (TCPROS) ingress and egress, bag replay and record
//! (rosbag2 MCAP, ROS 1 `.bag`), the synthetic sensor source, around the perturbation daemon
//! `perturbd`.

use anyhow::{Context, Result};
use clap::{Args, Parser, Subcommand};
use perturb_bridge::config::{
    BusKind, Config, EgressEntry, RecordSection, ReplaySection, SyntheticCamera, SyntheticLidar,
};
use perturb_bridge::dds::{BackendKind, Qos};
use perturb_bridge::frame::StreamKind;
use perturb_bridge::run;
use std::path::PathBuf;
use std::time::Duration;

/// Sensor bridges of the perturbation middleware.
///
/// With `--config FILE.toml` it runs the adapters the file describes (see config/bridge-*.toml).
/// The subcommands are shortcuts for common set-ups.
#[derive(Parser)]
#[command(name = "perturb-bridge", version, about, long_about)]
struct Cli {
    /// The configuration file.
    #[arg(long, short)]
    config: Option<PathBuf>,
    /// Only check the configuration, then exit.
    #[arg(long)]
    check: bool,
    /// Seconds to wait, once every finite source is done, for the sinks to receive the last
    /// frames through the daemon.
    #[arg(long, default_value_t = 2.0)]
    linger: f64,
    /// Write the end-of-run report (JSON) here.
    #[arg(long)]
    report: Option<PathBuf>,
    #[command(subcommand)]
    command: Option<Command>,
}

#[derive(Subcommand)]
enum Command {
    /// Replay a bag (rosbag2 MCAP, ROS 1 .bag or ROS 1 MCAP) into the raw streams with its
    /// original timing.
    Replay(ReplayArgs),
    /// Record streams (raw and perturbed) into a bag with the perturbation events.
    Record(RecordArgs),
    /// Run the synthetic camera and VLP-32C.
    Synthetic(SyntheticArgs),
}

/// The arguments of `perturb-bridge replay`.
#[derive(Args)]
struct ReplayArgs {
    /// The bag (`.mcap` file, rosbag2 directory, or ROS 1 `.bag` file).
    bag: PathBuf,
    /// Speed factor (0 = as fast as possible).
    #[arg(long, default_value_t = 1.0)]
    rate: f64,
    /// Seconds to skip at the start.
    #[arg(long, default_value_t = 0.0)]
    start: f64,
    /// Start again at the end.
    #[arg(long = "loop")]
    looped: bool,
    /// TOPIC or TOPIC=STREAM (repeatable; default: every sensor topic, stream = topic without `/`).
    #[arg(long = "topic")]
    topics: Vec<String>,
    /// Bus: iceoryx2 (through perturbd) or local (no daemon: a plain player).
    #[arg(long, default_value = "iceoryx2")]
    bus: String,
    /// Also publish every replayed stream on ROS 2 as PREFIX + the bag topic.
    #[arg(long)]
    ros_prefix: Option<String>,
    /// DDS backend for --ros-prefix.
    #[arg(long, default_value = "rustdds")]
    dds: String,
    /// Network interface DDS may use for --ros-prefix (name or IPv4 address; repeatable;
    /// default: the DDS implementation's choice). `lo` keeps it on this computer.
    #[arg(long = "dds-interface")]
    dds_interfaces: Vec<String>,
    /// Publish the --ros-prefix topics on ROS 1 (TCPROS; master from ROS_MASTER_URI)
    /// instead of ROS 2.
    #[arg(long)]
    ros1: bool,
    /// Publish the bag's time on the ROS 1 topic /clock (for nodes with use_sim_time).
    #[arg(long)]
    clock: bool,
    /// Also record the streams into this bag (a directory; a `.bag` path records a ROS 1 bag).
    #[arg(long)]
    record: Option<PathBuf>,
}

/// The arguments of `perturb-bridge record`.
#[derive(Args)]
struct RecordArgs {
    /// Output: the bag directory (mcap), or the `.bag` file (bag1; without the extension a
    /// directory holding NAME.bag).
    #[arg(long)]
    out: PathBuf,
    /// Bag format: mcap (rosbag2 MCAP) or bag1 (ROS 1 .bag).
    #[arg(long, default_value = "mcap")]
    format: String,
    /// STREAM=image or STREAM=cloud (repeatable).
    #[arg(long = "stream", required = true)]
    streams: Vec<String>,
    /// Only the raw side.
    #[arg(long, conflicts_with = "perturbed_only")]
    raw_only: bool,
    /// Only the perturbed side (and the events).
    #[arg(long)]
    perturbed_only: bool,
    /// Stop after this many frames per stream (default: until SIGINT/SIGTERM).
    #[arg(long)]
    max_frames: Option<u64>,
    /// Stop after this many seconds (default: until SIGINT/SIGTERM).
    #[arg(long)]
    seconds: Option<f64>,
    /// Bus.
    #[arg(long, default_value = "iceoryx2")]
    bus: String,
    /// Chunk compression: for mcap zstd (the default), zstd:LEVEL (1..19), lz4 or none; for
    /// bag1 none (the default), bz2 or lz4.
    #[arg(long)]
    compression: Option<String>,
}

/// The arguments of `perturb-bridge synthetic`.
#[derive(Args)]
struct SyntheticArgs {
    /// Camera stream (empty: no camera).
    #[arg(long, default_value = "camera_front")]
    camera: String,
    /// Camera size WxH.
    #[arg(long, default_value = "1920x1208")]
    size: String,
    /// Camera rate.
    #[arg(long, default_value_t = 30.0)]
    camera_hz: f64,
    /// LiDAR stream (empty: no LiDAR).
    #[arg(long, default_value = "lidar_top")]
    lidar: String,
    /// LiDAR rate.
    #[arg(long, default_value_t = 10.0)]
    lidar_hz: f64,
    /// Frames per sensor (default: until stopped).
    #[arg(long)]
    count: Option<u64>,
    /// Bus.
    #[arg(long, default_value = "iceoryx2")]
    bus: String,
}

fn bus_kind(s: &str) -> Result<BusKind> {
    match s {
        "iceoryx2" | "iox2" => Ok(BusKind::Iceoryx2),
        "local" => Ok(BusKind::Local),
        o => anyhow::bail!("--bus: unknown bus `{o}` (iceoryx2, local)"),
    }
}

fn config_of(cli: &Cli) -> Result<Config> {
    let mut cfg = match (&cli.config, &cli.command) {
        (Some(path), None) => Config::load(path)?,
        (None, Some(cmd)) => command_config(cmd)?,
        (Some(_), Some(_)) => anyhow::bail!("give either --config or a subcommand, not both"),
        (None, None) => anyhow::bail!(
            "nothing to do: give --config FILE.toml or a subcommand (replay, record, synthetic); see --help"
        ),
    };
    if cli.report.is_some() {
        cfg.bridge.report = cli.report.clone();
    }
    Ok(cfg)
}

fn command_config(cmd: &Command) -> Result<Config> {
    let mut cfg = Config::default();
    match cmd {
        Command::Replay(a) => replay_config(a, &mut cfg)?,
        Command::Record(a) => record_config(a, &mut cfg)?,
        Command::Synthetic(a) => synthetic_config(a, &mut cfg)?,
    }
    cfg.validate("(command line)")?;
    Ok(cfg)
}

/// `replay`: the bag as the source, optionally republished on ROS (`--ros-prefix`) and recorded.
fn replay_config(a: &ReplayArgs, cfg: &mut Config) -> Result<()> {
    let ReplayArgs {
        bag,
        rate,
        start,
        looped,
        topics,
        bus,
        ros_prefix,
        dds,
        dds_interfaces,
        ros1,
        clock,
        record,
    } = a;
    cfg.ros1.clock = *clock;
    cfg.bridge.bus = bus_kind(bus)?;
    cfg.dds.backend = dds.parse::<BackendKind>().map_err(anyhow::Error::msg)?;
    cfg.dds.interfaces = dds_interfaces.clone();
    let mut map = std::collections::BTreeMap::new();
    for t in topics {
        let (topic, stream) = match t.split_once('=') {
            Some((a, b)) => (a.to_string(), b.to_string()),
            None => (t.clone(), perturb_bridge::replay::default_stream(t)),
        };
        map.insert(topic, stream);
    }
    cfg.replay = Some(ReplaySection {
        bag: bag.clone(),
        rate: *rate,
        start_offset: *start,
        looped: *looped,
        topics: map,
    });
    let replay =
        perturb_bridge::replay::Replay::open(cfg.replay.clone().context("replay section")?)?;
    let routes: Vec<(String, String, StreamKind)> = replay
        .routes
        .iter()
        .map(|(t, (s, k))| (t.clone(), s.clone(), *k))
        .collect();
    if let Some(prefix) = ros_prefix {
        for (topic, stream, kind) in &routes {
            cfg.egress.push(EgressEntry {
                stream: stream.clone(),
                topic: format!("{}{}", prefix.trim_end_matches('/'), topic),
                kind: Some(*kind),
                transport: if *ros1 {
                    perturb_bridge::config::Transport::Ros1
                } else {
                    perturb_bridge::config::Transport::Dds
                },
                qos: Qos::default(),
                deadline_ms: None,
                rate_hz: None,
                on_late: Default::default(),
                camera_info: None,
            });
        }
    }
    if let Some(out) = record {
        cfg.record = Some(RecordSection {
            out: out.clone(),
            streams: routes.iter().map(|r| r.1.clone()).collect(),
            raw: true,
            perturbed: cfg.bridge.bus == BusKind::Iceoryx2,
            format: Some(if out.extension().is_some_and(|e| e == "bag") {
                "bag1".into()
            } else {
                "mcap".into()
            }),
            compression: None,
            max_frames: None,
            seconds: None,
        });
    }
    Ok(())
}

/// `record`: the given streams into a bag.
fn record_config(a: &RecordArgs, cfg: &mut Config) -> Result<()> {
    let RecordArgs {
        out,
        format,
        streams,
        raw_only,
        perturbed_only,
        max_frames,
        seconds,
        bus,
        compression,
    } = a;
    cfg.bridge.bus = bus_kind(bus)?;
    let mut names = Vec::new();
    for s in streams {
        let (name, kind) = s
            .split_once('=')
            .with_context(|| format!("--stream `{s}`: say STREAM=image or STREAM=cloud"))?;
        let kind = match kind {
            "image" => StreamKind::Image,
            "cloud" => StreamKind::Cloud,
            o => anyhow::bail!("--stream `{s}`: unknown kind `{o}` (image, cloud)"),
        };
        names.push(name.to_string());
        cfg.streams.insert(name.to_string(), kind);
    }
    cfg.record = Some(RecordSection {
        out: out.clone(),
        streams: names,
        raw: !perturbed_only,
        perturbed: !raw_only,
        format: Some(format.clone()),
        compression: compression.clone(),
        max_frames: *max_frames,
        seconds: *seconds,
    });
    Ok(())
}

/// `synthetic`: the synthetic camera and LiDAR as sources.
fn synthetic_config(a: &SyntheticArgs, cfg: &mut Config) -> Result<()> {
    let SyntheticArgs {
        camera,
        size,
        camera_hz,
        lidar,
        lidar_hz,
        count,
        bus,
    } = a;
    cfg.bridge.bus = bus_kind(bus)?;
    let (w, h) = size
        .split_once('x')
        .and_then(|(w, h)| Some((w.parse().ok()?, h.parse().ok()?)))
        .with_context(|| format!("--size `{size}`: expected WxH, e.g. 1920x1208"))?;
    if !camera.is_empty() {
        cfg.synthetic.camera.push(SyntheticCamera {
            stream: camera.clone(),
            width: w,
            height: h,
            rate_hz: *camera_hz,
            frame_id: "camera_front".into(),
            // As many of 30 as fit in the pre-render memory bound.
            prerender: perturb_bridge::config::prerender_that_fits(w, h, 30),
            count: *count,
        });
    }
    if !lidar.is_empty() {
        cfg.synthetic.lidar.push(SyntheticLidar {
            stream: lidar.clone(),
            rate_hz: *lidar_hz,
            frame_id: "velodyne".into(),
            prerender: 10,
            count: *count,
        });
    }
    Ok(())
}

fn main() {
    use tracing_subscriber::prelude::*;
    let filter = tracing_subscriber::EnvFilter::try_from_default_env()
        .unwrap_or_else(|_| "info,rustdds=warn,ros2_client=warn".into());
    let (filter, reload) = tracing_subscriber::reload::Layer::new(filter);
    tracing_subscriber::registry()
        .with(filter)
        .with(tracing_subscriber::fmt::layer().with_writer(std::io::stderr))
        .init();
    // Tearing the DDS participants down at the end makes RustDDS log errors that mean nothing
    // (leaving multicast groups, removing writers from closed channels): silence it then.
    run::on_stopping(Box::new(move || {
        let _ = reload.modify(|f| {
            *f = tracing_subscriber::EnvFilter::new(format!("{f},rustdds=off,ros2_client=off"));
        });
    }));
    let cli = Cli::parse();
    if let Err(e) = real_main(cli) {
        eprintln!("error: {e:#}");
        std::process::exit(1);
    }
}

fn real_main(cli: Cli) -> Result<()> {
    let cfg = config_of(&cli)?;
    if cli.check {
        // What the run resolves before it starts: the replay bag and its topics, stream kinds.
        run::resolve(&cfg)?;
        println!("configuration OK");
        return Ok(());
    }
    run::install_signal_handlers();
    let plan = run::plan(&cfg)?;
    let bus = run::make_bus(&cfg)?;
    let outcome = run::run(plan, bus, Duration::from_secs_f64(cli.linger.max(0.0)))?;
    let reports = outcome.reports;
    run::print_reports(&reports);
    println!("stopped: {}", outcome.stopped_by);
    if let Some(path) = &cfg.bridge.report {
        std::fs::write(path, serde_json::to_string_pretty(&reports)?)
            .with_context(|| format!("cannot write the report {}", path.display()))?;
    }
    Ok(())
}
