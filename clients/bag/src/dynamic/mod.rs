//! Reading any message by its schema: the message definitions a bag stores (`ros2msg` in rosbag2
//! MCAP, `ros1msg` in ROS 1 MCAP and the `message_definition` of ROS 1 bags) are parsed at run
//! time, and messages are decoded in ROS 2 CDR or in the ROS 1 wire format, whole or by field
//! path (`pose.pose.position.x`, `header.stamp.sec`, `fields[1].name`,
//! `drive.steering_angle`). No generated code: a message type the project has never seen is
//! readable as long as the bag carries its definition.
//!
//! ```
//! use perturb_bag::dynamic::{MessageCodec, Value};
//! let schema = "std_msgs/Header header\ngeometry_msgs/Point position\n\
//! ================================================================================\n\
//! MSG: std_msgs/Header\nbuiltin_interfaces/Time stamp\nstring frame_id\n\
//! ================================================================================\n\
//! MSG: geometry_msgs/Point\nfloat64 x\nfloat64 y\nfloat64 z\n";
//! let codec = MessageCodec::new("my_msgs/msg/Fix", "ros2msg", schema.as_bytes(), "cdr")?;
//! let bytes = codec.encode_fields(&[("position.x", Value::Float(2.5)), ("header.frame_id", Value::String("map".into()))])?;
//! let x = codec.path("position.x")?;
//! assert_eq!(codec.get_f64(&bytes, &x)?, 2.5);
//! assert_eq!(codec.decode(&bytes)?.field("header").unwrap().field("frame_id").unwrap().as_str(), Some("map"));
//! # Ok::<(), perturb_bag::dynamic::DynError>(())
//! ```

mod codec;
mod schema;
mod value;

pub use codec::MessageEncoding;
pub use schema::{
    ArrayKind, BaseType, Constant, Dialect, Field, FieldType, MsgDef, Primitive, Schema,
    normalize_type_name,
};
pub use value::Value;

use codec::{Decoder, Reader, Writer};

/// Where pose-like message types keep their position, most specific first (`Odometry`,
/// `PoseWithCovarianceStamped`: `pose.pose.position`; `PoseStamped`: `pose.position`; `Pose`:
/// `position`; `TransformStamped`: `transform.translation`; `PointStamped`: `point`).
pub const POSITION_CANDIDATES: [&str; 6] = [
    "pose.pose.position",
    "pose.position",
    "position",
    "transform.translation",
    "point",
    "pose.pose.pose.position",
];

/// The path of the position (a field with `x` and `y`) in `codec`'s type, from
/// [`POSITION_CANDIDATES`].
pub fn position_path(codec: &MessageCodec) -> Option<String> {
    POSITION_CANDIDATES
        .iter()
        .find(|c| codec.path(&format!("{c}.x")).is_ok() && codec.path(&format!("{c}.y")).is_ok())
        .map(|c| c.to_string())
}

