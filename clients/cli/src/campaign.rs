//! `perturb campaign check`: a campaign dry-run against a recorded drive, saying when and where
//! each step would fire, before the drive it is written for.

use anyhow::{Context, Result, bail};
use perturb_bag::dynamic::MessageCodec;
use perturb_bag::{Bag, Filter};
use perturb_campaign::{Campaign, Inputs, Trigger};
use perturb_core::route::Route;
use std::ops::ControlFlow;
use std::path::PathBuf;

/// Arguments of `perturb campaign`.
#[derive(clap::Args)]
pub struct Args {
    #[command(subcommand)]
    command: Command,
}

#[derive(clap::Subcommand)]
enum Command {
    /// Check a campaign file; with --bag, dry-run it against a recorded drive and print when
    /// and where each step would fire.
    #[command(after_help = "Examples:
  perturb campaign check config/campaign.toml
  perturb campaign check config/campaign.toml --bag drive.mcap --pose-topic /localization/current_pose
  perturb campaign check campaign.toml --route other_route.csv --bag drive.bag --pose-topic /odom --json

The campaign's clock starts at the drive's first message; manual steps fire on `perturb ctl next`
and are listed, not dry-run.")]
    Check {
        /// The campaign file (TOML; see config/campaign.toml).
        campaign: PathBuf,
        /// A route CSV (x,y) in place of the campaign's own.
        #[arg(long)]
        route: Option<PathBuf>,
        /// A recorded drive (rosbag2 MCAP, ROS 1 .bag) to dry-run the campaign on.
        #[arg(long, requires = "pose_topic")]
        bag: Option<PathBuf>,
        /// The pose topic in the drive (PoseStamped, Odometry, ... any type with a position).
        #[arg(long)]
        pose_topic: Option<String>,
        /// The field path of the position (default: found from the type, e.g.
        /// pose.pose.position).
        #[arg(long)]
        pose_field: Option<String>,
        /// Print JSON.
        #[arg(long)]
        json: bool,
    },
}

/// One time a step switched on or off in the dry run.
#[derive(Clone, Debug, serde::Serialize)]
struct Switch {
    /// Seconds since the drive's start.
    t_s: f64,
    /// Position.
    x: f64,
    /// Position.
    y: f64,
    /// Arc length along the route, if on it.
    arc_length_m: Option<f64>,
}

/// What the dry run found for one step.
#[derive(Clone, Debug, serde::Serialize)]
struct StepRun {
    index: usize,
    name: String,
    streams: Vec<String>,
    id: String,
    severity: u8,
    trigger: String,
    /// (on, off) pairs; `off` absent when the step was still on at the drive's end.
    windows: Vec<(Switch, Option<Switch>)>,
}

/// Runs `perturb campaign`.
pub fn run(a: Args) -> Result<()> {
    let Command::Check {
        campaign,
        route,
        bag,
        pose_topic,
        pose_field,
        json,
    } = a.command;
    let mut c = Campaign::load(&campaign)?;
    if let Some(r) = &route {
        let text =
            std::fs::read_to_string(r).with_context(|| format!("reading {}", r.display()))?;
        c = c.with_route(
            Route::from_csv_text(&text).map_err(|e| anyhow::anyhow!("{}: {e}", r.display()))?,
        );
    }
    let Some(bag) = bag else {
        println!(
            "{}: campaign `{}`, {} step(s), valid",
            campaign.display(),
            c.name,
            c.steps.len()
        );
        for (i, s) in c.steps.iter().enumerate() {
            println!(
                "  steps[{i}] {}: {} severity {} seed {} on {} when {}",
                s.name,
                s.id,
                s.severity,
                s.seed,
                s.streams.join(", "),
                s.trigger.describe()
            );
        }
        return Ok(());
    };
    let pose_topic = pose_topic.expect("clap requires it with --bag");
    let runs = dry_run(&c, &bag, &pose_topic, pose_field.as_deref())?;
    if json {
        println!("{}", serde_json::to_string_pretty(&runs)?);
        return Ok(());
    }
    println!(
        "campaign `{}` on {} ({pose_topic}); times from the drive's first message",
        c.name,
        bag.display()
    );
    let at = |s: &Switch| {
        format!(
            "{:.2} s at ({:.1}, {:.1}){}",
            s.t_s,
            s.x,
            s.y,
            s.arc_length_m
                .map(|m| format!(", {m:.1} m along the route"))
                .unwrap_or_default()
        )
    };
    for r in &runs {
        println!(
            "steps[{}] {} ({} severity {} on {}; {}):",
            r.index,
            r.name,
            r.id,
            r.severity,
            r.streams.join(", "),
            r.trigger
        );
        if r.trigger.starts_with("manual") {
            println!("    fires on `perturb ctl next`");
        } else if r.windows.is_empty() {
            println!("    never fires on this drive");
        }
        for (on, off) in &r.windows {
            println!(
                "    on  {}\n    off {}",
                at(on),
                off.as_ref()
                    .map(at)
                    .unwrap_or_else(|| "(still on at the end)".into())
            );
        }
    }
    Ok(())
}

