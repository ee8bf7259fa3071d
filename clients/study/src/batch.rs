//! Every selected perturbation at every severity over a dataset (paper, RQ1's perturbed sets).
//!
//! Output: `OUT/<ID>_<name>/s<N>/` holds the perturbed copy of the dataset (same file names and
//! formats; a bag for a bag). The frame sequence number is the file's index in sorted order (for
//! bags: the message's index on its topic), so every output can be reproduced with `perturb
//! apply`. An interrupted run resumes where it stopped: finished sets carry a `.done` marker and
//! are skipped, finished files are kept. `OUT/batch.json` records what was run.

use crate::dataset::Dataset;
use crate::error::{Result, StudyError};
use crate::files::{Loaded, load, save_cloud, save_image, sensor_for};
use crate::progress::Progress;
use perturb_bag::Bag;
use perturb_core::perturber::{CameraPerturber, LidarPerturber, Spec};
use perturb_core::registry::{CATALOGUE, Entry, Modality, find};
use perturb_core::sensor_model::SensorModel;
use rayon::prelude::*;
use std::path::{Path, PathBuf};

/// Which perturbations and severities to run. With no IDs, families or modality, every
/// perturbation of the dataset's modalities is selected.
#[derive(Clone, Debug, Default)]
pub struct Selection {
    /// Perturbation IDs or names.
    pub ids: Vec<String>,
    /// Every perturbation of these families (noise, blur, weather, ...).
    pub families: Vec<String>,
    /// Every perturbation of this modality.
    pub modality: Option<Modality>,
    /// Severities (empty: all of each perturbation).
    pub severities: Vec<u8>,
}

/// One (perturbation, severity) output set.
#[derive(Clone, Copy, Debug)]
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

/// The sets selected, restricted to the modalities of the dataset.
pub fn select(sel: &Selection, modalities: &[Modality]) -> Result<Vec<Set>> {
    let mut entries: Vec<&'static Entry> = Vec::new();
    for id in &sel.ids {
        entries.push(find(id)?);
    }
    for fam in &sel.families {
        let found: Vec<_> = CATALOGUE
            .iter()
            .filter(|e| e.family.eq_ignore_ascii_case(fam))
            .collect();
        if found.is_empty() {
            return Err(StudyError::Config(format!(
                "no perturbation in family `{fam}` (families: noise, blur, weather, distortion, pattern, color, sensor, local, affine, motion)"
            )));
        }
        entries.extend(found);
    }
    if let Some(m) = sel.modality {
        entries.extend(CATALOGUE.iter().filter(|e| e.modality == m));
    }
    if sel.ids.is_empty() && sel.families.is_empty() && sel.modality.is_none() {
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
            if !sel.ids.is_empty() {
                return Err(StudyError::Config(format!(
                    "{} is a {} perturbation and the dataset has no {} data",
                    e.id, e.modality, e.modality
                )));
            }
            continue;
        }
        let sevs: Vec<u8> = if sel.severities.is_empty() {
            e.severities().collect()
        } else {
            sel.severities
                .iter()
                .copied()
                .filter(|s| e.severities().contains(s))
                .collect()
        };
        for s in &sel.severities {
            if let Err(err) = e.check_severity(*s)
                && !sel.ids.is_empty()
            {
                return Err(err.into());
            }
        }
        sets.extend(sevs.into_iter().map(|severity| Set { entry: e, severity }));
    }
    if sets.is_empty() {
        return Err(StudyError::Config(
            "nothing to do: no implemented perturbation matches the selection for this dataset"
                .into(),
        ));
    }
    Ok(sets)
}

/// What `perturb batch` runs.
#[derive(Clone, Debug, Default)]
pub struct BatchOptions {
    /// A folder of images, a folder of point clouds, or a bag.
    pub input: PathBuf,
    /// Output folder.
    pub out: PathBuf,
    /// The perturbations and severities.
    pub selection: Selection,
    /// Seed.
    pub seed: u64,
    /// LiDAR sensor model (default: hdl64e for KITTI .bin, hdl32e for nuScenes .pcd.bin, vlp32c
    /// otherwise).
    pub sensor: Option<String>,
    /// LiDAR forward axis: +x, -x, +y or -y (default: +y for nuScenes .pcd.bin, +x otherwise).
    pub forward: Option<String>,
    /// Full-scale intensity of the clouds, 1 or 255.
    pub intensity_max: Option<f32>,
    /// Bags: only perturb these topics.
    pub topics: Vec<String>,
    /// Afterwards, compute the LiDAR detection metrics of the LiDAR sets.
    pub lidar_metrics: bool,
    /// Only this share of the sets (to spread a batch over machines without a cluster engine).
    pub shard: Option<Shard>,
    /// Bags: chunk compression of the output bags (see [`perturb_bag::AnyWriter::create`]).
    pub compression: Option<String>,
}

