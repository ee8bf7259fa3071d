//! The frame header every camera and LiDAR sample carries in shared memory.
//!
//! A sample is an iceoryx2 `[u8]` payload (the image rows or the PointCloud2 point data, exactly as
//! in the ROS message) plus one [`FrameHeader`] in iceoryx2's user-header slot. The header is
//! `#[repr(C)]` with fixed-size fields only, so every process, in any language, reads it in place.
//! It carries:
//!
//! - a magic and the wire [`WIRE_VERSION`]: a peer speaking another version is refused with
//!   [`WireError::VersionMismatch`] instead of being misread (iceoryx2 also refuses to open a
//!   service whose header type name or size differs, see [`FrameHeader`]'s type name);
//! - the frame's sequence number, its ROS stamp and `frame_id` (bit-exact pass-through);
//! - for images: width, height, step and the ROS encoding string; for clouds: the complete
//!   PointCloud2 layout (up to [`MAX_FIELDS`] fields with name, offset, datatype and count),
//!   point_step, row_step, width, height, is_bigendian and is_dense;
//! - how many payload bytes are valid ([`FrameHeader::data_len`]): a LiDAR perturbation writes into
//!   a loan sized for its worst case and reports the size it actually produced;
//! - one CLOCK_MONOTONIC timestamp per hop (ingress publish, daemon receive, daemon publish);
//! - the perturbation applied (ID, severity, seed), or none.

use crate::error::{WireError, WireResult};
use iceoryx2::prelude::ZeroCopySend;
use perturb_core::cloud::{CloudView, Datatype, PointField, PointLayout};
use perturb_core::encoding::{EncodedView, Encoding};
use perturb_core::image::{ImageView, ImageViewMut, PixelFormat};
use perturb_core::perturber::Spec;
use std::sync::Arc;

/// First four bytes of every header.
pub const MAGIC: [u8; 4] = *b"PTRB";
/// The wire format version this build reads and writes. Bumped on every incompatible change of
/// [`FrameHeader`]; the iceoryx2 type name carries it too.
pub const WIRE_VERSION: u16 = 3;
/// Most PointCloud2 fields a header can describe. Velodyne drivers publish 6, Ouster 9, Hesai 6,
/// Livox 7; a cloud with more fields is refused with a clear error at publish time.
pub const MAX_FIELDS: usize = 16;
/// Longest PointField name, in bytes (UTF-8).
pub const FIELD_NAME_LEN: usize = 32;
/// Longest `frame_id`, in bytes (UTF-8). ROS puts no limit on it; real frame_ids are short
/// (`camera_front`, `velodyne_top`, a few namespaced ones reach 60-100 bytes). A longer one is
/// refused with [`WireError::TooLong`] naming it, and the bridge counts the message as bad.
pub const FRAME_ID_LEN: usize = 256;
/// Longest image encoding string, in bytes.
pub const ENCODING_LEN: usize = 32;
/// Longest perturbation ID, in bytes.
pub const PERTURBATION_ID_LEN: usize = 16;
/// [`FrameHeader::flags`]: the daemon's kill switch was engaged when it published the frame
/// (every stream passes raw frames until `perturb ctl arm`).
pub const FLAG_KILLED: u8 = 1;

/// What a sample holds.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[repr(u8)]
pub enum WireModality {
    /// A `sensor_msgs/Image`.
    Camera = 1,
    /// A `sensor_msgs/PointCloud2`.
    Lidar = 2,
}

impl WireModality {
    /// From the header byte.
    pub fn from_code(code: u8) -> Option<Self> {
        match code {
            1 => Some(WireModality::Camera),
            2 => Some(WireModality::Lidar),
            _ => None,
        }
    }

    /// "camera" or "lidar".
    pub fn as_str(self) -> &'static str {
        match self {
            WireModality::Camera => "camera",
            WireModality::Lidar => "lidar",
        }
    }
}

impl From<perturb_core::registry::Modality> for WireModality {
    fn from(m: perturb_core::registry::Modality) -> Self {
        match m {
            perturb_core::registry::Modality::Camera => WireModality::Camera,
            perturb_core::registry::Modality::Lidar => WireModality::Lidar,
        }
    }
}

