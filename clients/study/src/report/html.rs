//! The report as one HTML page: inline CSS and SVG only (no script, no font, no image fetched),
//! so it opens the same offline, from a mail attachment or a CI artefact.

use super::{Combined, Report, Section, scatter};
use crate::analyze::Outcome;
use crate::plot::charts;
use crate::plot::xml_escape as esc;
use crate::table::num;
use std::fmt::Write;

const STYLE: &str = r#"
body { font-family: system-ui, -apple-system, "Segoe UI", Roboto, "DejaVu Sans", sans-serif; margin: 0; color: #1e1e1e; background: #fff; }
header { padding: 18px 28px 8px; border-bottom: 1px solid #ddd; }
header h1 { margin: 0 0 4px; font-size: 26px; }
header p { margin: 2px 0; color: #555; font-size: 14px; }
nav { margin-top: 8px; font-size: 14px; }
nav a { margin-right: 14px; color: #0b5cad; text-decoration: none; }
main { padding: 8px 28px 40px; }
section { margin: 26px 0; }
section h2 { font-size: 21px; border-bottom: 2px solid #0072b2; padding-bottom: 4px; }
section h3 { font-size: 17px; margin: 18px 0 6px; }
section.missing h2 { border-bottom-color: #c83232; }
p.missing-reason { background: #fff2f2; border-left: 4px solid #c83232; padding: 8px 12px; }
p.note, li.note { color: #6a4b00; }
table { border-collapse: collapse; font-size: 13px; margin: 6px 0 10px; }
th, td { border: 1px solid #d4d4d4; padding: 3px 7px; vertical-align: middle; }
th { background: #f2f5f8; text-align: left; position: sticky; top: 0; }
td.num { text-align: right; font-variant-numeric: tabular-nums; }
td.bad { color: #b00000; font-weight: 600; }
td.good { color: #1f7a33; }
tr:nth-child(even) td { background: #fafafa; }
figure { margin: 10px 0; }
figure svg { max-width: 100%; height: auto; }
figcaption { font-size: 13px; color: #444; margin-top: 4px; }
.grid { display: flex; flex-wrap: wrap; gap: 10px; }
.grid figure { border: 1px solid #e2e2e2; padding: 4px; }
td svg { display: block; }
code { background: #f3f3f3; padding: 0 3px; }
"#;

fn td_num(v: Option<f64>, digits: usize) -> String {
    format!("<td class=\"num\">{}</td>", esc(&num(v, digits)))
}

fn td(text: &str) -> String {
    format!("<td>{}</td>", esc(text))
}

fn head(cols: &[&str]) -> String {
    let mut s = String::from("<thead><tr>");
    for c in cols {
        let _ = write!(s, "<th>{}</th>", esc(c));
    }
    s.push_str("</tr></thead>");
    s
}

fn missing(s: &mut String, id: &str, title: &str, reason: &str) {
    let _ = writeln!(
        s,
        "<section id=\"{id}\" class=\"missing\" data-section=\"{id}\" data-status=\"missing\"><h2>{}</h2><p class=\"missing-reason\">Missing: {}</p></section>",
        esc(title),
        esc(reason)
    );
}

fn open(s: &mut String, id: &str, title: &str) {
    let _ = writeln!(
        s,
        "<section id=\"{id}\" data-section=\"{id}\" data-status=\"present\"><h2>{}</h2>",
        esc(title)
    );
}

fn figure(s: &mut String, id: &str, svg: &str, caption: &str) {
    let _ = writeln!(
        s,
        "<figure class=\"chart\" id=\"{id}\">{svg}<figcaption>{}</figcaption></figure>",
        esc(caption)
    );
}

fn feasible_cell(v: Option<bool>) -> String {
    match v {
        Some(true) => "<td class=\"good\">yes</td>".into(),
        Some(false) => "<td class=\"bad\">no</td>".into(),
        None => "<td>-</td>".into(),
    }
}

fn combined_table(s: &mut String, c: &Combined) -> crate::Result<()> {
    let camera = c.modality == "camera";
    let _ = write!(
        s,
        "<h3>{} perturbations</h3>",
        if camera { "Camera" } else { "LiDAR" }
    );
    for n in &c.notes {
        let _ = write!(s, "<p class=\"note\">{}</p>", esc(n));
    }
    let mut cols = vec!["ID", "name", "family"];
    if camera {
        cols.extend(["avg MSE", "max MSE", "max dev.", "MSE per severity"]);
    } else {
        cols.extend([
            "avg retention",
            "min retention",
            "max ATE (m)",
            "1 - retention per severity",
        ]);
    }
    cols.extend([
        "avg latency (ms)",
        "max latency (ms)",
        "node overhead (ms)",
        "budget (ms)",
        "feasible (avg)",
        "max within budget",
    ]);
    let _ = write!(
        s,
        "<table id=\"table-combined-{}\" class=\"combined\">{}<tbody>",
        c.modality,
        head(&cols)
    );
    let trend_max = c
        .rows
        .iter()
        .flat_map(|r| r.trend.iter().map(|t| t.1))
        .fold(0.0, f64::max);
    for r in &c.rows {
        s.push_str("<tr>");
        s.push_str(&td(&r.id));
        s.push_str(&td(&r.name));
        s.push_str(&td(&r.family));
        if camera {
            s.push_str(&td_num(r.avg_mse, 4));
            s.push_str(&td_num(r.max_mse, 4));
            s.push_str(&td_num(r.max_abs_deviation, 3));
        } else {
            s.push_str(&td_num(r.avg_retention, 3));
            s.push_str(&td_num(r.min_retention, 3));
            s.push_str(&td_num(r.max_ate, 3));
        }
        if r.trend.is_empty() {
            s.push_str("<td>-</td>");
        } else {
            let _ = write!(
                s,
                "<td class=\"trend\">{}</td>",
                charts::trend_bars(&r.trend, trend_max)?
            );
        }
        s.push_str(&td_num(r.avg_latency_ms, 2));
        s.push_str(&td_num(r.max_latency_ms, 2));
        s.push_str(&td_num(r.node_overhead_ms, 3));
        s.push_str(&td_num(Some(r.budget_ms), 0));
        s.push_str(&feasible_cell(r.feasible));
        s.push_str(&feasible_cell(r.max_within_budget));
        s.push_str("</tr>\n");
    }
    s.push_str("</tbody></table>\n");
    Ok(())
}

fn outcome_of(letter: &str) -> Outcome {
    match letter {
        "ok" => Outcome::Ok,
        "?" => Outcome::Unjudged,
        _ => Outcome::Failed,
    }
}

fn bars(completions: &[Option<f64>], outcomes: &[String]) -> crate::Result<String> {
    let runs: Vec<(Option<f64>, Outcome)> = completions
        .iter()
        .zip(outcomes.iter().map(|o| outcome_of(o)))
        .map(|(c, o)| (*c, o))
        .collect();
    charts::completion_bars(&runs)
}

/// The page.
pub(crate) fn render(r: &Report) -> crate::Result<String> {
    let mut s = String::with_capacity(1 << 20);
    let _ = writeln!(
        s,
        "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\"><meta name=\"viewport\" content=\"width=device-width, initial-scale=1\"><title>{}</title><style>{STYLE}</style></head><body>",
        esc(&r.title)
    );
    let _ = write!(
        s,
        "<header><h1>{}</h1><p>Built by <code>perturb report</code> from the outputs in <code>{}</code>. Definitions: docs/study.md.</p><nav>",
        esc(&r.title),
        esc(&r.study_dir.display().to_string())
    );
    for (id, name) in [
        ("inputs", "Inputs"),
        ("combined", "RQ1/RQ2"),
        ("rq3", "RQ3"),
        ("transfer", "Transfer"),
        ("hotspots", "Hotspots"),
        ("curves", "Severity curves"),
        ("latency", "Latency"),
        ("rq4", "RQ4"),
    ] {
        let _ = write!(s, "<a href=\"#{id}\">{name}</a>");
    }
    s.push_str("</nav></header><main>\n");
    inputs(&mut s, r);
    combined(&mut s, r)?;
    rq3(&mut s, r)?;
    transfer(&mut s, r)?;
    hotspots(&mut s, r);
    charts_section(
        &mut s,
        "curves",
        "Offline metrics per severity",
        &r.curves,
        "per severity, one panel per family",
    );
    charts_section(
        &mut s,
        "latency",
        "Latency against the real-time budget",
        &r.latency,
        "bars: average over severities; tick: maximum; red line: budget",
    );
    rq4(&mut s, r)?;
    s.push_str("</main></body></html>\n");
    Ok(s)
}

fn inputs(s: &mut String, r: &Report) {
    open(s, "inputs", "Inputs");
    let _ = write!(
        s,
        "<table id=\"table-inputs\">{}<tbody>",
        head(&["file", "read as", "written by"])
    );
    for i in &r.inputs.used {
        let _ = write!(
            s,
            "<tr>{}{}{}</tr>",
            td(&i.path.display().to_string()),
            td(&format!("{:?}", i.kind).to_lowercase()),
            td(i.kind.tool())
        );
    }
    s.push_str("</tbody></table>");
    let missing: Vec<_> = r.sections().into_iter().filter(|x| x.1.is_some()).collect();
    if !missing.is_empty() {
        s.push_str("<h3>Sections without their input</h3><ul id=\"missing-sections\">");
        for (name, why) in missing {
            let _ = write!(
                s,
                "<li class=\"note\"><b>{}</b>: {}</li>",
                esc(name),
                esc(why.unwrap_or_default())
            );
        }
        s.push_str("</ul>");
    }
    if !r.inputs.ignored.is_empty() {
        s.push_str("<h3>Files not used</h3><ul>");
        for i in &r.inputs.ignored {
            let _ = write!(
                s,
                "<li>{}: {}</li>",
                esc(&i.path.display().to_string()),
                esc(&i.reason)
            );
        }
        s.push_str("</ul>");
    }
    s.push_str("</section>\n");
}

fn combined(s: &mut String, r: &Report) -> crate::Result<()> {
    let title = "RQ1/RQ2: offline effect and feasibility per perturbation";
    match &r.combined {
        Section::Missing { reason } => missing(s, "combined", title, reason),
        Section::Present { content } => {
            open(s, "combined", title);
            s.push_str("<p>Offline effect over the severities (camera: steering MSE average and maximum, maximum absolute deviation; LiDAR: detection retention average and minimum, maximum ATE), trend bars per severity, latency per frame (average over severities, maximum), node overhead and feasibility: average latency within 33 ms (camera) or 200 ms (LiDAR).</p>");
            for c in content {
                combined_table(s, c)?;
            }
            s.push_str("</section>\n");
        }
    }
    Ok(())
}

fn rq3(s: &mut String, r: &Report) -> crate::Result<()> {
    let title = "RQ3: closed-loop outcomes per perturbation";
    let content = match &r.closed_loop {
        Section::Missing { reason } => {
            missing(s, "rq3", title, reason);
            return Ok(());
        }
        Section::Present { content } => content,
    };
    open(s, "rq3", title);
    s.push_str("<p>Completion of each run (bars; green ok, red failed, grey unjudged), failure types (E erratic start, U understeer, O oversteer, R road departure, C collision, T takeover, X timeout, I incomplete; ? unjudged), failure rate over the judged runs; CTE and jitter over the non-failing runs, near-field detection coverage.</p>");
    for (k, cl) in content.iter().enumerate() {
        let _ = write!(s, "<h3>{}</h3>", esc(&cl.name));
        if let Some(sum) = &cl.summary {
            let n = |key: &str| sum.get(key).and_then(|v| v.as_u64()).unwrap_or(0);
            let _ = write!(
                s,
                "<p class=\"summary\">{} runs: {} ok, {} failed, {} unjudged; {} could not be read. CTE against: {}. Failure checks: {}.</p>",
                n("runs"),
                n("ok"),
                n("failed"),
                n("unjudged"),
                n("errors"),
                esc(sum
                    .get("cte_reference")
                    .and_then(|v| v.as_str())
                    .unwrap_or("-")),
                esc(&sum
                    .get("checks")
                    .and_then(|v| v.as_array())
                    .map(|a| a
                        .iter()
                        .filter_map(|c| c.as_str())
                        .collect::<Vec<_>>()
                        .join(", "))
                    .unwrap_or_default())
            );
        }
        let _ = write!(
            s,
            "<table id=\"table-rq3-{k}\" class=\"rq3\">{}<tbody>",
            head(&[
                "perturbation",
                "name",
                "runs",
                "unjudged",
                "completion",
                "failure types",
                "failure rate",
                "CTE avg (m)",
                "CTE max (m)",
                "jitter avg",
                "jitter max",
                "jitter std",
                "coverage 5 m",
            ])
        );
        for x in &cl.rows {
            let _ = writeln!(
                s,
                "<tr>{}{}<td class=\"num\">{}</td><td class=\"num\">{}</td><td class=\"bars\">{}</td>{}{}{}{}{}{}{}{}</tr>",
                td(&x.perturbation),
                td(&x.name),
                x.runs,
                x.unjudged,
                bars(&x.completions, &x.outcomes)?,
                td(&format!("[{}]", x.outcomes.join(","))),
                td_num(x.failure_rate, 2),
                td_num(x.trajectory.cte_avg, 2),
                td_num(x.trajectory.cte_max, 2),
                td_num(x.trajectory.jitter_avg, 3),
                td_num(x.trajectory.jitter_max, 3),
                td_num(x.trajectory.jitter_std, 3),
                td_num(x.coverage_5m, 3),
            );
        }
        s.push_str("</tbody></table>\n");
    }
    s.push_str("</section>\n");
    Ok(())
}

fn transfer(s: &mut String, r: &Report) -> crate::Result<()> {
    let title = "Transfer: do offline effects predict closed-loop outcomes?";
    let ts = match &r.transfer {
        Section::Missing { reason } => {
            missing(s, "transfer", title, reason);
            return Ok(());
        }
        Section::Present { content } => content,
    };
    open(s, "transfer", title);
    let t = &ts.transfer;
    let _ = write!(
        s,
        "<p>{} matched (perturbation, severity) pairs; Spearman's rho with a {:.0}% percentile bootstrap interval ({} resamples, seed {}), p from Student's t, Benjamini-Hochberg q over the metric pairs, overlap of the top {} of both rankings. Source: {}.</p>",
        t.matched,
        t.level * 100.0,
        t.resamples,
        t.seed,
        t.top_k,
        esc(&ts.source)
    );
    if !ts.infeasible.is_empty() {
        let _ = write!(
            s,
            "<p class=\"note\">Left out as infeasible (average latency over the budget): {}.</p>",
            esc(&ts.infeasible.join(", "))
        );
    }
    let _ = write!(
        s,
        "<table id=\"table-transfer\">{}<tbody>",
        head(&[
            "offline",
            "closed loop",
            "n",
            "rho",
            "CI low",
            "CI high",
            "p",
            "q",
            "top-k overlap",
            "top offline",
            "top closed loop",
            "note",
        ])
    );
    for x in &t.rows {
        let _ = writeln!(
            s,
            "<tr>{}{}<td class=\"num\">{}</td>{}{}{}{}{}{}{}{}{}</tr>",
            td(&x.offline),
            td(&x.closed_loop),
            x.n,
            td_num(x.rho, 2),
            td_num(x.ci_low, 2),
            td_num(x.ci_high, 2),
            td_num(x.p, 4),
            td_num(x.q, 4),
            td_num(x.top_k_overlap, 2),
            td(&x.top_offline.join(", ")),
            td(&x.top_closed_loop.join(", ")),
            td(x.note.as_deref().unwrap_or("")),
        );
    }
    s.push_str("</tbody></table>\n<div class=\"grid\">");
    for k in 0..t.rows.len() {
        if let Some(svg) = scatter(t, k)? {
            let row = &t.rows[k];
            figure(
                s,
                &format!("chart-transfer-{k}"),
                &svg,
                &format!(
                    "{} vs {}: ringed, offline top {}; red, closed-loop top {}",
                    row.offline, row.closed_loop, t.top_k, t.top_k
                ),
            );
        }
    }
    s.push_str("</div></section>\n");
    Ok(())
}

fn hotspots(s: &mut String, r: &Report) {
    let title = "Failure hotspots and the trajectory map";
    let content = match &r.closed_loop {
        Section::Missing { reason } => {
            missing(s, "hotspots", title, reason);
            return;
        }
        Section::Present { content } => content,
    };
    open(s, "hotspots", title);
    for (k, cl) in content.iter().enumerate() {
        let _ = write!(s, "<h3>{}</h3>", esc(&cl.name));
        match &cl.map_svg {
            Some(svg) => figure(
                s,
                &format!("chart-map-{k}"),
                svg,
                "trajectories coloured by perturbation family, failure markers by type, hotspots outlined (DBSCAN per failure type)",
            ),
            None => {
                let _ = write!(
                    s,
                    "<p class=\"missing-reason\">Missing: no map.svg beside {} (written by perturb analyze --out DIR).</p>",
                    esc(&cl.path.display().to_string())
                );
            }
        }
        let _ = write!(
            s,
            "<table id=\"table-hotspots-{k}\">{}<tbody>",
            head(&[
                "hotspot",
                "failure",
                "x (m)",
                "y (m)",
                "size",
                "radius (m)",
                "perturbations",
                "families",
            ])
        );
        for h in &cl.hotspots {
            let _ = writeln!(
                s,
                "<tr>{}{}{}{}<td class=\"num\">{}</td>{}{}{}</tr>",
                td(&h.hotspot),
                td(&h.failure),
                td_num(Some(h.x), 1),
                td_num(Some(h.y), 1),
                h.size,
                td_num(Some(h.radius_m), 1),
                td(&h.perturbations),
                td(&h.families),
            );
        }
        s.push_str("</tbody></table>\n");
    }
    s.push_str("</section>\n");
}

fn charts_section(
    s: &mut String,
    id: &str,
    title: &str,
    sec: &Section<Vec<(String, String)>>,
    caption: &str,
) {
    match sec {
        Section::Missing { reason } => missing(s, id, title, reason),
        Section::Present { content } => {
            open(s, id, title);
            for (name, svg) in content {
                figure(
                    s,
                    &format!("chart-{id}-{name}"),
                    svg,
                    &format!("{name}: {caption}"),
                );
            }
            s.push_str("</section>\n");
        }
    }
}

fn rq4(s: &mut String, r: &Report) -> crate::Result<()> {
    let title = "RQ4: fine-tuned vs baseline";
    let rows = match &r.rq4 {
        Section::Missing { reason } => {
            missing(s, "rq4", title, reason);
            return Ok(());
        }
        Section::Present { content } => content,
    };
    open(s, "rq4", title);
    s.push_str("<p>Completion and failure types of every run; CTE and jitter over the shared non-failing portion of the condition's runs (the route up to the earliest failure, less the last d metres; the whole route when no run failed).</p>");
    let _ = write!(
        s,
        "<table id=\"table-rq4\">{}<tbody>",
        head(&[
            "condition",
            "set",
            "completion",
            "failure types",
            "CTE avg (m)",
            "CTE max (m)",
            "jitter avg",
            "jitter max",
            "jitter std",
            "shared portion (m)",
        ])
    );
    for x in rows {
        let _ = writeln!(
            s,
            "<tr>{}{}<td class=\"bars\">{}</td>{}{}{}{}{}{}{}</tr>",
            td(&x.condition),
            td(&x.set),
            bars(&x.completions, &x.outcomes)?,
            td(&format!("[{}]", x.outcomes.join(","))),
            td_num(x.trajectory.cte_avg, 2),
            td_num(x.trajectory.cte_max, 2),
            td_num(x.trajectory.jitter_avg, 2),
            td_num(x.trajectory.jitter_max, 2),
            td_num(x.trajectory.jitter_std, 2),
            td_num(x.shared_until_m, 1),
        );
    }
    s.push_str("</tbody></table></section>\n");
    Ok(())
}
