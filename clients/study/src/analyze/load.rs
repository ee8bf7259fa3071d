//! Reading the configured topics of a run into plain time series, decoding every message by the
//! schema stored in the bag.

use super::events::ExternalEvents;
use super::{AnalyzeConfig, Condition, ObjectsFrame, TopicField};
use crate::error::{Result, StudyError};
use crate::source::{RunEntry, RunMessage, TopicSchema, open_run};
use perturb_bag::dynamic::{DynError, FieldPath, MessageCodec, Value};
use perturb_bag::events::{EventKind, EventRecord};
use std::collections::BTreeMap;

/// One pose sample.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PoseSample {
    /// Seconds from the run's start.
    pub t: f64,
    /// Position in the pose frame, metres.
    pub p: [f64; 2],
    /// Heading (yaw), radians, when the message has an orientation.
    pub yaw: Option<f64>,
}

/// The time series of one run, as the metrics need them.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct RunData {
    /// The run's name.
    pub name: String,
    /// The run's group (sub-folder), if any.
    pub group: Option<String>,
    /// Log time of the first message read, ns (t = 0).
    pub t0_ns: u64,
    /// Seconds from the start to the last message read.
    pub end: f64,
    /// Poses in time order.
    pub poses: Vec<PoseSample>,
    /// Steering commands (t, value).
    pub steering: Vec<(f64, f64)>,
    /// Detected objects per message (t, positions in [`RunData::objects_frame`]).
    pub objects: Vec<(f64, Vec<[f64; 2]>)>,
    /// The frame of the objects.
    pub objects_frame: ObjectsFrame,
    /// First takeover signal.
    pub takeover: Option<f64>,
    /// First collision signal.
    pub collision: Option<f64>,
    /// Condition changes (t, condition from then on), in time order.
    pub events: Vec<(f64, Condition)>,
    /// Remarks.
    pub notes: Vec<String>,
}

/// The default position path of a pose-like message type.
const POSITION_CANDIDATES: [&str; 6] = [
    "pose.pose.position",
    "pose.position",
    "position",
    "transform.translation",
    "point",
    "pose.pose.pose.position",
];

fn default_steering_field(type_name: &str) -> Option<&'static str> {
    let t = perturb_bag::dynamic::normalize_type_name(type_name);
    Some(match t.as_str() {
        "ackermann_msgs/AckermannDriveStamped" => "drive.steering_angle",
        "ackermann_msgs/AckermannDrive" => "steering_angle",
        "std_msgs/Float32" | "std_msgs/Float64" => "data",
        "autoware_auto_control_msgs/AckermannControlCommand" | "autoware_control_msgs/Control" => {
            "lateral.steering_tire_angle"
        }
        "autoware_auto_control_msgs/AckermannLateralCommand" | "autoware_control_msgs/Lateral" => {
            "steering_tire_angle"
        }
        "autoware_msgs/VehicleCmd" => "ctrl_cmd.steering_angle",
        "autoware_msgs/ControlCommandStamped" => "cmd.steering_angle",
        _ => return None,
    })
}

fn default_objects(type_name: &str) -> Option<(&'static str, &'static str)> {
    let t = perturb_bag::dynamic::normalize_type_name(type_name);
    Some(match t.as_str() {
        "autoware_msgs/DetectedObjectArray" => ("objects", "pose.position"),
        "vision_msgs/Detection3DArray" => ("detections", "bbox.center.position"),
        "autoware_auto_perception_msgs/DetectedObjects"
        | "autoware_perception_msgs/DetectedObjects" => {
            ("objects", "kinematics.pose_with_covariance.pose.position")
        }
        "autoware_auto_perception_msgs/PredictedObjects"
        | "autoware_perception_msgs/PredictedObjects" => (
            "objects",
            "kinematics.initial_pose_with_covariance.pose.position",
        ),
        "autoware_auto_perception_msgs/TrackedObjects"
        | "autoware_perception_msgs/TrackedObjects" => {
            ("objects", "kinematics.pose_with_covariance.pose.position")
        }
        "visualization_msgs/MarkerArray" => ("markers", "pose.position"),
        "geometry_msgs/PoseArray" => ("poses", "position"),
        _ => return None,
    })
}

