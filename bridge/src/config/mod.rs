//! `perturb-bridge --config FILE.toml`: which adapters run and how topics map to streams.
//!
//! ```toml
//! [bridge]
//! name = "vehicle"            # ROS node name, log prefix
//! bus = "iceoryx2"            # or "local": in-process passthrough, no daemon
//! iox2 = { prefix = "iox2_" }  # iceoryx2 namespace shared with perturbd (PERTURB_IOX2_* override)
//! qos = { subscriber_buffer = 4 }   # iceoryx2 QoS, compatible with the daemon's streams
//!
//! [dds]
//! backend = "rustdds"         # or "cyclone"
//! domain_id = 0
//! interfaces = ["lo"]         # names or IPv4 addresses; omitted: the DDS implementation's default
//!
//! [ros1]                      # for entries with transport = "ros1"
//! master_uri = "http://127.0.0.1:11311/"   # default: ROS_MASTER_URI
//! hostname = "127.0.0.1"      # advertised to other nodes; default: ROS_HOSTNAME, ROS_IP, host name
//! node_name = "perturb_bridge"   # default: [bridge] name
//! clock = false               # publish /clock from the replayed bag (use_sim_time)
//!
//! [[ingress]]                 # ROS 2 (or ROS 1) topic -> <stream>/raw
//! topic = "/sensing/camera/front/image_raw"
//! type = "image"              # image | compressed_image | pointcloud2
//! stream = "camera_front"
//! transport = "dds"           # or "ros1"
//! qos = { reliability = "best_effort", depth = 5, durability = "volatile" }   # DDS only
//! camera_info = "/sensing/camera/front/camera_info"   # relayed with the images
//!
//! [[egress]]                  # <stream>/perturbed -> ROS 2 (or ROS 1) topic
//! stream = "camera_front"
//! topic = "/perturbed/camera/front/image_raw"
//! transport = "dds"           # or "ros1"
//! on_late = "raw"             # a frame late or without perturbd goes out raw; "drop": nothing
//! deadline_ms = 33.3          # default: one frame period (rate_hz, else the measured rate)
//! camera_info = "/camera_front/camera_info"   # relayed from the ingress's camera_info
//!
//! [replay]                    # bag -> <stream>/raw, with the original timing
//! bag = "drive.mcap"
//! rate = 1.0                  # 0 = as fast as possible
//! start_offset = 0.0          # seconds into the bag
//! loop = false
//! topics = { "/kitti/camera_color_left/image_raw" = "camera_front" }   # empty: every sensor topic
//!
//! [events]                    # the perturbation log on the bus (std_msgs/String, JSON)
//! topic = "/perturb/events"
//! transport = "ros1"          # default: ROS 1 if an egress is, else ROS 2
//! mode = "frames"             # or "changes": per change, plus a 1 Hz heartbeat per stream
//!
//! [kill]                      # the kill switch: raw frames from the next frame, until `perturb ctl arm`
//! topic = "/vehicle/takeover"
//! type = "std_msgs/msg/Bool"  # ROS 2 type (ROS 1: the publisher says); any type, by field path
//! field = "data"
//! kill_when = true            # or kill_unless = true (an engage flag)
//! deadman_s = 0.5             # also kill when the topic is silent this long or its publisher leaves
//!
//! [pose]                      # the vehicle's position, for the daemon's campaign (route, geofence)
//! topic = "/localization/current_pose"
//! type = "geometry_msgs/msg/PoseStamped"   # ROS 2 type; any type with a position
//!
//! [record]                    # streams -> rosbag2 MCAP + /perturb/events
//! out = "recording"
//! streams = ["camera_front"]
//! raw = true
//! perturbed = true
//!
//! [view]                      # live view: Foxglove WebSocket server (docs/live-view.md)
//! bind = "127.0.0.1"          # another address needs allow_remote = true
//! port = 8765
//! rate_hz = 10.0              # camera frames per second and side; clouds: cloud_rate_hz
//! max_width = 640             # camera frames shrunk by a whole factor to at most this width
//!
//! [[synthetic.camera]]        # street scene -> <stream>/raw
//! stream = "camera_front"
//! width = 1920
//! height = 1208
//! rate_hz = 30.0
//!
//! [[synthetic.lidar]]         # VLP-32C -> <stream>/raw
//! stream = "lidar_top"
//! rate_hz = 10.0
//!
//! [streams]                   # kinds of streams fed by another process
//! lidar_roof = "cloud"
//! ```

use crate::dds::{BackendKind, Qos, RosType};
use crate::frame::StreamKind;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

mod validate;

/// Which bus carries frames between the adapters and the daemon.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum BusKind {
    /// iceoryx2 shared memory: sources publish `<stream>/raw`, sinks read `<stream>/perturbed`
    /// written by `perturbd`.
    #[default]
    Iceoryx2,
    /// In-process passthrough without a daemon: sinks get the sources' frames unperturbed (a bag
    /// player, a recorder, a DDS relay).
    Local,
}

