//! ROS 1 serialization of `sensor_msgs/Image`, `sensor_msgs/CompressedImage`,
//! `sensor_msgs/PointCloud2`, `std_msgs/String` and `rosgraph_msgs/Clock`: the bytes of a TCPROS
//! message (after its 4-byte length), of a ROS 1 bag's MSG_DATA record and of an MCAP message
//! with encoding `ros1`.
//!
//! The ROS 1 wire format is little-endian and packed (no alignment padding); a string is a `u32`
//! byte length and the bytes (no NUL); `uint8[]` is a `u32` length and the bytes; `time` is
//! `u32` seconds and `u32` nanoseconds. ROS 1's `std_msgs/Header` starts with a `uint32 seq`
//! that ROS 2 dropped, so the messages decode into the same borrowed views as the CDR codecs of
//! [`super::ros`] plus the header's `seq`, returned beside them. ROS 1 stamps are unsigned; they
//! are kept bit for bit in the views' `i32` seconds (a stamp after 2038 reads as negative and
//! encodes back to the same bits).
//!
//! Every type also has its [`MsgType`]: the ROS 1 name, the md5sum the ROS 1 tools compare and
//! the full message definition (the `message_definition` of TCPROS headers and bag connection
//! records), as Debian's `python3-sensor-msgs` and `python3-std-msgs` generate them.
//!
//! ```
//! use perturb_core::formats::ros::{Header, ImageMsg};
//! let header = Header { stamp_sec: 1, stamp_nanosec: 2, frame_id: "cam" };
//! let msg = ImageMsg { header, height: 1, width: 2, encoding: "mono8", is_bigendian: 0, step: 2, data: &[7, 9] };
//! let bytes = msg.encode_ros1(41);
//! assert_eq!(bytes.len(), 4 + 8 + 7 + 4 + 4 + 9 + 1 + 4 + 6);
//! assert_eq!(ImageMsg::decode_ros1(&bytes).unwrap(), (41, msg));
//! ```

use super::ros::{CompressedImageMsg, Header, ImageMsg, PointCloud2Msg};
use crate::cloud::{Datatype, PointField};
use crate::error::{Error, Result};

/// A ROS 1 message type: name, md5sum and full definition.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct MsgType {
    /// The ROS 1 type name (`sensor_msgs/Image`).
    pub name: &'static str,
    /// The ROS 2 type name of the same message (`sensor_msgs/msg/Image`).
    pub ros2_name: &'static str,
    /// The md5sum ROS 1 publishers and subscribers compare.
    pub md5sum: &'static str,
    /// The full definition: the type's `.msg` text, then each dependency after a line of 80 `=`
    /// and a `MSG: pkg/Type` line.
    pub definition: &'static str,
}

/// `sensor_msgs/Image`.
pub const IMAGE: MsgType = MsgType {
    name: "sensor_msgs/Image",
    ros2_name: "sensor_msgs/msg/Image",
    md5sum: "060021388200f6f0f447d0fcd9c64743",
    definition: include_str!("ros1_msg/sensor_msgs-Image.txt"),
};

/// `sensor_msgs/CompressedImage`.
pub const COMPRESSED_IMAGE: MsgType = MsgType {
    name: "sensor_msgs/CompressedImage",
    ros2_name: "sensor_msgs/msg/CompressedImage",
    md5sum: "8f7a12909da2c9d3332d540a0977563f",
    definition: include_str!("ros1_msg/sensor_msgs-CompressedImage.txt"),
};

/// `sensor_msgs/PointCloud2`.
pub const POINT_CLOUD2: MsgType = MsgType {
    name: "sensor_msgs/PointCloud2",
    ros2_name: "sensor_msgs/msg/PointCloud2",
    md5sum: "1158d486dd51d683ce2f1be655c3c181",
    definition: include_str!("ros1_msg/sensor_msgs-PointCloud2.txt"),
};

