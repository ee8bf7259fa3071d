//! The schema-driven decoder against an independent one: every field of every message of real
//! bags in `../shared/data`, decoded here from the schema stored in the bag and by the Python
//! `rosbags` package (rosbag2 MCAP: KITTI CameraInfo, Image, CompressedImage, PointCloud2 and the
//! official rosbag2 writer's test_msgs reference; ROS 1 MCAP: the Ouster recording's TFMessage,
//! Log, PacketMsg, Imu, PointCloud2 and Images, read with the `mcap` package).

use perturb_bag::dynamic::{MessageCodec, Value};
use perturb_bag::{Bag, Filter};
use serde_json::json;
use std::collections::BTreeMap;
use std::ops::ControlFlow;
use std::path::PathBuf;

/// The shared data folder; None (skip) when absent, a failure under CI=true.
fn shared(test: &str) -> Option<PathBuf> {
    let dir = std::env::var_os("PERTURB_SHARED_DATA")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../../shared/data"));
    if dir.is_dir() {
        return Some(dir);
    }
    assert!(
        std::env::var("CI").as_deref() != Ok("true"),
        "{test}: the real data is required under CI but {} is missing",
        dir.display()
    );
    eprintln!("skipping {test}: real data not found at {}", dir.display());
    None
}

#[path = "../../../tests/support/python_oracle.rs"]
mod python_oracle;

/// [`python_oracle::python_oracle`] with the bag tests' install hint.
fn python(modules: &str, script: &str, args: &[&str]) -> Option<String> {
    python_oracle::python_oracle(modules, "pip install rosbags mcap numpy", script, args)
}

/// Flattens a message as `[[path, leaf], ...]` where byte arrays become `{len, sum}` with a
/// position-weighted checksum (sum of byte * (index + 1), wrapping u64).
const FLATTEN: &str = r#"
import sys, json, dataclasses
import numpy as np

def flat(v, prefix, out, ros1):
    def join(a, b):
        return b if not a else a + "." + b
    if dataclasses.is_dataclass(v):
        time = ros1 and getattr(v, "__msgtype__", "") in ("builtin_interfaces/msg/Time", "builtin_interfaces/msg/Duration")
        for f in dataclasses.fields(v):
            if f.name == "structure_needs_at_least_one_member" or str(f.type).startswith("ClassVar"):
                continue
            name = {"sec": "secs", "nanosec": "nsecs"}.get(f.name, f.name) if time else f.name
            flat(getattr(v, f.name), join(prefix, name), out, ros1)
    elif isinstance(v, np.ndarray) and v.dtype in (np.uint8, np.int8):
        b = v.view(np.uint8).astype(np.uint64)
        w = int((b * np.arange(1, len(b) + 1, dtype=np.uint64)).sum(dtype=np.uint64))
        out.append([prefix, {"len": int(len(b)), "sum": w}])
    elif isinstance(v, (list, np.ndarray)):
        for i, x in enumerate(v):
            flat(x.item() if isinstance(x, np.generic) else x, f"{prefix}[{i}]", out, ros1)
    elif isinstance(v, np.generic):
        out.append([prefix, v.item()])
    else:
        out.append([prefix, v])
"#;

const ROSBAGS_ROS2: &str = r#"
from pathlib import Path
from rosbags.highlevel import AnyReader
from rosbags.typesys import Stores, get_typestore
res = {}
with AnyReader([Path(sys.argv[1])], default_typestore=get_typestore(Stores.EMPTY)) as r:
    for conn, t, raw in r.messages():
        out = []
        flat(r.deserialize(raw, conn.msgtype), "", out, False)
        res.setdefault(conn.topic, []).append(out)
print(json.dumps(res))
"#;

