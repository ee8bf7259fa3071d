//! `perturb gallery`: every perturbation at every severity on one frame or scan, as one picture.

use crate::progress::Notes;
use anyhow::Result;
use perturb_core::formats::FileKind;
use perturb_core::viz::ColorBy;
use perturb_study::files::save_image;
use perturb_study::gallery::GalleryOptions;
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
    /// LiDAR full-scale intensity, 1 or 255.
    #[arg(long)]
    intensity_max: Option<f32>,
}

/// Renders the contact sheet.
pub fn run(a: Args) -> Result<()> {
    let opts = GalleryOptions {
        input: a.input,
        ids: a.ids,
        cell_width: a.cell_width,
        seed: a.seed,
        seq: a.seq,
        color_by: if a.color_by == "intensity" {
            ColorBy::Intensity
        } else {
            ColorBy::Height
        },
        range: a.range,
        sensor: a.sensor,
        intensity_max: a.intensity_max,
    };
    let sheet = perturb_study::gallery::render(&opts, &Notes)?;
    save_image(&a.output, &sheet.view(), FileKind::Png)?;
    eprintln!(
        "{}x{} gallery written to {}",
        sheet.width,
        sheet.height,
        a.output.display()
    );
    Ok(())
}
