//! Timing of perturbations on real frames: the numbers behind `perturb bench` and the feasibility
//! report. Pure measurement over in-memory inputs; callers choose the thread pool (run inside a
//! one-thread rayon pool for single-core figures).

use crate::cloud::CloudView;
use crate::encoding::{EncodedView, Scratch};
use crate::error::Result;
use crate::image::ImageView;
use crate::perturber::{CameraPerturber, LidarPerturber};
use crate::registry::Entry;
use crate::sensor_model::SensorModel;
use std::time::{Duration, Instant};

/// Latency statistics of one perturbation at one severity.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct Timing {
    /// Perturbation ID.
    pub id: &'static str,
    /// Perturbation name.
    pub name: &'static str,
    /// Severity.
    pub severity: u8,
    /// Frames timed.
    pub frames: usize,
    /// Configuration (build) time in milliseconds, paid once.
    pub setup_ms: f64,
    /// Mean per-frame latency in milliseconds.
    pub mean_ms: f64,
    /// Median per-frame latency in milliseconds.
    pub median_ms: f64,
    /// 99th percentile in milliseconds.
    pub p99_ms: f64,
    /// Maximum in milliseconds.
    pub max_ms: f64,
}

/// Summary statistics of a list of durations (percentiles by [`crate::percentile`]).
pub fn summarize(
    id: &'static str,
    name: &'static str,
    severity: u8,
    setup: Duration,
    samples: &mut [Duration],
) -> Timing {
    samples.sort();
    let ms = |d: Duration| d.as_secs_f64() * 1e3;
    let n = samples.len().max(1);
    let pick = |q: f64| crate::percentile::of_sorted(samples, q).unwrap_or_default();
    Timing {
        id,
        name,
        severity,
        frames: samples.len(),
        setup_ms: ms(setup),
        mean_ms: samples.iter().map(|d| ms(*d)).sum::<f64>() / n as f64,
        median_ms: ms(pick(0.5)),
        p99_ms: ms(pick(0.99)),
        max_ms: samples.last().map_or(0.0, |d| ms(*d)),
    }
}

/// Times `frames` applications of a camera perturbation to `input` (sequence numbers 0, 1, ...),
/// after one untimed warm-up frame; the setup time is measured separately.
pub fn time_camera(
    entry: &'static Entry,
    severity: u8,
    seed: u64,
    input: &ImageView<'_>,
    frames: usize,
) -> Result<Timing> {
    time_camera_over(entry, severity, seed, &[*input], frames, 1)
}

/// Like [`time_camera`], frame `k` read from `inputs[k % n]` and written to its own output of
/// `n`, by perturber `k % instances` (each with its own tables and buffers, as the streams of a
/// daemon have): with copies of a frame whose total exceeds the caches, every frame is timed on
/// memory that is not in them, as a live frame arriving from a sensor is (see [`cold_copies`]),
/// and with several instances each one's buffers are evicted by the others' between its frames.
pub fn time_camera_over(
    entry: &'static Entry,
    severity: u8,
    seed: u64,
    inputs: &[ImageView<'_>],
    frames: usize,
    instances: usize,
) -> Result<Timing> {
    let first = inputs.first().expect("at least one input");
    let t0 = Instant::now();
    let mut ps = Vec::with_capacity(instances.max(1));
    for _ in 0..instances.max(1) {
        let mut p = CameraPerturber::new(entry.id, severity, seed)?;
        p.prepare(first.geometry())?;
        ps.push(p);
    }
    let setup = t0.elapsed() / ps.len() as u32;
    // Written once before timing, as reused shared-memory samples are: a fresh allocation's
    // first write per page is a page fault, which no live frame pays.
    let mut outs: Vec<_> = inputs
        .iter()
        .map(|i| {
            let mut o = crate::image::Image::with_geometry(i.geometry());
            o.data.fill(1);
            o
        })
        .collect();
    for p in &mut ps {
        p.apply(first, &mut outs[0].view_mut(), u64::MAX / 2)?;
    }
    let mut samples = Vec::with_capacity(frames);
    for seq in 0..frames as u64 {
        let k = seq as usize % inputs.len();
        let n = ps.len();
        let p = &mut ps[seq as usize % n];
        let t = Instant::now();
        p.apply(&inputs[k], &mut outs[k].view_mut(), seq)?;
        samples.push(t.elapsed());
    }
    Ok(summarize(
        entry.id,
        entry.name,
        severity,
        setup,
        &mut samples,
    ))
}

/// How many copies of a `bytes`-long frame (each with an output as large) make a working set of
/// 64 MiB, twice the last-level cache of a typical vehicle or server CPU: enough that cycling
/// through them reads and writes every frame from memory (at least 2).
pub fn cold_copies(bytes: usize) -> usize {
    ((64usize << 20) / (2 * bytes.max(1))).max(2)
}

/// The conversion pair of a frame in a non-working encoding (medians over the timed frames).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct ConversionTiming {
    /// Into the working view (demosaic, YUV to RGB, 16 to 8 bits), median ms.
    pub to_working_ms: f64,
    /// Back into the frame's encoding, median ms.
    pub write_back_ms: f64,
    /// Both, per frame, median ms.
    pub pair_ms: f64,
    /// The perturbation alone on the working view, median ms.
    pub perturbation_ms: f64,
}

