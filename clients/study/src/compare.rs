//! Two (or more) sets of runs side by side per condition (paper, RQ4: the fine-tuned model and
//! the baseline under nominal and real weather conditions, three runs each).
//!
//! The condition of a run is the sub-folder it is in (`ft/mud/run1.mcap` is condition `mud`),
//! or, for runs directly in the set's folder, the perturbation active through the run
//! (`nominal`, an ID, or `mixed`). Rows are per (condition, set); completion and failure type of
//! every run, CTE and jitter aggregated as in [`crate::analyze::aggregate`] (by default over every
//! run, failing ones up to the failure, as the paper's RQ4 table).

use crate::analyze::{Aggregate, Aggregated, Analysis, aggregate};
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
    /// The aggregated metrics.
    #[serde(flatten)]
    pub metrics: Aggregated,
}

/// The rows of every set, conditions in order (nominal first, then as they first appear), the
/// sets in the order given within a condition.
pub fn compare(sets: &[(String, Analysis)], policy: Aggregate) -> Vec<CompareRow> {
    let mut conditions: Vec<String> = Vec::new();
    let mut rows: BTreeMap<(String, usize), Vec<&crate::analyze::RunResult>> = BTreeMap::new();
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
    let mut out = Vec::new();
    for c in &conditions {
        for (k, (name, _)) in sets.iter().enumerate() {
            let Some(runs) = rows.get(&(c.clone(), k)) else {
                continue;
            };
            let metrics: Vec<&crate::analyze::Metrics> = runs.iter().map(|r| &r.metrics).collect();
            out.push(CompareRow {
                condition: c.clone(),
                set: name.clone(),
                run_names: runs.iter().map(|r| r.run.clone()).collect(),
                metrics: aggregate(&metrics, policy),
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
            .failures
            .iter()
            .map(|f| f.map_or("ok".into(), |f| f.letter().to_string()))
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
        ]);
    }
    t.render(format)
}
