//! Parsing the message definitions stored in bags: `ros2msg` (rosbag2 MCAP) and `ros1msg`
//! (ROS 1 MCAP, the `message_definition` of ROS 1 bags). Both are the top-level `.msg` text
//! followed, for every dependency, by a line of `=` characters, a line `MSG: pkg/Type` and that
//! type's `.msg` text.

use super::DynError;
use std::collections::BTreeMap;

/// Which flavour of `.msg` text a definition is written in; it decides what the built-in type
/// names mean (`time`, `duration` and a bare `Header` exist in ROS 1 only).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Dialect {
    /// ROS 1 (`ros1msg`).
    Ros1,
    /// ROS 2 (`ros2msg`).
    Ros2,
}

/// A built-in (primitive) field type.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Primitive {
    /// `bool`, one byte.
    Bool,
    /// `byte`: signed in ROS 1 (an alias of `int8`), unsigned (`octet`) in ROS 2.
    Byte,
    /// `char`: unsigned, one byte (an alias of `uint8`).
    Char,
    /// `int8`.
    Int8,
    /// `uint8`.
    UInt8,
    /// `int16`.
    Int16,
    /// `uint16`.
    UInt16,
    /// `int32`.
    Int32,
    /// `uint32`.
    UInt32,
    /// `int64`.
    Int64,
    /// `uint64`.
    UInt64,
    /// `float32`.
    Float32,
    /// `float64`.
    Float64,
    /// `string` (and bounded `string<=N`).
    String,
    /// `wstring` (ROS 2; recognised, but not decoded).
    WString,
    /// ROS 1 `time`: `uint32 secs`, `uint32 nsecs`.
    Time,
    /// ROS 1 `duration`: `int32 secs`, `int32 nsecs`.
    Duration,
}

impl Primitive {
    /// The primitive named `name` in `dialect`, if it is one.
    pub fn from_name(name: &str, dialect: Dialect) -> Option<Primitive> {
        Some(match name {
            "bool" => Primitive::Bool,
            "byte" => Primitive::Byte,
            "char" => Primitive::Char,
            "int8" => Primitive::Int8,
            "uint8" => Primitive::UInt8,
            "int16" => Primitive::Int16,
            "uint16" => Primitive::UInt16,
            "int32" => Primitive::Int32,
            "uint32" => Primitive::UInt32,
            "int64" => Primitive::Int64,
            "uint64" => Primitive::UInt64,
            "float32" => Primitive::Float32,
            "float64" => Primitive::Float64,
            "string" => Primitive::String,
            "wstring" if dialect == Dialect::Ros2 => Primitive::WString,
            "time" if dialect == Dialect::Ros1 => Primitive::Time,
            "duration" if dialect == Dialect::Ros1 => Primitive::Duration,
            _ => return None,
        })
    }

    /// The name as written in a `.msg` file.
    pub fn name(self) -> &'static str {
        match self {
            Primitive::Bool => "bool",
            Primitive::Byte => "byte",
            Primitive::Char => "char",
            Primitive::Int8 => "int8",
            Primitive::UInt8 => "uint8",
            Primitive::Int16 => "int16",
            Primitive::UInt16 => "uint16",
            Primitive::Int32 => "int32",
            Primitive::UInt32 => "uint32",
            Primitive::Int64 => "int64",
            Primitive::UInt64 => "uint64",
            Primitive::Float32 => "float32",
            Primitive::Float64 => "float64",
            Primitive::String => "string",
            Primitive::WString => "wstring",
            Primitive::Time => "time",
            Primitive::Duration => "duration",
        }
    }

    /// Size in bytes of a fixed-size primitive (None for strings).
    pub fn size(self) -> Option<usize> {
        Some(match self {
            Primitive::Bool
            | Primitive::Byte
            | Primitive::Char
            | Primitive::Int8
            | Primitive::UInt8 => 1,
            Primitive::Int16 | Primitive::UInt16 => 2,
            Primitive::Int32 | Primitive::UInt32 | Primitive::Float32 => 4,
            Primitive::Int64 | Primitive::UInt64 | Primitive::Float64 => 8,
            Primitive::Time | Primitive::Duration => 8,
            Primitive::String | Primitive::WString => return None,
        })
    }

    /// True for the one-byte integer types whose arrays are kept as raw bytes.
    pub fn is_byte_like(self) -> bool {
        matches!(
            self,
            Primitive::UInt8 | Primitive::Char | Primitive::Byte | Primitive::Int8
        )
    }

    /// True for the numeric types (integers, floats, bool).
    pub fn is_number(self) -> bool {
        !matches!(
            self,
            Primitive::String | Primitive::WString | Primitive::Time | Primitive::Duration
        )
    }
}

