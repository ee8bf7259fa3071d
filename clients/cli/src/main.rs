//! `perturb`: the command-line face of the perturbation middleware.
//!
//! Every subcommand is a thin layer over the library crates: `perturb-core` does the work,
//! `perturb-bag` reads and writes bags. Errors go to stderr with a non-zero exit status.

mod analyze;
mod apply;
mod augment;
mod batch;
mod bench;
mod campaign;
mod capacity;
mod ctl;
mod demo;
mod demo_offline;
mod detect;
mod gallery;
mod hil;
mod info;
mod list;
mod metrics;
mod pipeline;
mod progress;
mod report;

use clap::{Parser, Subcommand};

/// Camera and LiDAR perturbations for testing autonomous driving systems under sensor degradation.
///
/// The same perturbations run live in the `perturbd` daemon (between the sensor drivers and the
/// ADS), in hardware-in-the-loop bag replay, and offline on files through this tool. With the same
/// seed and sequence number, `perturb apply` reproduces byte for byte what the daemon injected.
#[derive(Parser)]
#[command(
    name = "perturb",
    version,
    about,
    long_about,
    arg_required_else_help = true
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// List the catalogue of perturbations (IDs, names, modality, family, severities).
    List(list::Args),
    /// Perturb one image, point cloud or bag file.
    Apply(apply::Args),
    /// Apply perturbations at every severity to a whole dataset (folder of images or scans, or a bag).
    Batch(batch::Args),
    /// Render every perturbation at every severity on one frame or scan (bird's-eye views for LiDAR).
    Gallery(gallery::Args),
    /// Write one randomly drawn perturbed variant per training sample, with a manifest.
    Augment(augment::Args),
    /// The study's metric tables (steering MSE and deviation; LiDAR detection retention and ATE).
    Metrics(metrics::Args),
    /// The closed loop (RQ3, RQ4): completion, failures, CTE, jitter, coverage of recorded runs;
    /// transfer analysis; fine-tuned vs baseline.
    Analyze(Box<analyze::Args>),
    /// The paper's tables and figures in one self-contained HTML page, from a study folder.
    Report(report::Args),
    /// Run the LiDAR clustering detector on one point-cloud file and print its boxes.
    Detect(detect::Args),
    /// Show what a file holds (image, point cloud, or a bag's topics) and check that it decodes.
    Info(info::Args),
    /// Run the product on synthetic camera and LiDAR data it generates itself.
    Demo(demo::Args),
    /// Time every perturbation at every severity on a real frame or scan and check the budget.
    Bench(bench::Args),
    /// Control a running perturbd: set or switch off a stream's perturbation, show status and stats.
    Ctl(ctl::Args),
    /// Perturbation campaigns: check one, or dry-run it on a recorded drive.
    Campaign(campaign::Args),
}

/// Behave like a Unix tool when the reader of stdout goes away (`perturb list | head`): exit
/// quietly instead of panicking on a broken pipe.
// libc's signal.
#[allow(unsafe_code)]
fn restore_sigpipe() {
    // SAFETY: restoring the default disposition of SIGPIPE before any thread is started.
    #[cfg(unix)]
    unsafe {
        libc::signal(libc::SIGPIPE, libc::SIG_DFL);
    }
}

fn main() {
    restore_sigpipe();
    let cli = Cli::parse();
    let result = match cli.command {
        Command::List(a) => list::run(a),
        Command::Apply(a) => apply::run(a),
        Command::Batch(a) => batch::run(a),
        Command::Gallery(a) => gallery::run(a),
        Command::Augment(a) => augment::run(a),
        Command::Metrics(a) => metrics::run(a),
        Command::Analyze(a) => analyze::run(*a),
        Command::Report(a) => report::run(a),
        Command::Detect(a) => detect::run(a),
        Command::Info(a) => info::run(a),
        Command::Bench(a) => bench::run(a),
        Command::Demo(a) => demo::run(a),
        Command::Ctl(a) => ctl::run(a),
        Command::Campaign(a) => campaign::run(a),
    };
    if let Err(e) = result {
        eprintln!("error: {}", message(&e));
        std::process::exit(1);
    }
}

/// The error and its causes on one line, leaving out a cause whose text the message already
/// holds (library errors include their cause in their own text).
fn message(e: &anyhow::Error) -> String {
    let mut msg = e.to_string();
    for cause in e.chain().skip(1) {
        let c = cause.to_string();
        if !msg.contains(&c) {
            msg.push_str(": ");
            msg.push_str(&c);
        }
    }
    msg
}