/// Share `index` of `count` of a batch's sets: set k (in catalogue order, severities ascending)
/// belongs to shard k mod count. Every set is written whole by exactly one shard, so the shards
/// can write into one shared folder or into folders merged afterwards.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Shard {
    /// 0-based index, below `count`.
    pub index: usize,
    /// Number of shards, at least 1.
    pub count: usize,
}

impl std::str::FromStr for Shard {
    type Err = StudyError;
    fn from_str(s: &str) -> Result<Self> {
        let bad = || {
            StudyError::Config(format!(
                "--shard `{s}`: expected INDEX/COUNT with 0 <= INDEX < COUNT, e.g. 0/4 .. 3/4"
            ))
        };
        let (i, n) = s.split_once('/').ok_or_else(bad)?;
        let index: usize = i.trim().parse().map_err(|_| bad())?;
        let count: usize = n.trim().parse().map_err(|_| bad())?;
        if count == 0 || index >= count {
            return Err(bad());
        }
        Ok(Shard { index, count })
    }
}

impl std::fmt::Display for Shard {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}/{}", self.index, self.count)
    }
}

/// What a batch run did.
#[derive(Clone, Debug)]
pub struct BatchOutcome {
    /// Every selected set (finished now or before).
    pub sets: Vec<Set>,
    /// Sets that were already finished and skipped.
    pub resumed: usize,
    /// With [`BatchOptions::lidar_metrics`]: the RQ1 LiDAR table of this run's LiDAR sets, also
    /// written to `OUT/lidar_metrics.md` and `OUT/lidar_metrics.json` (None when the run has no
    /// LiDAR set).
    pub lidar: Option<crate::lidar_eval::Report>,
}

#[derive(serde::Serialize)]
struct Manifest<'a> {
    tool: &'static str,
    input: String,
    seed: u64,
    sensor: Option<&'a str>,
    forward: Option<&'a str>,
    intensity_max: Option<f32>,
    #[serde(skip_serializing_if = "Option::is_none")]
    shard: Option<String>,
    sets: Vec<String>,
}

/// Forwards progress but not the per-set remarks of [`crate::perturb_bag::perturb_bag`].
struct Ticks<'a>(&'a dyn Progress);

impl Progress for Ticks<'_> {
    fn inc(&self, n: u64) {
        self.0.inc(n)
    }
}

/// A batch ready to run: the dataset, its sets and which of them are still to do. Made by
/// [`plan`], which also writes `OUT/batch.json`.
pub struct Planned {
    /// The dataset.
    pub dataset: Dataset,
    /// Every selected set of this shard (finished now or before).
    pub sets: Vec<Set>,
    /// The sets without a `.done` marker.
    pub todo: Vec<Set>,
    /// For a folder of point clouds: the sensor model that reads them.
    pub sensor: Option<SensorModel>,
}

/// Opens the dataset, selects the sets (of this shard), writes the manifest `OUT/batch.json` and
/// finds the sets already done. `perturb batch` and the Python package's Ray batch both start
/// here, so they write the same folder layout and manifest.
pub fn plan(opts: &BatchOptions, progress: &dyn Progress) -> Result<Planned> {
    let dataset = Dataset::open(&opts.input)?;
    let modalities = match &dataset {
        Dataset::Files { modality, .. } => vec![*modality],
        Dataset::Bag(_) => vec![Modality::Camera, Modality::Lidar],
    };
    let mut sets = select(&opts.selection, &modalities)?;
    if let Some(shard) = opts.shard {
        sets = sets
            .into_iter()
            .enumerate()
            .filter(|(k, _)| k % shard.count == shard.index)
            .map(|(_, s)| s)
            .collect();
        if sets.is_empty() {
            progress.note(&format!("shard {shard}: no set falls to this shard"));
        }
    }
    std::fs::create_dir_all(&opts.out).map_err(StudyError::io(&opts.out))?;
    let manifest = Manifest {
        tool: concat!("perturb ", env!("CARGO_PKG_VERSION")),
        input: opts.input.display().to_string(),
        seed: opts.seed,
        sensor: opts.sensor.as_deref(),
        forward: opts.forward.as_deref(),
        intensity_max: opts.intensity_max,
        shard: opts.shard.map(|s| s.to_string()),
        sets: sets
            .iter()
            .map(|s| format!("{}:{}", s.entry.id, s.severity))
            .collect(),
    };
    let manifest_path = opts.out.join("batch.json");
    std::fs::write(
        &manifest_path,
        serde_json::to_string_pretty(&manifest).expect("the manifest serialises"),
    )
    .map_err(StudyError::io(&manifest_path))?;
    let todo: Vec<Set> = sets
        .iter()
        .copied()
        .filter(|s| !s.dir(&opts.out).join(".done").exists())
        .collect();
    let resumed = sets.len() - todo.len();
    if resumed > 0 {
        progress.note(&format!(
            "resuming: {resumed} of {} sets already done",
            sets.len()
        ));
    }
    let sensor = match &dataset {
        Dataset::Files {
            files,
            modality: Modality::Lidar,
            ..
        } => {
            let kind = perturb_core::formats::FileKind::from_path(&files[0]).ok();
            let s = sensor_for(
                kind,
                opts.sensor.as_deref(),
                opts.forward.as_deref(),
                opts.intensity_max,
            )?;
            progress.note(&crate::files::describe_sensor(&s));
            Some(s)
        }
        _ => None,
    };
    Ok(Planned {
        dataset,
        sets,
        todo,
        sensor,
    })
}

