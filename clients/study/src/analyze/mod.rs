//! The closed-loop analysis of recorded runs (paper, RQ3 and RQ4): completion, failure type,
//! cross-track error, steering jitter, near-field detection coverage and duration, per run, per
//! (perturbation, severity) segment of a run, per (perturbation, severity) and per perturbation.
//!
//! A run is a bag recorded while the vehicle (or the HiL replay) drove the route with `perturbd`
//! in the loop. Its `/perturb/events` channel says which perturbation and severity was active
//! for every frame; the run is split into segments of constant condition ("nominal" when no
//! perturbation was active). The pose, steering, objects, takeover and collision topics are
//! configured, and their messages are decoded by the schema stored in the bag, so any message
//! type works. The definitions (and the choices where the paper is silent) are in
//! `docs/study.md`; [`AnalyzeConfig`]'s fields carry the defaults.

mod aggregate;
mod events;
mod load;
mod metrics;
pub mod reference;
mod render;
mod trim;

pub use aggregate::{
    Aggregated, ConditionRow, PerturbationRow, aggregate, aggregate_conditions,
    aggregate_perturbations,
};
pub use events::{ExternalEvents, load_events_bags};
pub use load::{PoseSample, RunData, load_run};
pub use metrics::{RunTrack, WindowMetrics, analyze_run, jitter_stats, window_until};
pub use reference::ReferenceRegion;
pub use render::{
    outcome_letter, render_conditions, render_perturbations, render_runs, render_segments,
    render_summary,
};

use crate::error::StudyError;
use crate::route::Route;
use crate::source::{RunEntry, Skipped, find_runs};
use serde::Serialize;
use std::path::Path;
use std::sync::Arc;

/// A topic and, optionally, the path of the field to read in its messages.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct TopicField {
    /// Topic name.
    pub topic: String,
    /// Field path (None: the default for the topic's message type).
    pub field: Option<String>,
}

/// In which frame detected objects are given.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum ObjectsFrame {
    /// Relative to the vehicle (x forward, y left): distances are measured from the origin.
    #[default]
    Ego,
    /// In the pose frame (the map): distances are measured from the vehicle's position.
    Map,
}

/// The detected-objects topic and how to read positions from it.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ObjectsConfig {
    /// Topic name.
    pub topic: String,
    /// Path of the array of objects (None: by message type, e.g. `objects`, `detections`).
    pub array: Option<String>,
    /// Path of an object's position inside an element (None: by message type, e.g.
    /// `pose.position`, `bbox.center.position`); `.x` and `.y` are read below it.
    pub position: Option<String>,
    /// The frame of the positions.
    pub frame: ObjectsFrame,
}

/// How trajectory metrics are aggregated over runs.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Aggregate {
    /// Only runs (segments) that did not fail, as the paper's RQ3 table.
    #[default]
    NonFailing,
    /// Every run, failing ones over their part before the failure.
    All,
    /// Every run over the shared non-failing portion: the part of the route that every run of
    /// the row drove before failing (less the --cte-exclude metres before the earliest failure),
    /// the paper's RQ4 comparison; `analyze compare` only.
    Shared,
}

/// What the cross-track error is measured against.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum CteTo {
    /// The reference region of nominal drives when one is given (the paper's), the route
    /// otherwise.
    #[default]
    Region,
    /// The route polyline, even with a reference region.
    Route,
}

/// What the steering jitter is measured per.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum JitterUnit {
    /// Absolute change between consecutive steering commands (the paper's definition).
    #[default]
    Command,
    /// That change divided by the time between the commands (a rate per second).
    Second,
}

