//! Point-cloud views with the full `sensor_msgs/PointCloud2` layout.
//!
//! A cloud is `height` rows of `width` points; each point is `point_step` bytes holding named
//! [`PointField`]s at arbitrary (possibly unaligned) offsets, in either byte order. The same
//! [`CloudView`] wraps a shared-memory sample, a decoded PCD file or the data of a PointCloud2 in a
//! bag. Perturbations read the fields they need through [`FieldReader`]s and write results back in
//! the input's own layout, so every field they do not touch passes through byte for byte.
//!
//! ```
//! use perturb_core::cloud::{Cloud, PointLayout};
//! let layout = PointLayout::xyzi_f32();
//! let cloud = Cloud::from_xyzi(&layout, &[[1.0, 2.0, 3.0, 0.5]]);
//! let view = cloud.view();
//! let x = view.layout().reader("x").unwrap();
//! assert_eq!(x.read_f32(view.point(0)), 1.0);
//! ```

use crate::error::{Error, Result};
use std::sync::Arc;

/// The numeric type of a point field (the `sensor_msgs/PointField` constants).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[repr(u8)]
pub enum Datatype {
    /// Signed 8-bit integer (1).
    Int8 = 1,
    /// Unsigned 8-bit integer (2).
    Uint8 = 2,
    /// Signed 16-bit integer (3).
    Int16 = 3,
    /// Unsigned 16-bit integer (4).
    Uint16 = 4,
    /// Signed 32-bit integer (5).
    Int32 = 5,
    /// Unsigned 32-bit integer (6).
    Uint32 = 6,
    /// 32-bit float (7).
    Float32 = 7,
    /// 64-bit float (8).
    Float64 = 8,
}

impl Datatype {
    /// The datatype for a PointField constant.
    pub fn from_code(code: u8) -> Option<Self> {
        Some(match code {
            1 => Datatype::Int8,
            2 => Datatype::Uint8,
            3 => Datatype::Int16,
            4 => Datatype::Uint16,
            5 => Datatype::Int32,
            6 => Datatype::Uint32,
            7 => Datatype::Float32,
            8 => Datatype::Float64,
            _ => return None,
        })
    }

    /// The PointField constant.
    pub fn code(self) -> u8 {
        self as u8
    }

    /// Size in bytes.
    pub fn size(self) -> usize {
        match self {
            Datatype::Int8 | Datatype::Uint8 => 1,
            Datatype::Int16 | Datatype::Uint16 => 2,
            Datatype::Int32 | Datatype::Uint32 | Datatype::Float32 => 4,
            Datatype::Float64 => 8,
        }
    }

    /// True for the two float types.
    pub fn is_float(self) -> bool {
        matches!(self, Datatype::Float32 | Datatype::Float64)
    }

    /// PCD's (TYPE, SIZE) pair for this datatype.
    pub fn pcd_type(self) -> (char, usize) {
        let c = match self {
            Datatype::Int8 | Datatype::Int16 | Datatype::Int32 => 'I',
            Datatype::Uint8 | Datatype::Uint16 | Datatype::Uint32 => 'U',
            Datatype::Float32 | Datatype::Float64 => 'F',
        };
        (c, self.size())
    }

    /// The datatype of a PCD (TYPE, SIZE) pair.
    pub fn from_pcd(kind: char, size: usize) -> Option<Self> {
        Some(match (kind, size) {
            ('I', 1) => Datatype::Int8,
            ('U', 1) => Datatype::Uint8,
            ('I', 2) => Datatype::Int16,
            ('U', 2) => Datatype::Uint16,
            ('I', 4) => Datatype::Int32,
            ('U', 4) => Datatype::Uint32,
            ('F', 4) => Datatype::Float32,
            ('F', 8) => Datatype::Float64,
            _ => return None,
        })
    }
}

/// One named field of a point, as in `sensor_msgs/PointField`.
#[derive(Clone, Debug, PartialEq, Eq, Hash)]
pub struct PointField {
    /// Field name (`x`, `intensity`, `ring`, ...).
    pub name: String,
    /// Byte offset within the point.
    pub offset: u32,
    /// Numeric type.
    pub datatype: Datatype,
    /// Number of elements (usually 1).
    pub count: u32,
}

impl PointField {
    /// A field with count 1.
    pub fn new(name: &str, offset: u32, datatype: Datatype) -> Self {
        PointField {
            name: name.to_string(),
            offset,
            datatype,
            count: 1,
        }
    }

    /// Bytes the field occupies.
    pub fn byte_len(&self) -> usize {
        self.datatype.size() * self.count.max(1) as usize
    }
}