/// `[bridge]`.
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct BridgeSection {
    /// Node name.
    pub name: String,
    /// Bus.
    pub bus: BusKind,
    /// Where the end-of-run report (JSON) is written, if anywhere.
    pub report: Option<PathBuf>,
    /// The iceoryx2 namespace (prefix, root, config file) shared with `perturbd`; the
    /// `PERTURB_IOX2_*` environment variables take precedence.
    pub iox2: perturb_wire::TransportOptions,
    /// QoS of the iceoryx2 services the bridge opens: must be compatible with the daemon's
    /// `qos` for the same streams (the service is created with the first opener's values).
    pub qos: perturb_wire::StreamQos,
    /// Seconds: stop once the streams the sinks (egress, record) read have had no publisher
    /// (perturbd, or a source bridge) for this long, after one was seen. Off by default: an
    /// egress feeding an ADS never stops on its own.
    pub stop_after_publishers_gone: Option<f64>,
}

impl Default for BridgeSection {
    fn default() -> Self {
        BridgeSection {
            name: "perturb_bridge".into(),
            bus: BusKind::default(),
            report: None,
            iox2: perturb_wire::TransportOptions::default(),
            qos: perturb_wire::StreamQos::default(),
            stop_after_publishers_gone: None,
        }
    }
}

/// Which middleware an `[[ingress]]` or `[[egress]]` topic is on.
#[derive(
    Clone,
    Copy,
    Debug,
    Default,
    PartialEq,
    Eq,
    PartialOrd,
    Ord,
    Hash,
    serde::Serialize,
    serde::Deserialize,
)]
#[serde(rename_all = "snake_case")]
pub enum Transport {
    /// ROS 2 over DDS (`[dds]`).
    #[default]
    Dds,
    /// ROS 1 over TCPROS (`[ros1]`).
    Ros1,
}

/// `[ros1]`: how the bridge's ROS 1 node reaches the master. Unset keys fall back like the ROS 1
/// client libraries (see [`crate::ros1::Ros1Settings::resolve`]).
#[derive(Clone, Debug, Default, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Ros1Section {
    /// The master's URI; default `ROS_MASTER_URI`, else `http://localhost:11311/`.
    pub master_uri: Option<String>,
    /// The host name or address advertised to other nodes; default `ROS_HOSTNAME`, then
    /// `ROS_IP`, else this machine's host name.
    pub hostname: Option<String>,
    /// The node name; default the `[bridge]` name.
    pub node_name: Option<String>,
    /// Publish `/clock` (`rosgraph_msgs/Clock`) from the replayed bag's log time, as `rosbag
    /// play --clock` does, for ROS 1 nodes running with `use_sim_time`.
    pub clock: bool,
}

/// `[dds]`.
#[derive(Clone, Debug, Default, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct DdsSection {
    /// Backend.
    pub backend: BackendKind,
    /// Domain.
    pub domain_id: u16,
    /// Network interfaces DDS may use (names like `lo`, `eth0`, or IPv4 addresses). Empty (the
    /// default): the DDS implementation's own choice, as ROS 2 nodes on a vehicle expect.
    /// `["lo"]` keeps every DDS packet on this computer (tests, benchmarks, an ADS on the same
    /// computer whose DDS is also on loopback, e.g. with `ROS_LOCALHOST_ONLY=1`).
    pub interfaces: Vec<String>,
}

impl DdsSection {
    /// The participant this section describes.
    pub fn participant(&self) -> crate::dds::ParticipantConfig {
        crate::dds::ParticipantConfig {
            backend: self.backend,
            domain_id: self.domain_id,
            interfaces: self.interfaces.clone(),
        }
    }
}

/// One `[[ingress]]` entry.
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct IngressEntry {
    /// ROS 2 topic to read.
    pub topic: String,
    /// Its type.
    #[serde(rename = "type")]
    pub ros_type: RosType,
    /// Stream to publish into (`<stream>/raw`).
    pub stream: String,
    /// ROS 2 (DDS, the default) or ROS 1.
    #[serde(default)]
    pub transport: Transport,
    /// QoS (sensor data by default; DDS only).
    #[serde(default)]
    pub qos: Qos,
    /// The driver's `camera_info` topic (same transport), relayed with the stream's images by
    /// the egress that names a `camera_info` sink.
    #[serde(default)]
    pub camera_info: Option<String>,
}

