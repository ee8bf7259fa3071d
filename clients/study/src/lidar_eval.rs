//! LiDAR detection metrics (paper, RQ1) over the perturbed sets that `perturb batch` writes.
//!
//! The clustering detector (`perturb_core::detector`, after Autoware Mini) runs on every clean
//! scan and on its perturbed counterpart in each set `ROOT/<ID>_<name>/s<N>/`; the boxes are
//! matched per frame (`perturb_core::metrics::detection_metrics`: greedy, one-to-one, ground-plane
//! centre distance within the match radius) and the counts are pooled over the frames of a set:
//! retention = matched baseline detections / baseline detections over all frames (the recall of
//! the baseline detections over the dataset), ATE = mean centre distance over all matches. Per
//! perturbation, the severities are summarised as the paper does: average and minimum retention,
//! maximum ATE.
//!
//! Frames are detected in parallel (rayon); each frame's boxes depend only on its points, and the
//! pooling runs in frame order afterwards, so the numbers do not depend on the thread count.

use crate::dataset::Dataset;
use crate::error::{Result, StudyError};
use crate::files::{Loaded, load};
use crate::progress::Progress;
use perturb_bag::{Bag, Filter, SensorMessage};
use perturb_core::detector::{Detector, DetectorConfig, ObjectClass};
use perturb_core::lidar::{Box3, Points};
use perturb_core::metrics::{
    DetectionMetrics, LidarSummary, MatchConfig, detection_metrics, summarize_lidar,
};
use perturb_core::registry::{CATALOGUE, Entry, Modality};
use perturb_core::sensor_model::SensorModel;
use rayon::prelude::*;
use std::collections::HashMap;
use std::ops::ControlFlow;
use std::path::{Path, PathBuf};

/// Output format of a metrics table.
pub use crate::Format;

/// Bag clouds decoded and then detected together (in parallel) at a time.
const BAG_CHUNK: usize = 16;

/// How the metrics are computed.
#[derive(Clone, Debug)]
pub struct EvalConfig {
    /// The detector's parameters.
    pub detector: DetectorConfig,
    /// `"default"`, `"objects"` or the class counted, for the report.
    pub detector_name: &'static str,
    /// Box matching.
    pub matching: MatchConfig,
    /// Sensor model used to read the clouds of a bag (its intensity scale and axes).
    pub sensor: SensorModel,
    /// `--sensor` and `--forward` as given, for the files' own defaults (nuScenes `.pcd.bin`
    /// files are y-forward HDL-32E clouds unless told otherwise).
    pub sensor_args: (Option<String>, Option<String>),
    /// Bags: only these PointCloud2 topics (all when empty).
    pub topics: Vec<String>,
}

impl EvalConfig {
    /// The configuration from the command-line options: the detector's reference parameters
    /// (`objects`: only road users; `class`: only that class), the match radius, the sensor model
    /// and forward axis (defaults per file kind, see `files::sensor_for`).
    pub fn new(
        objects: bool,
        class: Option<&str>,
        match_distance: f32,
        (sensor, forward): (Option<&str>, Option<&str>),
        topics: Vec<String>,
    ) -> Result<Self> {
        if !(match_distance.is_finite() && match_distance > 0.0) {
            return Err(StudyError::Config(format!(
                "--match-distance must be a positive number of metres, not {match_distance}"
            )));
        }
        let (detector, detector_name) = match (class, objects) {
            (Some(c), _) => {
                let c = ObjectClass::parse(c)
                    .map_err(|e| StudyError::Config(format!("--class: {e}")))?;
                (DetectorConfig::only(c), c.as_str())
            }
            (None, true) => (DetectorConfig::objects(), "objects"),
            (None, false) => (DetectorConfig::default(), "default"),
        };
        Ok(EvalConfig {
            detector,
            detector_name,
            matching: MatchConfig {
                max_center_distance: match_distance,
            },
            sensor: crate::files::sensor_for(None, sensor, forward, None)?,
            sensor_args: (sensor.map(String::from), forward.map(String::from)),
            topics,
        })
    }