/// A ROS time stamp (`builtin_interfaces/Time`), passed through bit-exact.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub struct Stamp {
    /// Seconds.
    pub sec: i32,
    /// Nanoseconds within the second.
    pub nanosec: u32,
}

/// One `sensor_msgs/PointField` in fixed-size form (48 bytes).
#[derive(Clone, Copy, Debug, PartialEq, Eq, ZeroCopySend)]
#[repr(C)]
pub struct WireField {
    /// UTF-8 name, NUL-padded.
    pub name: [u8; FIELD_NAME_LEN],
    /// Byte offset within the point.
    pub offset: u32,
    /// Number of elements.
    pub count: u32,
    /// PointField datatype constant (1..=8).
    pub datatype: u8,
    /// Zero.
    pub reserved: [u8; 7],
}

impl WireField {
    /// The all-zero field (an unused slot).
    pub const EMPTY: WireField = WireField {
        name: [0; FIELD_NAME_LEN],
        offset: 0,
        count: 0,
        datatype: 0,
        reserved: [0; 7],
    };
}

/// The user header of every camera and LiDAR sample (1176 bytes, `#[repr(C)]`, no pointers).
///
/// All integers are in the host's byte order (shared memory never leaves the machine). Text fields
/// are UTF-8, NUL-padded. The iceoryx2 type name `perturb::FrameHeader.v<WIRE_VERSION>` makes
/// iceoryx2 itself refuse to connect a peer compiled against another version of this struct.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ZeroCopySend)]
#[type_name("perturb::FrameHeader.v3")]
#[repr(C)]
pub struct FrameHeader {
    /// [`MAGIC`].
    pub magic: [u8; 4],
    /// [`WIRE_VERSION`] of the writer.
    pub version: u16,
    /// [`WireModality`] code (0: not set).
    pub modality: u8,
    /// Severity of the applied perturbation (0 when none).
    pub severity: u8,
    /// Frame sequence number, assigned by the ingress and kept by every hop. Perturbations are
    /// seeded with it, so `perturb apply --seq` reproduces a frame.
    pub seq: u64,
    /// ROS stamp, seconds.
    pub stamp_sec: i32,
    /// ROS stamp, nanoseconds.
    pub stamp_nanosec: u32,
    /// Valid payload bytes (the sample's payload may be longer).
    pub data_len: u64,
    /// CLOCK_MONOTONIC ns when the ingress published the frame (0: not stamped).
    pub t_ingress_ns: u64,
    /// CLOCK_MONOTONIC ns when the daemon received it (0: not through the daemon).
    pub t_daemon_rx_ns: u64,
    /// CLOCK_MONOTONIC ns when the daemon published it (0: not through the daemon).
    pub t_daemon_tx_ns: u64,
    /// How many samples the publisher of this sample sent before it on this service, counted by
    /// [`crate::FramePublisher`] itself (from 0 for each new publisher port). A reader that sees
    /// it jump lost samples on its own input (it was stalled, or not running), whatever the
    /// frames' sequence numbers say.
    pub publish_index: u64,
    /// Seed of the applied perturbation.
    pub perturbation_seed: u64,
    /// ID of the applied perturbation (`C-A1`), NUL-padded; all zero when none was applied.
    pub perturbation_id: [u8; PERTURBATION_ID_LEN],
    /// Points per row (cloud) or pixels per row (image).
    pub width: u32,
    /// Rows.
    pub height: u32,
    /// Image: bytes from one row to the next.
    pub step: u32,
    /// Cloud: bytes per point.
    pub point_step: u32,
    /// Cloud: bytes per row.
    pub row_step: u32,
    /// 1 if multi-byte values are big-endian.
    pub is_bigendian: u8,
    /// Cloud: 1 if the cloud has no invalid points.
    pub is_dense: u8,
    /// Cloud: number of valid entries in `fields`.
    pub field_count: u8,
    /// 1 if a perturbation was applied to this frame.
    pub perturbed: u8,
    /// Bit flags: [`FLAG_KILLED`].
    pub flags: u8,
    /// Zero.
    pub reserved: u8,
    /// The campaign step that chose the perturbation, 1-based (0: none; the perturbation was
    /// set by hand or by the configuration).
    pub campaign_step: u16,
    /// Frames the source knows were lost before this one and after the previous one it
    /// published (gaps in a ROS 1 publisher's header `seq`, counted per publisher): lost
    /// upstream of the middleware (sensor, driver, network).
    pub lost_before: u32,
    /// Image: ROS encoding (`rgb8`, `bgr8`, `mono8`, ...), NUL-padded.
    pub encoding: [u8; ENCODING_LEN],
    /// ROS `header.frame_id`, NUL-padded.
    pub frame_id: [u8; FRAME_ID_LEN],
    /// Cloud: the PointCloud2 fields.
    pub fields: [WireField; MAX_FIELDS],
}

