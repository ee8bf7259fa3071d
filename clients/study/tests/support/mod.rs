//! Synthetic recorded runs for the analysis tests: a kinematic vehicle driving a known route
//! (100 m straight east, a 20 m radius left quarter turn, 80 m straight north) with a chosen
//! lateral offset, steering signal, perturbation events, collision flag and detected objects,
//! written as rosbag2 MCAP bags with the project's bag writer (the one recordings use). Message
//! types the project has no schema for (Odometry, AckermannDriveStamped, Bool, PoseArray) are
//! written with their ros2msg definitions and encoded by the schema-driven codec.
#![allow(dead_code)]

use perturb_bag::dynamic::{MessageCodec, Value};
use perturb_bag::events::{EVENTS_TOPIC, EVENTS_TYPE, EventRecord};
use perturb_bag::ros1::{Ros1Writer, Ros1WriterOptions};
use perturb_bag::{BagWriter, Compression, WriterOptions};
use std::collections::BTreeMap;
use std::f64::consts::PI;
use std::path::{Path, PathBuf};

const SEP: &str =
    "================================================================================\n";

fn msg(deps: &[(&str, &str)], main: &str) -> String {
    let mut s = main.to_string();
    for (name, text) in deps {
        s.push_str(SEP);
        s.push_str(&format!("MSG: {name}\n{text}"));
    }
    s
}

const HEADER: (&str, &str) = (
    "std_msgs/Header",
    "builtin_interfaces/Time stamp\nstring frame_id\n",
);
const TIME: (&str, &str) = ("builtin_interfaces/Time", "int32 sec\nuint32 nanosec\n");
const POSE: (&str, &str) = (
    "geometry_msgs/Pose",
    "Point position\nQuaternion orientation\n",
);
const POINT: (&str, &str) = ("geometry_msgs/Point", "float64 x\nfloat64 y\nfloat64 z\n");
const QUAT: (&str, &str) = (
    "geometry_msgs/Quaternion",
    "float64 x 0\nfloat64 y 0\nfloat64 z 0\nfloat64 w 1\n",
);
const VEC3: (&str, &str) = ("geometry_msgs/Vector3", "float64 x\nfloat64 y\nfloat64 z\n");

/// nav_msgs/msg/Odometry.
pub fn odometry_schema() -> String {
    msg(
        &[
            HEADER,
            TIME,
            (
                "geometry_msgs/PoseWithCovariance",
                "Pose pose\nfloat64[36] covariance\n",
            ),
            POSE,
            POINT,
            QUAT,
            (
                "geometry_msgs/TwistWithCovariance",
                "Twist twist\nfloat64[36] covariance\n",
            ),
            ("geometry_msgs/Twist", "Vector3  linear\nVector3  angular\n"),
            VEC3,
        ],
        "std_msgs/Header header\nstring child_frame_id\ngeometry_msgs/PoseWithCovariance pose\ngeometry_msgs/TwistWithCovariance twist\n",
    )
}

/// geometry_msgs/msg/PoseStamped.
pub fn pose_stamped_schema() -> String {
    msg(
        &[HEADER, TIME, POSE, POINT, QUAT],
        "std_msgs/Header header\nPose pose\n",
    )
}

/// ackermann_msgs/msg/AckermannDriveStamped.
pub fn ackermann_schema() -> String {
    msg(
        &[
            HEADER,
            TIME,
            (
                "ackermann_msgs/AckermannDrive",
                "float32 steering_angle\nfloat32 steering_angle_velocity\nfloat32 speed\nfloat32 acceleration\nfloat32 jerk\n",
            ),
        ],
        "std_msgs/Header header\nAckermannDrive drive\n",
    )
}

/// geometry_msgs/msg/PoseArray.
pub fn pose_array_schema() -> String {
    msg(
        &[HEADER, TIME, POSE, POINT, QUAT],
        "std_msgs/Header header\ngeometry_msgs/Pose[] poses\n",
    )
}

/// The route's radius of turn and lengths.
pub const R: f64 = 20.0;
pub const STRAIGHT1: f64 = 100.0;
pub const STRAIGHT2: f64 = 80.0;