    /// The sensor model of the cloud file `path`.
    fn sensor_of(&self, path: &Path) -> Result<SensorModel> {
        let kind = perturb_core::formats::FileKind::from_path(path).ok();
        let (s, f) = &self.sensor_args;
        crate::files::sensor_for(kind, s.as_deref(), f.as_deref(), None)
    }
}

/// Where the clean frames are, and where a perturbed set's counterparts are.
#[derive(Clone, Debug)]
pub enum Source {
    /// Point-cloud files `root/rel` for every `rel` (sorted).
    Files {
        /// The folder.
        root: PathBuf,
        /// Paths relative to `root`.
        files: Vec<PathBuf>,
    },
    /// A rosbag2 MCAP bag: every PointCloud2 message, keyed by topic and index on the topic.
    Bag(PathBuf),
}

impl Source {
    /// The clean dataset at `path` (a folder of point clouds, or a bag).
    pub fn open(path: &Path) -> Result<Source> {
        Ok(match Dataset::open(path)? {
            Dataset::Files {
                root,
                files,
                modality: Modality::Lidar,
            } => Source::Files { root, files },
            Dataset::Files { .. } => {
                return Err(StudyError::input(
                    path,
                    "holds images; the LiDAR metrics need point clouds (.bin .pcd .pcd.bin) or a bag",
                ));
            }
            Dataset::Bag(p) => Source::Bag(p),
        })
    }

    /// The same frames in a perturbed set directory (same relative files, or a bag).
    fn in_set(&self, dir: &Path) -> Source {
        match self {
            Source::Files { files, .. } => Source::Files {
                root: dir.to_path_buf(),
                files: files.clone(),
            },
            Source::Bag(_) => Source::Bag(dir.to_path_buf()),
        }
    }
}

/// The boxes of every frame of a source, in frame order, keyed by relative path (files) or
/// `topic#index` (bags).
pub type FrameBoxes = Vec<(String, Vec<Box3>)>;

fn points_of_file(path: &Path, cfg: &EvalConfig) -> Result<Points> {
    let sensor = cfg.sensor_of(path)?;
    match load(path)? {
        Loaded::Cloud(c, _, _) => Points::extract(&c.view(), &sensor, false).map_err(
            StudyError::perturb(format!("reading the points of {}", path.display())),
        ),
        Loaded::Image(..) => Err(StudyError::input(path, "is an image, not a point cloud")),
    }
}

/// Runs the detector on every frame of `source`.
pub fn detect_source(source: &Source, cfg: &EvalConfig, pb: &dyn Progress) -> Result<FrameBoxes> {
    match source {
        Source::Files { root, files } => files
            .par_iter()
            .map_init(
                || Detector::new(cfg.detector.clone()),
                |det, rel| {
                    let path = root.join(rel);
                    if !path.exists() {
                        return Err(StudyError::input(
                            &path,
                            "is missing (the set is incomplete; rerun `perturb batch` to finish it)",
                        ));
                    }
                    let p = points_of_file(&path, cfg)?;
                    let boxes = det.detect(&p);
                    pb.inc(1);
                    Ok((rel.display().to_string(), boxes))
                },
            )
            .collect(),
        Source::Bag(path) => detect_bag(path, cfg, pb),
    }
}

