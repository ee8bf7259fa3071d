//! `perturb analyze`: the closed-loop half of the study from recorded runs; `perturb analyze
//! transfer` (offline vs closed-loop) and `perturb analyze compare` (fine-tuned vs baseline).

use anyhow::{Context, Result, bail};
use perturb_study::Format;
use perturb_study::analyze::{
    Aggregate, AnalyzeConfig, CteTo, JitterUnit, ObjectsConfig, ObjectsFrame, TopicField,
    render_conditions, render_perturbations, render_runs, render_segments, render_summary,
};
use std::path::{Path, PathBuf};

/// Arguments of `perturb analyze`.
#[derive(clap::Args)]
#[command(
    args_conflicts_with_subcommands = true,
    subcommand_negates_reqs = true,
    after_help = "Reads every run in RUNS_DIR and one folder down: each bag file (.mcap, .bag, .bag.active) and
each rosbag2 folder (metadata.yaml, or only NAME_N.mcap files) is one run, never merged with
another; every other sub-folder is a group (e.g. a weather condition) whose bags are runs named
group/name. Other files are listed as skipped. Each run's /perturb/events channel (or, with
--events-bags, the events recorded apart by perturb-bridge record, matched by time) says which
perturbation and severity was active; a run whose condition changes is split into segments
(\"nominal\" = no perturbation). Topics are decoded by the schema stored in the bag, so any
message type works; fields are paths like pose.pose.position or drive.steering_angle. How to
record a run on the vehicle: docs/recording.md.

With a route, each run is trimmed to it (--trim-to-route): it starts where the vehicle first
comes within --goal-tolerance of the route's start and ends at the goal. A run whose failure
cannot be judged (no route, no pose, never on the route) is `unjudged` with the reason, never
`ok`; failure rates count judged runs only.

Per run, per segment, per (perturbation, severity) and per perturbation (the paper's RQ3 table):
  completion   share of the route length reached before the end or the failure (needs --route)
  failure      collision, takeover (signals), understeer / oversteer / road_departure (CTE over
               --cte-threshold, by the route's curvature there), erratic_start (an oscillation
               over --erratic-threshold before --erratic-distance m), timeout, incomplete
  cte_avg/max  |lateral distance| to the reference region of --reference-runs (the paper's: the
               band N nominal drives span per arc length; 0 inside it), or to the route; a
               failing run leaves out its last --cte-exclude m
  jitter_*     mean, max, std of |change between consecutive steering commands|
  coverage_5m  share of (objects message, known vehicle within --near-field m) pairs detected
  duration_s   seconds to the end or the failure
Per perturbation, trajectory metrics average the non-failing runs (--aggregate all: every run).
Definitions and choices: docs/study.md. A run that cannot be analysed is reported on stderr with
its name and the topic or field at fault, the others are still analysed, and the exit status is 1.

Examples:
  perturb analyze runs/ --route route.csv --pose-topic /localization/odometry \\
      --steering-topic /control/command --steering-field drive.steering_angle --out study/
  perturb analyze runs/ --route route.csv --pose-topic /pose --objects-topic /detection/objects \\
      --vehicles parked_cars.csv --collision-topic /safety/collision --json > closed_loop.json
  perturb analyze transfer --offline lidar_metrics.json --closed-loop closed_loop.json
  perturb analyze compare --set fine-tuned=ft_runs/ --set baseline=base_runs/ --route route.csv \\
      --pose-topic /pose --steering-topic /cmd"
)]
pub struct Args {
    #[command(subcommand)]
    command: Option<Command>,
    /// Folder of recorded runs (or one bag).
    #[arg(value_name = "RUNS_DIR", required = true)]
    runs: Option<PathBuf>,
    #[command(flatten)]
    run: RunArgs,
    /// Write every table (markdown and CSV), analysis.json, hotspots and map.svg into this folder.
    #[arg(long)]
    out: Option<PathBuf>,
    /// Print the whole analysis as JSON (runs, segments, conditions, perturbations, hotspots,
    /// errors) instead of tables.
    #[arg(long)]
    json: bool,
    /// Format of the tables printed.
    #[arg(long, value_enum, default_value_t = Format::Table)]
    format: Format,
    /// Tables to print (repeatable; default: runs, conditions, perturbations, hotspots).
    #[arg(long, value_enum)]
    table: Vec<TableKind>,
    /// Hotspots: DBSCAN radius in metres.
    #[arg(long, default_value_t = 10.0)]
    eps: f64,
    /// Hotspots: failures within --eps that make a hotspot (the failure itself included).
    #[arg(long, default_value_t = 2)]
    min_points: usize,
    /// Write the trajectory map here, as SVG (default OUT/map.svg with --out).
    #[arg(long)]
    map: Option<PathBuf>,
    /// Width of the map in pixels.
    #[arg(long, default_value_t = 1200)]
    map_width: u32,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
enum TableKind {
    Runs,
    Segments,
    Conditions,
    Perturbations,
    Hotspots,
}

#[derive(clap::Subcommand)]
enum Command {
    /// Transfer analysis: Spearman's rho between offline and closed-loop metrics, bootstrap CIs,
    /// Benjamini-Hochberg q-values, top-k overlap.
    #[command(
        after_help = "Tables: the JSON of `perturb metrics steering|lidar --format json` or of
`perturb analyze --json` (or OUT/analysis.json), or a CSV with `id` (or `perturbation`),
`severity` and metric columns. Rows are matched by (perturbation, severity); nominal rows are
left out. `retention` also gives `retention_loss` = 1 - retention.

For each (offline metric, closed-loop metric): n matched pairs, Spearman's rho (ties get
average ranks), its two-sided p-value (t with n - 2 degrees of freedom, as scipy.stats.spearmanr),
a percentile bootstrap CI (pairs resampled with replacement --resamples times from --seed;
resamples with a constant side are skipped), the Benjamini-Hochberg q-value across all tested
metric pairs, and the overlap of the top --top-k pairs of the two rankings (larger is worse,
except retention, completion and coverage_5m).

Defaults: offline mse, max_abs_deviation, retention_loss, ate; closed-loop failure_rate,
cte_avg, jitter_avg, coverage_5m, completion (those present in the tables). A metric pair over
fewer than 5 matched pairs gets no confidence interval and a note saying so. With --latency
BENCH only the pairs within their latency budget are matched (the paper's feasible pairs)."
    )]
    Transfer(TransferArgs),
    /// Fine-tuned vs baseline (RQ4): two or more sets of runs per condition in one table.
    #[command(
        after_help = "Each --set NAME=DIR is a folder of runs; a run's condition is the sub-folder
