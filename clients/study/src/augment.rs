//! Training data for fine-tuning (paper, RQ4): one perturbed variant per training sample,
//! reproducible from a manifest.
//!
//! For sample k (files in sorted order) a perturbation and severity are drawn uniformly from the
//! selection with the seed, and the perturbed variant is written as `<name>__<ID>_s<N>.<ext>`
//! beside a copy of the clean sample. `augment_manifest.csv` lists every output with its
//! perturbation, severity, seed and sequence number (= k), so each variant can be regenerated
//! with `perturb apply`.

use crate::batch::{Selection, Set, select};
use crate::dataset::Dataset;
use crate::error::{Result, StudyError};
use crate::files::{Loaded, load, save_cloud, save_image, sensor_for};
use crate::progress::Progress;
use perturb_core::perturber::{CameraPerturber, LidarPerturber};
use perturb_core::registry::Modality;
use perturb_core::rng::Rng;
use perturb_core::sensor_model::SensorModel;
use rayon::prelude::*;
use std::path::{Path, PathBuf};

/// Salt of the draw of (perturbation, severity) per sample.
const DRAW_SALT: u64 = 0xA11C_3E47;

/// What `perturb augment` does.
#[derive(Clone, Debug, Default)]
pub struct AugmentOptions {
    /// A folder of images or point clouds.
    pub input: PathBuf,
    /// Output folder.
    pub out: PathBuf,
    /// Perturbation IDs or names to draw from.
    pub ids: Vec<String>,
    /// Families to draw from.
    pub families: Vec<String>,
    /// Severities to draw from (empty: all).
    pub severities: Vec<u8>,
    /// Seed of the draws and of the perturbations.
    pub seed: u64,
    /// Do not copy the clean samples (write only the variants).
    pub no_clean: bool,
    /// LiDAR sensor model.
    pub sensor: Option<String>,
    /// LiDAR forward axis (`+x`, `-x`, `+y`, `-y`; default per file kind).
    pub forward: Option<String>,
    /// LiDAR full-scale intensity, 1 or 255.
    pub intensity_max: Option<f32>,
}

/// What an augmentation wrote.
#[derive(Clone, Debug)]
pub struct AugmentOutcome {
    /// Samples of the input.
    pub samples: usize,
    /// Variants written (one per sample).
    pub variants: usize,
    /// `OUT/augment_manifest.csv`.
    pub manifest: PathBuf,
}

/// Writes the variants and the manifest (samples in parallel on the current rayon pool).
pub fn run(a: &AugmentOptions, progress: &dyn Progress) -> Result<AugmentOutcome> {
    let Dataset::Files {
        root,
        files,
        modality,
    } = Dataset::open(&a.input)?
    else {
        return Err(StudyError::input(
            &a.input,
            "augment works on a folder of images or point clouds, not on a bag",
        ));
    };
    let sel = Selection {
        ids: a.ids.clone(),
        families: a.families.clone(),
        modality: (a.ids.is_empty() && a.families.is_empty()).then_some(modality),
        severities: a.severities.clone(),
    };
    let sets = select(&sel, &[modality])?;
    let sensor = if modality == Modality::Lidar {
        let kind = perturb_core::formats::FileKind::from_path(&files[0]).ok();
        let s = sensor_for(
            kind,
            a.sensor.as_deref(),
            a.forward.as_deref(),
            a.intensity_max,
        )?;
        progress.note(&crate::files::describe_sensor(&s));
        Some(s)
    } else {
        None
    };
    std::fs::create_dir_all(&a.out).map_err(StudyError::io(&a.out))?;
    progress.set_length(files.len() as u64);
    let rows: Vec<String> = files
        .par_iter()
        .enumerate()
        .map(|(k, rel)| -> Result<String> {
            let set =
                sets[Rng::for_frame(a.seed, k as u64, DRAW_SALT).below(sets.len() as u64) as usize];
            let row = augment_one(a, &root, rel, k as u64, set, sensor.as_ref())?;
            progress.inc(1);
            Ok(row)
        })
        .collect::<Result<_>>()?;
    let path = a.out.join("augment_manifest.csv");
    let mut text = String::from("sample,output,id,name,severity,seed,seq\n");
    for r in &rows {
        text.push_str(r);
        text.push('\n');
    }
    std::fs::write(&path, text).map_err(StudyError::io(&path))?;
    progress.finish();
    Ok(AugmentOutcome {
        samples: files.len(),
        variants: rows.len(),
        manifest: path,
    })
}

/// Writes sample `rel` (the `k`th) perturbed with `set` (and, unless `no_clean`, a clean copy)
/// under the output folder; returns its manifest row.
fn augment_one(
    a: &AugmentOptions,
    root: &Path,
    rel: &Path,
    k: u64,
    set: Set,
    sensor: Option<&SensorModel>,
) -> Result<String> {
    let input = root.join(rel);
    let stem = rel.file_name().and_then(|n| n.to_str()).unwrap_or("sample");
    let (base, ext) = match stem.find('.') {
        Some(i) => (&stem[..i], &stem[i..]),
        None => (stem, ""),
    };
    let variant = rel.with_file_name(format!("{base}__{}_s{}{ext}", set.entry.id, set.severity));
    let out = a.out.join(&variant);
    if let Some(p) = out.parent() {
        std::fs::create_dir_all(p).map_err(StudyError::io(p))?;
    }
    let perturbing = || format!("perturbing {}", input.display());
    match load(&input)? {
        Loaded::Image(img, kind) => {
            let o = CameraPerturber::new(set.entry.id, set.severity, a.seed)?
                .apply_owned(&img.view(), k)
                .map_err(StudyError::perturb(perturbing()))?;
            save_image(&out, &o.view(), kind)?;
        }
        Loaded::Cloud(c, kind, meta) => {
            let mut p = LidarPerturber::new(
                set.entry.id,
                set.severity,
                a.seed,
                sensor.cloned().unwrap_or_default(),
            )?;
            let o = p
                .apply_owned(&c.view(), k, None)
                .map_err(StudyError::perturb(perturbing()))?;
            save_cloud(&out, &o.view(), kind, meta)?;
        }
    }
    if !a.no_clean {
        let clean = a.out.join(rel);
        std::fs::copy(&input, &clean).map_err(|e| {
            StudyError::input(&input, format!("cannot copy to {}: {e}", clean.display()))
        })?;
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
}
