//! `[[streams]]`: one sensor's stream as configured, and the perturbation it starts with.

use perturb_core::registry::Modality;
use perturb_core::sensor_model::{Axes, Axis, SensorModel};
use perturb_wire::{StreamQos, names};
use serde::{Deserialize, Serialize};

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
    /// Camera only: significant bits of 16-bit samples (`mono16`, `rgb16`, `bayer_*16`, ...),
    /// 9..=16 (default 16): a 12-bit sensor stored in 16-bit containers is `bit_depth = 12`, so
    /// its white maps to the working view's 255.
    #[serde(default)]
    pub bit_depth: Option<u8>,
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

    /// Checks this stream's own settings (budget, queue, threads, QoS, the sensor of a LiDAR
    /// stream); `key(k)` names key `k` of this stream in an error.
    pub(crate) fn validate_settings(&self, key: &dyn Fn(&str) -> String) -> Result<(), String> {
        if let Some(b) = self.budget_ms
            && !(b > 0.0 && b.is_finite())
        {
            return Err(format!(
                "{}: {b} must be a positive number",
                key("budget_ms")
            ));
        }
        if !(1..=2).contains(&self.queue_depth) {
            return Err(format!(
                "{}: {} must be 1 or 2",
                key("queue_depth"),
                self.queue_depth
            ));
        }
        if let Some(n) = self.threads
            && !(1..=MAX_STREAM_THREADS).contains(&n)
        {
            return Err(format!(
                "{}: {n} must be between 1 and {MAX_STREAM_THREADS}",
                key("threads")
            ));
        }
        self.qos
            .validate()
            .map_err(|e| format!("{}: {e}", key("qos")))?;
        if self.qos.subscriber_borrowed < self.queue_depth + 2 {
            return Err(format!(
                "{}: {} is too small for queue_depth {}: the daemon holds queue_depth + 2 frames, set it to at least {}",
                key("qos.subscriber_borrowed"),
                self.qos.subscriber_borrowed,
                self.queue_depth,
                self.queue_depth + 2
            ));
        }
        match self.modality {
            Modality::Camera => {
                if self.sensor.is_some() {
                    return Err(format!(
                        "{}: only LiDAR streams have a sensor model",
                        key("sensor")
                    ));
                }
                if self.intensity_max.is_some() {
                    return Err(format!(
                        "{}: only LiDAR streams have an intensity scale",
                        key("intensity_max")
                    ));
                }
                if let Some(b) = self.bit_depth
                    && !(9..=16).contains(&b)
                {
                    return Err(format!(
                        "{}: {b} must be between 9 and 16 (the significant bits of 16-bit samples)",
                        key("bit_depth")
                    ));
                }
                for (k, v) in [("forward", &self.forward), ("up", &self.up)] {
                    if v.is_some() {
                        return Err(format!("{}: only LiDAR streams have axes", key(k)));
                    }
                }
            }
            Modality::Lidar => {
                if self.sensor.is_none() {
                    return Err(format!(
                        "{}: missing; a LiDAR stream needs its sensor model (vlp32c, vlp16, hdl32e or hdl64e)",
                        key("sensor")
                    ));
                }
                if self.bit_depth.is_some() {
                    return Err(format!(
                        "{}: only camera streams have a bit depth",
                        key("bit_depth")
                    ));
                }
                SensorModel::by_name(self.sensor.as_deref().unwrap_or("vlp32c"))
                    .map_err(|e| format!("{}: {e}", key("sensor")))?;
                self.axes_by_key()
                    .map_err(|(k, e)| format!("{}: {e}", key(k)))?;
                if let Some(m) = self.intensity_max
                    && m != 1.0
                    && m != 255.0
                {
                    return Err(format!("{}: {m} must be 1 or 255", key("intensity_max")));
                }
            }
        }
        Ok(())
    }

    /// Like [`StreamConfig::axes`], the error with the key it is about.
    pub(crate) fn axes_by_key(&self) -> Result<Axes, (&'static str, String)> {
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
