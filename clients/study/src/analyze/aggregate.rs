//! Rows per (perturbation, severity) and per perturbation, as the paper's tables aggregate runs.

use super::{Aggregate, Failure, Metrics, Outcome, SegmentResult};
use serde::Serialize;
use std::collections::BTreeMap;

/// Metrics aggregated over several runs (segments).
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct Aggregated {
    /// Runs (segments) aggregated.
    pub runs: usize,
    /// Of these, the ones whose failure could not be judged (never counted as ok).
    pub unjudged: usize,
    /// Mean completion.
    pub completion: Option<f64>,
    /// Completion of each run, in row order (the paper's bars).
    pub completions: Vec<Option<f64>>,
    /// The most frequent failure type among the failing runs (None: no run failed).
    pub failure: Option<Failure>,
    /// Failure type of each run (None: it did not fail or was not judged), in row order.
    pub failures: Vec<Option<Failure>>,
    /// Outcome of each run (ok, failed, unjudged), in row order.
    pub outcomes: Vec<Outcome>,
    /// Failing runs / judged runs (None when no run was judged).
    pub failure_rate: Option<f64>,
    /// Mean of the runs' average CTE.
    pub cte_avg: Option<f64>,
    /// Largest of the runs' maximum CTE.
    pub cte_max: Option<f64>,
    /// Mean of the runs' average jitter.
    pub jitter_avg: Option<f64>,
    /// Largest of the runs' maximum jitter.
    pub jitter_max: Option<f64>,
    /// Mean of the runs' jitter standard deviations.
    pub jitter_std: Option<f64>,
    /// Mean of the runs' coverage.
    pub coverage_5m: Option<f64>,
    /// Total seconds.
    pub duration_s: f64,
}

fn mean(v: impl Iterator<Item = Option<f64>>) -> Option<f64> {
    let v: Vec<f64> = v.flatten().collect();
    (!v.is_empty()).then(|| v.iter().sum::<f64>() / v.len() as f64)
}

fn max(v: impl Iterator<Item = Option<f64>>) -> Option<f64> {
    v.flatten().reduce(f64::max)
}

/// Aggregates segments: completion and failures over all of them (the failure rate over the
/// judged ones), trajectory metrics over the ones judged ok (or all, with [`Aggregate::All`] and
/// [`Aggregate::Shared`], whose parts the caller chose); coverage over all of them.
pub fn aggregate(rows: &[&Metrics], policy: Aggregate) -> Aggregated {
    let traj: Vec<&&Metrics> = rows
        .iter()
        .filter(|r| policy != Aggregate::NonFailing || r.outcome == Outcome::Ok)
        .collect();
    let mut counts: BTreeMap<Failure, usize> = BTreeMap::new();
    for f in rows.iter().filter_map(|r| r.failure) {
        *counts.entry(f).or_default() += 1;
    }
    let dominant = counts
        .iter()
        .max_by(|a, b| a.1.cmp(b.1).then(b.0.cmp(a.0)))
        .map(|(f, _)| *f);
    let n = rows.len();
    let unjudged = rows
        .iter()
        .filter(|r| r.outcome == Outcome::Unjudged)
        .count();
    let judged = n - unjudged;
    Aggregated {
        runs: n,
        unjudged,
        completion: mean(rows.iter().map(|r| r.completion)),
        completions: rows.iter().map(|r| r.completion).collect(),
        failure: dominant,
        failures: rows.iter().map(|r| r.failure).collect(),
        outcomes: rows.iter().map(|r| r.outcome).collect(),
        failure_rate: (judged > 0).then(|| counts.values().sum::<usize>() as f64 / judged as f64),
        cte_avg: mean(traj.iter().map(|r| r.cte_avg)),
        cte_max: max(traj.iter().map(|r| r.cte_max)),
        jitter_avg: mean(traj.iter().map(|r| r.jitter_avg)),
        jitter_max: max(traj.iter().map(|r| r.jitter_max)),
        jitter_std: mean(traj.iter().map(|r| r.jitter_std)),
        coverage_5m: mean(rows.iter().map(|r| r.coverage_5m)),
        duration_s: rows.iter().map(|r| r.duration_s).sum(),
    }
}

