//! `sensor_msgs/Image`, `sensor_msgs/CompressedImage` and `sensor_msgs/PointCloud2` in CDR, the
//! encoding of ROS 2 messages on DDS and in rosbag2.
//!
//! A serialised message is a 4-byte encapsulation header (`00 01 00 00` for little-endian CDR,
//! `00 00 00 00` for big-endian) followed by the XCDR1 body, aligned relative to the body's start.
//! Decoding borrows the pixel or point bytes from the input buffer (no copy); both byte orders are
//! read. Encoding always writes little-endian CDR, byte-identical to what rosbag2 and the ROS 2
//! client libraries write.
//!
//! ```
//! use perturb_core::formats::ros::{Header, ImageMsg};
//! let header = Header { stamp_sec: 1, stamp_nanosec: 2, frame_id: "cam" };
//! let msg = ImageMsg { header, height: 1, width: 2, encoding: "mono8", is_bigendian: 0, step: 2, data: &[7, 9] };
//! let bytes = msg.encode();
//! assert_eq!(ImageMsg::decode(&bytes).unwrap(), msg);
//! ```

use crate::cloud::{CloudView, Datatype, PointField, PointLayout};
use crate::encoding::EncodedView;
use crate::error::{Error, Result};
use crate::image::ImageView;
use std::sync::Arc;

/// `std_msgs/Header`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub struct Header<'a> {
    /// `stamp.sec`.
    pub stamp_sec: i32,
    /// `stamp.nanosec`.
    pub stamp_nanosec: u32,
    /// `frame_id`.
    pub frame_id: &'a str,
}

/// `sensor_msgs/Image`, borrowing its pixel bytes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ImageMsg<'a> {
    /// Header.
    pub header: Header<'a>,
    /// Rows.
    pub height: u32,
    /// Columns.
    pub width: u32,
    /// Pixel encoding (`rgb8`, ...).
    pub encoding: &'a str,
    /// Byte order of multi-byte pixels.
    pub is_bigendian: u8,
    /// Row length in bytes.
    pub step: u32,
    /// Pixel bytes.
    pub data: &'a [u8],
}

/// `sensor_msgs/CompressedImage`, borrowing its bytes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct CompressedImageMsg<'a> {
    /// Header.
    pub header: Header<'a>,
    /// `jpeg`, `png`, or `rgb8; jpeg compressed bgr8` style strings.
    pub format: &'a str,
    /// The compressed file bytes.
    pub data: &'a [u8],
}

/// `sensor_msgs/PointCloud2`, borrowing its point bytes.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct PointCloud2Msg<'a> {
    /// Header.
    pub header: Header<'a>,
    /// Rows.
    pub height: u32,
    /// Points per row.
    pub width: u32,
    /// Field layout.
    pub fields: Vec<PointField>,
    /// Byte order of the data.
    pub is_bigendian: bool,
    /// Bytes per point.
    pub point_step: u32,
    /// Bytes per row.
    pub row_step: u32,
    /// Point bytes.
    pub data: &'a [u8],
    /// No invalid points.
    pub is_dense: bool,
}

struct Reader<'a> {
    body: &'a [u8],
    pos: usize,
    le: bool,
    what: &'static str,
}

impl<'a> Reader<'a> {
    fn new(buf: &'a [u8], what: &'static str) -> Result<Self> {
        if buf.len() < 4 {
            return Err(Error::malformed(
                what,
                format!("{} bytes is shorter than the 4-byte CDR header", buf.len()),
            ));
        }
        let le = match (buf[0], buf[1]) {
            (0, 1) | (0, 3) => true,
            (0, 0) | (0, 2) => false,
            (a, b) => {
                return Err(Error::malformed(
                    what,
                    format!("unknown CDR encapsulation {a:#04x} {b:#04x}"),
                ));
            }
        };
        Ok(Reader::body(&buf[4..], le, what))
    }

    fn body(body: &'a [u8], le: bool, what: &'static str) -> Self {
        Reader {
            body,
            pos: 0,
            le,
            what,
        }
    }

