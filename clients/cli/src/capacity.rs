//! `perturb bench --capacity CONFIG`: how many streams like the ones a daemon configuration names
//! a host sustains at their rates, from each stream's cost per frame measured on this host.
//!
//! The model (printed with the report): perturbd processes every stream's frames on one pool of
//! worker threads, one per core (streams with their own `threads` get their own pool). A frame
//! costs its perturbation `c` (ms on one core) plus its transport `t`: the copies of its bytes
//! made on the same host outside perturbd (`--transport-copies`, default 2: the bridge writing
//! the sensor's frame into shared memory, the egress sending the result; each timed here as a
//! copy of the frame). A stream of rate `r` (Hz) keeps `u = (c + t) * r / 1000` of a core busy.
//! A host of `N` cores of which `R` are kept for other work (`--reserve-cores`: the drivers, the
//! ADS) sustains a set of streams without drops while the sum of their `u` stays under
//! `(N - R) * headroom` (the rest absorbs the variance of the frame times and the operating
//! system; `--headroom`, default 0.65) and every frame's p99 fits its period (a frame is
//! processed by one thread unless the stream has `threads`). Streams of one kind alone:
//! `floor((N - R) * headroom / u)` of them; the configuration as a whole:
//! `floor((N - R) * headroom / sum(u))` copies of it.
//!
//! The headroom is calibrated against the live pipeline (`benches/capacity/check.py`): a frame in
//! perturbd costs more than the same perturbation timed here (5.5 against 4.85 ms for zoom blur
//! s5 at 800x503 on this project's VM, the process's CPU time over its frames, 98 % of it in the
//! perturbation's own code), so 0.75 predicted one stream too many on two cores; 0.65 holds.

use anyhow::{Context, Result, bail};
use perturb_core::bench::{Timing, cold_copies, time_camera_over, time_lidar_over};
use perturb_core::image::resize_bilinear;
use perturb_core::registry::{Modality, find};
use perturb_study::Format;
use perturb_study::files::{Loaded, load, sensor_for};
use perturbd::StreamConfig;
use std::path::Path;
use std::time::Instant;

/// What `--capacity` needs besides the configuration.
pub struct Options<'a> {
    /// Camera frame size the streams are measured at.
    pub width: u32,
    /// Camera frame height.
    pub height: u32,
    /// Camera frame rate (Hz).
    pub camera_hz: f64,
    /// LiDAR scan rate (Hz).
    pub lidar_hz: f64,
    /// Frames timed per stream.
    pub frames: usize,
    /// Share of the cores the model lets the streams take.
    pub headroom: f64,
    /// Copies of each frame's bytes made outside perturbd on the host (the transport).
    pub transport_copies: usize,
    /// Cores kept for other work, taken off every core count.
    pub reserve_cores: f64,
    /// Instances of each stream's perturbation timed in turn (the streams sharing a core).
    pub interleave: usize,
    /// The camera frame (any size; scaled to `width` x `height`).
    pub image: &'a Path,
    /// The LiDAR scan.
    pub cloud: &'a Path,
    /// Output format.
    pub format: Format,
}

/// One stream's measured cost and what it means for a host.
#[derive(Clone, Debug, serde::Serialize)]
pub struct StreamCost {
    /// Stream name.
    pub name: String,
    /// `camera` or `lidar`.
    pub modality: &'static str,
    /// Perturbation ID and severity, or `off`.
    pub perturbation: String,
    /// Frame measured (`800x503`, `115384 points`).
    pub frame: String,
    /// Frames per second.
    pub rate_hz: f64,
    /// Median cost of one frame's perturbation on one core (ms).
    pub cost_p50_ms: f64,
    /// 99th percentile (ms).
    pub cost_p99_ms: f64,
    /// Median cost of the frame's transport copies on the host (ms).
    pub transport_ms: f64,
    /// Cores it keeps busy at its rate: `(cost_p50_ms + transport_ms) * rate_hz / 1000`.
    pub load_cores: f64,
    /// Whether its p99 frame fits one period on the threads it has.
    pub fits_period: bool,
    /// How many streams like it alone a host sustains, for 1, 2, 4, 8 and 16 cores.
    pub alone: Vec<(usize, usize)>,
}

/// The report.
#[derive(Clone, Debug, serde::Serialize)]
pub struct Capacity {
    /// Per stream.
    pub streams: Vec<StreamCost>,
    /// Sum of the streams' loads (cores).
    pub load_cores: f64,
    /// The model's headroom.
    pub headroom: f64,
    /// Cores kept for other work.
    pub reserve_cores: f64,
    /// Copies of a frame counted as its transport.
    pub transport_copies: usize,
    /// Copies of the whole configuration a host sustains, for 1, 2, 4, 8 and 16 cores.
    pub copies: Vec<(usize, usize)>,
    /// This host's cores.
    pub host_cores: usize,
}

/// Core counts the report covers.
const CORES: [usize; 5] = [1, 2, 4, 8, 16];

