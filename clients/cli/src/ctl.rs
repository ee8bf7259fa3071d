//! `perturb ctl`: runtime control of a running `perturbd` over its iceoryx2 control channel.

use anyhow::{Result, bail};
use perturb_wire::control::{
    ControlClient, ControlRequest, ControlResponse, LatencySummary, StreamReport,
};
use perturb_wire::{Transport, TransportOptions, names};
use std::path::PathBuf;
use std::time::Duration;

/// Arguments of `perturb ctl`.
#[derive(clap::Args)]
#[command(after_help = "Examples:
  perturb ctl set cam_front C-C7 --severity 3 --seed 42
  perturb ctl off cam_front
  perturb ctl off --all --reason 'safety driver took over'   # the kill switch (latched)
  perturb ctl arm                                              # release it
  perturb ctl campaign config/campaign.toml   # run a campaign; `perturb ctl next` for its manual steps
  perturb ctl status
  perturb ctl stats --json

A change takes effect on the stream's next frame; the daemon acknowledges it (or says why not).
`off --all` is the kill switch: every stream passes raw frames from its next frame on and stays so,
across daemon restarts too, until `perturb ctl arm`; then each stream runs what it is set to.
The daemon is found in the iceoryx2 namespace given by --iox2-prefix/--iox2-root/--iox2-config,
else by $PERTURB_IOX2_PREFIX, $PERTURB_IOX2_ROOT, $PERTURB_IOX2_CONFIG, else iceoryx2's defaults.")]
pub struct Args {
    #[command(subcommand)]
    command: Command,
    /// The daemon's control service (`[daemon] control_service`).
    #[arg(long, global = true, default_value = names::CONTROL)]
    service: String,
    /// iceoryx2 file prefix of the daemon's namespace.
    #[arg(long, global = true)]
    iox2_prefix: Option<String>,
    /// iceoryx2 root directory of the daemon's namespace.
    #[arg(long, global = true)]
    iox2_root: Option<PathBuf>,
    /// iceoryx2 config file of the daemon's namespace.
    #[arg(long, global = true)]
    iox2_config: Option<PathBuf>,
    /// Seconds to wait for the daemon's answer.
    #[arg(long, global = true, default_value_t = 3.0)]
    timeout: f64,
}

#[derive(clap::Subcommand)]
enum Command {
    /// Activate a perturbation on a stream from its next frame on.
    Set {
        /// Stream name (see `perturb ctl status`).
        stream: String,
        /// Perturbation ID or name (see `perturb list`).
        id: String,
        /// Severity: 1..5 for camera, 1..3 for LiDAR perturbations.
        #[arg(long, value_parser = clap::value_parser!(u8).range(1..=5))]
        severity: u8,
        /// Seed (default: the stream's current seed).
        #[arg(long)]
        seed: Option<u64>,
    },
    /// Switch a stream's perturbation off (frames are forwarded unchanged), or with `--all`
    /// engage the kill switch.
    Off {
        /// Stream name.
        #[arg(required_unless_present = "all", conflicts_with = "all")]
        stream: Option<String>,
        /// The kill switch: every stream passes raw frames from the next frame on, latched until
        /// `perturb ctl arm` (also across daemon restarts).
        #[arg(long)]
        all: bool,
        /// Why (logged by the daemon and reported by `status`), with `--all`.
        #[arg(long, requires = "all")]
        reason: Option<String>,
    },
    /// Release the kill switch: every stream runs what it is set to from its next frame on.
    Arm,
    /// The running campaign's next manual step.
    Next,
    /// Start a campaign (its streams follow its steps from now on), end it with `--stop`, or
    /// show the running one.
    Campaign {
        /// The campaign file (TOML; see config/campaign.toml), as the daemon's machine sees it.
        file: Option<PathBuf>,
        /// End the running campaign (its streams pass raw frames).
        #[arg(long, conflicts_with = "file")]
        stop: bool,
    },
    /// Show every stream's active perturbation and counters.
    Status {
        /// Print JSON: an array with one object per stream.
        #[arg(long)]
        json: bool,
    },
    /// Show every stream's counters and latency percentiles.
    Stats {
        /// Print JSON: an array with one object per stream.
        #[arg(long)]
        json: bool,
    },
}