/// Everything `perturb analyze` needs to know.
#[derive(Clone, Debug)]
pub struct AnalyzeConfig {
    /// The reference route (None: no completion, CTE or departure, unless a reference region
    /// gives one).
    pub route: Option<Route>,
    /// The reference region of nominal drives (the paper's CTE); see [`reference`].
    pub reference: Option<ReferenceRegion>,
    /// What the CTE is measured against.
    pub cte_to: CteTo,
    /// Start each run where the vehicle first comes within the goal tolerance of the route's
    /// start and end it at the goal (on by default; only with a route).
    pub trim_to_route: bool,
    /// The pose topic (geometry_msgs/PoseStamped, nav_msgs/Odometry, ... ) and the path of its
    /// position (x and y are read below it; None: found by message type). Without it only the
    /// metrics that need no position are computed (duration, jitter, segments).
    pub pose: Option<TopicField>,
    /// The steering command and the path of the angle.
    pub steering: Option<TopicField>,
    /// Detected objects (near-field coverage).
    pub objects: Option<ObjectsConfig>,
    /// Known vehicles (x, y in the pose frame) that should be detected when within
    /// [`AnalyzeConfig::near_field_m`]; None: taken from the nominal segments' detections.
    pub vehicles: Option<Vec<[f64; 2]>>,
    /// Takeover/disengagement signal: a failure at the first message whose field is true (any
    /// message when the type has no default field and none is given).
    pub takeover: Option<TopicField>,
    /// Collision signal, same rule.
    pub collision: Option<TopicField>,
    /// With a value, the takeover signal fires at the first message whose field equals it
    /// (numbers compared as numbers) after a message where it did not: e.g. `0` for a drive
    /// mode that turns manual.
    pub takeover_value: Option<String>,
    /// The same for the collision signal.
    pub collision_value: Option<String>,
    /// The perturbation events channel.
    pub events_topic: String,
    /// Perturbation events recorded apart from the runs (by `perturb-bridge record` while the
    /// vehicle's topics went to `rosbag record`), matched to each run by log time; used for a
    /// run whose bag has no events topic.
    pub external_events: Option<Arc<ExternalEvents>>,
    /// Only events of these sensor topics decide the condition (all when empty).
    pub event_streams: Vec<String>,
    /// Lateral distance to the route beyond which the run has left its lane or the road, metres.
    pub cte_threshold: f64,
    /// Metres of trajectory before a failure excluded from CTE (the paper's d = 5 m); at least
    /// this plus 1 m of trajectory must remain, otherwise the CTE of a failing run is left out.
    pub cte_exclude_m: f64,
    /// Failing runs below this completion get no CTE.
    pub cte_min_completion: f64,
    /// A run that has not completed the route after this many seconds fails with `timeout`.
    pub timeout_s: Option<f64>,
    /// The route counts as completed within this distance of its end, metres.
    pub goal_tolerance_m: f64,
    /// Steering change between consecutive commands that counts as an oscillation (the paper's
    /// 0.3) for erratic starts.
    pub erratic_threshold: f64,
    /// A run that fails before getting this far along the route, after such an oscillation,
    /// fails with `erratic_start`, metres.
    pub erratic_distance_m: f64,
    /// A departure where the route's curvature is at least this (1/m) is a turn: `understeer`
    /// (off to the outside) or `oversteer` (to the inside); below it, `road_departure`.
    pub turn_curvature: f64,
    /// Half-length of the route window the curvature is measured over, metres.
    pub curvature_window_m: f64,
    /// Near-field radius of the detection coverage, metres (the paper's 5 m).
    pub near_field_m: f64,
    /// A known vehicle counts as detected when an object lies within this distance, metres.
    pub match_distance_m: f64,
    /// Segments shorter than this (seconds) are merged into the next one (a switch of camera and
    /// LiDAR perturbations a few frames apart is one switch).
    pub min_segment_s: f64,
    /// Which runs the per-perturbation trajectory metrics average.
    pub aggregate: Aggregate,
    /// What jitter is measured per.
    pub jitter_unit: JitterUnit,
}

impl Default for AnalyzeConfig {
    fn default() -> Self {
        AnalyzeConfig {
            route: None,
            reference: None,
            cte_to: CteTo::Region,
            trim_to_route: true,
            pose: None,
            steering: None,
            objects: None,
            vehicles: None,
            takeover: None,
            collision: None,
            takeover_value: None,
            collision_value: None,
            events_topic: perturb_bag::events::EVENTS_TOPIC.to_string(),
            external_events: None,
            event_streams: Vec::new(),
            cte_threshold: 2.0,
            cte_exclude_m: 5.0,
            cte_min_completion: 0.0,
            timeout_s: None,
            goal_tolerance_m: 3.0,
            erratic_threshold: 0.3,
            erratic_distance_m: 5.0,
            turn_curvature: 0.02,
            curvature_window_m: 5.0,
            near_field_m: 5.0,
            match_distance_m: 2.0,
            min_segment_s: 0.5,
            aggregate: Aggregate::NonFailing,
            jitter_unit: JitterUnit::Command,
        }
    }
}