it is in (DIR/mud/run1.mcap: `mud`), or the perturbation active through it for runs directly in
DIR. Per (condition, set): completion and failure type of every run; CTE and jitter of every run
over the condition's shared non-failing portion (the paper's RQ4): the route up to where the
condition's earliest failure happened (over every set), less --cte-exclude metres, the whole
route when no run failed (column shared_until_m). --aggregate all: each run up to its own
failure; --aggregate non-failing: only the runs that did not fail.

Example:
  perturb analyze compare --set FT=ft/ --set Non-FT=baseline/ --route route.csv \\
      --pose-topic /odom --steering-topic /cmd --format markdown"
    )]
    Compare(Box<CompareArgs>),
}

/// How runs are read and judged (shared by `analyze` and `analyze compare`).
#[derive(clap::Args)]
struct RunArgs {
    /// Reference route: a CSV with columns x,y in the pose frame (default with --reference-runs:
    /// the centre line of the nominal drives).
    #[arg(long)]
    route: Option<PathBuf>,
    /// Nominal drives of the route (a folder of runs) whose per-arc-length band is the reference
    /// region the CTE is measured against (the paper's RQ3 uses three).
    #[arg(long, value_name = "DIR")]
    reference_runs: Option<PathBuf>,
    /// Grid spacing of the reference region along the route, metres.
    #[arg(long, default_value_t = 1.0)]
    reference_bin: f64,
    /// What the CTE is measured against: the reference region (with --reference-runs) or the
    /// route polyline.
    #[arg(long, value_enum, default_value_t = CteArg::Region)]
    cte_to: CteArg,
    /// Trim each run to the route: start where the vehicle first comes within --goal-tolerance
    /// of the route's start, end at the goal (only with a route).
    #[arg(long, action = clap::ArgAction::Set, default_value_t = true, value_name = "BOOL")]
    trim_to_route: bool,
    /// Folder of bags holding the /perturb/events recorded apart from the runs (perturb-bridge
    /// record beside rosbag record), matched to each run by log time.
    #[arg(long, value_name = "DIR")]
    events_bags: Option<PathBuf>,
    /// Pose topic (geometry_msgs/PoseStamped, nav_msgs/Odometry, ...).
    #[arg(long)]
    pose_topic: Option<String>,
    /// Path of the position in the pose messages (x and y below it; default by type, e.g.
    /// pose.pose.position for Odometry).
    #[arg(long)]
    pose_field: Option<String>,
    /// Steering command topic.
    #[arg(long)]
    steering_topic: Option<String>,
    /// Path of the steering angle (default by type: drive.steering_angle for
    /// AckermannDriveStamped, data for Float32/64, ...).
    #[arg(long)]
    steering_field: Option<String>,
    /// Detected objects topic (near-field coverage).
    #[arg(long)]
    objects_topic: Option<String>,
    /// Path of the objects array (default by type: objects, detections, markers, poses).
    #[arg(long)]
    objects_array: Option<String>,
    /// Path of an object's position inside an array element (default by type, e.g.
    /// pose.position, bbox.center.position).
    #[arg(long)]
    object_position: Option<String>,
    /// Frame of the object positions: ego (relative to the vehicle) or map (the pose frame).
    #[arg(long, value_enum, default_value_t = FrameArg::Ego)]
    objects_frame: FrameArg,
    /// Known vehicles to be detected: CSV x,y in the pose frame (default: the vehicles seen
    /// within the near field in the nominal segments).
    #[arg(long)]
    vehicles: Option<PathBuf>,
    /// Takeover/disengagement topic: a failure at the first message whose field is true.
    #[arg(long)]
    takeover_topic: Option<String>,
    /// Field of the takeover topic (default: data for std_msgs; none: any message).
    #[arg(long)]
    takeover_field: Option<String>,
    /// The takeover fires when the field changes to this value (e.g. 0 for Autoware Mini's
    /// /vehicle/vehicle_status drivemode turning manual) instead of when it is true.
    #[arg(long)]
    takeover_value: Option<String>,
    /// Collision topic: a failure at the first message whose field is true.
    #[arg(long)]
    collision_topic: Option<String>,
    /// Field of the collision topic (default: data for std_msgs; none: any message).
    #[arg(long)]
    collision_field: Option<String>,
    /// The collision fires when the field changes to this value instead of when it is true.
    #[arg(long)]
    collision_value: Option<String>,
    /// The perturbation events topic.
    #[arg(long, default_value = perturb_bag::events::EVENTS_TOPIC)]
    events_topic: String,
    /// Only the events of these sensor topics decide the condition (repeatable; default all).
    #[arg(long)]
    event_stream: Vec<String>,
    /// Lane/road departure beyond this |CTE|, metres.
    #[arg(long, default_value_t = 2.0)]
    cte_threshold: f64,
    /// Metres before a failure left out of the CTE (the paper's d).
    #[arg(long, default_value_t = 5.0)]
    cte_exclude: f64,
    /// Failing runs below this completion (0..1) get no CTE.
    #[arg(long, default_value_t = 0.0)]
    cte_min_completion: f64,
    /// Fail with `timeout` when the route is not completed after this many seconds.
    #[arg(long)]
    timeout: Option<f64>,
    /// The route counts as completed within this distance of its end, metres.
    #[arg(long, default_value_t = 3.0)]
    goal_tolerance: f64,
    /// Steering change between consecutive commands that counts as an oscillation.
    #[arg(long, default_value_t = 0.3)]
    erratic_threshold: f64,
    /// Failing before this many metres along the route after an oscillation: erratic_start.
    #[arg(long, default_value_t = 5.0)]
    erratic_distance: f64,
    /// Route curvature (1/m) from which a departure is understeer/oversteer, not road_departure.
    #[arg(long, default_value_t = 0.02)]
    turn_curvature: f64,
    /// Near-field radius of the coverage, metres.
    #[arg(long, default_value_t = 5.0)]
    near_field: f64,
    /// A known vehicle is detected when an object lies within this distance, metres.
    #[arg(long, default_value_t = 2.0)]
    match_distance: f64,
    /// Segments shorter than this many seconds merge into the next one.
    #[arg(long, default_value_t = 0.5)]
    min_segment: f64,
    /// Which runs the per-perturbation CTE and jitter average: non-failing (judged ok; the
    /// default of analyze, the paper's RQ3), all (failing ones up to the failure), or shared
    /// (compare only, its default: every run over the shared non-failing portion, the paper's
    /// RQ4).
    #[arg(long, value_enum)]
    aggregate: Option<AggregateArg>,
    /// Jitter per command (the paper) or per second (a rate).
    #[arg(long, value_enum, default_value_t = JitterArg::Command)]
    jitter_per: JitterArg,
    /// Worker threads (default: all cores).
    #[arg(long)]
    threads: Option<usize>,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
enum FrameArg {
    Ego,
    Map,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
enum AggregateArg {
    NonFailing,
    All,
    Shared,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
enum CteArg {
    Region,
    Route,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
enum JitterArg {
    Command,
    Second,
}

#[derive(clap::Args)]
struct TransferArgs {
    /// The model-level table (perturb metrics ... --format json, or CSV).
    #[arg(long)]
    offline: PathBuf,
    /// The closed-loop table (perturb analyze --json, or CSV).
    #[arg(long)]
    closed_loop: PathBuf,
    /// Offline metrics to test (repeatable).
    #[arg(long)]
    offline_metric: Vec<String>,
    /// Closed-loop metrics to test (repeatable).
    #[arg(long)]
    closed_loop_metric: Vec<String>,
    /// A latency table (perturb bench --json, or CSV with mean_ms): only the (perturbation,
    /// severity) pairs whose average latency is within their budget (33 ms camera, 200 ms
    /// LiDAR) are matched, as the paper does.
    #[arg(long, value_name = "BENCH")]
    latency: Option<PathBuf>,
    /// Bootstrap resamples.
    #[arg(long, default_value_t = 10_000)]
    resamples: usize,
    /// Seed of the bootstrap.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Confidence level of the intervals.
    #[arg(long, default_value_t = 0.95)]
    level: f64,
    /// k of the top-k overlap.
    #[arg(long, default_value_t = 5)]
    top_k: usize,
    /// Output format.
    #[arg(long, value_enum, default_value_t = Format::Table)]
    format: Format,
}

#[derive(clap::Args)]
struct CompareArgs {
    /// A set of runs: NAME=DIR (repeatable, in table order).
    #[arg(long = "set", value_name = "NAME=DIR", required = true)]
    sets: Vec<String>,
    #[command(flatten)]
    run: RunArgs,
    /// Output format.
    #[arg(long, value_enum, default_value_t = Format::Table)]
    format: Format,
}

impl RunArgs {
    fn config(&self, default_aggregate: Aggregate) -> Result<AnalyzeConfig> {
        if (self.route.is_some() || self.reference_runs.is_some()) && self.pose_topic.is_none() {
            bail!(
                "--route and --reference-runs need --pose-topic: the topic with the vehicle's position"
            );
        }
        let tf = |topic: &Option<String>, field: &Option<String>| {
            topic.as_ref().map(|t| TopicField {
                topic: t.clone(),
                field: field.clone(),
            })
        };
        if self.pose_field.is_some() && self.pose_topic.is_none() {
            bail!("--pose-field needs --pose-topic");
        }
        if self.steering_field.is_some() && self.steering_topic.is_none() {
            bail!("--steering-field needs --steering-topic");
        }
        for (value, topic, name) in [
            (&self.takeover_value, &self.takeover_topic, "takeover"),
            (&self.collision_value, &self.collision_topic, "collision"),
        ] {
            if value.is_some() && topic.is_none() {
                bail!("--{name}-value needs --{name}-topic");
            }
        }
        let aggregate = match self.aggregate {
            Some(AggregateArg::All) => Aggregate::All,
            Some(AggregateArg::NonFailing) => Aggregate::NonFailing,
            Some(AggregateArg::Shared) => Aggregate::Shared,
            None => default_aggregate,
        };
        if aggregate == Aggregate::Shared && default_aggregate != Aggregate::Shared {
            bail!(
                "--aggregate shared compares sets of runs: use it with `perturb analyze compare`"
            );
        }
        let mut cfg = AnalyzeConfig {
            route: self
                .route
                .as_deref()
                .map(perturb_study::route::load)
                .transpose()?,
            cte_to: match self.cte_to {
                CteArg::Region => CteTo::Region,
                CteArg::Route => CteTo::Route,
            },
            trim_to_route: self.trim_to_route,
            pose: tf(&self.pose_topic, &self.pose_field),
            steering: tf(&self.steering_topic, &self.steering_field),
            objects: self.objects_topic.as_ref().map(|t| ObjectsConfig {
                topic: t.clone(),
                array: self.objects_array.clone(),
                position: self.object_position.clone(),
                frame: match self.objects_frame {
                    FrameArg::Ego => ObjectsFrame::Ego,
                    FrameArg::Map => ObjectsFrame::Map,
                },
            }),
            vehicles: self
                .vehicles
                .as_deref()
                .map(perturb_study::route::read_xy_csv)
                .transpose()?,
            takeover: tf(&self.takeover_topic, &self.takeover_field),
            collision: tf(&self.collision_topic, &self.collision_field),
            takeover_value: self.takeover_value.clone(),
            collision_value: self.collision_value.clone(),
            events_topic: self.events_topic.clone(),
            event_streams: self.event_stream.clone(),
            cte_threshold: self.cte_threshold,
            cte_exclude_m: self.cte_exclude,
            cte_min_completion: self.cte_min_completion,
            timeout_s: self.timeout,
            goal_tolerance_m: self.goal_tolerance,
            erratic_threshold: self.erratic_threshold,
            erratic_distance_m: self.erratic_distance,
            turn_curvature: self.turn_curvature,
            near_field_m: self.near_field,
            match_distance_m: self.match_distance,
            min_segment_s: self.min_segment,
            aggregate,
            jitter_unit: match self.jitter_per {
                JitterArg::Command => JitterUnit::Command,
                JitterArg::Second => JitterUnit::Second,
            },
            ..AnalyzeConfig::default()
        };
        if let Some(dir) = &self.events_bags {
            let ev = perturb_study::analyze::load_events_bags(dir, &cfg.events_topic)?;
            eprintln!(
                "{} perturbation events from {} bag(s) in {}",
                ev.events.len(),
                ev.bags.len(),
                dir.display()
            );
            cfg.external_events = Some(std::sync::Arc::new(ev));
        }
        if let Some(dir) = &self.reference_runs {
            let set = self.pool()?.install(|| {
                perturb_study::analyze::reference_from_runs(dir, &cfg, self.reference_bin)
            })?;
            for n in &set.notes {
                eprintln!("note: {n}");
            }
            eprintln!(
                "reference region from {} nominal drive(s) in {}{}",
                set.region.runs.len(),
                dir.display(),
                if set.derived_route {
                    format!("; route: their centre line ({:.1} m)", set.route.length())
                } else {
                    String::new()
                }
            );
            cfg.route = Some(set.route);
            cfg.reference = Some(set.region);
        }
        Ok(cfg)
    }

