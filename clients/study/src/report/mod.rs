//! `perturb report`: the paper's tables and figures in one self-contained HTML page, built from
//! the outputs the study's tools already write into a folder (recognised by what they hold,
//! see [`inputs`]):
//!
//! - the combined per-perturbation tables, one per modality (RQ1 offline effect with trend bars
//!   per severity; RQ2 average and maximum latency, node overhead, feasibility against the
//!   33 ms / 200 ms budgets), from `perturb metrics` and `perturb bench`;
//! - the RQ3 table (completion bars per run, failure types, CTE, jitter, coverage, unjudged
//!   runs) from `perturb analyze`;
//! - transfer (rho, bootstrap CI, p, q, top-5 overlap, a scatter plot per metric pair), from
//!   `perturb analyze transfer` or computed from the offline and closed-loop tables;
//! - the trajectory map with the failure hotspots and their table;
//! - per-severity curves of the offline metrics, latency bars against the budget;
//! - the RQ4 table (fine-tuned vs baseline) from `perturb analyze compare`.
//!
//! A section whose input is missing says which input and how to make it. The same tables are
//! written beside the page as CSV and as one JSON document.

mod html;
pub mod inputs;

pub use inputs::{InputKind, Inputs, find_inputs};

use crate::error::{Result, StudyError};
use crate::plot::charts::{self, Curve, LatencyBar, ScatterPoint};
use crate::table::{Table, num, raw};
use crate::transfer::{
    MetricTable, Transfer, TransferConfig, default_budget, keep_feasible, read_table, transfer,
};
use perturb_core::registry::{CATALOGUE, Modality};
use serde::Serialize;
use serde_json::Value;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// How the report is built.
#[derive(Clone, Debug)]
pub struct ReportOptions {
    /// The page's title.
    pub title: String,
    /// The transfer analysis, when the report computes it.
    pub transfer: TransferConfig,
}

impl Default for ReportOptions {
    fn default() -> Self {
        ReportOptions {
            title: "Sensor perturbation study".into(),
            transfer: TransferConfig::default(),
        }
    }
}

/// A section of the report: its content, or why it is missing.
#[derive(Clone, Debug, Serialize)]
#[serde(tag = "status", rename_all = "snake_case")]
pub enum Section<T> {
    /// Built.
    Present {
        /// The content.
        content: T,
    },
    /// Not built, and why (the input that is missing and how to make it).
    Missing {
        /// Why.
        reason: String,
    },
}

impl<T> Section<T> {
    fn missing(reason: impl Into<String>) -> Self {
        Section::Missing {
            reason: reason.into(),
        }
    }

    /// The content, if present.
    pub fn content(&self) -> Option<&T> {
        match self {
            Section::Present { content } => Some(content),
            Section::Missing { .. } => None,
        }
    }
}

/// One perturbation in the combined RQ1/RQ2 table.
#[derive(Clone, Debug, Default, Serialize)]
pub struct CombinedRow {
    /// Perturbation ID.
    pub id: String,
    /// Catalogue name.
    pub name: String,
    /// Catalogue family.
    pub family: String,
    /// Severities with an offline measurement.
    pub severities: Vec<u8>,
    /// Camera: mean over the severities of the steering MSE.
    pub avg_mse: Option<f64>,
    /// Camera: largest MSE.
    pub max_mse: Option<f64>,
    /// Camera: largest absolute steering deviation.
    pub max_abs_deviation: Option<f64>,
    /// LiDAR: mean retention over the severities.
    pub avg_retention: Option<f64>,
    /// LiDAR: smallest retention.
    pub min_retention: Option<f64>,
    /// LiDAR: largest ATE, metres.
    pub max_ate: Option<f64>,
    /// The trend bars: MSE (camera) or 1 - retention (LiDAR) per severity.
    pub trend: Vec<(u8, f64)>,
    /// Mean over the severities of the mean latency per frame, ms.
    pub avg_latency_ms: Option<f64>,
    /// Largest latency per frame at any severity, ms.
    pub max_latency_ms: Option<f64>,
    /// Middleware (node) overhead, ms (`perturb bench --hil`).
    pub node_overhead_ms: Option<f64>,
    /// The budget, ms.
    pub budget_ms: f64,
    /// Feasible: the average latency is within the budget (None without latency).
    pub feasible: Option<bool>,
    /// The maximum latency is within the budget too.
    pub max_within_budget: Option<bool>,
}