/// The element type of a field.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum BaseType {
    /// A built-in type.
    Primitive(Primitive),
    /// A nested message, by its normalised name `pkg/Type`.
    Message(String),
}

/// Whether a field is an array, and which kind.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ArrayKind {
    /// A single value.
    Single,
    /// `T[N]`: exactly N elements, no length on the wire.
    Fixed(usize),
    /// `T[<=N]` (ROS 2): at most N elements, a length on the wire.
    Bounded(usize),
    /// `T[]`: a length on the wire.
    Unbounded,
}

/// The type of a field.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct FieldType {
    /// The element type.
    pub base: BaseType,
    /// Array or single value.
    pub array: ArrayKind,
    /// `string<=N`: the bound (ROS 2; not checked when decoding).
    pub string_bound: Option<usize>,
}

/// A field of a message definition.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Field {
    /// Field name.
    pub name: String,
    /// Field type.
    pub ty: FieldType,
}

/// A constant of a message definition (kept for completeness; constants are not on the wire).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Constant {
    /// Its type.
    pub ty: Primitive,
    /// Its name.
    pub name: String,
    /// Its value as written.
    pub value: String,
}

/// One message type's definition.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct MsgDef {
    /// Normalised name `pkg/Type`.
    pub name: String,
    /// The fields in wire order.
    pub fields: Vec<Field>,
    /// The constants.
    pub constants: Vec<Constant>,
}

/// A parsed definition: the root type and every type it depends on.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Schema {
    /// The dialect of the text.
    pub dialect: Dialect,
    /// The root type's normalised name.
    pub root: String,
    /// Every type by normalised name, the root included.
    pub types: BTreeMap<String, MsgDef>,
}

/// `pkg/msg/Type` -> `pkg/Type`; other names unchanged.
pub fn normalize_type_name(name: &str) -> String {
    let parts: Vec<&str> = name.split('/').collect();
    match parts.as_slice() {
        [pkg, "msg", ty] => format!("{pkg}/{ty}"),
        _ => name.to_string(),
    }
}

fn is_separator(line: &str) -> bool {
    let t = line.trim();
    t.len() >= 3 && t.chars().all(|c| c == '=')
}

/// Removes a `#` comment (outside string constants, which the caller handles).
fn strip_comment(line: &str) -> &str {
    match line.find('#') {
        Some(i) => &line[..i],
        None => line,
    }
}

fn valid_identifier(s: &str) -> bool {
    let mut c = s.chars();
    c.next()
        .is_some_and(|f| f.is_ascii_alphabetic() || f == '_')
        && c.all(|ch| ch.is_ascii_alphanumeric() || ch == '_')
}

/// Definitions ROS 2 bags sometimes leave out of the dependency list, because every ROS 2
/// installation has them.
fn ros2_builtin(name: &str) -> Option<MsgDef> {
    let field = |n: &str, p| Field {
        name: n.to_string(),
        ty: FieldType {
            base: BaseType::Primitive(p),
            array: ArrayKind::Single,
            string_bound: None,
        },
    };
    let fields = match name {
        "builtin_interfaces/Time" => vec![
            field("sec", Primitive::Int32),
            field("nanosec", Primitive::UInt32),
        ],
        "builtin_interfaces/Duration" => vec![
            field("sec", Primitive::Int32),
            field("nanosec", Primitive::UInt32),
        ],
        _ => return None,
    };
    Some(MsgDef {
        name: name.to_string(),
        fields,
        constants: Vec::new(),
    })
}

