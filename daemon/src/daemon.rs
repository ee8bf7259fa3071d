//! The daemon's life: sweep stale shared memory, open every stream's services, start the
//! workers, serve the control channel and log statistics until SIGINT/SIGTERM, then stop the
//! workers, write the JSON report and exit.

use crate::campaign::CampaignRunner;
use crate::config::{Config, Dispatch, StreamConfig};
use crate::perturbation::{self, Active};
use crate::safety::KillSwitch;
use crate::state::{self, CountersFile, RuntimeState, StatePaths};
use crate::worker::{self, Gate, StreamRuntime};
use perturb_core::registry::Modality;
use perturb_wire::control::{
    ControlClient, ControlRequest, ControlResponse, ControlServer, StreamReport,
};
use perturb_wire::iceoryx2::prelude::*;
use perturb_wire::iceoryx2::waitset::WaitSetRunResult;
use perturb_wire::{FramePublisher, FrameSubscriber, Hop, Ipc, Transport, TransportOptions};
use serde::Serialize;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};
use tracing::{error, info, warn};

/// What the daemon writes on exit.
#[derive(Debug, Serialize)]
pub struct Report {
    /// The configuration file.
    pub config: PathBuf,
    /// Unix time of the start, seconds.
    pub started_unix_s: f64,
    /// Seconds the daemon ran.
    pub duration_s: f64,
    /// Why it stopped.
    pub stopped_by: String,
    /// One entry per stream, as `perturb ctl stats --json`.
    pub streams: Vec<StreamReport>,
}

/// Runs the daemon until a termination signal. `report_path` overrides `[daemon] report`; the
/// state files go next to the report (see [`crate::state`]); `fresh` ignores what they hold.
pub fn run(
    config_path: &Path,
    cfg: Config,
    report_path: Option<PathBuf>,
    fresh: bool,
) -> anyhow::Result<()> {
    let started = Instant::now();
    let started_unix_s = SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map(|d| d.as_secs_f64())
        .unwrap_or(0.0);
    let options: TransportOptions = cfg.transport.clone().with_env_overrides();
    let transport = open_transport(config_path, &cfg, &options)?;
    let control_service = cfg.daemon.control_service.as_str();
    let server = claim_control(&transport, control_service, &options)?;
    let report_path = report_path
        .or(cfg.daemon.report.clone())
        .unwrap_or_else(|| PathBuf::from("perturbd-report.json"));
    let paths = StatePaths::for_report(&report_path);
    let saved = load_saved(&paths, fresh);
    let counters = open_counters(&paths, &cfg, fresh);
    let kill = Arc::new(KillSwitch::restored(
        saved.as_ref().and_then(|s| s.killed.clone()),
    ));
    if let Some(k) = kill.record() {
        warn!(
            reason = k.reason.as_str(),
            state = %paths.runtime.display(),
            "the kill switch was engaged before the restart and still is: every stream passes raw frames until `perturb ctl arm`"
        );
    }

    // Open every stream's services before starting any worker, so a bad stream stops the
    // daemon before it touches the others.
    let shutdown = Arc::new(AtomicBool::new(false));
    let gate = dispatch_gate(&cfg)?;
    let mut streams = Vec::new();
    let mut ports = Vec::new();
    for s in &cfg.streams {
        let initial = initial_perturbation(s, saved.as_ref(), &paths)?;
        let (rt, input, output) = open_stream(
            &transport,
            s,
            &initial,
            counters.as_ref(),
            kill.clone(),
            gate.clone(),
        )?;
        ports.push((rt.clone(), input, output, initial));
        streams.push(rt);
    }
    let mut threads = Vec::new();
    for (rt, input, output, initial) in ports {
        threads.extend(worker::spawn(rt, input, output, initial, shutdown.clone())?);
    }
    let persist = Persist {
        path: paths.runtime.clone(),
        kill: kill.clone(),
    };
    let resume = saved.as_ref().and_then(|s| s.campaign.clone());
    let campaign_file = cfg
        .daemon
        .campaign
        .clone()
        .or_else(|| resume.as_ref().map(|r| r.file.clone()));
    let campaign = match campaign_file {
        Some(f) => Some(
            CampaignRunner::start(f, &streams, resume.as_ref())
                .map_err(|e| anyhow::anyhow!("campaign: {e}"))?,
        ),
        None => None,
    };
    let mut ctx = Controlled {
        streams: &streams,
        kill: &kill,
        campaign,
    };
    if let Some(c) = &mut ctx.campaign {
        c.evaluate(&streams);
    }
    persist.save(&streams, ctx.campaign.as_ref());
    info!(control = control_service, "perturbd ready");

    let stopped_by = serve(&server, &mut ctx, cfg.daemon.stats_interval_s, &persist);
    info!(reason = stopped_by.as_str(), "perturbd stopping");
    shutdown.store(true, Ordering::Relaxed);
    for t in threads {
        if t.join().is_err() {
            error!("a worker thread panicked");
        }
    }
    log_stats(&streams);
    let report = Report {
        config: config_path.to_path_buf(),
        started_unix_s,
        duration_s: started.elapsed().as_secs_f64(),
        stopped_by,
        streams: streams.iter().map(|s| s.report(true)).collect(),
    };
    write_report(&report_path, &report)?;
    if let Some(c) = &counters {
        c.mark_clean();
    }
    Ok(())
}