/// What can go wrong reading a schema or a message; every variant names the type, field or
/// path concerned.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum DynError {
    /// The definition text could not be parsed.
    #[error("definition of `{type_name}`, line {line}: {reason}")]
    Definition {
        /// The type whose text is wrong.
        type_name: String,
        /// Line in the whole definition text (1-based; 0 when not tied to a line).
        line: usize,
        /// What is wrong.
        reason: String,
    },
    /// A field refers to a type the definition does not include.
    #[error("type `{type_name}` (used by `{referenced_by}`) is not defined in the schema")]
    UnknownType {
        /// The missing type.
        type_name: String,
        /// `Type.field` that uses it.
        referenced_by: String,
    },
    /// A schema or message encoding this decoder does not read.
    #[error("unsupported encoding: {what}")]
    UnsupportedEncoding {
        /// What was found.
        what: String,
    },
    /// A field path names a field the type does not have.
    #[error("field path `{path}`: `{type_name}` has no field `{field}` (its fields: {})", available.join(", "))]
    UnknownField {
        /// The whole path.
        path: String,
        /// The segment that does not exist.
        field: String,
        /// The type that lacks it.
        type_name: String,
        /// The fields it has.
        available: Vec<String>,
    },
    /// A field path is malformed or indexes something that is not an array.
    #[error("field path `{path}`: {reason}")]
    BadPath {
        /// The whole path.
        path: String,
        /// What is wrong.
        reason: String,
    },
    /// An index past the end of an array.
    #[error("field path `{path}`: index {index} is out of range (the array has {len} elements)")]
    IndexOutOfRange {
        /// The whole path.
        path: String,
        /// The index asked for.
        index: usize,
        /// The array's length in this message.
        len: usize,
    },
    /// The message ends before the schema says it should.
    #[error(
        "field `{field}`: the message is truncated ({needed} bytes needed at offset {offset}, the message has {len})"
    )]
    Truncated {
        /// The field being read.
        field: String,
        /// Where.
        offset: usize,
        /// Bytes needed.
        needed: usize,
        /// Message length.
        len: usize,
    },
    /// A value in the message is invalid (a string that is not UTF-8, a wstring).
    #[error("field `{field}`: {reason}")]
    InvalidData {
        /// The field.
        field: String,
        /// What is wrong.
        reason: String,
    },
    /// A value does not fit its field when encoding.
    #[error("encoding field `{field}`: {reason}")]
    Encode {
        /// The field.
        field: String,
        /// What is wrong.
        reason: String,
    },
    /// A value asked for as a number is not one.
    #[error("field path `{path}`: expected a number, found a {kind}")]
    NotANumber {
        /// The path.
        path: String,
        /// What was found.
        kind: &'static str,
    },
}

/// One step of a compiled field path.
#[derive(Clone, Debug, PartialEq, Eq)]
enum Step {
    /// The field at this index of the current message's fields.
    Field(usize),
    /// This element of the current array.
    Index(usize),
    /// Seconds (0) or nanoseconds (1) of a ROS 1 `time`/`duration`.
    TimePart(usize),
}

/// A field path checked against a schema, ready to be read from many messages.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct FieldPath {
    text: String,
    steps: Vec<Step>,
    leaf: FieldType,
}

impl FieldPath {
    /// The path as written.
    pub fn as_str(&self) -> &str {
        &self.text
    }

    /// The type of the value the path names (a ROS 1 `time` part is a `uint32`/`int32`).
    pub fn leaf_type(&self) -> &FieldType {
        &self.leaf
    }
}

impl std::fmt::Display for FieldPath {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.text)
    }
}

/// Splits `a.b[2].c` into segments: names and indices.
fn segments(path: &str) -> Result<Vec<Result<&str, usize>>, DynError> {
    let bad = |reason: String| DynError::BadPath {
        path: path.to_string(),
        reason,
    };
    let mut out = Vec::new();
    if path.trim().is_empty() {
        return Err(bad("the path is empty".into()));
    }
    for part in path.split('.') {
        let (name, mut rest) = match part.find('[') {
            Some(i) => (&part[..i], &part[i..]),
            None => (part, ""),
        };
        if name.is_empty() {
            if out.is_empty() || rest.is_empty() {
                return Err(bad(format!("empty segment in `{part}`")));
            }
        } else if let Ok(i) = name.parse::<usize>() {
            // `a.3` is accepted as `a[3]`.
            out.push(Err(i));
        } else {
            out.push(Ok(name));
        }
        while !rest.is_empty() {
            let close = rest
                .find(']')
                .ok_or_else(|| bad(format!("unclosed `[` in `{part}`")))?;
            let idx = rest[1..close]
                .trim()
                .parse::<usize>()
                .map_err(|_| bad(format!("`{}` is not an index", &rest[1..close])))?;
            out.push(Err(idx));
            rest = &rest[close + 1..];
            if !rest.is_empty() && !rest.starts_with('[') {
                return Err(bad(format!("unexpected `{rest}` after an index")));
            }
        }
    }
    Ok(out)
}

/// Decodes (and encodes) the messages of one type, given its schema and encoding.
#[derive(Clone, Debug)]
pub struct MessageCodec {
    schema: Schema,
    encoding: MessageEncoding,
}

