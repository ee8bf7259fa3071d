//! Finding the study's outputs in a folder: every `.json` and `.csv` file (the folder and two
//! levels down) is recognised by what it holds, not by its name.

use crate::error::{Result, StudyError};
use crate::transfer::{MetricTable, read_table};
use serde::Serialize;
use serde_json::Value;
use std::path::{Path, PathBuf};

/// What a file of the study folder is.
#[derive(Clone, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum InputKind {
    /// `perturb analyze --json` or `--out DIR/analysis.json`.
    Analysis,
    /// `perturb analyze transfer --format json`.
    Transfer,
    /// `perturb analyze compare --format json`.
    Compare,
    /// `perturb metrics steering --format json|csv` (per-severity `mse`).
    Steering,
    /// `perturb metrics lidar --format json|csv` (per-severity `retention`).
    Lidar,
    /// `perturb bench [--hil BAG] --json|--format csv` (per-severity `mean_ms`).
    Latency,
}

impl InputKind {
    /// What produces it.
    pub fn tool(&self) -> &'static str {
        match self {
            InputKind::Analysis => "perturb analyze --json (or --out DIR: analysis.json)",
            InputKind::Transfer => "perturb analyze transfer --format json",
            InputKind::Compare => "perturb analyze compare --format json",
            InputKind::Steering => "perturb metrics steering --format json",
            InputKind::Lidar => "perturb metrics lidar --format json",
            InputKind::Latency => "perturb bench --hil BAG --json",
        }
    }
}

/// A recognised file.
#[derive(Clone, Debug, Serialize)]
pub struct Input {
    /// The file.
    pub path: PathBuf,
    /// What it is.
    pub kind: InputKind,
    /// The parsed document (JSON files).
    #[serde(skip)]
    pub json: Option<Value>,
    /// Its per-(perturbation, severity) rows (metric and latency tables).
    #[serde(skip)]
    pub table: Option<MetricTable>,
    /// The trajectory map written beside an analysis (`map.svg`).
    #[serde(skip)]
    pub map_svg: Option<String>,
}

/// A file that was looked at and not used.
#[derive(Clone, Debug, Serialize)]
pub struct Ignored {
    /// The file.
    pub path: PathBuf,
    /// Why.
    pub reason: String,
}

/// Every file of a study folder, recognised or not.
#[derive(Clone, Debug, Default, Serialize)]
pub struct Inputs {
    /// The recognised ones, in path order.
    pub used: Vec<Input>,
    /// The others.
    pub ignored: Vec<Ignored>,
}

impl Inputs {
    /// The recognised files of a kind.
    pub fn of(&self, kind: InputKind) -> impl Iterator<Item = &Input> {
        self.used.iter().filter(move |i| i.kind == kind)
    }
}

fn files(dir: &Path, depth: usize, out: &mut Vec<PathBuf>) -> Result<()> {
    let mut entries: Vec<PathBuf> = std::fs::read_dir(dir)
        .map_err(StudyError::io(dir))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .collect();
    entries.sort();
    for p in entries {
        let hidden = p
            .file_name()
            .is_some_and(|n| n.to_string_lossy().starts_with('.'));
        if hidden {
            continue;
        }
        if p.is_dir() {
            // A bag folder holds no study output.
            if depth > 0 && !crate::source::is_rosbag2_dir(&p) {
                files(&p, depth - 1, out)?;
            }
        } else if p.extension().is_some_and(|e| e == "json" || e == "csv") {
            out.push(p);
        }
    }
    Ok(())
}

fn has_key_in_rows(rows: &[Value], key: &str) -> bool {
    rows.iter().any(|r| r.get(key).is_some())
}