/// Evaluates the campaign at every pose of the drive.
fn dry_run(
    c: &Campaign,
    bag: &std::path::Path,
    topic: &str,
    field: Option<&str>,
) -> Result<Vec<StepRun>> {
    let b = Bag::open(bag)?;
    let info = b
        .topics()?
        .into_iter()
        .find(|t| t.topic == topic)
        .with_context(|| format!("{}: no topic {topic}", bag.display()))?;
    let codec = MessageCodec::new(
        &info.type_name,
        &info.schema_encoding,
        &info.schema,
        &info.message_encoding,
    )
    .with_context(|| format!("{topic}: its definition"))?;
    let base = match field {
        Some(f) => f.trim_end_matches(".x").to_string(),
        None => perturb_bag::dynamic::position_path(&codec).with_context(|| {
            format!(
                "cannot tell where the position is in `{}` messages: give --pose-field",
                info.type_name
            )
        })?,
    };
    let (px, py) = (
        codec.path(&format!("{base}.x"))?,
        codec.path(&format!("{base}.y"))?,
    );
    let mut start: Option<u64> = None;
    let mut tracker = c.tracker();
    let mut runs: Vec<StepRun> = c
        .steps
        .iter()
        .enumerate()
        .map(|(index, s)| StepRun {
            index,
            name: s.name.clone(),
            streams: s.streams.clone(),
            id: s.id.clone(),
            severity: s.severity,
            trigger: s.trigger.describe(),
            windows: Vec::new(),
        })
        .collect();
    let mut on = vec![false; c.steps.len()];
    let mut poses = 0usize;
    let mut error = None;
    let report = b.for_each(&Filter::default(), |m| {
        let t0 = *start.get_or_insert(m.log_time);
        if m.topic != topic {
            return Ok(ControlFlow::Continue(()));
        }
        let (x, y) = match (codec.get_f64(m.data, &px), codec.get_f64(m.data, &py)) {
            (Ok(x), Ok(y)) => (x, y),
            (Err(e), _) | (_, Err(e)) => {
                error = Some(e);
                return Ok(ControlFlow::Break(()));
            }
        };
        poses += 1;
        let inputs = Inputs {
            t: m.log_time.saturating_sub(t0) as f64 / 1e9,
            pose: Some([x, y]),
            next: 0,
        };
        let active = c.active(&inputs, &mut tracker);
        let sw = Switch {
            t_s: inputs.t,
            x,
            y,
            arc_length_m: tracker.arc_length(),
        };
        for (i, step) in c.steps.iter().enumerate() {
            if matches!(step.trigger, Trigger::Manual(_)) {
                continue;
            }
            let now = active.contains(&i);
            if now && !on[i] {
                runs[i].windows.push((sw.clone(), None));
            } else if !now
                && on[i]
                && let Some(w) = runs[i].windows.last_mut()
            {
                w.1 = Some(sw.clone());
            }
            on[i] = now;
        }
        Ok(ControlFlow::Continue(()))
    })?;
    if let Some(e) = error {
        bail!("{topic}: {e}");
    }
    if poses == 0 {
        bail!("{}: no message on {topic}", bag.display());
    }
    if let Some(d) = report.damage {
        eprintln!("note: {}: read up to the damage ({d})", bag.display());
    }
    Ok(runs)
}
