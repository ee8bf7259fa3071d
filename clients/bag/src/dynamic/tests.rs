//! Round trips over generated message types and values, in both encodings; known byte layouts.

use super::*;
use proptest::prelude::*;

/// A small deterministic generator for the values of a generated type.
struct Gen(u64);

impl Gen {
    fn next(&mut self) -> u64 {
        // splitmix64
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
    fn below(&mut self, n: u64) -> u64 {
        self.next() % n.max(1)
    }
}

const ROS2_PRIMS: [Primitive; 14] = [
    Primitive::Bool,
    Primitive::Byte,
    Primitive::Char,
    Primitive::Int8,
    Primitive::UInt8,
    Primitive::Int16,
    Primitive::UInt16,
    Primitive::Int32,
    Primitive::UInt32,
    Primitive::Int64,
    Primitive::UInt64,
    Primitive::Float32,
    Primitive::Float64,
    Primitive::String,
];

/// Generates `ntypes` message definitions `gen/T0..` as schema text (type k uses only types
/// after it, so there is no recursion) in `dialect`.
fn gen_text(g: &mut Gen, ntypes: usize, dialect: Dialect) -> String {
    let mut prims: Vec<Primitive> = ROS2_PRIMS.to_vec();
    if dialect == Dialect::Ros1 {
        prims.extend([Primitive::Time, Primitive::Duration]);
    }
    let mut out = String::new();
    for k in 0..ntypes {
        if k > 0 {
            out.push_str(&"=".repeat(80));
            out.push_str(&format!("\nMSG: gen/T{k}\n"));
        }
        if g.below(3) == 0 {
            out.push_str("# a comment line\nint32 SOME_CONST = 7 # constant\n");
        }
        let nfields = g.below(6) as usize; // zero fields happen: an empty message
        for f in 0..nfields {
            let nested = k + 1 < ntypes && g.below(4) == 0;
            let ty = if nested {
                let j = k + 1 + g.below((ntypes - k - 1) as u64) as usize;
                if g.below(2) == 0 {
                    format!("T{j}")
                } else {
                    format!("gen/T{j}")
                }
            } else {
                prims[g.below(prims.len() as u64) as usize]
                    .name()
                    .to_string()
            };
            let arr = match g.below(if dialect == Dialect::Ros2 { 5 } else { 4 }) {
                0 | 1 => String::new(),
                2 => "[]".into(),
                3 => format!("[{}]", g.below(4)),
                _ => format!("[<={}]", 1 + g.below(4)),
            };
            out.push_str(&format!("{ty}{arr} f{f}"));
            if g.below(4) == 0 {
                out.push_str("   # trailing comment");
            }
            out.push('\n');
        }
    }
    out
}

fn gen_prim(g: &mut Gen, p: Primitive, dialect: Dialect) -> Value {
    let r = g.next();
    match p {
        Primitive::Bool => Value::Bool(r & 1 == 1),
        Primitive::Byte if dialect == Dialect::Ros1 => Value::Int(r as u8 as i8 as i64),
        Primitive::Byte | Primitive::Char | Primitive::UInt8 => Value::UInt(r as u8 as u64),
        Primitive::Int8 => Value::Int(r as i8 as i64),
        Primitive::Int16 => Value::Int(r as i16 as i64),
        Primitive::UInt16 => Value::UInt(r as u16 as u64),
        Primitive::Int32 => Value::Int(r as i32 as i64),
        Primitive::UInt32 => Value::UInt(r as u32 as u64),
        Primitive::Int64 => Value::Int(r as i64),
        Primitive::UInt64 => Value::UInt(r),
        Primitive::Float32 => Value::Float((r as i32 as f32 / 7.0) as f64),
        Primitive::Float64 => Value::Float(r as i64 as f64 / 3.0),
        Primitive::String => {
            let n = g.below(7) as usize;
            Value::String(
                (0..n)
                    .map(|_| ['a', 'Z', '#', ' ', 'é', '€', '0'][g.below(7) as usize])
                    .collect(),
            )
        }
        Primitive::WString => unreachable!("not generated"),
        Primitive::Time => Value::Message(vec![
            ("secs".into(), Value::UInt(r as u32 as u64)),
            ("nsecs".into(), Value::UInt((r >> 32) as u32 as u64)),
        ]),
        Primitive::Duration => Value::Message(vec![
            ("secs".into(), Value::Int(r as i32 as i64)),
            ("nsecs".into(), Value::Int((r >> 32) as i32 as i64)),
        ]),
    }
}

fn gen_value(g: &mut Gen, s: &Schema, def: &MsgDef) -> Value {
    let mut fields = Vec::new();
    for f in &def.fields {
        let one = |g: &mut Gen| match &f.ty.base {
            BaseType::Primitive(p) => gen_prim(g, *p, s.dialect),
            BaseType::Message(m) => gen_value(g, s, &s.types[m]),
        };
        let n = match f.ty.array {
            ArrayKind::Single => {
                let v = one(g);
                fields.push((f.name.clone(), v));
                continue;
            }
            ArrayKind::Fixed(n) => n,
            ArrayKind::Bounded(max) => g.below(max as u64 + 1) as usize,
            ArrayKind::Unbounded => g.below(4) as usize,
        };
        let v = match f.ty.base {
            BaseType::Primitive(p) if p.is_byte_like() => {
                Value::Bytes((0..n).map(|_| g.next() as u8).collect())
            }
            _ => Value::Array((0..n).map(|_| one(g)).collect()),
        };
        fields.push((f.name.clone(), v));
    }
    Value::Message(fields)
}

fn codec_for(text: &str, dialect: Dialect) -> MessageCodec {
    let (name, se, me) = match dialect {
        Dialect::Ros2 => ("gen/msg/T0", "ros2msg", "cdr"),
        Dialect::Ros1 => ("gen/T0", "ros1msg", "ros1"),
    };
    MessageCodec::new(name, se, text.as_bytes(), me).unwrap_or_else(|e| panic!("{e}\n{text}"))
}

/// The byte array leaves as `Value::Bytes` compare as-is; others by value.
fn round_trip(seed: u64, ntypes: usize, dialect: Dialect) {
    let mut g = Gen(seed);
    let text = gen_text(&mut g, ntypes, dialect);
    let codec = codec_for(&text, dialect);
    let value = gen_value(&mut g, codec.schema(), codec.schema().root_def());
    let bytes = codec
        .encode(&value)
        .unwrap_or_else(|e| panic!("{e}\n{text}"));
    let back = codec
        .decode(&bytes)
        .unwrap_or_else(|e| panic!("{e}\n{text}"));
    assert_eq!(back, value, "schema:\n{text}");
    // Every leaf is read back by its path, without decoding the rest.
    for (path, leaf) in value.flatten() {
        if path.is_empty() {
            continue;
        }
        let p = codec.path(&path).unwrap_or_else(|e| panic!("{e}\n{text}"));
        assert_eq!(&codec.get(&bytes, &p).unwrap(), leaf, "{path}\n{text}");
    }
    // Every strict prefix is an error naming a field, never a panic.
    for cut in 0..bytes.len() {
        assert!(
            codec.decode(&bytes[..cut]).is_err(),
            "prefix {cut} of {}\n{text}",
            bytes.len()
        );
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 300, ..ProptestConfig::default() })]

    #[test]
    fn cdr_round_trips_generated_messages(seed in any::<u64>(), ntypes in 1usize..5) {
        round_trip(seed, ntypes, Dialect::Ros2);
    }

    #[test]
    fn ros1_round_trips_generated_messages(seed in any::<u64>(), ntypes in 1usize..5) {
        round_trip(seed, ntypes, Dialect::Ros1);
    }

    #[test]
    fn random_bytes_never_panic(seed in any::<u64>(), data in proptest::collection::vec(any::<u8>(), 0..64)) {
        let mut g = Gen(seed);
        for dialect in [Dialect::Ros1, Dialect::Ros2] {
            let text = gen_text(&mut g, 3, dialect);
            let codec = codec_for(&text, dialect);
            let _ = codec.decode(&data);
        }
    }
}

