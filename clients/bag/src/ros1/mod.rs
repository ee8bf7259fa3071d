//! ROS 1 bags (format 2.0, the `.bag` files of `rosbag record`): reading in log-time order through
//! the bag's index, and writing bags that `rosbag info`, `rosbag play`, Python `rosbag` and
//! `rosbags` accept.
//!
//! A bag is the magic `#ROSBAG V2.0\n` followed by records `u32 header_len | header | u32
//! data_len | data`, the header being `name=value` fields each prefixed with its `u32` length
//! (the TCPROS header format). The records, by their `op` field:
//!
//! | op | record | where |
//! |---|---|---|
//! | 0x03 | bag header: `index_pos`, `conn_count`, `chunk_count` | first, padded to 4096 bytes |
//! | 0x05 | chunk: `compression` (`none`, `bz2`, `lz4`), uncompressed `size`; data = records | |
//! | 0x07 | connection: `conn`, `topic`; data = `topic`, `type`, `md5sum`, `message_definition`, ... | in the chunk where it first appears, and again in the index |
//! | 0x02 | message data: `conn`, `time`; data = the ROS 1 serialized message | inside chunks |
//! | 0x04 | index data: `ver`=1, `conn`, `count`; data = `count` x (time, offset in the chunk) | after each chunk |
//! | 0x06 | chunk info: `ver`=1, `chunk_pos`, `start_time`, `end_time`, `count`; data = (conn, messages) pairs | the index, at `index_pos` |
//!
//! A `time` is `u32` seconds and `u32` nanoseconds; a message's time is its record (log) time,
//! not its header stamp.

pub(crate) mod read;
mod write;

pub use write::{Ros1Compression, Ros1Writer, Ros1WriterOptions};

use std::collections::BTreeMap;

/// The first bytes of every format 2.0 bag.
pub const MAGIC: &[u8; 13] = b"#ROSBAG V2.0\n";

pub(crate) const OP_MSG_DATA: u8 = 0x02;
pub(crate) const OP_BAG_HEADER: u8 = 0x03;
pub(crate) const OP_INDEX_DATA: u8 = 0x04;
pub(crate) const OP_CHUNK: u8 = 0x05;
pub(crate) const OP_CHUNK_INFO: u8 = 0x06;
pub(crate) const OP_CONNECTION: u8 = 0x07;

/// One record, borrowed from the file or a decompressed chunk.
#[derive(Clone, Debug)]
pub(crate) struct Record<'a> {
    /// Header fields.
    pub fields: BTreeMap<&'a str, &'a [u8]>,
    /// The data part.
    pub data: &'a [u8],
    /// Offset of the byte after the record.
    pub end: usize,
}

impl<'a> Record<'a> {
    /// The `op` field.
    pub fn op(&self) -> Result<u8, String> {
        match self.fields.get("op") {
            Some([op]) => Ok(*op),
            Some(v) => Err(format!("`op` field has {} bytes instead of 1", v.len())),
            None => Err("record header has no `op` field".into()),
        }
    }

    /// A little-endian `u32` field.
    pub fn u32(&self, name: &str) -> Result<u32, String> {
        let v = self.field(name)?;
        Ok(u32::from_le_bytes(v.try_into().map_err(|_| {
            format!("field `{name}` has {} bytes instead of 4", v.len())
        })?))
    }

    /// A little-endian `u64` field.
    pub fn u64(&self, name: &str) -> Result<u64, String> {
        let v = self.field(name)?;
        Ok(u64::from_le_bytes(v.try_into().map_err(|_| {
            format!("field `{name}` has {} bytes instead of 8", v.len())
        })?))
    }

    /// A `time` field in ns.
    pub fn time(&self, name: &str) -> Result<u64, String> {
        let v = self.field(name)?;
        if v.len() != 8 {
            return Err(format!("field `{name}` has {} bytes instead of 8", v.len()));
        }
        Ok(time_ns(v))
    }