/// One (perturbation, severity).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct ConditionRow {
    /// `nominal`, the perturbation ID, or IDs joined with `+`.
    pub perturbation: String,
    /// Severity (None for nominal, or perturbations at different severities).
    pub severity: Option<u8>,
    /// The runs (segments) in row order.
    pub run_names: Vec<String>,
    /// The aggregated metrics.
    #[serde(flatten)]
    pub metrics: Aggregated,
}

/// One perturbation over its severities (the paper's table; nominal first).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct PerturbationRow {
    /// `nominal`, the perturbation ID, or IDs joined with `+`.
    pub perturbation: String,
    /// The catalogue name (empty for nominal and combinations).
    pub name: String,
    /// The catalogue family (empty for nominal and combinations).
    pub family: String,
    /// The severities tested, highest first (the order of the runs).
    pub severities: Vec<u8>,
    /// Severity of each run, in row order.
    pub run_severities: Vec<Option<u8>>,
    /// The runs (segments) in row order: by severity, highest first, then by name.
    pub run_names: Vec<String>,
    /// The aggregated metrics.
    #[serde(flatten)]
    pub metrics: Aggregated,
}

/// Sort key of a condition label: nominal, then catalogue order, then combinations.
pub(crate) fn order(label: &str) -> (usize, String) {
    if label == "nominal" {
        return (0, String::new());
    }
    match perturb_core::registry::CATALOGUE
        .iter()
        .position(|e| e.id == label)
    {
        Some(p) => (1 + p, String::new()),
        None => (usize::MAX, label.to_string()),
    }
}

/// One row per (perturbation, severity), nominal first.
pub fn aggregate_conditions(segments: &[SegmentResult], policy: Aggregate) -> Vec<ConditionRow> {
    type Key = ((usize, String), Option<u8>);
    let mut groups: BTreeMap<Key, Vec<&SegmentResult>> = BTreeMap::new();
    for s in segments {
        groups
            .entry((order(&s.perturbation), s.severity))
            .or_default()
            .push(s);
    }
    groups
        .into_values()
        .map(|rows| ConditionRow {
            perturbation: rows[0].perturbation.clone(),
            severity: rows[0].severity,
            run_names: rows.iter().map(|r| r.run.clone()).collect(),
            metrics: aggregate(&rows.iter().map(|r| &r.metrics).collect::<Vec<_>>(), policy),
        })
        .collect()
}

/// One row per perturbation (every severity), nominal first; runs ordered by severity, highest
/// first (the order the paper tests them in), then by name.
pub fn aggregate_perturbations(
    segments: &[SegmentResult],
    policy: Aggregate,
) -> Vec<PerturbationRow> {
    let mut groups: BTreeMap<(usize, String), Vec<&SegmentResult>> = BTreeMap::new();
    for s in segments {
        groups.entry(order(&s.perturbation)).or_default().push(s);
    }
    groups
        .into_values()
        .map(|mut rows| {
            rows.sort_by(|a, b| b.severity.cmp(&a.severity).then(a.run.cmp(&b.run)));
            let label = rows[0].perturbation.clone();
            let entry = perturb_core::registry::find(&label)
                .ok()
                .filter(|e| e.id == label);
            let mut severities: Vec<u8> = rows.iter().filter_map(|r| r.severity).collect();
            severities.dedup();
            PerturbationRow {
                name: entry.map(|e| e.name.to_string()).unwrap_or_default(),
                family: entry.map(|e| e.family.to_string()).unwrap_or_default(),
                perturbation: label,
                severities,
                run_severities: rows.iter().map(|r| r.severity).collect(),
                run_names: rows.iter().map(|r| r.run.clone()).collect(),
                metrics: aggregate(&rows.iter().map(|r| &r.metrics).collect::<Vec<_>>(), policy),
            }
        })
        .collect()
}