const IMAGE_ROS1: &str = "Header header\nuint32 height\nuint32 width\nstring encoding\nuint8 is_bigendian\nuint32 step\nuint8[] data\n================================================================================\nMSG: std_msgs/Header\nuint32 seq\ntime stamp\nstring frame_id\n";

#[test]
fn ros1_image_has_the_documented_56_bytes() {
    // ros1.md §3: a 2x2 rgb8 Image with frame_id `cam` and 12 data bytes is 56 bytes.
    let c = MessageCodec::new(
        "sensor_msgs/Image",
        "ros1msg",
        IMAGE_ROS1.as_bytes(),
        "ros1",
    )
    .unwrap();
    let b = c
        .encode_fields(&[
            ("header.seq", Value::UInt(7)),
            ("header.stamp.secs", Value::UInt(100)),
            ("header.stamp.nsecs", Value::UInt(5)),
            ("header.frame_id", Value::String("cam".into())),
            ("height", Value::UInt(2)),
            ("width", Value::UInt(2)),
            ("encoding", Value::String("rgb8".into())),
            ("step", Value::UInt(6)),
            ("data", Value::Bytes((0..12).collect())),
        ])
        .unwrap();
    assert_eq!(b.len(), 56);
    assert_eq!(&b[..4], &7u32.to_le_bytes());
    assert_eq!(&b[16..19], b"cam");
    let sec = c.path("header.stamp.sec").unwrap(); // the ROS 2 spelling is accepted
    assert_eq!(c.get_f64(&b, &sec).unwrap(), 100.0);
    assert_eq!(
        c.get(&b, &c.path("data").unwrap()).unwrap(),
        Value::Bytes((0..12).collect())
    );
}

