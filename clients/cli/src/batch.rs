//! `perturb batch`: every selected perturbation at every severity over a dataset.

use crate::dataset::Dataset;
use crate::files::{Loaded, load, save_cloud, save_image, sensor_for};
use anyhow::{Context, Result, bail};
use indicatif::{ProgressBar, ProgressStyle};
use perturb_bag::Bag;
use perturb_core::perturber::{CameraPerturber, LidarPerturber, Spec};
use perturb_core::registry::{CATALOGUE, Entry, Modality, find};
use perturb_core::sensors::SensorModel;
use rayon::prelude::*;
use std::path::{Path, PathBuf};

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
    /// LiDAR sensor model (default: hdl64e for KITTI .bin, vlp32c otherwise).
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
}

/// One (perturbation, severity) output set.
#[derive(Clone, Copy)]
pub struct Set {
    /// The catalogue entry.
    pub entry: &'static Entry,
    /// Severity.
    pub severity: u8,
}

impl Set {
    /// `OUT/<ID>_<name>/s<N>`.
    pub fn dir(&self, out: &Path) -> PathBuf {
        out.join(format!("{}_{}", self.entry.id, self.entry.name))
            .join(format!("s{}", self.severity))
    }
}

/// The sets selected by the arguments, restricted to the modalities of the dataset.
pub fn select(args: &Args, modalities: &[Modality]) -> Result<Vec<Set>> {
    let mut entries: Vec<&'static Entry> = Vec::new();
    for id in &args.ids {
        entries.push(find(id)?);
    }
    for fam in &args.family {
        let found: Vec<_> = CATALOGUE
            .iter()
            .filter(|e| e.family.eq_ignore_ascii_case(fam))
            .collect();
        if found.is_empty() {
            bail!(
                "no perturbation in family `{fam}` (families: noise, blur, weather, distortion, pattern, color, sensor, local, affine, motion)"
            );
        }
        entries.extend(found);
    }
    if let Some(m) = args.modality {
        entries.extend(CATALOGUE.iter().filter(|e| e.modality == m));
    }
    if args.ids.is_empty() && args.family.is_empty() && args.modality.is_none() {
        entries.extend(
            CATALOGUE
                .iter()
                .filter(|e| modalities.contains(&e.modality)),
        );
    }
    entries.sort_by_key(|e| CATALOGUE.iter().position(|c| c.id == e.id));
    entries.dedup_by_key(|e| e.id);
    let mut sets = Vec::new();
    for e in entries {
        if !modalities.contains(&e.modality) {
            if !args.ids.is_empty() {
                bail!(
                    "{} is a {} perturbation and the dataset has no {} data",
                    e.id,
                    e.modality,
                    e.modality
                );
            }
            continue;
        }
        if !e.is_implemented() {
            eprintln!(
                "skipping {} ({}): not implemented in this build",
                e.id, e.name
            );
            continue;
        }
        let sevs: Vec<u8> = if args.severities.is_empty() {
            e.severities().collect()
        } else {
            args.severities
                .iter()
                .copied()
                .filter(|s| e.severities().contains(s))
                .collect()
        };
        for s in &args.severities {
            e.check_severity(*s).or_else(|err| {
                if args.ids.is_empty() {
                    Ok(())
                } else {
                    Err(err)
                }
            })?;
        }
        sets.extend(sevs.into_iter().map(|severity| Set { entry: e, severity }));
    }
    if sets.is_empty() {
        bail!("nothing to do: no implemented perturbation matches the selection for this dataset");
    }
    Ok(sets)
}

fn progress(total: u64, quiet: bool) -> ProgressBar {
    if quiet {
        return ProgressBar::hidden();
    }
    let pb = ProgressBar::new(total);
    pb.set_style(
        ProgressStyle::with_template(
            "{elapsed_precise} [{bar:40}] {pos}/{len} frames {msg} (eta {eta})",
        )
        .expect("template")
        .progress_chars("=> "),
    );
    pb
}

