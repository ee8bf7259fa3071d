//! `perturbd`'s configuration file (TOML): the iceoryx2 namespace, the daemon settings and one
//! `[[streams]]` table per sensor. Unknown keys are refused, and every error names the key and
//! what is wrong with it (see `config/README.md` for the reference).

use crate::perturbation::{self, Active};
pub use crate::stream::{MAX_STREAM_THREADS, PerturbationConfig, StreamConfig};
use perturb_wire::{TransportOptions, names};
use serde::{Deserialize, Serialize};
use std::collections::HashSet;
use std::path::{Path, PathBuf};

/// The whole file.
#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct Config {
    /// Daemon-wide settings.
    #[serde(default)]
    pub daemon: DaemonConfig,
    /// The iceoryx2 namespace (prefix, root, config file). `PERTURB_IOX2_PREFIX`,
    /// `PERTURB_IOX2_ROOT` and `PERTURB_IOX2_CONFIG` override these.
    #[serde(default)]
    pub transport: TransportOptions,
    /// One entry per sensor stream.
    #[serde(default)]
    pub streams: Vec<StreamConfig>,
}

/// `[daemon]`.
#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct DaemonConfig {
    /// iceoryx2 service of the control channel.
    pub control_service: String,
    /// Seconds between two statistics log lines (0: never).
    pub stats_interval_s: f64,
    /// Where the JSON report is written on exit (relative paths: to the working directory).
    pub report: Option<PathBuf>,
    /// A campaign to run from the start (relative paths: to this file's folder); see
    /// `config/campaign.toml`.
    pub campaign: Option<PathBuf>,
    /// How the frames of the streams without their own `threads` reach the worker threads.
    pub dispatch: Dispatch,
    /// `dispatch = "deadline"` only: frames processed at a time, each on its own share of the
    /// worker threads (default: see [`DaemonConfig::slots`]).
    pub dispatch_slots: Option<usize>,
}

/// `[daemon] dispatch`: how the frames of the streams without their own `threads` reach the
/// worker threads (one per core).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Deserialize, Serialize)]
#[serde(try_from = "String", rename_all = "lowercase")]
pub enum Dispatch {
    /// Every stream's frame work goes to one pool as it comes: concurrent frames share its
    /// workers (the default: a frame alone uses every core).
    #[default]
    Shared,
    /// Frames enter a gate in front of the workers and run earliest deadline first (arrival
    /// plus the stream's `budget_ms`), `dispatch_slots` at a time, each on its own workers
    /// (shorter tails than `Shared` with more streams than cores, docs/performance.md; a frame
    /// alone takes its one-core time).
    Deadline,
}

/// A `[daemon] dispatch` value that is not a policy.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct UnknownDispatch(pub String);

impl std::fmt::Display for UnknownDispatch {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "daemon.dispatch: `{}` is not a dispatch policy; use \"shared\" (every frame on one pool as it comes) or \"deadline\" (earliest deadline first)",
            self.0
        )
    }
}

impl std::error::Error for UnknownDispatch {}

impl TryFrom<String> for Dispatch {
    type Error = UnknownDispatch;

    fn try_from(s: String) -> Result<Self, Self::Error> {
        match s.as_str() {
            "shared" => Ok(Dispatch::Shared),
            "deadline" => Ok(Dispatch::Deadline),
            _ => Err(UnknownDispatch(s)),
        }
    }
}

impl Dispatch {
    /// The configuration's name of the policy.
    pub fn as_str(self) -> &'static str {
        match self {
            Dispatch::Shared => "shared",
            Dispatch::Deadline => "deadline",
        }
    }
}

impl DaemonConfig {
    /// With `dispatch = "deadline"`: the gate's slots and the worker threads of each, for
    /// `workers` threads in all (one per core): `dispatch_slots` (default one per worker), each
    /// with an equal share of the workers (at least one).
    pub fn slots(&self, workers: usize) -> (usize, usize) {
        let slots = self.dispatch_slots.unwrap_or(workers).max(1);
        (slots, (workers / slots).max(1))
    }
}

impl Default for DaemonConfig {
    fn default() -> Self {
        DaemonConfig {
            control_service: names::CONTROL.to_string(),
            stats_interval_s: 5.0,
            report: None,
            campaign: None,
            dispatch: Dispatch::Shared,
            dispatch_slots: None,
        }
    }
}

/// A configuration error: the file, the key and the problem.
#[derive(Debug)]
pub struct ConfigError {
    /// The file.
    pub path: PathBuf,
    /// What is wrong, starting with the key.
    pub message: String,
}