impl Default for FrameHeader {
    /// An empty header of this wire version (modality unset, so it does not validate).
    fn default() -> Self {
        FrameHeader {
            magic: MAGIC,
            version: WIRE_VERSION,
            modality: 0,
            severity: 0,
            seq: 0,
            stamp_sec: 0,
            stamp_nanosec: 0,
            data_len: 0,
            t_ingress_ns: 0,
            t_daemon_rx_ns: 0,
            t_daemon_tx_ns: 0,
            publish_index: 0,
            perturbation_seed: 0,
            perturbation_id: [0; PERTURBATION_ID_LEN],
            width: 0,
            height: 0,
            step: 0,
            point_step: 0,
            row_step: 0,
            is_bigendian: 0,
            is_dense: 0,
            field_count: 0,
            perturbed: 0,
            flags: 0,
            reserved: 0,
            campaign_step: 0,
            lost_before: 0,
            encoding: [0; ENCODING_LEN],
            frame_id: [0; FRAME_ID_LEN],
            fields: [WireField::EMPTY; MAX_FIELDS],
        }
    }
}

fn put_str<const N: usize>(dst: &mut [u8; N], s: &str, what: &'static str) -> WireResult<()> {
    if s.len() > N {
        return Err(WireError::TooLong {
            what,
            value: s.to_string(),
            max: N,
        });
    }
    if s.as_bytes().contains(&0) {
        return Err(WireError::invalid(format!(
            "{what} `{s}` contains a NUL byte"
        )));
    }
    *dst = [0; N];
    dst[..s.len()].copy_from_slice(s.as_bytes());
    Ok(())
}

fn get_str<'a>(src: &'a [u8], what: &'static str) -> WireResult<&'a str> {
    let end = src.iter().position(|&b| b == 0).unwrap_or(src.len());
    std::str::from_utf8(&src[..end])
        .map_err(|_| WireError::invalid(format!("{what} is not valid UTF-8")))
}

/// What a perturbation applied to a frame was, read back from a header.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Applied {
    /// Catalogue ID.
    pub id: String,
    /// Severity.
    pub severity: u8,
    /// Seed.
    pub seed: u64,
}

impl FrameHeader {
    /// A header for an image of `width` x `height` pixels, rows `step` bytes apart, in the ROS
    /// `encoding` (any string up to [`ENCODING_LEN`] bytes; the daemon perturbs the encodings of
    /// [`perturb_core::encoding::ENCODINGS`] and refuses the others). Set `is_bigendian` for
    /// big-endian 16-bit data.
    pub fn image(
        seq: u64,
        stamp: Stamp,
        frame_id: &str,
        width: u32,
        height: u32,
        step: u32,
        encoding: &str,
    ) -> WireResult<Self> {
        let mut h = FrameHeader {
            modality: WireModality::Camera as u8,
            seq,
            stamp_sec: stamp.sec,
            stamp_nanosec: stamp.nanosec,
            width,
            height,
            step,
            data_len: step as u64 * height as u64,
            ..FrameHeader::default()
        };
        put_str(&mut h.frame_id, frame_id, "frame_id")?;
        put_str(&mut h.encoding, encoding, "image encoding")?;
        Ok(h)
    }

    /// A header for an image view (tight or padded stride), with the view's format as encoding.
    pub fn for_image_view(
        seq: u64,
        stamp: Stamp,
        frame_id: &str,
        view: &ImageView<'_>,
    ) -> WireResult<Self> {
        let step = u32::try_from(view.stride)
            .map_err(|_| WireError::invalid(format!("image stride {} too large", view.stride)))?;
        let mut h = Self::image(
            seq,
            stamp,
            frame_id,
            view.width,
            view.height,
            step,
            view.format.ros_encoding(),
        )?;
        h.data_len = image_bytes(view.height, step as usize, view.geometry().row_bytes()) as u64;
        Ok(h)
    }

