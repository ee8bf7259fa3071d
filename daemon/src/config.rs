//! `perturbd`'s configuration file (TOML): the iceoryx2 namespace, the daemon settings and one
//! `[[streams]]` table per sensor. Unknown keys are refused, and every error names the key and
//! what is wrong with it (see `config/README.md` for the reference).

use crate::perturbation::{self, Active};
use perturb_core::registry::Modality;
use perturb_core::sensor_model::{Axes, Axis, SensorModel};
use perturb_wire::{StreamQos, TransportOptions, names};
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
}

impl Default for DaemonConfig {
    fn default() -> Self {
        DaemonConfig {
            control_service: names::CONTROL.to_string(),
            stats_interval_s: 5.0,
            report: None,
        }
    }
}

/// `[[streams]]`: one sensor.
#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct StreamConfig {
    /// Unique stream name (`cam_front`, `lidar_top`).
    pub name: String,
    /// `camera` or `lidar`.
    pub modality: Modality,
    /// Input service (default `<name>/raw`).
    #[serde(default)]
    pub input: Option<String>,
    /// Output service (default `<name>/perturbed`).
    #[serde(default)]
    pub output: Option<String>,
    /// Budget for ingress-to-publish latency in milliseconds (default 33 for cameras, 200 for
    /// LiDARs); frames over it are counted.
    #[serde(default)]
    pub budget_ms: Option<f64>,
    /// LiDAR only (required): sensor model (`vlp32c`, `vlp16`, `hdl32e`, `hdl64e`).
    #[serde(default)]
    pub sensor: Option<String>,
    /// LiDAR only: full-scale intensity of the clouds, 1 or 255 (default: the sensor model's).
    #[serde(default)]
    pub intensity_max: Option<f32>,
    /// LiDAR only: the sensor axis that points forward, `+x`, `-x`, `+y` or `-y` (default `+x`,
    /// the ROS convention; nuScenes' `LIDAR_TOP` is `+y`).
    #[serde(default)]
    pub forward: Option<String>,
    /// LiDAR only: the sensor axis that points up, `+z` or `-z` (default `+z`; `-z` for a sensor
    /// mounted upside down).
    #[serde(default)]
    pub up: Option<String>,
    /// Frames waiting between reception and processing (1 or 2; default 2). When the worker
    /// falls behind, the oldest waiting frame is dropped and counted.
    #[serde(default = "default_queue_depth")]
    pub queue_depth: usize,
    /// Worker threads of this stream's frame work (absent: the process-wide pool, one thread per
    /// core, shared by every stream). A stream whose perturbation needs several cores to fit its
    /// budget (`perturb bench` says how many) gets its own pool of this many threads, so other
    /// streams cannot take them.
    #[serde(default)]
    pub threads: Option<usize>,
    /// The perturbation active from the start (absent: frames are forwarded unchanged).
    #[serde(default)]
    pub perturbation: Option<PerturbationConfig>,
    /// iceoryx2 QoS of the stream's two services (every process on them must agree).
    #[serde(default)]
    pub qos: StreamQos,
}

/// The most worker threads one stream may ask for.
pub const MAX_STREAM_THREADS: usize = 256;

fn default_queue_depth() -> usize {
    2
}

/// `[streams.perturbation]`.
#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct PerturbationConfig {
    /// Catalogue ID or name.
    pub id: String,
    /// Severity (1..=5 camera, 1..=3 LiDAR).
    pub severity: u8,
    /// Seed (default 0).
    #[serde(default)]
    pub seed: u64,
}

impl StreamConfig {
    /// The input service name.
    pub fn input_service(&self) -> String {
        self.input.clone().unwrap_or_else(|| names::raw(&self.name))
    }

    /// The output service name.
    pub fn output_service(&self) -> String {
        self.output
            .clone()
            .unwrap_or_else(|| names::perturbed(&self.name))
    }

    /// The budget in milliseconds.
    pub fn budget(&self) -> f64 {
        self.budget_ms.unwrap_or(match self.modality {
            Modality::Camera => 33.0,
            Modality::Lidar => 200.0,
        })
    }

    /// The LiDAR sensor model (with the intensity scale and the axes applied).
    pub fn sensor_model(&self) -> Result<SensorModel, String> {
        let name = self.sensor.as_deref().unwrap_or("vlp32c");
        let mut m = SensorModel::by_name(name).map_err(|e| e.to_string())?;
        if let Some(max) = self.intensity_max {
            m = m.with_intensity_max(max);
        }
        Ok(m.with_axes(self.axes()?))
    }

    /// The LiDAR's forward and up axes (`forward`, `up`; default x forward, z up).
    pub fn axes(&self) -> Result<Axes, String> {
        self.axes_by_key().map_err(|(_, e)| e)
    }