/// Times `frames` applications of a camera perturbation to a frame in any encoding (see
/// [`crate::encoding`]), after one untimed warm-up frame: the [`Timing`] of the whole (working
/// view, perturbation, write-back) and the conversion pair's share.
pub fn time_camera_encoded(
    entry: &'static Entry,
    severity: u8,
    seed: u64,
    input: &EncodedView<'_>,
    frames: usize,
) -> Result<(Timing, ConversionTiming)> {
    let mut p = CameraPerturber::new(entry.id, severity, seed)?;
    let t0 = Instant::now();
    p.prepare(input.working_geometry())?;
    let setup = t0.elapsed();
    let mut scratch = Scratch::new();
    let mut work_out = crate::image::Image::with_geometry(input.working_geometry());
    let mut out = vec![0u8; input.data().len()];
    let mut phases = [Vec::new(), Vec::new(), Vec::new()];
    let mut whole = Vec::with_capacity(frames);
    for seq in std::iter::once(u64::MAX / 2).chain(0..frames as u64) {
        let t0 = Instant::now();
        let working = scratch.to_working(input);
        let t1 = Instant::now();
        p.apply(&working, &mut work_out.view_mut(), seq)?;
        let t2 = Instant::now();
        scratch.from_working(input, &work_out.view(), &mut out)?;
        let t3 = Instant::now();
        if seq != u64::MAX / 2 {
            for (v, d) in phases.iter_mut().zip([t1 - t0, t2 - t1, t3 - t2]) {
                v.push(d);
            }
            whole.push(t3 - t0);
        }
    }
    let median = |v: &mut Vec<Duration>| {
        v.sort();
        crate::percentile::of_sorted(v, 0.5).map_or(0.0, |d| d.as_secs_f64() * 1e3)
    };
    let mut pairs: Vec<Duration> = phases[0]
        .iter()
        .zip(&phases[2])
        .map(|(a, b)| *a + *b)
        .collect();
    let [to, perturb, back] = &mut phases;
    let conversion = ConversionTiming {
        to_working_ms: median(to),
        write_back_ms: median(back),
        pair_ms: median(&mut pairs),
        perturbation_ms: median(perturb),
    };
    let timing = summarize(entry.id, entry.name, severity, setup, &mut whole);
    Ok((timing, conversion))
}

/// Times `frames` applications of a LiDAR perturbation to `input`, writing into one reused
/// buffer. Object-level perturbations get their boxes the way the daemon does (see
/// [`LidarPerturber::apply`]), so the detector's cost is included where it is needed.
pub fn time_lidar(
    entry: &'static Entry,
    severity: u8,
    seed: u64,
    sensor: &SensorModel,
    input: &CloudView<'_>,
    frames: usize,
) -> Result<Timing> {
    time_lidar_over(
        entry,
        severity,
        seed,
        sensor,
        std::slice::from_ref(input),
        frames,
        1,
    )
}

/// Like [`time_lidar`], scan `k` read from `inputs[k % n]` and written to its own output of `n`,
/// by perturber `k % instances` (see [`time_camera_over`]).
pub fn time_lidar_over(
    entry: &'static Entry,
    severity: u8,
    seed: u64,
    sensor: &SensorModel,
    inputs: &[CloudView<'_>],
    frames: usize,
    instances: usize,
) -> Result<Timing> {
    let first = inputs.first().expect("at least one input");
    let t0 = Instant::now();
    let mut ps = Vec::with_capacity(instances.max(1));
    for _ in 0..instances.max(1) {
        ps.push(LidarPerturber::new(
            entry.id,
            severity,
            seed,
            sensor.clone(),
        )?);
    }
    let setup = t0.elapsed() / ps.len() as u32;
    let mut outs: Vec<Vec<u8>> = inputs
        .iter()
        .map(|i| vec![1u8; ps[0].max_output_bytes(i)])
        .collect();
    for p in &mut ps {
        p.apply(first, &mut outs[0], u64::MAX / 2, None)?;
    }
    let mut samples = Vec::with_capacity(frames);
    for seq in 0..frames as u64 {
        let k = seq as usize % inputs.len();
        let n = ps.len();
        let p = &mut ps[seq as usize % n];
        let t = Instant::now();
        p.apply(&inputs[k], &mut outs[k], seq, None)?;
        samples.push(t.elapsed());
    }
    Ok(summarize(
        entry.id,
        entry.name,
        severity,
        setup,
        &mut samples,
    ))
}
