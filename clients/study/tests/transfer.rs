//! The transfer statistics against scipy on the same numbers: the tables are written as the
//! project writes them (offline JSON of `perturb metrics`, closed-loop CSV of `perturb
//! analyze`), read back here and, independently, by a Python script that matches the pairs
//! itself and computes Spearman's rho and p (scipy.stats.spearmanr), the Benjamini-Hochberg
//! q-values (scipy.stats.false_discovery_control), the percentile CI over the same resamples,
//! and the top-k overlap.

use perturb_study::stats::resample;
use perturb_study::transfer::{TransferConfig, read_table, transfer};
use std::collections::BTreeMap;

#[path = "../../../tests/support/python_oracle.rs"]
mod python_oracle;

/// [`python_oracle::python_oracle`] with scipy's install hint.
fn python(modules: &str, script: &str, args: &[&str]) -> Option<String> {
    python_oracle::python_oracle(modules, "pip install scipy numpy", script, args)
}

const SCIPY: &str = r#"
import sys, json, csv
import numpy as np
from scipy import stats
off = {(r["id"], r["severity"]): r for r in json.load(open(sys.argv[1]))["per_severity"]}
cl = {}
for r in csv.DictReader(open(sys.argv[2])):
    if r["severity"] not in ("", "-"):
        cl[(r["perturbation"], int(r["severity"]))] = r
resamples = json.load(open(sys.argv[3]))
k = int(sys.argv[4])
keys = sorted(set(off) & set(cl))
rows = []
for o in ["mse", "max_abs_deviation", "retention_loss"]:
    for c in ["failure_rate", "cte_avg", "jitter_avg", "coverage_5m"]:
        xs, ys = [], []
        for key in keys:
            xv = 1.0 - off[key]["retention"] if o == "retention_loss" else off[key][o]
            yv = cl[key][c]
            if xv is None or yv == "":
                continue
            xs.append(float(xv)); ys.append(float(yv))
        x, y = np.array(xs), np.array(ys)
        res = stats.spearmanr(x, y)
        rhos = []
        for idx in resamples[str(len(x))]:
            xb, yb = x[idx], y[idx]
            if np.ptp(xb) == 0 or np.ptp(yb) == 0:
                continue
            rhos.append(np.corrcoef(stats.rankdata(xb), stats.rankdata(yb))[0, 1])
        lo, hi = np.percentile(rhos, [2.5, 97.5])
        sign = -1.0 if c == "coverage_5m" else 1.0
        top = lambda v: sorted(range(len(v)), key=lambda i: (-v[i], i))[:k]
        overlap = len(set(top(list(x))) & set(top(list(sign * y)))) / k
        rows.append({"offline": o, "closed_loop": c, "n": len(x), "rho": float(res.statistic),
                     "p": float(res.pvalue), "ci": [float(lo), float(hi)], "used": len(rhos),
                     "overlap": overlap})
q = stats.false_discovery_control([r["p"] for r in rows], method="bh")
for r, qv in zip(rows, q):
    r["q"] = float(qv)
print(json.dumps(rows))
"#;