/// The per-point layout: fields, point size and byte order. Shared (cheaply cloned) between a
/// cloud and the perturbed clouds made from it.
#[derive(Clone, Debug, PartialEq, Eq, Hash)]
pub struct PointLayout {
    /// The fields, in declaration order.
    pub fields: Vec<PointField>,
    /// Bytes per point.
    pub point_step: u32,
    /// True if multi-byte values are big-endian.
    pub big_endian: bool,
}

/// Names under which the standard fields appear in the drivers and datasets the project reads.
pub mod names {
    /// Intensity (Velodyne, Ouster, KITTI calls it reflectance).
    pub const INTENSITY: &[&str] = &["intensity", "i", "reflectance", "remission"];
    /// Ring / laser channel.
    pub const RING: &[&str] = &["ring", "channel", "laser_id", "line"];
    /// Per-point time offset.
    pub const TIME: &[&str] = &["time", "t", "timestamp", "time_stamp", "offset_time"];
}

impl PointLayout {
    /// Validates and wraps a field list.
    pub fn new(fields: Vec<PointField>, point_step: u32, big_endian: bool) -> Result<Self> {
        for f in &fields {
            let end = f.offset as usize + f.byte_len();
            if end > point_step as usize {
                return Err(Error::cloud(format!(
                    "field `{}` at offset {} ({} bytes) runs past point_step {}",
                    f.name,
                    f.offset,
                    f.byte_len(),
                    point_step
                )));
            }
        }
        Ok(PointLayout {
            fields,
            point_step,
            big_endian,
        })
    }

    /// x, y, z, intensity as little-endian float32, 16 bytes per point (KITTI `.bin`).
    pub fn xyzi_f32() -> Self {
        PointLayout {
            fields: vec![
                PointField::new("x", 0, Datatype::Float32),
                PointField::new("y", 4, Datatype::Float32),
                PointField::new("z", 8, Datatype::Float32),
                PointField::new("intensity", 12, Datatype::Float32),
            ],
            point_step: 16,
            big_endian: false,
        }
    }

    /// x, y, z, intensity, ring (float32 x 4 + uint16), 18 bytes per point, packed.
    pub fn xyzir() -> Self {
        PointLayout {
            fields: vec![
                PointField::new("x", 0, Datatype::Float32),
                PointField::new("y", 4, Datatype::Float32),
                PointField::new("z", 8, Datatype::Float32),
                PointField::new("intensity", 12, Datatype::Float32),
                PointField::new("ring", 16, Datatype::Uint16),
            ],
            point_step: 18,
            big_endian: false,
        }
    }

    /// The field called `name`, if any.
    pub fn field(&self, name: &str) -> Option<&PointField> {
        self.fields.iter().find(|f| f.name == name)
    }

    /// The first field whose name is one of `names`.
    pub fn field_any(&self, names: &[&str]) -> Option<&PointField> {
        names.iter().find_map(|n| self.field(n))
    }

    /// A reader for the field called `name`.
    pub fn reader(&self, name: &str) -> Option<FieldReader> {
        self.field(name)
            .map(|f| FieldReader::new(f, self.big_endian))
    }

    /// A reader for the first field whose name is one of `names`.
    pub fn reader_any(&self, names: &[&str]) -> Option<FieldReader> {
        self.field_any(names)
            .map(|f| FieldReader::new(f, self.big_endian))
    }

    /// Readers for x, y and z, or a clear error if the layout lacks one.
    pub fn xyz_readers(&self) -> Result<[FieldReader; 3]> {
        let get = |name: &'static str| {
            let f = self.field(name).ok_or(Error::MissingField {
                field: name,
                hint: ": a point cloud needs x, y and z",
            })?;
            if !f.datatype.is_float() {
                return Err(Error::cloud(format!(
                    "field `{name}` is {:?}; x, y and z must be float32 or float64",
                    f.datatype
                )));
            }
            Ok(FieldReader::new(f, self.big_endian))
        };
        Ok([get("x")?, get("y")?, get("z")?])
    }
}

/// Reads and writes one field of a point at a fixed offset, any datatype, either byte order.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct FieldReader {
    /// Byte offset within the point.
    pub offset: usize,
    /// Numeric type.
    pub datatype: Datatype,
    /// Byte order.
    pub big_endian: bool,
}

macro_rules! rd {
    ($t:ty, $p:expr, $o:expr, $be:expr) => {{
        let mut b = [0u8; std::mem::size_of::<$t>()];
        b.copy_from_slice(&$p[$o..$o + std::mem::size_of::<$t>()]);
        if $be {
            <$t>::from_be_bytes(b)
        } else {
            <$t>::from_le_bytes(b)
        }
    }};
}