fn default_flag_field(type_name: &str) -> Option<&'static str> {
    let t = perturb_bag::dynamic::normalize_type_name(type_name);
    match t.as_str() {
        "std_msgs/Bool" | "std_msgs/Int8" | "std_msgs/UInt8" | "std_msgs/Int32"
        | "std_msgs/String" => Some("data"),
        _ => None,
    }
}

/// Everything needed to read one topic.
struct Reader {
    codec: MessageCodec,
    topic: String,
}

impl Reader {
    fn path(&self, run: &str, field: &str) -> Result<FieldPath> {
        self.codec.path(field).map_err(|source| StudyError::Field {
            run: run.to_string(),
            topic: self.topic.clone(),
            field: field.to_string(),
            source: Box::new(source),
        })
    }
}

fn reader(run: &str, topics: &[TopicSchema], topic: &str, what: &str) -> Result<Reader> {
    let Some(t) = topics.iter().find(|t| t.topic == topic) else {
        let mut names: Vec<&str> = topics.iter().map(|t| t.topic.as_str()).collect();
        names.sort();
        return Err(StudyError::Run {
            run: run.to_string(),
            reason: format!(
                "no {what} topic `{topic}` in the bag (its topics: {})",
                names.join(", ")
            ),
        });
    };
    let codec = MessageCodec::new(
        &t.type_name,
        &t.schema_encoding,
        &t.schema,
        &t.message_encoding,
    )
    .map_err(|e| StudyError::Run {
        run: run.to_string(),
        reason: format!("the schema of `{topic}` ({}) is unusable: {e}", t.type_name),
    })?;
    Ok(Reader {
        codec,
        topic: topic.to_string(),
    })
}

/// The yaw of a quaternion (x, y, z, w).
fn yaw_of(q: [f64; 4]) -> f64 {
    let [x, y, z, w] = q;
    (2.0 * (w * z + x * y)).atan2(1.0 - 2.0 * (y * y + z * z))
}

struct PoseReader {
    r: Reader,
    x: FieldPath,
    y: FieldPath,
    orientation: Option<FieldPath>,
}

fn pose_reader(run: &str, topics: &[TopicSchema], cfg: &TopicField) -> Result<PoseReader> {
    let r = reader(run, topics, &cfg.topic, "pose")?;
    let base = match &cfg.field {
        Some(f) => f.trim_end_matches(".x").to_string(),
        None => POSITION_CANDIDATES
            .iter()
            .find(|c| r.codec.path(&format!("{c}.x")).is_ok())
            .map(|c| c.to_string())
            .ok_or_else(|| StudyError::Run {
                run: run.to_string(),
                reason: format!(
                    "cannot tell where the position is in `{}` messages ({}); give it with --pose-field (e.g. pose.pose.position)",
                    cfg.topic,
                    r.codec.schema().root
                ),
            })?,
    };
    let x = r.path(run, &format!("{base}.x"))?;
    let y = r.path(run, &format!("{base}.y"))?;
    let parent = base
        .rsplit_once('.')
        .map(|(p, _)| format!("{p}."))
        .unwrap_or_default();
    let orientation = ["orientation", "rotation"]
        .iter()
        .find_map(|o| r.codec.path(&format!("{parent}{o}")).ok());
    Ok(PoseReader {
        r,
        x,
        y,
        orientation,
    })
}

struct ScalarReader {
    r: Reader,
    /// None: every message counts (a signal topic without a field).
    field: Option<FieldPath>,
}

