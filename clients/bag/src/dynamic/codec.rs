//! Decoding and encoding messages by their schema, in ROS 2 CDR and in the ROS 1 wire format.
//!
//! CDR (XCDR1, what rosbag2 stores): a 4-byte encapsulation header (`00 01 00 00` little endian,
//! `00 00 00 00` big endian), then the body, where every primitive is aligned to its size counted
//! from the start of the body; strings are a u32 length that counts a terminating NUL, the bytes
//! and the NUL; sequences a u32 count and the elements; fixed arrays the elements only; a message
//! without fields holds one `uint8` placeholder. ROS 1: little endian and packed (no alignment),
//! strings a u32 length and the bytes (no NUL), `time`/`duration` two 32-bit integers.

use super::schema::{ArrayKind, BaseType, Dialect, FieldType, MsgDef, Primitive, Schema};
use super::value::Value;
use super::{DynError, FieldPath, Step};

/// How the message bytes are laid out.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum MessageEncoding {
    /// ROS 2 CDR with its 4-byte encapsulation header (`cdr` in MCAP).
    Cdr,
    /// The ROS 1 wire format (`ros1` in MCAP, every message of a ROS 1 bag).
    Ros1,
}

impl MessageEncoding {
    /// The encoding named `name` in an MCAP channel (`cdr`, `ros1`).
    pub fn from_name(name: &str) -> Result<Self, DynError> {
        match name {
            "cdr" => Ok(MessageEncoding::Cdr),
            "ros1" | "ros" => Ok(MessageEncoding::Ros1),
            other => Err(DynError::UnsupportedEncoding {
                what: format!("message encoding `{other}` (this decoder reads `cdr` and `ros1`)"),
            }),
        }
    }
}

/// Prefixes the name of the field being read to an error coming from inside it.
fn in_field(e: DynError, name: &str) -> DynError {
    let join = |f: String| {
        if f.is_empty() {
            name.to_string()
        } else if f.starts_with('[') {
            format!("{name}{f}")
        } else {
            format!("{name}.{f}")
        }
    };
    match e {
        DynError::Truncated {
            field,
            offset,
            needed,
            len,
        } => DynError::Truncated {
            field: join(field),
            offset,
            needed,
            len,
        },
        DynError::InvalidData { field, reason } => DynError::InvalidData {
            field: join(field),
            reason,
        },
        DynError::Encode { field, reason } => DynError::Encode {
            field: join(field),
            reason,
        },
        other => other,
    }
}

/// The most elements of zero size an array may claim.
const MAX_EMPTY_ELEMENTS: usize = 1 << 20;

pub(super) struct Reader<'a> {
    buf: &'a [u8],
    pos: usize,
    /// Where alignment is counted from (the start of the CDR body).
    base: usize,
    big_endian: bool,
    cdr: bool,
}

impl<'a> Reader<'a> {
    /// A reader positioned at the start of the message body (after the CDR header).
    pub(super) fn new(data: &'a [u8], enc: MessageEncoding) -> Result<Self, DynError> {
        match enc {
            MessageEncoding::Ros1 => Ok(Reader {
                buf: data,
                pos: 0,
                base: 0,
                big_endian: false,
                cdr: false,
            }),
            MessageEncoding::Cdr => {
                if data.len() < 4 {
                    return Err(DynError::Truncated {
                        field: String::new(),
                        offset: 0,
                        needed: 4,
                        len: data.len(),
                    });
                }
                let big_endian = match (data[0], data[1]) {
                    (0, 0) => true,
                    (0, 1) => false,
                    (a, b) => {
                        return Err(DynError::UnsupportedEncoding {
                            what: format!(
                                "CDR encapsulation {a:02x} {b:02x} (only plain CDR, 00 00 or 00 01, is read; parameter lists and XCDR2 are not)"
                            ),
                        });
                    }
                };
                Ok(Reader {
                    buf: data,
                    pos: 4,
                    base: 4,
                    big_endian,
                    cdr: true,
                })
            }
        }
    }

    fn align(&mut self, n: usize) {
        if self.cdr && n > 1 {
            let rel = self.pos - self.base;
            self.pos = self.base + rel.div_ceil(n) * n;
        }
    }

