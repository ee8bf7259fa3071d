//! `perturb metrics`: the study's tables from batch outputs and model predictions.

use anyhow::{Context, Result, bail};
use perturb_core::metrics::{SteeringMetrics, steering_metrics, summarize_camera};
use perturb_core::registry::{CATALOGUE, Entry};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// Output format of a metrics table.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, clap::ValueEnum)]
pub enum Format {
    /// Aligned terminal table.
    #[default]
    Table,
    /// Markdown table.
    Markdown,
    /// CSV, one row per perturbation and severity.
    Csv,
    /// JSON.
    Json,
}

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
        } => steering(&baseline, &predictions, format),
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
            let clean = match clean {
                Some(c) => c,
                None => clean_from_manifest(&perturbed)?,
            };
            let mut sets = crate::lidar_eval::discover_sets(&perturbed)?;
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
            let cfg = crate::lidar_eval::EvalConfig::new(
                objects,
                class.as_deref(),
                match_distance,
                (sensor.as_deref(), forward.as_deref()),
                topic,
                quiet,
            )?;
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads.unwrap_or(0))
                .build()?;
            let report = pool.install(|| crate::lidar_eval::evaluate(&clean, &sets, &cfg))?;
            print!("{}", crate::lidar_eval::render(&report, format)?);
            Ok(())
        }
    }
}

/// The input recorded in ROOT/batch.json.
fn clean_from_manifest(root: &Path) -> Result<PathBuf> {
    let path = root.join("batch.json");
    let text = std::fs::read_to_string(&path).with_context(|| {
        format!(
            "cannot read {} to find the clean data; give it with --clean",
            path.display()
        )
    })?;
    let v: serde_json::Value =
        serde_json::from_str(&text).with_context(|| format!("{} is not JSON", path.display()))?;
    match v.get("input").and_then(|i| i.as_str()) {
        Some(i) => {
            eprintln!(
                "clean data: {i} (from {}; override with --clean)",
                path.display()
            );
            Ok(PathBuf::from(i))
        }
        None => bail!(
            "{} records no input; give the clean data with --clean",
            path.display()
        ),
    }
}

/// Reads `frame,value` lines.
pub fn read_steering_csv(path: &Path) -> Result<Vec<(String, f64)>> {
    let text =
        std::fs::read_to_string(path).with_context(|| format!("cannot read {}", path.display()))?;
    let mut out = Vec::new();
    for (n, line) in text.lines().enumerate() {
        let line = line.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let mut it = line.split(',');
        let (Some(frame), Some(value)) = (it.next(), it.next()) else {
            bail!(
                "{}:{}: expected `frame,value`, found `{line}`",
                path.display(),
                n + 1
            );
        };
        match value.trim().parse::<f64>() {
            Ok(v) if v.is_finite() => out.push((frame.trim().to_string(), v)),
            Ok(_) => bail!(
                "{}:{}: steering value `{}` is not finite",
                path.display(),
                n + 1,
                value.trim()
            ),
            Err(_) if out.is_empty() && n == 0 => {} // a header line
            Err(_) => bail!(
                "{}:{}: `{}` is not a number",
                path.display(),
                n + 1,
                value.trim()
            ),
        }
    }
    if out.is_empty() {
        bail!("{} holds no prediction", path.display());
    }
    Ok(out)
}

/// The (perturbation, severity) a prediction file belongs to, from its path.
fn classify(rel: &Path) -> Option<(&'static Entry, u8)> {
    let parts: Vec<String> = rel
        .iter()
        .map(|c| c.to_string_lossy().trim_end_matches(".csv").to_string())
        .collect();
    let mut entry = None;
    let mut severity = None;
    for p in &parts {
        for e in CATALOGUE {
            let rest = p
                .strip_prefix(e.id)
                .filter(|r| r.is_empty() || r.starts_with('_'));
            if let Some(rest) = rest {
                // Longest ID wins (C-C1 vs C-C10).
                if entry.is_none_or(|x: &Entry| x.id.len() < e.id.len()) {
                    entry = Some(e);
                }
                if let Some(s) = rest
                    .rsplit('_')
                    .next()
                    .and_then(|t| t.strip_prefix('s'))
                    .and_then(|t| t.parse().ok())
                {
                    severity = Some(s);
                }
            }
        }
        if let Some(s) = p.strip_prefix('s').and_then(|t| t.parse::<u8>().ok()) {
            severity = Some(s);
        }
    }
    Some((entry?, severity?))
}

fn csv_files(dir: &Path, out: &mut Vec<PathBuf>) -> Result<()> {
    for e in std::fs::read_dir(dir).with_context(|| format!("cannot read {}", dir.display()))? {
        let p = e?.path();
        if p.is_dir() {
            csv_files(&p, out)?;
        } else if p.extension().is_some_and(|x| x == "csv") {
            out.push(p);
        }
    }
    Ok(())
}