const MCAP_ROS1: &str = r#"
from mcap.reader import make_reader
from rosbags.typesys import Stores, get_typestore, get_types_from_msg
ts = get_typestore(Stores.EMPTY)
res = {}
with open(sys.argv[1], "rb") as f:
    for schema, channel, message in make_reader(f).iter_messages(log_time_order=False):
        name = schema.name.replace("/", "/msg/") if "/msg/" not in schema.name else schema.name
        if name not in ts.types:
            ts.register(get_types_from_msg(schema.data.decode(), schema.name))
        out = []
        flat(ts.deserialize_ros1(message.data, name), "", out, True)
        res.setdefault(channel.topic, []).append(out)
print(json.dumps(res))
"#;

fn leaf(v: &Value) -> serde_json::Value {
    match v {
        Value::Bool(b) => json!(b),
        Value::Int(i) => json!(i),
        Value::UInt(u) => json!(u),
        Value::Float(f) => json!(f),
        Value::String(s) => json!(s),
        Value::Bytes(b) => {
            let sum = b.iter().enumerate().fold(0u64, |acc, (i, x)| {
                acc.wrapping_add((*x as u64).wrapping_mul(i as u64 + 1))
            });
            json!({"len": b.len(), "sum": sum})
        }
        Value::Array(_) | Value::Message(_) => unreachable!("flatten yields leaves"),
    }
}

fn flatten(v: &Value) -> Vec<(String, serde_json::Value)> {
    v.flatten().into_iter().map(|(p, l)| (p, leaf(l))).collect()
}

/// Integers compare exactly; floats by value within 1e-15 relative (serde_json's default float
/// parser is not correctly rounded in the last bit); everything else exactly.
fn same(a: &serde_json::Value, b: &serde_json::Value) -> bool {
    if let (Some(x), Some(y)) = (a.as_u64(), b.as_u64()) {
        return x == y;
    }
    if let (Some(x), Some(y)) = (a.as_i64(), b.as_i64()) {
        return x == y;
    }
    match (a.as_f64(), b.as_f64()) {
        (Some(x), Some(y)) if a.is_number() && b.is_number() => {
            x == y || (x - y).abs() <= 1e-15 * x.abs().max(y.abs())
        }
        _ => a == b,
    }
}

type Decoded = BTreeMap<String, Vec<Vec<(String, serde_json::Value)>>>;

fn compare(ours: &Decoded, theirs: &str, what: &str) -> usize {
    let theirs: BTreeMap<String, Vec<Vec<(String, serde_json::Value)>>> =
        serde_json::from_str(theirs).unwrap();
    assert_eq!(
        ours.keys().collect::<Vec<_>>(),
        theirs.keys().collect::<Vec<_>>(),
        "{what}: topics"
    );
    let mut leaves = 0;
    for (topic, msgs) in ours {
        let t = &theirs[topic];
        assert_eq!(msgs.len(), t.len(), "{what}: {topic}: message count");
        for (k, (a, b)) in msgs.iter().zip(t).enumerate() {
            let pa: Vec<&str> = a.iter().map(|x| x.0.as_str()).collect();
            let pb: Vec<&str> = b.iter().map(|x| x.0.as_str()).collect();
            assert_eq!(pa, pb, "{what}: {topic} #{k}: field paths");
            for ((p, x), (_, y)) in a.iter().zip(b) {
                assert!(
                    same(x, y),
                    "{what}: {topic} #{k} `{p}`: ours {x}, rosbags {y}"
                );
                leaves += 1;
            }
        }
    }
    leaves
}

fn decode_ros2_bag(path: &std::path::Path) -> Decoded {
    let bag = Bag::open(path).unwrap();
    let codecs: BTreeMap<String, MessageCodec> = bag
        .topics()
        .unwrap()
        .into_iter()
        .map(|t| {
            let c = MessageCodec::new(
                &t.type_name,
                &t.schema_encoding,
                &t.schema,
                &t.message_encoding,
            )
            .unwrap_or_else(|e| panic!("{}: {e}", t.topic));
            (t.topic, c)
        })
        .collect();
    let mut out = Decoded::new();
    bag.for_each(&Filter::default(), |m| {
        let v = codecs[m.topic]
            .decode(m.data)
            .unwrap_or_else(|e| panic!("{} at {}: {e}", m.topic, m.log_time));
        out.entry(m.topic.to_string())
            .or_default()
            .push(flatten(&v));
        Ok(ControlFlow::Continue(()))
    })
    .unwrap();
    out
}

