//! Decoded message values.

/// A decoded value: what a field holds, whatever its message type.
#[derive(Clone, Debug, PartialEq)]
pub enum Value {
    /// `bool`.
    Bool(bool),
    /// Signed integers (`int8` .. `int64`, ROS 1 `byte`).
    Int(i64),
    /// Unsigned integers (`uint8` .. `uint64`, `char`, ROS 2 `byte`).
    UInt(u64),
    /// `float32` (widened exactly) and `float64`.
    Float(f64),
    /// `string`.
    String(String),
    /// An array of one-byte integers (`uint8[]`, `byte[]`, `char[]`, `int8[]`), kept as bytes.
    Bytes(Vec<u8>),
    /// Any other array.
    Array(Vec<Value>),
    /// A nested message (or a ROS 1 `time`/`duration`: `secs`, `nsecs`), fields in order.
    Message(Vec<(String, Value)>),
}

impl Value {
    /// The value as a number, if it is one (bools are 0 or 1).
    pub fn as_f64(&self) -> Option<f64> {
        match self {
            Value::Bool(b) => Some(f64::from(u8::from(*b))),
            Value::Int(v) => Some(*v as f64),
            Value::UInt(v) => Some(*v as f64),
            Value::Float(v) => Some(*v),
            _ => None,
        }
    }

    /// The value as a bool: a bool, or a number that is not zero.
    pub fn as_bool(&self) -> Option<bool> {
        match self {
            Value::Bool(b) => Some(*b),
            other => other.as_f64().map(|v| v != 0.0),
        }
    }

    /// The string, if it is one.
    pub fn as_str(&self) -> Option<&str> {
        match self {
            Value::String(s) => Some(s),
            _ => None,
        }
    }

    /// A field of a message value, by name.
    pub fn field(&self, name: &str) -> Option<&Value> {
        match self {
            Value::Message(fields) => fields.iter().find(|(n, _)| n == name).map(|(_, v)| v),
            _ => None,
        }
    }

    /// The value at a relative field path inside this value (`pose.position.x`,
    /// `points[2].x`), as [`super::MessageCodec::path`] writes paths; None if it is not there.
    pub fn at(&self, path: &str) -> Option<&Value> {
        let mut cur = self;
        for seg in super::segments(path).ok()? {
            cur = match seg {
                Ok(name) => cur.field(name)?,
                Err(i) => match cur {
                    Value::Array(items) => items.get(i)?,
                    _ => return None,
                },
            };
        }
        Some(cur)
    }

    /// The number of elements of an array value.
    pub fn len(&self) -> Option<usize> {
        match self {
            Value::Bytes(b) => Some(b.len()),
            Value::Array(a) => Some(a.len()),
            _ => None,
        }
    }

    /// True for an empty array.
    pub fn is_empty(&self) -> bool {
        self.len() == Some(0)
    }

    /// A short name of the kind of value, for messages.
    pub fn kind(&self) -> &'static str {
        match self {
            Value::Bool(_) => "bool",
            Value::Int(_) => "signed integer",
            Value::UInt(_) => "unsigned integer",
            Value::Float(_) => "float",
            Value::String(_) => "string",
            Value::Bytes(_) => "byte array",
            Value::Array(_) => "array",
            Value::Message(_) => "message",
        }
    }

    /// Every leaf of the value as `(path, value)`, paths written as in [`super::FieldPath`]
    /// (`header.stamp.sec`, `fields[0].name`); byte arrays are one leaf.
    pub fn flatten(&self) -> Vec<(String, &Value)> {
        fn go<'a>(v: &'a Value, prefix: &str, out: &mut Vec<(String, &'a Value)>) {
            match v {
                Value::Message(fields) => {
                    for (n, f) in fields {
                        let p = if prefix.is_empty() {
                            n.clone()
                        } else {
                            format!("{prefix}.{n}")
                        };
                        go(f, &p, out);
                    }
                }
                Value::Array(items) => {
                    for (i, f) in items.iter().enumerate() {
                        go(f, &format!("{prefix}[{i}]"), out);
                    }
                }
                leaf => out.push((prefix.to_string(), leaf)),
            }
        }
        let mut out = Vec::new();
        go(self, "", &mut out);
        out
    }
}
