//! `perturb bench`: latency of every perturbation at every severity on a real frame or scan.

use anyhow::{Context, Result, bail};
use perturb_core::bench::{ConversionTiming, Timing, time_camera, time_camera_encoded, time_lidar};
use perturb_core::encoding::{ENCODINGS, EncodedView, Encoding, from_image};
use perturb_core::image::resize_bilinear;
use perturb_core::registry::{Modality, of_modality};
use perturb_study::Format;
use perturb_study::files::{Loaded, describe_sensor, load, sensor_for};
use std::path::PathBuf;

/// Arguments of `perturb bench`.
#[derive(clap::Args)]
#[command(after_help = "Examples:
  perturb bench --modality camera                       # KITTI frame scaled to 1920x1208, one thread
  perturb bench --modality camera --width 800 --height 503 --json
  perturb bench --modality lidar --input scan.bin --threads 2
  perturb bench --modality camera --hil drive.mcap --window 10 --format markdown
  perturb bench --modality camera --encoding bayer_rggb8 --width 2064 --height 1544 --id C-C4
  perturb bench --modality camera --encoding all --id C-C4
  perturb bench --capacity config/vehicle-perturbd.toml --width 2064 --height 1544

Without --input the real KITTI frame or scan in ../shared/data is used. Times are per frame,
after a warm-up frame; setup (tables, textures, particle sets) is reported separately.

With --encoding E the frame is first made into encoding E (a Bayer mosaic, YUV 4:2:2, 16-bit
samples; `all` for every encoding that is not a working layout) and each frame is timed through
its working view: the table's times are the whole (conversion, perturbation, write-back), and a
line per encoding gives the conversion pair's median beside the perturbation's.

With --hil BAG the table is measured in the live pipeline instead: the bag is replayed (looped,
original timing) through perturb-bridge and perturbd (started as child processes, which must
be next to perturb), each perturbation and severity is active for --window seconds, and each
frame is timed from ingress publish to daemon publish (what the budget applies to). A first
window with everything off gives the middleware (node) overhead.")]
pub struct Args {
    /// camera or lidar.
    #[arg(long, required_unless_present = "capacity")]
    modality: Option<Modality>,
    /// Capacity report for this perturbd configuration: each stream's cost per frame on this
    /// host and how many such streams a host of N cores sustains at their rates.
    #[arg(long, value_name = "CONFIG", conflicts_with_all = ["modality", "hil", "encodings", "input"])]
    capacity: Option<PathBuf>,
    /// Camera frame rate of the capacity report (Hz).
    #[arg(long, default_value_t = 30.0)]
    camera_hz: f64,
    /// LiDAR scan rate of the capacity report (Hz).
    #[arg(long, default_value_t = 10.0)]
    lidar_hz: f64,
    /// Share of the cores the capacity model lets the streams take (the rest absorbs frame-time
    /// variance, the transport and the operating system).
    #[arg(long, default_value_t = 0.65)]
    headroom: f64,
    /// Capacity report: copies of each frame's bytes made on the host outside perturbd (the
    /// bridge writing the sensor's frame into shared memory, the egress sending the result),
    /// timed here and added to every frame's cost.
    #[arg(long, default_value_t = 2)]
    transport_copies: usize,
    /// Capacity report: cores kept for what else runs on the host (the sensors' drivers, the
    /// ADS), taken off every core count before the streams are fitted.
    #[arg(long, default_value_t = 0.0)]
    reserve_cores: f64,
    /// Capacity report: instances of each stream's perturbation timed in turn, each with its own
    /// buffers (the streams sharing a core evict each other's from the caches).
    #[arg(long, default_value_t = 8)]
    interleave: usize,
    /// Image width the input is scaled to (camera).
    #[arg(long, default_value_t = 1920)]
    width: u32,
    /// Image height the input is scaled to (camera).
    #[arg(long, default_value_t = 1208)]
    height: u32,
    /// Input image or point-cloud file (default: KITTI 000000 from ../shared/data).
    #[arg(long)]
    input: Option<PathBuf>,
    /// Frames timed per perturbation and severity.
    #[arg(long, default_value_t = 10)]
    frames: usize,
    /// Worker threads per frame (1 gives the single-core figure).
    #[arg(long, default_value_t = 1)]
    threads: usize,
    /// Only these IDs (repeatable).
    #[arg(long = "id")]
    ids: Vec<String>,
    /// For every perturbation and severity whose median frame misses the budget, time it again
    /// with 2, 3, ... threads up to this machine's cores and report how many it needs; beyond the
    /// cores, estimate the count from the measured speed-up (Amdahl's law, marked `~`).
    #[arg(long)]
    fit_threads: bool,
    /// Budget in milliseconds (default 33 for camera, 200 for LiDAR).
    #[arg(long)]
    budget_ms: Option<f64>,
    /// LiDAR sensor model (default: hdl64e for KITTI .bin, hdl32e for nuScenes .pcd.bin, vlp32c otherwise).
    #[arg(long)]
    sensor: Option<String>,
    /// LiDAR forward axis: +x, -x, +y or -y (default: +y for nuScenes .pcd.bin, +x otherwise).
    #[arg(long, allow_hyphen_values = true)]
    forward: Option<String>,
    /// Full-scale intensity of the cloud, 1 or 255.
    #[arg(long)]
    intensity_max: Option<f32>,
    /// Measure in the live pipeline: replay this rosbag2 MCAP bag through perturb-bridge and
    /// perturbd and sweep the perturbations (hardware-in-the-loop feasibility).
    #[arg(long)]
    hil: Option<PathBuf>,
    /// Seconds each perturbation and severity is active in --hil mode (the paper used 10).
    #[arg(long, default_value_t = 10.0)]
    window: f64,
    /// Print JSON (shorthand for --format json).
    #[arg(long)]
    json: bool,
    /// Report format.
    #[arg(long, value_enum, default_value_t = Format::Table)]
    format: Format,
    /// Camera: time frames in this encoding (repeatable; `all`: every encoding that is not a
    /// working layout), converted to the working view and back around the perturbation.
    #[arg(long = "encoding")]
    encodings: Vec<String>,
}

