//! Transfer analysis (paper, qualitative analysis): do model-level (offline) effects predict
//! closed-loop outcomes? For matched (perturbation, severity) pairs present in both tables:
//! Spearman's rho between each offline metric and each closed-loop metric, its two-sided
//! p-value, a percentile bootstrap 95% confidence interval (seeded, so reproducible),
//! Benjamini-Hochberg q-values across all the tested metric pairs, and the overlap of the top-k
//! (perturbation, severity) pairs of both rankings.
//!
//! Tables are read from what the project writes: the JSON of `perturb metrics steering|lidar
//! --format json` (`per_severity`) and of `perturb analyze --json` (`conditions`), or any CSV
//! with an `id` (or `perturbation`) column, a `severity` column and numeric columns. A
//! `retention` column also gives `retention_loss` (1 - retention), the paper's offline LiDAR
//! measure. For the top-k rankings, larger is worse, except for `retention`, `completion` and
//! `coverage_5m`, where smaller is worse.

use crate::error::{Result, StudyError};
use crate::stats;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::path::Path;

/// (perturbation ID, severity) -> metric name -> value.
pub type MetricTable = BTreeMap<(String, u8), BTreeMap<String, f64>>;

/// Columns that are identifiers or counts, not metrics.
const NOT_METRICS: [&str; 10] = [
    "severity",
    "frames",
    "runs",
    "baseline",
    "retained",
    "translation_sum",
    "duration_s",
    "seed",
    "setup_ms",
    "severities",
];

/// Metrics where a smaller value is worse (for the top-k rankings).
const SMALLER_IS_WORSE: [&str; 3] = ["retention", "completion", "coverage_5m"];

/// Fewer matched pairs than this give no confidence interval (the bootstrap over 2-4 pairs has
/// a handful of distinct resamples, most with a constant side) and a note on the sample size.
pub const MIN_PAIRS_FOR_CI: usize = 5;

/// The default offline metrics, when present.
pub const DEFAULT_OFFLINE: [&str; 4] = ["mse", "max_abs_deviation", "retention_loss", "ate"];
/// The default closed-loop metrics, when present.
pub const DEFAULT_CLOSED_LOOP: [&str; 5] = [
    "failure_rate",
    "cte_avg",
    "jitter_avg",
    "coverage_5m",
    "completion",
];

fn derive(table: &mut MetricTable) {
    for m in table.values_mut() {
        if let (Some(r), false) = (
            m.get("retention").copied(),
            m.contains_key("retention_loss"),
        ) {
            m.insert("retention_loss".into(), 1.0 - r);
        }
    }
}

fn table_err(path: &Path, line: Option<usize>, reason: impl Into<String>) -> StudyError {
    StudyError::Table {
        path: path.to_path_buf(),
        line,
        reason: reason.into(),
    }
}

/// Reads a table of per-(perturbation, severity) metrics (JSON or CSV, see the module doc).
/// Rows without a perturbation ID and severity (nominal rows) are left out.
pub fn read_table(path: &Path) -> Result<MetricTable> {
    let text = std::fs::read_to_string(path).map_err(StudyError::io(path))?;
    let mut t = if text.trim_start().starts_with(['{', '[']) {
        read_json(path, &text)?
    } else {
        read_csv(path, &text)?
    };
    derive(&mut t);
    if t.is_empty() {
        return Err(table_err(
            path,
            None,
            "holds no row with a perturbation ID and a severity",
        ));
    }
    Ok(t)
}

fn read_json(path: &Path, text: &str) -> Result<MetricTable> {
    let v: serde_json::Value =
        serde_json::from_str(text).map_err(|e| table_err(path, None, format!("not JSON: {e}")))?;
    let rows = match &v {
        serde_json::Value::Array(a) => a,
        serde_json::Value::Object(o) => ["per_severity", "conditions"]
            .iter()
            .find_map(|k| o.get(*k).and_then(|x| x.as_array()))
            .ok_or_else(|| {
                table_err(
                    path,
                    None,
                    "no `per_severity` or `conditions` array (give the JSON of `perturb metrics ... --format json` or `perturb analyze --json`)",
                )
            })?,
        _ => return Err(table_err(path, None, "expected a JSON object or array")),
    };
    let mut t = MetricTable::new();
    for row in rows {
        let Some(o) = row.as_object() else { continue };
        let id = o
            .get("id")
            .or_else(|| o.get("perturbation"))
            .and_then(|x| x.as_str());
        let sev = o.get("severity").and_then(|x| x.as_u64());
        let (Some(id), Some(sev)) = (id, sev) else {
            continue;
        };
        let metrics = o
            .iter()
            .filter(|(k, _)| !NOT_METRICS.contains(&k.as_str()))
            .filter_map(|(k, v)| Some((k.clone(), v.as_f64()?)))
            .collect();
        t.insert((id.to_string(), sev as u8), metrics);
    }
    Ok(t)
}