/// The combined table of one modality.
#[derive(Clone, Debug, Serialize)]
pub struct Combined {
    /// `camera` or `lidar`.
    pub modality: String,
    /// One row per perturbation, catalogue order.
    pub rows: Vec<CombinedRow>,
    /// Parts without their input (e.g. no latency).
    pub notes: Vec<String>,
}

/// The trajectory metrics of an aggregated row, as the tools wrote them.
#[derive(Clone, Debug, Serialize)]
pub struct Trajectory {
    /// CTE average, m.
    pub cte_avg: Option<f64>,
    /// CTE maximum, m.
    pub cte_max: Option<f64>,
    /// Jitter average.
    pub jitter_avg: Option<f64>,
    /// Jitter maximum.
    pub jitter_max: Option<f64>,
    /// Jitter standard deviation.
    pub jitter_std: Option<f64>,
}

impl Trajectory {
    fn of(row: &Value) -> Self {
        Trajectory {
            cte_avg: f(row, "cte_avg"),
            cte_max: f(row, "cte_max"),
            jitter_avg: f(row, "jitter_avg"),
            jitter_max: f(row, "jitter_max"),
            jitter_std: f(row, "jitter_std"),
        }
    }

    /// The five values as CSV cells.
    fn cells(&self) -> [String; 5] {
        [
            raw(self.cte_avg),
            raw(self.cte_max),
            raw(self.jitter_avg),
            raw(self.jitter_max),
            raw(self.jitter_std),
        ]
    }
}

/// One row of the RQ3 table (a perturbation over its runs).
#[derive(Clone, Debug, Serialize)]
pub struct Rq3Row {
    /// `nominal` or the ID.
    pub perturbation: String,
    /// Catalogue name.
    pub name: String,
    /// Runs (segments).
    pub runs: usize,
    /// Runs not judged.
    pub unjudged: usize,
    /// Completion of each run, highest severity first.
    pub completions: Vec<Option<f64>>,
    /// Outcome letters (`ok`, failure letter, `?`).
    pub outcomes: Vec<String>,
    /// Severity of each run.
    pub run_severities: Vec<Option<u8>>,
    /// Failing / judged runs.
    pub failure_rate: Option<f64>,
    /// CTE and jitter.
    #[serde(flatten)]
    pub trajectory: Trajectory,
    /// Near-field coverage.
    pub coverage_5m: Option<f64>,
}

/// One hotspot (or noise failure) row.
#[derive(Clone, Debug, Serialize)]
pub struct HotspotRow {
    /// `H0`, ... or `noise`.
    pub hotspot: String,
    /// Failure type.
    pub failure: String,
    /// Centre (or position), pose frame, m.
    pub x: f64,
    /// Centre, m.
    pub y: f64,
    /// Failures in it.
    pub size: usize,
    /// Radius, m.
    pub radius_m: f64,
    /// Perturbations with counts, most first.
    pub perturbations: String,
    /// Families with counts.
    pub families: String,
}

/// One analysis (a folder of runs) in the report.
#[derive(Clone, Debug, Serialize)]
pub struct ClosedLoop {
    /// Its name (the folder of its analysis.json).
    pub name: String,
    /// The file.
    pub path: PathBuf,
    /// Counts of ok, failed and unjudged runs (`summary`), when the file has them.
    pub summary: Option<Value>,
    /// The RQ3 rows.
    pub rows: Vec<Rq3Row>,
    /// Hotspots and noise failures.
    pub hotspots: Vec<HotspotRow>,
    /// The trajectory map (the map.svg beside the analysis), inline.
    #[serde(skip)]
    pub map_svg: Option<String>,
}

/// The transfer section.
#[derive(Clone, Debug, Serialize)]
pub struct TransferSection {
    /// Where it came from: a file, or computed here.
    pub source: String,
    /// Pairs left out as infeasible (latency over budget).
    pub infeasible: Vec<String>,
    /// The analysis.
    pub transfer: Transfer,
}

/// The RQ4 rows, as `perturb analyze compare` wrote them.
#[derive(Clone, Debug, Serialize)]
pub struct Rq4Row {
    /// Condition.
    pub condition: String,
    /// Set (model).
    pub set: String,
    /// Completions.
    pub completions: Vec<Option<f64>>,
    /// Outcome letters.
    pub outcomes: Vec<String>,
    /// CTE and jitter.
    #[serde(flatten)]
    pub trajectory: Trajectory,
    /// The shared non-failing portion, m.
    pub shared_until_m: Option<f64>,
}