fn scalar_reader(
    run: &str,
    topics: &[TopicSchema],
    cfg: &TopicField,
    what: &str,
    default: fn(&str) -> Option<&'static str>,
    required: bool,
) -> Result<ScalarReader> {
    let r = reader(run, topics, &cfg.topic, what)?;
    let type_name = &r.codec.schema().root;
    let field = match (&cfg.field, default(type_name)) {
        (Some(f), _) => Some(f.clone()),
        (None, Some(d)) => Some(d.to_string()),
        (None, None) if required => {
            return Err(StudyError::Run {
                run: run.to_string(),
                reason: format!(
                    "no default {what} field for `{}` messages on `{}`; give it with --{what}-field",
                    type_name, cfg.topic
                ),
            });
        }
        (None, None) => None,
    };
    let field = field.map(|f| r.path(run, &f)).transpose()?;
    Ok(ScalarReader { r, field })
}

struct ObjectsReader {
    r: Reader,
    array: FieldPath,
    position: String,
}

fn objects_reader(
    run: &str,
    topics: &[TopicSchema],
    cfg: &super::ObjectsConfig,
) -> Result<ObjectsReader> {
    let r = reader(run, topics, &cfg.topic, "objects")?;
    let defaults = default_objects(&r.codec.schema().root);
    let array = match (&cfg.array, defaults) {
        (Some(a), _) => a.clone(),
        (None, Some((a, _))) => a.to_string(),
        (None, None) => {
            return Err(StudyError::Run {
                run: run.to_string(),
                reason: format!(
                    "cannot tell where the objects are in `{}` messages on `{}`; give --objects-array and --object-position",
                    r.codec.schema().root,
                    cfg.topic
                ),
            });
        }
    };
    let position = match (&cfg.position, defaults) {
        (Some(p), _) => p.clone(),
        (None, Some((_, p))) => p.to_string(),
        (None, None) => "pose.position".to_string(),
    };
    // Check the element paths against the schema now, so a typo is an error, not silence.
    r.path(run, &format!("{array}[0].{position}.x"))?;
    r.path(run, &format!("{array}[0].{position}.y"))?;
    let array = r.path(run, &array)?;
    Ok(ObjectsReader { r, array, position })
}

/// Reads the configured topics of a run. Errors name the run (and the topic and field): a
/// missing pose topic, a field path the message type does not have, an unreadable bag.
pub fn load_run(entry: &RunEntry, cfg: &AnalyzeConfig) -> Result<RunData> {
    let run = entry.name.as_str();
    let failed = |e: &dyn std::fmt::Display| StudyError::Run {
        run: run.to_string(),
        reason: e.to_string(),
    };
    let bag = open_run(&entry.path).map_err(|e| failed(&e))?;
    let topics = bag.topics().map_err(|e| failed(&e))?;
    let mut notes = Vec::new();
    let readers = Readers::open(run, &topics, cfg, &mut notes)?;
    let wanted = readers.topics();
    let mut c = Collector {
        cfg,
        readers: &readers,
        d: RunData {
            name: entry.name.clone(),
            group: entry.group.clone(),
            objects_frame: cfg.objects.as_ref().map(|o| o.frame).unwrap_or_default(),
            ..RunData::default()
        },
        t0: None,
        last: 0,
        bad: BTreeMap::new(),
        stream_state: BTreeMap::new(),
        fallbacks: BTreeMap::new(),
        lost: BTreeMap::new(),
        other_streams: BTreeMap::new(),
        current: None,
        signal_state: [None; 2],
    };
    let damage = bag
        .read(&wanted, &mut |m| {
            c.message(m);
            Ok(())
        })
        .map_err(|e| failed(&e))?;
    if let Some(dmg) = damage {
        notes.push(format!("the bag is damaged; read up to the damage: {dmg}"));
    }
    if readers.events.is_none()
        && let Some(ext) = &cfg.external_events
    {
        c.external(ext);
    }
    c.finish(run, &wanted, notes)
}

/// The readers of the configured topics a run has.
struct Readers {
    pose: Option<PoseReader>,
    steering: Option<ScalarReader>,
    objects: Option<ObjectsReader>,
    takeover: Option<ScalarReader>,
    collision: Option<ScalarReader>,
    events: Option<Reader>,
    events_data: Option<FieldPath>,
}