    /// A text field.
    pub fn text(&self, name: &str) -> Result<&'a str, String> {
        std::str::from_utf8(self.field(name)?).map_err(|_| format!("field `{name}` is not UTF-8"))
    }

    /// A field's bytes.
    pub fn field(&self, name: &str) -> Result<&'a [u8], String> {
        self.fields
            .get(name)
            .copied()
            .ok_or_else(|| format!("record has no `{name}` field"))
    }
}

/// Reads a `time` (u32 secs, u32 nsecs) into ns.
pub(crate) fn time_ns(b: &[u8]) -> u64 {
    let s = u32::from_le_bytes(b[..4].try_into().expect("4 bytes")) as u64;
    let n = u32::from_le_bytes(b[4..8].try_into().expect("4 bytes")) as u64;
    s * 1_000_000_000 + n
}

/// Writes ns as a `time`.
pub(crate) fn time_bytes(ns: u64) -> [u8; 8] {
    let mut b = [0u8; 8];
    b[..4].copy_from_slice(&((ns / 1_000_000_000) as u32).to_le_bytes());
    b[4..].copy_from_slice(&((ns % 1_000_000_000) as u32).to_le_bytes());
    b
}

/// Parses header fields (`u32 len | name=value`, repeated).
pub(crate) fn parse_fields(mut h: &[u8]) -> Result<BTreeMap<&str, &[u8]>, String> {
    let mut out = BTreeMap::new();
    while !h.is_empty() {
        if h.len() < 4 {
            return Err(format!("{} stray bytes at the end of a header", h.len()));
        }
        let n = u32::from_le_bytes(h[..4].try_into().expect("4 bytes")) as usize;
        if n > h.len() - 4 {
            return Err(format!(
                "a header field of {n} bytes runs past the header ({} bytes left)",
                h.len() - 4
            ));
        }
        let f = &h[4..4 + n];
        let eq = f
            .iter()
            .position(|&b| b == b'=')
            .ok_or_else(|| "a header field has no `=`".to_string())?;
        let name = std::str::from_utf8(&f[..eq])
            .map_err(|_| "a header field name is not UTF-8".to_string())?;
        out.insert(name, &f[eq + 1..]);
        h = &h[4 + n..];
    }
    Ok(out)
}

/// Reads the record at `pos` of `buf` (a file or a decompressed chunk).
pub(crate) fn record_at(buf: &[u8], pos: usize) -> Result<Record<'_>, String> {
    let rest = buf
        .get(pos..)
        .ok_or_else(|| format!("record offset {pos} is past the end ({} bytes)", buf.len()))?;
    let u32_at = |at: usize, what: &str| -> Result<usize, String> {
        rest.get(at..at + 4)
            .map(|b| u32::from_le_bytes(b.try_into().expect("4 bytes")) as usize)
            .ok_or_else(|| format!("the {what} length at byte {} is cut off", pos + at))
    };
    let hlen = u32_at(0, "record header")?;
    let header = rest.get(4..4 + hlen).ok_or_else(|| {
        format!(
            "the record header at byte {pos} ({hlen} bytes) runs past the end ({} bytes)",
            buf.len()
        )
    })?;
    let dlen = u32_at(4 + hlen, "record data")?;
    let start = 8 + hlen;
    let data = rest.get(start..start + dlen).ok_or_else(|| {
        format!(
            "the record data at byte {} ({dlen} bytes) runs past the end ({} bytes)",
            pos + start,
            buf.len()
        )
    })?;
    let fields = parse_fields(header).map_err(|e| format!("record at byte {pos}: {e}"))?;
    Ok(Record {
        fields,
        data,
        end: pos + start + dlen,
    })
}

/// Appends a header field.
pub(crate) fn push_field(out: &mut Vec<u8>, name: &str, value: &[u8]) {
    out.extend_from_slice(&((name.len() + 1 + value.len()) as u32).to_le_bytes());
    out.extend_from_slice(name.as_bytes());
    out.push(b'=');
    out.extend_from_slice(value);
}