struct Parser<'a> {
    dialect: Dialect,
    /// The type being parsed (for error messages) and its package (to resolve relative names).
    type_name: &'a str,
    package: &'a str,
}

impl Parser<'_> {
    fn err(&self, line: usize, reason: impl Into<String>) -> DynError {
        DynError::Definition {
            type_name: self.type_name.to_string(),
            line,
            reason: reason.into(),
        }
    }

    /// Resolves a field's type name (without array suffix) to a base type.
    fn base_type(&self, name: &str, line: usize) -> Result<(BaseType, Option<usize>), DynError> {
        // Bounded strings: string<=N, wstring<=N.
        if let Some((s, bound)) = name.split_once("<=") {
            if s == "string" || s == "wstring" {
                let n = bound
                    .parse()
                    .map_err(|_| self.err(line, format!("bad string bound in `{name}`")))?;
                let p = Primitive::from_name(s, self.dialect)
                    .ok_or_else(|| self.err(line, format!("`{s}` is not a ROS 1 type")))?;
                return Ok((BaseType::Primitive(p), Some(n)));
            }
            return Err(self.err(line, format!("`{name}`: only strings can be bounded")));
        }
        if let Some(p) = Primitive::from_name(name, self.dialect) {
            return Ok((BaseType::Primitive(p), None));
        }
        if self.dialect == Dialect::Ros1 && name == "Header" {
            return Ok((BaseType::Message("std_msgs/Header".into()), None));
        }
        let full = if name.contains('/') {
            normalize_type_name(name)
        } else {
            format!("{}/{name}", self.package)
        };
        let valid = full.split('/').count() == 2 && full.split('/').all(valid_identifier);
        if !valid {
            return Err(self.err(line, format!("`{name}` is not a valid type name")));
        }
        Ok((BaseType::Message(full), None))
    }

    fn field_type(&self, spec: &str, line: usize) -> Result<FieldType, DynError> {
        let (name, array) = match spec.find('[') {
            None => (spec, ArrayKind::Single),
            Some(i) => {
                let inner = spec[i + 1..]
                    .strip_suffix(']')
                    .ok_or_else(|| self.err(line, format!("`{spec}`: unclosed `[`")))?;
                let kind = if inner.is_empty() {
                    ArrayKind::Unbounded
                } else if let Some(b) = inner.strip_prefix("<=") {
                    ArrayKind::Bounded(
                        b.parse()
                            .map_err(|_| self.err(line, format!("`{spec}`: bad array bound")))?,
                    )
                } else {
                    ArrayKind::Fixed(
                        inner
                            .parse()
                            .map_err(|_| self.err(line, format!("`{spec}`: bad array size")))?,
                    )
                };
                (&spec[..i], kind)
            }
        };
        let (base, string_bound) = self.base_type(name, line)?;
        Ok(FieldType {
            base,
            array,
            string_bound,
        })
    }

    fn parse(&self, text: &str, first_line: usize) -> Result<MsgDef, DynError> {
        let mut def = MsgDef {
            name: self.type_name.to_string(),
            fields: Vec::new(),
            constants: Vec::new(),
        };
        for (k, raw) in text.lines().enumerate() {
            let line = first_line + k;
            let code = strip_comment(raw).trim();
            if code.is_empty() {
                continue;
            }
            let (ty, rest) = code
                .split_once(char::is_whitespace)
                .ok_or_else(|| self.err(line, format!("`{code}`: expected `type name`")))?;
            let rest = rest.trim_start();
            // A constant: `type NAME=value` (spaces around `=` allowed). String constants keep
            // the rest of the raw line, `#` included.
            let name_end = rest
                .find(|c: char| c.is_whitespace() || c == '=')
                .unwrap_or(rest.len());
            let (name, after) = rest.split_at(name_end);
            if after.trim_start().starts_with('=') {
                let p = Primitive::from_name(ty, self.dialect)
                    .filter(|p| p.is_number() || *p == Primitive::String)
                    .ok_or_else(|| {
                        self.err(
                            line,
                            format!("constant `{name}` has non-primitive type `{ty}`"),
                        )
                    })?;
                let value = if p == Primitive::String {
                    let raw_rest = raw.trim_start()[ty.len()..].trim_start();
                    raw_rest
                        .split_once('=')
                        .map_or("", |(_, v)| v)
                        .trim()
                        .to_string()
                } else {
                    after.trim_start()[1..].trim().to_string()
                };
                if !valid_identifier(name) {
                    return Err(self.err(line, format!("`{name}` is not a valid constant name")));
                }
                def.constants.push(Constant {
                    ty: p,
                    name: name.to_string(),
                    value,
                });
                continue;
            }
            if !valid_identifier(name) {
                return Err(self.err(line, format!("`{name}` is not a valid field name")));
            }
            // Anything after the name is a default value (ROS 2); it is not on the wire.
            let ty = self.field_type(ty, line)?;
            if def.fields.iter().any(|f| f.name == name) {
                return Err(self.err(line, format!("field `{name}` is defined twice")));
            }
            def.fields.push(Field {
                name: name.to_string(),
                ty,
            });
        }
        Ok(def)
    }
}

