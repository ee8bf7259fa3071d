//! `perturb-test-sink`: a subscriber process for the end-to-end tests. Subscribes to one
//! service of a daemon configuration's stream and writes every frame it receives to a folder:
//! the valid payload bytes as `<seq>.bin` and one JSON line per frame in `frames.jsonl`
//! (sequence number, stamp, frame_id, geometry, applied perturbation, hop timestamps).
//!
//! Prints `ready` on stdout once subscribed. Stops after `--idle` seconds without a frame (once at
//! least one arrived), after `--max` frames, or on SIGTERM/SIGINT.

use clap::Parser;
use perturb_tests::FrameRecord;
use perturb_wire::{Transport, TransportOptions};
use std::io::Write;
use std::path::PathBuf;
use std::time::{Duration, Instant};

/// Writes the frames of one stream service to a folder.
#[derive(Parser)]
struct Args {
    /// The daemon configuration (for the stream's services and QoS).
    #[arg(long)]
    config: PathBuf,
    /// Stream name.
    #[arg(long)]
    stream: String,
    /// Subscribe to the raw input instead of the perturbed output.
    #[arg(long)]
    raw: bool,
    /// Output folder.
    #[arg(long)]
    out: PathBuf,
    /// Seconds without a frame (after the first) before stopping.
    #[arg(long, default_value_t = 5.0)]
    idle: f64,
    /// Seconds to wait for the first frame.
    #[arg(long, default_value_t = 60.0)]
    first: f64,
    /// Stop after this many frames.
    #[arg(long)]
    max: Option<usize>,
}

fn main() -> anyhow::Result<()> {
    let a = Args::parse();
    let cfg = perturbd::Config::load(&a.config).map_err(|e| anyhow::anyhow!("{e}"))?;
    let stream = cfg
        .streams
        .iter()
        .find(|s| s.name == a.stream)
        .ok_or_else(|| anyhow::anyhow!("no stream `{}` in {}", a.stream, a.config.display()))?;
    let service = if a.raw {
        stream.input_service()
    } else {
        stream.output_service()
    };
    let opts: TransportOptions = cfg.transport.clone().with_env_overrides();
    let t = Transport::open("test_sink", &opts)?;
    let sub = t.subscriber(&service, &stream.qos, None)?;
    std::fs::create_dir_all(&a.out)?;
    let mut log = std::fs::File::create(a.out.join("frames.jsonl"))?;
    println!("ready");
    std::io::stdout().flush()?;
    let mut n = 0usize;
    let mut last = Instant::now();
    loop {
        let limit = if n == 0 { a.first } else { a.idle };
        if last.elapsed().as_secs_f64() > limit || a.max.is_some_and(|m| n >= m) {
            break;
        }
        match sub.wait(Duration::from_millis(200)) {
            Ok(Some(frame)) => {
                let h = frame.header();
                let data = frame.data().unwrap_or(frame.payload());
                std::fs::write(a.out.join(format!("{}.bin", h.seq)), data)?;
                let rec = FrameRecord::from_header(h);
                writeln!(log, "{}", serde_json::to_string(&rec)?)?;
                log.flush()?;
                n += 1;
                last = Instant::now();
            }
            Ok(None) => {}
            Err(e) => {
                eprintln!("sink: {e}");
                if !e.is_borrow_limit() {
                    std::thread::sleep(Duration::from_millis(50));
                }
            }
        }
    }
    eprintln!("sink: {n} frame(s) from `{service}`");
    Ok(())
}