macro_rules! wr {
    ($v:expr, $p:expr, $o:expr, $be:expr) => {{
        let b = if $be {
            $v.to_be_bytes()
        } else {
            $v.to_le_bytes()
        };
        $p[$o..$o + b.len()].copy_from_slice(&b);
    }};
}

impl FieldReader {
    /// A reader for `field` in a layout of the given byte order.
    pub fn new(field: &PointField, big_endian: bool) -> Self {
        FieldReader {
            offset: field.offset as usize,
            datatype: field.datatype,
            big_endian,
        }
    }

    /// The value as f64.
    #[inline]
    pub fn read_f64(&self, point: &[u8]) -> f64 {
        let (o, be) = (self.offset, self.big_endian);
        match self.datatype {
            Datatype::Int8 => point[o] as i8 as f64,
            Datatype::Uint8 => point[o] as f64,
            Datatype::Int16 => rd!(i16, point, o, be) as f64,
            Datatype::Uint16 => rd!(u16, point, o, be) as f64,
            Datatype::Int32 => rd!(i32, point, o, be) as f64,
            Datatype::Uint32 => rd!(u32, point, o, be) as f64,
            Datatype::Float32 => rd!(f32, point, o, be) as f64,
            Datatype::Float64 => rd!(f64, point, o, be),
        }
    }

    /// The value as f32.
    #[inline]
    pub fn read_f32(&self, point: &[u8]) -> f32 {
        if self.datatype == Datatype::Float32 {
            rd!(f32, point, self.offset, self.big_endian)
        } else {
            self.read_f64(point) as f32
        }
    }

    /// Writes `v`, rounding and saturating for integer fields.
    #[inline]
    pub fn write_f64(&self, point: &mut [u8], v: f64) {
        let (o, be) = (self.offset, self.big_endian);
        let r = v.round();
        match self.datatype {
            Datatype::Int8 => point[o] = r.clamp(i8::MIN as f64, i8::MAX as f64) as i8 as u8,
            Datatype::Uint8 => point[o] = r.clamp(0.0, u8::MAX as f64) as u8,
            Datatype::Int16 => wr!(
                (r.clamp(i16::MIN as f64, i16::MAX as f64) as i16),
                point,
                o,
                be
            ),
            Datatype::Uint16 => wr!((r.clamp(0.0, u16::MAX as f64) as u16), point, o, be),
            Datatype::Int32 => wr!(
                (r.clamp(i32::MIN as f64, i32::MAX as f64) as i32),
                point,
                o,
                be
            ),
            Datatype::Uint32 => wr!((r.clamp(0.0, u32::MAX as f64) as u32), point, o, be),
            Datatype::Float32 => wr!((v as f32), point, o, be),
            Datatype::Float64 => wr!(v, point, o, be),
        }
    }

    /// True if the field is a little-endian f32 that lies within a point of `step` bytes: such a
    /// field can be read and written as the four bytes at its offset.
    pub fn is_le_f32_within(&self, step: usize) -> bool {
        self.datatype == Datatype::Float32 && !self.big_endian && self.offset + 4 <= step
    }

    /// Writes `v` (see [`FieldReader::write_f64`]).
    #[inline]
    pub fn write_f32(&self, point: &mut [u8], v: f32) {
        if self.datatype == Datatype::Float32 {
            wr!(v, point, self.offset, self.big_endian);
        } else {
            self.write_f64(point, v as f64)
        }
    }
}

fn check_cloud(
    len: usize,
    layout: &PointLayout,
    width: u32,
    height: u32,
    row_step: usize,
) -> Result<()> {
    let step = layout.point_step as usize;
    let row = width as usize * step;
    if step == 0 && width > 0 {
        return Err(Error::cloud("point_step is 0"));
    }
    // A cloud without rows that declares points per row contradicts itself: forwarded as an
    // empty cloud, its points would be lost without a word. (An empty cloud has width 0, with
    // height 0 or 1.)
    if height == 0 && width > 0 {
        return Err(Error::cloud(format!(
            "height is 0 but width is {width} ({len} data bytes): a cloud without rows cannot have points per row"
        )));
    }
    if row_step < row {
        return Err(Error::cloud(format!(
            "row_step {row_step} is smaller than width {width} x point_step {step} = {row}"
        )));
    }
    let needed = if height == 0 || width == 0 {
        0
    } else {
        row_step * (height as usize - 1) + row
    };
    if len < needed {
        return Err(Error::cloud(format!(
            "data is {len} bytes but {height}x{width} points of {step} bytes with row_step {row_step} need {needed}"
        )));
    }
    Ok(())
}