fn read_csv(path: &Path, text: &str) -> Result<MetricTable> {
    let mut lines = text
        .lines()
        .enumerate()
        .filter(|(_, l)| !l.trim().is_empty() && !l.starts_with('#'));
    let Some((_, header)) = lines.next() else {
        return Err(table_err(path, None, "is empty"));
    };
    let cols: Vec<&str> = header.split(',').map(str::trim).collect();
    let find = |names: &[&str]| cols.iter().position(|c| names.contains(c));
    let id_col = find(&["id", "perturbation"])
        .ok_or_else(|| table_err(path, Some(1), "no `id` or `perturbation` column"))?;
    let sev_col =
        find(&["severity"]).ok_or_else(|| table_err(path, Some(1), "no `severity` column"))?;
    let mut t = MetricTable::new();
    for (n, line) in lines {
        let cells: Vec<&str> = line.split(',').map(str::trim).collect();
        if cells.len() != cols.len() {
            return Err(table_err(
                path,
                Some(n + 1),
                format!("{} cells, the header has {}", cells.len(), cols.len()),
            ));
        }
        let Ok(sev) = cells[sev_col].parse::<u8>() else {
            continue; // nominal or aggregate rows
        };
        let mut m = BTreeMap::new();
        for (c, name) in cols.iter().enumerate() {
            if c == id_col || c == sev_col || NOT_METRICS.contains(name) {
                continue;
            }
            if let Ok(v) = cells[c].parse::<f64>() {
                m.insert(name.to_string(), v);
            }
        }
        t.insert((cells[id_col].to_string(), sev), m);
    }
    Ok(t)
}

/// Leaves out of `offline` the (perturbation, severity) pairs whose measured latency
/// (`mean_ms` of a `perturb bench` table) exceeds their budget (`budget_ms`, or 33 ms for camera
/// and 200 ms for LiDAR perturbations): the paper matches only pairs that satisfy the latency
/// constraints. Pairs without a latency are kept. Returns the pairs left out.
pub fn keep_feasible(offline: &mut MetricTable, latency: &MetricTable) -> Vec<(String, u8)> {
    let mut out = Vec::new();
    offline.retain(|k, _| {
        let Some(m) = latency.get(k) else {
            return true;
        };
        let budget = m
            .get("budget_ms")
            .copied()
            .unwrap_or_else(|| default_budget(&k.0));
        let ok = m.get("mean_ms").is_none_or(|v| *v <= budget);
        if !ok {
            out.push(k.clone());
        }
        ok
    });
    out
}

/// The real-time budget of a perturbation: 33 ms per camera frame, 200 ms per LiDAR cloud.
pub fn default_budget(id: &str) -> f64 {
    match perturb_core::registry::find(id).map(|e| e.modality) {
        Ok(perturb_core::registry::Modality::Lidar) => 200.0,
        _ => 33.0,
    }
}

/// How the transfer analysis runs.
#[derive(Clone, Debug)]
pub struct TransferConfig {
    /// Offline metrics to test (empty: those of [`DEFAULT_OFFLINE`] present in the table).
    pub offline_metrics: Vec<String>,
    /// Closed-loop metrics to test (empty: those of [`DEFAULT_CLOSED_LOOP`] present).
    pub closed_loop_metrics: Vec<String>,
    /// Bootstrap resamples.
    pub resamples: usize,
    /// Seed of the bootstrap.
    pub seed: u64,
    /// Confidence level of the interval.
    pub level: f64,
    /// k of the top-k overlap.
    pub top_k: usize,
}

impl Default for TransferConfig {
    fn default() -> Self {
        TransferConfig {
            offline_metrics: Vec::new(),
            closed_loop_metrics: Vec::new(),
            resamples: 10_000,
            seed: 0,
            level: 0.95,
            top_k: 5,
        }
    }
}