/// `std_msgs/String` (the `/perturb/events` channel).
pub const STRING: MsgType = MsgType {
    name: "std_msgs/String",
    ros2_name: "std_msgs/msg/String",
    md5sum: "992ce8a1687cec8c8bd883ec73ca41d1",
    definition: include_str!("ros1_msg/std_msgs-String.txt"),
};

/// `rosgraph_msgs/Clock` (`/clock` under `use_sim_time`).
pub const CLOCK: MsgType = MsgType {
    name: "rosgraph_msgs/Clock",
    ros2_name: "rosgraph_msgs/msg/Clock",
    md5sum: "a9c97c1d230cfc112e270351a944ee47",
    definition: include_str!("ros1_msg/rosgraph_msgs-Clock.txt"),
};

/// The ROS 1 type named `name`, in any spelling the message-kind table knows
/// ([`super::kinds`]: `sensor_msgs/Image`, `sensor_msgs/msg/Image`, ...).
pub fn msg_type(name: &str) -> Option<MsgType> {
    super::kinds::Kind::parse(name).map(|k| k.info().ros1)
}

/// Little-endian packed reader.
struct Reader<'a> {
    buf: &'a [u8],
    pos: usize,
    what: &'static str,
}

impl<'a> Reader<'a> {
    fn new(buf: &'a [u8], what: &'static str) -> Self {
        Reader { buf, pos: 0, what }
    }

    fn take(&mut self, n: usize, field: &str) -> Result<&'a [u8]> {
        if n > self.buf.len() - self.pos {
            return Err(Error::malformed(
                self.what,
                format!(
                    "message ends inside `{field}` (needs {n} bytes at offset {}, message has {})",
                    self.pos,
                    self.buf.len()
                ),
            ));
        }
        let s = &self.buf[self.pos..self.pos + n];
        self.pos += n;
        Ok(s)
    }

    fn u8(&mut self, field: &str) -> Result<u8> {
        Ok(self.take(1, field)?[0])
    }

    fn u32(&mut self, field: &str) -> Result<u32> {
        let b: [u8; 4] = self.take(4, field)?.try_into().expect("4 bytes");
        Ok(u32::from_le_bytes(b))
    }

    fn bytes(&mut self, field: &str) -> Result<&'a [u8]> {
        let n = self.u32(field)? as usize;
        self.take(n, field)
    }

    fn string(&mut self, field: &str) -> Result<&'a str> {
        let raw = self.bytes(field)?;
        std::str::from_utf8(raw)
            .map_err(|_| Error::malformed(self.what, format!("`{field}` is not UTF-8")))
    }

    /// `std_msgs/Header`: seq, then the parts ROS 2 kept.
    fn header(&mut self) -> Result<(u32, Header<'a>)> {
        let seq = self.u32("header.seq")?;
        let header = Header {
            stamp_sec: self.u32("header.stamp.secs")? as i32,
            stamp_nanosec: self.u32("header.stamp.nsecs")?,
            frame_id: self.string("header.frame_id")?,
        };
        Ok((seq, header))
    }

    /// Refuses bytes after the last field (a framing error or another type).
    fn finish(&self) -> Result<()> {
        if self.pos != self.buf.len() {
            return Err(Error::malformed(
                self.what,
                format!(
                    "{} bytes follow the last field (message is {} bytes, fields end at {})",
                    self.buf.len() - self.pos,
                    self.buf.len(),
                    self.pos
                ),
            ));
        }
        Ok(())
    }
}

/// Little-endian packed writer.
#[derive(Default)]
struct Writer {
    buf: Vec<u8>,
}

impl Writer {
    fn with_capacity(n: usize) -> Self {
        Writer {
            buf: Vec::with_capacity(n),
        }
    }
    fn u8(&mut self, v: u8) {
        self.buf.push(v);
    }
    fn u32(&mut self, v: u32) {
        self.buf.extend_from_slice(&v.to_le_bytes());
    }
    fn string(&mut self, s: &str) {
        self.u32(s.len() as u32);
        self.buf.extend_from_slice(s.as_bytes());
    }
    fn header(&mut self, seq: u32, h: &Header<'_>) {
        self.u32(seq);
        self.u32(h.stamp_sec as u32);
        self.u32(h.stamp_nanosec);
        self.string(h.frame_id);
    }
}