/// One `[[egress]]` entry.
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct EgressEntry {
    /// Stream to read (`<stream>/perturbed`).
    pub stream: String,
    /// ROS 2 topic to write.
    pub topic: String,
    /// Stream kind; taken from the ingress, replay or synthetic entry of the stream when omitted.
    #[serde(default)]
    pub kind: Option<StreamKind>,
    /// ROS 2 (DDS, the default) or ROS 1.
    #[serde(default)]
    pub transport: Transport,
    /// QoS (sensor data by default; DDS only).
    #[serde(default)]
    pub qos: Qos,
    /// Milliseconds a raw frame waits for its perturbed version before `on_late` applies;
    /// default one frame period of `rate_hz`, else of the rate measured on the stream.
    #[serde(default)]
    pub deadline_ms: Option<f64>,
    /// The stream's nominal rate (frames per second), for the default deadline.
    #[serde(default)]
    pub rate_hz: Option<f64>,
    /// What a frame that misses its deadline becomes: `raw` (the default: the raw frame goes out
    /// in its place, as on a vehicle), `drop` (nothing goes out, counted: timing studies) or
    /// `wait` (no deadline: each perturbed frame goes out when it comes, nothing while perturbd
    /// is down).
    #[serde(default)]
    pub on_late: crate::guard::OnLate,
    /// Where the stream's `camera_info` goes (the ingress of the stream names its source).
    #[serde(default)]
    pub camera_info: Option<String>,
}

/// `[events]`: the perturbation log on the bus.
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct EventsSection {
    /// The topic (`/perturb/events`).
    #[serde(default = "events_topic")]
    pub topic: String,
    /// ROS 1 or ROS 2; default the transport of the egress topics (ROS 1 if any is).
    #[serde(default)]
    pub transport: Option<Transport>,
    /// `frames` (one record per frame published) or `changes` (per change, and a heartbeat per
    /// stream once a second).
    #[serde(default)]
    pub mode: crate::events::EventsMode,
}

/// `[kill]`: the kill switch's topic.
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct KillSection {
    /// The topic (`/vehicle/takeover`).
    pub topic: String,
    /// ROS 1 or ROS 2; default the transport of the egress topics (ROS 1 if any is).
    #[serde(default)]
    pub transport: Option<Transport>,
    /// The ROS 2 type (`std_msgs/msg/Bool`, the default); over ROS 1 the publisher says.
    #[serde(rename = "type", default = "bool_type")]
    pub ros2_type: String,
    /// The field path read (`data`, the default).
    #[serde(default = "data_field")]
    pub field: String,
    /// Kill when the field equals this (default `true`).
    #[serde(default)]
    pub kill_when: Option<crate::kill::Expected>,
    /// Kill when the field differs from this (an engage flag: `kill_unless = true`).
    #[serde(default)]
    pub kill_unless: Option<crate::kill::Expected>,
    /// The type's definition (`.msg` text with its dependencies), for a ROS 2 type the bridge
    /// does not know.
    #[serde(default)]
    pub definition: Option<String>,
    /// Dead man: seconds of silence (after the first message), or the publisher gone, that
    /// also kill. Absent: off.
    #[serde(default)]
    pub deadman_s: Option<f64>,
    /// The daemon's control service.
    #[serde(default = "control_service")]
    pub control_service: String,
}

impl KillSection {
    /// When it kills.
    pub fn rule(&self) -> crate::kill::Rule {
        match (&self.kill_when, &self.kill_unless) {
            (_, Some(u)) => crate::kill::Rule::Unless(u.clone()),
            (Some(w), None) => crate::kill::Rule::When(w.clone()),
            (None, None) => crate::kill::Rule::When(crate::kill::Expected::Bool(true)),
        }
    }
}

/// `[pose]`: the vehicle's position, sent to the daemon for its campaign's route and geofence
/// steps.
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PoseSection {
    /// The topic (`/localization/current_pose`).
    pub topic: String,
    /// ROS 1 or ROS 2; default the transport of the egress topics (ROS 1 if any is).
    #[serde(default)]
    pub transport: Option<Transport>,
    /// The ROS 2 type (default `geometry_msgs/msg/PoseStamped`); over ROS 1 the publisher says.
    #[serde(rename = "type", default = "pose_type")]
    pub ros2_type: String,
    /// The position's field path (default: found from the type, e.g. `pose.pose.position`).
    #[serde(default)]
    pub field: Option<String>,
    /// The type's definition, for a ROS 2 type the bridge does not know.
    #[serde(default)]
    pub definition: Option<String>,
    /// At most this many positions a second go to the daemon (default 50).
    #[serde(default = "pose_rate")]
    pub max_rate_hz: f64,
    /// The daemon's control service.
    #[serde(default = "control_service")]
    pub control_service: String,
}

fn pose_type() -> String {
    "geometry_msgs/msg/PoseStamped".into()
}

fn pose_rate() -> f64 {
    50.0
}

fn bool_type() -> String {
    "std_msgs/msg/Bool".into()
}

fn data_field() -> String {
    "data".into()
}

fn control_service() -> String {
    perturb_wire::names::CONTROL.to_string()
}