/// Opens the iceoryx2 node and removes the shared memory dead processes left behind.
fn open_transport(
    config_path: &Path,
    cfg: &Config,
    options: &TransportOptions,
) -> anyhow::Result<Transport> {
    let transport = Transport::open("perturbd", options)?;
    info!(
        config = %config_path.display(),
        namespace = %options.describe(),
        streams = cfg.streams.len(),
        "perturbd starting"
    );
    let sweep = transport.sweep_dead_nodes()?;
    if sweep.removed > 0 || sweep.failed > 0 {
        info!(
            removed = sweep.removed,
            failed = sweep.failed,
            alive = sweep.alive,
            "removed stale shared memory of dead processes"
        );
    }
    Ok(transport)
}

/// Creates the control service; refuses when another perturbd already answers on it.
fn claim_control(
    transport: &Transport,
    control_service: &str,
    options: &TransportOptions,
) -> anyhow::Result<ControlServer> {
    if let Ok(client) = ControlClient::connect(transport, control_service)
        && client
            .request(&ControlRequest::Status, Duration::from_millis(500))
            .is_ok()
    {
        anyhow::bail!(
            "another perturbd already serves `{control_service}` in this iceoryx2 namespace ({}); stop it first",
            options.describe()
        );
    }
    Ok(ControlServer::create(transport, control_service)?)
}

/// The runtime state the last run saved (None with `--fresh`, or when it cannot be read).
fn load_saved(paths: &StatePaths, fresh: bool) -> Option<RuntimeState> {
    if fresh {
        info!(state = %paths.runtime.display(), "--fresh: the runtime state and counters of the last run are ignored");
        return None;
    }
    match RuntimeState::load(&paths.runtime) {
        Ok(s) => s,
        Err(e) => {
            warn!("{e}; starting from the configuration");
            None
        }
    }
}

/// The counters file, carried on from the last run unless `fresh`; None (counters in memory
/// only) when it cannot be kept.
fn open_counters(paths: &StatePaths, cfg: &Config, fresh: bool) -> Option<CountersFile> {
    match CountersFile::open(&paths.counters, &cfg.streams, fresh) {
        Ok((f, carried)) => {
            for (stream, lost) in &carried.after_crash {
                warn!(
                    stream = stream.as_str(),
                    lost_in_flight = lost,
                    counters = %paths.counters.display(),
                    "the last perturbd did not stop cleanly: its counters carry on, and the frames it had taken in but not published are counted as dropped_restart"
                );
            }
            Some(f)
        }
        Err(e) => {
            warn!(
                counters = %paths.counters.display(),
                "cannot keep the counters in a file ({e}): they live in memory only and a restart will not know where the streams were"
            );
            None
        }
    }
}