/// How many worker threads a perturbation needs for its median frame to fit the budget.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct Fit {
    /// The thread count.
    pub threads: usize,
    /// True when it is beyond this machine's cores, estimated from the measured speed-up.
    pub estimated: bool,
}

impl std::fmt::Display for Fit {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        if self.estimated {
            write!(f, "~{}", self.threads)
        } else {
            write!(f, "{}", self.threads)
        }
    }
}

/// The thread count at which Amdahl's law puts a frame that takes `t1` ms on one thread and
/// `tn` ms on `n` threads under `budget` ms: the serial share `s` solves `tn = t1 (s + (1 - s) /
/// n)`, and the count is the least `k` with `t1 (s + (1 - s) / k) <= budget`. `None` when the
/// serial part alone exceeds the budget or the measurements show no speed-up.
pub fn amdahl_threads(t1: f64, tn: f64, n: usize, budget: f64) -> Option<usize> {
    if t1 <= budget {
        return Some(1);
    }
    let n = n as f64;
    if n < 2.0 || tn >= t1 {
        return None;
    }
    let s = ((tn / t1 - 1.0 / n) / (1.0 - 1.0 / n)).clamp(0.0, 1.0);
    let room = budget / t1 - s;
    if room <= 0.0 {
        return None;
    }
    Some(((1.0 - s) / room).ceil().max(1.0) as usize)
}

#[derive(serde::Serialize)]
struct Row<'a> {
    #[serde(flatten)]
    timing: &'a Timing,
    /// --fit-threads: the threads the median frame needs to fit the budget.
    #[serde(skip_serializing_if = "Option::is_none")]
    threads_to_fit: Option<Fit>,
    budget_ms: f64,
    fits_budget: bool,
    /// --hil: mean latency with every perturbation off (the middleware alone).
    #[serde(skip_serializing_if = "Option::is_none")]
    node_overhead_ms: Option<f64>,
    /// --hil: frames the daemon dropped during the window.
    #[serde(skip_serializing_if = "Option::is_none")]
    dropped: Option<u64>,
    /// --encoding: the frame's encoding.
    #[serde(skip_serializing_if = "Option::is_none")]
    encoding: Option<&'static str>,
    /// --encoding: the conversion pair's medians.
    #[serde(flatten, skip_serializing_if = "Option::is_none")]
    conversion: Option<ConversionTiming>,
}

/// What only --hil measures.
struct Live<'a> {
    overhead_ms: f64,
    dropped: &'a [u64],
}

fn default_input(modality: Modality) -> Result<PathBuf> {
    let base = std::env::var_os("PERTURB_SHARED_DATA")
        .map_or_else(|| PathBuf::from("../shared/data"), PathBuf::from);
    let p = match modality {
        Modality::Camera => base.join("kitti/image_2/000000.png"),
        Modality::Lidar => base.join("kitti/velodyne/000000.bin"),
    };
    if !p.exists() {
        bail!(
            "no --input given and the default real input {} does not exist",
            p.display()
        );
    }
    Ok(p)
}