fn events_topic() -> String {
    perturb_bag::events::EVENTS_TOPIC.to_string()
}

/// `[replay]`.
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ReplaySection {
    /// The bag (a `.mcap` file or a rosbag2 directory).
    pub bag: PathBuf,
    /// Speed factor (2 = twice as fast; 0 = as fast as possible).
    #[serde(default = "one")]
    pub rate: f64,
    /// Seconds to skip from the start of the bag.
    #[serde(default)]
    pub start_offset: f64,
    /// Start again at the end.
    #[serde(default, rename = "loop")]
    pub looped: bool,
    /// Bag topic -> stream; empty: every Image, CompressedImage and PointCloud2 topic, each on a
    /// stream named after the topic without its leading `/`.
    #[serde(default)]
    pub topics: BTreeMap<String, String>,
}

fn one() -> f64 {
    1.0
}

fn yes() -> bool {
    true
}

/// `[record]`.
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RecordSection {
    /// Output bag directory (must not exist or be empty).
    pub out: PathBuf,
    /// Streams to record.
    pub streams: Vec<String>,
    /// Record `<stream>/raw` (topic `/<stream>/raw` unless `topics` says otherwise).
    #[serde(default = "yes")]
    pub raw: bool,
    /// Record `<stream>/perturbed` (topic `/<stream>/perturbed`) and the event channel.
    #[serde(default = "yes")]
    pub perturbed: bool,
    /// Bag format: `mcap` (rosbag2 MCAP, the default) or `bag1` (a ROS 1 `.bag` file).
    #[serde(default)]
    pub format: Option<String>,
    /// Chunk compression: for `mcap` zstd (default), `zstd:LEVEL` (1..=19), lz4, none; for
    /// `bag1` none (default), bz2, lz4.
    #[serde(default)]
    pub compression: Option<String>,
    /// Stop after this many perturbed (or, when only raw is recorded, raw) frames per stream.
    #[serde(default)]
    pub max_frames: Option<u64>,
    /// Stop after this many seconds of recording.
    #[serde(default)]
    pub seconds: Option<f64>,
}

/// The largest synthetic camera frame (RGB, 3 bytes a pixel): 256 MiB, e.g. 8192x8192.
pub const MAX_SYNTHETIC_FRAME_BYTES: u64 = 256 << 20;

/// The most memory a synthetic camera's pre-rendered frames may take: 1 GiB (30 frames of
/// 1920x1208 take 209 MB).
pub const MAX_PRERENDER_BYTES: u64 = 1 << 30;

/// Bytes of one synthetic camera frame of `width` x `height` (RGB).
pub fn synthetic_frame_bytes(width: u32, height: u32) -> u64 {
    width as u64 * height as u64 * 3
}

/// How many frames of `width` x `height` fit in [`MAX_PRERENDER_BYTES`], at most `want`.
pub fn prerender_that_fits(width: u32, height: u32, want: u32) -> u32 {
    let per = synthetic_frame_bytes(width, height).max(1);
    want.min(u32::try_from(MAX_PRERENDER_BYTES / per).unwrap_or(u32::MAX))
}

/// `[[synthetic.camera]]`.
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SyntheticCamera {
    /// Stream.
    pub stream: String,
    /// Width.
    #[serde(default = "default_width")]
    pub width: u32,
    /// Height.
    #[serde(default = "default_height")]
    pub height: u32,
    /// Frames per second.
    #[serde(default = "default_cam_rate")]
    pub rate_hz: f64,
    /// frame_id.
    #[serde(default = "default_cam_frame")]
    pub frame_id: String,
    /// Frames rendered ahead and cycled (rendering a 1920x1208 scene takes longer than a frame
    /// period on a small machine); 0 renders every frame live.
    #[serde(default = "default_prerender")]
    pub prerender: u32,
    /// Stop after this many frames (default: run until stopped).
    #[serde(default)]
    pub count: Option<u64>,
}

fn default_width() -> u32 {
    1920
}
fn default_height() -> u32 {
    1208
}
fn default_cam_rate() -> f64 {
    30.0
}
fn default_lidar_rate() -> f64 {
    10.0
}
fn default_cam_frame() -> String {
    "camera_front".into()
}
fn default_lidar_frame() -> String {
    "velodyne".into()
}
fn default_prerender() -> u32 {
    30
}

/// `[[synthetic.lidar]]`.
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SyntheticLidar {
    /// Stream.
    pub stream: String,
    /// Scans per second.
    #[serde(default = "default_lidar_rate")]
    pub rate_hz: f64,
    /// frame_id.
    #[serde(default = "default_lidar_frame")]
    pub frame_id: String,
    /// Scans rendered ahead and cycled; 0 renders every scan live.
    #[serde(default = "default_prerender")]
    pub prerender: u32,
    /// Stop after this many scans.
    #[serde(default)]
    pub count: Option<u64>,
}

