//! `perturb bench --hil BAG`: the feasibility table measured in the live pipeline. The bag is
//! replayed (looped, original timing) through `perturb-bridge` into `perturbd`; every perturbation
//! and severity is switched on for a window while this process reads the daemon's output in
//! shared memory and times each frame from its header: ingress publish to daemon publish, the
//! latency the real-time budget applies to. A first window with every perturbation off gives the
//! middleware (node) overhead alone.

use crate::pipeline::{Options, Pipeline, Source};
use anyhow::{Result, bail};
use perturb_core::bench::Timing;
use perturb_core::registry::{Entry, Modality};
use perturb_wire::FrameSubscriber;
use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;

/// Frame latencies by the perturbation their header says was applied (`None`: off).
type Samples = Arc<Mutex<HashMap<Option<(String, u8)>, Vec<f64>>>>;

/// What the sweep measured.
pub struct HilResult {
    /// One row per perturbation and severity (latencies: ingress publish to daemon publish).
    pub rows: Vec<Timing>,
    /// Mean ingress-to-publish latency with every perturbation off, ms.
    pub overhead_ms: f64,
    /// Frames the daemon dropped during each row's window, same order as `rows`.
    pub dropped: Vec<u64>,
}

fn summarize(e: &Entry, severity: u8, v: &mut [f64]) -> Timing {
    v.sort_by(f64::total_cmp);
    let n = v.len();
    let at = |p: f64| perturb_core::percentile::of_sorted(v, p).unwrap_or(f64::NAN);
    Timing {
        id: e.id,
        name: e.name,
        severity,
        frames: n,
        setup_ms: 0.0,
        mean_ms: if n == 0 {
            f64::NAN
        } else {
            v.iter().sum::<f64>() / n as f64
        },
        median_ms: at(0.5),
        p99_ms: at(0.99),
        max_ms: if n == 0 { f64::NAN } else { v[n - 1] },
    }
}

/// Replays `bag` through the pipeline and sweeps `entries` (of `modality`) at every severity,
/// `window` seconds each.
pub fn sweep(
    bag: &Path,
    modality: Modality,
    entries: &[&'static Entry],
    window: f64,
    sensor: &str,
) -> Result<HilResult> {
    let out = std::env::temp_dir().join(format!("perturb-hil-{}", std::process::id()));
    let mut p = Pipeline::start(&Options {
        out: out.clone(),
        source: Source::Bag(PathBuf::from(bag)),
        sensor: sensor.to_string(),
        record: None,
    })?;
    let streams: Vec<String> = p
        .streams
        .iter()
        .filter(|(_, m)| *m == modality)
        .map(|(n, _)| n.clone())
        .collect();
    if streams.is_empty() {
        bail!("{} has no {modality:?} topic", bag.display());
    }
    let samples: Samples = Arc::default();
    let stop = Arc::new(AtomicBool::new(false));
    let mut threads = Vec::new();
    for name in &streams {
        threads.push(collect_latencies(&p, name, &samples, &stop)?);
    }
    let settle = Duration::from_millis(500);
    let run = Duration::from_secs_f64(window.max(0.1));
    eprintln!(
        "HiL sweep of {} perturbation(s) on {} ({}), {window} s each, after {:.0} s with every perturbation off",
        entries.len(),
        bag.display(),
        streams.join(", "),
        run.as_secs_f64()
    );
    let dropped_now = |p: &Pipeline| -> Result<u64> {
        Ok(p.stats()?
            .iter()
            .filter(|s| streams.contains(&s.name))
            .map(|s| s.dropped)
            .sum())
    };
    std::thread::sleep(settle + run);
    p.check_running()?;
    let mut keys = Vec::new();
    let mut dropped = Vec::new();
    for e in entries {
        for s in e.severities() {
            let before = dropped_now(&p)?;
            for name in &streams {
                p.set(name, e.id, s, 1)?;
            }
            std::thread::sleep(settle + run);
            p.check_running()?;
            dropped.push(dropped_now(&p)? - before);
            keys.push((*e, s));
            eprintln!("  {} {} s{s} done", e.id, e.name);
        }
    }
    for name in &streams {
        p.off(name)?;
    }
    stop.store(true, Ordering::Relaxed);
    for t in threads {
        let _ = t.join();
    }
    p.stop()?;
    let _ = std::fs::remove_dir_all(&out);
    let samples = std::mem::take(&mut *samples.lock().map_err(|_| anyhow::anyhow!("poisoned"))?);
    result(samples, &keys, dropped)
}

/// A thread that records, per active perturbation (None: off), the ingress-to-daemon-publish
/// latency of every perturbed frame of stream `name` until `stop`.
fn collect_latencies(
    p: &Pipeline,
    name: &str,
    samples: &Samples,
    stop: &Arc<AtomicBool>,
) -> Result<std::thread::JoinHandle<()>> {
    let sub: FrameSubscriber = p.transport.subscriber(
        &perturb_wire::names::perturbed(name),
        &perturb_wire::StreamQos {
            subscriber_buffer: 4,
            ..Default::default()
        },
        None,
    )?;
    let (samples, stop) = (samples.clone(), stop.clone());
    Ok(std::thread::spawn(move || {
        while !stop.load(Ordering::Relaxed) {
            if let Ok(Some(f)) = sub.wait(Duration::from_millis(100)) {
                let h = f.header();
                let ms = h.t_daemon_tx_ns.saturating_sub(h.t_ingress_ns) as f64 / 1e6;
                let key = h.applied().map(|a| (a.id, a.severity));
                if let Ok(mut s) = samples.lock() {
                    s.entry(key).or_default().push(ms);
                }
            }
        }
    }))
}

/// The sweep's rows (one per perturbation and severity in `keys`) and the overhead with every
/// perturbation off, from the latencies collected.
fn result(
    mut samples: HashMap<Option<(String, u8)>, Vec<f64>>,
    keys: &[(&'static Entry, u8)],
    dropped: Vec<u64>,
) -> Result<HilResult> {
    let off = samples.remove(&None).unwrap_or_default();
    if off.is_empty() {
        bail!("no frame came through the daemon with the perturbation off: is the bag replaying?");
    }
    let overhead_ms = off.iter().sum::<f64>() / off.len() as f64;
    let rows = keys
        .iter()
        .map(|(e, s)| {
            let mut v = samples
                .remove(&Some((e.id.to_string(), *s)))
                .unwrap_or_default();
            summarize(e, *s, &mut v)
        })
        .collect();
    Ok(HilResult {
        rows,
        overhead_ms,
        dropped,
    })
}