/// The kind of a JSON document, or why it is not one the report uses.
fn json_kind(v: &Value) -> std::result::Result<InputKind, String> {
    if let Value::Object(o) = v {
        if o.contains_key("runs") && o.contains_key("perturbations") && o.contains_key("conditions")
        {
            return Ok(InputKind::Analysis);
        }
        if o.contains_key("rows") && o.contains_key("matched") {
            return Ok(InputKind::Transfer);
        }
        if let Some(Value::Array(rows)) = o.get("per_severity") {
            if has_key_in_rows(rows, "mse") {
                return Ok(InputKind::Steering);
            }
            if has_key_in_rows(rows, "retention") {
                return Ok(InputKind::Lidar);
            }
        }
    }
    if let Value::Array(rows) = v {
        if has_key_in_rows(rows, "condition") && has_key_in_rows(rows, "set") {
            return Ok(InputKind::Compare);
        }
        if has_key_in_rows(rows, "mean_ms") {
            return Ok(InputKind::Latency);
        }
    }
    Err("a JSON document of no study tool the report reads".into())
}

/// The kind of a per-(perturbation, severity) table by its columns.
fn table_kind(t: &MetricTable) -> Option<InputKind> {
    let has = |k: &str| t.values().any(|m| m.contains_key(k));
    if has("mean_ms") {
        Some(InputKind::Latency)
    } else if has("mse") {
        Some(InputKind::Steering)
    } else if has("retention") {
        Some(InputKind::Lidar)
    } else {
        None
    }
}

/// Reads every study output under `dir` (itself and two folders down), skipping the files the
/// report writes (`skip`, its own tables beside it).
pub fn find_inputs(dir: &Path, skip: &[PathBuf]) -> Result<Inputs> {
    if !dir.is_dir() {
        return Err(StudyError::input(dir, "is not a folder"));
    }
    let mut paths = Vec::new();
    files(dir, 2, &mut paths)?;
    let mut inputs = Inputs::default();
    // The analyze --out folders: their tables are the analysis's own, already in analysis.json.
    let analysis_dirs: Vec<PathBuf> = paths
        .iter()
        .filter(|p| p.file_name().is_some_and(|n| n == "analysis.json"))
        .filter_map(|p| p.parent().map(Path::to_path_buf))
        .collect();
    for p in paths {
        if skip.iter().any(|s| s == &p) {
            continue;
        }
        let ignore = |reason: &str| Ignored {
            path: p.clone(),
            reason: reason.to_string(),
        };
        let is_json = p.extension().is_some_and(|e| e == "json");
        if !is_json
            && p.parent()
                .is_some_and(|d| analysis_dirs.iter().any(|a| a == d))
        {
            inputs.ignored.push(ignore(
                "a table written by perturb analyze --out (the report reads its analysis.json)",
            ));
            continue;
        }
        if is_json {
            let text = std::fs::read_to_string(&p).map_err(StudyError::io(&p))?;
            let v: Value = match serde_json::from_str(&text) {
                Ok(v) => v,
                Err(e) => {
                    inputs
                        .ignored
                        .push(ignore(&format!("not valid JSON ({e})")));
                    continue;
                }
            };
            match json_kind(&v) {
                Ok(kind) => {
                    let table = match kind {
                        InputKind::Steering | InputKind::Lidar | InputKind::Latency => {
                            Some(read_table(&p)?)
                        }
                        _ => None,
                    };
                    let map_svg = (kind == InputKind::Analysis)
                        .then(|| p.with_file_name("map.svg"))
                        .and_then(|m| std::fs::read_to_string(m).ok())
                        .filter(|s| s.trim_start().starts_with("<svg") && !s.contains("<script"));
                    inputs.used.push(Input {
                        path: p,
                        kind,
                        json: Some(v),
                        table,
                        map_svg,
                    });
                }
                Err(why) => inputs.ignored.push(ignore(&why)),
            }
        } else {
            match read_table(&p) {
                Ok(t) => match table_kind(&t) {
                    Some(kind) => inputs.used.push(Input {
                        path: p,
                        kind,
                        json: None,
                        table: Some(t),
                        map_svg: None,
                    }),
                    None => inputs.ignored.push(ignore(
                        "a CSV table without mean_ms, mse or retention columns",
                    )),
                },
                Err(e) => inputs.ignored.push(ignore(&e.to_string())),
            }
        }
    }
    Ok(inputs)
}
