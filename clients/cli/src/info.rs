//! `perturb info`.

use anyhow::{Result, bail};
use perturb_bag::{Bag, Filter, SensorMessage};
use perturb_core::formats::FileKind;
use perturb_study::files::{Loaded, load};
use std::collections::BTreeMap;
use std::ops::ControlFlow;
use std::path::PathBuf;

/// Arguments of `perturb info`.
#[derive(clap::Args)]
pub struct Args {
    /// An image, point-cloud or bag file (or rosbag2 directory).
    input: PathBuf,
}

/// Prints what the file holds; every sensor message of a bag is decoded and checked.
pub fn run(a: Args) -> Result<()> {
    let kind = if a.input.is_dir() {
        FileKind::Mcap
    } else {
        FileKind::from_path(&a.input)?
    };
    if kind != FileKind::Mcap {
        match load(&a.input)? {
            Loaded::Image(img, _) => println!("image {}x{} {}", img.width, img.height, img.format),
            Loaded::Cloud(c, _, meta) => {
                let fields: Vec<String> = c
                    .layout
                    .fields
                    .iter()
                    .map(|f| format!("{}@{}:{:?}x{}", f.name, f.offset, f.datatype, f.count))
                    .collect();
                println!(
                    "point cloud {} points ({}x{}), point_step {}, fields {}{}",
                    c.len(),
                    c.height,
                    c.width,
                    c.layout.point_step,
                    fields.join(" "),
                    meta.map(|(d, _)| format!(", PCD data {d:?}"))
                        .unwrap_or_default()
                );
            }
        }
        return Ok(());
    }
    let bag = Bag::open(&a.input)?;
    println!(
        "bag {} ({}, {})",
        a.input.display(),
        bag.format_name(),
        if bag.is_indexed() {
            "indexed"
        } else {
            "no index: file order"
        }
    );
    for t in bag.topics()? {
        println!(
            "  {:<48} {:<34} {}",
            t.topic,
            t.type_name,
            t.message_count.map_or("?".into(), |n| n.to_string())
        );
    }
    let mut summary: BTreeMap<String, String> = BTreeMap::new();
    let mut errors = Vec::new();
    let report = bag.for_each(&Filter::default(), |m| {
        match m.decode() {
            Some(Ok(SensorMessage::Image(img))) => match img.view() {
                Ok(v) => {
                    summary.insert(
                        m.topic.to_string(),
                        format!("image {}x{} {}", v.width, v.height, v.format),
                    );
                }
                Err(e) => errors.push(format!("{} @ {}: {e}", m.topic, m.log_time)),
            },
            Some(Ok(SensorMessage::Compressed(c))) => {
                summary.insert(
                    m.topic.to_string(),
                    format!("compressed image ({}, {} bytes)", c.format, c.data.len()),
                );
            }
            Some(Ok(SensorMessage::Cloud(c))) => match c.view() {
                Ok(v) => {
                    let names: Vec<&str> =
                        v.layout().fields.iter().map(|f| f.name.as_str()).collect();
                    summary.insert(
                        m.topic.to_string(),
                        format!("point cloud {} points, fields {}", v.len(), names.join(",")),
                    );
                }
                Err(e) => errors.push(format!("{} @ {}: {e}", m.topic, m.log_time)),
            },
            Some(Err(e)) => errors.push(e.to_string()),
            None => {}
        }
        Ok(ControlFlow::Continue(()))
    })?;
    for (t, s) in &summary {
        println!("  {t}: {s}");
    }
    println!("{} messages read", report.delivered);
    for n in &report.notes {
        println!("note: {n}");
    }
    for e in &errors {
        eprintln!("invalid message: {e}");
    }
    if let Some(d) = report.damage {
        bail!("damaged bag: {d}");
    }
    if !errors.is_empty() {
        bail!("{} invalid messages", errors.len());
    }
    Ok(())
}