impl MessageCodec {
    /// A codec for messages of `type_name` stored with this schema encoding (`ros2msg`,
    /// `ros1msg`), schema text and message encoding (`cdr`, `ros1`), as an MCAP channel or a ROS 1
    /// connection describes them.
    pub fn new(
        type_name: &str,
        schema_encoding: &str,
        schema: &[u8],
        message_encoding: &str,
    ) -> Result<Self, DynError> {
        let dialect = match schema_encoding {
            "ros2msg" => Dialect::Ros2,
            "ros1msg" => Dialect::Ros1,
            other => {
                return Err(DynError::UnsupportedEncoding {
                    what: format!(
                        "schema encoding `{other}` for `{type_name}` (this decoder reads `ros2msg` and `ros1msg` definitions)"
                    ),
                });
            }
        };
        let text = std::str::from_utf8(schema).map_err(|e| DynError::Definition {
            type_name: type_name.to_string(),
            line: 0,
            reason: format!("the definition is not UTF-8 text ({e})"),
        })?;
        let schema = Schema::parse(type_name, text, dialect)?;
        Ok(MessageCodec {
            schema,
            encoding: MessageEncoding::from_name(message_encoding)?,
        })
    }

    /// A codec for an already parsed schema.
    pub fn from_schema(schema: Schema, encoding: MessageEncoding) -> Self {
        MessageCodec { schema, encoding }
    }

    /// The parsed schema.
    pub fn schema(&self) -> &Schema {
        &self.schema
    }

    /// The message encoding.
    pub fn encoding(&self) -> MessageEncoding {
        self.encoding
    }