impl Readers {
    /// The readers of `cfg`'s topics among the run's `topics`; a topic the run does not have is
    /// a note (no jitter, no coverage, no signal, all nominal), except the pose topic.
    fn open(
        run: &str,
        topics: &[TopicSchema],
        cfg: &AnalyzeConfig,
        notes: &mut Vec<String>,
    ) -> Result<Readers> {
        if cfg.route.is_some() && cfg.pose.is_none() {
            return Err(StudyError::Config(
                "a route needs a pose topic (--pose-topic) to follow the vehicle".into(),
            ));
        }
        let pose = cfg
            .pose
            .as_ref()
            .map(|p| pose_reader(run, topics, p))
            .transpose()?;
        // A run without the steering or objects topic (a LiDAR run has no steering command of an
        // end-to-end model, a camera run no detections) has no jitter or coverage, with a note.
        let has = |topic: &str| topics.iter().any(|t| t.topic == topic);
        let steering = match &cfg.steering {
            Some(s) if has(&s.topic) => Some(scalar_reader(
                run,
                topics,
                s,
                "steering",
                default_steering_field,
                true,
            )?),
            Some(s) => {
                notes.push(format!("no steering topic `{}`: no jitter", s.topic));
                None
            }
            None => None,
        };
        let objects = match &cfg.objects {
            Some(o) if has(&o.topic) => Some(objects_reader(run, topics, o)?),
            Some(o) => {
                notes.push(format!("no objects topic `{}`: no coverage", o.topic));
                None
            }
            None => None,
        };
        // A missing takeover or collision topic means the signal never fired (a recorder only
        // writes topics that had messages).
        let mut flag = |cfg: &Option<TopicField>, what: &str| -> Result<Option<ScalarReader>> {
            match cfg {
                Some(c) if has(&c.topic) => Ok(Some(scalar_reader(
                    run,
                    topics,
                    c,
                    what,
                    default_flag_field,
                    false,
                )?)),
                Some(c) => {
                    notes.push(format!("no `{}` topic: no {what} signal", c.topic));
                    Ok(None)
                }
                None => Ok(None),
            }
        };
        let takeover = flag(&cfg.takeover, "takeover")?;
        let collision = flag(&cfg.collision, "collision")?;
        let events = if has(&cfg.events_topic) {
            if cfg.external_events.is_some() {
                notes.push(format!(
                    "the bag has its own `{}`: the events recorded apart are not used for it",
                    cfg.events_topic
                ));
            }
            Some(reader(run, topics, &cfg.events_topic, "events")?)
        } else if let Some(ext) = &cfg.external_events {
            notes.push(format!(
                "no `{}` topic in the bag: its events come from the {} events bag(s) recorded apart, matched by log time",
                cfg.events_topic,
                ext.bags.len()
            ));
            None
        } else {
            notes.push(format!(
                "no `{}` topic: the whole run counts as nominal",
                cfg.events_topic
            ));
            None
        };
        let events_data = events.as_ref().map(|e| e.path(run, "data")).transpose()?;
        Ok(Readers {
            pose,
            steering,
            objects,
            takeover,
            collision,
            events,
            events_data,
        })
    }

    /// The topics to read, each once, in the order pose, steering, objects, takeover,
    /// collision, events.
    fn topics(&self) -> Vec<String> {
        let mut wanted: Vec<String> = Vec::new();
        for r in [
            self.pose.as_ref().map(|p| &p.r),
            self.steering.as_ref().map(|s| &s.r),
            self.objects.as_ref().map(|o| &o.r),
            self.takeover.as_ref().map(|s| &s.r),
            self.collision.as_ref().map(|s| &s.r),
            self.events.as_ref(),
        ]
        .into_iter()
        .flatten()
        {
            if !wanted.contains(&r.topic) {
                wanted.push(r.topic.clone());
            }
        }
        wanted
    }
}