#[derive(serde::Serialize)]
struct SteeringRow {
    id: &'static str,
    name: &'static str,
    severity: u8,
    #[serde(flatten)]
    m: SteeringMetrics,
}

fn steering(baseline: &Path, predictions: &Path, format: Format) -> Result<()> {
    let base = read_steering_csv(baseline)?;
    let mut files = Vec::new();
    csv_files(predictions, &mut files)?;
    files.sort();
    let mut rows: Vec<SteeringRow> = Vec::new();
    for f in &files {
        let rel = f.strip_prefix(predictions).unwrap_or(f);
        let Some((entry, severity)) = classify(rel) else {
            eprintln!(
                "skipping {}: cannot tell the perturbation and severity from its path",
                f.display()
            );
            continue;
        };
        let pert = read_steering_csv(f)?;
        let m = steering_metrics(&base, &pert)
            .with_context(|| format!("comparing {} with {}", f.display(), baseline.display()))?;
        rows.push(SteeringRow {
            id: entry.id,
            name: entry.name,
            severity,
            m,
        });
    }
    if rows.is_empty() {
        bail!("no prediction CSV found under {}", predictions.display());
    }
    let mut by_id: BTreeMap<usize, Vec<&SteeringRow>> = BTreeMap::new();
    for r in &rows {
        let pos = CATALOGUE
            .iter()
            .position(|e| e.id == r.id)
            .unwrap_or(usize::MAX);
        by_id.entry(pos).or_default().push(r);
    }
    match format {
        Format::Json => {
            #[derive(serde::Serialize)]
            struct Out<'a> {
                per_severity: &'a [SteeringRow],
                per_perturbation: Vec<serde_json::Value>,
            }
            let per: Vec<serde_json::Value> = by_id
                .values()
                .map(|rs| {
                    let s = summarize_camera(&rs.iter().map(|r| r.m).collect::<Vec<_>>());
                    serde_json::json!({"id": rs[0].id, "name": rs[0].name, "avg_mse": s.avg_mse, "max_mse": s.max_mse, "max_abs_deviation": s.max_abs_deviation})
                })
                .collect();
            println!(
                "{}",
                serde_json::to_string_pretty(&Out {
                    per_severity: &rows,
                    per_perturbation: per
                })?
            );
        }
        Format::Csv => {
            println!(
                "id,name,severity,frames,mse,max_abs_deviation,jitter_baseline,jitter_perturbed"
            );
            for r in &rows {
                println!(
                    "{},{},{},{},{},{},{},{}",
                    r.id,
                    r.name,
                    r.severity,
                    r.m.frames,
                    r.m.mse,
                    r.m.max_abs_deviation,
                    r.m.jitter_baseline,
                    r.m.jitter_perturbed
                );
            }
        }
        Format::Table | Format::Markdown => {
            let md = format == Format::Markdown;
            if md {
                println!(
                    "| id | name | avg MSE | max MSE | max deviation | severities |\n|---|---|---:|---:|---:|---|"
                );
            } else {
                println!(
                    "{:<7} {:<24} {:>10} {:>10} {:>13}  severities",
                    "id", "name", "avg_mse", "max_mse", "max_deviation"
                );
            }
            for rs in by_id.values() {
                let s = summarize_camera(&rs.iter().map(|r| r.m).collect::<Vec<_>>());
                let sev: Vec<String> = rs.iter().map(|r| r.severity.to_string()).collect();
                if md {
                    println!(
                        "| {} | {} | {:.5} | {:.5} | {:.4} | {} |",
                        rs[0].id,
                        rs[0].name,
                        s.avg_mse,
                        s.max_mse,
                        s.max_abs_deviation,
                        sev.join(",")
                    );
                } else {
                    println!(
                        "{:<7} {:<24} {:>10.5} {:>10.5} {:>13.4}  {}",
                        rs[0].id,
                        rs[0].name,
                        s.avg_mse,
                        s.max_mse,
                        s.max_abs_deviation,
                        sev.join(",")
                    );
                }
            }
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn classifies_the_documented_layouts() {
        let c = |p: &str| classify(Path::new(p)).map(|(e, s)| (e.id, s));
        assert_eq!(c("C-A1_gaussian_noise/s3.csv"), Some(("C-A1", 3)));
        assert_eq!(c("C-C10_s5.csv"), Some(("C-C10", 5)));
        assert_eq!(c("C-C1_frost/s2/preds.csv"), Some(("C-C1", 2)));
        assert_eq!(c("baseline.csv"), None);
    }
}