/// Why a run failed.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Failure {
    /// Collision signal (C).
    Collision,
    /// Takeover or disengagement signal (T).
    Takeover,
    /// Left the lane to the outside of a turn (U).
    Understeer,
    /// Left the lane to the inside of a turn (O).
    Oversteer,
    /// Left the lane or road on a straight part (R).
    RoadDeparture,
    /// Steering oscillations right after the start and no progress (E).
    ErraticStart,
    /// Not at the end of the route after the timeout (X).
    Timeout,
    /// The recording ended before the end of the route, with no other failure (I).
    Incomplete,
}

impl Failure {
    /// The letter of the paper's tables (T, X and I are this project's additions).
    pub fn letter(self) -> &'static str {
        match self {
            Failure::Collision => "C",
            Failure::Takeover => "T",
            Failure::Understeer => "U",
            Failure::Oversteer => "O",
            Failure::RoadDeparture => "R",
            Failure::ErraticStart => "E",
            Failure::Timeout => "X",
            Failure::Incomplete => "I",
        }
    }

    /// The stable name (as in JSON).
    pub fn name(self) -> &'static str {
        match self {
            Failure::Collision => "collision",
            Failure::Takeover => "takeover",
            Failure::Understeer => "understeer",
            Failure::Oversteer => "oversteer",
            Failure::RoadDeparture => "road_departure",
            Failure::ErraticStart => "erratic_start",
            Failure::Timeout => "timeout",
            Failure::Incomplete => "incomplete",
        }
    }
}

/// The judgement of a run or segment.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Outcome {
    /// Judged and did not fail.
    Ok,
    /// Failed (the failure type says how).
    Failed,
    /// Whether it failed cannot be told (no route, no pose, never on the route); the reason is
    /// given beside it. Never counted as ok.
    #[default]
    Unjudged,
}

impl Outcome {
    /// The stable name (as in JSON).
    pub fn name(self) -> &'static str {
        match self {
            Outcome::Ok => "ok",
            Outcome::Failed => "failed",
            Outcome::Unjudged => "unjudged",
        }
    }
}

/// Which perturbations were active: empty for nominal, one (perturbation, severity) per stream
/// otherwise (sorted, duplicates removed); and the campaign steps that chose them (sorted, empty
/// when no campaign did).
#[derive(Clone, Debug, Default, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct Condition(pub Vec<(String, u8)>, pub Vec<u16>);

impl Condition {
    /// `nominal`, the perturbation ID, or IDs joined with `+`.
    pub fn label(&self) -> String {
        if self.0.is_empty() {
            return "nominal".into();
        }
        let mut ids: Vec<&str> = self.0.iter().map(|(i, _)| i.as_str()).collect();
        ids.dedup();
        ids.join("+")
    }

    /// The severity when one perturbation (at one severity) was active.
    pub fn severity(&self) -> Option<u8> {
        let mut s: Vec<u8> = self.0.iter().map(|(_, s)| *s).collect();
        s.dedup();
        (s.len() == 1).then(|| s[0])
    }

    /// True when nothing was active.
    pub fn is_nominal(&self) -> bool {
        self.0.is_empty()
    }

    /// The campaign step, when one step chose every active perturbation.
    pub fn step(&self) -> Option<u16> {
        match self.1.as_slice() {
            [s] => Some(*s),
            _ => None,
        }
    }
}

/// The metrics of a run or a segment. JSON field names are stable.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct Metrics {
    /// Ok, failed, or unjudged.
    pub outcome: Outcome,
    /// Why it is unjudged.
    pub unjudged_reason: Option<String>,
    /// Share of the route length reached before the run (segment) ended or failed, 0..1 (None
    /// without a route).
    pub completion: Option<f64>,
    /// Why it failed (None: it did not).
    pub failure: Option<Failure>,
    /// Mean absolute cross-track error over the valid part, metres.
    pub cte_avg: Option<f64>,
    /// Largest absolute cross-track error over the valid part, metres.
    pub cte_max: Option<f64>,
    /// Mean absolute steering change between consecutive commands.
    pub jitter_avg: Option<f64>,
    /// Largest absolute steering change.
    pub jitter_max: Option<f64>,
    /// Standard deviation of the absolute steering changes (population).
    pub jitter_std: Option<f64>,
    /// Share of (objects message, known vehicle within the near field) pairs with the vehicle
    /// detected.
    pub coverage_5m: Option<f64>,
    /// Seconds from the start to the end or the failure.
    pub duration_s: f64,
}