/// An event stream's perturbation (id, severity; None when off) and the campaign step that chose
/// it.
type StreamState = (Option<(String, u8)>, Option<u16>);

/// The time series of a run as its messages arrive, and what could not be read.
struct Collector<'a> {
    cfg: &'a AnalyzeConfig,
    readers: &'a Readers,
    d: RunData,
    t0: Option<u64>,
    last: u64,
    /// Per topic: messages that could not be read, and the first reason.
    bad: BTreeMap<String, (usize, String)>,
    /// Per event stream: its perturbation (id, severity), None when off, and the campaign step
    /// that chose it.
    stream_state: BTreeMap<String, StreamState>,
    /// Frames that went out raw in place of their perturbed version (late, perturbd down), per
    /// reason: they do not change the condition.
    fallbacks: BTreeMap<String, usize>,
    /// Frames lost, per cause, as the gap records say.
    lost: BTreeMap<String, u64>,
    /// Events of streams the configuration does not follow, per stream.
    other_streams: BTreeMap<String, usize>,
    current: Option<Condition>,
    /// Per signal (takeover, collision) with a value: whether its last message had it.
    signal_state: [Option<bool>; 2],
}

/// A signal field that is "true": non-zero, `true`, or a non-empty string other than `0` and
/// `false`.
fn truthy(v: &Value) -> bool {
    match v {
        Value::String(st) => {
            let st = st.trim().to_ascii_lowercase();
            !(st.is_empty() || st == "0" || st == "false")
        }
        other => other.as_bool().unwrap_or(false),
    }
}

/// A signal field equal to `want`: as numbers when both are numbers, as text otherwise.
fn equals(v: &Value, want: &str) -> bool {
    let want = want.trim();
    match (v.as_f64(), want.parse::<f64>()) {
        (Some(a), Ok(b)) => a == b,
        _ => match v {
            Value::String(s) => s.trim() == want,
            Value::Bool(b) => want.eq_ignore_ascii_case(if *b { "true" } else { "false" }),
            _ => false,
        },
    }
}