fn detect_bag(path: &Path, cfg: &EvalConfig, pb: &dyn Progress) -> Result<FrameBoxes> {
    let bag = Bag::open(path)?;
    let mut out: FrameBoxes = Vec::new();
    let mut chunk: Vec<(String, Points)> = Vec::with_capacity(BAG_CHUNK);
    let mut index: HashMap<String, u64> = HashMap::new();
    let flush = |chunk: &mut Vec<(String, Points)>, out: &mut FrameBoxes| {
        let done: FrameBoxes = chunk
            .par_iter()
            .map_init(
                || Detector::new(cfg.detector.clone()),
                |det, (key, p)| (key.clone(), det.detect(p)),
            )
            .collect();
        pb.inc(done.len() as u64);
        out.extend(done);
        chunk.clear();
    };
    let filter = Filter {
        topics: cfg.topics.clone(),
        ..Filter::default()
    };
    let report = bag.for_each(&filter, |m| {
        if perturb_bag::SensorType::of(m.type_name) != Some(perturb_bag::SensorType::PointCloud2) {
            return Ok(ControlFlow::Continue(()));
        }
        let Some(Ok(SensorMessage::Cloud(pc))) = m.decode() else {
            return Err(perturb_bag::BagError::Callback(format!(
                "{}: `{}` at log time {}: the PointCloud2 message does not decode",
                m.path.display(),
                m.topic,
                m.log_time
            )));
        };
        let points = pc
            .view()
            .and_then(|v| Points::extract(&v, &cfg.sensor, false))
            .map_err(|e| {
                perturb_bag::BagError::Callback(format!(
                    "{}: `{}` at log time {}: {e}",
                    m.path.display(),
                    m.topic,
                    m.log_time
                ))
            })?;
        let k = index.entry(m.topic.to_string()).or_default();
        chunk.push((format!("{}#{}", m.topic, *k), points));
        *k += 1;
        if chunk.len() == BAG_CHUNK {
            flush(&mut chunk, &mut out);
        }
        Ok(ControlFlow::Continue(()))
    })?;
    flush(&mut chunk, &mut out);
    if let Some(d) = report.damage {
        return Err(StudyError::input(path, format!("the bag is damaged: {d}")));
    }
    Ok(out)
}

/// The clean data recorded as the input of `perturb batch` in `ROOT/batch.json`.
pub fn clean_from_manifest(root: &Path) -> Result<PathBuf> {
    let path = root.join("batch.json");
    let text = std::fs::read_to_string(&path).map_err(|e| {
        StudyError::input(
            &path,
            format!("cannot read it to find the clean data ({e}); give it with --clean"),
        )
    })?;
    let v: serde_json::Value = serde_json::from_str(&text)
        .map_err(|e| StudyError::input(&path, format!("is not JSON ({e})")))?;
    match v.get("input").and_then(|i| i.as_str()) {
        Some(i) => Ok(PathBuf::from(i)),
        None => Err(StudyError::input(
            &path,
            "records no input; give the clean data with --clean",
        )),
    }
}

/// One perturbed set found under a batch output root.
#[derive(Clone, Debug)]
pub struct SetDir {
    /// The perturbation.
    pub entry: &'static Entry,
    /// Severity.
    pub severity: u8,
    /// `ROOT/<ID>_<name>/s<N>`.
    pub dir: PathBuf,
}

/// The finished LiDAR sets under `root` (`<ID>_<name>/s<N>/` with a `.done` marker), in catalogue
/// and severity order. Unfinished sets are skipped with a note; camera sets are ignored.
pub fn discover_sets(root: &Path, progress: &dyn Progress) -> Result<Vec<SetDir>> {
    let mut sets = Vec::new();
    let rd = std::fs::read_dir(root).map_err(StudyError::io(root))?;
    for e in rd {
        let dir = e.map_err(StudyError::io(root))?.path();
        if !dir.is_dir() {
            continue;
        }
        let name = dir
            .file_name()
            .map(|n| n.to_string_lossy().to_string())
            .unwrap_or_default();
        let Some(entry) = CATALOGUE
            .iter()
            .filter(|e| name == format!("{}_{}", e.id, e.name))
            .max_by_key(|e| e.id.len())
        else {
            continue;
        };
        if entry.modality != Modality::Lidar {
            continue;
        }
        for s in std::fs::read_dir(&dir).map_err(StudyError::io(&dir))? {
            let sdir = s.map_err(StudyError::io(&dir))?.path();
            let Some(severity) = sdir
                .file_name()
                .and_then(|n| n.to_str())
                .and_then(|n| n.strip_prefix('s'))
                .and_then(|n| n.parse::<u8>().ok())
            else {
                continue;
            };
            if !sdir.is_dir() {
                continue;
            }
            if !sdir.join(".done").exists() {
                progress.note(&format!(
                    "skipping {}: unfinished (no .done marker; rerun `perturb batch` to finish it)",
                    sdir.display()
                ));
                continue;
            }
            sets.push(SetDir {
                entry,
                severity,
                dir: sdir,
            });
        }
    }
    sets.sort_by_key(|s| {
        (
            CATALOGUE.iter().position(|c| c.id == s.entry.id),
            s.severity,
        )
    });
    Ok(sets)
}