    fn pool(&self) -> Result<rayon::ThreadPool> {
        Ok(rayon::ThreadPoolBuilder::new()
            .num_threads(self.threads.unwrap_or(0))
            .build()?)
    }
}

fn write(path: &Path, text: &str) -> Result<()> {
    std::fs::write(path, text).with_context(|| format!("cannot write {}", path.display()))
}

/// Runs `perturb analyze`.
pub fn run(a: Args) -> Result<()> {
    match a.command {
        Some(Command::Transfer(t)) => return transfer(t),
        Some(Command::Compare(c)) => return compare(*c),
        None => {}
    }
    let runs_dir = a.runs.clone().expect("required by clap");
    let cfg = a.run.config(Aggregate::NonFailing)?;
    let analysis = a
        .run
        .pool()?
        .install(|| perturb_study::analyze::analyze_dir(&runs_dir, &cfg))?;
    let hot = perturb_study::hotspots::hotspots(&analysis.runs, a.eps, a.min_points);
    let map_path = a
        .map
        .clone()
        .or_else(|| a.out.as_ref().map(|o| o.join("map.svg")));
    if let Some(dir) = &a.out {
        write_outputs(dir, &analysis, &hot)?;
    }
    if let Some(path) = &map_path {
        draw_map(path, &analysis, &hot, a.map_width)?;
    }
    if a.json {
        print!("{}", analysis_json(&analysis, &hot));
    } else {
        let tables = if a.table.is_empty() {
            vec![
                TableKind::Runs,
                TableKind::Conditions,
                TableKind::Perturbations,
                TableKind::Hotspots,
            ]
        } else {
            a.table.clone()
        };
        print_tables(&tables, &analysis, &hot, a.format);
    }
    for r in &analysis.runs {
        for n in &r.notes {
            eprintln!("note: run `{}`: {n}", r.run);
        }
    }
    for sk in &analysis.skipped {
        eprintln!("skipped: {}: {}", sk.path.display(), sk.reason);
    }
    eprint!("{}", render_summary(&analysis.summary));
    if let (Some(dir), false) = (&a.out, a.json) {
        eprintln!(
            "tables, analysis.json and the map written to {}",
            dir.display()
        );
    }
    if !analysis.errors.is_empty() {
        for e in &analysis.errors {
            eprintln!("error: {}", e.error);
        }
        bail!(
            "{} of {} runs could not be analysed (the others were)",
            analysis.errors.len(),
            analysis.errors.len() + analysis.runs.len()
        );
    }
    Ok(())
}

impl TableKind {
    /// Every table, in the order of the files written to `--out`.
    const ALL: [TableKind; 5] = [
        TableKind::Runs,
        TableKind::Segments,
        TableKind::Conditions,
        TableKind::Perturbations,
        TableKind::Hotspots,
    ];