#[test]
fn every_field_of_the_ros2_bags_matches_rosbags() {
    let Some(data) = shared("every_field_of_the_ros2_bags_matches_rosbags") else {
        return;
    };
    for bag in ["ros2_mcap_kitti_000001", "format_ref_rosbag2_cdr_test"] {
        let path = data.join(bag);
        let ours = decode_ros2_bag(&path);
        let script = format!("{FLATTEN}{ROSBAGS_ROS2}");
        let Some(theirs) = python("rosbags, numpy", &script, &[path.to_str().unwrap()]) else {
            return;
        };
        let n = compare(&ours, &theirs, bag);
        eprintln!("{bag}: {n} leaves identical");
        assert!(n > 20, "{bag}: only {n} leaves compared");
    }
    // Field paths into the CameraInfo, as `perturb analyze` uses them.
    let bag = Bag::open(&data.join("ros2_mcap_kitti_000001")).unwrap();
    let info = bag
        .topics()
        .unwrap()
        .into_iter()
        .find(|t| t.type_name == "sensor_msgs/msg/CameraInfo")
        .unwrap();
    let c = MessageCodec::new(&info.type_name, &info.schema_encoding, &info.schema, "cdr").unwrap();
    let filter = Filter {
        topics: vec![info.topic.clone()],
        ..Filter::default()
    };
    bag.for_each(&filter, |m| {
        let get = |p: &str| c.get(m.data, &c.path(p).unwrap()).unwrap();
        let whole = c.decode(m.data).unwrap();
        for p in [
            "width",
            "height",
            "k[0]",
            "k[4]",
            "p[2]",
            "header.stamp.sec",
            "roi.do_rectify",
            "distortion_model",
        ] {
            assert_eq!(Some(&get(p)), whole.at(p), "{p}");
        }
        assert_eq!(get("width"), Value::UInt(1242));
        Ok(ControlFlow::Break(()))
    })
    .unwrap();
}

#[test]
fn every_field_of_the_ros1_mcap_matches_rosbags() {
    let Some(data) = shared("every_field_of_the_ros1_mcap_matches_rosbags") else {
        return;
    };
    let path = data.join("mcap_ouster_os1_pointcloudset/test.mcap");
    let bytes = std::fs::read(&path).unwrap();
    let mut ours = Decoded::new();
    let mut codecs: BTreeMap<u16, MessageCodec> = BTreeMap::new();
    for m in mcap::MessageStream::new(&bytes).unwrap() {
        let m = m.unwrap();
        let s = m.channel.schema.as_ref().unwrap();
        let codec = codecs.entry(m.channel.id).or_insert_with(|| {
            MessageCodec::new(&s.name, &s.encoding, &s.data, &m.channel.message_encoding)
                .unwrap_or_else(|e| panic!("{}: {e}", m.channel.topic))
        });
        let v = codec
            .decode(&m.data)
            .unwrap_or_else(|e| panic!("{}: {e}", m.channel.topic));
        ours.entry(m.channel.topic.clone())
            .or_default()
            .push(flatten(&v));
    }
    let script = format!("{FLATTEN}{MCAP_ROS1}");
    let Some(theirs) = python("rosbags, mcap, numpy", &script, &[path.to_str().unwrap()]) else {
        return;
    };
    let n = compare(&ours, &theirs, "ouster ros1 mcap");
    eprintln!("ouster: {n} leaves identical");
    assert!(n > 1000, "only {n} leaves compared");
    // ROS 1 paths: the header's seq and a time's parts under either spelling.
    let imu = codecs
        .values()
        .find(|c| c.schema().root == "sensor_msgs/Imu")
        .unwrap();
    for p in [
        "header.seq",
        "header.stamp.secs",
        "header.stamp.sec",
        "orientation_covariance[8]",
    ] {
        imu.path(p).unwrap_or_else(|e| panic!("{e}"));
    }
}
