//! # perturbd
//!
//! The perturbation daemon of the middleware. For each configured sensor stream it wakes on
//! frames published on the stream's input service (`<stream>/raw`), reads them in shared
//! memory, writes the perturbed frame straight into a loaned sample of the output service
//! (`<stream>/perturbed`) and publishes it, with the hop timestamps and the applied perturbation
//! in the header. Perturbations are switched at runtime over the control channel
//! (`perturb ctl`); per-stream counters and latency percentiles are logged, readable live and
//! written to a JSON report on exit.
//!
//! The library exposes the configuration (used by the end-to-end tests and tools to find the
//! services and QoS of a stream) and the pieces of the daemon.

pub mod campaign;
pub mod config;
pub mod daemon;
pub mod perturbation;
pub mod safety;
pub mod state;
pub mod stats;
pub mod stream;
pub mod worker;

pub use config::{Config, StreamConfig};