    fn take(&mut self, n: usize) -> Result<&'a [u8], DynError> {
        let end = self.pos.checked_add(n).filter(|&e| e <= self.buf.len());
        match end {
            Some(end) => {
                let s = &self.buf[self.pos..end];
                self.pos = end;
                Ok(s)
            }
            None => Err(DynError::Truncated {
                field: String::new(),
                offset: self.pos,
                needed: n,
                len: self.buf.len(),
            }),
        }
    }

    fn fixed<const N: usize>(&mut self) -> Result<[u8; N], DynError> {
        self.align(N);
        let mut a: [u8; N] = self.take(N)?.try_into().expect("N bytes");
        if self.big_endian {
            a.reverse();
        }
        Ok(a)
    }

    fn u32(&mut self) -> Result<u32, DynError> {
        Ok(u32::from_le_bytes(self.fixed()?))
    }

    fn remaining(&self) -> usize {
        self.buf.len().saturating_sub(self.pos)
    }

    /// The element count of a sequence; refuses counts the remaining bytes cannot hold.
    fn count(&mut self, elem_min: usize) -> Result<usize, DynError> {
        let at = self.pos;
        let n = self.u32()? as usize;
        // Elements that take no bytes (empty ROS 1 messages) cannot be checked against the
        // remaining length; a million of them is not a real message.
        if elem_min == 0 && n > MAX_EMPTY_ELEMENTS {
            return Err(DynError::InvalidData {
                field: String::new(),
                reason: format!("an array of {n} empty elements is not plausible"),
            });
        }
        if elem_min > 0 && n.saturating_mul(elem_min) > self.remaining() {
            return Err(DynError::Truncated {
                field: String::new(),
                offset: at,
                needed: n.saturating_mul(elem_min),
                len: self.buf.len(),
            });
        }
        Ok(n)
    }

    fn string(&mut self) -> Result<String, DynError> {
        let n = self.u32()? as usize;
        let mut b = self.take(n)?;
        if self.cdr {
            b = b.strip_suffix(&[0]).unwrap_or(b);
        }
        String::from_utf8(b.to_vec()).map_err(|e| DynError::InvalidData {
            field: String::new(),
            reason: format!("the string is not UTF-8 ({e})"),
        })
    }

    fn skip_string(&mut self) -> Result<(), DynError> {
        let n = self.u32()? as usize;
        self.take(n).map(|_| ())
    }

    fn primitive(&mut self, p: Primitive, dialect: Dialect) -> Result<Value, DynError> {
        Ok(match p {
            Primitive::Bool => Value::Bool(self.take(1)?[0] != 0),
            Primitive::Byte if dialect == Dialect::Ros1 => {
                Value::Int(self.take(1)?[0] as i8 as i64)
            }
            Primitive::Byte | Primitive::Char | Primitive::UInt8 => {
                Value::UInt(self.take(1)?[0] as u64)
            }
            Primitive::Int8 => Value::Int(self.take(1)?[0] as i8 as i64),
            Primitive::Int16 => Value::Int(i16::from_le_bytes(self.fixed()?) as i64),
            Primitive::UInt16 => Value::UInt(u16::from_le_bytes(self.fixed()?) as u64),
            Primitive::Int32 => Value::Int(i32::from_le_bytes(self.fixed()?) as i64),
            Primitive::UInt32 => Value::UInt(u32::from_le_bytes(self.fixed()?) as u64),
            Primitive::Int64 => Value::Int(i64::from_le_bytes(self.fixed()?)),
            Primitive::UInt64 => Value::UInt(u64::from_le_bytes(self.fixed()?)),
            Primitive::Float32 => Value::Float(f32::from_le_bytes(self.fixed()?) as f64),
            Primitive::Float64 => Value::Float(f64::from_le_bytes(self.fixed()?)),
            Primitive::String => Value::String(self.string()?),
            Primitive::WString => {
                return Err(DynError::InvalidData {
                    field: String::new(),
                    reason: "wstring fields are not supported by this decoder".into(),
                });
            }
            Primitive::Time => {
                let s = u32::from_le_bytes(self.fixed()?);
                let n = u32::from_le_bytes(self.fixed()?);
                Value::Message(vec![
                    ("secs".into(), Value::UInt(s as u64)),
                    ("nsecs".into(), Value::UInt(n as u64)),
                ])
            }
            Primitive::Duration => {
                let s = i32::from_le_bytes(self.fixed()?);
                let n = i32::from_le_bytes(self.fixed()?);
                Value::Message(vec![
                    ("secs".into(), Value::Int(s as i64)),
                    ("nsecs".into(), Value::Int(n as i64)),
                ])
            }
        })
    }

    fn skip_primitive(&mut self, p: Primitive) -> Result<(), DynError> {
        match p {
            Primitive::String => self.skip_string(),
            Primitive::WString => Err(DynError::InvalidData {
                field: String::new(),
                reason: "wstring fields are not supported by this decoder".into(),
            }),
            Primitive::Time | Primitive::Duration => {
                self.align(4);
                self.take(8).map(|_| ())
            }
            p => {
                let n = p.size().expect("fixed size");
                self.align(n);
                self.take(n).map(|_| ())
            }
        }
    }
}