/// Everything the page shows.
#[derive(Clone, Debug, Serialize)]
pub struct Report {
    /// Title.
    pub title: String,
    /// The study folder.
    pub study_dir: PathBuf,
    /// The files used and ignored.
    pub inputs: Inputs,
    /// Combined RQ1/RQ2 tables, camera then LiDAR.
    pub combined: Section<Vec<Combined>>,
    /// RQ3, one per analysis.
    pub closed_loop: Section<Vec<ClosedLoop>>,
    /// Transfer.
    pub transfer: Section<TransferSection>,
    /// RQ4.
    pub rq4: Section<Vec<Rq4Row>>,
    /// Per-severity curves: (metric, SVG).
    #[serde(skip)]
    pub curves: Section<Vec<(String, String)>>,
    /// Latency bars: (modality, SVG).
    #[serde(skip)]
    pub latency: Section<Vec<(String, String)>>,
}

fn f(v: &Value, k: &str) -> Option<f64> {
    v.get(k).and_then(Value::as_f64)
}

fn text(v: &Value, k: &str) -> String {
    v.get(k)
        .and_then(Value::as_str)
        .unwrap_or_default()
        .to_string()
}

fn merged(inputs: &Inputs, kind: InputKind) -> Option<MetricTable> {
    let mut t = MetricTable::new();
    for i in inputs.of(kind) {
        if let Some(table) = &i.table {
            t.extend(table.clone());
        }
    }
    (!t.is_empty()).then_some(t)
}

fn mean(v: &[f64]) -> Option<f64> {
    (!v.is_empty()).then(|| v.iter().sum::<f64>() / v.len() as f64)
}

fn column(t: Option<&MetricTable>, id: &str, key: &str) -> Vec<(u8, f64)> {
    t.map(|t| {
        t.iter()
            .filter(|((i, _), _)| i == id)
            .filter_map(|((_, s), m)| m.get(key).map(|v| (*s, *v)))
            .collect()
    })
    .unwrap_or_default()
}

fn values(v: &[(u8, f64)]) -> Vec<f64> {
    v.iter().map(|x| x.1).collect()
}

fn max(v: &[f64]) -> Option<f64> {
    v.iter().copied().reduce(f64::max)
}

fn min(v: &[f64]) -> Option<f64> {
    v.iter().copied().reduce(f64::min)
}

const HOW_METRICS: &str = "write `perturb metrics steering --format json > STUDY_DIR/steering.json` (camera) or `perturb metrics lidar --format json > STUDY_DIR/lidar.json` (LiDAR)";
const HOW_BENCH: &str = "write `perturb bench --modality camera --hil BAG --json > STUDY_DIR/bench_camera.json` (and the same for lidar)";
const HOW_ANALYZE: &str = "write `perturb analyze RUNS_DIR --route ROUTE --pose-topic TOPIC ... --out STUDY_DIR/closed_loop`";

fn combined(inputs: &Inputs) -> Section<Vec<Combined>> {
    let steering = merged(inputs, InputKind::Steering);
    let lidar = merged(inputs, InputKind::Lidar);
    let latency = merged(inputs, InputKind::Latency);
    if steering.is_none() && lidar.is_none() && latency.is_none() {
        return Section::missing(format!(
            "no model-level metrics and no latency table in the study folder: {HOW_METRICS}; {HOW_BENCH}"
        ));
    }
    let ids = |t: &Option<MetricTable>| -> Vec<String> {
        t.as_ref()
            .map(|t| t.keys().map(|k| k.0.clone()).collect())
            .unwrap_or_default()
    };
    let mut out = Vec::new();
    for (modality, offline, what) in [
        (Modality::Camera, &steering, "camera"),
        (Modality::Lidar, &lidar, "lidar"),
    ] {
        let mut present = ids(offline);
        present.extend(ids(&latency));
        let entries: Vec<_> = CATALOGUE
            .iter()
            .filter(|e| e.modality == modality && present.iter().any(|p| p == e.id))
            .collect();
        if entries.is_empty() {
            continue;
        }
        let mut notes = Vec::new();
        if offline.is_none() {
            notes.push(format!("offline effect: missing ({HOW_METRICS})"));
        }
        if latency.is_none() {
            notes.push(format!("latency and feasibility: missing ({HOW_BENCH})"));
        }
        let rows = entries
            .iter()
            .map(|e| {
                let off = offline.as_ref();
                let lat = latency.as_ref();
                let mean_ms = column(lat, e.id, "mean_ms");
                let max_ms = column(lat, e.id, "max_ms");
                let overhead = column(lat, e.id, "node_overhead_ms");
                let budget = column(lat, e.id, "budget_ms")
                    .first()
                    .map_or_else(|| default_budget(e.id), |b| b.1);
                let avg_latency_ms = mean(&values(&mean_ms));
                let max_latency_ms = max(&values(&max_ms));
                let (mse, dev, ret, ate) = (
                    column(off, e.id, "mse"),
                    column(off, e.id, "max_abs_deviation"),
                    column(off, e.id, "retention"),
                    column(off, e.id, "ate"),
                );
                let trend: Vec<(u8, f64)> = if modality == Modality::Camera {
                    mse.clone()
                } else {
                    ret.iter().map(|(s, r)| (*s, 1.0 - r)).collect()
                };
                CombinedRow {
                    id: e.id.to_string(),
                    name: e.name.to_string(),
                    family: e.family.to_string(),
                    severities: trend.iter().map(|t| t.0).collect(),
                    avg_mse: mean(&values(&mse)),
                    max_mse: max(&values(&mse)),
                    max_abs_deviation: max(&values(&dev)),
                    avg_retention: mean(&values(&ret)),
                    min_retention: min(&values(&ret)),
                    max_ate: max(&values(&ate)),
                    trend,
                    avg_latency_ms,
                    max_latency_ms,
                    node_overhead_ms: mean(&values(&overhead)),
                    budget_ms: budget,
                    feasible: avg_latency_ms.map(|a| a <= budget),
                    max_within_budget: max_latency_ms.map(|m| m <= budget),
                }
            })
            .collect();
        out.push(Combined {
            modality: what.into(),
            rows,
            notes,
        });
    }
    Section::Present { content: out }
}