/// One segment of constant condition within a run.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct SegmentResult {
    /// The run's name.
    pub run: String,
    /// The run's group (sub-folder), if any.
    pub group: Option<String>,
    /// `nominal`, the perturbation ID, or IDs joined with `+`.
    pub perturbation: String,
    /// The severity, when one perturbation at one severity was active.
    pub severity: Option<u8>,
    /// The campaign step that chose the segment's perturbation (1-based), when one did.
    pub step: Option<u16>,
    /// Seconds from the run's start to the segment's start.
    pub start_s: f64,
    /// Seconds from the run's start to the segment's end (or failure).
    pub end_s: f64,
    /// Share of the route reached when the segment began.
    pub route_start: Option<f64>,
    /// The metrics over the segment.
    #[serde(flatten)]
    pub metrics: Metrics,
    #[serde(skip)]
    /// The condition.
    pub condition: Condition,
}

/// One analysed run.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct RunResult {
    /// The run's name (its file or folder name; `group/name` for runs in a sub-folder).
    pub run: String,
    /// The run's group (sub-folder), if any.
    pub group: Option<String>,
    /// The condition if it was the same through the run, `mixed` otherwise.
    pub perturbation: String,
    /// The severity when one perturbation at one severity was active through the run.
    pub severity: Option<u8>,
    /// The metrics over the whole run.
    #[serde(flatten)]
    pub metrics: Metrics,
    /// Seconds from the start to the failure.
    pub failure_time_s: Option<f64>,
    /// Where the vehicle was when it failed (pose frame).
    pub failure_position: Option<[f64; 2]>,
    /// Where the analysed part lies in the recording, seconds from its first message (start,
    /// end), when it was trimmed to the route.
    pub trimmed: Option<[f64; 2]>,
    /// Remarks (messages that did not decode, missing topics that were optional, ...).
    pub notes: Vec<String>,
    /// The segments of constant condition.
    #[serde(skip)]
    pub segments: Vec<SegmentResult>,
    /// The driven trajectory (pose frame) with the condition active at each sample, for maps.
    #[serde(skip)]
    pub trajectory: Vec<([f64; 2], Condition)>,
    /// Per pose: time, route progress and CTE; the steering commands (for the shared-portion
    /// comparison).
    #[serde(skip)]
    pub track: RunTrack,
}

/// A run that could not be analysed.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct RunError {
    /// The run's name.
    pub run: String,
    /// Why.
    pub error: String,
}

/// How many runs were analysed, and how they came out.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct Summary {
    /// Runs analysed.
    pub runs: usize,
    /// Judged and did not fail.
    pub ok: usize,
    /// Failed.
    pub failed: usize,
    /// Not judged, counted apart (never as ok).
    pub unjudged: usize,
    /// The reasons of the unjudged runs, with their counts.
    pub unjudged_reasons: Vec<(String, usize)>,
    /// Runs that could not be read or analysed.
    pub errors: usize,
    /// Files and folders in the runs folder that are not runs.
    pub skipped: usize,
    /// The failure checks that ran (e.g. `departure`, `collision`): a failure of another kind
    /// cannot have been seen.
    pub checks: Vec<String>,
    /// What the CTE was measured against: `reference region (N nominal drives)`, `route` or
    /// `none`.
    pub cte_reference: String,
}