/// `[synthetic]`.
#[derive(Clone, Debug, Default, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SyntheticSection {
    /// Cameras.
    pub camera: Vec<SyntheticCamera>,
    /// LiDARs.
    pub lidar: Vec<SyntheticLidar>,
}

/// The whole configuration.
#[derive(Clone, Debug, Default, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Config {
    /// `[bridge]`.
    pub bridge: BridgeSection,
    /// `[dds]`.
    pub dds: DdsSection,
    /// `[ros1]`.
    pub ros1: Ros1Section,
    /// `[[ingress]]`.
    pub ingress: Vec<IngressEntry>,
    /// `[[egress]]`.
    pub egress: Vec<EgressEntry>,
    /// `[replay]`.
    pub replay: Option<ReplaySection>,
    /// `[record]`.
    pub record: Option<RecordSection>,
    /// `[synthetic]`.
    pub synthetic: SyntheticSection,
    /// `[streams]`: what streams fed by another process carry (`camera_front = "image"`), for
    /// bridges that only record or only egress.
    pub streams: BTreeMap<String, StreamKind>,
    /// `[events]`: publish the events records on the bus.
    pub events: Option<EventsSection>,
    /// `[kill]`: the kill switch's topic.
    pub kill: Option<KillSection>,
    /// `[pose]`: the vehicle's position, for the daemon's campaign.
    pub pose: Option<PoseSection>,
    /// `[view]`: the live view (Foxglove WebSocket server).
    pub view: Option<ViewSection>,
}

/// `[view]`: the live view, a Foxglove WebSocket server in the bridge showing each stream raw
/// beside perturbed, the events, the statistics, with the daemon's controls (`docs/live-view.md`).
/// Off unless the section is there.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ViewSection {
    /// The address the server listens on: a loopback address unless `allow_remote`.
    pub bind: String,
    /// The TCP port (0: any free port, logged).
    pub port: u16,
    /// Serve on an address other viewers than this computer's can reach (the view shows the
    /// cameras and can switch perturbations and the kill switch).
    pub allow_remote: bool,
    /// The streams shown (default: every stream this bridge knows the kind of).
    pub streams: Vec<String>,
    /// Camera frames per second and side sent to viewers (the others are skipped).
    pub rate_hz: f64,
    /// Point clouds per second and side sent to viewers.
    pub cloud_rate_hz: f64,
    /// Camera frames wider than this are shrunk by the smallest whole factor that makes them at
    /// most this wide before JPEG encoding (1920x1208 -> 640x402, 800x503 -> 400x251).
    pub max_width: u32,
    /// JPEG quality, 1..=100.
    pub jpeg_quality: u8,
    /// Clouds are thinned (every k-th point) to at most this many points.
    pub max_points: u32,
    /// Seconds between two statistics messages of a stream (and two daemon status queries).
    pub stats_interval_s: f64,
    /// Offer the daemon's controls (set, off, kill, arm, status) as services.
    pub control: bool,
    /// The daemon's control service.
    pub control_service: String,
    /// Messages queued for one viewer before the oldest are dropped (a slow viewer loses view
    /// messages, never the pipeline's frames).
    pub backlog: usize,
}

impl Default for ViewSection {
    fn default() -> Self {
        ViewSection {
            bind: "127.0.0.1".into(),
            port: 8765,
            allow_remote: false,
            streams: Vec::new(),
            rate_hz: 10.0,
            cloud_rate_hz: 5.0,
            max_width: 640,
            jpeg_quality: 75,
            max_points: 150_000,
            stats_interval_s: 1.0,
            control: true,
            control_service: control_service(),
            backlog: 64,
        }
    }
}

/// A configuration error: the file, the key and the problem.
#[derive(Debug, thiserror::Error)]
#[error("{file}: {key}: {problem}")]
pub struct ConfigError {
    /// The file.
    pub file: String,
    /// The key (`egress[1].topic`).
    pub key: String,
    /// What is wrong.
    pub problem: String,
}

impl Config {
    /// Reads and validates a file.
    pub fn load(path: &Path) -> Result<Config, ConfigError> {
        let file = path.display().to_string();
        let text = std::fs::read_to_string(path).map_err(|e| ConfigError {
            file: file.clone(),
            key: "(file)".into(),
            problem: e.to_string(),
        })?;
        let mut cfg = Self::parse(&text, &file)?;
        // Relative paths in the file (bag, record.out, report) are relative to the file.
        if let Some(dir) = path.parent() {
            if let Some(r) = &mut cfg.replay
                && r.bag.is_relative()
            {
                r.bag = dir.join(&r.bag);
            }
            if let Some(r) = &mut cfg.record
                && r.out.is_relative()
            {
                r.out = dir.join(&r.out);
            }
            if let Some(r) = &mut cfg.bridge.report
                && r.is_relative()
            {
                *r = dir.join(&*r);
            }
        }
        Ok(cfg)
    }