/// Total route length.
pub fn route_length() -> f64 {
    STRAIGHT1 + PI * R / 2.0 + STRAIGHT2
}

/// The route point at arc length s (clamped) and the unit normal to its left.
pub fn route_point(s: f64) -> ([f64; 2], [f64; 2]) {
    let s = s.clamp(0.0, route_length());
    let turn = PI * R / 2.0;
    if s <= STRAIGHT1 {
        ([s, 0.0], [0.0, 1.0])
    } else if s <= STRAIGHT1 + turn {
        let th = (s - STRAIGHT1) / R;
        (
            [STRAIGHT1 + R * th.sin(), R - R * th.cos()],
            [-th.sin(), th.cos()],
        )
    } else {
        ([STRAIGHT1 + R, R + (s - STRAIGHT1 - turn)], [-1.0, 0.0])
    }
}

/// Heading of the route at s.
pub fn route_heading(s: f64) -> f64 {
    let (_, n) = route_point(s);
    n[1].atan2(n[0]) - PI / 2.0
}

/// Writes the route as ROUTE.csv (a point every metre and the end).
pub fn write_route(path: &Path) {
    let l = route_length();
    let mut text = String::from("x,y\n");
    let mut s = 0.0;
    while s < l {
        let (p, _) = route_point(s);
        text.push_str(&format!("{},{}\n", p[0], p[1]));
        s += 1.0;
    }
    let (p, _) = route_point(l);
    text.push_str(&format!("{},{}\n", p[0], p[1]));
    std::fs::write(path, text).unwrap();
}

/// Base log time of every run, ns.
pub const T0: u64 = 1_700_000_000_000_000_000;

/// Pose, steering, events and objects are sampled at 10 Hz, shifted so they never coincide:
/// events at k/10 s, poses at k/10 + 0.02 s, steering at k/10 + 0.05 s, objects at k/10 +
/// 0.07 s.
pub const POSE_SHIFT: f64 = 0.02;
pub const STEER_SHIFT: f64 = 0.05;
pub const OBJECTS_SHIFT: f64 = 0.07;