/// Everything `perturb analyze` computed.
#[derive(Clone, Debug, Default, Serialize)]
pub struct Analysis {
    /// Counts of ok, failed and unjudged runs, errors and skipped files; the checks that ran.
    pub summary: Summary,
    /// One row per run.
    pub runs: Vec<RunResult>,
    /// One row per segment of constant condition (a run without switches has one).
    pub segments: Vec<SegmentResult>,
    /// One row per (perturbation, severity).
    pub conditions: Vec<ConditionRow>,
    /// One row per perturbation (the paper's table), nominal first.
    pub perturbations: Vec<PerturbationRow>,
    /// Runs that could not be analysed.
    pub errors: Vec<RunError>,
    /// Files and folders of the runs folder that are not runs.
    pub skipped: Vec<Skipped>,
    /// The route the runs were judged against (given, or the centre line of the reference
    /// drives), for maps.
    #[serde(skip)]
    pub route: Option<Route>,
    /// The reference region, for maps.
    #[serde(skip)]
    pub reference: Option<ReferenceRegion>,
}

/// Analyses every run in `runs_dir` (see [`find_runs`]); a run that cannot be analysed is
/// reported in [`Analysis::errors`] and the others are still analysed. Runs are read in
/// parallel on the current rayon pool.
pub fn analyze_dir(runs_dir: &Path, cfg: &AnalyzeConfig) -> crate::Result<Analysis> {
    let found = find_runs(runs_dir)?;
    let mut a = analyze_entries(&found.runs, cfg);
    a.skipped = found.skipped;
    a.summary.skipped = a.skipped.len();
    Ok(a)
}

/// Analyses the given runs (see [`analyze_dir`]).
pub fn analyze_entries(runs: &[RunEntry], cfg: &AnalyzeConfig) -> Analysis {
    use rayon::prelude::*;
    let loaded: Vec<Result<RunData, StudyError>> =
        runs.par_iter().map(|r| load_run(r, cfg)).collect();
    let mut data = Vec::new();
    let mut errors = Vec::new();
    for (entry, r) in runs.iter().zip(loaded) {
        match r {
            Ok(d) => data.push(d),
            Err(e) => errors.push(RunError {
                run: entry.name.clone(),
                error: e.to_string(),
            }),
        }
    }
    let vehicles = match (&cfg.vehicles, &cfg.objects) {
        (Some(v), _) => Some(v.clone()),
        (None, Some(_)) => metrics::vehicles_from_nominal(&data, cfg),
        (None, None) => None,
    };
    let results: Vec<RunResult> = data
        .par_iter()
        .map(|d| analyze_run(d, cfg, vehicles.as_deref()))
        .collect();
    let segments: Vec<SegmentResult> = results
        .iter()
        .flat_map(|r| r.segments.iter().cloned())
        .collect();
    let conditions = aggregate_conditions(&segments, cfg.aggregate);
    let perturbations = aggregate_perturbations(&segments, cfg.aggregate);
    let summary = summarize(&results, errors.len(), cfg);
    Analysis {
        summary,
        runs: results,
        segments,
        conditions,
        perturbations,
        errors,
        skipped: Vec::new(),
        route: cfg.route.clone(),
        reference: cfg.reference.clone(),
    }
}

/// The failure checks a configuration runs.
pub fn checks(cfg: &AnalyzeConfig) -> Vec<String> {
    let mut v = Vec::new();
    if cfg.route.is_some() && cfg.pose.is_some() {
        v.extend(["departure", "erratic_start", "incomplete"].map(String::from));
        if cfg.timeout_s.is_some() {
            v.push("timeout".into());
        }
    }
    if cfg.collision.is_some() {
        v.push("collision".into());
    }
    if cfg.takeover.is_some() {
        v.push("takeover".into());
    }
    v
}

fn summarize(runs: &[RunResult], errors: usize, cfg: &AnalyzeConfig) -> Summary {
    let count = |o: Outcome| runs.iter().filter(|r| r.metrics.outcome == o).count();
    let mut reasons: Vec<(String, usize)> = Vec::new();
    for r in runs {
        if let Some(why) = &r.metrics.unjudged_reason {
            match reasons.iter_mut().find(|(w, _)| w == why) {
                Some(e) => e.1 += 1,
                None => reasons.push((why.clone(), 1)),
            }
        }
    }
    let cte_reference = match (&cfg.reference, cfg.cte_to, &cfg.route) {
        (Some(r), CteTo::Region, _) => format!(
            "reference region ({} nominal drive{})",
            r.runs.len(),
            if r.runs.len() == 1 { "" } else { "s" }
        ),
        (_, _, Some(_)) => "route".into(),
        _ => "none".into(),
    };
    Summary {
        runs: runs.len(),
        ok: count(Outcome::Ok),
        failed: count(Outcome::Failed),
        unjudged: count(Outcome::Unjudged),
        unjudged_reasons: reasons,
        errors,
        skipped: 0,
        checks: checks(cfg),
        cte_reference,
    }
}