/// The smallest number of bytes an element of `base` takes (for sanity checks of counts).
fn min_size(schema: &Schema, base: &BaseType, cdr: bool) -> usize {
    match base {
        BaseType::Primitive(p) => p.size().unwrap_or(4),
        BaseType::Message(m) => {
            let def = &schema.types[m];
            if def.fields.is_empty() {
                return usize::from(cdr);
            }
            def.fields
                .iter()
                .map(|f| match f.ty.array {
                    ArrayKind::Single => min_size(schema, &f.ty.base, cdr),
                    ArrayKind::Fixed(n) => n * min_size(schema, &f.ty.base, cdr),
                    _ => 4,
                })
                .sum()
        }
    }
}

pub(super) struct Decoder<'s> {
    pub(super) schema: &'s Schema,
}

impl Decoder<'_> {
    fn def(&self, name: &str) -> &MsgDef {
        &self.schema.types[name]
    }

    pub(super) fn message(&self, r: &mut Reader<'_>, def: &MsgDef) -> Result<Value, DynError> {
        if def.fields.is_empty() {
            if r.cdr {
                r.take(1)?;
            }
            return Ok(Value::Message(Vec::new()));
        }
        let mut out = Vec::with_capacity(def.fields.len());
        for f in &def.fields {
            let v = self.field(r, &f.ty).map_err(|e| in_field(e, &f.name))?;
            out.push((f.name.clone(), v));
        }
        Ok(Value::Message(out))
    }

    fn base(&self, r: &mut Reader<'_>, base: &BaseType) -> Result<Value, DynError> {
        match base {
            BaseType::Primitive(p) => r.primitive(*p, self.schema.dialect),
            BaseType::Message(m) => self.message(r, self.def(m)),
        }
    }

    pub(super) fn field(&self, r: &mut Reader<'_>, ty: &FieldType) -> Result<Value, DynError> {
        let n = match ty.array {
            ArrayKind::Single => return self.base(r, &ty.base),
            ArrayKind::Fixed(n) => n,
            ArrayKind::Bounded(_) | ArrayKind::Unbounded => {
                r.count(min_size(self.schema, &ty.base, r.cdr))?
            }
        };
        if let BaseType::Primitive(p) = ty.base
            && p.is_byte_like()
        {
            return Ok(Value::Bytes(r.take(n)?.to_vec()));
        }
        let mut items = Vec::with_capacity(n.min(r.remaining()));
        for i in 0..n {
            items.push(
                self.base(r, &ty.base)
                    .map_err(|e| in_field(e, &format!("[{i}]")))?,
            );
        }
        Ok(Value::Array(items))
    }

    fn skip_base(&self, r: &mut Reader<'_>, base: &BaseType) -> Result<(), DynError> {
        match base {
            BaseType::Primitive(p) => r.skip_primitive(*p),
            BaseType::Message(m) => {
                let def = self.def(m);
                if def.fields.is_empty() {
                    if r.cdr {
                        r.take(1)?;
                    }
                    return Ok(());
                }
                for f in &def.fields {
                    self.skip_field(r, &f.ty)
                        .map_err(|e| in_field(e, &f.name))?;
                }
                Ok(())
            }
        }
    }

    fn skip_elements(&self, r: &mut Reader<'_>, base: &BaseType, n: usize) -> Result<(), DynError> {
        if let BaseType::Primitive(p) = base
            && let (Some(size), false) =
                (p.size(), matches!(p, Primitive::Time | Primitive::Duration))
        {
            // Primitive arrays: aligned once, then contiguous.
            if n > 0 {
                r.align(size);
                r.take(n * size)?;
            }
            return Ok(());
        }
        for _ in 0..n {
            self.skip_base(r, base)?;
        }
        Ok(())
    }

    fn skip_field(&self, r: &mut Reader<'_>, ty: &FieldType) -> Result<(), DynError> {
        let n = match ty.array {
            ArrayKind::Single => return self.skip_base(r, &ty.base),
            ArrayKind::Fixed(n) => n,
            ArrayKind::Bounded(_) | ArrayKind::Unbounded => {
                r.count(min_size(self.schema, &ty.base, r.cdr))?
            }
        };
        self.skip_elements(r, &ty.base, n)
    }

    /// Walks `path` from the root message and decodes the value it names.
    pub(super) fn get(&self, r: &mut Reader<'_>, path: &FieldPath) -> Result<Value, DynError> {
        let mut ty = FieldType {
            base: BaseType::Message(self.schema.root.clone()),
            array: ArrayKind::Single,
            string_bound: None,
        };
        let wrap = |e: DynError| in_field(e, &path.text);
        for step in &path.steps {
            match *step {
                Step::Field(idx) => {
                    let BaseType::Message(m) = &ty.base else {
                        unreachable!("checked when the path was compiled")
                    };
                    let def = self.def(m);
                    for f in &def.fields[..idx] {
                        self.skip_field(r, &f.ty).map_err(wrap)?;
                    }
                    ty = def.fields[idx].ty.clone();
                }
                Step::Index(i) => {
                    let n = match ty.array {
                        ArrayKind::Fixed(n) => n,
                        _ => r
                            .count(min_size(self.schema, &ty.base, r.cdr))
                            .map_err(wrap)?,
                    };
                    if i >= n {
                        return Err(DynError::IndexOutOfRange {
                            path: path.text.clone(),
                            index: i,
                            len: n,
                        });
                    }
                    self.skip_elements(r, &ty.base, i).map_err(wrap)?;
                    ty.array = ArrayKind::Single;
                }
                Step::TimePart(k) => {
                    r.align(4);
                    let b = r.take(8).map_err(wrap)?;
                    let w: [u8; 4] = b[k * 4..k * 4 + 4].try_into().expect("4 bytes");
                    let v = match ty.base {
                        BaseType::Primitive(Primitive::Duration) => {
                            Value::Int(i32::from_le_bytes(w) as i64)
                        }
                        _ => Value::UInt(u32::from_le_bytes(w) as u64),
                    };
                    return Ok(v);
                }
            }
        }
        self.field(r, &ty).map_err(wrap)
    }
}