/// Runs the benchmark and prints the report.
pub fn run(a: Args) -> Result<()> {
    let format = if a.json { Format::Json } else { a.format };
    if let Some(config) = &a.capacity {
        let (image, cloud) = (
            default_input(Modality::Camera)?,
            default_input(Modality::Lidar)?,
        );
        return crate::capacity::run(
            config,
            &crate::capacity::Options {
                width: a.width,
                height: a.height,
                camera_hz: a.camera_hz,
                lidar_hz: a.lidar_hz,
                frames: a.frames,
                headroom: a.headroom,
                transport_copies: a.transport_copies,
                reserve_cores: a.reserve_cores,
                interleave: a.interleave,
                image: &image,
                cloud: &cloud,
                format,
            },
        );
    }
    let modality = a.modality.context("--modality is needed")?;
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(a.threads.max(1))
        .build()?;
    let budget = a.budget_ms.unwrap_or(match modality {
        Modality::Camera => 33.0,
        Modality::Lidar => 200.0,
    });
    let selected = |id: &str| a.ids.is_empty() || a.ids.iter().any(|i| i.eq_ignore_ascii_case(id));
    if let Some(bag) = &a.hil {
        let entries: Vec<_> = of_modality(modality).filter(|e| selected(e.id)).collect();
        if entries.is_empty() {
            bail!("no perturbation selected");
        }
        let sensor = a.sensor.as_deref().unwrap_or("vlp32c");
        let r = crate::hil::sweep(bag, modality, &entries, a.window, sensor)?;
        let live = Live {
            overhead_ms: r.overhead_ms,
            dropped: &r.dropped,
        };
        return print_report(&r.rows, budget, format, Some(&live), &[]);
    }
    let input = match &a.input {
        Some(p) => p.clone(),
        None => default_input(modality)?,
    };
    let (rows, fits): (Vec<Timing>, Vec<Option<Fit>>);
    match (modality, load(&input)?) {
        (Modality::Camera, Loaded::Image(img, _)) => {
            let frame = if (img.width, img.height) == (a.width, a.height) {
                img
            } else {
                resize_bilinear(&img.view(), a.width, a.height)
            };
            eprintln!(
                "camera bench on {} scaled to {}x{}, {} thread(s)",
                input.display(),
                a.width,
                a.height,
                a.threads
            );
            if !a.encodings.is_empty() {
                let encodings = chosen_encodings(&a.encodings)?;
                return bench_encodings(&a, budget, format, &pool, &frame, &encodings);
            }
            let entries = of_modality(Modality::Camera).filter(|e| selected(e.id));
            (rows, fits) = time_all(entries, &a, budget, &pool, |e, s, pool| {
                pool.install(|| time_camera(e, s, 1, &frame.view(), a.frames))
            })?;
        }
        (Modality::Lidar, Loaded::Cloud(cloud, kind, _)) => {
            let sensor = sensor_for(
                Some(kind),
                a.sensor.as_deref(),
                a.forward.as_deref(),
                a.intensity_max,
            )?;
            eprintln!("{}", describe_sensor(&sensor));
            eprintln!(
                "lidar bench on {} ({} points), {} thread(s)",
                input.display(),
                cloud.len(),
                a.threads
            );
            let entries = of_modality(Modality::Lidar).filter(|e| selected(e.id));
            (rows, fits) = time_all(entries, &a, budget, &pool, |e, s, pool| {
                pool.install(|| time_lidar(e, s, 1, &sensor, &cloud.view(), a.frames))
            })?;
        }
        (m, _) => bail!(
            "{} is not {} input",
            input.display(),
            if m == Modality::Camera {
                "image"
            } else {
                "point-cloud"
            }
        ),
    }
    print_report(&rows, budget, format, None, &fits)
}

/// The encodings `--encoding` names (`all`: every encoding that is not a working layout).
fn chosen_encodings(names: &[String]) -> Result<Vec<&'static Encoding>> {
    let mut out = Vec::new();
    for n in names {
        if n == "all" {
            out.extend(ENCODINGS.iter().filter(|e| !e.is_working()));
        } else {
            out.push(Encoding::find(n)?);
        }
    }
    Ok(out)
}