#[test]
fn transfer_statistics_match_scipy_on_the_same_numbers() {
    let dir = std::env::temp_dir().join(format!("perturb-transfer-test-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    // 16 (perturbation, severity) pairs offline, 14 of them closed-loop, with ties (failure
    // rates are thirds), a missing CTE and a nominal row that must be left out.
    let ids = [
        "C-A1", "C-B1", "C-C7", "C-F5", "L-A9", "L-B1", "L-C1", "L-A4",
    ];
    let mut per = Vec::new();
    let mut csv = String::from(
        "perturbation,severity,runs,completion,failures,failure_rate,cte_avg,cte_max,jitter_avg,jitter_max,jitter_std,coverage_5m\n",
    );
    csv.push_str("nominal,-,3,1,ok;ok;ok,0,0.4,0.6,0.1,0.3,0.05,1\n");
    for (i, id) in ids.iter().enumerate() {
        for sev in [1u8, 3] {
            let k = (i * 2 + sev as usize) as f64;
            let mse = ((k * 7.3).sin() + 1.2) * (sev as f64);
            per.push(serde_json::json!({
                "id": id, "name": "x", "severity": sev, "frames": 40,
                "mse": mse, "max_abs_deviation": (k * 1.7).cos().abs() * 2.0,
                "jitter_baseline": 0.1, "jitter_perturbed": 0.2,
                "retention": 1.0 - ((k * 3.1).sin().abs() * 0.5), "ate": 0.2
            }));
            if i == 7 {
                continue; // L-A4: offline only
            }
            let failure_rate = ((k as usize * 5) % 4) as f64 / 3.0;
            let cte = if k == 5.0 {
                String::new()
            } else {
                format!("{}", 0.3 + 0.1 * ((k * 2.9).sin() + mse / 4.0))
            };
            csv.push_str(&format!(
                "{id},{sev},3,0.8,ok;C;ok,{failure_rate},{cte},2.0,{},0.5,0.1,{}\n",
                0.05 + 0.01 * (k * 1.3).cos() + mse / 50.0,
                1.0 - (k * 0.7).sin().abs() / 10.0
            ));
        }
    }
    let off_path = dir.join("offline.json");
    std::fs::write(
        &off_path,
        serde_json::to_string(&serde_json::json!({"per_severity": per, "per_perturbation": []}))
            .unwrap(),
    )
    .unwrap();
    let cl_path = dir.join("closed_loop.csv");
    std::fs::write(&cl_path, &csv).unwrap();

    let cfg = TransferConfig {
        offline_metrics: vec![
            "mse".into(),
            "max_abs_deviation".into(),
            "retention_loss".into(),
        ],
        closed_loop_metrics: vec![
            "failure_rate".into(),
            "cte_avg".into(),
            "jitter_avg".into(),
            "coverage_5m".into(),
        ],
        resamples: 1000,
        seed: 42,
        level: 0.95,
        top_k: 5,
    };
    let t = transfer(
        &read_table(&off_path).unwrap(),
        &read_table(&cl_path).unwrap(),
        &cfg,
    )
    .unwrap();
    assert_eq!(t.matched, 14);
    assert_eq!(t.rows.len(), 12);
    // The resamples Rust drew, for every n that occurs.
    let mut res: BTreeMap<String, Vec<Vec<usize>>> = BTreeMap::new();
    for r in &t.rows {
        res.entry(r.n.to_string()).or_insert_with(|| {
            (0..cfg.resamples)
                .map(|k| resample(r.n, k, cfg.seed).collect())
                .collect()
        });
    }
    let res_path = dir.join("resamples.json");
    std::fs::write(&res_path, serde_json::to_string(&res).unwrap()).unwrap();
    let Some(out) = python(
        "scipy, numpy",
        SCIPY,
        &[
            off_path.to_str().unwrap(),
            cl_path.to_str().unwrap(),
            res_path.to_str().unwrap(),
            "5",
        ],
    ) else {
        return;
    };
    let py: Vec<serde_json::Value> = serde_json::from_str(&out).unwrap();
    assert_eq!(py.len(), t.rows.len());
    let close = |a: f64, b: f64, what: &str| {
        assert!(
            (a - b).abs() <= 1e-9 * b.abs().max(1.0),
            "{what}: {a} vs scipy {b}"
        );
    };
    for (r, p) in t.rows.iter().zip(&py) {
        let what = format!("{} vs {}", r.offline, r.closed_loop);
        assert_eq!(r.offline, p["offline"].as_str().unwrap());
        assert_eq!(r.closed_loop, p["closed_loop"].as_str().unwrap());
        assert_eq!(r.n as u64, p["n"].as_u64().unwrap(), "{what}: n");
        close(
            r.rho.unwrap(),
            p["rho"].as_f64().unwrap(),
            &format!("{what}: rho"),
        );
        close(
            r.p.unwrap(),
            p["p"].as_f64().unwrap(),
            &format!("{what}: p"),
        );
        close(
            r.q.unwrap(),
            p["q"].as_f64().unwrap(),
            &format!("{what}: q"),
        );
        close(
            r.ci_low.unwrap(),
            p["ci"][0].as_f64().unwrap(),
            &format!("{what}: ci low"),
        );
        close(
            r.ci_high.unwrap(),
            p["ci"][1].as_f64().unwrap(),
            &format!("{what}: ci high"),
        );
        assert_eq!(
            r.resamples_used as u64,
            p["used"].as_u64().unwrap(),
            "{what}: resamples"
        );
        close(
            r.top_k_overlap.unwrap(),
            p["overlap"].as_f64().unwrap(),
            &format!("{what}: top-5 overlap"),
        );
        assert!(r.ci_low.unwrap() <= r.ci_high.unwrap());
    }
    // The two missing CTEs leave two pairs out of the CTE rows.
    assert!(
        t.rows
            .iter()
            .all(|r| (r.closed_loop == "cte_avg") == (r.n == 12))
    );
    // Same seed, same intervals; another seed, other intervals.
    let again = transfer(
        &read_table(&off_path).unwrap(),
        &read_table(&cl_path).unwrap(),
        &cfg,
    )
    .unwrap();
    assert_eq!(again, t);
    let other = transfer(
        &read_table(&off_path).unwrap(),
        &read_table(&cl_path).unwrap(),
        &TransferConfig {
            seed: 43,
            ..cfg.clone()
        },
    )
    .unwrap();
    assert_ne!(other.rows[0].ci_low, t.rows[0].ci_low);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn tables_without_common_pairs_or_metrics_are_refused_by_name() {
    let dir = std::env::temp_dir().join(format!("perturb-transfer-bad-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let a = dir.join("a.csv");
    std::fs::write(&a, "id,severity,mse\nC-A1,1,0.5\nC-A1,2,0.7\n").unwrap();
    let b = dir.join("b.csv");
    std::fs::write(&b, "perturbation,severity,failure_rate\nC-B1,1,0.5\n").unwrap();
    let cfg = TransferConfig::default();
    let e = transfer(&read_table(&a).unwrap(), &read_table(&b).unwrap(), &cfg).unwrap_err();
    assert!(
        e.to_string()
            .contains("no (perturbation, severity) pair in common"),
        "{e}"
    );
    let cfg = TransferConfig {
        closed_loop_metrics: vec!["crashes".into()],
        ..TransferConfig::default()
    };
    let e = transfer(&read_table(&a).unwrap(), &read_table(&a).unwrap(), &cfg).unwrap_err();
    assert!(
        e.to_string().contains("`crashes`") && e.to_string().contains("mse"),
        "{e}"
    );
    let c = dir.join("c.csv");
    std::fs::write(&c, "name,mse\nx,1\n").unwrap();
    let e = read_table(&c).unwrap_err().to_string();
    assert!(e.contains("c.csv") && e.contains("`id`"), "{e}");
    let _ = std::fs::remove_dir_all(&dir);
}

/// Before: with 2 pairs, rho 1.00 and CI [1.00, 1.00] without a word. Now a row over fewer than
/// 5 pairs has no interval and says why; from 5 pairs on the interval is estimated.
#[test]
fn fewer_than_five_pairs_give_no_interval_and_a_note() {
    let dir = std::env::temp_dir().join(format!("perturb-transfer-few-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let off = dir.join("off.csv");
    std::fs::write(
        &off,
        "id,severity,mse\nC-A1,1,0.1\nC-A1,2,0.3\nC-A1,3,0.5\nC-A1,4,0.6\nC-A1,5,0.9\n",
    )
    .unwrap();
    let two = dir.join("two.csv");
    std::fs::write(
        &two,
        "perturbation,severity,cte_avg\nC-A1,1,0.2\nC-A1,2,0.4\n",
    )
    .unwrap();
    let five = dir.join("five.csv");
    std::fs::write(
        &five,
        "perturbation,severity,cte_avg\nC-A1,1,0.2\nC-A1,2,0.4\nC-A1,3,0.3\nC-A1,4,0.8\nC-A1,5,0.9\n",
    )
    .unwrap();
    let cfg = TransferConfig {
        resamples: 500,
        ..TransferConfig::default()
    };
    let t = transfer(&read_table(&off).unwrap(), &read_table(&two).unwrap(), &cfg).unwrap();
    let r = &t.rows[0];
    assert_eq!((r.n, r.rho), (2, Some(1.0)));
    assert_eq!((r.ci_low, r.ci_high, r.p), (None, None, None));
    let note = r.note.as_deref().unwrap();
    assert!(
        note.contains("only 2 matched pairs") && note.contains("fewer than 5"),
        "{note}"
    );
    assert_eq!(r.points.len(), 2);
    let text = perturb_study::transfer::render(&t, perturb_study::Format::Table);
    assert!(
        text.contains("note: mse vs cte_avg: only 2 matched pairs"),
        "{text}"
    );
    let t = transfer(
        &read_table(&off).unwrap(),
        &read_table(&five).unwrap(),
        &cfg,
    )
    .unwrap();
    let r = &t.rows[0];
    assert_eq!(r.n, 5);
    assert!(
        r.ci_low.is_some() && r.ci_high.is_some() && r.note.is_none(),
        "{r:?}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}