/// Appends a whole record.
pub(crate) fn push_record(out: &mut Vec<u8>, fields: &[(&str, &[u8])], data: &[u8]) {
    let mut h = Vec::with_capacity(64);
    for (n, v) in fields {
        push_field(&mut h, n, v);
    }
    out.extend_from_slice(&(h.len() as u32).to_le_bytes());
    out.extend_from_slice(&h);
    out.extend_from_slice(&(data.len() as u32).to_le_bytes());
    out.extend_from_slice(data);
}

/// A connection: one topic as published by one node.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Connection {
    /// The connection id.
    pub id: u32,
    /// The topic.
    pub topic: String,
    /// ROS 1 type name (`sensor_msgs/Image`).
    pub type_name: String,
    /// The type's md5sum.
    pub md5sum: String,
    /// The full message definition.
    pub definition: String,
    /// The publishing node, when recorded.
    pub callerid: Option<String>,
    /// True if the publisher was latched.
    pub latching: bool,
}

impl Connection {
    /// Parses a connection record.
    pub(crate) fn from_record(r: &Record<'_>) -> Result<Self, String> {
        let id = r.u32("conn")?;
        let f = parse_fields(r.data).map_err(|e| format!("connection {id}: {e}"))?;
        let text = |name: &str| -> Result<String, String> {
            let v = f
                .get(name)
                .ok_or_else(|| format!("connection {id} has no `{name}`"))?;
            String::from_utf8(v.to_vec())
                .map_err(|_| format!("connection {id}: `{name}` is not UTF-8"))
        };
        Ok(Connection {
            id,
            topic: r
                .text("topic")
                .map(str::to_string)
                .or_else(|_| text("topic"))?,
            type_name: text("type")?,
            md5sum: text("md5sum")?,
            definition: text("message_definition").unwrap_or_default(),
            callerid: text("callerid").ok(),
            latching: f.get("latching").is_some_and(|v| v == b"1"),
        })
    }

    /// The connection record's header fields and data.
    pub(crate) fn to_record(&self, out: &mut Vec<u8>) {
        let mut data = Vec::with_capacity(self.definition.len() + 128);
        push_field(&mut data, "topic", self.topic.as_bytes());
        push_field(&mut data, "type", self.type_name.as_bytes());
        push_field(&mut data, "md5sum", self.md5sum.as_bytes());
        push_field(&mut data, "message_definition", self.definition.as_bytes());
        if let Some(c) = &self.callerid {
            push_field(&mut data, "callerid", c.as_bytes());
        }
        if self.latching {
            push_field(&mut data, "latching", b"1");
        }
        push_record(
            out,
            &[
                ("op", &[OP_CONNECTION]),
                ("conn", &self.id.to_le_bytes()),
                ("topic", self.topic.as_bytes()),
            ],
            &data,
        );
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn records_round_trip_and_damage_is_named() {
        let mut b = Vec::new();
        push_record(
            &mut b,
            &[
                ("op", &[OP_MSG_DATA]),
                ("conn", &7u32.to_le_bytes()),
                ("time", &time_bytes(1_000_000_005)),
            ],
            b"xyz",
        );
        let r = record_at(&b, 0).unwrap();
        assert_eq!(r.op().unwrap(), OP_MSG_DATA);
        assert_eq!(r.u32("conn").unwrap(), 7);
        assert_eq!(r.time("time").unwrap(), 1_000_000_005);
        assert_eq!(r.data, b"xyz");
        assert_eq!(r.end, b.len());
        let e = record_at(&b[..b.len() - 1], 0).unwrap_err();
        assert!(e.contains("runs past the end"), "{e}");
        assert!(r.u64("conn").unwrap_err().contains("4 bytes instead of 8"));
        let c = Connection {
            id: 3,
            topic: "/a=b".into(),
            type_name: "std_msgs/String".into(),
            md5sum: "992ce8a1687cec8c8bd883ec73ca41d1".into(),
            definition: "string data\n".into(),
            callerid: Some("/me".into()),
            latching: true,
        };
        let mut b = Vec::new();
        c.to_record(&mut b);
        assert_eq!(
            Connection::from_record(&record_at(&b, 0).unwrap()).unwrap(),
            c
        );
    }
}
