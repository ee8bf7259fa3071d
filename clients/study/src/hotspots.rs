//! Failure hotspots (paper, qualitative analysis): where on the route runs fail. The failure
//! point of a failing run is where the vehicle was when it failed (the trajectory's end); the
//! points are clustered with DBSCAN in the pose frame, separately per failure type so that
//! nearby but different failures (oversteer and understeer after the same turn) are not merged.
//! A failure in no cluster is noise (drawn faintly on the map).

use crate::analyze::{Failure, RunResult};
use crate::stats::dbscan;
use serde::Serialize;
use std::collections::BTreeMap;

/// One failure of one run.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct FailurePoint {
    /// The run.
    pub run: String,
    /// The condition active when it failed.
    pub perturbation: String,
    /// Its severity.
    pub severity: Option<u8>,
    /// The failure type.
    pub failure: Failure,
    /// Where, in the pose frame.
    pub position: [f64; 2],
    /// The hotspot it belongs to (index into [`Hotspots::clusters`]), None for noise.
    pub cluster: Option<usize>,
}

/// One hotspot.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Cluster {
    /// The failure type of its members.
    pub failure: Failure,
    /// Mean position.
    pub centre: [f64; 2],
    /// Members.
    pub size: usize,
    /// Largest distance of a member from the centre, metres.
    pub radius_m: f64,
    /// Member runs.
    pub runs: Vec<String>,
    /// Failures per perturbation ID, most first.
    pub perturbations: Vec<(String, usize)>,
    /// Failures per perturbation family (catalogue family, `nominal`, or `mixed`), most first.
    pub families: Vec<(String, usize)>,
}

/// The hotspots of a set of runs.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct Hotspots {
    /// DBSCAN radius, metres.
    pub eps_m: f64,
    /// DBSCAN minimum points.
    pub min_points: usize,
    /// Every failure point.
    pub failures: Vec<FailurePoint>,
    /// The clusters, by failure type then position along discovery.
    pub clusters: Vec<Cluster>,
}

/// The family of a condition label for maps and hotspots: the catalogue family of a single
/// perturbation, `nominal`, or `mixed` for combinations.
pub fn family_of(label: &str) -> String {
    if label == "nominal" {
        return "nominal".into();
    }
    match perturb_core::registry::find(label) {
        Ok(e) if e.id == label => format!("{} {}", e.modality, e.family),
        _ => "mixed".into(),
    }
}

fn counted(items: impl Iterator<Item = String>) -> Vec<(String, usize)> {
    let mut m: BTreeMap<String, usize> = BTreeMap::new();
    for i in items {
        *m.entry(i).or_default() += 1;
    }
    let mut v: Vec<(String, usize)> = m.into_iter().collect();
    v.sort_by(|a, b| b.1.cmp(&a.1).then(a.0.cmp(&b.0)));
    v
}

/// Clusters the failure points of `runs` per failure type.
pub fn hotspots(runs: &[RunResult], eps_m: f64, min_points: usize) -> Hotspots {
    let mut failures: Vec<FailurePoint> = runs
        .iter()
        .filter_map(|r| {
            let f = r.metrics.failure?;
            let pos = r.failure_position?;
            // The condition at the failure: the last segment's.
            let seg = r.segments.last();
            Some(FailurePoint {
                run: r.run.clone(),
                perturbation: seg.map_or(r.perturbation.clone(), |s| s.perturbation.clone()),
                severity: seg.map_or(r.severity, |s| s.severity),
                failure: f,
                position: pos,
                cluster: None,
            })
        })
        .collect();
    let mut types: Vec<Failure> = failures.iter().map(|f| f.failure).collect();
    types.sort();
    types.dedup();
    let mut clusters = Vec::new();
    for ty in types {
        let idx: Vec<usize> = (0..failures.len())
            .filter(|&i| failures[i].failure == ty)
            .collect();
        let pts: Vec<[f64; 2]> = idx.iter().map(|&i| failures[i].position).collect();
        let labels = dbscan(&pts, eps_m, min_points.max(1));
        let n = labels.iter().flatten().max().map_or(0, |m| m + 1);
        for k in 0..n {
            let members: Vec<usize> = idx
                .iter()
                .zip(&labels)
                .filter(|(_, l)| **l == Some(k))
                .map(|(i, _)| *i)
                .collect();
            let m = members.len() as f64;
            let centre = [
                members
                    .iter()
                    .map(|&i| failures[i].position[0])
                    .sum::<f64>()
                    / m,
                members
                    .iter()
                    .map(|&i| failures[i].position[1])
                    .sum::<f64>()
                    / m,
            ];
            let radius_m = members
                .iter()
                .map(|&i| {
                    let p = failures[i].position;
                    (p[0] - centre[0]).hypot(p[1] - centre[1])
                })
                .fold(0.0, f64::max);
            let id = clusters.len();
            for &i in &members {
                failures[i].cluster = Some(id);
            }
            clusters.push(Cluster {
                failure: ty,
                centre,
                size: members.len(),
                radius_m,
                runs: members.iter().map(|&i| failures[i].run.clone()).collect(),
                perturbations: counted(members.iter().map(|&i| failures[i].perturbation.clone())),
                families: counted(
                    members
                        .iter()
                        .map(|&i| family_of(&failures[i].perturbation)),
                ),
            });
        }
    }
    Hotspots {
        eps_m,
        min_points,
        failures,
        clusters,
    }
}

/// The hotspots as a table (one row per cluster, then one per noise failure).
pub fn render(h: &Hotspots, format: crate::Format) -> String {
    use crate::table::Table;
    if format == crate::Format::Json {
        return serde_json::to_string_pretty(h).expect("serialises") + "\n";
    }
    let mut t = Table::new(&[
        ("hotspot", true),
        ("failure", false),
        ("x", true),
        ("y", true),
        ("size", true),
        ("radius_m", true),
        ("perturbations", false),
        ("families", false),
    ]);
    let list = |v: &[(String, usize)]| {
        v.iter()
            .map(|(k, n)| format!("{k} x{n}"))
            .collect::<Vec<_>>()
            .join("; ")
    };
    for (i, c) in h.clusters.iter().enumerate() {
        t.push(vec![
            i.to_string(),
            c.failure.name().into(),
            format!("{:.1}", c.centre[0]),
            format!("{:.1}", c.centre[1]),
            c.size.to_string(),
            format!("{:.1}", c.radius_m),
            list(&c.perturbations),
            list(&c.families),
        ]);
    }
    for f in h.failures.iter().filter(|f| f.cluster.is_none()) {
        t.push(vec![
            "noise".into(),
            f.failure.name().into(),
            format!("{:.1}", f.position[0]),
            format!("{:.1}", f.position[1]),
            "1".into(),
            "0.0".into(),
            f.perturbation.clone(),
            family_of(&f.perturbation),
        ]);
    }
    t.render(format)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn dbscan_finds_two_clusters_and_noise() {
        let pts = [
            [0.0, 0.0],
            [1.0, 0.0],
            [0.5, 0.8],
            [20.0, 20.0],
            [21.0, 20.0],
            [50.0, 0.0],
        ];
        let l = dbscan(&pts, 1.5, 2);
        assert_eq!(l, vec![Some(0), Some(0), Some(0), Some(1), Some(1), None]);
        // With min_points 3, the pair is noise too.
        let l = dbscan(&pts, 1.5, 3);
        assert_eq!(l, vec![Some(0), Some(0), Some(0), None, None, None]);
    }
}