/// How many streams of load `u` fit `cores` cores, `reserve` of them kept for other work, at
/// `headroom` (0 when one does not fit its period: no number of cores helps a stream whose
/// frames are longer than their period).
pub fn sustained(u: f64, cores: usize, reserve: f64, headroom: f64, fits_period: bool) -> usize {
    if !fits_period || u <= 0.0 {
        return if fits_period { usize::MAX } else { 0 };
    }
    let usable = (cores as f64 - reserve).max(0.0);
    (usable * headroom / u + 1e-9).floor() as usize
}

/// Measures every stream of the daemon configuration at `config` and prints the report.
pub fn run(config: &Path, o: &Options<'_>) -> Result<()> {
    let cfg = perturbd::Config::load(config).map_err(|e| anyhow::anyhow!("{e}"))?;
    if !(o.headroom > 0.0 && o.headroom <= 1.0) {
        bail!("--headroom {}: a share of the cores in (0, 1]", o.headroom);
    }
    if !(o.reserve_cores >= 0.0 && o.reserve_cores.is_finite()) {
        bail!(
            "--reserve-cores {}: a number of cores, 0 or more",
            o.reserve_cores
        );
    }
    let image = match load(o.image)? {
        Loaded::Image(img, _) if (img.width, img.height) == (o.width, o.height) => img,
        Loaded::Image(img, _) => resize_bilinear(&img.view(), o.width, o.height),
        _ => bail!("{}: not an image", o.image.display()),
    };
    let Loaded::Cloud(cloud, kind, _) = load(o.cloud)? else {
        bail!("{}: not a point cloud", o.cloud.display());
    };
    // One thread: the cost of a frame on one core, whatever this host has.
    let one = rayon::ThreadPoolBuilder::new().num_threads(1).build()?;
    one.install(|| measure(&cfg, o, &image, &cloud, kind))
        .and_then(|report| print(&report, config, o.format))
}

/// Every stream's cost and counts (on the calling thread's pool).
fn measure(
    cfg: &perturbd::Config,
    o: &Options<'_>,
    image: &perturb_core::image::Image,
    cloud: &perturb_core::cloud::Cloud,
    kind: perturb_core::formats::FileKind,
) -> Result<Capacity> {
    // Copies of the frame and the scan beyond the caches: a live frame arrives new from the
    // sensor, so every timed frame reads and writes memory the caches do not hold.
    let images = vec![image.clone(); cold_copies(image.data.len())];
    let image_views: Vec<_> = images.iter().map(|i| i.view()).collect();
    let clouds = vec![cloud.clone(); cold_copies(cloud.data.len())];
    let cloud_views: Vec<_> = clouds.iter().map(|c| c.view()).collect();
    let mut streams = Vec::new();
    for s in &cfg.streams {
        let (timing, copy, frame, rate) = match s.modality {
            Modality::Camera => (
                time_stream(s, |id, sev, seed| {
                    let e = find(id).context("unknown perturbation")?;
                    Ok(time_camera_over(
                        e,
                        sev,
                        seed,
                        &image_views,
                        o.frames,
                        o.interleave,
                    )?)
                })?,
                copy_cost(image.data.len(), o.frames),
                format!("{}x{}", o.width, o.height),
                o.camera_hz,
            ),
            Modality::Lidar => {
                let sensor = sensor_for(
                    Some(kind),
                    s.sensor.as_deref(),
                    s.forward.as_deref(),
                    s.intensity_max,
                )?;
                (
                    time_stream(s, |id, sev, seed| {
                        let e = find(id).context("unknown perturbation")?;
                        Ok(time_lidar_over(
                            e,
                            sev,
                            seed,
                            &sensor,
                            &cloud_views,
                            o.frames,
                            o.interleave,
                        )?)
                    })?,
                    copy_cost(cloud.data.len(), o.frames),
                    format!("{} points", cloud.len()),
                    o.lidar_hz,
                )
            }
        };
        // Perturbation off: perturbd copies the frame through.
        let timing = timing.unwrap_or(copy);
        let copy_ms = copy.0;
        let threads = s.threads.unwrap_or(1).max(1) as f64;
        let transport_ms = copy_ms * o.transport_copies as f64;
        let fits_period = timing.1 / threads + transport_ms <= 1000.0 / rate;
        let load_cores = (timing.0 + transport_ms) * rate / 1000.0;
        streams.push(StreamCost {
            name: s.name.clone(),
            modality: match s.modality {
                Modality::Camera => "camera",
                Modality::Lidar => "lidar",
            },
            perturbation: s
                .perturbation
                .as_ref()
                .map_or("off".into(), |p| format!("{} s{}", p.id, p.severity)),
            frame,
            rate_hz: rate,
            cost_p50_ms: timing.0,
            cost_p99_ms: timing.1,
            transport_ms,
            load_cores,
            fits_period,
            alone: CORES
                .iter()
                .map(|&n| {
                    (
                        n,
                        sustained(load_cores, n, o.reserve_cores, o.headroom, fits_period),
                    )
                })
                .collect(),
        });
    }
    let total: f64 = streams.iter().map(|s| s.load_cores).sum();
    let all_fit = streams.iter().all(|s| s.fits_period);
    Ok(Capacity {
        load_cores: total,
        headroom: o.headroom,
        reserve_cores: o.reserve_cores,
        transport_copies: o.transport_copies,
        copies: CORES
            .iter()
            .map(|&n| (n, sustained(total, n, o.reserve_cores, o.headroom, all_fit)))
            .collect(),
        host_cores: std::thread::available_parallelism().map_or(1, |n| n.get()),
        streams,
    })
}