impl std::fmt::Display for ConfigError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "config {}: {}", self.path.display(), self.message)
    }
}

impl std::error::Error for ConfigError {}

impl Config {
    /// Reads, parses and validates a configuration file.
    pub fn load(path: &Path) -> Result<Config, ConfigError> {
        let err = |message: String| ConfigError {
            path: path.to_path_buf(),
            message,
        };
        let text = std::fs::read_to_string(path).map_err(|e| err(format!("cannot read: {e}")))?;
        let mut cfg = Config::parse(&text).map_err(err)?;
        if let Some(c) = &mut cfg.daemon.campaign {
            if c.is_relative()
                && let Some(dir) = path.parent()
            {
                *c = dir.join(&*c);
            }
            let campaign = perturb_campaign::Campaign::load(c)
                .map_err(|e| err(format!("daemon.campaign: {e}")))?;
            let streams: Vec<(String, perturb_core::registry::Modality)> = cfg
                .streams
                .iter()
                .map(|s| (s.name.clone(), s.modality))
                .collect();
            campaign
                .check_streams(&streams)
                .map_err(|e| err(format!("daemon.campaign: {e}")))?;
        }
        Ok(cfg)
    }

    /// Parses and validates TOML text.
    pub fn parse(text: &str) -> Result<Config, String> {
        let cfg: Config = toml::from_str(text).map_err(|e| e.to_string().trim_end().to_string())?;
        cfg.validate()?;
        Ok(cfg)
    }

    /// Checks every value; the error starts with the key (`streams[1] (cam_left).budget_ms`).
    pub fn validate(&self) -> Result<(), String> {
        self.validate_daemon()?;
        if self.streams.is_empty() {
            return Err("streams: no [[streams]] configured; perturbd needs at least one".into());
        }
        let mut seen = Seen::default();
        for (i, s) in self.streams.iter().enumerate() {
            let key = |k: &str| format!("streams[{i}] ({}).{k}", s.name);
            seen.claim(i, s)?;
            s.validate_settings(&key)?;
            if let Some(p) = &s.perturbation {
                let built: Result<Active, String> =
                    perturbation::build(s, &p.id, p.severity, p.seed, None).map(|(_, a)| a);
                built.map_err(|e| format!("{}: {e}", key("perturbation")))?;
            }
        }
        Ok(())
    }

    /// `[daemon]` and `[transport]`.
    fn validate_daemon(&self) -> Result<(), String> {
        let d = &self.daemon;
        if d.control_service.is_empty() || d.control_service.len() > 255 {
            return Err("daemon.control_service: must be 1..=255 bytes".into());
        }
        if !(d.stats_interval_s >= 0.0 && d.stats_interval_s.is_finite()) {
            return Err(format!(
                "daemon.stats_interval_s: {} is not a number of seconds >= 0",
                d.stats_interval_s
            ));
        }
        if let Some(n) = d.dispatch_slots {
            if d.dispatch != Dispatch::Deadline {
                return Err(format!(
                    "daemon.dispatch_slots: only with dispatch = \"deadline\" (dispatch is \"{}\")",
                    d.dispatch.as_str()
                ));
            }
            if !(1..=MAX_STREAM_THREADS).contains(&n) {
                return Err(format!(
                    "daemon.dispatch_slots: {n} must be between 1 and {MAX_STREAM_THREADS}"
                ));
            }
        }
        if let Some(p) = &self.transport.prefix
            && (p.is_empty()
                || !p
                    .chars()
                    .all(|c| c.is_ascii_alphanumeric() || matches!(c, '_' | '-' | '.')))
        {
            return Err(format!(
                "transport.prefix: `{p}` must be non-empty letters, digits, `_`, `-` or `.`"
            ));
        }
        Ok(())
    }
}

/// Checks that the report (and the state files kept beside it) can be written: its folder
/// exists. The error names the key and the folder.
pub fn check_report_path(report: &std::path::Path) -> Result<(), String> {
    let dir = report
        .parent()
        .filter(|d| !d.as_os_str().is_empty())
        .unwrap_or(std::path::Path::new("."));
    if dir.is_dir() {
        Ok(())
    } else {
        Err(format!(
            "daemon.report (or --report) {}: the folder {} does not exist; the report and the restart state (kill switch, perturbations set at runtime, counters) are kept there",
            report.display(),
            dir.display()
        ))
    }
}

