//! The paper's figure 1 for any frame: every perturbation at every severity on one frame or
//! scan, as one picture (bird's-eye views for LiDAR, clean beside perturbed).

use crate::error::{Result, StudyError};
use crate::files::{Loaded, load, sensor_for};
use crate::progress::Progress;
use perturb_core::image::Image;
use perturb_core::perturber::{CameraPerturber, LidarPerturber};
use perturb_core::registry::{Entry, Modality, of_modality};
use perturb_core::viz::{Cell, ColorBy, bird_eye_view, contact_sheet};
use rayon::prelude::*;
use std::path::PathBuf;

/// What the gallery shows.
#[derive(Clone, Debug)]
pub struct GalleryOptions {
    /// An image or point-cloud file.
    pub input: PathBuf,
    /// Only these IDs (all of the input's modality when empty).
    pub ids: Vec<String>,
    /// Width of one cell in pixels.
    pub cell_width: u32,
    /// Seed.
    pub seed: u64,
    /// Frame sequence number.
    pub seq: u64,
    /// LiDAR: colour points by height or intensity.
    pub color_by: ColorBy,
    /// LiDAR: half-width of the bird's-eye view in metres.
    pub range: f32,
    /// LiDAR sensor model.
    pub sensor: Option<String>,
    /// LiDAR forward axis (`+x`, `-x`, `+y`, `-y`; default per file kind).
    pub forward: Option<String>,
    /// LiDAR full-scale intensity, 1 or 255.
    pub intensity_max: Option<f32>,
}

fn selected(a: &GalleryOptions, m: Modality) -> Vec<&'static Entry> {
    of_modality(m)
        .filter(|e| a.ids.is_empty() || a.ids.iter().any(|i| i.eq_ignore_ascii_case(e.id)))
        .collect()
}

/// Renders the contact sheet; a perturbation that fails on this input is left out with a note.
pub fn render(a: &GalleryOptions, progress: &dyn Progress) -> Result<Image> {
    let label = |e: &Entry, s: u8| format!("{} {} S{s}", e.id, e.name);
    let sheet = match load(&a.input)? {
        Loaded::Image(img, _) => {
            let entries = selected(a, Modality::Camera);
            if entries.is_empty() {
                return Err(StudyError::Config("no camera perturbation selected".into()));
            }
            let rows: Vec<Vec<Cell>> = entries
                .par_iter()
                .map(|e| {
                    let mut row = vec![Cell {
                        image: img.clone(),
                        label: format!("{} clean", e.id),
                    }];
                    for s in e.severities() {
                        let image = match CameraPerturber::new(e.id, s, a.seed)
                            .and_then(|mut p| p.apply_owned(&img.view(), a.seq))
                        {
                            Ok(out) => out,
                            Err(err) => {
                                progress.note(&format!("{} s{s}: {err}", e.id));
                                continue;
                            }
                        };
                        row.push(Cell {
                            image,
                            label: label(e, s),
                        });
                    }
                    row
                })
                .collect();
            contact_sheet(
                &format!(
                    "{} - {} camera perturbations",
                    a.input.display(),
                    entries.len()
                ),
                &rows,
                a.cell_width,
            )
        }
        Loaded::Cloud(cloud, kind, _) => {
            let entries = selected(a, Modality::Lidar);
            if entries.is_empty() {
                return Err(StudyError::Config("no LiDAR perturbation selected".into()));
            }
            let sensor = sensor_for(
                Some(kind),
                a.sensor.as_deref(),
                a.forward.as_deref(),
                a.intensity_max,
            )?;
            progress.note(&crate::files::describe_sensor(&sensor));
            let color = a.color_by;
            let size = a.cell_width.max(64);
            let bev = |c: &perturb_core::cloud::CloudView<'_>| {
                bird_eye_view(c, size, a.range, color, sensor.intensity_max, &[])
            };
            let clean = bev(&cloud.view());
            let rows: Vec<Vec<Cell>> = entries
                .par_iter()
                .map(|e| {
                    let mut row = vec![Cell {
                        image: clean.clone(),
                        label: format!("{} clean {}", e.id, cloud.len()),
                    }];
                    for s in e.severities() {
                        let out = LidarPerturber::new(e.id, s, a.seed, sensor.clone())
                            .and_then(|mut p| p.apply_owned(&cloud.view(), a.seq, None));
                        match out {
                            Ok(o) => row.push(Cell {
                                image: bev(&o.view()),
                                label: format!("{} S{s} {}", e.id, o.len()),
                            }),
                            Err(err) => progress.note(&format!("{} s{s}: {err}", e.id)),
                        }
                    }
                    row
                })
                .collect();
            contact_sheet(
                &format!(
                    "{} - {} lidar perturbations (bev)",
                    a.input.display(),
                    entries.len()
                ),
                &rows,
                size,
            )
        }
    };
    Ok(sheet)
}