/// Marks a set of a folder dataset finished (`DIR/.done`, with its number of files): a resumed
/// batch skips it.
pub fn mark_done(dir: &Path, files: usize) -> Result<()> {
    let done = dir.join(".done");
    std::fs::write(&done, format!("{{\"files\": {files}}}")).map_err(StudyError::io(&done))
}

/// Runs the batch on the current rayon pool: every unfinished set is written, then (optionally)
/// the LiDAR metrics are computed. Progress counts frames.
pub fn run(opts: &BatchOptions, progress: &dyn Progress) -> Result<BatchOutcome> {
    let Planned {
        dataset,
        sets,
        todo,
        sensor,
    } = plan(opts, progress)?;
    let resumed = sets.len() - todo.len();
    match &dataset {
        Dataset::Files { root, files, .. } => {
            progress.set_length((todo.len() * files.len()) as u64);
            for set in &todo {
                progress.set_message(&format!("{} s{}", set.entry.id, set.severity));
                run_files_set(opts, *set, root, files, sensor.as_ref(), progress)?;
            }
        }
        Dataset::Bag(path) => {
            let bag = Bag::open(path)?;
            let total: u64 = bag.topics()?.iter().filter_map(|t| t.message_count).sum();
            progress.set_length(total * todo.len() as u64);
            let sensor = sensor_for(
                None,
                opts.sensor.as_deref(),
                opts.forward.as_deref(),
                opts.intensity_max,
            )?;
            progress.note(&crate::files::describe_sensor(&sensor));
            todo.par_iter().try_for_each(|set| -> Result<()> {
                let dir = set.dir(&opts.out);
                if dir.exists() {
                    std::fs::remove_dir_all(&dir).map_err(|e| {
                        StudyError::input(&dir, format!("cannot clear the unfinished set: {e}"))
                    })?;
                }
                if let Some(parent) = dir.parent() {
                    std::fs::create_dir_all(parent).map_err(StudyError::io(parent))?;
                }
                let spec = Spec::new(set.entry.id, set.severity, opts.seed)?;
                let options = crate::perturb_bag::BagOptions {
                    seq_offset: 0,
                    sensor: sensor.clone(),
                    topics: opts.topics.clone(),
                    bit_depth: None,
                    compression: opts.compression.clone(),
                };
                let n = crate::perturb_bag::perturb_bag_with(
                    &bag,
                    &dir,
                    spec,
                    &options,
                    &Ticks(progress),
                )?;
                let done = dir.join(".done");
                std::fs::write(&done, format!("{{\"messages\": {n}}}"))
                    .map_err(StudyError::io(&done))
            })?;
        }
    }
    progress.finish();
    let lidar = if opts.lidar_metrics {
        lidar_metrics(opts, &sets, progress)?
    } else {
        None
    };
    Ok(BatchOutcome {
        sets,
        resumed,
        lidar,
    })
}