/// The names and services of the streams checked so far: each belongs to one stream.
#[derive(Default)]
struct Seen {
    names: HashSet<String>,
    inputs: HashSet<String>,
    outputs: HashSet<String>,
}

impl Seen {
    /// Checks stream `i`'s name and services, and that no earlier stream has them.
    fn claim(&mut self, i: usize, s: &StreamConfig) -> Result<(), String> {
        let key = |k: &str| format!("streams[{i}] ({}).{k}", s.name);
        perturb_wire::names::check_stream(&s.name)
            .map_err(|e| format!("streams[{i}].name: {e}"))?;
        if !self.names.insert(s.name.clone()) {
            return Err(format!(
                "streams[{i}].name: `{}` is used by two streams",
                s.name
            ));
        }
        let (input, output) = (s.input_service(), s.output_service());
        for (k, v) in [("input", &input), ("output", &output)] {
            if v.is_empty() || v.len() > 255 {
                return Err(format!("{}: `{v}` must be 1..=255 bytes", key(k)));
            }
        }
        if input == output {
            return Err(format!(
                "{}: `{output}` is also the input; the daemon would read its own output",
                key("output")
            ));
        }
        if !self.outputs.insert(output.clone()) {
            return Err(format!(
                "{}: `{output}` is the output of another stream",
                key("output")
            ));
        }
        if !self.inputs.insert(input.clone()) {
            return Err(format!(
                "{}: `{input}` is the input of another stream",
                key("input")
            ));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use perturb_core::sensor_model::SensorModel;

    const GOOD: &str = r#"
        [[streams]]
        name = "cam"
        modality = "camera"
        perturbation = { id = "C-A1", severity = 3, seed = 7 }

        [[streams]]
        name = "lidar"
        modality = "lidar"
        sensor = "vlp32c"
    "#;

    #[test]
    fn a_report_in_a_missing_folder_is_refused_naming_the_key() {
        let e =
            check_report_path(std::path::Path::new("/nonexistent-folder-xyz/r.json")).unwrap_err();
        assert!(
            e.contains("daemon.report") && e.contains("does not exist"),
            "{e}"
        );
        assert!(check_report_path(std::path::Path::new("report.json")).is_ok());
    }

    #[test]
    fn good_config_parses_with_defaults() {
        let c = Config::parse(GOOD).unwrap();
        assert_eq!(c.streams[0].input_service(), "cam/raw");
        assert_eq!(c.streams[1].output_service(), "lidar/perturbed");
        assert_eq!(c.streams[1].budget(), 200.0);
        assert_eq!(c.daemon.control_service, "perturb/control");
        assert_eq!(c.streams[0].threads, None);
        assert_eq!(c.daemon.dispatch, Dispatch::Shared);
        assert_eq!(c.daemon.slots(2), (2, 1));
        let c = Config::parse(&format!("{GOOD}\nthreads = 4\n")).unwrap();
        assert_eq!(c.streams[1].threads, Some(4));
    }

    fn err(text: &str) -> String {
        Config::parse(text).unwrap_err()
    }

    #[test]
    fn errors_name_the_key() {
        let e = err(&GOOD.replace("sensor =", "sensr ="));
        assert!(e.contains("sensr"), "{e}");
        let e = err(&GOOD.replace("sensor = \"vlp32c\"", ""));
        assert!(e.contains("streams[1] (lidar).sensor: missing"), "{e}");
        let e = err(&GOOD.replace("severity = 3", "severity = 9"));
        assert!(
            e.contains("streams[0] (cam).perturbation") && e.contains("1..=5"),
            "{e}"
        );
        let e = err(&GOOD.replace("C-A1", "C-Z9"));
        assert!(e.contains("C-Z9"), "{e}");
        let e = err(&GOOD.replace("C-A1", "L-C1"));
        assert!(e.contains("camera stream") && e.contains("LiDAR"), "{e}");
        let e = err(&GOOD.replace("\"vlp32c\"", "\"vlp99\""));
        assert!(
            e.contains("streams[1] (lidar).sensor") && e.contains("vlp99"),
            "{e}"
        );
        for bad in ["../etc", "/cam", "cam//x", "a b"] {
            let e = err(&GOOD.replace("name = \"lidar\"", &format!("name = \"{bad}\"")));
            assert!(e.contains("streams[1].name"), "{bad}: {e}");
        }
        let e = err(&GOOD.replace("name = \"lidar\"", "name = \"cam\""));
        assert!(
            e.contains("streams[1].name") && e.contains("two streams"),
            "{e}"
        );
        let e = err(&format!("{GOOD}\nqueue_depth = 5\n"));
        assert!(e.contains("queue_depth"), "{e}");
        let e = err(&format!("{GOOD}\nthreads = 0\n"));
        assert!(
            e.contains("streams[1] (lidar).threads") && e.contains("between 1"),
            "{e}"
        );
        let e = err("[daemon]\n");
        assert!(e.contains("streams"), "{e}");
        let e = err(&GOOD.replace("modality = \"lidar\"", "modality = \"radar\""));
        assert!(e.contains("radar"), "{e}");
        let e = err(&format!("{GOOD}forward = \"+z\"\n"));
        assert!(
            e.contains("streams[1] (lidar).forward") && e.contains("+z"),
            "{e}"
        );
        let e = err(&format!("{GOOD}forward = \"ahead\"\n"));
        assert!(
            e.contains("streams[1] (lidar).forward") && e.contains("ahead"),
            "{e}"
        );
        let e = err(&format!("{GOOD}up = \"+x\"\n"));
        assert!(e.contains("streams[1] (lidar).up"), "{e}");
        let e = err(&GOOD.replace("seed = 7 }", "seed = 7 }\n        forward = \"+y\""));
        assert!(e.contains("streams[0] (cam).forward"), "{e}");
    }

    #[test]
    fn dispatch_is_shared_or_deadline_and_its_slots_are_checked() {
        let with = |d: &str| format!("[daemon]\n{d}\n{GOOD}");
        let c = Config::parse(&with("dispatch = \"deadline\"")).unwrap();
        assert_eq!(c.daemon.dispatch, Dispatch::Deadline);
        assert_eq!(c.daemon.slots(2), (2, 1));
        assert_eq!(c.daemon.slots(5), (5, 1));
        let c = Config::parse(&with("dispatch = \"deadline\"\ndispatch_slots = 1")).unwrap();
        assert_eq!(c.daemon.slots(4), (1, 4));
        let c = Config::parse(&with("dispatch = \"deadline\"\ndispatch_slots = 2")).unwrap();
        assert_eq!(c.daemon.slots(5), (2, 2));
        assert_eq!(c.daemon.slots(1), (2, 1));
        let c = Config::parse(&with("dispatch = \"shared\"")).unwrap();
        assert_eq!(c.daemon.dispatch, Dispatch::Shared);
        let e = err(&with("dispatch = \"fifo\""));
        assert!(
            e.contains("daemon.dispatch") && e.contains("`fifo`") && e.contains("\"deadline\""),
            "{e}"
        );
        assert_eq!(
            Dispatch::try_from("edf".to_string()),
            Err(UnknownDispatch("edf".into()))
        );
        let e = err(&with("dispatch = \"deadline\"\ndispatch_slots = 0"));
        assert!(
            e.contains("daemon.dispatch_slots") && e.contains("between 1"),
            "{e}"
        );
        let e = err(&with("dispatch = \"shared\"\ndispatch_slots = 2"));
        assert!(
            e.contains("daemon.dispatch_slots") && e.contains("only with"),
            "{e}"
        );
    }

    #[test]
    fn a_camera_stream_takes_a_bit_depth_for_its_16_bit_samples() {
        let with = |v: &str| {
            GOOD.replace(
                "seed = 7 }",
                &format!("seed = 7 }}\n        bit_depth = {v}"),
            )
        };
        let c = Config::parse(&with("12")).unwrap();
        assert_eq!(c.streams[0].bit_depth, Some(12));
        assert_eq!(Config::parse(GOOD).unwrap().streams[0].bit_depth, None);
        let e = err(&with("17"));
        assert!(
            e.contains("streams[0] (cam).bit_depth") && e.contains("between 9 and 16"),
            "{e}"
        );
        let e = err(&format!("{GOOD}bit_depth = 12\n"));
        assert!(e.contains("streams[1] (lidar).bit_depth"), "{e}");
    }

    #[test]
    fn lidar_axes_reach_the_sensor_model() {
        let c = Config::parse(&format!("{GOOD}forward = \"+y\"\n")).unwrap();
        let m = c.streams[1].sensor_model().unwrap();
        assert_eq!(m.axes, SensorModel::nuscenes().axes);
        assert_eq!(m.name, "VLP-32C");
        let c = Config::parse(GOOD).unwrap();
        assert!(c.streams[1].sensor_model().unwrap().axes.is_canonical());
    }
}