    fn decoder(&self) -> Decoder<'_> {
        Decoder {
            schema: &self.schema,
        }
    }

    /// Decodes a whole message.
    pub fn decode(&self, data: &[u8]) -> Result<Value, DynError> {
        let mut r = Reader::new(data, self.encoding)?;
        self.decoder().message(&mut r, self.schema.root_def())
    }

    /// Checks `path` against the schema: every segment must name a field of the message it is
    /// in, indices must follow arrays. A ROS 1 `time`/`duration` has the parts `secs`/`nsecs`
    /// (also accepted as ROS 2's `sec`/`nanosec`).
    pub fn path(&self, path: &str) -> Result<FieldPath, DynError> {
        let mut ty = FieldType {
            base: BaseType::Message(self.schema.root.clone()),
            array: ArrayKind::Single,
            string_bound: None,
        };
        let mut steps = Vec::new();
        let segs = segments(path)?;
        for (k, seg) in segs.iter().enumerate() {
            let bad = |reason: String| DynError::BadPath {
                path: path.to_string(),
                reason,
            };
            match *seg {
                Ok(name) => {
                    if ty.array != ArrayKind::Single {
                        return Err(bad(format!(
                            "`{name}`: the value before it is an array; give an index first (e.g. `[0].{name}`)"
                        )));
                    }
                    match &ty.base {
                        BaseType::Message(m) => {
                            let idx = self.field_index(path, m, name)?;
                            steps.push(Step::Field(idx));
                            ty = self.schema.types[m].fields[idx].ty.clone();
                        }
                        BaseType::Primitive(p @ (Primitive::Time | Primitive::Duration)) => {
                            let (part, leaf) = time_part(path, *p, name)?;
                            if k + 1 != segs.len() {
                                return Err(bad(format!(
                                    "`{name}` of a {} is a number, nothing is inside it",
                                    p.name()
                                )));
                            }
                            steps.push(Step::TimePart(part));
                            return Ok(FieldPath {
                                text: path.to_string(),
                                steps,
                                leaf,
                            });
                        }
                        BaseType::Primitive(p) => {
                            return Err(bad(format!(
                                "`{name}`: the value before it is a {}, not a message",
                                p.name()
                            )));
                        }
                    }
                }
                Err(i) => {
                    match ty.array {
                        ArrayKind::Single => {
                            return Err(bad(format!("[{i}]: the value before it is not an array")));
                        }
                        ArrayKind::Fixed(n) if i >= n => {
                            return Err(DynError::IndexOutOfRange {
                                path: path.to_string(),
                                index: i,
                                len: n,
                            });
                        }
                        _ => {}
                    }
                    steps.push(Step::Index(i));
                    ty.array = ArrayKind::Single;
                }
            }
        }
        Ok(FieldPath {
            text: path.to_string(),
            steps,
            leaf: ty,
        })
    }

    /// The index of field `name` of message type `m`, or an error listing the fields it has.
    fn field_index(&self, path: &str, m: &str, name: &str) -> Result<usize, DynError> {
        let def = &self.schema.types[m];
        def.fields
            .iter()
            .position(|f| f.name == name)
            .ok_or_else(|| DynError::UnknownField {
                path: path.to_string(),
                field: name.to_string(),
                type_name: m.to_string(),
                available: def.fields.iter().map(|f| f.name.clone()).collect(),
            })
    }

    /// Reads the value at `path` from a message, decoding only what lies on the way.
    pub fn get(&self, data: &[u8], path: &FieldPath) -> Result<Value, DynError> {
        let mut r = Reader::new(data, self.encoding)?;
        self.decoder().get(&mut r, path)
    }

    /// Reads a number at `path` (integers and bools are converted).
    pub fn get_f64(&self, data: &[u8], path: &FieldPath) -> Result<f64, DynError> {
        let v = self.get(data, path)?;
        v.as_f64().ok_or_else(|| DynError::NotANumber {
            path: path.text.clone(),
            kind: v.kind(),
        })
    }

    /// Encodes a message value (a [`Value::Message`] of the root type). Fields the value leaves
    /// out are written as zero, empty string or empty array.
    pub fn encode(&self, value: &Value) -> Result<Vec<u8>, DynError> {
        let mut w = Writer::new(self.encoding, self.schema.dialect);
        w.message(&self.schema, self.schema.root_def(), Some(value))?;
        Ok(w.buf)
    }

    /// Encodes a message given as `(field path, value)` pairs; every other field is zero,
    /// empty or empty. Paths are checked against the schema; array elements are addressed as
    /// `a[2]` (the array grows to hold them).
    pub fn encode_fields(&self, fields: &[(&str, Value)]) -> Result<Vec<u8>, DynError> {
        let mut root = Value::Message(Vec::new());
        for (path, v) in fields {
            self.path(path)?;
            let segs = segments(path)?;
            let mut cur = &mut root;
            for seg in segs {
                cur = match seg {
                    Ok(name) => {
                        let Value::Message(fs) = cur else {
                            unreachable!("checked by path()")
                        };
                        let i = match fs.iter().position(|(n, _)| n == name) {
                            Some(i) => i,
                            None => {
                                fs.push((name.to_string(), Value::Message(Vec::new())));
                                fs.len() - 1
                            }
                        };
                        &mut fs[i].1
                    }
                    Err(i) => {
                        if !matches!(cur, Value::Array(_)) {
                            *cur = Value::Array(Vec::new());
                        }
                        let Value::Array(items) = cur else {
                            unreachable!()
                        };
                        while items.len() <= i {
                            items.push(Value::Message(Vec::new()));
                        }
                        &mut items[i]
                    }
                };
            }
            *cur = v.clone();
        }
        self.encode(&root)
    }
}

#[cfg(test)]
mod tests;

/// Part `name` of a ROS time or duration `p` (`secs` or `nsecs`, ROS 2's `sec`/`nanosec` too): its
/// index and its type (u32 for a time, i32 for a duration).
fn time_part(path: &str, p: Primitive, name: &str) -> Result<(usize, FieldType), DynError> {
    let part = match name {
        "secs" | "sec" => 0,
        "nsecs" | "nanosec" | "nsec" => 1,
        _ => {
            return Err(DynError::UnknownField {
                path: path.to_string(),
                field: name.to_string(),
                type_name: p.name().to_string(),
                available: vec!["secs".into(), "nsecs".into()],
            });
        }
    };
    let leaf = FieldType {
        base: BaseType::Primitive(if p == Primitive::Time {
            Primitive::UInt32
        } else {
            Primitive::Int32
        }),
        array: ArrayKind::Single,
        string_bound: None,
    };
    Ok((part, leaf))
}
