//! Camera metrics (paper, RQ1): a driving model's steering predictions on every perturbed set
//! compared with its predictions on the clean frames: MSE and maximum deviation per
//! (perturbation, severity), summarised per perturbation as the paper does.
//!
//! Prediction files are CSVs of `frame,steering` lines (a header line is allowed). Layouts found
//! under the predictions folder: `PRED/C-A1_gaussian_noise/s3.csv`, `PRED/C-A1_s3.csv`,
//! `PRED/C-A1_gaussian_noise/s3/anything.csv`. Frames are matched by the first column.

use crate::Format;
use crate::error::{Result, StudyError};
use perturb_core::metrics::{SteeringMetrics, steering_metrics, summarize_camera};
use perturb_core::registry::{CATALOGUE, Entry};
use std::collections::BTreeMap;
use std::fmt::Write;
use std::path::{Path, PathBuf};

/// Reads `frame,value` lines.
pub fn read_steering_csv(path: &Path) -> Result<Vec<(String, f64)>> {
    let text = std::fs::read_to_string(path).map_err(StudyError::io(path))?;
    let bad = |line: usize, reason: String| StudyError::Table {
        path: path.to_path_buf(),
        line: Some(line),
        reason,
    };
    let mut out = Vec::new();
    for (n, line) in text.lines().enumerate() {
        let line = line.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let mut it = line.split(',');
        let (Some(frame), Some(value)) = (it.next(), it.next()) else {
            return Err(bad(
                n + 1,
                format!("expected `frame,value`, found `{line}`"),
            ));
        };
        match value.trim().parse::<f64>() {
            Ok(v) if v.is_finite() => out.push((frame.trim().to_string(), v)),
            Ok(_) => {
                return Err(bad(
                    n + 1,
                    format!("steering value `{}` is not finite", value.trim()),
                ));
            }
            Err(_) if out.is_empty() && n == 0 => {} // a header line
            Err(_) => return Err(bad(n + 1, format!("`{}` is not a number", value.trim()))),
        }
    }
    if out.is_empty() {
        return Err(StudyError::Table {
            path: path.to_path_buf(),
            line: None,
            reason: "holds no prediction".into(),
        });
    }
    Ok(out)
}

/// The (perturbation, severity) a prediction file belongs to, from its path.
pub fn classify(rel: &Path) -> Option<(&'static Entry, u8)> {
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
    for e in std::fs::read_dir(dir).map_err(StudyError::io(dir))? {
        let p = e.map_err(StudyError::io(dir))?.path();
        if p.is_dir() {
            csv_files(&p, out)?;
        } else if p.extension().is_some_and(|x| x == "csv") {
            out.push(p);
        }
    }
    Ok(())
}

/// The metrics of one (perturbation, severity) prediction file.
#[derive(Clone, Debug, serde::Serialize)]
pub struct SteeringRow {
    /// Perturbation ID.
    pub id: &'static str,
    /// Perturbation name.
    pub name: &'static str,
    /// Severity.
    pub severity: u8,
    /// MSE, maximum deviation, jitter.
    #[serde(flatten)]
    pub m: SteeringMetrics,
}

/// Every prediction file under a folder compared with the baseline.
#[derive(Clone, Debug)]
pub struct SteeringReport {
    /// Per (perturbation, severity), in file order.
    pub rows: Vec<SteeringRow>,
    /// Files whose perturbation and severity could not be told from their path.
    pub skipped: Vec<PathBuf>,
}

/// Compares every prediction CSV under `predictions` with `baseline`.
pub fn evaluate(baseline: &Path, predictions: &Path) -> Result<SteeringReport> {
    let base = read_steering_csv(baseline)?;
    let mut files = Vec::new();
    csv_files(predictions, &mut files)?;
    files.sort();
    let mut rows: Vec<SteeringRow> = Vec::new();
    let mut skipped = Vec::new();
    for f in &files {
        let rel = f.strip_prefix(predictions).unwrap_or(f);
        let Some((entry, severity)) = classify(rel) else {
            skipped.push(f.clone());
            continue;
        };
        let pert = read_steering_csv(f)?;
        let m = steering_metrics(&base, &pert).map_err(|e| {
            StudyError::input(f, format!("comparing with {}: {e}", baseline.display()))
        })?;
        rows.push(SteeringRow {
            id: entry.id,
            name: entry.name,
            severity,
            m,
        });
    }
    if rows.is_empty() {
        return Err(StudyError::input(
            predictions,
            "no prediction CSV found under it",
        ));
    }
    Ok(SteeringReport { rows, skipped })
}

/// The report in `format`: per perturbation (table, markdown: the paper's columns), per
/// severity (CSV), or both (JSON).
pub fn render(report: &SteeringReport, format: Format) -> String {
    let rows = &report.rows;
    let mut by_id: BTreeMap<usize, Vec<&SteeringRow>> = BTreeMap::new();
    for r in rows {
        let pos = CATALOGUE
            .iter()
            .position(|e| e.id == r.id)
            .unwrap_or(usize::MAX);
        by_id.entry(pos).or_default().push(r);
    }
    let mut s = String::new();
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
            s = serde_json::to_string_pretty(&Out {
                per_severity: rows,
                per_perturbation: per,
            })
            .expect("the report serialises")
                + "\n";
        }
        Format::Csv => {
            s.push_str(
                "id,name,severity,frames,mse,max_abs_deviation,jitter_baseline,jitter_perturbed\n",
            );
            for r in rows {
                let _ = writeln!(
                    s,
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
                s.push_str(
                    "| id | name | avg MSE | max MSE | max deviation | severities |\n|---|---|---:|---:|---:|---|\n",
                );
            } else {
                let _ = writeln!(
                    s,
                    "{:<7} {:<24} {:>10} {:>10} {:>13}  severities",
                    "id", "name", "avg_mse", "max_mse", "max_deviation"
                );
            }
            for rs in by_id.values() {
                let sm = summarize_camera(&rs.iter().map(|r| r.m).collect::<Vec<_>>());
                let sev: Vec<String> = rs.iter().map(|r| r.severity.to_string()).collect();
                if md {
                    let _ = writeln!(
                        s,
                        "| {} | {} | {:.5} | {:.5} | {:.4} | {} |",
                        rs[0].id,
                        rs[0].name,
                        sm.avg_mse,
                        sm.max_mse,
                        sm.max_abs_deviation,
                        sev.join(",")
                    );
                } else {
                    let _ = writeln!(
                        s,
                        "{:<7} {:<24} {:>10.5} {:>10.5} {:>13.4}  {}",
                        rs[0].id,
                        rs[0].name,
                        sm.avg_mse,
                        sm.max_mse,
                        sm.max_abs_deviation,
                        sev.join(",")
                    );
                }
            }
        }
    }
    s
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
