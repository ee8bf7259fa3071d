//! The analysis as tables: per run, per segment, per (perturbation, severity) and per
//! perturbation (the paper's layout).

use super::aggregate::Aggregated;
use super::{
    ConditionRow, Failure, Metrics, Outcome, PerturbationRow, RunResult, SegmentResult, Summary,
};
use crate::Format;
use crate::table::{Table, num, raw};

fn failure(f: Option<Failure>, csv: bool) -> String {
    match (f, csv) {
        (Some(f), _) => f.name().to_string(),
        (None, true) => String::new(),
        (None, false) => "-".into(),
    }
}

fn sev(s: Option<u8>) -> String {
    s.map_or("-".into(), |s| s.to_string())
}

const METRIC_COLUMNS: [(&str, bool); 10] = [
    ("outcome", false),
    ("completion", true),
    ("failure", false),
    ("cte_avg", true),
    ("cte_max", true),
    ("jitter_avg", true),
    ("jitter_max", true),
    ("jitter_std", true),
    ("coverage_5m", true),
    ("duration_s", true),
];

fn metric_cells(m: &Metrics, csv: bool) -> Vec<String> {
    let f = |v: Option<f64>, d: usize| if csv { raw(v) } else { num(v, d) };
    vec![
        m.outcome.name().to_string(),
        f(m.completion, 3),
        failure(m.failure, csv),
        f(m.cte_avg, 3),
        f(m.cte_max, 3),
        f(m.jitter_avg, 4),
        f(m.jitter_max, 4),
        f(m.jitter_std, 4),
        f(m.coverage_5m, 3),
        f(Some(m.duration_s), 1),
    ]
}

fn json<T: serde::Serialize>(rows: &T) -> String {
    serde_json::to_string_pretty(rows).expect("rows serialise") + "\n"
}

/// One row per run.
pub fn render_runs(runs: &[RunResult], format: Format) -> String {
    if format == Format::Json {
        return json(&runs);
    }
    let csv = format == Format::Csv;
    let mut cols = vec![("run", false), ("perturbation", false), ("severity", true)];
    cols.extend(METRIC_COLUMNS);
    let mut t = Table::new(&cols);
    for r in runs {
        let mut row = vec![r.run.clone(), r.perturbation.clone(), sev(r.severity)];
        row.extend(metric_cells(&r.metrics, csv));
        t.push(row);
    }
    t.render(format)
}

/// One row per segment of constant condition.
pub fn render_segments(segments: &[SegmentResult], format: Format) -> String {
    if format == Format::Json {
        return json(&segments);
    }
    let csv = format == Format::Csv;
    let mut cols = vec![
        ("run", false),
        ("perturbation", false),
        ("severity", true),
        ("step", true),
        ("start_s", true),
        ("end_s", true),
    ];
    cols.extend(METRIC_COLUMNS);
    let mut t = Table::new(&cols);
    for s in segments {
        let mut row = vec![
            s.run.clone(),
            s.perturbation.clone(),
            sev(s.severity),
            s.step.map_or_else(|| "-".to_string(), |k| k.to_string()),
            format!("{:.1}", s.start_s),
            format!("{:.1}", s.end_s),
        ];
        row.extend(metric_cells(&s.metrics, csv));
        t.push(row);
    }
    t.render(format)
}

/// The letter of an outcome in the paper's `[C,ok,...]` lists: the failure's letter, `ok`, or
/// `?` for a run that was not judged.
pub fn outcome_letter(o: Outcome, f: Option<Failure>) -> &'static str {
    match (o, f) {
        (_, Some(f)) => f.letter(),
        (Outcome::Unjudged, None) => "?",
        _ => "ok",
    }
}

/// Completions and outcomes per run, e.g. `45% C, 100% ✓`.
fn outcomes(a: &Aggregated, csv: bool) -> (String, String) {
    let comp: Vec<String> = a
        .completions
        .iter()
        .map(|c| c.map_or("-".into(), |c| format!("{:.0}%", c * 100.0)))
        .collect();
    let fails: Vec<String> = a
        .outcomes
        .iter()
        .zip(&a.failures)
        .map(|(o, f)| outcome_letter(*o, *f).to_string())
        .collect();
    if csv {
        (comp.join(";"), fails.join(";"))
    } else {
        (comp.join(" "), format!("[{}]", fails.join(",")))
    }
}

fn aggregated_cells(a: &Aggregated, csv: bool) -> Vec<String> {
    let f = |v: Option<f64>, d: usize| if csv { raw(v) } else { num(v, d) };
    let (comp, fails) = outcomes(a, csv);
    vec![
        a.runs.to_string(),
        a.unjudged.to_string(),
        comp,
        fails,
        f(a.failure_rate, 2),
        f(a.cte_avg, 2),
        f(a.cte_max, 2),
        f(a.jitter_avg, 3),
        f(a.jitter_max, 3),
        f(a.jitter_std, 3),
        f(a.coverage_5m, 3),
    ]
}

const AGG_COLUMNS: [(&str, bool); 11] = [
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
];

/// One row per (perturbation, severity).
pub fn render_conditions(rows: &[ConditionRow], format: Format) -> String {
    if format == Format::Json {
        return json(&rows);
    }
    let csv = format == Format::Csv;
    let mut cols = vec![("perturbation", false), ("severity", true)];
    cols.extend(AGG_COLUMNS);
    let mut t = Table::new(&cols);
    for r in rows {
        let mut row = vec![r.perturbation.clone(), sev(r.severity)];
        row.extend(aggregated_cells(&r.metrics, csv));
        t.push(row);
    }
    t.render(format)
}

/// One row per perturbation, the paper's RQ3 layout: completion of every run (highest
/// severity first), failure types, CTE, jitter and coverage.
pub fn render_perturbations(rows: &[PerturbationRow], format: Format) -> String {
    if format == Format::Json {
        return json(&rows);
    }
    let csv = format == Format::Csv;
    let mut cols = vec![
        ("perturbation", false),
        ("name", false),
        ("severities", false),
    ];
    cols.extend(AGG_COLUMNS);
    let mut t = Table::new(&cols);
    for r in rows {
        let sevs: Vec<String> = r.severities.iter().map(|s| s.to_string()).collect();
        let mut row = vec![
            r.perturbation.clone(),
            r.name.clone(),
            sevs.join(if csv { ";" } else { "," }),
        ];
        row.extend(aggregated_cells(&r.metrics, csv));
        t.push(row);
    }
    t.render(format)
}

/// The summary as lines of text: counts of ok, failed and unjudged runs (with the reasons),
/// errors and skipped files, the checks that ran and the CTE's reference.
pub fn render_summary(s: &Summary) -> String {
    let mut out = format!(
        "{} run{} analysed: {} ok, {} failed, {} unjudged",
        s.runs,
        if s.runs == 1 { "" } else { "s" },
        s.ok,
        s.failed,
        s.unjudged
    );
    if s.errors > 0 {
        out.push_str(&format!("; {} could not be read", s.errors));
    }
    if s.skipped > 0 {
        out.push_str(&format!(
            "; {} file(s) or folder(s) skipped (not runs)",
            s.skipped
        ));
    }
    out.push('\n');
    for (why, n) in &s.unjudged_reasons {
        out.push_str(&format!("  unjudged ({n}): {why}\n"));
    }
    out.push_str(&format!(
        "failure checks: {}; CTE against: {}\n",
        if s.checks.is_empty() {
            "none".to_string()
        } else {
            s.checks.join(", ")
        },
        s.cte_reference
    ));
    out
}