    /// A header for a point cloud in `layout`, `width` x `height` points, rows `row_step` bytes
    /// apart. Fails if the layout has more than [`MAX_FIELDS`] fields or a name longer than
    /// [`FIELD_NAME_LEN`] bytes.
    #[allow(clippy::too_many_arguments)]
    pub fn cloud(
        seq: u64,
        stamp: Stamp,
        frame_id: &str,
        layout: &PointLayout,
        width: u32,
        height: u32,
        row_step: u32,
        is_dense: bool,
    ) -> WireResult<Self> {
        let mut h = FrameHeader {
            modality: WireModality::Lidar as u8,
            seq,
            stamp_sec: stamp.sec,
            stamp_nanosec: stamp.nanosec,
            width,
            height,
            row_step,
            is_dense: is_dense as u8,
            ..FrameHeader::default()
        };
        h.set_layout(layout)?;
        h.data_len = row_step as u64 * height as u64;
        put_str(&mut h.frame_id, frame_id, "frame_id")?;
        Ok(h)
    }

    /// A header for a cloud view (its layout, shape and density).
    pub fn for_cloud_view(
        seq: u64,
        stamp: Stamp,
        frame_id: &str,
        view: &CloudView<'_>,
    ) -> WireResult<Self> {
        let row_step = u32::try_from(view.row_step)
            .map_err(|_| WireError::invalid(format!("row_step {} too large", view.row_step)))?;
        let mut h = Self::cloud(
            seq,
            stamp,
            frame_id,
            view.layout(),
            view.width,
            view.height,
            row_step,
            view.is_dense,
        )?;
        h.data_len = cloud_bytes(
            view.height,
            view.row_step,
            view.width,
            view.layout().point_step,
        ) as u64;
        Ok(h)
    }

    /// Writes the PointCloud2 layout (fields, point_step, byte order) into the header.
    pub fn set_layout(&mut self, layout: &PointLayout) -> WireResult<()> {
        if layout.fields.len() > MAX_FIELDS {
            return Err(WireError::TooManyFields {
                count: layout.fields.len(),
                max: MAX_FIELDS,
            });
        }
        self.fields = [WireField::EMPTY; MAX_FIELDS];
        for (slot, f) in self.fields.iter_mut().zip(&layout.fields) {
            put_str(&mut slot.name, &f.name, "point field name")?;
            slot.offset = f.offset;
            slot.count = f.count;
            slot.datatype = f.datatype.code();
        }
        self.field_count = layout.fields.len() as u8;
        self.point_step = layout.point_step;
        self.is_bigendian = layout.big_endian as u8;
        Ok(())
    }

    /// Checks the magic and the wire version.
    pub fn check_version(&self) -> WireResult<()> {
        if self.magic != MAGIC || self.version != WIRE_VERSION {
            return Err(WireError::VersionMismatch {
                magic: self.magic,
                found: self.version,
                expected: WIRE_VERSION,
            });
        }
        Ok(())
    }

    /// The modality, after checking the version.
    pub fn modality(&self) -> WireResult<WireModality> {
        self.check_version()?;
        WireModality::from_code(self.modality).ok_or_else(|| {
            WireError::invalid(format!(
                "modality byte is {} (expected 1 = camera or 2 = lidar)",
                self.modality
            ))
        })
    }

    /// The ROS stamp.
    pub fn stamp(&self) -> Stamp {
        Stamp {
            sec: self.stamp_sec,
            nanosec: self.stamp_nanosec,
        }
    }

    /// The `frame_id` string.
    pub fn frame_id(&self) -> WireResult<&str> {
        get_str(&self.frame_id, "frame_id")
    }

    /// Sets the `frame_id`.
    pub fn set_frame_id(&mut self, frame_id: &str) -> WireResult<()> {
        put_str(&mut self.frame_id, frame_id, "frame_id")
    }

    /// The image encoding string.
    pub fn encoding(&self) -> WireResult<&str> {
        get_str(&self.encoding, "image encoding")
    }

    /// Sets the image encoding string.
    pub fn set_encoding(&mut self, encoding: &str) -> WireResult<()> {
        put_str(&mut self.encoding, encoding, "image encoding")
    }