/// A serialized ROS 1 message in three parts, so the large `data` array can be written to a
/// socket or a file straight from where it lies (shared memory) without being copied into one
/// buffer first. The message is `head ++ data ++ tail`.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Ros1Parts<'a> {
    /// Every field before the data bytes, the data's length prefix included.
    pub head: Vec<u8>,
    /// The data bytes.
    pub data: &'a [u8],
    /// Every field after the data bytes (PointCloud2's `is_dense`; empty for images).
    pub tail: Vec<u8>,
}

impl Ros1Parts<'_> {
    /// The message's length in bytes.
    pub fn len(&self) -> usize {
        self.head.len() + self.data.len() + self.tail.len()
    }

    /// True for an empty message (never, for the types here).
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The message in one buffer.
    pub fn to_vec(&self) -> Vec<u8> {
        let mut v = Vec::with_capacity(self.len());
        v.extend_from_slice(&self.head);
        v.extend_from_slice(self.data);
        v.extend_from_slice(&self.tail);
        v
    }
}

impl<'a> ImageMsg<'a> {
    /// Decodes a ROS 1 `sensor_msgs/Image`, borrowing the pixels; returns the header's `seq`
    /// beside the message.
    pub fn decode_ros1(buf: &'a [u8]) -> Result<(u32, Self)> {
        let mut r = Reader::new(buf, "sensor_msgs/Image (ROS 1)");
        let (seq, header) = r.header()?;
        let msg = ImageMsg {
            header,
            height: r.u32("height")?,
            width: r.u32("width")?,
            encoding: r.string("encoding")?,
            is_bigendian: r.u8("is_bigendian")?,
            step: r.u32("step")?,
            data: r.bytes("data")?,
        };
        r.finish()?;
        Ok((seq, msg))
    }

    /// The ROS 1 serialization with header `seq`, in parts (see [`Ros1Parts`]).
    pub fn ros1_parts(&self, seq: u32) -> Ros1Parts<'a> {
        let mut w = Writer::with_capacity(64 + self.header.frame_id.len() + self.encoding.len());
        w.header(seq, &self.header);
        w.u32(self.height);
        w.u32(self.width);
        w.string(self.encoding);
        w.u8(self.is_bigendian);
        w.u32(self.step);
        w.u32(self.data.len() as u32);
        Ros1Parts {
            head: w.buf,
            data: self.data,
            tail: Vec::new(),
        }
    }

    /// The ROS 1 serialization with header `seq`.
    pub fn encode_ros1(&self, seq: u32) -> Vec<u8> {
        self.ros1_parts(seq).to_vec()
    }
}

impl<'a> CompressedImageMsg<'a> {
    /// Decodes a ROS 1 `sensor_msgs/CompressedImage`; returns the header's `seq` beside it.
    pub fn decode_ros1(buf: &'a [u8]) -> Result<(u32, Self)> {
        let mut r = Reader::new(buf, "sensor_msgs/CompressedImage (ROS 1)");
        let (seq, header) = r.header()?;
        let msg = CompressedImageMsg {
            header,
            format: r.string("format")?,
            data: r.bytes("data")?,
        };
        r.finish()?;
        Ok((seq, msg))
    }

    /// The ROS 1 serialization with header `seq`.
    pub fn encode_ros1(&self, seq: u32) -> Vec<u8> {
        let mut w = Writer::with_capacity(64 + self.data.len());
        w.header(seq, &self.header);
        w.string(self.format);
        w.u32(self.data.len() as u32);
        w.buf.extend_from_slice(self.data);
        w.buf
    }
}

