//! The study's metrics (paper, section RQ1), as pure functions.
//!
//! LiDAR: the **retention rate** is the share of baseline detections (boxes found on the clean cloud)
//! that are still detected on the perturbed cloud; the **average translation error** (ATE) is the
//! mean distance between the centres of matched boxes. Matching is greedy by increasing centre
//! distance in the ground plane (x, y), one-to-one, within [`MatchConfig::max_center_distance`]
//! (2 m by default, nuScenes' middle threshold; the paper does not state its own).
//!
//! Camera: per-frame steering predictions on the perturbed set are compared with the baseline
//! predictions: **MSE**, **maximum absolute deviation**, and the **steering jitter** (mean absolute
//! change between consecutive commands) of both.
//!
//! Aggregation over severities follows the paper: average and minimum retention, maximum ATE;
//! average and maximum MSE, maximum deviation.
//!
//! ```
//! use perturb_core::lidar::Box3;
//! use perturb_core::metrics::{detection_metrics, MatchConfig};
//! let b = |x: f32| Box3 { center: [x, 0.0, 0.0], size: [4.0, 2.0, 1.5], yaw: 0.0 };
//! let m = detection_metrics(&[b(10.0), b(20.0)], &[b(10.5)], &MatchConfig::default());
//! assert_eq!(m.retained, 1);
//! assert!((m.retention - 0.5).abs() < 1e-12);
//! assert!((m.ate.unwrap() - 0.5).abs() < 1e-6);
//! ```

use crate::error::{Error, Result};
use crate::lidar::Box3;

/// How boxes are matched.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MatchConfig {
    /// Largest ground-plane centre distance of a match, in metres.
    pub max_center_distance: f32,
}

impl Default for MatchConfig {
    fn default() -> Self {
        MatchConfig {
            max_center_distance: 2.0,
        }
    }
}

/// Detection metrics of one perturbed cloud (or summed over a dataset, see [`DetectionMetrics::add`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
pub struct DetectionMetrics {
    /// Baseline detections.
    pub baseline: usize,
    /// Baseline detections matched on the perturbed cloud.
    pub retained: usize,
    /// retained / baseline (1 when there is no baseline detection).
    pub retention: f64,
    /// Sum of the matched centre distances (for pooling over frames).
    pub translation_sum: f64,
    /// Mean centre distance of the matches, if any.
    pub ate: Option<f64>,
}

impl DetectionMetrics {
    /// Pools another frame's counts into this one.
    pub fn add(&mut self, other: &DetectionMetrics) {
        self.baseline += other.baseline;
        self.retained += other.retained;
        self.translation_sum += other.translation_sum;
        self.retention = if self.baseline == 0 {
            1.0
        } else {
            self.retained as f64 / self.baseline as f64
        };
        self.ate = (self.retained > 0).then(|| self.translation_sum / self.retained as f64);
    }
}

fn ground_distance(a: &Box3, b: &Box3) -> f32 {
    ((a.center[0] - b.center[0]).powi(2) + (a.center[1] - b.center[1]).powi(2)).sqrt()
}

/// Matches `perturbed` boxes to `baseline` boxes (greedy by increasing centre distance,
/// one-to-one) and returns the retention and translation error.
pub fn detection_metrics(
    baseline: &[Box3],
    perturbed: &[Box3],
    cfg: &MatchConfig,
) -> DetectionMetrics {
    let mut pairs: Vec<(f32, usize, usize)> = Vec::new();
    for (i, b) in baseline.iter().enumerate() {
        for (j, p) in perturbed.iter().enumerate() {
            let d = ground_distance(b, p);
            if d <= cfg.max_center_distance {
                pairs.push((d, i, j));
            }
        }
    }
    pairs.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)).then(a.2.cmp(&b.2)));
    let (mut used_b, mut used_p) = (vec![false; baseline.len()], vec![false; perturbed.len()]);
    let mut m = DetectionMetrics {
        baseline: baseline.len(),
        ..Default::default()
    };
    for (d, i, j) in pairs {
        if !used_b[i] && !used_p[j] {
            used_b[i] = true;
            used_p[j] = true;
            m.retained += 1;
            m.translation_sum += d as f64;
        }
    }
    m.retention = if m.baseline == 0 {
        1.0
    } else {
        m.retained as f64 / m.baseline as f64
    };
    m.ate = (m.retained > 0).then(|| m.translation_sum / m.retained as f64);
    m
}