/// The metrics of one (perturbation, severity) set.
#[derive(Clone, Debug, serde::Serialize)]
pub struct SetMetrics {
    /// Perturbation ID.
    pub id: &'static str,
    /// Perturbation name.
    pub name: &'static str,
    /// Severity.
    pub severity: u8,
    /// Frames compared.
    pub frames: usize,
    /// Pooled over the frames.
    #[serde(flatten)]
    pub m: DetectionMetrics,
}

/// One perturbation summarised over its severities.
#[derive(Clone, Debug, serde::Serialize)]
pub struct PerturbationSummary {
    /// Perturbation ID.
    pub id: &'static str,
    /// Perturbation name.
    pub name: &'static str,
    /// The severities evaluated.
    pub severities: Vec<u8>,
    /// Average / minimum retention, maximum ATE.
    #[serde(flatten)]
    pub s: LidarSummary,
}

/// The whole evaluation.
#[derive(Clone, Debug, serde::Serialize)]
pub struct Report {
    /// The clean dataset.
    pub clean: String,
    /// Clean frames.
    pub frames: usize,
    /// Detections on the clean frames.
    pub baseline_detections: usize,
    /// `default` (Autoware Mini's parameters) or `objects` (plus a road-user size limit).
    pub detector: &'static str,
    /// Largest matched centre distance, metres.
    pub match_distance_m: f32,
    /// Per set.
    pub per_severity: Vec<SetMetrics>,
    /// Per perturbation.
    pub per_perturbation: Vec<PerturbationSummary>,
}

/// Pools the per-frame metrics of a set against the clean boxes, in the clean frame order.
pub fn compare(
    clean: &FrameBoxes,
    perturbed: &FrameBoxes,
    m: &MatchConfig,
) -> std::result::Result<DetectionMetrics, String> {
    let index: HashMap<&str, &Vec<Box3>> = perturbed.iter().map(|(k, b)| (k.as_str(), b)).collect();
    let mut total = DetectionMetrics {
        retention: 1.0,
        ..DetectionMetrics::default()
    };
    for (key, base) in clean {
        let Some(p) = index.get(key.as_str()) else {
            return Err(format!(
                "frame `{key}` of the clean data has no perturbed counterpart"
            ));
        };
        total.add(&detection_metrics(base, p, m));
    }
    Ok(total)
}

/// Detects on the clean data and on every set, and computes the metrics (frames in parallel on
/// the current rayon pool; progress counts clouds).
pub fn evaluate(
    clean_path: &Path,
    sets: &[SetDir],
    cfg: &EvalConfig,
    pb: &dyn Progress,
) -> Result<Report> {
    if sets.is_empty() {
        return Err(StudyError::Config(
            "no finished LiDAR set to evaluate".into(),
        ));
    }
    let clean = Source::open(clean_path)?;
    let frames_hint = match &clean {
        Source::Files { files, .. } => files.len() as u64,
        Source::Bag(_) => 0,
    };
    pb.set_length(frames_hint * (sets.len() as u64 + 1));
    pb.set_message("clean");
    let base = detect_source(&clean, cfg, pb)?;
    if base.is_empty() {
        return Err(StudyError::input(clean_path, "holds no point cloud"));
    }
    if frames_hint == 0 {
        pb.set_length(base.len() as u64 * (sets.len() as u64 + 1));
    }
    let mut per_severity = Vec::new();
    for set in sets {
        pb.set_message(&format!("{} s{}", set.entry.id, set.severity));
        let pert = detect_source(&clean.in_set(&set.dir), cfg, pb)?;
        let m = compare(&base, &pert, &cfg.matching).map_err(|reason| {
            StudyError::input(
                &set.dir,
                format!("comparing with {}: {reason}", clean_path.display()),
            )
        })?;
        per_severity.push(SetMetrics {
            id: set.entry.id,
            name: set.entry.name,
            severity: set.severity,
            frames: base.len(),
            m,
        });
    }
    pb.finish();
    let mut per_perturbation: Vec<PerturbationSummary> = Vec::new();
    for r in &per_severity {
        if per_perturbation.last().is_none_or(|p| p.id != r.id) {
            let rows: Vec<&SetMetrics> = per_severity.iter().filter(|x| x.id == r.id).collect();
            per_perturbation.push(PerturbationSummary {
                id: r.id,
                name: r.name,
                severities: rows.iter().map(|x| x.severity).collect(),
                s: summarize_lidar(&rows.iter().map(|x| x.m).collect::<Vec<_>>()),
            });
        }
    }
    Ok(Report {
        clean: clean_path.display().to_string(),
        frames: base.len(),
        baseline_detections: base.iter().map(|(_, b)| b.len()).sum(),
        detector: cfg.detector_name,
        match_distance_m: cfg.matching.max_center_distance,
        per_severity,
        per_perturbation,
    })
}