/// The perturbation stream `s` starts with: the one set at runtime before a restart, if the
/// saved state still applies, else the configured one (each change said in the log).
fn initial_perturbation(
    s: &StreamConfig,
    saved: Option<&RuntimeState>,
    paths: &StatePaths,
) -> anyhow::Result<Option<Active>> {
    let restored = saved.and_then(|st| st.restore_for(s));
    let wanted = match &restored {
        Some(r) => r.clone(),
        None => state::configured(s),
    };
    let initial: Option<Active> = match &wanted {
        Some(p) => Some(
            perturbation::build(s, &p.id, p.severity, p.seed, None)
                .map(|(_, a)| a)
                .map_err(|e| anyhow::anyhow!("stream `{}`: {e}", s.name))?,
        ),
        None => None,
    };
    if let Some(r) = &restored
        && *r != state::configured(s)
    {
        let what = |p: &Option<state::Saved>| match p {
            Some(p) => format!("{} severity {} seed {}", p.id, p.severity, p.seed),
            None => "off".into(),
        };
        info!(
            stream = s.name.as_str(),
            runtime = what(r).as_str(),
            configured = what(&state::configured(s)).as_str(),
            state = %paths.runtime.display(),
            "restored the perturbation set at runtime before the restart (--fresh starts from the configuration)"
        );
    }
    if restored.is_none()
        && let Some(st) = saved.and_then(|st| st.streams.get(&s.name))
        && st.active != state::configured(s)
    {
        info!(
            stream = s.name.as_str(),
            state = %paths.runtime.display(),
            "the configuration's perturbation changed since the runtime state was saved: the configuration wins"
        );
    }
    Ok(initial)
}

/// The deadline gate of `[daemon] dispatch = "deadline"` when a stream without its own
/// `threads` would use it (None: every frame goes to the global pool as it comes).
fn dispatch_gate(cfg: &Config) -> anyhow::Result<Option<Arc<Gate>>> {
    let d = &cfg.daemon;
    let gated = cfg.streams.iter().filter(|s| s.threads.is_none()).count();
    if d.dispatch != Dispatch::Deadline || gated == 0 {
        info!(
            dispatch = d.dispatch.as_str(),
            workers = rayon::current_num_threads(),
            "frames dispatched to the shared pool as they come"
        );
        return Ok(None);
    }
    let (slots, threads) = d.slots(rayon::current_num_threads());
    // The last free slot is kept for frames due within the shortest budget behind the gate.
    let reserve_ms = cfg
        .streams
        .iter()
        .filter(|s| s.threads.is_none())
        .map(StreamConfig::budget)
        .fold(f64::INFINITY, f64::min);
    let gate = Gate::new(slots, threads, Duration::from_secs_f64(reserve_ms / 1e3))
        .map_err(|e| anyhow::anyhow!("dispatch: cannot start the worker threads: {e}"))?;
    info!(
        dispatch = d.dispatch.as_str(),
        slots,
        threads_per_slot = threads,
        streams = gated,
        reserve_ms,
        "frames dispatched earliest deadline first"
    );
    Ok(Some(Arc::new(gate)))
}

/// Opens stream `s`'s output and input services (the output first: once the input has its
/// subscriber, what a publisher waits for, the output is ready too) and its runtime state.
fn open_stream(
    transport: &Transport,
    s: &StreamConfig,
    initial: &Option<Active>,
    counters: Option<&CountersFile>,
    kill: Arc<KillSwitch>,
    gate: Option<Arc<Gate>>,
) -> anyhow::Result<(Arc<StreamRuntime>, FrameSubscriber, FramePublisher)> {
    let output = transport
        .publisher(&s.output_service(), &s.qos, Hop::Keep, 1)
        .map_err(|e| anyhow::anyhow!("stream `{}` output: {e}", s.name))?;
    let input = transport
        .subscriber(&s.input_service(), &s.qos, None)
        .map_err(|e| anyhow::anyhow!("stream `{}` input: {e}", s.name))?;
    let cell = counters.and_then(|f| f.cell(&s.name)).unwrap_or_default();
    let rt = Arc::new(
        StreamRuntime::new(s.clone(), initial.as_ref().map(|a| a.spec()), cell)
            .map_err(|e| anyhow::anyhow!("stream `{}` worker threads: {e}", s.name))?
            .with_kill(kill)
            .with_gate(gate),
    );
    info!(
        stream = s.name.as_str(),
        modality = s.modality.as_str(),
        input = %s.input_service(),
        output = %s.output_service(),
        sensor = match s.modality {
            Modality::Lidar => s
                .sensor_model()
                .map(|m| m.describe())
                .unwrap_or_else(|e| e),
            Modality::Camera => "-".to_string(),
        },
        perturbation = initial
            .as_ref()
            .map(|a| format!("{} severity {} seed {}", a.spec().entry.id, a.spec().severity, a.spec().seed))
            .unwrap_or_else(|| "off".into()),
        budget_ms = s.budget(),
        worker_threads = rt.worker_threads(),
        "stream configured"
    );
    Ok((rt, input, output))
}

