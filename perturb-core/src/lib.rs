//! # perturb-core
//!
//! The perturbation library of the sensor-degradation middleware: camera and LiDAR perturbations
//! over borrowed sensor buffers, the catalogue that lists them, the sensor models, and decoders and
//! encoders for the file and message formats the project reads. It does no IPC and no networking:
//! the same code runs on a shared-memory sample in the daemon, on a decoded file in the CLI and on a
//! message of a recorded bag.
//!
//! Start with [`perturber::CameraPerturber`] / [`perturber::LidarPerturber`] and
//! [`registry::CATALOGUE`].

pub mod bench;
pub mod camera;
pub mod cloud;
pub mod encoding;
pub mod error;
pub mod formats;
pub mod image;
pub mod lidar;
pub mod math;
pub mod metrics;
pub mod percentile;
pub mod perturber;
pub mod registry;
pub mod rng;
pub mod route;
pub mod sensor_model;
pub mod synthetic;
pub mod viz;

pub use error::{Error, Result};
pub use lidar::detector;
pub use perturber::{CameraPerturber, LidarPerturber, Spec};
pub use registry::{CATALOGUE, Modality, find};
