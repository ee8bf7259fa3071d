//! `perturb report`: the paper's tables and figures in one HTML page from a study folder.

use anyhow::{Result, bail};
use perturb_study::report::{ReportOptions, write_report};
use perturb_study::transfer::TransferConfig;
use std::path::PathBuf;

/// Arguments of `perturb report`.
#[derive(clap::Args)]
#[command(
    after_help = "STUDY_DIR holds what the study's tools wrote (the folder and two levels
down; files are recognised by what they hold, not by their names):
  perturb metrics steering --format json      RQ1 camera (per-severity mse)
  perturb metrics lidar --format json         RQ1 LiDAR (per-severity retention, ate)
  perturb bench --hil BAG --json              RQ2 latency, node overhead (per severity)
  perturb analyze ... --out DIR               RQ3 (analysis.json) and the map (map.svg)
  perturb analyze transfer --format json      transfer (else computed from the tables above,
                                              over the pairs within their latency budget)
  perturb analyze compare --format json       RQ4
The page is self-contained (inline CSS and SVG, nothing fetched when it is opened). A section
whose input is missing says which and how to make it. Beside the page: STEM.json (every table)
and STEM-TABLE.csv.

Example:
  perturb report study/ -o study/report.html"
)]
pub struct Args {
    /// The study folder.
    #[arg(value_name = "STUDY_DIR")]
    study: PathBuf,
    /// The HTML page to write.
    #[arg(short, long, default_value = "report.html")]
    output: PathBuf,
    /// The page's title.
    #[arg(long, default_value = "Sensor perturbation study")]
    title: String,
    /// Transfer computed here: bootstrap resamples.
    #[arg(long, default_value_t = 10_000)]
    resamples: usize,
    /// Transfer computed here: seed of the bootstrap.
    #[arg(long, default_value_t = 0)]
    seed: u64,
}

/// Runs `perturb report`.
pub fn run(a: Args) -> Result<()> {
    if a.resamples == 0 {
        bail!("--resamples must be at least 1");
    }
    let opts = ReportOptions {
        title: a.title,
        transfer: TransferConfig {
            resamples: a.resamples,
            seed: a.seed,
            ..TransferConfig::default()
        },
    };
    let w = write_report(&a.study, &a.output, &opts)?;
    for p in &w.used {
        eprintln!("read {}", p.display());
    }
    for (name, why) in &w.missing {
        eprintln!("section `{name}` missing: {why}");
    }
    eprintln!(
        "{} written ({} of {} sections), with {} and {} CSV tables",
        w.html.display(),
        w.present.len(),
        w.present.len() + w.missing.len(),
        w.json.display(),
        w.csv.len()
    );
    Ok(())
}