    /// The perturbation applied to this frame, if any.
    pub fn applied(&self) -> Option<Applied> {
        if self.perturbed == 0 {
            return None;
        }
        let id = get_str(&self.perturbation_id, "perturbation id").ok()?;
        Some(Applied {
            id: id.to_string(),
            severity: self.severity,
            seed: self.perturbation_seed,
        })
    }

    /// Records the perturbation applied (or clears it with `None`).
    pub fn set_applied(&mut self, spec: Option<&Spec>) {
        match spec {
            Some(s) => {
                // Catalogue IDs are short ASCII; truncation cannot happen for them.
                let id = s.entry.id.as_bytes();
                let n = id.len().min(PERTURBATION_ID_LEN);
                self.perturbation_id = [0; PERTURBATION_ID_LEN];
                self.perturbation_id[..n].copy_from_slice(&id[..n]);
                self.severity = s.severity;
                self.perturbation_seed = s.seed;
                self.perturbed = 1;
            }
            None => {
                self.perturbation_id = [0; PERTURBATION_ID_LEN];
                self.severity = 0;
                self.perturbation_seed = 0;
                self.perturbed = 0;
            }
        }
    }

    /// The pixel format of an image frame in one of the 8-bit working layouts (a clear error
    /// for other encodings; [`FrameHeader::image_encoding`] reads every encoding).
    pub fn pixel_format(&self) -> WireResult<PixelFormat> {
        Ok(PixelFormat::from_ros_encoding(self.encoding()?)?)
    }