impl Schema {
    /// Parses the definition text stored for `type_name` (`geometry_msgs/msg/PoseStamped` or
    /// `geometry_msgs/PoseStamped`) and checks that every referenced type is defined.
    pub fn parse(type_name: &str, text: &str, dialect: Dialect) -> Result<Schema, DynError> {
        let root = normalize_type_name(type_name.trim());
        let mut types = BTreeMap::new();
        // Split into sections: (name, first line number, text).
        let mut sections: Vec<(String, usize, String)> = vec![(root.clone(), 1, String::new())];
        let mut expect_msg_line = false;
        for (k, line) in text.lines().enumerate() {
            if is_separator(line) {
                expect_msg_line = true;
                continue;
            }
            if expect_msg_line {
                if line.trim().is_empty() {
                    continue;
                }
                let name =
                    line.trim()
                        .strip_prefix("MSG:")
                        .ok_or_else(|| DynError::Definition {
                            type_name: root.clone(),
                            line: k + 1,
                            reason: format!(
                                "expected `MSG: pkg/Type` after the separator line, found `{}`",
                                line.trim()
                            ),
                        })?;
                sections.push((normalize_type_name(name.trim()), k + 2, String::new()));
                expect_msg_line = false;
                continue;
            }
            let s = &mut sections.last_mut().expect("one section").2;
            s.push_str(line);
            s.push('\n');
        }
        for (name, first, body) in &sections {
            let package = name.split('/').next().unwrap_or("");
            if name.split('/').count() != 2 {
                return Err(DynError::Definition {
                    type_name: name.clone(),
                    line: *first,
                    reason: "a type name must be `package/Type`".into(),
                });
            }
            let p = Parser {
                dialect,
                type_name: name,
                package,
            };
            let def = p.parse(body, *first)?;
            // The first definition of a name wins (a bag may repeat one).
            types.entry(name.clone()).or_insert(def);
        }
        let mut schema = Schema {
            dialect,
            root,
            types,
        };
        schema.check()?;
        Ok(schema)
    }