    /// Parses and validates TOML text; `file` names it in errors.
    pub fn parse(text: &str, file: &str) -> Result<Config, ConfigError> {
        let cfg: Config = toml::from_str(text).map_err(|e| {
            let key = e
                .span()
                .map(|s| {
                    let start = s.start.min(text.len());
                    let line = text[..start].matches('\n').count() + 1;
                    let what: String = text
                        .get(start..s.end.min(text.len()))
                        .unwrap_or("")
                        .chars()
                        .take(40)
                        .collect();
                    if what.trim().is_empty() || what.contains('\n') {
                        format!("line {line}")
                    } else {
                        format!("line {line} `{}`", what.trim())
                    }
                })
                .unwrap_or_else(|| "(toml)".into());
            ConfigError {
                file: file.to_string(),
                key,
                problem: e.message().to_string(),
            }
        })?;
        cfg.validate(file)?;
        Ok(cfg)
    }

    /// True if the bridge needs a ROS 1 node (a ROS 1 topic, or `/clock`).
    pub fn uses_ros1(&self) -> bool {
        self.ingress.iter().any(|i| i.transport == Transport::Ros1)
            || self.egress.iter().any(|e| e.transport == Transport::Ros1)
            || self.ros1.clock
            || self.events_transport() == Some(Transport::Ros1)
            || self.kill_transport() == Some(Transport::Ros1)
            || self.pose_transport() == Some(Transport::Ros1)
    }

    /// The transport of the pose topic, if there is one.
    pub fn pose_transport(&self) -> Option<Transport> {
        let p = self.pose.as_ref()?;
        Some(p.transport.unwrap_or(self.default_small_transport()))
    }

    /// The transport of the kill switch's topic, if there is one.
    pub fn kill_transport(&self) -> Option<Transport> {
        let k = self.kill.as_ref()?;
        Some(k.transport.unwrap_or(self.default_small_transport()))
    }

    /// ROS 1 if an egress topic is on ROS 1, else ROS 2.
    fn default_small_transport(&self) -> Transport {
        if self.egress.iter().any(|e| e.transport == Transport::Ros1) {
            Transport::Ros1
        } else {
            Transport::Dds
        }
    }

    /// The transport of the events topic, if the bridge publishes one.
    pub fn events_transport(&self) -> Option<Transport> {
        let e = self.events.as_ref()?;
        Some(e.transport.unwrap_or(self.default_small_transport()))
    }

    /// The ROS 1 node's settings (`[ros1]` with the environment's fallbacks).
    pub fn ros1_settings(&self) -> Result<crate::ros1::Ros1Settings, String> {
        crate::ros1::Ros1Settings::resolve(
            self.ros1.master_uri.as_deref(),
            self.ros1.hostname.as_deref(),
            self.ros1.node_name.as_deref().unwrap_or(&self.bridge.name),
        )
    }

    /// The bag format of `[record]`.
    pub fn record_format(&self) -> perturb_bag::BagFormat {
        self.record
            .as_ref()
            .and_then(|r| r.format.as_deref())
            .and_then(|f| f.parse().ok())
            .unwrap_or_default()
    }