/// Writes the JSON report at `path`.
fn write_report(path: &Path, report: &Report) -> anyhow::Result<()> {
    let json = serde_json::to_string_pretty(&report_value(report))?;
    std::fs::write(path, json + "\n")
        .map_err(|e| anyhow::anyhow!("cannot write the report {}: {e}", path.display()))?;
    info!(report = %path.display(), "report written");
    Ok(())
}

fn report_value(r: &Report) -> serde_json::Value {
    serde_json::to_value(r).unwrap_or(serde_json::Value::Null)
}

/// Writes the runtime state file after every change.
pub struct Persist {
    /// The runtime state file.
    pub path: PathBuf,
    /// The kill switch (kept engaged across restarts).
    pub kill: Arc<KillSwitch>,
}

/// What the control handler works on: the streams, the kill switch, the campaign.
pub struct Controlled<'a> {
    /// Every stream.
    pub streams: &'a [Arc<StreamRuntime>],
    /// The kill switch.
    pub kill: &'a KillSwitch,
    /// The running campaign.
    pub campaign: Option<CampaignRunner>,
}

impl Persist {
    /// Saves what every stream runs now, the kill switch and the campaign (a failure is
    /// logged: the daemon goes on).
    pub fn save(&self, streams: &[Arc<StreamRuntime>], campaign: Option<&CampaignRunner>) {
        let mut st = RuntimeState {
            version: 1,
            killed: self.kill.record(),
            campaign: campaign.map(|c| c.state().clone()),
            ..Default::default()
        };
        for rt in streams {
            st.streams.insert(
                rt.config.name.clone(),
                state::StreamState {
                    active: rt.current().map(|s| state::Saved {
                        id: s.entry.id.to_string(),
                        severity: s.severity,
                        seed: s.seed,
                    }),
                    configured: state::configured(&rt.config),
                },
            );
        }
        if let Err(e) = st.save(&self.path) {
            warn!(
                state = %self.path.display(),
                "cannot save the runtime state ({e}): a restart will start from the configuration"
            );
        }
    }
}

/// The control and statistics loop; returns why it stopped.
fn serve(
    server: &ControlServer,
    ctx: &mut Controlled<'_>,
    stats_interval_s: f64,
    persist: &Persist,
) -> String {
    let waitset = match WaitSetBuilder::new().create::<Ipc>() {
        Ok(w) => w,
        Err(e) => return format!("cannot create the main WaitSet: {e:?}"),
    };
    let control = match waitset.attach_notification(server.listener()) {
        Ok(g) => g,
        Err(e) => return format!("cannot attach the control listener: {e:?}"),
    };
    // Also wakes regularly to notice a termination signal delivered to another thread, to log
    // statistics and to move a campaign's time steps on.
    let _tick = match waitset.attach_interval(Duration::from_millis(250)) {
        Ok(g) => g,
        Err(e) => return format!("cannot attach the tick: {e:?}"),
    };
    let mut last_log = Instant::now();
    loop {
        let r = waitset.wait_and_process_once(|id| {
            if id.has_event_from(&control)
                && let Err(e) = server.serve(|req| {
                    let change = !matches!(
                        req,
                        ControlRequest::Status
                            | ControlRequest::Stats
                            | ControlRequest::Pose { .. }
                    );
                    let resp = handle(ctx, req);
                    if change && resp.ok {
                        persist.save(ctx.streams, ctx.campaign.as_ref());
                    }
                    resp
                })
            {
                warn!("control channel: {e}");
            }
            CallbackProgression::Continue
        });
        match r {
            Ok(WaitSetRunResult::TerminationRequest) => return "SIGINT/SIGTERM".into(),
            Ok(_) => {}
            Err(e) => return format!("WaitSet failed: {e:?}"),
        }
        if let Some(c) = &mut ctx.campaign {
            c.evaluate(ctx.streams);
        }
        if stats_interval_s > 0.0 && last_log.elapsed().as_secs_f64() >= stats_interval_s {
            last_log = Instant::now();
            log_stats(ctx.streams);
        }
    }
}

