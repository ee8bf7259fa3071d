//! # perturb-study
//!
//! The study behind `perturb` as a library: everything the `perturb` tool's study commands do,
//! callable from another program (or a Python binding) with plain data in and plain data out,
//! errors as [`StudyError`] naming the file, run, topic or field concerned.
//!
//! Model level (paper, RQ1 and RQ4's training data):
//! - [`batch`]: every perturbation at every severity over a dataset (folder or bag);
//! - [`steering`]: steering MSE and deviation of a driving model's predictions;
//! - [`lidar_eval`]: LiDAR detection retention and ATE with the clustering detector;
//! - [`augment`]: one perturbed variant per training sample, with a manifest;
//! - [`gallery`]: every perturbation on one frame or scan, as one picture.
//!
//! Closed loop (paper, RQ3, RQ4 and the qualitative analysis), from recorded runs:
//! - [`analyze`]: completion, failure type, cross-track error, steering jitter, near-field
//!   detection coverage and duration per run, per (perturbation, severity) segment and per
//!   perturbation, from bags with a `/perturb/events` channel and any pose, steering, objects,
//!   takeover and collision topics (decoded by their stored schema);
//! - [`transfer`]: Spearman's rho between offline and closed-loop metrics with bootstrap
//!   confidence intervals, Benjamini-Hochberg q-values and top-k overlap;
//! - [`hotspots`]: DBSCAN over failure positions and the trajectory map;
//! - [`compare`]: two sets of runs (fine-tuned and baseline) per condition in one table;
//! - [`report`]: the paper's tables and figures in one self-contained HTML page, from the
//!   outputs above ([`plot`] draws the charts and the map as SVG).
//!
//! Definitions and the choices where the paper is silent are in `docs/study.md`.

pub mod analyze;
pub mod augment;
pub mod batch;
pub mod compare;
pub mod dataset;
pub mod error;
pub mod files;
pub mod gallery;
pub mod hotspots;
pub mod lidar_eval;
pub mod perturb_bag;
pub mod plot;
pub mod progress;
pub mod report;
pub mod route;
pub mod source;
pub mod stats;
pub mod steering;
pub mod table;
pub mod transfer;

pub use error::{Result, StudyError};
pub use progress::{Progress, Silent};

/// Output format of a table (with the `clap` feature, also a command-line value).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "clap", derive(clap::ValueEnum))]
pub enum Format {
    /// Aligned terminal table.
    #[default]
    Table,
    /// Markdown table.
    Markdown,
    /// CSV.
    Csv,
    /// JSON.
    Json,
}
