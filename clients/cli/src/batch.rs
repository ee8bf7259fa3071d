//! `perturb batch`: every selected perturbation at every severity over a dataset.

use crate::progress::Bar;
use anyhow::Result;
use perturb_core::registry::Modality;
use perturb_study::Format;
use perturb_study::batch::{BatchOptions, Selection};
use std::path::PathBuf;

/// Arguments of `perturb batch`.
#[derive(clap::Args)]
#[command(after_help = "Examples:
  perturb batch images/ --out perturbed/ --family blur          # every blur at severities 1..5
  perturb batch scans/ --out perturbed/ --modality lidar --lidar-metrics
  perturb batch drive.mcap --out perturbed/ --id C-C7 --id L-A9 --severity 1 --severity 3

Output: OUT/<ID>_<name>/s<N>/ holds the perturbed copy of the dataset (same file names and
formats; a bag for a bag). The frame sequence number is the file's index in sorted order (for
bags: the message's index on its topic), so every output can be reproduced with `perturb apply`.
An interrupted run resumes where it stopped: finished sets carry a .done marker and are skipped,
finished files are kept. OUT/batch.json records what was run.

--shard INDEX/COUNT spreads a batch over machines without a cluster engine: run the same command
with --shard 0/N .. N-1/N on N machines (same input, output on a shared folder or merged later);
each writes whole sets, every set is written once.

--lidar-metrics then runs the detector on the clean and the perturbed clouds of this run's LiDAR
sets and writes the RQ1 table (retention, ATE; see `perturb metrics lidar --help`) to
OUT/lidar_metrics.md and OUT/lidar_metrics.json, and prints it.")]
pub struct Args {
    /// A folder of images, a folder of point clouds (KITTI .bin, .pcd, .pcd.bin), or a bag.
    pub input: PathBuf,
    /// Output folder.
    #[arg(short, long)]
    pub out: PathBuf,
    /// Perturbation IDs or names (repeatable).
    #[arg(long = "id")]
    pub ids: Vec<String>,
    /// Every perturbation of a family (noise, blur, weather, ...; repeatable).
    #[arg(long)]
    pub family: Vec<String>,
    /// Every perturbation of a modality.
    #[arg(long)]
    pub modality: Option<Modality>,
    /// Severities (repeatable; default all of each perturbation).
    #[arg(long = "severity")]
    pub severities: Vec<u8>,
    /// Seed.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Worker threads (default: all cores).
    #[arg(long)]
    pub threads: Option<usize>,
    /// LiDAR sensor model (default: hdl64e for KITTI .bin, hdl32e for nuScenes .pcd.bin, vlp32c otherwise).
    #[arg(long)]
    pub sensor: Option<String>,
    /// LiDAR forward axis: +x, -x, +y or -y (default: +y for nuScenes .pcd.bin, +x otherwise).
    #[arg(long, allow_hyphen_values = true)]
    pub forward: Option<String>,
    /// Full-scale intensity of the clouds, 1 or 255.
    #[arg(long)]
    pub intensity_max: Option<f32>,
    /// Bags: only perturb these topics (repeatable).
    #[arg(long)]
    pub topic: Vec<String>,
    /// Hide the progress bar.
    #[arg(long)]
    pub quiet: bool,
    /// Afterwards, compute the LiDAR detection metrics (retention, ATE) of the LiDAR sets and
    /// write them to OUT/lidar_metrics.md and OUT/lidar_metrics.json.
    #[arg(long, visible_alias = "metrics")]
    pub lidar_metrics: bool,
    /// Only share INDEX/COUNT of the sets (0-based, e.g. 0/4 .. 3/4): set k of the selection
    /// goes to shard k mod COUNT, so COUNT machines that each run one shard write every set once.
    #[arg(long, value_name = "INDEX/COUNT")]
    pub shard: Option<perturb_study::batch::Shard>,
    /// Bags: chunk compression of the output bags; rosbag2 zstd (the default), zstd:LEVEL
    /// (1..19), lz4 or none; ROS 1 none (the default), bz2 or lz4.
    #[arg(long)]
    pub compression: Option<String>,
}

/// Runs `perturb batch`.
pub fn run(a: Args) -> Result<()> {
    let opts = BatchOptions {
        input: a.input,
        out: a.out,
        selection: Selection {
            ids: a.ids,
            families: a.family,
            modality: a.modality,
            severities: a.severities,
        },
        seed: a.seed,
        sensor: a.sensor,
        forward: a.forward,
        intensity_max: a.intensity_max,
        topics: a.topic,
        lidar_metrics: a.lidar_metrics,
        shard: a.shard,
        compression: a.compression,
    };
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(a.threads.unwrap_or(0))
        .build()?;
    let bar = Bar::new("frames", a.quiet);
    let outcome = pool.install(|| perturb_study::batch::run(&opts, &bar))?;
    eprintln!(
        "{} sets written under {}",
        outcome.sets.len(),
        opts.out.display()
    );
    if let Some(report) = &outcome.lidar {
        print!(
            "{}",
            perturb_study::lidar_eval::render(report, Format::Table)
        );
    }
    Ok(())
}