/// `--encoding`: every selected perturbation timed on `frame` made into each encoding, through
/// its working view; the conversion pair's cost per encoding beside the perturbation's.
fn bench_encodings(
    a: &Args,
    budget: f64,
    format: Format,
    pool: &rayon::ThreadPool,
    frame: &perturb_core::image::Image,
    encodings: &[&'static Encoding],
) -> Result<()> {
    let selected = |id: &str| a.ids.is_empty() || a.ids.iter().any(|i| i.eq_ignore_ascii_case(id));
    let (mut rows, mut conv, mut names) = (Vec::new(), Vec::new(), Vec::new());
    let mut lines = Vec::new();
    for &e in encodings {
        let step = e.row_bytes(frame.width);
        let data = from_image(&frame.view(), e, step, false)?;
        let input = EncodedView::new(&data, frame.width, frame.height, step, e, false)?;
        let first = rows.len();
        for entry in of_modality(Modality::Camera).filter(|x| selected(x.id)) {
            for s in entry.severities() {
                let (t, c) = pool
                    .install(|| time_camera_encoded(entry, s, 1, &input, a.frames))
                    .with_context(|| format!("{} severity {s} on {e}", entry.id))?;
                rows.push(t);
                conv.push(c);
                names.push(e.name);
            }
        }
        let mid = |f: fn(&ConversionTiming) -> f64| {
            let mut v: Vec<f64> = conv[first..].iter().map(f).collect();
            if v.is_empty() {
                0.0
            } else {
                perturb_core::percentile::of_f64(&mut v, 0.5)
            }
        };
        lines.push(format!(
            "{:<13} {}x{}: conversion pair {:.2} ms (to {} {:.2} ms, back {:.2} ms) beside the perturbation's {:.2} ms (medians over {} rows)",
            e.name,
            frame.width,
            frame.height,
            mid(|c| c.pair_ms),
            e.working_format(),
            mid(|c| c.to_working_ms),
            mid(|c| c.write_back_ms),
            mid(|c| c.perturbation_ms),
            rows.len() - first
        ));
    }
    if format == Format::Json {
        let out: Vec<Row<'_>> = rows
            .iter()
            .enumerate()
            .map(|(i, t)| Row {
                timing: t,
                threads_to_fit: None,
                budget_ms: budget,
                fits_budget: t.max_ms <= budget,
                node_overhead_ms: None,
                dropped: None,
                encoding: Some(names[i]),
                conversion: Some(conv[i]),
            })
            .collect();
        println!("{}", serde_json::to_string_pretty(&out)?);
        return Ok(());
    }
    for l in &lines {
        println!("{l}");
    }
    if format == Format::Csv {
        println!(
            "encoding,id,severity,whole_median_ms,perturbation_ms,to_working_ms,write_back_ms,pair_ms"
        );
        for ((t, c), n) in rows.iter().zip(&conv).zip(&names) {
            println!(
                "{n},{},{},{:.3},{:.3},{:.3},{:.3},{:.3}",
                t.id,
                t.severity,
                t.median_ms,
                c.perturbation_ms,
                c.to_working_ms,
                c.write_back_ms,
                c.pair_ms
            );
        }
        return Ok(());
    }
    println!("(the table: the whole frame, conversion and perturbation together)");
    print_table(&rows, budget, format == Format::Markdown, None, &[]);
    Ok(())
}

/// Times every severity of `entries` on `pool` with `time`, and with `--fit-threads` the threads
/// each needs to fit `budget` (one entry per row then, none otherwise).
fn time_all<'e>(
    entries: impl Iterator<Item = &'e perturb_core::registry::Entry>,
    a: &Args,
    budget: f64,
    pool: &rayon::ThreadPool,
    time: impl Fn(
        &'e perturb_core::registry::Entry,
        u8,
        &rayon::ThreadPool,
    ) -> perturb_core::Result<Timing>,
) -> Result<(Vec<Timing>, Vec<Option<Fit>>)> {
    let (mut rows, mut fits) = (Vec::new(), Vec::new());
    for e in entries {
        for s in e.severities() {
            let t = time(e, s, pool).with_context(|| format!("{} severity {s}", e.id))?;
            if a.fit_threads {
                fits.push(threads_to_fit(&t, a.threads, budget, |pool| {
                    time(e, s, pool)
                })?);
            }
            rows.push(t);
        }
    }
    Ok((rows, fits))
}