fn frames(n: usize) -> String {
    format!("{n} frame{}", if n == 1 { "" } else { "s" })
}

fn ate(v: Option<f64>) -> String {
    v.map_or("-".to_string(), |a| format!("{a:.3}"))
}

/// The report in `format`.
pub fn render(r: &Report, format: Format) -> String {
    use std::fmt::Write;
    let mut s = String::new();
    let per_sev = |id: &str, md: bool| -> String {
        r.per_severity
            .iter()
            .filter(|x| x.id == id)
            .map(|x| {
                if md {
                    format!("s{}: {:.3} / {}", x.severity, x.m.retention, ate(x.m.ate))
                } else {
                    format!("s{} {:.3}/{}", x.severity, x.m.retention, ate(x.m.ate))
                }
            })
            .collect::<Vec<_>>()
            .join(if md { ", " } else { "  " })
    };
    match format {
        Format::Json => s = serde_json::to_string_pretty(r).expect("the report serialises") + "\n",
        Format::Csv => {
            let _ = writeln!(
                s,
                "id,name,severity,frames,baseline,retained,retention,ate_m"
            );
            for x in &r.per_severity {
                let _ = writeln!(
                    s,
                    "{},{},{},{},{},{},{},{}",
                    x.id,
                    x.name,
                    x.severity,
                    x.frames,
                    x.m.baseline,
                    x.m.retained,
                    x.m.retention,
                    x.m.ate.map_or(String::new(), |a| a.to_string())
                );
            }
        }
        Format::Markdown => {
            let _ = writeln!(
                s,
                "LiDAR detection metrics: {} of `{}`, {} baseline detections (detector `{}`, match within {} m)\n",
                frames(r.frames),
                r.clean,
                r.baseline_detections,
                r.detector,
                r.match_distance_m
            );
            let _ = writeln!(
                s,
                "| id | name | avg retention | min retention | max ATE (m) | retention / ATE per severity |\n|---|---|---:|---:|---:|---|"
            );
            for p in &r.per_perturbation {
                let _ = writeln!(
                    s,
                    "| {} | {} | {:.3} | {:.3} | {} | {} |",
                    p.id,
                    p.name,
                    p.s.avg_retention,
                    p.s.min_retention,
                    ate(p.s.max_ate),
                    per_sev(p.id, true)
                );
            }
        }
        Format::Table => {
            let _ = writeln!(
                s,
                "{} of {}, {} baseline detections (detector {}, match within {} m)",
                frames(r.frames),
                r.clean,
                r.baseline_detections,
                r.detector,
                r.match_distance_m
            );
            let _ = writeln!(
                s,
                "{:<7} {:<26} {:>8} {:>8} {:>8}  retention/ATE per severity",
                "id", "name", "avg_ret", "min_ret", "max_ate"
            );
            for p in &r.per_perturbation {
                let _ = writeln!(
                    s,
                    "{:<7} {:<26} {:>8.3} {:>8.3} {:>8}  {}",
                    p.id,
                    p.name,
                    p.s.avg_retention,
                    p.s.min_retention,
                    ate(p.s.max_ate),
                    per_sev(p.id, false)
                );
            }
        }
    }
    s
}
