//! `perturb gallery`: every perturbation at every severity on one frame or scan, as one picture.

use crate::files::{Loaded, load, save_image, sensor_for};
use anyhow::{Result, bail};
use perturb_core::formats::FileKind;
use perturb_core::perturber::{CameraPerturber, LidarPerturber};
use perturb_core::registry::{Entry, Modality, of_modality};
use perturb_core::viz::{Cell, ColorBy, bird_eye_view, contact_sheet};
use rayon::prelude::*;
use std::path::PathBuf;

/// Arguments of `perturb gallery`.
#[derive(clap::Args)]
#[command(after_help = "Examples:
  perturb gallery frame.png -o gallery.png                 # the paper's figure 1 for your camera
  perturb gallery scan.bin -o bev.png --color-by intensity  # bird's-eye views, clean beside perturbed")]
pub struct Args {
    /// An image or point-cloud file.
    input: PathBuf,
    /// Output PNG.
    #[arg(short, long)]
    output: PathBuf,
    /// Only these IDs (repeatable).
    #[arg(long = "id")]
    ids: Vec<String>,
    /// Width of one cell in pixels.
    #[arg(long, default_value_t = 320)]
    cell_width: u32,
    /// Seed.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Frame sequence number.
    #[arg(long, default_value_t = 0)]
    seq: u64,
    /// LiDAR: colour points by height or intensity.
    #[arg(long, value_parser = ["height", "intensity"], default_value = "height")]
    color_by: String,
    /// LiDAR: half-width of the bird's-eye view in metres.
    #[arg(long, default_value_t = 40.0)]
    range: f32,
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

fn selected(a: &Args, m: Modality) -> Vec<&'static Entry> {
    of_modality(m)
        .filter(|e| e.is_implemented())
        .filter(|e| a.ids.is_empty() || a.ids.iter().any(|i| i.eq_ignore_ascii_case(e.id)))
        .collect()
}

/// Renders the contact sheet.
pub fn run(a: Args) -> Result<()> {
    let label = |e: &Entry, s: u8| format!("{} {} S{s}", e.id, e.name);
    let sheet = match load(&a.input)? {
        Loaded::Image(img, _) => {
            let entries = selected(&a, Modality::Camera);
            if entries.is_empty() {
                bail!("no camera perturbation selected");
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
                                eprintln!("{} s{s}: {err}", e.id);
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
            let entries = selected(&a, Modality::Lidar);
            if entries.is_empty() {
                bail!("no LiDAR perturbation selected");
            }
            let sensor = sensor_for(
                Some(kind),
                a.sensor.as_deref(),
                a.forward.as_deref(),
                a.intensity_max,
                false,
            )?;
            let color = if a.color_by == "intensity" {
                ColorBy::Intensity
            } else {
                ColorBy::Height
            };
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
                            Err(err) => eprintln!("{} s{s}: {err}", e.id),
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
    save_image(&a.output, &sheet.view(), FileKind::Png)?;
    eprintln!(
        "{}x{} gallery written to {}",
        sheet.width,
        sheet.height,
        a.output.display()
    );
    Ok(())
}