    /// The kind of every stream a source feeds (ingress, replay with explicit topics, synthetic).
    pub fn source_kinds(&self) -> BTreeMap<String, StreamKind> {
        let mut m = self.streams.clone();
        for i in &self.ingress {
            let k = match i.ros_type {
                RosType::PointCloud2 => StreamKind::Cloud,
                _ => StreamKind::Image,
            };
            m.insert(i.stream.clone(), k);
        }
        for c in &self.synthetic.camera {
            m.insert(c.stream.clone(), StreamKind::Image);
        }
        for l in &self.synthetic.lidar {
            m.insert(l.stream.clone(), StreamKind::Cloud);
        }
        m
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(s: &str) -> Result<Config, ConfigError> {
        Config::parse(s, "t.toml")
    }

    #[test]
    fn full_example_parses_with_defaults() {
        let c = parse(
            r#"
[dds]
backend = "cyclone"
[[ingress]]
topic = "/sensing/camera/front/image_raw"
type = "compressed_image"
stream = "camera_front"
[[egress]]
stream = "camera_front"
topic = "/perturbed/camera_front"
qos = { reliability = "reliable", depth = 10 }
[[synthetic.lidar]]
stream = "lidar_top"
[record]
out = "rec"
streams = ["camera_front", "lidar_top"]
"#,
        )
        .unwrap();
        assert_eq!(c.dds.backend, BackendKind::Cyclone);
        assert_eq!(c.ingress[0].qos, Qos::SENSOR_DATA);
        assert_eq!(c.egress[0].qos.depth, 10);
        assert_eq!(c.egress[0].qos.durability, crate::dds::Durability::Volatile);
        assert_eq!(c.synthetic.lidar[0].rate_hz, 10.0);
        assert!(c.record.as_ref().unwrap().raw);
    }

    #[test]
    fn errors_name_the_key_and_the_problem() {
        let e = parse("[[ingress]]\ntopic = \"/a\"\ntype = \"image\"\nstream = \"s\"\n[[egress]]\nstream = \"s\"\ntopic = \"/a\"\n").unwrap_err();
        assert_eq!(e.key, "egress[0].topic");
        assert!(e.problem.contains("its own output"), "{e}");
        let e = parse("[[egress]]\nstream = \"s\"\ntopic = \"no_slash\"\nkind = \"image\"\n")
            .unwrap_err();
        assert_eq!(e.key, "egress[0].topic");
        let e = parse("[[egress]]\nstream = \"s\"\ntopic = \"/t\"\n").unwrap_err();
        assert_eq!(e.key, "egress[0].kind");
        let e = parse("[replay]\nbag = \"b\"\nrate = -1\n").unwrap_err();
        assert_eq!(e.key, "replay.rate");
        let e = parse("[replay]\nbag = \"b\"\nspeed = 2\n").unwrap_err();
        assert!(e.problem.contains("unknown field `speed`"), "{e}");
        assert_eq!(e.key, "line 3 `speed`");
        let e =
            parse("[[ingress]]\ntopic = \"/a\"\ntype = \"video\"\nstream = \"s\"\n").unwrap_err();
        assert!(e.problem.contains("video"), "{e}");
        let e = parse("").unwrap_err();
        assert!(e.problem.contains("no adapter"), "{e}");
        let e = parse("[record]\nout = \"x\"\nstreams = [\"a\", \"a\"]\n").unwrap_err();
        assert_eq!(e.key, "record.streams[1]");
        assert!(e.problem.contains("twice"), "{e}");
        let e = parse("[record]\nout = \"x\"\nstreams = [\"../../etc\"]\n").unwrap_err();
        assert_eq!(e.key, "record.streams[0]");
        assert!(e.problem.contains("not a path"), "{e}");
        let e = parse("[record]\nout = \"x\"\nstreams = [\"a\"]\ncompression = \"gzip\"\n")
            .unwrap_err();
        assert_eq!(e.key, "record.compression");
        let e = parse(
            "[bridge]\nstop_after_publishers_gone = 0\n[record]\nout = \"x\"\nstreams = [\"a\"]\n",
        )
        .unwrap_err();
        assert_eq!(e.key, "bridge.stop_after_publishers_gone");
    }

    /// What the outside test found `--check` let through: a frame_id longer than the wire
    /// header holds, `subscriber_buffer = 0`, a report in a folder that does not exist, stream
    /// names the daemon would refuse; and the new sections' keys.
    #[test]
    fn check_refuses_what_would_fail_later_naming_the_key() {
        let long = "f".repeat(300);
        let e = parse(&format!(
            "[[synthetic.camera]]\nstream = \"c\"\nwidth = 64\nheight = 48\nframe_id = \"{long}\"\n"
        ))
        .unwrap_err();
        assert_eq!(e.key, "synthetic.camera[0].frame_id");
        assert!(e.problem.contains("256"), "{e}");
        let e = parse(
            "[bridge]\nqos = { subscriber_buffer = 0 }\n[[synthetic.lidar]]\nstream = \"l\"\n",
        )
        .unwrap_err();
        assert_eq!(e.key, "bridge.qos");
        assert!(e.problem.contains("subscriber_buffer"), "{e}");
        let e = parse(
            "[bridge]\nreport = \"/nonexistent-folder-xyz/report.json\"\n[[synthetic.lidar]]\nstream = \"l\"\n",
        )
        .unwrap_err();
        assert_eq!(e.key, "bridge.report");
        assert!(e.problem.contains("does not exist"), "{e}");
        for bad in ["a/../b", "/a", "a//b", "a b"] {
            let e = parse(&format!("[[synthetic.lidar]]\nstream = \"{bad}\"\n")).unwrap_err();
            assert_eq!(e.key, "synthetic.lidar[0].stream", "{bad}");
        }
        let cam = "[[ingress]]\ntopic = \"/a\"\ntype = \"image\"\nstream = \"s\"\n";
        let e = parse(&format!(
            "{cam}[[egress]]\nstream = \"s\"\ntopic = \"/b\"\ncamera_info = \"/b_info\"\n"
        ))
        .unwrap_err();
        assert_eq!(e.key, "egress[0].camera_info");
        assert!(e.problem.contains("names the camera_info"), "{e}");
        let e = parse(&format!(
            "{cam}[[egress]]\nstream = \"s\"\ntopic = \"/b\"\ndeadline_ms = 0\n"
        ))
        .unwrap_err();
        assert_eq!(e.key, "egress[0].deadline_ms");
        let e = parse(&format!("{cam}[events]\ntopic = \"/a\"\n")).unwrap_err();
        assert_eq!(e.key, "events.topic");
        let e = parse(&format!(
            "{cam}[kill]\ntopic = \"/k\"\ntype = \"my_msgs/msg/Engage\"\n"
        ))
        .unwrap_err();
        assert_eq!(e.key, "kill.definition");
        let e = parse(&format!("{cam}[kill]\ntopic = \"/k\"\nfield = \"state\"\n")).unwrap_err();
        assert_eq!(e.key, "kill.field");
        assert!(e.problem.contains("state"), "{e}");
        let e = parse(&format!(
            "{cam}[kill]\ntopic = \"/k\"\nkill_when = true\nkill_unless = false\n"
        ))
        .unwrap_err();
        assert_eq!(e.key, "kill.kill_unless");
        let ok = parse(&format!(
            "{cam}[kill]\ntopic = \"/k\"\ntype = \"my_msgs/msg/Mode\"\nfield = \"mode\"\nkill_when = 2\n\
             definition = \"uint8 mode\"\n[pose]\ntopic = \"/odom\"\ntype = \"nav_msgs/msg/Odometry\"\n"
        ))
        .unwrap();
        assert!(
            ok.kill
                .unwrap()
                .rule()
                .kills(&perturb_bag::dynamic::Value::Int(2))
        );
        let e = parse(&format!(
            "{cam}[pose]\ntopic = \"/odom\"\ntype = \"std_msgs/msg/Bool\"\n"
        ))
        .unwrap_err();
        assert_eq!(e.key, "pose.field");
    }

    /// `[view]`: loopback unless `allow_remote`, keys named in every refusal.
    #[test]
    fn view_binds_to_loopback_unless_remote_is_allowed() {
        let cam = "[[synthetic.camera]]\nstream = \"c\"\n";
        let c = parse(&format!("{cam}[view]\n")).unwrap();
        let v = c.view.unwrap();
        assert_eq!(
            (v.bind.as_str(), v.port, v.max_width),
            ("127.0.0.1", 8765, 640)
        );
        for ok in ["::1", "localhost", "127.0.0.2"] {
            assert!(
                parse(&format!("{cam}[view]\nbind = \"{ok}\"\n")).is_ok(),
                "{ok}"
            );
        }
        let e = parse(&format!("{cam}[view]\nbind = \"0.0.0.0\"\n")).unwrap_err();
        assert_eq!(e.key, "view.bind");
        assert!(e.problem.contains("allow_remote = true"), "{e}");
        assert!(
            parse(&format!(
                "{cam}[view]\nbind = \"0.0.0.0\"\nallow_remote = true\n"
            ))
            .is_ok()
        );
        let e = parse(&format!("{cam}[view]\nbind = \"my-laptop\"\n")).unwrap_err();
        assert_eq!(e.key, "view.bind");
        for (key, bad) in [
            ("rate_hz", "0"),
            ("max_width", "8"),
            ("jpeg_quality", "101"),
            ("stats_interval_s", "0"),
            ("backlog", "0"),
        ] {
            let e = parse(&format!("{cam}[view]\n{key} = {bad}\n")).unwrap_err();
            assert_eq!(e.key, format!("view.{key}"), "{e}");
        }
        let e = parse(&format!("{cam}[view]\nstreams = [\"c\", \"c\"]\n")).unwrap_err();
        assert_eq!(e.key, "view.streams[1]");
        // A view alone (streams fed by another process) is a bridge of its own.
        assert!(parse("[streams]\nc = \"image\"\n[view]\n").is_ok());
    }

    /// A 16384x16384 synthetic camera pre-rendered 24 GB before it published anything (and
    /// heeded no SIGINT meanwhile): the frame size and the pre-render memory are bounded, and
    /// the command line's pre-render shrinks to what fits.
    #[test]
    fn synthetic_frames_are_bounded_in_memory() {
        let cam = |size: &str, extra: &str| {
            let (w, h) = size.split_once('x').unwrap();
            parse(&format!(
                "[[synthetic.camera]]\nstream = \"c\"\nwidth = {w}\nheight = {h}\n{extra}"
            ))
        };
        let e = cam("16384x16384", "").unwrap_err();
        assert_eq!(e.key, "synthetic.camera[0].width");
        assert!(e.problem.contains("768 MiB each"), "{e}");
        let e = cam("8192x8192", "").unwrap_err();
        assert_eq!(e.key, "synthetic.camera[0].prerender");
        assert!(e.problem.contains("prerender = 5 or less"), "{e}");
        assert!(cam("8192x8192", "prerender = 5").is_ok());
        assert!(cam("1920x1208", "").is_ok());
        assert_eq!(prerender_that_fits(8192, 8192, 30), 5);
        assert_eq!(prerender_that_fits(1920, 1208, 30), 30);
    }
}