    fn err(&self, field: &str, need: usize) -> Error {
        Error::malformed(
            self.what,
            format!(
                "message ends inside `{field}` (needs {need} bytes at offset {}, body has {})",
                self.pos + 4,
                self.body.len()
            ),
        )
    }

    fn align(&mut self, n: usize) {
        self.pos = self.pos.div_ceil(n) * n;
    }

    fn take(&mut self, n: usize, field: &str) -> Result<&'a [u8]> {
        if self.pos + n > self.body.len() {
            return Err(self.err(field, n));
        }
        let s = &self.body[self.pos..self.pos + n];
        self.pos += n;
        Ok(s)
    }

    fn u8(&mut self, field: &str) -> Result<u8> {
        Ok(self.take(1, field)?[0])
    }

    fn u32(&mut self, field: &str) -> Result<u32> {
        self.align(4);
        let b: [u8; 4] = self.take(4, field)?.try_into().expect("4 bytes");
        Ok(if self.le {
            u32::from_le_bytes(b)
        } else {
            u32::from_be_bytes(b)
        })
    }

    fn string(&mut self, field: &str) -> Result<&'a str> {
        let len = self.u32(field)? as usize;
        if len == 0 {
            return Ok("");
        }
        let raw = self.take(len, field)?;
        let s = raw.strip_suffix(&[0]).unwrap_or(raw);
        std::str::from_utf8(s)
            .map_err(|_| Error::malformed(self.what, format!("`{field}` is not UTF-8")))
    }

    fn bytes(&mut self, field: &str) -> Result<&'a [u8]> {
        let len = self.u32(field)? as usize;
        self.take(len, field)
    }

    fn header(&mut self) -> Result<Header<'a>> {
        Ok(Header {
            stamp_sec: self.u32("header.stamp.sec")? as i32,
            stamp_nanosec: self.u32("header.stamp.nanosec")?,
            frame_id: self.string("header.frame_id")?,
        })
    }
}

/// Little-endian CDR writer.
struct Writer {
    buf: Vec<u8>,
}

impl Writer {
    fn new(capacity: usize) -> Self {
        let mut buf = Vec::with_capacity(capacity + 64);
        buf.extend_from_slice(&[0, 1, 0, 0]);
        Writer { buf }
    }
    fn align(&mut self, n: usize) {
        let body = self.buf.len() - 4;
        let pad = body.div_ceil(n) * n - body;
        self.buf.extend(std::iter::repeat_n(0, pad));
    }
    fn u8(&mut self, v: u8) {
        self.buf.push(v);
    }
    fn u32(&mut self, v: u32) {
        self.align(4);
        self.buf.extend_from_slice(&v.to_le_bytes());
    }
    fn string(&mut self, s: &str) {
        self.u32(s.len() as u32 + 1);
        self.buf.extend_from_slice(s.as_bytes());
        self.buf.push(0);
    }
    fn bytes(&mut self, b: &[u8]) {
        self.u32(b.len() as u32);
        self.buf.extend_from_slice(b);
    }
    fn header(&mut self, h: &Header<'_>) {
        self.u32(h.stamp_sec as u32);
        self.u32(h.stamp_nanosec);
        self.string(h.frame_id);
    }
}

impl<'a> ImageMsg<'a> {
    /// Decodes a CDR `sensor_msgs/Image`, borrowing the pixels.
    pub fn decode(buf: &'a [u8]) -> Result<Self> {
        Self::read(Reader::new(buf, "sensor_msgs/Image CDR")?)
    }

    /// Decodes the CDR body of a `sensor_msgs/Image` (the bytes after the 4-byte encapsulation
    /// header, as DDS implementations hand them out) in the given byte order.
    pub fn decode_body(body: &'a [u8], little_endian: bool) -> Result<Self> {
        Self::read(Reader::body(body, little_endian, "sensor_msgs/Image CDR"))
    }

    fn read(mut r: Reader<'a>) -> Result<Self> {
        Ok(ImageMsg {
            header: r.header()?,
            height: r.u32("height")?,
            width: r.u32("width")?,
            encoding: r.string("encoding")?,
            is_bigendian: r.u8("is_bigendian")?,
            step: r.u32("step")?,
            data: r.bytes("data")?,
        })
    }