fn outcome_letters(row: &Value) -> Vec<String> {
    let fails: Vec<Value> = row
        .get("failures")
        .and_then(Value::as_array)
        .cloned()
        .unwrap_or_default();
    let outcomes: Vec<String> = row
        .get("outcomes")
        .and_then(Value::as_array)
        .map(|a| {
            a.iter()
                .map(|o| o.as_str().unwrap_or("").to_string())
                .collect()
        })
        .unwrap_or_default();
    fails
        .iter()
        .enumerate()
        .map(|(i, f)| match f.as_str() {
            Some(name) => failure_letter(name).to_string(),
            None if outcomes.get(i).is_some_and(|o| o == "unjudged") => "?".into(),
            None => "ok".into(),
        })
        .collect()
}

fn failure_letter(name: &str) -> &'static str {
    match name {
        "collision" => "C",
        "takeover" => "T",
        "understeer" => "U",
        "oversteer" => "O",
        "road_departure" => "R",
        "erratic_start" => "E",
        "timeout" => "X",
        "incomplete" => "I",
        _ => "?",
    }
}

fn completions(row: &Value) -> Vec<Option<f64>> {
    row.get("completions")
        .and_then(Value::as_array)
        .map(|a| a.iter().map(Value::as_f64).collect())
        .unwrap_or_default()
}

fn list(v: Option<&Value>) -> String {
    v.and_then(Value::as_array)
        .map(|a| {
            a.iter()
                .filter_map(|p| {
                    let p = p.as_array()?;
                    Some(format!("{} x{}", p.first()?.as_str()?, p.get(1)?.as_u64()?))
                })
                .collect::<Vec<_>>()
                .join("; ")
        })
        .unwrap_or_default()
}