#[derive(serde::Serialize)]
struct Manifest<'a> {
    tool: &'static str,
    input: String,
    seed: u64,
    sensor: Option<&'a str>,
    forward: Option<&'a str>,
    intensity_max: Option<f32>,
    sets: Vec<String>,
}

/// Runs `perturb batch`.
pub fn run(args: Args) -> Result<()> {
    let dataset = Dataset::open(&args.input)?;
    let modalities = match &dataset {
        Dataset::Files { modality, .. } => vec![*modality],
        Dataset::Bag(_) => vec![Modality::Camera, Modality::Lidar],
    };
    let sets = select(&args, &modalities)?;
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("cannot create {}", args.out.display()))?;
    let manifest = Manifest {
        tool: concat!("perturb ", env!("CARGO_PKG_VERSION")),
        input: args.input.display().to_string(),
        seed: args.seed,
        sensor: args.sensor.as_deref(),
        forward: args.forward.as_deref(),
        intensity_max: args.intensity_max,
        sets: sets
            .iter()
            .map(|s| format!("{}:{}", s.entry.id, s.severity))
            .collect(),
    };
    std::fs::write(
        args.out.join("batch.json"),
        serde_json::to_string_pretty(&manifest)?,
    )?;
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(args.threads.unwrap_or(0))
        .build()?;
    let todo: Vec<Set> = sets
        .iter()
        .copied()
        .filter(|s| !s.dir(&args.out).join(".done").exists())
        .collect();
    if todo.len() < sets.len() {
        eprintln!(
            "resuming: {} of {} sets already done",
            sets.len() - todo.len(),
            sets.len()
        );
    }
    match &dataset {
        Dataset::Files {
            root,
            files,
            modality,
        } => {
            let pb = progress((todo.len() * files.len()) as u64, args.quiet);
            let sensor = if *modality == Modality::Lidar {
                let kind = perturb_core::formats::FileKind::from_path(&files[0]).ok();
                Some(sensor_for(
                    kind,
                    args.sensor.as_deref(),
                    args.forward.as_deref(),
                    args.intensity_max,
                    args.quiet,
                )?)
            } else {
                None
            };
            for set in &todo {
                pb.set_message(format!("{} s{}", set.entry.id, set.severity));
                pool.install(|| run_files_set(&args, *set, root, files, sensor.as_ref(), &pb))?;
            }
            pb.finish_with_message("done");
        }
        Dataset::Bag(path) => {
            let bag = Bag::open(path)?;
            let total: u64 = bag.topics()?.iter().filter_map(|t| t.message_count).sum();
            let pb = progress(total * todo.len() as u64, args.quiet);
            let sensor = sensor_for(
                None,
                args.sensor.as_deref(),
                args.forward.as_deref(),
                args.intensity_max,
                args.quiet,
            )?;
            pool.install(|| {
                todo.par_iter().try_for_each(|set| {
                    let dir = set.dir(&args.out);
                    if dir.exists() {
                        std::fs::remove_dir_all(&dir).with_context(|| {
                            format!("cannot clear unfinished {}", dir.display())
                        })?;
                    }
                    if let Some(parent) = dir.parent() {
                        std::fs::create_dir_all(parent)?;
                    }
                    let spec = Spec::new(set.entry.id, set.severity, args.seed)?;
                    let n = crate::apply::perturb_bag(
                        &bag,
                        &dir,
                        spec,
                        0,
                        &sensor,
                        &args.topic,
                        true,
                        &|| pb.inc(1),
                    )?;
                    std::fs::write(dir.join(".done"), format!("{{\"messages\": {n}}}"))?;
                    anyhow::Ok(())
                })
            })?;
            pb.finish_with_message("done");
        }
    }
    eprintln!("{} sets written under {}", sets.len(), args.out.display());
    if args.lidar_metrics {
        lidar_metrics(&args, &sets, &pool)?;
    }
    Ok(())
}