    /// Like [`StreamConfig::axes`], the error with the key it is about.
    fn axes_by_key(&self) -> Result<Axes, (&'static str, String)> {
        let parse = |key: &'static str, v: Option<&str>, default: Axis| {
            v.map_or(Ok(default), Axis::parse)
                .map_err(|e| (key, e.to_string()))
        };
        let forward = parse("forward", self.forward.as_deref(), Axis::PosX)?;
        if forward.index_sign().0 == 2 {
            return Err(("forward", format!("{forward} must be +x, -x, +y or -y")));
        }
        let up = parse("up", self.up.as_deref(), Axis::PosZ)?;
        Axes::new(forward, up).map_err(|e| ("up", e.to_string()))
    }

    /// The seed of the initial perturbation (0 if none).
    pub fn initial_seed(&self) -> u64 {
        self.perturbation.as_ref().map_or(0, |p| p.seed)
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
        let cfg = Config::parse(&text).map_err(err)?;
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
        if self.streams.is_empty() {
            return Err("streams: no [[streams]] configured; perturbd needs at least one".into());
        }
        let mut names_seen = HashSet::new();
        let mut outputs = HashSet::new();
        let mut inputs = HashSet::new();
        for (i, s) in self.streams.iter().enumerate() {
            let key = |k: &str| format!("streams[{i}] ({}).{k}", s.name);
            if s.name.is_empty()
                || s.name.len() > 200
                || s.name.chars().any(|c| c.is_whitespace() || c.is_control())
            {
                return Err(format!(
                    "streams[{i}].name: `{}` must be 1..=200 bytes without spaces",
                    s.name
                ));
            }
            if !names_seen.insert(s.name.as_str()) {
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
            if !outputs.insert(output.clone()) {
                return Err(format!(
                    "{}: `{output}` is the output of another stream",
                    key("output")
                ));
            }
            if !inputs.insert(input.clone()) {
                return Err(format!(
                    "{}: `{input}` is the input of another stream",
                    key("input")
                ));
            }
            if let Some(b) = s.budget_ms
                && !(b > 0.0 && b.is_finite())
            {
                return Err(format!(
                    "{}: {b} must be a positive number",
                    key("budget_ms")
                ));
            }
            if !(1..=2).contains(&s.queue_depth) {
                return Err(format!(
                    "{}: {} must be 1 or 2",
                    key("queue_depth"),
                    s.queue_depth
                ));
            }
            if let Some(n) = s.threads
                && !(1..=MAX_STREAM_THREADS).contains(&n)
            {
                return Err(format!(
                    "{}: {n} must be between 1 and {MAX_STREAM_THREADS}",
                    key("threads")
                ));
            }
            s.qos
                .validate()
                .map_err(|e| format!("{}: {e}", key("qos")))?;
            if s.qos.subscriber_borrowed < s.queue_depth + 2 {
                return Err(format!(
                    "{}: {} is too small for queue_depth {}: the daemon holds queue_depth + 2 frames, set it to at least {}",
                    key("qos.subscriber_borrowed"),
                    s.qos.subscriber_borrowed,
                    s.queue_depth,
                    s.queue_depth + 2
                ));
            }
            match s.modality {
                Modality::Camera => {
                    if s.sensor.is_some() {
                        return Err(format!(
                            "{}: only LiDAR streams have a sensor model",
                            key("sensor")
                        ));
                    }
                    if s.intensity_max.is_some() {
                        return Err(format!(
                            "{}: only LiDAR streams have an intensity scale",
                            key("intensity_max")
                        ));
                    }
                    for (k, v) in [("forward", &s.forward), ("up", &s.up)] {
                        if v.is_some() {
                            return Err(format!("{}: only LiDAR streams have axes", key(k)));
                        }
                    }
                }
                Modality::Lidar => {
                    if s.sensor.is_none() {
                        return Err(format!(
                            "{}: missing; a LiDAR stream needs its sensor model (vlp32c, vlp16, hdl32e or hdl64e)",
                            key("sensor")
                        ));
                    }
                    SensorModel::by_name(s.sensor.as_deref().unwrap_or("vlp32c"))
                        .map_err(|e| format!("{}: {e}", key("sensor")))?;
                    s.axes_by_key()
                        .map_err(|(k, e)| format!("{}: {e}", key(k)))?;
                    if let Some(m) = s.intensity_max
                        && m != 1.0
                        && m != 255.0
                    {
                        return Err(format!("{}: {m} must be 1 or 255", key("intensity_max")));
                    }
                }
            }
            if let Some(p) = &s.perturbation {
                let built: Result<Active, String> =
                    perturbation::build(s, &p.id, p.severity, p.seed, None).map(|(_, a)| a);
                built.map_err(|e| format!("{}: {e}", key("perturbation")))?;
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

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
    fn good_config_parses_with_defaults() {
        let c = Config::parse(GOOD).unwrap();
        assert_eq!(c.streams[0].input_service(), "cam/raw");
        assert_eq!(c.streams[1].output_service(), "lidar/perturbed");
        assert_eq!(c.streams[1].budget(), 200.0);
        assert_eq!(c.daemon.control_service, "perturb/control");
        assert_eq!(c.streams[0].threads, None);
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
    fn lidar_axes_reach_the_sensor_model() {
        let c = Config::parse(&format!("{GOOD}forward = \"+y\"\n")).unwrap();
        let m = c.streams[1].sensor_model().unwrap();
        assert_eq!(m.axes, SensorModel::nuscenes().axes);
        assert_eq!(m.name, "VLP-32C");
        let c = Config::parse(GOOD).unwrap();
        assert!(c.streams[1].sensor_model().unwrap().axes.is_canonical());
    }
}