    /// The image encoding's row of the encoding table (a clear error naming an encoding the
    /// project does not handle).
    pub fn image_encoding(&self) -> WireResult<&'static Encoding> {
        Ok(Encoding::find(self.encoding()?)?)
    }

    /// Bytes an image with this header's geometry occupies (last row without padding).
    pub fn image_len(&self) -> WireResult<usize> {
        let e = self.image_encoding()?;
        Ok(image_bytes(
            self.height,
            self.step as usize,
            e.row_bytes(self.width),
        ))
    }

    /// Checks that the header describes a frame of its modality and that `payload_len` bytes
    /// hold it: version, modality, data_len within the payload, image geometry and encoding, or
    /// cloud layout (valid datatypes, fields inside the point, float x, y and z).
    pub fn validate(&self, payload_len: usize) -> WireResult<WireModality> {
        let m = self.modality()?;
        if self.data_len > payload_len as u64 {
            return Err(WireError::invalid(format!(
                "header says {} valid bytes but the sample payload has {payload_len}",
                self.data_len
            )));
        }
        self.frame_id()?;
        match m {
            WireModality::Camera => {
                // The encoding table checks the encoding, the tile (even sizes for Bayer and
                // YUV), the step and that `data_len` holds the rows; errors name the field.
                self.image_encoding()?.check(
                    self.width,
                    self.height,
                    self.step as usize,
                    self.data_len as usize,
                )?;
            }
            WireModality::Lidar => {
                let layout = self.point_layout()?;
                layout.xyz_readers()?;
                let min_row = self.width as u64 * self.point_step as u64;
                if self.height > 1 && (self.row_step as u64) < min_row {
                    return Err(WireError::invalid(format!(
                        "row_step {} is smaller than width {} x point_step {}",
                        self.row_step, self.width, self.point_step
                    )));
                }
                let need = cloud_bytes(
                    self.height,
                    self.row_step as usize,
                    self.width,
                    self.point_step,
                );
                if (self.data_len as usize) < need {
                    return Err(WireError::invalid(format!(
                        "{}x{} points of {} bytes (row_step {}) need {need} bytes but the header says {} are valid",
                        self.height, self.width, self.point_step, self.row_step, self.data_len
                    )));
                }
            }
        }
        Ok(m)
    }

    /// The PointCloud2 layout described by the header.
    pub fn point_layout(&self) -> WireResult<PointLayout> {
        let n = self.field_count as usize;
        if n > MAX_FIELDS {
            return Err(WireError::invalid(format!(
                "field_count {n} exceeds the maximum of {MAX_FIELDS}"
            )));
        }
        let mut fields = Vec::with_capacity(n);
        for (i, f) in self.fields[..n].iter().enumerate() {
            let name = get_str(&f.name, "point field name")?;
            let datatype = Datatype::from_code(f.datatype).ok_or_else(|| {
                WireError::invalid(format!(
                    "point field {i} (`{name}`) has datatype {} (valid: 1..=8)",
                    f.datatype
                ))
            })?;
            fields.push(PointField {
                name: name.to_string(),
                offset: f.offset,
                datatype,
                count: f.count,
            });
        }
        Ok(PointLayout::new(
            fields,
            self.point_step,
            self.is_bigendian != 0,
        )?)
    }

    /// True if `other` has the same point layout (fields, point_step, byte order): lets a reader
    /// reuse a parsed [`PointLayout`] from frame to frame.
    pub fn same_layout(&self, other: &FrameHeader) -> bool {
        self.field_count == other.field_count
            && self.point_step == other.point_step
            && self.is_bigendian == other.is_bigendian
            && self.fields == other.fields
    }

    /// An image view over `payload` (in place), after [`FrameHeader::validate`]-style checks.
    pub fn image_view<'a>(&self, payload: &'a [u8]) -> WireResult<ImageView<'a>> {
        let data = self.valid_bytes(payload)?;
        Ok(ImageView::new(
            data,
            self.width,
            self.height,
            self.step as usize,
            self.pixel_format()?,
        )?)
    }

    /// A view of the image in its own encoding over `payload` (in place), checked against the
    /// encoding table: what the daemon perturbs through a working view.
    pub fn encoded_view<'a>(&self, payload: &'a [u8]) -> WireResult<EncodedView<'a>> {
        let data = self.valid_bytes(payload)?;
        Ok(EncodedView::new(
            data,
            self.width,
            self.height,
            self.step as usize,
            self.image_encoding()?,
            self.is_bigendian != 0,
        )?)
    }

    /// A writable image view over `payload` with this header's geometry.
    pub fn image_view_mut<'a>(&self, payload: &'a mut [u8]) -> WireResult<ImageViewMut<'a>> {
        let len = self.data_len as usize;
        if len > payload.len() {
            return Err(WireError::invalid(format!(
                "header says {len} bytes but the payload has {}",
                payload.len()
            )));
        }
        Ok(ImageViewMut::new(
            &mut payload[..len],
            self.width,
            self.height,
            self.step as usize,
            self.pixel_format()?,
        )?)
    }

    /// A cloud view over `payload` (in place) in `layout` (from [`FrameHeader::point_layout`],
    /// possibly cached).
    pub fn cloud_view<'a>(
        &self,
        payload: &'a [u8],
        layout: Arc<PointLayout>,
    ) -> WireResult<CloudView<'a>> {
        let data = self.valid_bytes(payload)?;
        let row_step = if self.height <= 1 {
            // An unorganised cloud: ROS drivers set row_step = width * point_step; accept 0 too.
            (self.width as usize * self.point_step as usize).max(self.row_step as usize)
        } else {
            self.row_step as usize
        };
        Ok(CloudView::new(
            layout,
            data,
            self.width,
            self.height,
            row_step,
            self.is_dense != 0,
        )?)
    }

    /// The valid part of `payload` (`data_len` bytes).
    pub fn valid_bytes<'a>(&self, payload: &'a [u8]) -> WireResult<&'a [u8]> {
        self.check_version()?;
        payload.get(..self.data_len as usize).ok_or_else(|| {
            WireError::invalid(format!(
                "header says {} valid bytes but the sample payload has {}",
                self.data_len,
                payload.len()
            ))
        })
    }
}

/// Bytes of `height` rows `step` apart, the last one `row` long.
pub fn image_bytes(height: u32, step: usize, row: usize) -> usize {
    if height == 0 {
        0
    } else {
        step * (height as usize - 1) + row
    }
}