/// Steering metrics of one perturbed set against the baseline.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
pub struct SteeringMetrics {
    /// Frames compared.
    pub frames: usize,
    /// Mean squared difference to the baseline prediction.
    pub mse: f64,
    /// Largest absolute difference to the baseline prediction.
    pub max_abs_deviation: f64,
    /// Mean absolute change between consecutive baseline commands.
    pub jitter_baseline: f64,
    /// Mean absolute change between consecutive perturbed commands.
    pub jitter_perturbed: f64,
}

fn jitter(v: &[f64]) -> f64 {
    if v.len() < 2 {
        return 0.0;
    }
    v.windows(2).map(|w| (w[1] - w[0]).abs()).sum::<f64>() / (v.len() - 1) as f64
}

/// Compares predictions frame by frame. Both lists are `(frame, value)`; frames are matched by
/// key, in the baseline's order. Every baseline frame must have a perturbed prediction.
pub fn steering_metrics(
    baseline: &[(String, f64)],
    perturbed: &[(String, f64)],
) -> Result<SteeringMetrics> {
    let index: std::collections::HashMap<&str, f64> =
        perturbed.iter().map(|(k, v)| (k.as_str(), *v)).collect();
    let mut b = Vec::with_capacity(baseline.len());
    let mut p = Vec::with_capacity(baseline.len());
    for (k, v) in baseline {
        let q = index.get(k.as_str()).ok_or_else(|| Error::InvalidConfig {
            reason: format!("frame `{k}` has a baseline prediction but no perturbed one"),
        })?;
        b.push(*v);
        p.push(*q);
    }
    if b.is_empty() {
        return Err(Error::InvalidConfig {
            reason: "no frames to compare".into(),
        });
    }
    let n = b.len() as f64;
    let diffs: Vec<f64> = b.iter().zip(&p).map(|(x, y)| y - x).collect();
    Ok(SteeringMetrics {
        frames: b.len(),
        mse: diffs.iter().map(|d| d * d).sum::<f64>() / n,
        max_abs_deviation: diffs.iter().fold(0.0, |m, d| m.max(d.abs())),
        jitter_baseline: jitter(&b),
        jitter_perturbed: jitter(&p),
    })
}

/// LiDAR metrics of one perturbation over its severities.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct LidarSummary {
    /// Mean retention over the severities.
    pub avg_retention: f64,
    /// Lowest retention over the severities.
    pub min_retention: f64,
    /// Highest ATE over the severities (None if nothing matched at any severity).
    pub max_ate: Option<f64>,
}

/// Aggregates per-severity detection metrics as the paper does.
pub fn summarize_lidar(per_severity: &[DetectionMetrics]) -> LidarSummary {
    let n = per_severity.len().max(1) as f64;
    LidarSummary {
        avg_retention: per_severity.iter().map(|m| m.retention).sum::<f64>() / n,
        min_retention: per_severity
            .iter()
            .map(|m| m.retention)
            .fold(f64::INFINITY, f64::min)
            .min(1.0),
        max_ate: per_severity.iter().filter_map(|m| m.ate).reduce(f64::max),
    }
}

/// Camera metrics of one perturbation over its severities.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct CameraSummary {
    /// Mean MSE over the severities.
    pub avg_mse: f64,
    /// Highest MSE over the severities.
    pub max_mse: f64,
    /// Highest absolute deviation over the severities.
    pub max_abs_deviation: f64,
}