/// A read-only view of a point cloud in borrowed bytes.
#[derive(Clone, Debug)]
pub struct CloudView<'a> {
    layout: Arc<PointLayout>,
    data: &'a [u8],
    /// Points per row.
    pub width: u32,
    /// Rows (1 for an unorganised cloud).
    pub height: u32,
    /// Bytes from one row to the next.
    pub row_step: usize,
    /// True if the cloud promises no invalid (NaN) points.
    pub is_dense: bool,
}

impl<'a> CloudView<'a> {
    /// Wraps `data`; fails if the buffer is shorter than the layout says.
    pub fn new(
        layout: Arc<PointLayout>,
        data: &'a [u8],
        width: u32,
        height: u32,
        row_step: usize,
        is_dense: bool,
    ) -> Result<Self> {
        check_cloud(data.len(), &layout, width, height, row_step)?;
        Ok(CloudView {
            layout,
            data,
            width,
            height,
            row_step,
            is_dense,
        })
    }

    /// The point layout.
    pub fn layout(&self) -> &PointLayout {
        &self.layout
    }

    /// The shared point layout.
    pub fn layout_arc(&self) -> &Arc<PointLayout> {
        &self.layout
    }

    /// Number of points.
    pub fn len(&self) -> usize {
        self.width as usize * self.height as usize
    }

    /// True if the cloud has no points.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The bytes of point `i` (row-major).
    #[inline]
    pub fn point(&self, i: usize) -> &'a [u8] {
        let step = self.layout.point_step as usize;
        // Points stored back to back (every unorganised cloud) need no row arithmetic: a
        // division per point is a large share of reading a field.
        let start = if self.height <= 1 || self.row_step == self.width as usize * step {
            i * step
        } else {
            let w = self.width as usize;
            (i / w) * self.row_step + (i % w) * step
        };
        &self.data[start..start + step]
    }

    /// The underlying bytes.
    pub fn data(&self) -> &'a [u8] {
        self.data
    }

    /// True when the points are stored back to back (row_step = width x point_step or one row).
    pub fn is_contiguous(&self) -> bool {
        self.height <= 1 || self.row_step == self.width as usize * self.layout.point_step as usize
    }
}

/// An owned point cloud.
#[derive(Clone, Debug, PartialEq)]
pub struct Cloud {
    /// The point layout.
    pub layout: Arc<PointLayout>,
    /// The bytes, `row_step * height` long.
    pub data: Vec<u8>,
    /// Points per row.
    pub width: u32,
    /// Rows.
    pub height: u32,
    /// Bytes per row.
    pub row_step: usize,
    /// True if there are no NaN points.
    pub is_dense: bool,
}

impl Cloud {
    /// An unorganised cloud of `n` zeroed points.
    pub fn zeroed(layout: Arc<PointLayout>, n: usize) -> Self {
        let step = layout.point_step as usize;
        Cloud {
            data: vec![0; n * step],
            width: n as u32,
            height: 1,
            row_step: n * step,
            is_dense: true,
            layout,
        }
    }

    /// Wraps owned bytes, checking the layout.
    pub fn from_vec(
        layout: Arc<PointLayout>,
        data: Vec<u8>,
        width: u32,
        height: u32,
        row_step: usize,
        is_dense: bool,
    ) -> Result<Self> {
        check_cloud(data.len(), &layout, width, height, row_step)?;
        Ok(Cloud {
            layout,
            data,
            width,
            height,
            row_step,
            is_dense,
        })
    }

    /// A cloud in `layout` from (x, y, z, intensity) tuples; fields other than x, y, z and the
    /// intensity field are zero.
    pub fn from_xyzi(layout: &PointLayout, pts: &[[f32; 4]]) -> Self {
        let layout = Arc::new(layout.clone());
        let mut c = Cloud::zeroed(layout.clone(), pts.len());
        let [rx, ry, rz] = layout.xyz_readers().expect("layout with x, y, z");
        let ri = layout.reader_any(names::INTENSITY);
        let step = layout.point_step as usize;
        for (p, chunk) in pts.iter().zip(c.data.chunks_exact_mut(step)) {
            rx.write_f32(chunk, p[0]);
            ry.write_f32(chunk, p[1]);
            rz.write_f32(chunk, p[2]);
            if let Some(ri) = ri {
                ri.write_f32(chunk, p[3]);
            }
        }
        c
    }