/// The median and p99 (ms) of one stream's perturbation, `None` when it has none.
fn time_stream(
    s: &StreamConfig,
    time: impl Fn(&str, u8, u64) -> Result<Timing>,
) -> Result<Option<(f64, f64)>> {
    s.perturbation
        .as_ref()
        .map(|p| {
            let t = time(&p.id, p.severity, p.seed)
                .with_context(|| format!("stream {}: {} s{}", s.name, p.id, p.severity))?;
            Ok((t.median_ms, t.p99_ms))
        })
        .transpose()
}

/// One copy of a frame's `bytes` from memory to memory (median, p99 in ms), cycling over
/// buffers beyond the caches as the transport's copies of live frames do.
fn copy_cost(bytes: usize, frames: usize) -> (f64, f64) {
    let n = perturb_core::bench::cold_copies(bytes);
    let src: Vec<Vec<u8>> = (0..n).map(|_| vec![1u8; bytes]).collect();
    let mut dst: Vec<Vec<u8>> = (0..n).map(|_| vec![2u8; bytes]).collect(); // faulted in
    let mut ms: Vec<f64> = (0..frames.max(3))
        .map(|i| {
            let k = i % n;
            let t = Instant::now();
            dst[k].copy_from_slice(std::hint::black_box(&src[k]));
            std::hint::black_box(&dst[k]);
            t.elapsed().as_secs_f64() * 1e3
        })
        .collect();
    ms.sort_by(f64::total_cmp);
    let at = |q: f64| ms[((ms.len() - 1) as f64 * q).round() as usize];
    (at(0.5), at(0.99))
}

fn count(n: usize) -> String {
    if n == usize::MAX {
        "any".into()
    } else {
        n.to_string()
    }
}

fn print(r: &Capacity, config: &Path, format: Format) -> Result<()> {
    if format == Format::Json {
        println!("{}", serde_json::to_string_pretty(r)?);
        return Ok(());
    }
    println!(
        "capacity of {} on this host ({} cores), each stream's frame timed on one core:",
        config.display(),
        r.host_cores
    );
    println!(
        "{:<12} {:<10} {:<16} {:>7} {:>16} {:>9} {:>7} {:>6} | streams like it alone on 1/2/4/8/16 cores",
        "stream", "perturb", "frame", "Hz", "p50 / p99 ms", "transport", "cores", "fits"
    );
    for s in &r.streams {
        let alone: Vec<String> = s.alone.iter().map(|&(_, n)| count(n)).collect();
        println!(
            "{:<12} {:<10} {:<16} {:>7.1} {:>16} {:>9.2} {:>7.3} {:>6} | {}",
            s.name,
            s.perturbation,
            s.frame,
            s.rate_hz,
            format!("{:.2} / {:.2}", s.cost_p50_ms, s.cost_p99_ms),
            s.transport_ms,
            s.load_cores,
            if s.fits_period { "yes" } else { "NO" },
            alone.join(" / ")
        );
    }
    let copies: Vec<String> = r
        .copies
        .iter()
        .map(|&(n, k)| format!("{n} cores: {}", count(k)))
        .collect();
    println!(
        "the whole configuration keeps {:.3} cores busy; copies of it a host sustains: {}",
        r.load_cores,
        copies.join(", ")
    );
    println!(
        "model: one worker pool, one thread per core; a frame costs its perturbation plus its \
         transport ({} copies of its bytes on the host: the bridge's ingress and egress); a host \
         sustains streams while the sum of cost x rate stays under (cores - {}) x {:.2} (cores \
         kept for other work; headroom for frame-time variance and the OS) and each stream's \
         p99 frame plus transport fits its period (\"fits\"). Not counted: the sensors' \
         drivers and the ADS beyond the reserved cores; measure the whole host with the live \
         pipeline (perturb-e2e-bench load).",
        r.transport_copies, r.reserve_cores, r.headroom
    );
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn counts_follow_the_model() {
        // 5 ms at 30 Hz: 0.15 of a core; 0.75 of one core holds 5 of them, 2 cores 10.
        assert_eq!(sustained(0.15, 1, 0.0, 0.75, true), 5);
        assert_eq!(sustained(0.15, 2, 0.0, 0.75, true), 10);
        assert_eq!(sustained(0.15, 2, 0.0, 0.75, false), 0);
        assert_eq!(sustained(0.8, 1, 0.0, 0.75, true), 0);
        assert_eq!(sustained(0.0, 1, 0.0, 0.75, true), usize::MAX);
        // A core kept for the drivers: 4 cores hold what 3 would.
        assert_eq!(sustained(0.15, 4, 1.0, 0.75, true), 15);
        assert_eq!(sustained(0.15, 1, 2.0, 0.75, true), 0);
    }
}