impl Collector<'_> {
    /// Takes one message of any of the readers' topics.
    fn message(&mut self, m: RunMessage<'_>) {
        let t0 = *self.t0.get_or_insert(m.log_time);
        self.last = self.last.max(m.log_time);
        let t = m.log_time.saturating_sub(t0) as f64 / 1e9;
        let r = self.readers;
        if let Some(pose) = &r.pose
            && m.topic == pose.r.topic
        {
            self.pose(pose, m, t);
        }
        if let Some(s) = &r.steering
            && m.topic == s.r.topic
            && let Some(f) = &s.field
        {
            match s.r.codec.get_f64(m.data, f) {
                Ok(v) => self.d.steering.push((t, v)),
                Err(e) => self.fail(m.topic, e.to_string()),
            }
        }
        if let Some(o) = &r.objects
            && m.topic == o.r.topic
        {
            self.objects(o, m, t);
        }
        self.flags(m, t);
        if let (Some(e), Some(path)) = (&r.events, &r.events_data)
            && m.topic == e.topic
        {
            self.event(e, path, m, t);
        }
    }

    /// Counts a message of `topic` that could not be read.
    fn fail(&mut self, topic: &str, reason: String) {
        let b = self.bad.entry(topic.to_string()).or_insert((0, reason));
        b.0 += 1;
    }

    fn pose(&mut self, pose: &PoseReader, m: RunMessage<'_>, t: f64) {
        let xy = pose
            .r
            .codec
            .get_f64(m.data, &pose.x)
            .and_then(|x| Ok([x, pose.r.codec.get_f64(m.data, &pose.y)?]));
        match xy {
            Ok(p) => {
                let yaw = pose.orientation.as_ref().and_then(|o| {
                    let q = pose.r.codec.get(m.data, o).ok()?;
                    let c = |n| q.field(n).and_then(Value::as_f64);
                    Some(yaw_of([c("x")?, c("y")?, c("z")?, c("w")?]))
                });
                self.d.poses.push(PoseSample { t, p, yaw });
            }
            Err(e) => self.fail(m.topic, e.to_string()),
        }
    }

    fn objects(&mut self, o: &ObjectsReader, m: RunMessage<'_>, t: f64) {
        match o.r.codec.get(m.data, &o.array) {
            Ok(Value::Array(items)) => {
                let pts = items
                    .iter()
                    .filter_map(|it| {
                        let p = it.at(&o.position)?;
                        Some([p.field("x")?.as_f64()?, p.field("y")?.as_f64()?])
                    })
                    .collect();
                self.d.objects.push((t, pts));
            }
            Ok(other) => {
                let e = DynError::NotANumber {
                    path: o.array.to_string(),
                    kind: other.kind(),
                };
                self.fail(m.topic, e.to_string())
            }
            Err(e) => self.fail(m.topic, e.to_string()),
        }
    }

    /// The takeover and collision signals: the first message that fires each.
    fn flags(&mut self, m: RunMessage<'_>, t: f64) {
        let r = self.readers;
        let cfg = self.cfg;
        for (k, sig, value) in [
            (0, &r.takeover, &cfg.takeover_value),
            (1, &r.collision, &cfg.collision_value),
        ] {
            let Some(s) = sig else { continue };
            let slot = if k == 1 {
                &self.d.collision
            } else {
                &self.d.takeover
            };
            if m.topic != s.r.topic || slot.is_some() {
                continue;
            }
            let fired = match (&s.field, value) {
                (None, _) => Ok(true),
                (Some(f), None) => s.r.codec.get(m.data, f).map(|v| truthy(&v)),
                (Some(f), Some(want)) => s.r.codec.get(m.data, f).map(|v| {
                    let now = equals(&v, want);
                    let before = self.signal_state[k].replace(now);
                    now && before == Some(false)
                }),
            };
            match fired {
                Ok(true) if k == 1 => self.d.collision = Some(t),
                Ok(true) => self.d.takeover = Some(t),
                Ok(false) => {}
                Err(e) => self.fail(m.topic, e.to_string()),
            }
        }
    }

    /// A perturbation event message: decoded, then applied.
    fn event(&mut self, e: &Reader, path: &FieldPath, m: RunMessage<'_>, t: f64) {
        let text = e.codec.get(m.data, path);
        let ev = match &text {
            Ok(Value::String(s)) => {
                EventRecord::parse(s).map_err(|err| format!("not a perturbation event ({err})"))
            }
            Ok(v) => Err(format!("expected a string, found a {}", v.kind())),
            Err(err) => Err(err.to_string()),
        };
        match ev {
            Ok(ev) => self.apply_event(ev, t),
            Err(reason) => self.fail(m.topic, reason),
        }
    }

    /// A perturbation event: the condition (every followed stream's perturbation) from `t` on.
    /// Gap records are counted, kill and arm records need nothing (the frames after them say
    /// what the ADS got), and a frame that went out raw because perturbd was late or down does
    /// not change the condition (it is counted): the run stays under the perturbation it was
    /// given.
    fn apply_event(&mut self, ev: EventRecord, t: f64) {
        match ev.kind {
            EventKind::Gap => {
                let cause = ev.cause.clone().unwrap_or_else(|| "?".into());
                *self.lost.entry(cause).or_default() += ev.count.unwrap_or(0);
                return;
            }
            EventKind::Kill | EventKind::Arm => return,
            EventKind::Frame | EventKind::Heartbeat => {}
        }
        let streams = &self.cfg.event_streams;
        if !(streams.is_empty() || streams.contains(&ev.topic)) {
            *self.other_streams.entry(ev.topic.clone()).or_default() += 1;
            return;
        }
        if let Some(why @ ("late" | "daemon_down")) = ev.reason.as_deref()
            && !ev.applied
        {
            *self.fallbacks.entry(why.to_string()).or_default() += 1;
            return;
        }
        let state = match (ev.id, ev.severity) {
            (Some(id), Some(s)) => Some((id, s)),
            _ => None,
        };
        let step = state.as_ref().and(ev.step);
        self.stream_state.insert(ev.topic, (state, step));
        let mut c: Vec<(String, u8)> = self
            .stream_state
            .values()
            .filter_map(|(s, _)| s.clone())
            .collect();
        c.sort();
        c.dedup();
        let mut steps: Vec<u16> = self.stream_state.values().filter_map(|(_, k)| *k).collect();
        steps.sort();
        steps.dedup();
        let c = Condition(c, steps);
        if self.current.as_ref() != Some(&c) {
            self.d.events.push((t, c.clone()));
            self.current = Some(c);
        }
    }

    /// The events recorded apart that fall in this run (up to its last message), the last
    /// one of each stream before its first message included.
    fn external(&mut self, ext: &ExternalEvents) {
        let Some(t0) = self.t0 else { return };
        let window = ext.window(t0, self.last);
        for (ns, ev) in window {
            let t = (*ns as f64 - t0 as f64) / 1e9;
            self.apply_event(ev.clone(), t);
        }
    }

    /// The run's data with its notes; an error when nothing (or no pose) could be read.
    fn finish(self, run: &str, wanted: &[String], mut notes: Vec<String>) -> Result<RunData> {
        let cfg = self.cfg;
        if !self.fallbacks.is_empty() {
            let what: Vec<String> = self
                .fallbacks
                .iter()
                .map(|(why, n)| format!("{n} {why}"))
                .collect();
            notes.push(format!(
                "frames the ADS got raw in place of their perturbed version (perturbd late or down), counted under the perturbation the run had: {}",
                what.join(", ")
            ));
        }
        if !self.lost.is_empty() {
            let what: Vec<String> = self
                .lost
                .iter()
                .map(|(cause, n)| format!("{n} {cause}"))
                .collect();
            notes.push(format!(
                "frames lost before the ADS (the events' gap records): {}",
                what.join(", ")
            ));
        }
        if !cfg.event_streams.is_empty()
            && self.stream_state.is_empty()
            && !self.other_streams.is_empty()
        {
            notes.push(format!(
                "no event of the streams {} (the events name {}): the whole run counts as nominal",
                cfg.event_streams.join(", "),
                self.other_streams
                    .keys()
                    .cloned()
                    .collect::<Vec<_>>()
                    .join(", ")
            ));
        }
        for (topic, (n, first)) in self.bad {
            notes.push(format!(
                "{n} message(s) on `{topic}` could not be read and were skipped (first: {first})"
            ));
        }
        let mut d = self.d;
        if let Some(p) = &cfg.pose
            && d.poses.is_empty()
        {
            return Err(StudyError::Run {
                run: run.to_string(),
                reason: format!("no readable message on the pose topic `{}`", p.topic),
            });
        }
        let Some(t0) = self.t0 else {
            return Err(StudyError::Run {
                run: run.to_string(),
                reason: format!(
                    "no message on any of the topics read ({})",
                    wanted.join(", ")
                ),
            });
        };
        d.t0_ns = t0;
        d.end = self.last.saturating_sub(d.t0_ns) as f64 / 1e9;
        // Events before the first message (recorded apart) set the condition at t = 0.
        if let Some(k) = d.events.iter().rposition(|(t, _)| *t <= 0.0) {
            d.events.drain(..k);
            d.events[0].0 = 0.0;
        }
        d.notes = notes;
        // The bag's order is log time; sort defensively (a bag without index is read in file
        // order).
        d.poses.sort_by(|a, b| a.t.total_cmp(&b.t));
        d.steering.sort_by(|a, b| a.0.total_cmp(&b.0));
        d.objects.sort_by(|a, b| a.0.total_cmp(&b.0));
        Ok(d)
    }
}