fn ms(us: f64) -> String {
    format!("{:.2}", us / 1000.0)
}

fn log_stats(streams: &[Arc<StreamRuntime>]) {
    for s in streams {
        let r = s.report(true);
        let l = r.latency.clone().unwrap_or_default();
        info!(
            stream = r.name.as_str(),
            active = r.id.as_deref().unwrap_or("off"),
            frames_in = r.frames_in,
            frames_out = r.frames_out,
            dropped = r.dropped,
            invalid = r.invalid,
            over_budget = r.over_budget,
            perturb_p50_ms = %ms(l.perturb.p50_us),
            perturb_p99_ms = %ms(l.perturb.p99_us),
            hop_p50_ms = %ms(l.ingress_to_rx.p50_us),
            daemon_p50_ms = %ms(l.rx_to_tx.p50_us),
            daemon_p99_ms = %ms(l.rx_to_tx.p99_us),
            daemon_max_ms = %ms(l.rx_to_tx.max_us),
            "stats"
        );
    }
}

/// Answers one control request.
pub fn handle(ctx: &mut Controlled<'_>, req: ControlRequest) -> ControlResponse {
    let (streams, kill) = (ctx.streams, ctx.kill);
    let campaign_status = |c: &Option<CampaignRunner>| c.as_ref().map(CampaignRunner::status);
    let find = |name: &str| {
        streams
            .iter()
            .find(|s| s.config.name == name)
            .ok_or_else(|| {
                let known: Vec<&str> = streams.iter().map(|s| s.config.name.as_str()).collect();
                Box::new(ControlResponse::error(format!(
                    "unknown stream `{name}` (streams: {})",
                    known.join(", ")
                )))
            })
    };
    match req {
        ControlRequest::Set {
            stream,
            id,
            severity,
            seed,
        } => {
            let rt = match find(&stream) {
                Ok(r) => r,
                Err(e) => return *e,
            };
            if rt.in_campaign() {
                return ControlResponse::error(format!(
                    "stream `{stream}` is driven by the running campaign: `perturb ctl campaign --stop` first"
                ));
            }
            let seed = seed.unwrap_or_else(|| rt.current_seed());
            match perturbation::build(&rt.config, &id, severity, seed, rt.last_geometry()) {
                Ok((spec, active)) => {
                    rt.set(active);
                    info!(
                        stream = stream.as_str(),
                        id = spec.entry.id,
                        severity,
                        seed,
                        "control: set"
                    );
                    let when = if kill.engaged() {
                        "held while the kill switch is engaged (active after `perturb ctl arm`)"
                    } else {
                        "active from the next frame"
                    };
                    ControlResponse::ack(format!(
                        "{stream}: {} ({}) severity {severity} seed {seed}, {when}",
                        spec.entry.id, spec.entry.name
                    ))
                }
                Err(e) => ControlResponse::error(format!("stream `{stream}`: {e}")),
            }
        }
        ControlRequest::Off { stream } => {
            let rt = match find(&stream) {
                Ok(r) => r,
                Err(e) => return *e,
            };
            if rt.in_campaign() {
                return ControlResponse::error(format!(
                    "stream `{stream}` is driven by the running campaign: `perturb ctl campaign --stop` first (or the kill switch, `perturb ctl off --all`)"
                ));
            }
            rt.off();
            info!(stream = stream.as_str(), "control: off");
            ControlResponse::ack(format!(
                "{stream}: perturbation off, frames forwarded unchanged from the next frame"
            ))
        }
        ControlRequest::Status => ControlResponse {
            ok: true,
            streams: Some(streams.iter().map(|s| s.report(false)).collect()),
            killed: kill.record(),
            campaign: campaign_status(&ctx.campaign),
            ..Default::default()
        },
        ControlRequest::Stats => ControlResponse {
            ok: true,
            streams: Some(streams.iter().map(|s| s.report(true)).collect()),
            killed: kill.record(),
            campaign: campaign_status(&ctx.campaign),
            ..Default::default()
        },
        ControlRequest::Kill { reason } => {
            let reason = reason.unwrap_or_else(|| "perturb ctl off --all".into());
            let first = kill.engage(&reason);
            let k = kill.record();
            if first {
                warn!(
                    reason = reason.as_str(),
                    "kill switch engaged: every stream passes raw frames from the next frame on, until `perturb ctl arm`"
                );
            }
            ControlResponse {
                ok: true,
                message: Some(if first {
                    format!(
                        "kill switch engaged ({reason}): every stream passes raw frames from the next frame on, until `perturb ctl arm`"
                    )
                } else {
                    format!(
                        "kill switch already engaged ({}): every stream passes raw frames until `perturb ctl arm`",
                        k.as_ref().map_or("?", |k| k.reason.as_str())
                    )
                }),
                killed: k,
                ..Default::default()
            }
        }
        ControlRequest::Arm => match kill.arm() {
            Some(k) => {
                warn!(
                    was = k.reason.as_str(),
                    "kill switch armed again: every stream runs what it is set to from the next frame"
                );
                let what: Vec<String> = streams
                    .iter()
                    .map(|s| {
                        let r = s.report(false);
                        format!(
                            "{} {}",
                            r.name,
                            r.id.map_or("off".to_string(), |id| format!(
                                "{id} severity {}",
                                r.severity.unwrap_or(0)
                            ))
                        )
                    })
                    .collect();
                ControlResponse::ack(format!(
                    "armed (the kill switch had been engaged by: {}); from the next frame: {}",
                    k.reason,
                    what.join(", ")
                ))
            }
            None => ControlResponse::ack("the kill switch was not engaged: nothing to arm"),
        },
        ControlRequest::Pose { x, y } => {
            if !(x.is_finite() && y.is_finite()) {
                return ControlResponse::error(format!("pose ({x}, {y}) is not finite"));
            }
            match &mut ctx.campaign {
                Some(c) => {
                    c.pose(x, y);
                    c.evaluate(streams);
                    ControlResponse::ack("pose taken")
                }
                None => ControlResponse::ack("no campaign runs: pose ignored"),
            }
        }
        ControlRequest::Next => match &mut ctx.campaign {
            Some(c) => match c.advance() {
                Ok(msg) => {
                    c.evaluate(streams);
                    info!("control: next ({msg})");
                    ControlResponse {
                        ok: true,
                        message: Some(msg),
                        campaign: campaign_status(&ctx.campaign),
                        ..Default::default()
                    }
                }
                Err(e) => ControlResponse::error(e),
            },
            None => ControlResponse::error(
                "no campaign runs (start one with `perturb ctl campaign FILE`)",
            ),
        },
        ControlRequest::Campaign { file, stop } => {
            if stop {
                return match ctx.campaign.take() {
                    Some(c) => {
                        c.stop(streams);
                        ControlResponse::ack(
                            "campaign stopped: its streams pass raw frames and take `perturb ctl set` again",
                        )
                    }
                    None => ControlResponse::error("no campaign runs"),
                };
            }
            if let Some(f) = file {
                if let Some(c) = ctx.campaign.take() {
                    c.stop(streams);
                }
                match CampaignRunner::start(PathBuf::from(&f), streams, None) {
                    Ok(mut c) => {
                        c.evaluate(streams);
                        ctx.campaign = Some(c);
                    }
                    Err(e) => return ControlResponse::error(format!("campaign {f}: {e}")),
                }
            }
            ControlResponse {
                ok: true,
                message: Some(match &ctx.campaign {
                    Some(c) => format!("campaign `{}` runs", c.status().name),
                    None => "no campaign runs".into(),
                }),
                campaign: campaign_status(&ctx.campaign),
                ..Default::default()
            }
        }
    }
}