pub(super) struct Writer {
    pub(super) buf: Vec<u8>,
    base: usize,
    cdr: bool,
    dialect: Dialect,
}

fn enc_err(reason: impl Into<String>) -> DynError {
    DynError::Encode {
        field: String::new(),
        reason: reason.into(),
    }
}

impl Writer {
    pub(super) fn new(enc: MessageEncoding, dialect: Dialect) -> Self {
        match enc {
            MessageEncoding::Cdr => Writer {
                buf: vec![0, 1, 0, 0],
                base: 4,
                cdr: true,
                dialect,
            },
            MessageEncoding::Ros1 => Writer {
                buf: Vec::new(),
                base: 0,
                cdr: false,
                dialect,
            },
        }
    }

    fn align(&mut self, n: usize) {
        if self.cdr && n > 1 {
            let rel = self.buf.len() - self.base;
            let pad = rel.div_ceil(n) * n - rel;
            self.buf.extend(std::iter::repeat_n(0, pad));
        }
    }

    fn put(&mut self, bytes: &[u8]) {
        self.align(bytes.len());
        self.buf.extend_from_slice(bytes);
    }

    fn u32(&mut self, v: u32) {
        self.put(&v.to_le_bytes());
    }

    fn string(&mut self, s: &str) {
        if self.cdr {
            self.u32(s.len() as u32 + 1);
            self.buf.extend_from_slice(s.as_bytes());
            self.buf.push(0);
        } else {
            self.u32(s.len() as u32);
            self.buf.extend_from_slice(s.as_bytes());
        }
    }