/// Bytes of `height` rows of `width` points, rows `row_step` apart.
pub fn cloud_bytes(height: u32, row_step: usize, width: u32, point_step: u32) -> usize {
    if height == 0 || width == 0 {
        0
    } else {
        row_step * (height as usize - 1) + width as usize * point_step as usize
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use perturb_core::cloud::Cloud;
    use perturb_core::image::Image;

    #[test]
    fn header_is_plain_and_stable() {
        assert_eq!(std::mem::size_of::<WireField>(), 48);
        assert_eq!(std::mem::size_of::<FrameHeader>(), 1176);
        assert_eq!(std::mem::align_of::<FrameHeader>(), 8);
    }

    #[test]
    fn image_round_trip_in_place() {
        let mut img = Image::new(5, 3, PixelFormat::Bgr8);
        img.data
            .iter_mut()
            .enumerate()
            .for_each(|(i, b)| *b = i as u8);
        let h =
            FrameHeader::for_image_view(9, Stamp { sec: 1, nanosec: 2 }, "cam_front", &img.view())
                .unwrap();
        assert_eq!(h.validate(img.data.len()).unwrap(), WireModality::Camera);
        let v = h.image_view(&img.data).unwrap();
        assert_eq!(v.row(2), img.view().row(2));
        assert_eq!(h.frame_id().unwrap(), "cam_front");
        assert_eq!(h.seq, 9);
    }

    #[test]
    fn cloud_layout_round_trips() {
        let layout = perturb_core::synthetic::velodyne_layout();
        let c = Cloud::from_xyzi(&layout, &[[1.0, 2.0, 3.0, 4.0], [5.0, 6.0, 7.0, 8.0]]);
        let h = FrameHeader::for_cloud_view(1, Stamp::default(), "velodyne", &c.view()).unwrap();
        assert_eq!(h.validate(c.data.len()).unwrap(), WireModality::Lidar);
        assert_eq!(h.point_layout().unwrap(), layout);
        let v = h.cloud_view(&c.data, Arc::new(layout)).unwrap();
        assert_eq!(v.len(), 2);
    }

    #[test]
    fn mismatches_are_named() {
        let img = Image::new(4, 4, PixelFormat::Rgb8);
        let mut h = FrameHeader::for_image_view(0, Stamp::default(), "c", &img.view()).unwrap();
        let e = h.validate(10).unwrap_err().to_string();
        assert!(e.contains("48 valid bytes") && e.contains("10"), "{e}");
        h.version = 7;
        let e = h.validate(48).unwrap_err();
        assert!(
            matches!(e, WireError::VersionMismatch { found: 7, .. }),
            "{e}"
        );
        h.version = WIRE_VERSION;
        h.set_encoding("nv21").unwrap();
        let e = h.validate(48).unwrap_err().to_string();
        assert!(e.contains("`nv21`"), "{e}");
        // Encodings of the table validate with their own rules: a Bayer frame's width is even.
        h.set_encoding("bayer_rggb8").unwrap();
        assert!(h.validate(48).is_ok());
        h.width = 3;
        let e = h.validate(48).unwrap_err().to_string();
        assert!(
            e.contains("bayer_rggb8") && e.contains("width 3 is odd"),
            "{e}"
        );
        h.set_encoding("mono16").unwrap();
        h.step = 5;
        let e = h.validate(48).unwrap_err().to_string();
        assert!(e.contains("step 5 is smaller than width 3 x 2"), "{e}");

        let layout = PointLayout::new(
            vec![PointField::new("intensity", 0, Datatype::Float32)],
            4,
            false,
        )
        .unwrap();
        let h = FrameHeader::cloud(0, Stamp::default(), "l", &layout, 1, 1, 4, true).unwrap();
        let e = h.validate(4).unwrap_err().to_string();
        assert!(e.contains("`x`"), "{e}");
        let long = "x".repeat(FRAME_ID_LEN + 1);
        let e = FrameHeader::cloud(0, Stamp::default(), &long, &layout, 1, 1, 4, true)
            .unwrap_err()
            .to_string();
        assert!(e.contains("frame_id"), "{e}");
    }

    #[test]
    fn frame_ids_of_up_to_256_bytes_pass_through() {
        let layout = perturb_core::synthetic::velodyne_layout();
        let id = format!("/{}", "vehicle/sensors/lidar_".repeat(11));
        assert!(id.len() > 64 && id.len() <= FRAME_ID_LEN, "{}", id.len());
        let full = "f".repeat(FRAME_ID_LEN);
        for frame_id in [id.as_str(), full.as_str()] {
            let h =
                FrameHeader::cloud(0, Stamp::default(), frame_id, &layout, 0, 1, 0, true).unwrap();
            assert_eq!(h.frame_id().unwrap(), frame_id);
        }
    }
}