/// One tested (offline metric, closed-loop metric) pair.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TransferRow {
    /// The offline metric.
    pub offline: String,
    /// The closed-loop metric.
    pub closed_loop: String,
    /// Matched (perturbation, severity) pairs with both values.
    pub n: usize,
    /// Spearman's rho (None when a side is constant).
    pub rho: Option<f64>,
    /// Lower bound of the bootstrap confidence interval.
    pub ci_low: Option<f64>,
    /// Upper bound.
    pub ci_high: Option<f64>,
    /// Bootstrap resamples with a defined rho.
    pub resamples_used: usize,
    /// Two-sided p-value.
    pub p: Option<f64>,
    /// Benjamini-Hochberg q-value across the tested pairs.
    pub q: Option<f64>,
    /// Share of the top-k pairs the two rankings have in common.
    pub top_k_overlap: Option<f64>,
    /// The offline ranking's top k, `ID s<severity>`.
    pub top_offline: Vec<String>,
    /// The closed-loop ranking's top k.
    pub top_closed_loop: Vec<String>,
    /// The matched pairs (for scatter plots).
    #[serde(default)]
    pub points: Vec<TransferPoint>,
    /// What a reader must know about this row (too few pairs, a constant side).
    #[serde(default)]
    pub note: Option<String>,
}

/// One matched (perturbation, severity) pair of a row.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TransferPoint {
    /// Perturbation ID.
    pub perturbation: String,
    /// Severity.
    pub severity: u8,
    /// The offline metric's value.
    pub offline: f64,
    /// The closed-loop metric's value.
    pub closed_loop: f64,
}

/// The whole analysis.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Transfer {
    /// (perturbation, severity) pairs present in both tables.
    pub matched: usize,
    /// k of the top-k overlap.
    pub top_k: usize,
    /// Resamples drawn per pair.
    pub resamples: usize,
    /// Seed.
    pub seed: u64,
    /// Confidence level.
    pub level: f64,
    /// One row per metric pair.
    pub rows: Vec<TransferRow>,
}

fn columns(t: &MetricTable) -> Vec<String> {
    let mut v: Vec<String> = t.values().flat_map(|m| m.keys().cloned()).collect();
    v.sort();
    v.dedup();
    v
}

/// Runs the analysis over two tables.
pub fn transfer(
    offline: &MetricTable,
    closed_loop: &MetricTable,
    cfg: &TransferConfig,
) -> Result<Transfer> {
    let keys: Vec<&(String, u8)> = offline
        .keys()
        .filter(|k| closed_loop.contains_key(*k))
        .collect();
    if keys.is_empty() {
        return Err(StudyError::Config(
            "the offline and the closed-loop tables have no (perturbation, severity) pair in common"
                .into(),
        ));
    }
    let off = pick_metrics(&cfg.offline_metrics, &DEFAULT_OFFLINE, offline, "offline")?;
    let cl = pick_metrics(
        &cfg.closed_loop_metrics,
        &DEFAULT_CLOSED_LOOP,
        closed_loop,
        "closed-loop",
    )?;
    let mut rows = Vec::new();
    for o in &off {
        for c in &cl {
            rows.push(transfer_row(&keys, offline, closed_loop, (o, c), cfg));
        }
    }
    let ps: Vec<f64> = rows.iter().map(|r| r.p.unwrap_or(f64::NAN)).collect();
    let qs = stats::benjamini_hochberg(&ps);
    for (r, q) in rows.iter_mut().zip(qs) {
        r.q = q.is_finite().then_some(q);
    }
    Ok(Transfer {
        matched: keys.len(),
        top_k: cfg.top_k,
        resamples: cfg.resamples,
        seed: cfg.seed,
        level: cfg.level,
        rows,
    })
}

/// The metrics of `t` to correlate: those `asked` (each must be a column), or the `defaults` the
/// table has.
fn pick_metrics(
    asked: &[String],
    defaults: &[&str],
    t: &MetricTable,
    which: &str,
) -> Result<Vec<String>> {
    let have = columns(t);
    if asked.is_empty() {
        let v: Vec<String> = defaults
            .iter()
            .filter(|d| have.iter().any(|h| h == *d))
            .map(|d| d.to_string())
            .collect();
        if v.is_empty() {
            return Err(StudyError::Config(format!(
                "the {which} table has none of the default metrics ({}); its columns: {}; choose with --{which}-metric",
                defaults.join(", "),
                have.join(", ")
            )));
        }
        return Ok(v);
    }
    for a in asked {
        if !have.contains(a) {
            return Err(StudyError::Config(format!(
                "the {which} table has no metric `{a}` (its columns: {})",
                have.join(", ")
            )));
        }
    }
    Ok(asked.to_vec())
}