    fn int(v: Option<&Value>, lo: i128, hi: i128) -> Result<i128, DynError> {
        let x: i128 = match v {
            None => 0,
            Some(Value::Int(i)) => *i as i128,
            Some(Value::UInt(u)) => *u as i128,
            Some(Value::Bool(b)) => *b as i128,
            Some(Value::Float(f)) if f.fract() == 0.0 && f.is_finite() => *f as i128,
            Some(other) => {
                return Err(enc_err(format!(
                    "expected an integer, got a {}",
                    other.kind()
                )));
            }
        };
        if x < lo || x > hi {
            return Err(enc_err(format!("{x} is out of range {lo}..={hi}")));
        }
        Ok(x)
    }

    fn float(v: Option<&Value>) -> Result<f64, DynError> {
        match v {
            None => Ok(0.0),
            Some(v) => v
                .as_f64()
                .ok_or_else(|| enc_err(format!("expected a number, got a {}", v.kind()))),
        }
    }

    fn primitive(&mut self, p: Primitive, v: Option<&Value>) -> Result<(), DynError> {
        // An empty message is the placeholder `encode_fields` leaves for unset array elements.
        let v = v.filter(|v| !matches!(v, Value::Message(f) if f.is_empty()));
        match p {
            Primitive::Bool => {
                let b = match v {
                    None => false,
                    Some(v) => v
                        .as_bool()
                        .ok_or_else(|| enc_err(format!("expected a bool, got a {}", v.kind())))?,
                };
                self.buf.push(u8::from(b));
            }
            Primitive::Byte if self.dialect == Dialect::Ros1 => {
                self.buf.push(Self::int(v, -128, 127)? as i8 as u8)
            }
            Primitive::Int8 => self.buf.push(Self::int(v, -128, 127)? as i8 as u8),
            Primitive::Byte | Primitive::Char | Primitive::UInt8 => {
                self.buf.push(Self::int(v, 0, 255)? as u8)
            }
            Primitive::Int16 => {
                self.put(&(Self::int(v, i16::MIN as i128, i16::MAX as i128)? as i16).to_le_bytes())
            }
            Primitive::UInt16 => {
                self.put(&(Self::int(v, 0, u16::MAX as i128)? as u16).to_le_bytes())
            }
            Primitive::Int32 => {
                self.put(&(Self::int(v, i32::MIN as i128, i32::MAX as i128)? as i32).to_le_bytes())
            }
            Primitive::UInt32 => {
                self.put(&(Self::int(v, 0, u32::MAX as i128)? as u32).to_le_bytes())
            }
            Primitive::Int64 => {
                self.put(&(Self::int(v, i64::MIN as i128, i64::MAX as i128)? as i64).to_le_bytes())
            }
            Primitive::UInt64 => {
                self.put(&(Self::int(v, 0, u64::MAX as i128)? as u64).to_le_bytes())
            }
            Primitive::Float32 => self.put(&(Self::float(v)? as f32).to_le_bytes()),
            Primitive::Float64 => self.put(&Self::float(v)?.to_le_bytes()),
            Primitive::String => match v {
                None => self.string(""),
                Some(Value::String(s)) => self.string(s),
                Some(other) => {
                    return Err(enc_err(format!(
                        "expected a string, got a {}",
                        other.kind()
                    )));
                }
            },
            Primitive::WString => return Err(enc_err("wstring fields are not supported")),
            Primitive::Time | Primitive::Duration => {
                let part = |names: [&str; 2]| -> Option<&Value> {
                    v.and_then(|v| names.iter().find_map(|n| v.field(n)))
                };
                let (s, n) = (part(["secs", "sec"]), part(["nsecs", "nanosec"]));
                if p == Primitive::Time {
                    self.put(&(Self::int(s, 0, u32::MAX as i128)? as u32).to_le_bytes());
                    self.put(&(Self::int(n, 0, u32::MAX as i128)? as u32).to_le_bytes());
                } else {
                    self.put(
                        &(Self::int(s, i32::MIN as i128, i32::MAX as i128)? as i32).to_le_bytes(),
                    );
                    self.put(
                        &(Self::int(n, i32::MIN as i128, i32::MAX as i128)? as i32).to_le_bytes(),
                    );
                }
            }
        }
        Ok(())
    }