fn closed_loop(inputs: &Inputs, study_dir: &Path) -> Section<Vec<ClosedLoop>> {
    let docs: Vec<_> = inputs.of(InputKind::Analysis).collect();
    if docs.is_empty() {
        return Section::missing(format!(
            "no closed-loop analysis (analysis.json of perturb analyze) in the study folder: {HOW_ANALYZE}"
        ));
    }
    let out = docs
        .iter()
        .map(|d| {
            let v = d.json.as_ref().expect("parsed");
            let rows = v
                .get("perturbations")
                .and_then(Value::as_array)
                .cloned()
                .unwrap_or_default()
                .iter()
                .map(|r| Rq3Row {
                    perturbation: text(r, "perturbation"),
                    name: text(r, "name"),
                    runs: r.get("runs").and_then(Value::as_u64).unwrap_or(0) as usize,
                    unjudged: r.get("unjudged").and_then(Value::as_u64).unwrap_or(0) as usize,
                    completions: completions(r),
                    outcomes: outcome_letters(r),
                    run_severities: r
                        .get("run_severities")
                        .and_then(Value::as_array)
                        .map(|a| a.iter().map(|s| s.as_u64().map(|s| s as u8)).collect())
                        .unwrap_or_default(),
                    failure_rate: f(r, "failure_rate"),
                    trajectory: Trajectory::of(r),
                    coverage_5m: f(r, "coverage_5m"),
                })
                .collect();
            let hot = v.get("hotspots");
            let mut hotspots: Vec<HotspotRow> = hot
                .and_then(|h| h.get("clusters"))
                .and_then(Value::as_array)
                .cloned()
                .unwrap_or_default()
                .iter()
                .enumerate()
                .map(|(i, c)| HotspotRow {
                    hotspot: format!("H{i}"),
                    failure: text(c, "failure"),
                    x: c["centre"][0].as_f64().unwrap_or(f64::NAN),
                    y: c["centre"][1].as_f64().unwrap_or(f64::NAN),
                    size: c.get("size").and_then(Value::as_u64).unwrap_or(0) as usize,
                    radius_m: f(c, "radius_m").unwrap_or(0.0),
                    perturbations: list(c.get("perturbations")),
                    families: list(c.get("families")),
                })
                .collect();
            for fp in hot
                .and_then(|h| h.get("failures"))
                .and_then(Value::as_array)
                .cloned()
                .unwrap_or_default()
                .iter()
                .filter(|fp| fp.get("cluster").is_none_or(Value::is_null))
            {
                let p = text(fp, "perturbation");
                hotspots.push(HotspotRow {
                    hotspot: "noise".into(),
                    failure: text(fp, "failure"),
                    x: fp["position"][0].as_f64().unwrap_or(f64::NAN),
                    y: fp["position"][1].as_f64().unwrap_or(f64::NAN),
                    size: 1,
                    radius_m: 0.0,
                    families: crate::hotspots::family_of(&p),
                    perturbations: p,
                });
            }
            let name = d
                .path
                .parent()
                .and_then(|p| p.strip_prefix(study_dir).ok())
                .map(|p| p.display().to_string())
                .filter(|s| !s.is_empty())
                .unwrap_or_else(|| {
                    d.path
                        .file_stem()
                        .map(|s| s.to_string_lossy().to_string())
                        .unwrap_or_default()
                });
            ClosedLoop {
                name,
                path: d.path.clone(),
                summary: v.get("summary").cloned(),
                rows,
                hotspots,
                map_svg: d.map_svg.clone(),
            }
        })
        .collect();
    Section::Present { content: out }
}

fn transfer_section(inputs: &Inputs, opts: &ReportOptions) -> Result<Section<TransferSection>> {
    if let Some(t) = inputs.of(InputKind::Transfer).next() {
        let v = t.json.clone().expect("parsed");
        let transfer: Transfer = serde_json::from_value(v).map_err(|e| StudyError::Table {
            path: t.path.clone(),
            line: None,
            reason: format!("not the JSON of perturb analyze transfer ({e})"),
        })?;
        return Ok(Section::Present {
            content: TransferSection {
                source: t.path.display().to_string(),
                infeasible: Vec::new(),
                transfer,
            },
        });
    }
    let mut offline = MetricTable::new();
    for k in [InputKind::Steering, InputKind::Lidar] {
        if let Some(t) = merged(inputs, k) {
            offline.extend(t);
        }
    }
    let analyses: Vec<_> = inputs.of(InputKind::Analysis).collect();
    if offline.is_empty() || analyses.is_empty() {
        let what = match (offline.is_empty(), analyses.is_empty()) {
            (true, true) => "neither model-level metrics nor a closed-loop analysis",
            (true, false) => "no model-level metrics",
            _ => "no closed-loop analysis",
        };
        return Ok(Section::missing(format!(
            "{what} in the study folder, and no perturb analyze transfer --format json output: the transfer needs both ({HOW_METRICS}; {HOW_ANALYZE})"
        )));
    }
    let mut closed = MetricTable::new();
    for a in &analyses {
        match read_table(&a.path) {
            Ok(t) => closed.extend(t),
            Err(e) => return Ok(Section::missing(format!("{e}"))),
        }
    }
    let infeasible = match merged(inputs, InputKind::Latency) {
        Some(lat) => keep_feasible(&mut offline, &lat)
            .into_iter()
            .map(|(id, s)| format!("{id} s{s}"))
            .collect(),
        None => Vec::new(),
    };
    match transfer(&offline, &closed, &opts.transfer) {
        Ok(t) => Ok(Section::Present {
            content: TransferSection {
                source: format!(
                    "computed by perturb report ({} resamples, seed {}, level {}){}",
                    opts.transfer.resamples,
                    opts.transfer.seed,
                    opts.transfer.level,
                    if infeasible.is_empty() {
                        String::new()
                    } else {
                        " over the pairs within their latency budget".into()
                    }
                ),
                infeasible,
                transfer: t,
            },
        }),
        Err(e) => Ok(Section::missing(e.to_string())),
    }
}