#[test]
fn cdr_image_matches_the_projects_own_encoder() {
    use perturb_core::formats::ros::{Header, ImageMsg};
    let text = crate::schema::ros2msg("sensor_msgs/msg/Image").unwrap();
    let c = MessageCodec::new("sensor_msgs/msg/Image", "ros2msg", text.as_bytes(), "cdr").unwrap();
    let data: Vec<u8> = (0..30).collect();
    let msg = ImageMsg {
        header: Header {
            stamp_sec: -3,
            stamp_nanosec: 999,
            frame_id: "camera_front",
        },
        height: 2,
        width: 5,
        encoding: "rgb8",
        is_bigendian: 0,
        step: 15,
        data: &data,
    };
    let cdr = msg.encode();
    let v = c.decode(&cdr).unwrap();
    let get = |p: &str| c.get(&cdr, &c.path(p).unwrap()).unwrap();
    assert_eq!(get("header.stamp.sec"), Value::Int(-3));
    assert_eq!(get("header.stamp.nanosec"), Value::UInt(999));
    assert_eq!(get("header.frame_id"), Value::String("camera_front".into()));
    assert_eq!(get("step"), Value::UInt(15));
    assert_eq!(v.field("data"), Some(&Value::Bytes(data.clone())));
    // And the codec writes the same bytes the project's encoder does.
    assert_eq!(c.encode(&v).unwrap(), cdr);
}

#[test]
fn cdr_aligns_8_byte_values_from_the_body_start() {
    let c = MessageCodec::new(
        "a/msg/T",
        "ros2msg",
        b"uint8 a\nfloat64 b\nstring s\nuint16 c\n",
        "cdr",
    )
    .unwrap();
    let b = c
        .encode_fields(&[
            ("a", Value::UInt(1)),
            ("b", Value::Float(0.5)),
            ("s", Value::String("hi".into())),
            ("c", Value::UInt(9)),
        ])
        .unwrap();
    // header 4 | a 1 + pad 7 | b 8 | len 4 "hi\0" 3 | pad 1 | c 2
    assert_eq!(b.len(), 4 + 8 + 8 + 4 + 3 + 1 + 2);
    assert_eq!(&b[12..20], &0.5f64.to_le_bytes());
    assert_eq!(&b[20..24], &3u32.to_le_bytes());
    // Big-endian CDR is read too.
    let mut be = vec![0, 0, 0, 0, 1, 0, 0, 0, 0, 0, 0, 0];
    be.extend_from_slice(&0.5f64.to_be_bytes());
    be.extend_from_slice(&3u32.to_be_bytes());
    be.extend_from_slice(b"hi\0\0");
    be.extend_from_slice(&9u16.to_be_bytes());
    let v = c.decode(&be).unwrap();
    assert_eq!(v.field("b"), Some(&Value::Float(0.5)));
    assert_eq!(v.field("c"), Some(&Value::UInt(9)));
}

#[test]
fn path_errors_name_the_path_and_the_field() {
    let c = MessageCodec::new(
        "sensor_msgs/Image",
        "ros1msg",
        IMAGE_ROS1.as_bytes(),
        "ros1",
    )
    .unwrap();
    let e = c.path("header.stmp.secs").unwrap_err().to_string();
    assert!(
        e.contains("header.stmp.secs")
            && e.contains("`stmp`")
            && e.contains("std_msgs/Header")
            && e.contains("frame_id"),
        "{e}"
    );
    let e = c.path("height[0]").unwrap_err().to_string();
    assert!(e.contains("not an array"), "{e}");
    let e = c.path("data.x").unwrap_err().to_string();
    assert!(e.contains("array"), "{e}");
    let e = c.path("").unwrap_err().to_string();
    assert!(e.contains("empty"), "{e}");
    let b = c
        .encode_fields(&[("data", Value::Bytes(vec![1, 2]))])
        .unwrap();
    let e = c
        .get(&b, &c.path("data[5]").unwrap())
        .unwrap_err()
        .to_string();
    assert!(e.contains("index 5") && e.contains("2 elements"), "{e}");
    let e = c
        .get_f64(&b, &c.path("encoding").unwrap())
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("expected a number") && e.contains("encoding"),
        "{e}"
    );
    let e = c.decode(&b[..20]).unwrap_err().to_string();
    assert!(e.contains("truncated") && e.contains("field `"), "{e}");
}

#[test]
fn unsupported_encodings_are_refused_by_name() {
    let e = MessageCodec::new("a/msg/T", "ros2idl", b"", "cdr")
        .unwrap_err()
        .to_string();
    assert!(e.contains("ros2idl") && e.contains("a/msg/T"), "{e}");
    let e = MessageCodec::new("a/msg/T", "ros2msg", b"int32 x\n", "json")
        .unwrap_err()
        .to_string();
    assert!(e.contains("json"), "{e}");
    let c = MessageCodec::new("a/msg/T", "ros2msg", b"int32 x\n", "cdr").unwrap();
    let e = c.decode(&[0, 7, 0, 0, 1, 0, 0, 0]).unwrap_err().to_string();
    assert!(e.contains("encapsulation 00 07"), "{e}");
}