    pub(super) fn message(
        &mut self,
        schema: &Schema,
        def: &MsgDef,
        v: Option<&Value>,
    ) -> Result<(), DynError> {
        let fields: &[(String, Value)] = match v {
            None => &[],
            Some(Value::Message(f)) => f,
            Some(other) => {
                return Err(enc_err(format!(
                    "expected a {} message, got a {}",
                    def.name,
                    other.kind()
                )));
            }
        };
        if let Some((unknown, _)) = fields
            .iter()
            .find(|(n, _)| !def.fields.iter().any(|f| &f.name == n))
        {
            return Err(DynError::UnknownField {
                path: unknown.clone(),
                field: unknown.clone(),
                type_name: def.name.clone(),
                available: def.fields.iter().map(|f| f.name.clone()).collect(),
            });
        }
        if def.fields.is_empty() {
            if self.cdr {
                self.buf.push(0);
            }
            return Ok(());
        }
        for f in &def.fields {
            let fv = fields.iter().find(|(n, _)| n == &f.name).map(|(_, v)| v);
            self.field(schema, &f.ty, fv)
                .map_err(|e| in_field(e, &f.name))?;
        }
        Ok(())
    }

    fn base(
        &mut self,
        schema: &Schema,
        base: &BaseType,
        v: Option<&Value>,
    ) -> Result<(), DynError> {
        match base {
            BaseType::Primitive(p) => self.primitive(*p, v),
            BaseType::Message(m) => self.message(schema, &schema.types[m], v),
        }
    }

    fn field(
        &mut self,
        schema: &Schema,
        ty: &FieldType,
        v: Option<&Value>,
    ) -> Result<(), DynError> {
        if ty.array == ArrayKind::Single {
            return self.base(schema, &ty.base, v);
        }
        let byte_like = matches!(ty.base, BaseType::Primitive(p) if p.is_byte_like());
        let bytes: Option<&[u8]> = match v {
            Some(Value::Bytes(b)) if byte_like => Some(b),
            Some(Value::Bytes(_)) => {
                return Err(enc_err("a byte array given for a non-byte array"));
            }
            _ => None,
        };
        let given = match (bytes, v) {
            (Some(b), _) => b.len(),
            (None, None) => 0,
            (None, Some(Value::Array(a))) => a.len(),
            (None, Some(other)) => {
                return Err(enc_err(format!(
                    "expected an array, got a {}",
                    other.kind()
                )));
            }
        };
        let n = match ty.array {
            ArrayKind::Fixed(n) => {
                if v.is_some() && given != n {
                    return Err(enc_err(format!("expected {n} elements, got {given}")));
                }
                n
            }
            ArrayKind::Bounded(max) if given > max => {
                return Err(enc_err(format!("at most {max} elements, got {given}")));
            }
            _ => {
                self.u32(given as u32);
                given
            }
        };
        if let Some(b) = bytes {
            self.buf.extend_from_slice(b);
            return Ok(());
        }
        let items: Vec<Option<&Value>> = match v {
            Some(Value::Array(a)) => a.iter().map(Some).collect(),
            _ => vec![None; n],
        };
        for (i, item) in items.into_iter().enumerate() {
            self.base(schema, &ty.base, item)
                .map_err(|e| in_field(e, &format!("[{i}]")))?;
        }
        Ok(())
    }
}