/// The correlation of offline metric `o` with closed-loop metric `c` over the matched `keys`
/// where both are finite (q filled in later, over every row).
fn transfer_row(
    keys: &[&(String, u8)],
    offline: &MetricTable,
    closed_loop: &MetricTable,
    (o, c): (&str, &str),
    cfg: &TransferConfig,
) -> TransferRow {
    let pairs: Vec<(&(String, u8), f64, f64)> = keys
        .iter()
        .filter_map(|k| {
            let x = *offline[*k].get(o)?;
            let y = *closed_loop[*k].get(c)?;
            (x.is_finite() && y.is_finite()).then_some((*k, x, y))
        })
        .collect();
    let x: Vec<f64> = pairs.iter().map(|p| p.1).collect();
    let y: Vec<f64> = pairs.iter().map(|p| p.2).collect();
    let rho = stats::spearman(&x, &y);
    let p = rho.and_then(|r| stats::spearman_p(r, x.len()));
    let few = x.len() < MIN_PAIRS_FOR_CI;
    let ci = rho
        .filter(|_| !few)
        .and_then(|_| stats::bootstrap_spearman_ci(&x, &y, cfg.resamples, cfg.seed, cfg.level));
    let note = if few {
        Some(format!(
            "only {} matched pair{}: fewer than {MIN_PAIRS_FOR_CI}, no confidence interval; rho {}",
            x.len(),
            if x.len() == 1 { "" } else { "s" },
            match x.len() {
                0 | 1 => "is undefined",
                2 => "of 2 pairs is always +1 or -1 and p is undefined",
                _ => "and p rest on very few pairs",
            }
        ))
    } else if rho.is_none() {
        Some("one side is constant over the pairs: rho is undefined".into())
    } else {
        None
    };
    let worse = |name: &str, v: &[f64]| -> Vec<f64> {
        if SMALLER_IS_WORSE.contains(&name) {
            v.iter().map(|x| -x).collect()
        } else {
            v.to_vec()
        }
    };
    let (wx, wy) = (worse(o, &x), worse(c, &y));
    let top = |v: &[f64]| -> Vec<String> {
        let mut idx: Vec<usize> = (0..v.len()).collect();
        idx.sort_by(|&i, &j| v[j].total_cmp(&v[i]).then(i.cmp(&j)));
        idx.iter()
            .take(cfg.top_k)
            .map(|&i| format!("{} s{}", pairs[i].0.0, pairs[i].0.1))
            .collect()
    };
    TransferRow {
        offline: o.to_string(),
        closed_loop: c.to_string(),
        n: x.len(),
        rho,
        ci_low: ci.map(|c| c.0),
        ci_high: ci.map(|c| c.1),
        resamples_used: ci.map_or(0, |c| c.2),
        p,
        q: None,
        top_k_overlap: stats::top_k_overlap(&wx, &wy, cfg.top_k),
        top_offline: top(&wx),
        top_closed_loop: top(&wy),
        points: pairs
            .iter()
            .map(|(k, x, y)| TransferPoint {
                perturbation: k.0.clone(),
                severity: k.1,
                offline: *x,
                closed_loop: *y,
            })
            .collect(),
        note,
    }
}

/// The analysis as a table.
pub fn render(t: &Transfer, format: crate::Format) -> String {
    use crate::table::{Table, num, raw};
    if format == crate::Format::Json {
        return serde_json::to_string_pretty(t).expect("serialises") + "\n";
    }
    let csv = format == crate::Format::Csv;
    let f = |v: Option<f64>, d: usize| if csv { raw(v) } else { num(v, d) };
    let pct = (t.level * 100.0).round();
    let ci_lo = format!("ci{pct}_low");
    let ci_hi = format!("ci{pct}_high");
    let top = format!("top{}_overlap", t.top_k);
    let mut table = Table::new(&[
        ("offline", false),
        ("closed_loop", false),
        ("n", true),
        ("rho", true),
        (&ci_lo, true),
        (&ci_hi, true),
        ("p", true),
        ("q", true),
        (&top, true),
    ]);
    let p = |v: Option<f64>| match v {
        Some(x) if !csv && x < 1e-4 => "<1e-4".to_string(),
        other => f(other, 4),
    };
    for r in &t.rows {
        table.push(vec![
            r.offline.clone(),
            r.closed_loop.clone(),
            r.n.to_string(),
            f(r.rho, 2),
            f(r.ci_low, 2),
            f(r.ci_high, 2),
            p(r.p),
            p(r.q),
            f(r.top_k_overlap, 2),
        ]);
    }
    let mut out = table.render(format);
    if !csv {
        for r in t.rows.iter().filter(|r| r.note.is_some()) {
            let line = format!(
                "note: {} vs {}: {}",
                r.offline,
                r.closed_loop,
                r.note.as_deref().unwrap_or_default()
            );
            out.push_str(&if format == crate::Format::Markdown {
                format!("\n> {line}\n")
            } else {
                format!("{line}\n")
            });
        }
    }
    out
}
