//! `perturb augment`: one perturbed variant per training sample, reproducible from a manifest.

use crate::progress::Notes;
use anyhow::Result;
use perturb_study::augment::AugmentOptions;
use std::path::PathBuf;

/// Arguments of `perturb augment`.
#[derive(clap::Args)]
#[command(after_help = "Example:
  perturb augment train_images/ --out augmented/ --id C-C8 --id C-C11 --id C-E1 --seed 1

For sample k (files in sorted order) a perturbation and severity are drawn uniformly from the
selection with the seed, and the perturbed variant is written as <name>__<ID>_s<N>.<ext> beside a copy
of the clean sample. augment_manifest.csv lists every output with its perturbation, severity, seed
and sequence number (= k), so each variant can be regenerated with `perturb apply`.")]
pub struct Args {
    /// A folder of images or point clouds.
    input: PathBuf,
    /// Output folder.
    #[arg(short, long)]
    out: PathBuf,
    /// Perturbation IDs or names to draw from (repeatable).
    #[arg(long = "id")]
    ids: Vec<String>,
    /// Families to draw from (repeatable).
    #[arg(long)]
    family: Vec<String>,
    /// Severities to draw from (repeatable; default all).
    #[arg(long = "severity")]
    severities: Vec<u8>,
    /// Seed of the draws and of the perturbations.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Do not copy the clean samples (write only the variants).
    #[arg(long)]
    no_clean: bool,
    /// LiDAR sensor model.
    #[arg(long)]
    sensor: Option<String>,
    /// LiDAR full-scale intensity, 1 or 255.
    #[arg(long)]
    intensity_max: Option<f32>,
}

/// Runs `perturb augment`.
pub fn run(a: Args) -> Result<()> {
    let opts = AugmentOptions {
        input: a.input,
        out: a.out,
        ids: a.ids,
        families: a.family,
        severities: a.severities,
        seed: a.seed,
        no_clean: a.no_clean,
        sensor: a.sensor,
        intensity_max: a.intensity_max,
    };
    let o = perturb_study::augment::run(&opts, &Notes)?;
    eprintln!(
        "{} samples, {} variants{} written to {}",
        o.samples,
        o.variants,
        if opts.no_clean {
            ""
        } else {
            " and clean copies"
        },
        opts.out.display()
    );
    Ok(())
}