/// `--lidar-metrics`: the RQ1 table of this run's LiDAR sets, into OUT.
fn lidar_metrics(args: &Args, sets: &[Set], pool: &rayon::ThreadPool) -> Result<()> {
    use crate::lidar_eval::{EvalConfig, Format, SetDir, evaluate, render};
    let lidar: Vec<SetDir> = sets
        .iter()
        .filter(|s| s.entry.modality == Modality::Lidar)
        .map(|s| SetDir {
            entry: s.entry,
            severity: s.severity,
            dir: s.dir(&args.out),
        })
        .collect();
    if lidar.is_empty() {
        eprintln!("--lidar-metrics: no LiDAR set in this run, nothing to measure");
        return Ok(());
    }
    let cfg = EvalConfig::new(
        false,
        None,
        2.0,
        (args.sensor.as_deref(), args.forward.as_deref()),
        args.topic.clone(),
        args.quiet,
    )?;
    let report = pool
        .install(|| evaluate(&args.input, &lidar, &cfg))
        .context("computing the LiDAR metrics")?;
    let md = args.out.join("lidar_metrics.md");
    std::fs::write(&md, render(&report, Format::Markdown)?)
        .with_context(|| format!("cannot write {}", md.display()))?;
    let json = args.out.join("lidar_metrics.json");
    std::fs::write(&json, render(&report, Format::Json)?)
        .with_context(|| format!("cannot write {}", json.display()))?;
    print!("{}", render(&report, Format::Table)?);
    eprintln!(
        "LiDAR metrics written to {} and {}",
        md.display(),
        json.display()
    );
    Ok(())
}

fn run_files_set(
    args: &Args,
    set: Set,
    root: &Path,
    files: &[PathBuf],
    sensor: Option<&SensorModel>,
    pb: &ProgressBar,
) -> Result<()> {
    let dir = set.dir(&args.out);
    std::fs::create_dir_all(&dir).with_context(|| format!("cannot create {}", dir.display()))?;
    let spec = Spec::new(set.entry.id, set.severity, args.seed)?;
    enum Worker {
        Camera(CameraPerturber),
        Lidar(Box<LidarPerturber>),
    }
    let make = || -> Result<Worker> {
        Ok(match set.entry.modality {
            Modality::Camera => Worker::Camera(CameraPerturber::from_spec(spec)?),
            Modality::Lidar => Worker::Lidar(Box::new(LidarPerturber::from_spec(
                spec,
                sensor.cloned().unwrap_or_default(),
            )?)),
        })
    };
    files
        .par_iter()
        .enumerate()
        .map_init(make, |worker, (seq, rel)| {
            let worker = worker.as_mut().map_err(|e| anyhow::anyhow!("{e:#}"))?;
            let out = dir.join(rel);
            if out.exists() {
                pb.inc(1);
                return Ok(());
            }
            if let Some(p) = out.parent() {
                std::fs::create_dir_all(p)?;
            }
            let input = root.join(rel);
            // Written under a temporary name and renamed, so an interrupted run never leaves a
            // half-written file that a resumed run would take as done.
            let tmp = out.with_file_name(format!(
                ".{}.partial",
                rel.file_name().and_then(|n| n.to_str()).unwrap_or("frame")
            ));
            match (load(&input)?, worker) {
                (Loaded::Image(img, kind), Worker::Camera(p)) => {
                    let o = p
                        .apply_owned(&img.view(), seq as u64)
                        .with_context(|| format!("perturbing {}", input.display()))?;
                    save_image(&tmp, &o.view(), kind)?;
                }
                (Loaded::Cloud(c, kind, meta), Worker::Lidar(p)) => {
                    let o = p
                        .apply_owned(&c.view(), seq as u64, None)
                        .with_context(|| format!("perturbing {}", input.display()))?;
                    save_cloud(&tmp, &o.view(), kind, meta)?;
                }
                _ => bail!(
                    "{} does not match the perturbation's modality",
                    input.display()
                ),
            }
            std::fs::rename(&tmp, &out)
                .with_context(|| format!("cannot rename {} to {}", tmp.display(), out.display()))?;
            pb.inc(1);
            Ok(())
        })
        .collect::<Result<Vec<()>>>()?;
    std::fs::write(dir.join(".done"), format!("{{\"files\": {}}}", files.len()))?;
    Ok(())
}