type F1 = Box<dyn Fn(f64) -> f64>;
/// The condition at a time.
pub type CondFn = Box<dyn Fn(f64) -> Option<(&'static str, u8)>>;
/// Objects in the vehicle frame for message k at time t, the vehicle at a position.
type ObjectsFn = Box<dyn Fn(usize, f64, [f64; 2]) -> Vec<[f64; 2]>>;

/// A synthetic run.
pub struct Run {
    /// Bag folder name.
    pub name: String,
    /// Seconds recorded.
    pub duration: f64,
    /// Arc length at time t.
    pub s_of_t: F1,
    /// Lateral offset (left positive) at time t.
    pub offset: Box<dyn Fn(f64, f64) -> f64>,
    /// Steering command k (at k/10 + 0.05 s); None: no steering topic.
    pub steer: Option<Box<dyn Fn(usize) -> f64>>,
    /// Number of steering commands (default: all within the duration).
    pub steer_count: Option<usize>,
    /// The condition at time t: (ID, severity) or None for nominal; None: no events topic.
    pub cond: Option<CondFn>,
    /// Collision flag true from this time on (Bool messages at 1 Hz, false before).
    pub collision_at: Option<f64>,
    /// Detected objects in the vehicle frame at time t (PoseArray on /objects).
    pub objects: Option<ObjectsFn>,
    /// Pose topic as PoseStamped instead of Odometry.
    pub pose_stamped: bool,
    /// Leave out the pose topic.
    pub no_pose: bool,
    /// Rewrites each events record (message k at time t) into the records written in its place
    /// (none, itself, or more: fallbacks, campaign steps, gap and kill records).
    pub records: Option<RecordsFn>,
}

/// See [`Run::records`].
pub type RecordsFn = Box<dyn Fn(usize, f64, EventRecord) -> Vec<EventRecord>>;

impl Run {
    /// A run at 10 m/s along the route, stopping at its end, offset 0, no steering, nominal.
    pub fn new(name: &str, duration: f64) -> Run {
        let l = route_length();
        Run {
            name: name.into(),
            duration,
            s_of_t: Box::new(move |t| (10.0 * t).min(l)),
            offset: Box::new(|_, _| 0.0),
            steer: None,
            steer_count: None,
            cond: Some(Box::new(|_| None)),
            collision_at: None,
            objects: None,
            pose_stamped: false,
            no_pose: false,
            records: None,
        }
    }

    /// Times of the pose samples.
    pub fn pose_times(&self) -> Vec<f64> {
        (0..)
            .map(|k| k as f64 / 10.0 + POSE_SHIFT)
            .take_while(|t| *t <= self.duration)
            .collect()
    }

    /// Position at time t (route point + offset along the left normal).
    pub fn position(&self, t: f64) -> [f64; 2] {
        let s = (self.s_of_t)(t);
        let (p, n) = route_point(s);
        let o = (self.offset)(s, t);
        [p[0] + o * n[0], p[1] + o * n[1]]
    }

    /// Steering commands (t, value).
    pub fn steering(&self) -> Vec<(f64, f64)> {
        let Some(f) = &self.steer else {
            return Vec::new();
        };
        (0..)
            .map(|k| (k as f64 / 10.0 + STEER_SHIFT, k))
            .take_while(|(t, k)| *t <= self.duration && self.steer_count.is_none_or(|n| *k < n))
            .map(|(t, k)| (t, f(k)))
            .collect()
    }

    /// Writes the bag under `dir` as a rosbag2 folder; returns its path and the last log time
    /// (s from T0).
    pub fn write(&self, dir: &Path) -> (PathBuf, f64) {
        self.write_as(dir, Layout::Rosbag2)
    }

    /// Writes the bag under `dir` in `layout`; returns its path and the last log time (s from
    /// T0).
    pub fn write_as(&self, dir: &Path, layout: Layout) -> (PathBuf, f64) {
        let ros1 = layout == Layout::Ros1Bag;
        let mut w = match layout {
            Layout::Rosbag2 => Writer::Ros2(Box::new(
                BagWriter::create(&dir.join(&self.name), &WriterOptions::default()).unwrap(),
            )),
            Layout::McapFile => Writer::Ros2(Box::new(
                BagWriter::create(
                    &dir.join(format!(".{}.tmp", self.name)),
                    &WriterOptions {
                        compression: Compression::None,
                        ..WriterOptions::default()
                    },
                )
                .unwrap(),
            )),
            Layout::Ros1Bag => Writer::Ros1(Box::new(
                Ros1Writer::create(
                    &dir.join(format!("{}.bag", self.name)),
                    &Ros1WriterOptions::default(),
                )
                .unwrap(),
            )),
        };
        let mut codecs: BTreeMap<u16, MessageCodec> = BTreeMap::new();
        let mut add = |w: &mut Writer, topic: &str, ty: &str, schema: &str| {
            let (id, codec) = w.add(topic, ty, schema);
            codecs.insert(id, codec);
            id
        };
        let pose_ch = (!self.no_pose).then(|| {
            if self.pose_stamped {
                add(
                    &mut w,
                    "/pose",
                    "geometry_msgs/msg/PoseStamped",
                    &pose_stamped_schema(),
                )
            } else {
                add(&mut w, "/odom", "nav_msgs/msg/Odometry", &odometry_schema())
            }
        });
        let steer_ch = self.steer.as_ref().map(|_| {
            add(
                &mut w,
                "/cmd",
                "ackermann_msgs/msg/AckermannDriveStamped",
                &ackermann_schema(),
            )
        });
        let coll_ch = self
            .collision_at
            .map(|_| add(&mut w, "/collision", "std_msgs/msg/Bool", "bool data\n"));
        let obj_ch = self.objects.as_ref().map(|_| {
            add(
                &mut w,
                "/objects",
                "geometry_msgs/msg/PoseArray",
                &pose_array_schema(),
            )
        });
        let ev_ch = self
            .cond
            .as_ref()
            .map(|_| add(&mut w, EVENTS_TOPIC, EVENTS_TYPE, "string data\n"));
        // Every message, then written in time order.
        let mut msgs: Vec<(f64, u16, Vec<u8>)> = Vec::new();
        let stamp = |t: f64| {
            let ns = T0 + (t * 1e9).round() as u64;
            (
                Value::Int((ns / 1_000_000_000) as i64),
                Value::UInt(ns % 1_000_000_000),
            )
        };
        if let Some(ch) = pose_ch {
            let prefix = if self.pose_stamped {
                "pose"
            } else {
                "pose.pose"
            };
            for t in self.pose_times() {
                let p = self.position(t);
                let yaw = route_heading((self.s_of_t)(t));
                let (sec, nsec) = stamp(t);
                let mut fields = vec![
                    (format!("{prefix}.position.x"), Value::Float(p[0])),
                    (format!("{prefix}.position.y"), Value::Float(p[1])),
                    (
                        format!("{prefix}.orientation.z"),
                        Value::Float((yaw / 2.0).sin()),
                    ),
                    (
                        format!("{prefix}.orientation.w"),
                        Value::Float((yaw / 2.0).cos()),
                    ),
                ];
                if !ros1 {
                    fields.push(("header.stamp.sec".into(), sec));
                    fields.push(("header.stamp.nanosec".into(), nsec));
                    fields.push(("header.frame_id".into(), Value::String("map".into())));
                }
                let refs: Vec<(&str, Value)> = fields
                    .iter()
                    .map(|(k, v)| (k.as_str(), v.clone()))
                    .collect();
                let bytes = codecs[&ch].encode_fields(&refs).unwrap();
                msgs.push((t, ch, bytes));
            }
        }
        if let Some(ch) = steer_ch {
            for (t, v) in self.steering() {
                let bytes = codecs[&ch]
                    .encode_fields(&[("drive.steering_angle", Value::Float(v))])
                    .unwrap();
                msgs.push((t, ch, bytes));
            }
        }
        if let (Some(ch), Some(at)) = (coll_ch, self.collision_at) {
            let mut t = 0.5;
            while t <= self.duration {
                let b = codecs[&ch]
                    .encode_fields(&[("data", Value::Bool(t >= at))])
                    .unwrap();
                msgs.push((t, ch, b));
                t += if t + 1.0 > at && t < at { at - t } else { 1.0 };
            }
        }
        if let (Some(ch), Some(f)) = (obj_ch, &self.objects) {
            for k in 0.. {
                let t = k as f64 / 10.0 + OBJECTS_SHIFT;
                if t > self.duration {
                    break;
                }
                let ego = self.position(t);
                let items: Vec<Value> = f(k, t, ego)
                    .into_iter()
                    .map(|o| {
                        Value::Message(vec![(
                            "position".into(),
                            Value::Message(vec![
                                ("x".into(), Value::Float(o[0])),
                                ("y".into(), Value::Float(o[1])),
                            ]),
                        )])
                    })
                    .collect();
                let v = Value::Message(vec![("poses".into(), Value::Array(items))]);
                msgs.push((t, ch, codecs[&ch].encode(&v).unwrap()));
            }
        }
        if let (Some(ch), Some(cond)) = (ev_ch, &self.cond) {
            for (t, json) in self.events(cond) {
                let b = codecs[&ch]
                    .encode_fields(&[("data", Value::String(json))])
                    .unwrap();
                msgs.push((t, ch, b));
            }
        }
        msgs.sort_by(|a, b| a.0.total_cmp(&b.0));
        let last = msgs.last().map_or(0.0, |m| m.0);
        for (t, ch, bytes) in &msgs {
            let ns = T0 + (t * 1e9).round() as u64;
            w.write(*ch, ns, bytes);
        }
        let path = w.finish();
        let path = match layout {
            Layout::McapFile => {
                let file = dir.join(format!("{}.mcap", self.name));
                let inner = std::fs::read_dir(&path)
                    .unwrap()
                    .flatten()
                    .map(|e| e.path())
                    .find(|p| p.extension().is_some_and(|x| x == "mcap"))
                    .unwrap();
                std::fs::rename(inner, &file).unwrap();
                std::fs::remove_dir_all(&path).unwrap();
                file
            }
            _ => path,
        };
        (path, last)
    }

    /// The perturbation events (t, JSON), one per 0.1 s, as perturbd writes them.
    pub fn events(&self, cond: &CondFn) -> Vec<(f64, String)> {
        let mut out = Vec::new();
        for k in 0.. {
            let t = k as f64 / 10.0;
            if t > self.duration {
                break;
            }
            let c = cond(t);
            let ev = EventRecord::frame(
                "camera",
                "/camera/image",
                k as u64,
                (0, 0),
                "camera",
                c.map(|c| (c.0, c.1, 1)),
                None,
                0,
            );
            let records = match &self.records {
                Some(f) => f(k, t, ev),
                None => vec![ev],
            };
            for r in records {
                out.push((t, serde_json::to_string(&r).unwrap()));
            }
        }
        out
    }
}

/// How a run is written.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Layout {
    /// A rosbag2 folder (`NAME/NAME_0.mcap` and `metadata.yaml`).
    Rosbag2,
    /// One MCAP file, `NAME.mcap` (uncompressed, as `ros2 bag record` writes by default; one
    /// chunk for a short run).
    McapFile,
    /// A ROS 1 bag, `NAME.bag` (uncompressed 768 KiB chunks as `rosbag record` writes them:
    /// one chunk for a short run).
    Ros1Bag,
}