fn rq4(inputs: &Inputs) -> Section<Vec<Rq4Row>> {
    let Some(doc) = inputs.of(InputKind::Compare).next() else {
        return Section::missing(
            "no fine-tuned vs baseline comparison in the study folder: write `perturb analyze compare --set FT=ft_runs/ --set Non-FT=base_runs/ ... --format json > STUDY_DIR/rq4.json`",
        );
    };
    let rows = doc
        .json
        .as_ref()
        .and_then(Value::as_array)
        .cloned()
        .unwrap_or_default()
        .iter()
        .map(|r| Rq4Row {
            condition: text(r, "condition"),
            set: text(r, "set"),
            completions: completions(r),
            outcomes: outcome_letters(r),
            trajectory: Trajectory::of(r),
            shared_until_m: f(r, "shared_until_m"),
        })
        .collect();
    Section::Present { content: rows }
}

fn curves(inputs: &Inputs) -> Result<Section<Vec<(String, String)>>> {
    let mut out = Vec::new();
    for (kind, metrics) in [
        (InputKind::Steering, ["mse", "max_abs_deviation"]),
        (InputKind::Lidar, ["retention", "ate"]),
    ] {
        let Some(t) = merged(inputs, kind) else {
            continue;
        };
        for metric in metrics {
            let mut panels: BTreeMap<(usize, String), Vec<Curve>> = BTreeMap::new();
            for e in CATALOGUE {
                let points = column(Some(&t), e.id, metric);
                if points.is_empty() {
                    continue;
                }
                let fam_pos = CATALOGUE
                    .iter()
                    .position(|x| x.family == e.family && x.modality == e.modality)
                    .unwrap_or(0);
                panels
                    .entry((fam_pos, format!("{} {}", e.modality, e.family)))
                    .or_default()
                    .push(Curve {
                        id: e.id.to_string(),
                        points,
                    });
            }
            if panels.is_empty() {
                continue;
            }
            let panels: Vec<(String, Vec<Curve>)> =
                panels.into_iter().map(|((_, n), c)| (n, c)).collect();
            out.push((
                metric.to_string(),
                charts::severity_curves(metric, &panels)?,
            ));
        }
    }
    Ok(if out.is_empty() {
        Section::missing(format!(
            "no model-level metrics in the study folder: {HOW_METRICS}"
        ))
    } else {
        Section::Present { content: out }
    })
}

fn latency(combined: &Section<Vec<Combined>>) -> Result<Section<Vec<(String, String)>>> {
    let mut out = Vec::new();
    for c in combined.content().into_iter().flatten() {
        let bars: Vec<LatencyBar> = c
            .rows
            .iter()
            .filter_map(|r| {
                Some(LatencyBar {
                    id: r.id.clone(),
                    avg_ms: r.avg_latency_ms?,
                    max_ms: r.max_latency_ms?,
                })
            })
            .collect();
        if bars.is_empty() {
            continue;
        }
        let budget = c.rows[0].budget_ms;
        out.push((
            c.modality.clone(),
            charts::latency_bars(
                &format!(
                    "{} latency per frame against the {budget} ms budget",
                    c.modality
                ),
                &bars,
                budget,
            )?,
        ));
    }
    Ok(if out.is_empty() {
        Section::missing(format!("no latency table in the study folder: {HOW_BENCH}"))
    } else {
        Section::Present { content: out }
    })
}

/// Reads the study folder and builds every section (the files in `skip` are the report's own
/// outputs and are not read).
pub fn build(study_dir: &Path, opts: &ReportOptions, skip: &[PathBuf]) -> Result<Report> {
    let inputs = find_inputs(study_dir, skip)?;
    let combined = combined(&inputs);
    let closed_loop = closed_loop(&inputs, study_dir);
    let transfer = transfer_section(&inputs, opts)?;
    let rq4 = rq4(&inputs);
    let curves = curves(&inputs)?;
    let latency = latency(&combined)?;
    Ok(Report {
        title: opts.title.clone(),
        study_dir: study_dir.to_path_buf(),
        inputs,
        combined,
        closed_loop,
        transfer,
        rq4,
        curves,
        latency,
    })
}

