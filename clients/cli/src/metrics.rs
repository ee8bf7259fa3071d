//! `perturb metrics`: the study's tables from batch outputs and model predictions.

use crate::progress::{Bar, Notes};
use anyhow::{Result, bail};
use perturb_study::Format;
use std::path::PathBuf;

/// Arguments of `perturb metrics`.
#[derive(clap::Args)]
pub struct Args {
    #[command(subcommand)]
    command: Command,
}

#[derive(clap::Subcommand)]
enum Command {
    /// Camera (RQ1): MSE and maximum deviation of steering predictions against the baseline.
    #[command(
        after_help = "Run your driving model on the clean frames and on each set written by
`perturb batch` (OUT/<ID>_<name>/s<N>/), and save one CSV per set with lines `frame,steering`
(a header line is allowed). Layouts found under --predictions:
  PRED/C-A1_gaussian_noise/s3.csv   PRED/C-A1_s3.csv   PRED/C-A1_gaussian_noise/s3/anything.csv
Frames are matched by the first column."
    )]
    Steering {
        /// The baseline predictions (clean frames).
        #[arg(long)]
        baseline: PathBuf,
        /// Folder of per-set prediction CSVs.
        #[arg(long)]
        predictions: PathBuf,
        /// Report format.
        #[arg(long, value_enum, default_value_t = Format::Table)]
        format: Format,
    },
    /// LiDAR (RQ1): retention of the baseline detections and their translation error (ATE).
    #[command(
        after_help = "Runs the clustering detector (Autoware Mini's lidar_cluster pipeline: ground removal,
voxel grid, DBSCAN, minimum-area boxes; see `perturb detect`) on every clean scan and on its
counterpart in every finished set that `perturb batch` wrote under ROOT
(ROOT/<ID>_<name>/s<N>/: a folder of scans or a bag), and matches the boxes frame by frame (greedy,
one-to-one, centre distance in x, y within --match-distance).

Per (perturbation, severity), pooled over the frames:
  retention = baseline detections still matched / baseline detections   (recall, 0..1)
  ATE       = mean centre distance of the matched boxes, metres
Per perturbation (the paper's RQ1 table): retention average and minimum over the severities,
ATE maximum over the severities. Frames are detected in parallel; the numbers do not depend
on --threads.

Examples:
  perturb batch scans/ --out perturbed/ --id L-B1 --id L-A9
  perturb metrics lidar --clean scans/ --perturbed perturbed/
  perturb metrics lidar --perturbed perturbed/ --format csv > lidar.csv   # --clean from batch.json
  perturb metrics lidar --clean drive.mcap --perturbed perturbed_bags/ --format markdown"
    )]
    Lidar {
        /// The clean data: the folder of scans or the bag given to `perturb batch` (default: the
        /// input recorded in PERTURBED/batch.json).
        #[arg(long)]
        clean: Option<PathBuf>,
        /// The output root of `perturb batch`.
        #[arg(long)]
        perturbed: PathBuf,
        /// Report format (csv: one row per perturbation and severity).
        #[arg(long, value_enum, default_value_t = Format::Table)]
        format: Format,
        /// Only these perturbations (IDs or names, repeatable; default every LiDAR set found).
        #[arg(long = "id")]
        ids: Vec<String>,
        /// Largest centre distance of a match in the ground plane, metres.
        #[arg(long, default_value_t = 2.0)]
        match_distance: f32,
        /// Count only the boxes classed as road users (vehicle, pedestrian/cyclist-sized); by
        /// default every box counts, as the object-level perturbations use them.
        #[arg(long)]
        objects: bool,
        /// Count only the boxes of this class: vehicle, pedestrian or other.
        #[arg(long)]
        class: Option<String>,
        /// LiDAR sensor model used to read the clouds (its intensity scale and axes).
        #[arg(long)]
        sensor: Option<String>,
        /// LiDAR forward axis: +x, -x, +y or -y (default: +y for nuScenes .pcd.bin, +x otherwise).
        #[arg(long, allow_hyphen_values = true)]
        forward: Option<String>,
        /// Bags: only these PointCloud2 topics (repeatable; default all).
        #[arg(long)]
        topic: Vec<String>,
        /// Worker threads (default: all cores).
        #[arg(long)]
        threads: Option<usize>,
        /// Hide the progress bar.
        #[arg(long)]
        quiet: bool,
    },
}

/// Runs `perturb metrics`.
pub fn run(a: Args) -> Result<()> {
    match a.command {
        Command::Steering {
            baseline,
            predictions,
            format,
        } => {
            let report = perturb_study::steering::evaluate(&baseline, &predictions)?;
            for f in &report.skipped {
                eprintln!(
                    "skipping {}: cannot tell the perturbation and severity from its path",
                    f.display()
                );
            }
            print!("{}", perturb_study::steering::render(&report, format));
            Ok(())
        }
        Command::Lidar {
            clean,
            perturbed,
            format,
            ids,
            match_distance,
            objects,
            class,
            sensor,
            forward,
            topic,
            threads,
            quiet,
        } => {
            use perturb_study::lidar_eval;
            let clean = match clean {
                Some(c) => c,
                None => {
                    let c = lidar_eval::clean_from_manifest(&perturbed)?;
                    eprintln!(
                        "clean data: {} (from {}; override with --clean)",
                        c.display(),
                        perturbed.join("batch.json").display()
                    );
                    c
                }
            };
            let mut sets = lidar_eval::discover_sets(&perturbed, &Notes)?;
            if !ids.is_empty() {
                let wanted = ids
                    .iter()
                    .map(|i| perturb_core::registry::find(i).map(|e| e.id))
                    .collect::<std::result::Result<Vec<_>, _>>()?;
                sets.retain(|s| wanted.contains(&s.entry.id));
            }
            if sets.is_empty() {
                bail!(
                    "no finished LiDAR set (<ID>_<name>/s<N>/ with a .done marker) under {}",
                    perturbed.display()
                );
            }
            let cfg = lidar_eval::EvalConfig::new(
                objects,
                class.as_deref(),
                match_distance,
                (sensor.as_deref(), forward.as_deref()),
                topic,
            )?;
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads.unwrap_or(0))
                .build()?;
            let bar = Bar::new("clouds detected", quiet);
            let report = pool.install(|| lidar_eval::evaluate(&clean, &sets, &cfg, &bar))?;
            print!("{}", lidar_eval::render(&report, format));
            Ok(())
        }
    }
}
