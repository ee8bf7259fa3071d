//! `perturb augment`: one perturbed variant per training sample, reproducible from a manifest.

use crate::batch::{Args as BatchArgs, select};
use crate::dataset::Dataset;
use crate::files::{Loaded, load, save_cloud, save_image, sensor_for};
use anyhow::{Context, Result, bail};
use perturb_core::perturber::{CameraPerturber, LidarPerturber};
use perturb_core::registry::Modality;
use perturb_core::rng::Rng;
use rayon::prelude::*;
use std::io::Write;
use std::path::PathBuf;

/// Salt of the draw of (perturbation, severity) per sample.
const DRAW_SALT: u64 = 0xA11C_3E47;

/// Arguments of `perturb augment`.
#[derive(clap::Args)]
#[command(after_help = "Example:
  perturb augment train_images/ --out augmented/ --id C-C8 --id C-C11 --id C-E1 --seed 1

For sample k (files in sorted order) a perturbation and severity are drawn uniformly from the
selection with the seed, and the perturbed variant is written as <name>__<ID>_s<N>.<ext> beside a copy
of the clean sample. augment_manifest.csv lists every output with its perturbation, severity, seed
and sequence number (= k), so each variant can be regenerated with `perturb apply`.")]
pub struct Args {
    /// A folder of images or point clouds.
    input: PathBuf,
    /// Output folder.
    #[arg(short, long)]
    out: PathBuf,
    /// Perturbation IDs or names to draw from (repeatable).
    #[arg(long = "id")]
    ids: Vec<String>,
    /// Families to draw from (repeatable).
    #[arg(long)]
    family: Vec<String>,
    /// Severities to draw from (repeatable; default all).
    #[arg(long = "severity")]
    severities: Vec<u8>,
    /// Seed of the draws and of the perturbations.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Do not copy the clean samples (write only the variants).
    #[arg(long)]
    no_clean: bool,
    /// LiDAR sensor model.
    #[arg(long)]
    sensor: Option<String>,
    /// LiDAR forward axis: +x, -x, +y or -y (default: +y for nuScenes .pcd.bin, +x otherwise).
    #[arg(long, allow_hyphen_values = true)]
    forward: Option<String>,
    /// LiDAR full-scale intensity, 1 or 255.
    #[arg(long)]
    intensity_max: Option<f32>,
}

/// Runs `perturb augment`.
pub fn run(a: Args) -> Result<()> {
    let Dataset::Files {
        root,
        files,
        modality,
    } = Dataset::open(&a.input)?
    else {
        bail!("augment works on a folder of images or point clouds, not on a bag");
    };
    let sel = BatchArgs {
        input: a.input.clone(),
        out: a.out.clone(),
        ids: a.ids.clone(),
        family: a.family.clone(),
        modality: (a.ids.is_empty() && a.family.is_empty()).then_some(modality),
        severities: a.severities.clone(),
        seed: a.seed,
        threads: None,
        sensor: a.sensor.clone(),
        forward: a.forward.clone(),
        intensity_max: a.intensity_max,
        topic: vec![],
        quiet: true,
        lidar_metrics: false,
    };
    let sets = select(&sel, &[modality])?;
    let sensor = if modality == Modality::Lidar {
        let kind = perturb_core::formats::FileKind::from_path(&files[0]).ok();
        Some(sensor_for(
            kind,
            a.sensor.as_deref(),
            a.forward.as_deref(),
            a.intensity_max,
            false,
        )?)
    } else {
        None
    };
    std::fs::create_dir_all(&a.out)
        .with_context(|| format!("cannot create {}", a.out.display()))?;
    let rows: Vec<String> = files
        .par_iter()
        .enumerate()
        .map(|(k, rel)| -> Result<String> {
            let set =
                sets[Rng::for_frame(a.seed, k as u64, DRAW_SALT).below(sets.len() as u64) as usize];
            let input = root.join(rel);
            let stem = rel.file_name().and_then(|n| n.to_str()).unwrap_or("sample");
            let (base, ext) = match stem.find('.') {
                Some(i) => (&stem[..i], &stem[i..]),
                None => (stem, ""),
            };
            let variant =
                rel.with_file_name(format!("{base}__{}_s{}{ext}", set.entry.id, set.severity));
            let out = a.out.join(&variant);
            if let Some(p) = out.parent() {
                std::fs::create_dir_all(p)?;
            }
            match load(&input)? {
                Loaded::Image(img, kind) => {
                    let o = CameraPerturber::new(set.entry.id, set.severity, a.seed)?
                        .apply_owned(&img.view(), k as u64)?;
                    save_image(&out, &o.view(), kind)?;
                }
                Loaded::Cloud(c, kind, meta) => {
                    let mut p = LidarPerturber::new(
                        set.entry.id,
                        set.severity,
                        a.seed,
                        sensor.clone().unwrap_or_default(),
                    )?;
                    let o = p.apply_owned(&c.view(), k as u64, None)?;
                    save_cloud(&out, &o.view(), kind, meta)?;
                }
            }
            if !a.no_clean {
                std::fs::copy(&input, a.out.join(rel))
                    .with_context(|| format!("cannot copy {}", input.display()))?;
            }
            Ok(format!(
                "{},{},{},{},{},{},{}",
                rel.display(),
                variant.display(),
                set.entry.id,
                set.entry.name,
                set.severity,
                a.seed,
                k
            ))
        })
        .collect::<Result<_>>()?;
    let path = a.out.join("augment_manifest.csv");
    let mut f =
        std::fs::File::create(&path).with_context(|| format!("cannot write {}", path.display()))?;
    writeln!(f, "sample,output,id,name,severity,seed,seq")?;
    for r in &rows {
        writeln!(f, "{r}")?;
    }
    eprintln!(
        "{} samples, {} variants{} written to {}",
        files.len(),
        rows.len(),
        if a.no_clean { "" } else { " and clean copies" },
        a.out.display()
    );
    Ok(())
}