impl<'a> PointCloud2Msg<'a> {
    /// Decodes a ROS 1 `sensor_msgs/PointCloud2`, borrowing the points; returns the header's
    /// `seq` beside the message.
    pub fn decode_ros1(buf: &'a [u8]) -> Result<(u32, Self)> {
        const WHAT: &str = "sensor_msgs/PointCloud2 (ROS 1)";
        let mut r = Reader::new(buf, WHAT);
        let (seq, header) = r.header()?;
        let height = r.u32("height")?;
        let width = r.u32("width")?;
        let nfields = r.u32("fields")? as usize;
        if nfields > 4096 {
            return Err(Error::malformed(
                WHAT,
                format!("{nfields} fields is not plausible"),
            ));
        }
        let mut fields = Vec::with_capacity(nfields);
        for _ in 0..nfields {
            let name = r.string("fields[].name")?.to_string();
            let offset = r.u32("fields[].offset")?;
            let code = r.u8("fields[].datatype")?;
            let count = r.u32("fields[].count")?;
            let datatype = Datatype::from_code(code).ok_or_else(|| {
                Error::malformed(WHAT, format!("field `{name}` has unknown datatype {code}"))
            })?;
            fields.push(PointField {
                name,
                offset,
                datatype,
                count,
            });
        }
        let msg = PointCloud2Msg {
            header,
            height,
            width,
            fields,
            is_bigendian: r.u8("is_bigendian")? != 0,
            point_step: r.u32("point_step")?,
            row_step: r.u32("row_step")?,
            data: r.bytes("data")?,
            is_dense: r.u8("is_dense")? != 0,
        };
        r.finish()?;
        Ok((seq, msg))
    }

    /// The ROS 1 serialization with header `seq`, in parts (see [`Ros1Parts`]).
    pub fn ros1_parts(&self, seq: u32) -> Ros1Parts<'a> {
        let mut w = Writer::with_capacity(64 + self.fields.len() * 24);
        w.header(seq, &self.header);
        w.u32(self.height);
        w.u32(self.width);
        w.u32(self.fields.len() as u32);
        for f in &self.fields {
            w.string(&f.name);
            w.u32(f.offset);
            w.u8(f.datatype.code());
            w.u32(f.count);
        }
        w.u8(self.is_bigendian as u8);
        w.u32(self.point_step);
        w.u32(self.row_step);
        w.u32(self.data.len() as u32);
        Ros1Parts {
            head: w.buf,
            data: self.data,
            tail: vec![self.is_dense as u8],
        }
    }

    /// The ROS 1 serialization with header `seq`.
    pub fn encode_ros1(&self, seq: u32) -> Vec<u8> {
        self.ros1_parts(seq).to_vec()
    }
}

/// Encodes a `std_msgs/String`.
pub fn encode_string(s: &str) -> Vec<u8> {
    let mut w = Writer::with_capacity(4 + s.len());
    w.string(s);
    w.buf
}

/// Decodes a `std_msgs/String`.
pub fn decode_string(buf: &[u8]) -> Result<&str> {
    let mut r = Reader::new(buf, "std_msgs/String (ROS 1)");
    let s = r.string("data")?;
    r.finish()?;
    Ok(s)
}

/// Encodes a `rosgraph_msgs/Clock` holding `ns` nanoseconds since the epoch.
pub fn encode_clock(ns: u64) -> Vec<u8> {
    let mut w = Writer::with_capacity(8);
    w.u32((ns / 1_000_000_000) as u32);
    w.u32((ns % 1_000_000_000) as u32);
    w.buf
}

/// Decodes a `rosgraph_msgs/Clock` into nanoseconds since the epoch.
pub fn decode_clock(buf: &[u8]) -> Result<u64> {
    let mut r = Reader::new(buf, "rosgraph_msgs/Clock (ROS 1)");
    let sec = r.u32("clock.secs")? as u64;
    let nsec = r.u32("clock.nsecs")? as u64;
    r.finish()?;
    Ok(sec * 1_000_000_000 + nsec)
}