/// The RQ1 table of this run's LiDAR sets, written into OUT.
fn lidar_metrics(
    opts: &BatchOptions,
    sets: &[Set],
    progress: &dyn Progress,
) -> Result<Option<crate::lidar_eval::Report>> {
    use crate::lidar_eval::{EvalConfig, Format, SetDir, evaluate, render};
    let lidar: Vec<SetDir> = sets
        .iter()
        .filter(|s| s.entry.modality == Modality::Lidar)
        .map(|s| SetDir {
            entry: s.entry,
            severity: s.severity,
            dir: s.dir(&opts.out),
        })
        .collect();
    if lidar.is_empty() {
        progress.note("--lidar-metrics: no LiDAR set in this run, nothing to measure");
        return Ok(None);
    }
    let cfg = EvalConfig::new(
        false,
        None,
        2.0,
        (opts.sensor.as_deref(), opts.forward.as_deref()),
        opts.topics.clone(),
    )?;
    let report = evaluate(&opts.input, &lidar, &cfg, progress)?;
    for (name, format) in [
        ("lidar_metrics.md", Format::Markdown),
        ("lidar_metrics.json", Format::Json),
    ] {
        let path = opts.out.join(name);
        std::fs::write(&path, render(&report, format)).map_err(StudyError::io(&path))?;
    }
    progress.note(&format!(
        "LiDAR metrics written to {} and {}",
        opts.out.join("lidar_metrics.md").display(),
        opts.out.join("lidar_metrics.json").display()
    ));
    Ok(Some(report))
}

/// The perturber of one set for the files of a folder dataset, as `perturb batch` runs it on
/// each worker thread (and the Python package's Ray batch on each actor).
pub struct FileWorker {
    set: Set,
    worker: Worker,
}

enum Worker {
    Camera(CameraPerturber),
    Lidar(Box<LidarPerturber>),
}

impl FileWorker {
    /// The perturber of `set` with `seed`; `sensor` reads point clouds (default VLP-32C).
    pub fn new(set: Set, seed: u64, sensor: Option<&SensorModel>) -> Result<Self> {
        let spec = Spec::new(set.entry.id, set.severity, seed)?;
        let worker = match set.entry.modality {
            Modality::Camera => Worker::Camera(CameraPerturber::from_spec(spec)?),
            Modality::Lidar => Worker::Lidar(Box::new(LidarPerturber::from_spec(
                spec,
                sensor.cloned().unwrap_or_default(),
            )?)),
        };
        Ok(FileWorker { set, worker })
    }

    /// The set.
    pub fn set(&self) -> Set {
        self.set
    }

    /// Perturbs `root/rel` (frame sequence number `seq`) into `dir/rel` in the input's format,
    /// unless that file exists already. Returns whether it wrote the file. The file is written
    /// under a temporary name and renamed, so an interrupted run never leaves a half-written file
    /// that a resumed run would take as done.
    pub fn run(&mut self, root: &Path, rel: &Path, dir: &Path, seq: u64) -> Result<bool> {
        let out = dir.join(rel);
        if out.exists() {
            return Ok(false);
        }
        if let Some(p) = out.parent() {
            std::fs::create_dir_all(p).map_err(StudyError::io(p))?;
        }
        let input = root.join(rel);
        let tmp = out.with_file_name(format!(
            ".{}.partial",
            rel.file_name().and_then(|n| n.to_str()).unwrap_or("frame")
        ));
        let perturbing = || format!("perturbing {}", input.display());
        match (load(&input)?, &mut self.worker) {
            (Loaded::Image(img, kind), Worker::Camera(p)) => {
                let o = p
                    .apply_owned(&img.view(), seq)
                    .map_err(StudyError::perturb(perturbing()))?;
                save_image(&tmp, &o.view(), kind)?;
            }
            (Loaded::Cloud(c, kind, meta), Worker::Lidar(p)) => {
                let o = p
                    .apply_owned(&c.view(), seq, None)
                    .map_err(StudyError::perturb(perturbing()))?;
                save_cloud(&tmp, &o.view(), kind, meta)?;
            }
            _ => {
                return Err(StudyError::input(
                    &input,
                    "does not match the perturbation's modality",
                ));
            }
        }
        std::fs::rename(&tmp, &out).map_err(|e| {
            StudyError::input(&tmp, format!("cannot rename to {}: {e}", out.display()))
        })?;
        Ok(true)
    }
}

fn run_files_set(
    opts: &BatchOptions,
    set: Set,
    root: &Path,
    files: &[PathBuf],
    sensor: Option<&SensorModel>,
    progress: &dyn Progress,
) -> Result<()> {
    let dir = set.dir(&opts.out);
    std::fs::create_dir_all(&dir).map_err(StudyError::io(&dir))?;
    // Fails here, with its own error, if the perturbation cannot be built; the workers' copies
    // below are then built the same way.
    FileWorker::new(set, opts.seed, sensor)?;
    files
        .par_iter()
        .enumerate()
        .map_init(
            || FileWorker::new(set, opts.seed, sensor),
            |worker, (seq, rel)| -> Result<()> {
                let worker = worker
                    .as_mut()
                    .map_err(|e| StudyError::Config(e.to_string()))?;
                worker.run(root, rel, &dir, seq as u64)?;
                progress.inc(1);
                Ok(())
            },
        )
        .collect::<Result<Vec<()>>>()?;
    mark_done(&dir, files.len())
}