/// The threads `t` (measured with `base` threads) needs for its median frame to fit `budget`:
/// `None` when it fits already; measured with more threads up to this machine's cores, then
/// estimated from the last two measurements.
fn threads_to_fit(
    t: &Timing,
    base: usize,
    budget: f64,
    time: impl Fn(&rayon::ThreadPool) -> perturb_core::Result<Timing>,
) -> Result<Option<Fit>> {
    if t.median_ms <= budget {
        return Ok(None);
    }
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    let (mut n, mut tn) = (base.max(1), t.median_ms);
    let t1 = if n == 1 { Some(t.median_ms) } else { None };
    let mut t1 = t1;
    while n < cores {
        n += 1;
        let pool = rayon::ThreadPoolBuilder::new().num_threads(n).build()?;
        tn = time(&pool)?.median_ms;
        if tn <= budget {
            return Ok(Some(Fit {
                threads: n,
                estimated: false,
            }));
        }
    }
    if t1.is_none() {
        let pool = rayon::ThreadPoolBuilder::new().num_threads(1).build()?;
        t1 = Some(time(&pool)?.median_ms);
    }
    let t1 = t1.unwrap_or(t.median_ms);
    Ok(amdahl_threads(t1, tn, n, budget).map(|k| Fit {
        threads: k.max(n + 1),
        estimated: true,
    }))
}

fn print_report(
    rows: &[Timing],
    budget: f64,
    format: Format,
    live: Option<&Live>,
    fits: &[Option<Fit>],
) -> Result<()> {
    match format {
        Format::Json => print_json(rows, budget, live, fits)?,
        Format::Csv => print_csv(rows, budget, live, fits),
        Format::Table | Format::Markdown => {
            print_table(rows, budget, format == Format::Markdown, live, fits)
        }
    }
    Ok(())
}

/// The threads row `i` needs to fit, if it was measured or estimated.
fn fit_of(fits: &[Option<Fit>], i: usize) -> Option<Fit> {
    fits.get(i).copied().flatten()
}

/// One JSON object per perturbation and severity.
fn print_json(
    rows: &[Timing],
    budget: f64,
    live: Option<&Live>,
    fits: &[Option<Fit>],
) -> Result<()> {
    let fit_of = |i: usize| fit_of(fits, i);
    let out: Vec<Row<'_>> = rows
        .iter()
        .enumerate()
        .map(|(i, t)| Row {
            timing: t,
            threads_to_fit: fit_of(i),
            budget_ms: budget,
            fits_budget: t.max_ms <= budget,
            node_overhead_ms: live.map(|l| l.overhead_ms),
            dropped: live.and_then(|l| l.dropped.get(i).copied()),
            encoding: None,
            conversion: None,
        })
        .collect();
    println!("{}", serde_json::to_string_pretty(&out)?);
    Ok(())
}

/// One CSV line per perturbation and severity, after the header.
fn print_csv(rows: &[Timing], budget: f64, live: Option<&Live>, fits: &[Option<Fit>]) {
    let fit_of = |i: usize| fit_of(fits, i);
    let fit_cell = |f: Option<Fit>| f.map_or("-".to_string(), |f| f.to_string());
    println!(
        "id,name,severity,frames,setup_ms,mean_ms,median_ms,p99_ms,max_ms,budget_ms,fits_budget{}{}",
        if live.is_some() {
            ",node_overhead_ms,dropped"
        } else {
            ""
        },
        if fits.is_empty() {
            ""
        } else {
            ",threads_to_fit"
        }
    );
    for (i, t) in rows.iter().enumerate() {
        let extra = live
            .map(|l| {
                format!(
                    ",{:.3},{}",
                    l.overhead_ms,
                    l.dropped.get(i).copied().unwrap_or(0)
                )
            })
            .unwrap_or_default();
        let extra = if fits.is_empty() {
            extra
        } else {
            format!("{extra},{}", fit_cell(fit_of(i)))
        };
        println!(
            "{},{},{},{},{:.3},{:.3},{:.3},{:.3},{:.3},{},{}{extra}",
            t.id,
            t.name,
            t.severity,
            t.frames,
            t.setup_ms,
            t.mean_ms,
            t.median_ms,
            t.p99_ms,
            t.max_ms,
            budget,
            t.max_ms <= budget
        );
    }
}