    /// Encodes as little-endian CDR.
    pub fn encode(&self) -> Vec<u8> {
        let mut w = Writer::new(self.data.len());
        w.header(&self.header);
        w.u32(self.height);
        w.u32(self.width);
        w.string(self.encoding);
        w.u8(self.is_bigendian);
        w.u32(self.step);
        w.bytes(self.data);
        w.buf
    }

    /// A view of the pixels in their encoding (any row of [`crate::encoding::ENCODINGS`]),
    /// checking that the encoding is supported and that width, height, step and the data length
    /// agree (`step * height` bytes); an error names the field and its value.
    pub fn view(&self) -> Result<EncodedView<'a>> {
        EncodedView::from_ros(
            self.data,
            self.width,
            self.height,
            self.step as usize,
            self.encoding,
            self.is_bigendian,
        )
    }

    /// A message for `view` with `header` (the data must be the view's bytes, so padding is kept).
    pub fn from_view(header: Header<'a>, view: &ImageView<'a>) -> Self {
        let len = view.stride * view.height as usize;
        ImageMsg {
            header,
            height: view.height,
            width: view.width,
            encoding: view.format.ros_encoding(),
            is_bigendian: 0,
            step: view.stride as u32,
            data: &view.data()[..len.min(view.data().len())],
        }
    }
}

impl<'a> CompressedImageMsg<'a> {
    /// Decodes a CDR `sensor_msgs/CompressedImage`.
    pub fn decode(buf: &'a [u8]) -> Result<Self> {
        Self::read(Reader::new(buf, "sensor_msgs/CompressedImage CDR")?)
    }

    /// Decodes the CDR body (without the encapsulation header) in the given byte order.
    pub fn decode_body(body: &'a [u8], little_endian: bool) -> Result<Self> {
        Self::read(Reader::body(
            body,
            little_endian,
            "sensor_msgs/CompressedImage CDR",
        ))
    }

    fn read(mut r: Reader<'a>) -> Result<Self> {
        Ok(CompressedImageMsg {
            header: r.header()?,
            format: r.string("format")?,
            data: r.bytes("data")?,
        })
    }

    /// Encodes as little-endian CDR.
    pub fn encode(&self) -> Vec<u8> {
        let mut w = Writer::new(self.data.len());
        w.header(&self.header);
        w.string(self.format);
        w.bytes(self.data);
        w.buf
    }
}

impl<'a> PointCloud2Msg<'a> {
    /// Decodes a CDR `sensor_msgs/PointCloud2`, borrowing the points.
    pub fn decode(buf: &'a [u8]) -> Result<Self> {
        Self::read(Reader::new(buf, "sensor_msgs/PointCloud2 CDR")?)
    }

    /// Decodes the CDR body (without the encapsulation header) in the given byte order.
    pub fn decode_body(body: &'a [u8], little_endian: bool) -> Result<Self> {
        Self::read(Reader::body(
            body,
            little_endian,
            "sensor_msgs/PointCloud2 CDR",
        ))
    }

    fn read(mut r: Reader<'a>) -> Result<Self> {
        let header = r.header()?;
        let height = r.u32("height")?;
        let width = r.u32("width")?;
        let nfields = r.u32("fields")? as usize;
        if nfields > 4096 {
            return Err(Error::malformed(
                "sensor_msgs/PointCloud2 CDR",
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
                Error::malformed(
                    "sensor_msgs/PointCloud2 CDR",
                    format!("field `{name}` has unknown datatype {code}"),
                )
            })?;
            fields.push(PointField {
                name,
                offset,
                datatype,
                count,
            });
        }
        Ok(PointCloud2Msg {
            header,
            height,
            width,
            fields,
            is_bigendian: r.u8("is_bigendian")? != 0,
            point_step: r.u32("point_step")?,
            row_step: r.u32("row_step")?,
            data: r.bytes("data")?,
            is_dense: r.u8("is_dense")? != 0,
        })
    }