/// Runs `perturb ctl`.
pub fn run(a: Args) -> Result<()> {
    let mut opts = TransportOptions::from_env();
    if a.iox2_prefix.is_some() {
        opts.prefix = a.iox2_prefix.clone();
    }
    if a.iox2_root.is_some() {
        opts.root = a.iox2_root.clone();
    }
    if a.iox2_config.is_some() {
        opts.iceoryx2_config = a.iox2_config.clone();
    }
    if !a.timeout.is_finite() || a.timeout <= 0.0 {
        bail!("--timeout must be a positive number of seconds");
    }
    let node = format!("perturb_ctl_{}", std::process::id());
    let transport = Transport::open(&node, &opts)?;
    let client = ControlClient::connect(&transport, &a.service)?;
    let timeout = Duration::from_secs_f64(a.timeout);
    let (request, json, latency) = match a.command {
        Command::Set {
            stream,
            id,
            severity,
            seed,
        } => (
            ControlRequest::Set {
                stream,
                id,
                severity,
                seed,
            },
            false,
            false,
        ),
        Command::Off {
            all: true, reason, ..
        } => (
            ControlRequest::Kill {
                reason: Some(reason.unwrap_or_else(|| "perturb ctl off --all".into())),
            },
            false,
            false,
        ),
        Command::Off { stream, .. } => (
            ControlRequest::Off {
                stream: stream.unwrap_or_default(),
            },
            false,
            false,
        ),
        Command::Arm => (ControlRequest::Arm, false, false),
        Command::Next => (ControlRequest::Next, false, false),
        Command::Campaign { file, stop } => (
            ControlRequest::Campaign {
                // The daemon reads the file: hand it an absolute path.
                file: file.map(|f| {
                    std::path::absolute(&f)
                        .unwrap_or(f)
                        .to_string_lossy()
                        .into_owned()
                }),
                stop,
            },
            false,
            false,
        ),
        Command::Status { json } => (ControlRequest::Status, json, false),
        Command::Stats { json } => (ControlRequest::Stats, json, true),
    };
    let resp = client.request(&request, timeout)?;
    print_response(&resp, json, latency)
}

fn print_response(resp: &ControlResponse, json: bool, latency: bool) -> Result<()> {
    if !resp.ok {
        bail!(
            "perturbd refused: {}",
            resp.error.as_deref().unwrap_or("no reason given")
        );
    }
    if let Some(m) = &resp.message {
        println!("{m}");
    }
    if let (Some(c), false) = (&resp.campaign, json) {
        println!(
            "campaign `{}` ({}): {:.1} s, {} next; position {}; active: {}",
            c.name,
            c.file,
            c.elapsed_s,
            c.next,
            match (c.pose, c.arc_length_m) {
                (Some(p), Some(s)) =>
                    format!("({:.1}, {:.1}), {s:.1} m along the route", p[0], p[1]),
                (Some(p), None) => format!("({:.1}, {:.1})", p[0], p[1]),
                _ => "none yet".into(),
            },
            if c.active.is_empty() {
                "none".to_string()
            } else {
                c.active.join(", ")
            }
        );
    }
    if let (Some(k), false, Some(_)) = (&resp.killed, json, &resp.streams) {
        println!(
            "KILL SWITCH ENGAGED ({}): every stream passes raw frames until `perturb ctl arm`",
            k.reason
        );
    }
    if let Some(streams) = &resp.streams {
        if json {
            println!("{}", serde_json::to_string_pretty(streams)?);
        } else if latency {
            print_stats(streams);
        } else {
            print_status(streams);
        }
    }
    Ok(())
}

fn print_status(streams: &[StreamReport]) {
    println!(
        "{:<16} {:<8} {:<28} {:>3} {:>12} {:>9} {:>9} {:>8} {:>8}",
        "STREAM", "MODALITY", "PERTURBATION", "SEV", "SEED", "IN", "OUT", "DROPPED", "INVALID"
    );
    for s in streams {
        let p = match (&s.id, &s.perturbation) {
            (Some(id), Some(name)) => format!("{id} {name}"),
            _ => "off".to_string(),
        };
        println!(
            "{:<16} {:<8} {:<28} {:>3} {:>12} {:>9} {:>9} {:>8} {:>8}",
            s.name,
            s.modality,
            p,
            s.severity.map_or("-".to_string(), |v| v.to_string()),
            s.seed,
            s.frames_in,
            s.frames_out,
            s.dropped,
            s.invalid
        );
    }
}

fn lat(l: &LatencySummary) -> String {
    if l.count == 0 {
        return format!("{:>26}", "-");
    }
    format!(
        "{:>8.3} {:>8.3} {:>8.3}",
        l.p50_us / 1000.0,
        l.p99_us / 1000.0,
        l.max_us / 1000.0
    )
}

fn print_stats(streams: &[StreamReport]) {
    print_status(streams);
    println!();
    println!(
        "{:<16} {:<16} {:>8} {:>8} {:>8}   (milliseconds)",
        "STREAM", "LATENCY", "p50", "p99", "max"
    );
    for s in streams {
        let Some(l) = &s.latency else { continue };
        for (what, v) in [
            ("perturbation", &l.perturb),
            ("ingress->daemon", &l.ingress_to_rx),
            ("in daemon", &l.rx_to_tx),
            ("ingress->out", &l.ingress_to_tx),
        ] {
            println!("{:<16} {:<16} {}", s.name, what, lat(v));
        }
        println!(
            "{:<16} {:<16} {} of {} frames over the {} ms budget; perturbation failed {}",
            s.name, "budget", s.over_budget, s.frames_out, s.budget_ms, s.perturb_failed
        );
        println!(
            "{:<16} {:<16} {} not published by the daemon, by cause: {}",
            s.name,
            "lost",
            s.lost.total(),
            s.lost.describe()
        );
    }
}