/// The `seq` of a ROS 1 message that starts with a `std_msgs/Header` (every sensor message).
pub fn header_seq(buf: &[u8]) -> Option<u32> {
    Some(u32::from_le_bytes(buf.get(..4)?.try_into().ok()?))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cloud::{Cloud, PointLayout};

    #[test]
    fn image_layout_matches_the_reference_example() {
        // ros1.md §3: a 2x2 rgb8 Image with frame_id `cam` and 12 data bytes is 56 bytes.
        let data: Vec<u8> = (0..12).collect();
        let msg = ImageMsg {
            header: Header {
                stamp_sec: 7,
                stamp_nanosec: 9,
                frame_id: "cam",
            },
            height: 2,
            width: 2,
            encoding: "rgb8",
            is_bigendian: 0,
            step: 6,
            data: &data,
        };
        let b = msg.encode_ros1(3);
        assert_eq!(b.len(), 56);
        let want: Vec<u8> = [
            &3u32.to_le_bytes()[..],
            &7u32.to_le_bytes(),
            &9u32.to_le_bytes(),
            &3u32.to_le_bytes(),
            b"cam",
            &2u32.to_le_bytes(),
            &2u32.to_le_bytes(),
            &4u32.to_le_bytes(),
            b"rgb8",
            &[0],
            &6u32.to_le_bytes(),
            &12u32.to_le_bytes(),
            &data,
        ]
        .concat();
        assert_eq!(b, want);
        assert_eq!(ImageMsg::decode_ros1(&b).unwrap(), (3, msg));
        assert_eq!(header_seq(&b), Some(3));
    }

    #[test]
    fn cloud_round_trips_packed_and_errors_say_where() {
        let cloud = Cloud::from_xyzi(&PointLayout::xyzi_f32(), &[[1.0, 2.0, 3.0, 4.0]; 10]);
        let mut msg = PointCloud2Msg::from_view(Header::default(), &cloud.view());
        msg.header.stamp_sec = -1; // 0xffffffff on the ROS 1 wire, kept bit for bit
        let b = msg.encode_ros1(u32::MAX);
        let (seq, back) = PointCloud2Msg::decode_ros1(&b).unwrap();
        assert_eq!((seq, &back), (u32::MAX, &msg));
        assert_eq!(&b[4..8], &[0xff; 4]);
        // No padding: the first field's `count` follows its datatype byte directly.
        let f0 = 4 + 8 + 4 + 4 + 4 + 4 + 4 + 1 + 4;
        assert_eq!(
            &b[f0..f0 + 2],
            &[7, 1],
            "datatype FLOAT32 then count 1 unaligned"
        );
        let err = PointCloud2Msg::decode_ros1(&b[..b.len() - 20]).unwrap_err();
        assert!(err.to_string().contains("`data`"), "{err}");
        let mut long = b.clone();
        long.push(0);
        let err = PointCloud2Msg::decode_ros1(&long).unwrap_err();
        assert!(err.to_string().contains("1 bytes follow"), "{err}");
        assert_eq!(msg.ros1_parts(u32::MAX).to_vec(), b);
    }

    #[test]
    fn small_types_and_names() {
        let c = CompressedImageMsg {
            header: Header::default(),
            format: "jpeg",
            data: &[1, 2, 3],
        };
        assert_eq!(
            CompressedImageMsg::decode_ros1(&c.encode_ros1(5)).unwrap(),
            (5, c)
        );
        assert_eq!(encode_string("hi"), [2, 0, 0, 0, b'h', b'i']);
        assert_eq!(decode_string(&encode_string("héllo")).unwrap(), "héllo");
        assert_eq!(
            decode_clock(&encode_clock(1_500_000_000_123)).unwrap(),
            1_500_000_000_123
        );
        assert_eq!(msg_type("sensor_msgs/msg/PointCloud2"), Some(POINT_CLOUD2));
        assert_eq!(msg_type("sensor_msgs/Image"), Some(IMAGE));
        assert_eq!(msg_type("sensor_msgs/Imu"), None);
        assert!(IMAGE.definition.contains("MSG: std_msgs/Header\n"));
        assert!(
            POINT_CLOUD2
                .definition
                .contains("MSG: sensor_msgs/PointField\n")
        );
    }
}
