//! Two (or more) sets of runs side by side per condition (paper, RQ4: the fine-tuned model and
//! the baseline under nominal and real weather conditions, three runs each).
//!
//! The condition of a run is the sub-folder it is in (`ft/mud/run1.mcap` is condition `mud`),
//! or, for runs directly in the set's folder, the perturbation active through the run
//! (`nominal`, an ID, or `mixed`). Rows are per (condition, set); completion and failure type of
//! every run, CTE and jitter aggregated as in [`crate::analyze::aggregate`], by default over
//! every run's part of the shared non-failing portion of the route (the paper's RQ4: "comparison
//! is restricted to the shared non-failing portion of each run").

use crate::analyze::{
    Aggregate, Aggregated, Analysis, AnalyzeConfig, Metrics, RunResult, aggregate, window_until,
};
use crate::table::{Table, num, raw};
use serde::Serialize;
use std::collections::BTreeMap;

/// One (condition, set) row.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct CompareRow {
    /// The condition.
    pub condition: String,
    /// The set (system under test), e.g. `fine-tuned`.
    pub set: String,
    /// The runs, by name.
    pub run_names: Vec<String>,
    /// With [`Aggregate::Shared`]: the trajectory metrics cover the route up to this arc length,
    /// metres (the shared non-failing portion of the condition's runs, every set together).
    pub shared_until_m: Option<f64>,
    /// The aggregated metrics.
    #[serde(flatten)]
    pub metrics: Aggregated,
}

/// How far along the route a run got before failing, less `exclude` metres (the CTE's d); the
/// route's length for a run that did not fail; None without a route or progress.
fn safe_reach(r: &RunResult, length: f64, exclude: f64) -> Option<f64> {
    let last = *r.track.reached.last()?;
    Some(if r.metrics.failure.is_some() {
        (last - exclude).max(0.0)
    } else {
        length
    })
}

/// The rows of every set, conditions in order (nominal first, then as they first appear), the
/// sets in the order given within a condition. With `cfg.aggregate` [`Aggregate::Shared`] (the
/// paper's RQ4), each condition's trajectory metrics cover only the part of the route every one
/// of its runs (in every set) drove before failing, less `cfg.cte_exclude_m` before the earliest
/// failure; completion and failures are the runs' own.
pub fn compare(sets: &[(String, Analysis)], cfg: &AnalyzeConfig) -> Vec<CompareRow> {
    let policy = cfg.aggregate;
    let mut conditions: Vec<String> = Vec::new();
    let mut rows: BTreeMap<(String, usize), Vec<&RunResult>> = BTreeMap::new();
    for (k, (_, a)) in sets.iter().enumerate() {
        for r in &a.runs {
            let c = r.group.clone().unwrap_or_else(|| r.perturbation.clone());
            if !conditions.contains(&c) {
                conditions.push(c.clone());
            }
            rows.entry((c, k)).or_default().push(r);
        }
    }
    conditions.sort_by_key(|c| c != "nominal");
    let length = sets
        .iter()
        .find_map(|(_, a)| a.route.as_ref().map(|r| r.length()));
    let mut out = Vec::new();
    for c in &conditions {
        let shared = (policy == Aggregate::Shared)
            .then(|| {
                let length = length?;
                rows.iter()
                    .filter(|((cc, _), _)| cc == c)
                    .flat_map(|(_, runs)| runs.iter())
                    .filter_map(|r| safe_reach(r, length, cfg.cte_exclude_m))
                    .reduce(f64::min)
            })
            .flatten();
        for (k, (name, _)) in sets.iter().enumerate() {
            let Some(runs) = rows.get(&(c.clone(), k)) else {
                continue;
            };
            let metrics: Vec<Metrics> = runs
                .iter()
                .map(|r| match shared {
                    Some(until) => {
                        let w = window_until(&r.track, until, cfg.jitter_unit);
                        Metrics {
                            cte_avg: w.cte_avg,
                            cte_max: w.cte_max,
                            jitter_avg: w.jitter_avg,
                            jitter_max: w.jitter_max,
                            jitter_std: w.jitter_std,
                            ..r.metrics.clone()
                        }
                    }
                    None => r.metrics.clone(),
                })
                .collect();
            let refs: Vec<&Metrics> = metrics.iter().collect();
            out.push(CompareRow {
                condition: c.clone(),
                set: name.clone(),
                run_names: runs.iter().map(|r| r.run.clone()).collect(),
                shared_until_m: shared,
                metrics: aggregate(&refs, policy),
            });
        }
    }
    out
}

/// The comparison in the paper's RQ4 layout.
pub fn render(rows: &[CompareRow], format: crate::Format) -> String {
    if format == crate::Format::Json {
        return serde_json::to_string_pretty(rows).expect("serialises") + "\n";
    }
    let csv = format == crate::Format::Csv;
    let f = |v: Option<f64>, d: usize| if csv { raw(v) } else { num(v, d) };
    let mut t = Table::new(&[
        ("condition", false),
        ("set", false),
        ("runs", true),
        ("completion", false),
        ("failures", false),
        ("cte_avg", true),
        ("cte_max", true),
        ("jitter_avg", true),
        ("jitter_max", true),
        ("jitter_std", true),
        ("shared_until_m", true),
    ]);
    let mut last = String::new();
    for r in rows {
        let comp: Vec<String> = r
            .metrics
            .completions
            .iter()
            .map(|c| c.map_or("-".into(), |c| format!("{:.0}%", c * 100.0)))
            .collect();
        let fails: Vec<String> = r
            .metrics
            .outcomes
            .iter()
            .zip(&r.metrics.failures)
            .map(|(o, f)| crate::analyze::outcome_letter(*o, *f).to_string())
            .collect();
        let cond = if csv || r.condition != last {
            r.condition.clone()
        } else {
            String::new()
        };
        last = r.condition.clone();
        t.push(vec![
            cond,
            r.set.clone(),
            r.metrics.runs.to_string(),
            comp.join(if csv { ";" } else { " " }),
            if csv {
                fails.join(";")
            } else {
                format!("[{}]", fails.join(","))
            },
            f(r.metrics.cte_avg, 2),
            f(r.metrics.cte_max, 2),
            f(r.metrics.jitter_avg, 2),
            f(r.metrics.jitter_max, 2),
            f(r.metrics.jitter_std, 2),
            f(r.shared_until_m, 1),
        ]);
    }
    t.render(format)
}