/// The route and reference region built from nominal drives (see [`reference`]).
#[derive(Clone, Debug)]
pub struct ReferenceSet {
    /// The route: the one given, or the centre line of the drives.
    pub route: Route,
    /// True when the route is the drives' centre line.
    pub derived_route: bool,
    /// The band the drives span.
    pub region: ReferenceRegion,
    /// Remarks (drives left out, parts that were not nominal).
    pub notes: Vec<String>,
}

/// Builds the paper's reference region from the nominal drives in `dir` (read with `cfg`'s pose
/// topic; `cfg.route` is the route, or None to take the drives' centre line), every `bin_m`
/// metres. A drive's perturbed parts are left out (only nominal driving spans the region); each
/// drive is trimmed to the route like a run when `cfg.trim_to_route`.
pub fn reference_from_runs(
    dir: &Path,
    cfg: &AnalyzeConfig,
    bin_m: f64,
) -> crate::Result<ReferenceSet> {
    if cfg.pose.is_none() {
        return Err(StudyError::Config(
            "reference runs need a pose topic (--pose-topic)".into(),
        ));
    }
    let found = find_runs(dir)?;
    let read_cfg = AnalyzeConfig {
        route: None,
        steering: None,
        objects: None,
        takeover: None,
        collision: None,
        ..cfg.clone()
    };
    let mut notes = Vec::new();
    let mut drives: Vec<(String, Vec<load::PoseSample>)> = Vec::new();
    for entry in &found.runs {
        let d = load_run(entry, &read_cfg).map_err(|e| StudyError::Run {
            run: format!("reference {}", entry.name),
            reason: e.to_string(),
        })?;
        let segs = metrics::segments(&d, cfg.min_segment_s);
        let nominal = |t: f64| {
            segs.iter()
                .any(|(a, b, c)| c.is_nominal() && t >= *a && t <= *b)
        };
        let poses: Vec<load::PoseSample> =
            d.poses.iter().copied().filter(|p| nominal(p.t)).collect();
        if poses.len() < d.poses.len() {
            notes.push(format!(
                "reference drive `{}`: {} of {} poses under a perturbation left out",
                entry.name,
                d.poses.len() - poses.len(),
                d.poses.len()
            ));
        }
        if poses.len() < 2 {
            notes.push(format!(
                "reference drive `{}` has no nominal driving: not used",
                entry.name
            ));
            continue;
        }
        drives.push((entry.name.clone(), poses));
    }
    let xy = |drives: &[(String, Vec<load::PoseSample>)]| -> Vec<(String, Vec<[f64; 2]>)> {
        drives
            .iter()
            .map(|(n, p)| (n.clone(), reference::positions(p)))
            .collect()
    };
    let (route, derived_route) = match &cfg.route {
        Some(r) => (r.clone(), false),
        None => (
            reference::centre_line(&xy(&drives), bin_m).ok_or_else(|| {
                StudyError::input(dir, "holds no nominal drive to take a centre line from")
            })?,
            true,
        ),
    };
    if cfg.trim_to_route {
        for (name, poses) in &mut drives {
            let d = RunData {
                end: poses.last().map_or(0.0, |p| p.t),
                poses: poses.clone(),
                ..RunData::default()
            };
            match trim::window(&d, &route, cfg.goal_tolerance_m, cfg.cte_threshold) {
                trim::Window::On { start, end, .. } => {
                    poses.retain(|p| p.t >= start && p.t <= end);
                }
                trim::Window::Off(why) => {
                    notes.push(format!("reference drive `{name}`: {why}; not used"));
                    poses.clear();
                }
            }
        }
        drives.retain(|(_, p)| !p.is_empty());
    }
    let region = ReferenceRegion::build(&route, &xy(&drives), bin_m)
        .ok_or_else(|| StudyError::input(dir, "holds no usable nominal drive"))?;
    Ok(ReferenceSet {
        route,
        derived_route,
        region,
        notes,
    })
}