/// The scatter plot of one transfer row.
pub(crate) fn scatter(t: &Transfer, k: usize) -> Result<Option<String>> {
    let r = &t.rows[k];
    if r.points.len() < 2 {
        return Ok(None);
    }
    let key = |p: &crate::transfer::TransferPoint| format!("{} s{}", p.perturbation, p.severity);
    let points: Vec<ScatterPoint> = r
        .points
        .iter()
        .map(|p| ScatterPoint {
            x: p.offline,
            y: p.closed_loop,
            top_offline: r.top_offline.contains(&key(p)),
            top_closed_loop: r.top_closed_loop.contains(&key(p)),
        })
        .collect();
    let title = format!(
        "rho {}{}",
        num(r.rho, 2),
        match (r.ci_low, r.ci_high) {
            (Some(a), Some(b)) => format!(" [{a:.2}, {b:.2}]"),
            _ => String::new(),
        }
    );
    Ok(Some(charts::transfer_scatter(
        &title,
        &r.offline,
        &r.closed_loop,
        &points,
    )?))
}

/// The report's tables as (file suffix, table), for CSV beside the page.
pub fn tables(r: &Report) -> Vec<(String, Table)> {
    let mut out = Vec::new();
    let o = |v: Option<f64>| raw(v);
    let b = |v: Option<bool>| v.map_or(String::new(), |b| b.to_string());
    for c in r.combined.content().into_iter().flatten() {
        let mut t = Table::new(&[
            ("id", false),
            ("name", false),
            ("family", false),
            ("severities", false),
            ("avg_mse", true),
            ("max_mse", true),
            ("max_abs_deviation", true),
            ("avg_retention", true),
            ("min_retention", true),
            ("max_ate", true),
            ("avg_latency_ms", true),
            ("max_latency_ms", true),
            ("node_overhead_ms", true),
            ("budget_ms", true),
            ("feasible", false),
            ("max_within_budget", false),
        ]);
        for x in &c.rows {
            t.push(vec![
                x.id.clone(),
                x.name.clone(),
                x.family.clone(),
                x.severities
                    .iter()
                    .map(|s| s.to_string())
                    .collect::<Vec<_>>()
                    .join(";"),
                o(x.avg_mse),
                o(x.max_mse),
                o(x.max_abs_deviation),
                o(x.avg_retention),
                o(x.min_retention),
                o(x.max_ate),
                o(x.avg_latency_ms),
                o(x.max_latency_ms),
                o(x.node_overhead_ms),
                x.budget_ms.to_string(),
                b(x.feasible),
                b(x.max_within_budget),
            ]);
        }
        out.push((format!("combined_{}", c.modality), t));
    }
    for (k, cl) in r.closed_loop.content().into_iter().flatten().enumerate() {
        let mut t = Table::new(&[
            ("perturbation", false),
            ("name", false),
            ("runs", true),
            ("unjudged", true),
            ("completion", false),
            ("failures", false),
            ("failure_rate", true),
            ("cte_avg", true),
            ("cte_max", true),
            ("jitter_avg", true),
            ("jitter_max", true),
            ("jitter_std", true),
            ("coverage_5m", true),
        ]);
        for x in &cl.rows {
            let mut row = vec![
                x.perturbation.clone(),
                x.name.clone(),
                x.runs.to_string(),
                x.unjudged.to_string(),
                x.completions
                    .iter()
                    .map(|c| raw(*c))
                    .collect::<Vec<_>>()
                    .join(";"),
                x.outcomes.join(";"),
                o(x.failure_rate),
            ];
            row.extend(x.trajectory.cells());
            row.push(o(x.coverage_5m));
            t.push(row);
        }
        out.push((format!("rq3_{k}"), t));
        let mut h = Table::new(&[
            ("hotspot", false),
            ("failure", false),
            ("x", true),
            ("y", true),
            ("size", true),
            ("radius_m", true),
            ("perturbations", false),
            ("families", false),
        ]);
        for x in &cl.hotspots {
            h.push(vec![
                x.hotspot.clone(),
                x.failure.clone(),
                x.x.to_string(),
                x.y.to_string(),
                x.size.to_string(),
                x.radius_m.to_string(),
                x.perturbations.clone(),
                x.families.clone(),
            ]);
        }
        out.push((format!("hotspots_{k}"), h));
    }
    if let Some(ts) = r.transfer.content() {
        let mut t = Table::new(&[
            ("offline", false),
            ("closed_loop", false),
            ("n", true),
            ("rho", true),
            ("ci_low", true),
            ("ci_high", true),
            ("p", true),
            ("q", true),
            ("top_k_overlap", true),
            ("top_offline", false),
            ("top_closed_loop", false),
            ("note", false),
        ]);
        for x in &ts.transfer.rows {
            t.push(vec![
                x.offline.clone(),
                x.closed_loop.clone(),
                x.n.to_string(),
                o(x.rho),
                o(x.ci_low),
                o(x.ci_high),
                o(x.p),
                o(x.q),
                o(x.top_k_overlap),
                x.top_offline.join(";"),
                x.top_closed_loop.join(";"),
                x.note.clone().unwrap_or_default(),
            ]);
        }
        out.push(("transfer".into(), t));
    }
    if let Some(rows) = r.rq4.content() {
        let mut t = Table::new(&[
            ("condition", false),
            ("set", false),
            ("completion", false),
            ("failures", false),
            ("cte_avg", true),
            ("cte_max", true),
            ("jitter_avg", true),
            ("jitter_max", true),
            ("jitter_std", true),
            ("shared_until_m", true),
        ]);
        for x in rows {
            let mut row = vec![
                x.condition.clone(),
                x.set.clone(),
                x.completions
                    .iter()
                    .map(|c| raw(*c))
                    .collect::<Vec<_>>()
                    .join(";"),
                x.outcomes.join(";"),
            ];
            row.extend(x.trajectory.cells());
            row.push(o(x.shared_until_m));
            t.push(row);
        }
        out.push(("rq4".into(), t));
    }
    out
}