    /// Every referenced type must be defined (ROS 2's builtin_interfaces are added if missing),
    /// and a type must not contain itself.
    fn check(&mut self) -> Result<(), DynError> {
        loop {
            let mut missing = None;
            'outer: for def in self.types.values() {
                for f in &def.fields {
                    if let BaseType::Message(m) = &f.ty.base
                        && !self.types.contains_key(m)
                    {
                        missing = Some((m.clone(), def.name.clone(), f.name.clone()));
                        break 'outer;
                    }
                }
            }
            let Some((m, in_type, field)) = missing else {
                break;
            };
            match (self.dialect, ros2_builtin(&m)) {
                (Dialect::Ros2, Some(def)) => {
                    self.types.insert(m, def);
                }
                _ => {
                    return Err(DynError::UnknownType {
                        type_name: m,
                        referenced_by: format!("{in_type}.{field}"),
                    });
                }
            }
        }
        // Recursion check: depth-first from the root.
        fn visit<'a>(
            s: &'a Schema,
            name: &'a str,
            stack: &mut Vec<&'a str>,
        ) -> Result<(), DynError> {
            if stack.contains(&name) {
                return Err(DynError::Definition {
                    type_name: name.to_string(),
                    line: 0,
                    reason: format!("the type contains itself ({})", stack.join(" -> ")),
                });
            }
            stack.push(name);
            for f in &s.types[name].fields {
                if let BaseType::Message(m) = &f.ty.base {
                    visit(s, m, stack)?;
                }
            }
            stack.pop();
            Ok(())
        }
        visit(self, &self.root, &mut Vec::new())
    }

    /// The root type's definition.
    pub fn root_def(&self) -> &MsgDef {
        &self.types[&self.root]
    }

    /// The definition of `name` (normalised), if present.
    pub fn def(&self, name: &str) -> Option<&MsgDef> {
        self.types.get(name)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_ros1_with_header_constants_and_comments() {
        let text = "byte DEBUG=1 #debug level\nstring S = a # not a comment\nHeader header\nbyte level\nstring[] topics # names\nfloat64[9] K\n\n================================================================================\nMSG: std_msgs/Header\nuint32 seq\ntime stamp\nstring frame_id\n";
        let s = Schema::parse("rosgraph_msgs/Log", text, Dialect::Ros1).unwrap();
        let root = s.root_def();
        assert_eq!(root.constants.len(), 2);
        assert_eq!(root.constants[0].value, "1");
        assert_eq!(root.constants[1].value, "a # not a comment");
        let names: Vec<&str> = root.fields.iter().map(|f| f.name.as_str()).collect();
        assert_eq!(names, ["header", "level", "topics", "K"]);
        assert_eq!(
            root.fields[0].ty.base,
            BaseType::Message("std_msgs/Header".into())
        );
        assert_eq!(root.fields[3].ty.array, ArrayKind::Fixed(9));
        assert_eq!(
            s.def("std_msgs/Header").unwrap().fields[1].ty.base,
            BaseType::Primitive(Primitive::Time)
        );
    }

    #[test]
    fn parses_ros2_bounds_defaults_and_adds_builtin_time() {
        let text = "std_msgs/Header header\nstring<=10 name\nint32[<=5] a [1, 2]\nuint8 x 7\n================================================================================\nMSG: std_msgs/Header\nbuiltin_interfaces/Time stamp\nstring frame_id\n";
        let s = Schema::parse("pkg/msg/T", text, Dialect::Ros2).unwrap();
        assert_eq!(s.root, "pkg/T");
        let f = &s.root_def().fields;
        assert_eq!(f[1].ty.string_bound, Some(10));
        assert_eq!(f[2].ty.array, ArrayKind::Bounded(5));
        assert!(s.def("builtin_interfaces/Time").is_some());
    }

    #[test]
    fn missing_dependency_names_the_type_and_field() {
        let e = Schema::parse("a/B", "Other thing\n", Dialect::Ros2).unwrap_err();
        let msg = e.to_string();
        assert!(
            msg.contains("a/Other") && msg.contains("a/B.thing"),
            "{msg}"
        );
        let e = Schema::parse("a/B", "int32\n", Dialect::Ros2).unwrap_err();
        assert!(e.to_string().contains("line 1"), "{e}");
        // `time` is not a ROS 2 type.
        let e = Schema::parse("a/B", "time t\n", Dialect::Ros2).unwrap_err();
        assert!(e.to_string().contains("a/time"), "{e}");
    }
}
