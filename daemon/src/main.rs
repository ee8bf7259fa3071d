//! `perturbd --config FILE.toml`: the perturbation daemon.

use clap::Parser;
use perturbd::Config;
use std::path::PathBuf;

/// The perturbation daemon: perturbs live camera and LiDAR streams in iceoryx2 shared memory.
///
/// Reads one `[[streams]]` table per sensor from the configuration (see config/README.md),
/// perturbs each stream's input service into its output service, serves `perturb ctl` and logs
/// statistics. SIGINT or SIGTERM stops it cleanly and writes the JSON report. Log verbosity:
/// RUST_LOG (default info).
#[derive(Parser)]
#[command(name = "perturbd", version, about, long_about)]
struct Args {
    /// Configuration file (TOML).
    #[arg(long, short)]
    config: PathBuf,
    /// Where to write the JSON report on exit (default: `[daemon] report`, else
    /// ./perturbd-report.json).
    #[arg(long)]
    report: Option<PathBuf>,
    /// Only check the configuration and exit.
    #[arg(long)]
    check: bool,
    /// Start from the configuration alone: ignore the perturbations set at runtime before the
    /// last restart and the counters of the last run (both kept next to the report).
    #[arg(long)]
    fresh: bool,
}

fn main() {
    let args = Args::parse();
    tracing_subscriber::fmt()
        .with_env_filter(
            tracing_subscriber::EnvFilter::try_from_default_env()
                .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("info")),
        )
        .with_writer(std::io::stderr)
        .init();
    let cfg = match Config::load(&args.config) {
        Ok(c) => c,
        Err(e) => {
            eprintln!("error: {e}");
            std::process::exit(2);
        }
    };
    // The report, and the restart state beside it, must be writable: found at --check, not
    // when the daemon stops (the state would live in memory only meanwhile).
    if let Some(r) = args.report.as_ref().or(cfg.daemon.report.as_ref())
        && let Err(e) = perturbd::config::check_report_path(r)
    {
        eprintln!("error: {}: {e}", args.config.display());
        std::process::exit(2);
    }
    if args.check {
        println!(
            "{}: {} stream(s), configuration valid",
            args.config.display(),
            cfg.streams.len()
        );
        return;
    }
    if let Err(e) = perturbd::daemon::run(&args.config, cfg, args.report, args.fresh) {
        eprintln!("error: {e:#}");
        std::process::exit(1);
    }
}
