//! Building the perturbation a stream applies, with the checks a control request or the config
//! gets a clear error from: unknown ID, wrong modality, severity out of range, not implemented in
//! this build, needs object boxes the daemon does not have.

use crate::stream::StreamConfig;
use perturb_core::cloud::{CloudView, PointLayout};
use perturb_core::image::ImageGeometry;
use perturb_core::perturber::{CameraPerturber, LidarPerturber, Spec};
use perturb_core::registry::{self, Modality};
use std::sync::Arc;

/// A perturbation ready to run on a stream's frames.
pub enum Active {
    /// For a camera stream.
    Camera(CameraPerturber),
    /// For a LiDAR stream.
    Lidar(Box<LidarPerturber>),
}

impl std::fmt::Debug for Active {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Active::Camera(p) => p.fmt(f),
            Active::Lidar(p) => p.fmt(f),
        }
    }
}

impl Active {
    /// The configuration.
    pub fn spec(&self) -> Spec {
        match self {
            Active::Camera(p) => p.spec(),
            Active::Lidar(p) => p.spec(),
        }
    }
}

fn modality_word(m: Modality) -> &'static str {
    match m {
        Modality::Camera => "camera",
        Modality::Lidar => "LiDAR",
    }
}

/// Builds perturbation `id` at `severity` with `seed` for `stream`. For a camera stream whose
/// frame geometry is known, the per-geometry state is built here too, so the first frame with the
/// new perturbation does not pay for it.
pub fn build(
    stream: &StreamConfig,
    id: &str,
    severity: u8,
    seed: u64,
    geometry: Option<ImageGeometry>,
) -> Result<(Spec, Active), String> {
    let entry = registry::find(id).map_err(|e| e.to_string())?;
    if entry.modality != stream.modality {
        return Err(format!(
            "stream `{}` is a {} stream; {} ({}) is a {} perturbation",
            stream.name,
            modality_word(stream.modality),
            entry.id,
            entry.name,
            modality_word(entry.modality)
        ));
    }
    let spec = Spec::new(entry.id, severity, seed).map_err(|e| e.to_string())?;
    let active = match stream.modality {
        Modality::Camera => {
            let mut p = CameraPerturber::from_spec(spec).map_err(|e| e.to_string())?;
            if let Some(g) = geometry {
                p.prepare(g).map_err(|e| {
                    format!("{} cannot run on this stream's {g} frames: {e}", entry.id)
                })?;
            }
            Active::Camera(p)
        }
        Modality::Lidar => {
            let sensor = stream.sensor_model()?;
            let mut p = LidarPerturber::from_spec(spec, sensor).map_err(|e| e.to_string())?;
            // A dry run on an empty cloud finds the perturbations that need inputs the daemon
            // does not have (object boxes from a detector or the dataset's labels).
            let layout = Arc::new(PointLayout::xyzi_f32());
            let empty = CloudView::new(layout, &[], 0, 1, 0, true).map_err(|e| e.to_string())?;
            p.apply(&empty, &mut [], 0, None)
                .map_err(|e| format!("{} cannot run in the daemon: {e}", entry.id))?;
            Active::Lidar(Box::new(p))
        }
    };
    Ok((spec, active))
}