/// Aggregates per-severity steering metrics as the paper does.
pub fn summarize_camera(per_severity: &[SteeringMetrics]) -> CameraSummary {
    let n = per_severity.len().max(1) as f64;
    CameraSummary {
        avg_mse: per_severity.iter().map(|m| m.mse).sum::<f64>() / n,
        max_mse: per_severity.iter().map(|m| m.mse).fold(0.0, f64::max),
        max_abs_deviation: per_severity
            .iter()
            .map(|m| m.max_abs_deviation)
            .fold(0.0, f64::max),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn b(x: f32, y: f32) -> Box3 {
        Box3 {
            center: [x, y, -1.0],
            size: [4.0, 1.8, 1.5],
            yaw: 0.3,
        }
    }

    #[test]
    fn known_offsets_give_known_ate() {
        // Three cars moved by 0.3, 0.4 and 0.5 m; a fourth lost; a false positive far away.
        let base = [b(10.0, 0.0), b(20.0, 3.0), b(30.0, -3.0), b(40.0, 0.0)];
        let pert = [b(10.3, 0.0), b(20.0, 3.4), b(30.3, -3.4), b(80.0, 0.0)];
        let m = detection_metrics(&base, &pert, &MatchConfig::default());
        assert_eq!((m.baseline, m.retained), (4, 3));
        assert!((m.retention - 0.75).abs() < 1e-12);
        assert!((m.ate.unwrap() - 0.4).abs() < 1e-6, "{:?}", m.ate);
    }

    #[test]
    fn matching_is_one_to_one_and_nearest_first() {
        let base = [b(10.0, 0.0), b(11.0, 0.0)];
        let pert = [b(10.9, 0.0)];
        let m = detection_metrics(&base, &pert, &MatchConfig::default());
        assert_eq!(m.retained, 1);
        assert!(
            (m.ate.unwrap() - 0.1).abs() < 1e-5,
            "the nearer baseline box wins"
        );
        let none = detection_metrics(&[], &pert, &MatchConfig::default());
        assert_eq!(none.retention, 1.0);
        assert_eq!(none.ate, None);
    }

    #[test]
    fn pooling_and_summaries() {
        let mut total = DetectionMetrics::default();
        total.add(&detection_metrics(
            &[b(0.0, 0.0)],
            &[b(1.0, 0.0)],
            &MatchConfig::default(),
        ));
        total.add(&detection_metrics(
            &[b(0.0, 0.0)],
            &[],
            &MatchConfig::default(),
        ));
        assert_eq!((total.baseline, total.retained), (2, 1));
        assert!((total.retention - 0.5).abs() < 1e-12);
        let s = summarize_lidar(&[
            total,
            detection_metrics(&[b(0.0, 0.0)], &[b(0.0, 0.0)], &MatchConfig::default()),
        ]);
        assert!((s.avg_retention - 0.75).abs() < 1e-12);
        assert_eq!(s.min_retention, 0.5);
        assert!((s.max_ate.unwrap() - 1.0).abs() < 1e-6);
    }

    #[test]
    fn steering_hand_computed() {
        let base: Vec<(String, f64)> = [0.0, 0.1, 0.2, 0.1]
            .iter()
            .enumerate()
            .map(|(i, v)| (i.to_string(), *v))
            .collect();
        let pert: Vec<(String, f64)> = [0.1, 0.1, -0.1, 0.1]
            .iter()
            .enumerate()
            .map(|(i, v)| (i.to_string(), *v))
            .collect();
        let m = steering_metrics(&base, &pert).unwrap();
        // diffs 0.1, 0, -0.3, 0 -> mse (0.01 + 0.09) / 4 = 0.025
        assert!((m.mse - 0.025).abs() < 1e-12);
        assert!((m.max_abs_deviation - 0.3).abs() < 1e-12);
        assert!((m.jitter_baseline - 0.1).abs() < 1e-12);
        assert!((m.jitter_perturbed - (0.0 + 0.2 + 0.2) / 3.0).abs() < 1e-12);
        let err = steering_metrics(&base, &pert[..2]).unwrap_err();
        assert!(err.to_string().contains("frame `2`"), "{err}");
        let s = summarize_camera(&[
            m,
            SteeringMetrics {
                mse: 0.075,
                max_abs_deviation: 0.1,
                ..m
            },
        ]);
        assert!((s.avg_mse - 0.05).abs() < 1e-12 && s.max_mse == 0.075);
        assert!((s.max_abs_deviation - 0.3).abs() < 1e-12);
    }
}