/// One line per perturbation (the severities folded: mean of means, max of medians and maxima),
/// as a text table or markdown, and the summary line.
fn print_table(rows: &[Timing], budget: f64, md: bool, live: Option<&Live>, fits: &[Option<Fit>]) {
    let fit_of = |i: usize| fit_of(fits, i);
    if let Some(l) = live {
        println!(
            "live pipeline (bag replay -> perturbd): latency = ingress publish -> daemon publish; \
             middleware (node) overhead with every perturbation off: {:.3} ms mean; frames dropped by the daemon: {}{}",
            l.overhead_ms,
            l.dropped.iter().sum::<u64>(),
            if md { "\n" } else { "" }
        );
    }
    let mut ids: Vec<&'static str> = rows.iter().map(|t| t.id).collect();
    ids.dedup();
    let with_fit = !fits.is_empty();
    if md {
        println!(
            "| id | name | mean ms (avg over severities) | median ms (max over severities) | max ms | setup ms | fits {budget} ms |{}",
            if with_fit { " threads to fit |" } else { "" }
        );
        println!(
            "|---|---|---:|---:|---:|---:|:---:|{}",
            if with_fit { "---:|" } else { "" }
        );
    } else {
        println!(
            "{:<7} {:<24} {:>9} {:>10} {:>9} {:>9}  fits {budget} ms{}",
            "id",
            "name",
            "mean_ms",
            "median_ms",
            "max_ms",
            "setup_ms",
            if with_fit { "  threads to fit" } else { "" }
        );
    }
    let mut fits_all = 0;
    for id in &ids {
        let rs: Vec<&Timing> = rows.iter().filter(|t| t.id == *id).collect();
        // The most threads any severity needs (an estimate wins over a measurement of
        // the same count: it is the less certain figure).
        let need = rows
            .iter()
            .enumerate()
            .filter(|(_, t)| t.id == *id)
            .filter_map(|(i, _)| fit_of(i))
            .max_by_key(|f| (f.threads, f.estimated));
        let need = if with_fit {
            let cell = need.map_or_else(|| "1".to_string(), |f| f.to_string());
            if md {
                format!(" {cell} |")
            } else {
                format!("  {cell:>6}")
            }
        } else {
            String::new()
        };
        let mean = rs.iter().map(|t| t.mean_ms).sum::<f64>() / rs.len() as f64;
        let med = rs.iter().map(|t| t.median_ms).fold(0.0, f64::max);
        let max = rs.iter().map(|t| t.max_ms).fold(0.0, f64::max);
        let setup = rs.iter().map(|t| t.setup_ms).fold(0.0, f64::max);
        let fits = max <= budget;
        fits_all += fits as usize;
        let mark = if fits { "yes" } else { "NO" };
        if md {
            println!(
                "| {} | {} | {mean:.2} | {med:.2} | {max:.2} | {setup:.1} | {mark} |{need}",
                id, rs[0].name
            );
        } else {
            println!(
                "{:<7} {:<24} {mean:>9.2} {med:>10.2} {max:>9.2} {setup:>9.1}  {mark}{need}",
                id, rs[0].name
            );
        }
    }
    // The project's one percentile definition (nearest rank), as every other report.
    let mut medians: Vec<f64> = rows.iter().map(|t| t.median_ms).collect();
    let median = if medians.is_empty() {
        0.0
    } else {
        perturb_core::percentile::of_f64(&mut medians, 0.5)
    };
    println!(
        "{}{fits_all}/{} perturbations fit {budget} ms at every severity; median over all rows {median:.2} ms",
        if md { "\n" } else { "" },
        ids.len()
    );
}

#[cfg(test)]
mod tests {
    use super::amdahl_threads;

    #[test]
    fn amdahl_counts_follow_the_measured_speed_up() {
        // Perfectly parallel: 100 ms on one thread, 50 on two: 4 threads for 25 ms, 4 for 30.
        assert_eq!(amdahl_threads(100.0, 50.0, 2, 25.0), Some(4));
        assert_eq!(amdahl_threads(100.0, 50.0, 2, 30.0), Some(4));
        // A fifth serial: 100 -> 60 ms on two threads; 33 ms needs ceil(0.8 / 0.13) = 7.
        assert_eq!(amdahl_threads(100.0, 60.0, 2, 33.0), Some(7));
        // The serial part alone (60 %) misses a 50 ms budget; no speed-up gives no count.
        assert_eq!(amdahl_threads(100.0, 80.0, 2, 50.0), None);
        assert_eq!(amdahl_threads(100.0, 100.0, 2, 50.0), None);
        // Already fits.
        assert_eq!(amdahl_threads(20.0, 15.0, 2, 33.0), Some(1));
    }
}
