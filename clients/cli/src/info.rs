//! `perturb info`.

use anyhow::{Result, bail};
use perturb_bag::{Bag, Filter, SensorMessage};
use perturb_core::formats::FileKind;
use perturb_study::files::{Loaded, load};
use std::collections::BTreeMap;
use std::ops::ControlFlow;
use std::path::{Path, PathBuf};

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
    if kind == FileKind::Mcap {
        bag_info(&a.input)
    } else {
        file_info(&a.input)
    }
}

/// One image or point-cloud file: its size, layout and the sensor model assumed for it.
fn file_info(path: &Path) -> Result<()> {
    match load(path)? {
        Loaded::Image(img, _) => println!("image {}x{} {}", img.width, img.height, img.format),
        Loaded::Cloud(c, kind, meta) => {
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
            let sensor = perturb_study::files::sensor_for(Some(kind), None, None, None)?;
            println!(
                "sensor model assumed: {} (from the file kind; --sensor, --forward and --intensity-max change it in the other commands)",
                sensor.describe()
            );
        }
    }
    Ok(())
}

/// A bag: its topics, what each sensor topic carries (every message decoded), notes and damage.
fn bag_info(path: &Path) -> Result<()> {
    let bag = Bag::open(path)?;
    println!(
        "bag {} ({}, {})",
        path.display(),
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
        match describe(&m) {
            Ok(Some(s)) => {
                summary.insert(m.topic.to_string(), s);
            }
            Ok(None) => {}
            Err(e) => errors.push(e),
        }
        Ok(ControlFlow::Continue(()))
    })?;
    for (t, s) in &summary {
        println!("  {t}: {s}");
    }
    if summary.values().any(|s| s.starts_with("point cloud")) {
        let sensor = perturb_study::files::sensor_for(None, None, None, None)?;
        println!(
            "sensor model assumed for the point clouds: {} (ROS convention; --sensor, --forward and --intensity-max change it in the other commands)",
            sensor.describe()
        );
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

/// What a sensor message carries (None for other messages), or why it is invalid.
fn describe(m: &perturb_bag::BagMessage<'_>) -> std::result::Result<Option<String>, String> {
    let invalid = |e: &dyn std::fmt::Display| format!("{} @ {}: {e}", m.topic, m.log_time);
    Ok(match m.decode() {
        Some(Ok(SensorMessage::Image(img))) => {
            let v = img.view().map_err(|e| invalid(&e))?;
            Some(describe_image(&v, img.encoding))
        }
        Some(Ok(SensorMessage::Compressed(c))) => Some(format!(
            "compressed image ({}, {} bytes)",
            c.format,
            c.data.len()
        )),
        Some(Ok(SensorMessage::Cloud(c))) => {
            let v = c.view().map_err(|e| invalid(&e))?;
            let names: Vec<&str> = v.layout().fields.iter().map(|f| f.name.as_str()).collect();
            Some(format!(
                "point cloud {} points, fields {}",
                v.len(),
                names.join(",")
            ))
        }
        Some(Err(e)) => return Err(e.to_string()),
        None => None,
    })
}

/// What an image message's encoding is, as the encoding table describes it: its name (and the
/// alias the message used), its layout, step and byte order, and the working view perturbations
/// run on.
fn describe_image(v: &perturb_core::encoding::EncodedView<'_>, written: &str) -> String {
    let e = v.encoding;
    let name = if written == e.name {
        e.name.to_string()
    } else {
        format!("{written} (= {})", e.name)
    };
    let order = if e.bits == 16 {
        if v.big_endian {
            ", big-endian"
        } else {
            ", little-endian"
        }
    } else {
        ""
    };
    let work = if e.is_working() {
        "perturbed in place".to_string()
    } else {
        format!("perturbed through an {} view", e.working_format())
    };
    format!(
        "image {}x{} {name}: {}, {} bits{order}, step {}; {work}",
        v.width, v.height, e.summary, e.bits, v.step
    )
}