    /// Encodes as little-endian CDR.
    pub fn encode(&self) -> Vec<u8> {
        let mut w = Writer::new(self.data.len());
        w.header(&self.header);
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
        w.bytes(self.data);
        w.u8(self.is_dense as u8);
        w.buf
    }

    /// The point layout, validated.
    pub fn layout(&self) -> Result<PointLayout> {
        PointLayout::new(self.fields.clone(), self.point_step, self.is_bigendian)
    }

    /// A view of the points, checking the layout and that the data holds what the header says.
    pub fn view(&self) -> Result<CloudView<'a>> {
        CloudView::new(
            Arc::new(self.layout()?),
            self.data,
            self.width,
            self.height,
            self.row_step as usize,
            self.is_dense,
        )
    }

    /// A message for `cloud` with `header`; the cloud's points must be contiguous.
    pub fn from_view(header: Header<'a>, cloud: &CloudView<'a>) -> Self {
        let layout = cloud.layout();
        let len = if cloud.height == 0 {
            0
        } else {
            cloud.row_step * (cloud.height as usize - 1)
                + cloud.width as usize * layout.point_step as usize
        };
        PointCloud2Msg {
            header,
            height: cloud.height,
            width: cloud.width,
            fields: layout.fields.clone(),
            is_bigendian: layout.big_endian,
            point_step: layout.point_step,
            row_step: cloud.row_step as u32,
            data: &cloud.data()[..len],
            is_dense: cloud.is_dense,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cloud::Cloud;

    #[test]
    fn image_layout_matches_hand_encoded_cdr() {
        let h = Header {
            stamp_sec: 5,
            stamp_nanosec: 6,
            frame_id: "ab",
        };
        let msg = ImageMsg {
            header: h,
            height: 1,
            width: 1,
            encoding: "mono8",
            is_bigendian: 0,
            step: 1,
            data: &[42],
        };
        let b = msg.encode();
        let want: Vec<u8> = [
            &[0u8, 1, 0, 0][..],
            &5u32.to_le_bytes(),
            &6u32.to_le_bytes(),
            &3u32.to_le_bytes(),
            b"ab\0",
            &[0], // pad to 4
            &1u32.to_le_bytes(),
            &1u32.to_le_bytes(),
            &6u32.to_le_bytes(),
            b"mono8\0",
            &[0], // is_bigendian
            &[0], // pad to 4 (body offset 32)
            &1u32.to_le_bytes(),
            &1u32.to_le_bytes(),
            &[42],
        ]
        .concat();
        assert_eq!(b, want);
        assert_eq!(ImageMsg::decode(&b).unwrap(), msg);
    }

    #[test]
    fn truncated_messages_say_where() {
        let cloud = Cloud::from_xyzi(&PointLayout::xyzi_f32(), &[[1.0, 2.0, 3.0, 4.0]; 10]);
        let msg = PointCloud2Msg::from_view(Header::default(), &cloud.view());
        let b = msg.encode();
        assert_eq!(PointCloud2Msg::decode(&b).unwrap(), msg);
        let err = PointCloud2Msg::decode(&b[..b.len() - 20]).unwrap_err();
        assert!(err.to_string().contains("`data`"), "{err}");
        assert!(ImageMsg::decode(&[0, 1]).is_err());
    }

    #[test]
    fn image_header_lies_are_caught_by_view() {
        let msg = ImageMsg {
            header: Header::default(),
            height: 4,
            width: 4,
            encoding: "rgb8",
            is_bigendian: 0,
            step: 12,
            data: &[0; 40],
        };
        let err = msg.view().unwrap_err();
        assert!(err.to_string().contains("48 bytes"), "{err}");
        let msg = ImageMsg {
            encoding: "nv21",
            data: &[0; 48],
            ..msg
        };
        assert!(msg.view().unwrap_err().to_string().contains("`nv21`"));
        let msg = ImageMsg {
            encoding: "bayer_rggb8",
            width: 3,
            step: 3,
            ..msg
        };
        let err = msg.view().unwrap_err().to_string();
        assert!(err.contains("width 3 is odd"), "{err}");
    }
}