/// What [`write_report`] wrote.
#[derive(Clone, Debug, Serialize)]
pub struct Written {
    /// The HTML page.
    pub html: PathBuf,
    /// The JSON of every table.
    pub json: PathBuf,
    /// The CSV tables.
    pub csv: Vec<PathBuf>,
    /// Sections present.
    pub present: Vec<String>,
    /// Sections missing, with the reason.
    pub missing: Vec<(String, String)>,
    /// Input files used.
    pub used: Vec<PathBuf>,
}

impl Report {
    /// (section name, missing reason) of every section.
    pub fn sections(&self) -> Vec<(&'static str, Option<&str>)> {
        fn why<T>(s: &Section<T>) -> Option<&str> {
            match s {
                Section::Present { .. } => None,
                Section::Missing { reason } => Some(reason),
            }
        }
        vec![
            ("combined", why(&self.combined)),
            ("rq3", why(&self.closed_loop)),
            ("transfer", why(&self.transfer)),
            ("hotspots", why(&self.closed_loop)),
            ("curves", why(&self.curves)),
            ("latency", why(&self.latency)),
            ("rq4", why(&self.rq4)),
        ]
    }
}

/// Builds the report of `study_dir` and writes it to `html` (a self-contained page: inline
/// CSS and SVG, no script, nothing fetched at view time), with `<stem>.json` (every table) and
/// `<stem>-<table>.csv` beside it.
pub fn write_report(study_dir: &Path, html: &Path, opts: &ReportOptions) -> Result<Written> {
    let stem = html
        .file_stem()
        .map(|s| s.to_string_lossy().to_string())
        .unwrap_or_else(|| "report".into());
    let dir = html.parent().map(Path::to_path_buf).unwrap_or_default();
    let dir = if dir.as_os_str().is_empty() {
        PathBuf::from(".")
    } else {
        dir
    };
    let json_path = dir.join(format!("{stem}.json"));
    // The report's own outputs from an earlier run are not inputs.
    let mut skip = vec![json_path.clone()];
    if let Ok(rd) = std::fs::read_dir(&dir) {
        for e in rd.flatten() {
            let n = e.file_name().to_string_lossy().to_string();
            if n.starts_with(&format!("{stem}-")) && n.ends_with(".csv") {
                skip.push(e.path());
            }
        }
    }
    let report = build(study_dir, opts, &skip)?;
    std::fs::create_dir_all(&dir).map_err(StudyError::io(&dir))?;
    let page = html::render(&report)?;
    std::fs::write(html, page).map_err(StudyError::io(html))?;
    let json = serde_json::to_string_pretty(&report).expect("the report serialises") + "\n";
    std::fs::write(&json_path, json).map_err(StudyError::io(&json_path))?;
    let mut csv = Vec::new();
    for (name, t) in tables(&report) {
        let p = dir.join(format!("{stem}-{name}.csv"));
        std::fs::write(&p, t.render(crate::Format::Csv)).map_err(StudyError::io(&p))?;
        csv.push(p);
    }
    let sections = report.sections();
    Ok(Written {
        html: html.to_path_buf(),
        json: json_path,
        csv,
        present: sections
            .iter()
            .filter(|s| s.1.is_none())
            .map(|s| s.0.to_string())
            .collect(),
        missing: sections
            .iter()
            .filter_map(|s| Some((s.0.to_string(), s.1?.to_string())))
            .collect(),
        used: report.inputs.used.iter().map(|i| i.path.clone()).collect(),
    })
}