/// The ROS 1 form of a ros2msg definition: `std_msgs/Header` with `seq` and a ROS 1 `time`.
fn ros1_schema(text: &str) -> String {
    let mut out = Vec::new();
    for part in text.split(SEP) {
        if part.starts_with("MSG: builtin_interfaces/Time") {
            continue;
        }
        if part.starts_with("MSG: std_msgs/Header") {
            out.push("MSG: std_msgs/Header\nuint32 seq\ntime stamp\nstring frame_id\n".to_string());
            continue;
        }
        out.push(part.to_string());
    }
    out.join(SEP)
}

/// A bag being written in either format.
pub enum Writer {
    /// rosbag2 (MCAP, CDR).
    Ros2(Box<BagWriter>),
    /// ROS 1 `.bag`.
    Ros1(Box<Ros1Writer>),
}

impl Writer {
    /// Adds a topic of type `ty` (ROS 2 spelling) with its ros2msg definition; returns its id
    /// and the codec of its messages.
    pub fn add(&mut self, topic: &str, ty: &str, schema: &str) -> (u16, MessageCodec) {
        match self {
            Writer::Ros2(w) => {
                let id = w
                    .add_topic_with_schema(topic, ty, "ros2msg", schema.as_bytes(), BTreeMap::new())
                    .unwrap();
                (
                    id,
                    MessageCodec::new(ty, "ros2msg", schema.as_bytes(), "cdr").unwrap(),
                )
            }
            Writer::Ros1(w) => {
                let ty1 = ty.replace("/msg/", "/");
                let def = ros1_schema(schema);
                let id = w
                    .add_connection(
                        topic,
                        &ty1,
                        "00000000000000000000000000000000",
                        &def,
                        None,
                        false,
                    )
                    .unwrap();
                (
                    id,
                    MessageCodec::new(&ty1, "ros1msg", def.as_bytes(), "ros1").unwrap(),
                )
            }
        }
    }

    /// Writes one message.
    pub fn write(&mut self, id: u16, ns: u64, bytes: &[u8]) {
        match self {
            Writer::Ros2(w) => w.write(id, ns, ns, bytes).unwrap(),
            Writer::Ros1(w) => w.write(id, ns, bytes).unwrap(),
        }
    }

    /// Finishes the bag; returns its path.
    pub fn finish(self) -> PathBuf {
        match self {
            Writer::Ros2(w) => w.finish().unwrap(),
            Writer::Ros1(w) => w.finish().unwrap(),
        }
    }
}

/// The time of the first pose within `tol` of the route's end (where a run trimmed to the route
/// ends), or the last pose's time.
pub fn goal_time(run: &Run, tol: f64) -> f64 {
    let times = run.pose_times();
    times
        .iter()
        .copied()
        .find(|t| (run.s_of_t)(*t) >= route_length() - tol)
        .unwrap_or(*times.last().unwrap())
}

/// A fresh scratch directory.
pub fn tmp(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("perturb-study-test-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}