    /// The table's file name in `--out` (without the extension).
    fn file_stem(self) -> &'static str {
        match self {
            TableKind::Runs => "runs",
            TableKind::Segments => "segments",
            TableKind::Conditions => "conditions",
            TableKind::Perturbations => "perturbations",
            TableKind::Hotspots => "hotspots",
        }
    }

    /// The table's title when printed.
    fn title(self) -> &'static str {
        match self {
            TableKind::Runs => "runs",
            TableKind::Segments => "segments",
            TableKind::Conditions => "per (perturbation, severity)",
            TableKind::Perturbations => "per perturbation",
            TableKind::Hotspots => "failure hotspots",
        }
    }

    /// The table in `format`.
    fn render(
        self,
        analysis: &perturb_study::analyze::Analysis,
        hot: &perturb_study::hotspots::Hotspots,
        format: perturb_study::Format,
    ) -> String {
        match self {
            TableKind::Runs => render_runs(&analysis.runs, format),
            TableKind::Segments => render_segments(&analysis.segments, format),
            TableKind::Conditions => render_conditions(&analysis.conditions, format),
            TableKind::Perturbations => render_perturbations(&analysis.perturbations, format),
            TableKind::Hotspots => perturb_study::hotspots::render(hot, format),
        }
    }
}

/// Every table as markdown and CSV, and analysis.json, into `dir`.
fn write_outputs(
    dir: &Path,
    analysis: &perturb_study::analyze::Analysis,
    hot: &perturb_study::hotspots::Hotspots,
) -> Result<()> {
    std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
    use perturb_study::Format as F;
    for (ext, f) in [("md", F::Markdown), ("csv", F::Csv)] {
        for t in TableKind::ALL {
            write(
                &dir.join(format!("{}.{ext}", t.file_stem())),
                &t.render(analysis, hot, f),
            )?;
        }
    }
    write(&dir.join("analysis.json"), &analysis_json(analysis, hot))
}

/// The trajectory map with the failure hotspots, as an SVG at `path` (nothing when there is
/// nothing to draw).
fn draw_map(
    path: &Path,
    analysis: &perturb_study::analyze::Analysis,
    hot: &perturb_study::hotspots::Hotspots,
    width: u32,
) -> Result<()> {
    if path.extension().is_some_and(|e| e != "svg") {
        bail!(
            "--map {}: the map is written as SVG (vector; a browser or rsvg-convert turns it into a picture); give a .svg path",
            path.display()
        );
    }
    let options = perturb_study::plot::MapOptions {
        width,
        ..Default::default()
    };
    match perturb_study::plot::trajectory_map(
        analysis.route.as_ref(),
        analysis.reference.as_ref(),
        &analysis.runs,
        hot,
        &options,
    )? {
        Some(svg) => write(path, &svg)?,
        None => eprintln!("no map: nothing to draw"),
    }
    Ok(())
}

/// `tables` printed one after the other with their titles.
fn print_tables(
    tables: &[TableKind],
    analysis: &perturb_study::analyze::Analysis,
    hot: &perturb_study::hotspots::Hotspots,
    format: perturb_study::Format,
) {
    for (k, t) in tables.iter().enumerate() {
        if k > 0 {
            println!();
        }
        let title = t.title();
        match format {
            perturb_study::Format::Csv => println!("# {title}"),
            perturb_study::Format::Markdown => println!("### {title}\n"),
            _ => println!("== {title}"),
        }
        print!("{}", t.render(analysis, hot, format));
    }
}

fn analysis_json(
    a: &perturb_study::analyze::Analysis,
    hot: &perturb_study::hotspots::Hotspots,
) -> String {
    #[derive(serde::Serialize)]
    struct Out<'a> {
        #[serde(flatten)]
        analysis: &'a perturb_study::analyze::Analysis,
        hotspots: &'a perturb_study::hotspots::Hotspots,
    }
    serde_json::to_string_pretty(&Out {
        analysis: a,
        hotspots: hot,
    })
    .expect("the analysis serialises")
        + "\n"
}

fn transfer(t: TransferArgs) -> Result<()> {
    use perturb_study::transfer::{TransferConfig, read_table, render, transfer};
    if !(t.level > 0.0 && t.level < 1.0) {
        bail!("--level must be between 0 and 1, not {}", t.level);
    }
    if t.resamples == 0 {
        bail!("--resamples must be at least 1");
    }
    let mut off = read_table(&t.offline)?;
    let cl = read_table(&t.closed_loop)?;
    if let Some(bench) = &t.latency {
        let left_out = perturb_study::transfer::keep_feasible(&mut off, &read_table(bench)?);
        eprintln!(
            "{} (perturbation, severity) pair(s) left out as over their latency budget{}",
            left_out.len(),
            if left_out.is_empty() {
                String::new()
            } else {
                format!(
                    ": {}",
                    left_out
                        .iter()
                        .map(|(id, s)| format!("{id} s{s}"))
                        .collect::<Vec<_>>()
                        .join(", ")
                )
            }
        );
    }
    let res = transfer(
        &off,
        &cl,
        &TransferConfig {
            offline_metrics: t.offline_metric,
            closed_loop_metrics: t.closed_loop_metric,
            resamples: t.resamples,
            seed: t.seed,
            level: t.level,
            top_k: t.top_k,
        },
    )?;
    eprintln!(
        "{} (perturbation, severity) pairs in both tables; {} resamples from seed {}",
        res.matched, res.resamples, res.seed
    );
    // The text and markdown tables carry the notes themselves.
    let machine = matches!(t.format, Format::Json | Format::Csv);
    for r in res.rows.iter().filter(|r| machine && r.note.is_some()) {
        eprintln!(
            "note: {} vs {}: {}",
            r.offline,
            r.closed_loop,
            r.note.as_deref().unwrap_or_default()
        );
    }
    print!("{}", render(&res, t.format));
    Ok(())
}

fn compare(c: CompareArgs) -> Result<()> {
    let cfg = c.run.config(Aggregate::Shared)?;
    let pool = c.run.pool()?;
    let mut sets = Vec::new();
    let mut failed = 0;
    for s in &c.sets {
        let Some((name, dir)) = s.split_once('=') else {
            bail!("--set {s}: expected NAME=DIR");
        };
        let a = pool.install(|| perturb_study::analyze::analyze_dir(Path::new(dir), &cfg))?;
        for e in &a.errors {
            eprintln!("error: set `{name}`: {}", e.error);
        }
        failed += a.errors.len();
        sets.push((name.to_string(), a));
    }
    let rows = perturb_study::compare::compare(&sets, &cfg);
    for (name, a) in &sets {
        eprint!("set `{name}`: {}", render_summary(&a.summary));
    }
    print!("{}", perturb_study::compare::render(&rows, c.format));
    if failed > 0 {
        bail!("{failed} runs could not be analysed (the others were)");
    }
    Ok(())
}