    /// A read-only view.
    pub fn view(&self) -> CloudView<'_> {
        CloudView {
            layout: self.layout.clone(),
            data: &self.data,
            width: self.width,
            height: self.height,
            row_step: self.row_step,
            is_dense: self.is_dense,
        }
    }

    /// Number of points.
    pub fn len(&self) -> usize {
        self.width as usize * self.height as usize
    }

    /// True if the cloud has no points.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// A contiguous owned copy of a view.
    pub fn from_view(v: &CloudView<'_>) -> Self {
        let step = v.layout().point_step as usize;
        let mut data = Vec::with_capacity(v.len() * step);
        for i in 0..v.len() {
            data.extend_from_slice(v.point(i));
        }
        Cloud {
            layout: v.layout_arc().clone(),
            data,
            width: v.width,
            height: v.height,
            row_step: v.width as usize * step,
            is_dense: v.is_dense,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn unaligned_float64_field_round_trips() {
        // A point_step of 26 with a float64 at offset 18 (seen in real drivers).
        let layout = PointLayout::new(
            vec![
                PointField::new("x", 0, Datatype::Float32),
                PointField::new("y", 4, Datatype::Float32),
                PointField::new("z", 8, Datatype::Float32),
                PointField::new("intensity", 12, Datatype::Float32),
                PointField::new("ring", 16, Datatype::Uint16),
                PointField::new("time", 18, Datatype::Float64),
            ],
            26,
            false,
        )
        .unwrap();
        let mut p = vec![0u8; 26];
        let t = layout.reader("time").unwrap();
        t.write_f64(&mut p, 1234.5678);
        assert_eq!(t.read_f64(&p), 1234.5678);
        let r = layout.reader("ring").unwrap();
        r.write_f64(&mut p, 70000.0);
        assert_eq!(r.read_f64(&p), 65535.0, "integer writes saturate");
    }

    #[test]
    fn big_endian_reads() {
        let layout =
            PointLayout::new(vec![PointField::new("x", 0, Datatype::Float32)], 4, true).unwrap();
        let p = 1.5f32.to_be_bytes();
        assert_eq!(layout.reader("x").unwrap().read_f32(&p), 1.5);
    }

    #[test]
    fn rejects_field_past_point_step_and_short_data() {
        let err = PointLayout::new(vec![PointField::new("x", 14, Datatype::Float32)], 16, false)
            .unwrap_err();
        assert!(err.to_string().contains("`x`"), "{err}");
        let layout = Arc::new(PointLayout::xyzi_f32());
        let err = CloudView::new(layout.clone(), &[0u8; 31], 2, 1, 32, true).unwrap_err();
        assert!(err.to_string().contains("31 bytes"), "{err}");
        assert!(CloudView::new(layout, &[], 0, 1, 0, true).is_ok());
    }

    /// A PointCloud2 with height 0 and a width (and the data of its points) was forwarded as an
    /// empty cloud and counted as forwarded: it is invalid. Empty clouds stay valid.
    #[test]
    fn height_zero_with_points_per_row_is_refused() {
        let layout = Arc::new(PointLayout::xyzi_f32());
        let err = CloudView::new(layout.clone(), &[0u8; 64], 4, 0, 64, true).unwrap_err();
        assert!(
            err.to_string().contains("height is 0 but width is 4"),
            "{err}"
        );
        assert!(CloudView::new(layout.clone(), &[], 0, 0, 0, true).is_ok());
        assert!(CloudView::new(layout, &[], 0, 1, 0, true).is_ok());
    }

    #[test]
    fn missing_xyz_is_named() {
        let layout =
            PointLayout::new(vec![PointField::new("x", 0, Datatype::Float32)], 4, false).unwrap();
        let err = layout.xyz_readers().unwrap_err();
        assert!(err.to_string().contains("`y`"), "{err}");
    }

    #[test]
    fn organised_cloud_with_row_padding() {
        let layout = Arc::new(PointLayout::xyzi_f32());
        let mut data = vec![0u8; 2 * 40];
        let rx = layout.reader("x").unwrap();
        rx.write_f32(&mut data[40 + 16..], 7.0);
        let v = CloudView::new(layout, &data, 2, 2, 40, true).unwrap();
        assert_eq!(v.len(), 4);
        assert_eq!(rx.read_f32(v.point(3)), 7.0);
        assert!(!v.is_contiguous());
        let owned = Cloud::from_view(&v);
        assert_eq!(owned.data.len(), 64);
        assert_eq!(rx.read_f32(owned.view().point(3)), 7.0);
    }
}
