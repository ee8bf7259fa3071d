//! What the live view sends of a frame: a camera frame as a JPEG (through its 8-bit working view,
//! shrunk by a whole factor to a maximum width, encoded by `jpeg-encoder`), a point cloud as a
//! `foxglove.PointCloud` over the same point bytes (thinned to a maximum number of points), a
//! `camera_info` as a `foxglove.CameraCalibration` scaled to the JPEG's size.

use crate::frame::Payload;
use foxglove::schemas::packed_element_field::NumericType;
use foxglove::schemas::{
    CameraCalibration, CompressedImage, PackedElementField, PointCloud, Timestamp,
};
use perturb_bag::dynamic::{MessageCodec, Value};
use perturb_core::cloud::Datatype;
use perturb_core::encoding::Scratch;
use perturb_core::image::{Image, PixelFormat, resize_bilinear};

/// Why a frame could not be shown.
#[derive(Debug, thiserror::Error)]
pub enum FrameError {
    /// The frame is not of the stream's kind.
    #[error("a {got} frame on a {want} stream")]
    WrongKind {
        /// What the stream carries.
        want: &'static str,
        /// What came.
        got: &'static str,
    },
    /// The message does not hold what its header says (or its encoding is unknown).
    #[error("{0}")]
    Invalid(#[from] perturb_core::Error),
    /// A big-endian point cloud (Foxglove reads little-endian points only).
    #[error("big-endian point clouds are not shown")]
    BigEndianCloud,
    /// A calibration message that does not decode as `sensor_msgs/CameraInfo`.
    #[error("camera_info: {0}")]
    Calibration(String),
    /// The JPEG encoder refused the frame.
    #[error("JPEG: {0}")]
    Jpeg(#[from] jpeg_encoder::EncodingError),
    /// A frame too large for JPEG (65535 pixels a side).
    #[error("{0}x{1} is too large for JPEG (65535 pixels a side): lower [view] max_width")]
    TooLarge(u32, u32),
}

fn kind_name(p: &Payload<'_>) -> &'static str {
    match p {
        Payload::Image(_) => "image",
        Payload::Cloud(_) => "cloud",
    }
}

/// The header stamp as a Foxglove timestamp (negative seconds, which ROS allows, become 0).
pub fn stamp(sec: i32, nanosec: u32) -> Timestamp {
    Timestamp::new(sec.max(0) as u32, nanosec.min(999_999_999))
}

/// A camera frame shrunk for the view, borrowing nothing: its pixels (rgb8, bgr8, rgba8, bgra8
/// or mono8, as the working view), the factor it was shrunk by, and its header.
pub struct Shrunk {
    /// The pixels.
    pub image: Image,
    /// Width and height were divided by it.
    pub factor: u32,
    /// Header stamp.
    pub stamp: Timestamp,
    /// `frame_id`.
    pub frame_id: String,
}

/// The smallest whole factor that brings `width` to at most `max_width`.
pub fn factor(width: u32, max_width: u32) -> u32 {
    width.div_ceil(max_width.max(1)).max(1)
}

/// Shrinks an image frame to at most `max_width` by a whole factor (bilinear, through its 8-bit
/// working view: Bayer, YUV and 16-bit frames are converted as the daemon converts them); the
/// copy lets the shared-memory sample go before the JPEG is encoded.
pub fn shrink(
    p: &Payload<'_>,
    max_width: u32,
    scratch: &mut Scratch,
) -> Result<Shrunk, FrameError> {
    let Payload::Image(m) = p else {
        return Err(FrameError::WrongKind {
            want: "image",
            got: kind_name(p),
        });
    };
    let encoded = m.view()?;
    let work = scratch.to_working(&encoded);
    let factor = factor(work.width, max_width);
    let (w, h) = ((work.width / factor).max(1), (work.height / factor).max(1));
    let image = if factor > 1 {
        resize_bilinear(&work, w, h)
    } else {
        Image::from_view(&work)
    };
    Ok(Shrunk {
        image,
        factor,
        stamp: stamp(m.header.stamp_sec, m.header.stamp_nanosec),
        frame_id: m.header.frame_id.to_string(),
    })
}

/// The JPEG message of a shrunk frame at `quality` (alpha is dropped).
pub fn jpeg(s: &Shrunk, quality: u8) -> Result<CompressedImage, FrameError> {
    use jpeg_encoder::ColorType;
    let img = &s.image;
    let (w, h) = (
        u16::try_from(img.width).map_err(|_| FrameError::TooLarge(img.width, img.height))?,
        u16::try_from(img.height).map_err(|_| FrameError::TooLarge(img.width, img.height))?,
    );
    let color = match img.format {
        PixelFormat::Rgb8 => ColorType::Rgb,
        PixelFormat::Bgr8 => ColorType::Bgr,
        PixelFormat::Rgba8 => ColorType::Rgba,
        PixelFormat::Bgra8 => ColorType::Bgra,
        PixelFormat::Mono8 => ColorType::Luma,
    };
    let mut data = Vec::with_capacity(img.data.len() / 8);
    jpeg_encoder::Encoder::new(&mut data, quality.clamp(1, 100)).encode(&img.data, w, h, color)?;
    Ok(CompressedImage {
        timestamp: Some(s.stamp),
        frame_id: s.frame_id.clone(),
        data: data.into(),
        format: "jpeg".into(),
    })
}

/// The Foxglove numeric type of a PointCloud2 datatype.
fn numeric(d: Datatype) -> NumericType {
    match d {
        Datatype::Int8 => NumericType::Int8,
        Datatype::Uint8 => NumericType::Uint8,
        Datatype::Int16 => NumericType::Int16,
        Datatype::Uint16 => NumericType::Uint16,
        Datatype::Int32 => NumericType::Int32,
        Datatype::Uint32 => NumericType::Uint32,
        Datatype::Float32 => NumericType::Float32,
        Datatype::Float64 => NumericType::Float64,
    }
}

/// A cloud frame as a `foxglove.PointCloud`: the same point bytes and fields (array fields,
/// `count > 1`, are left out), every k-th point so that at most `max_points` remain.
pub fn cloud(p: &Payload<'_>, max_points: u32) -> Result<PointCloud, FrameError> {
    let Payload::Cloud(m) = p else {
        return Err(FrameError::WrongKind {
            want: "cloud",
            got: kind_name(p),
        });
    };
    let view = m.view()?;
    let layout = view.layout();
    if layout.big_endian {
        return Err(FrameError::BigEndianCloud);
    }
    let n = view.len();
    let every = n.div_ceil(max_points.max(1) as usize).max(1);
    let step = layout.point_step as usize;
    let mut data = Vec::with_capacity(n.div_ceil(every) * step);
    for i in (0..n).step_by(every) {
        data.extend_from_slice(view.point(i));
    }
    let fields = layout
        .fields
        .iter()
        .filter(|f| f.count == 1)
        .map(|f| PackedElementField {
            name: f.name.clone(),
            offset: f.offset,
            r#type: numeric(f.datatype) as i32,
        })
        .collect();
    Ok(PointCloud {
        timestamp: Some(stamp(m.header.stamp_sec, m.header.stamp_nanosec)),
        frame_id: m.header.frame_id.to_string(),
        pose: None,
        point_stride: layout.point_step,
        fields,
        data: data.into(),
    })
}

/// `sensor_msgs/msg/CameraInfo` in ROS 2's definition (its fields in lower case).
const CAMERA_INFO_ROS2: &str = "std_msgs/Header header\nuint32 height\nuint32 width\n\
string distortion_model\nfloat64[] d\nfloat64[9] k\nfloat64[9] r\nfloat64[12] p\n\
uint32 binning_x\nuint32 binning_y\nsensor_msgs/RegionOfInterest roi\n\
================================================================================\n\
MSG: std_msgs/Header\nbuiltin_interfaces/Time stamp\nstring frame_id\n\
================================================================================\n\
MSG: builtin_interfaces/Time\nint32 sec\nuint32 nanosec\n\
================================================================================\n\
MSG: sensor_msgs/RegionOfInterest\nuint32 x_offset\nuint32 y_offset\nuint32 height\n\
uint32 width\nbool do_rectify\n";

/// Decodes `sensor_msgs/CameraInfo` messages of either serialization.
pub struct CalibrationDecoder {
    ros1: MessageCodec,
    ros2: MessageCodec,
}

impl CalibrationDecoder {
    /// The decoder (the definitions are the project's own: they always parse).
    pub fn new() -> Result<Self, FrameError> {
        let codec = |name, dialect, def: &str, enc| {
            MessageCodec::new(name, dialect, def.as_bytes(), enc)
                .map_err(|e| FrameError::Calibration(e.to_string()))
        };
        Ok(CalibrationDecoder {
            ros1: codec(
                "sensor_msgs/CameraInfo",
                "ros1msg",
                crate::msgs::CAMERA_INFO.ros1().definition,
                "ros1",
            )?,
            ros2: codec(
                "sensor_msgs/msg/CameraInfo",
                "ros2msg",
                CAMERA_INFO_ROS2,
                "cdr",
            )?,
        })
    }

    /// The calibration of `c` as Foxglove shows it, for frames shrunk by `factor`: width,
    /// height and the focal lengths and principal point (K, P) divided by it.
    pub fn calibration(
        &self,
        c: &crate::camera_info::Calibration,
        factor: u32,
    ) -> Result<CameraCalibration, FrameError> {
        use crate::msgs::Wire;
        let (value, upper) = match c.wire {
            Wire::Ros1 => (self.ros1.decode(&c.data), true),
            Wire::Cdr => (self.ros2.decode(&c.data), false),
        };
        let v = value.map_err(|e| FrameError::Calibration(e.to_string()))?;
        let name = |n: &str| {
            if upper {
                n.to_uppercase()
            } else {
                n.to_string()
            }
        };
        let floats = |n: &str| -> Vec<f64> {
            match v.field(&name(n)) {
                Some(Value::Array(a)) => a.iter().filter_map(Value::as_f64).collect(),
                _ => Vec::new(),
            }
        };
        let uint = |n: &str| v.field(n).and_then(Value::as_f64).unwrap_or(0.0) as u32;
        let f = f64::from(factor.max(1));
        // Rows 0 and 1 of K (3x3) and P (3x4) hold fx, cx, fy, cy (and P's Tx, Ty): they scale
        // with the image; row 2 does not.
        let scale = |m: Vec<f64>, cols: usize| -> Vec<f64> {
            m.into_iter()
                .enumerate()
                .map(|(i, x)| if i < 2 * cols { x / f } else { x })
                .collect()
        };
        let frame_id = v
            .at("header.frame_id")
            .and_then(Value::as_str)
            .unwrap_or("")
            .to_string();
        Ok(CameraCalibration {
            timestamp: Some(stamp(c.stamp.0, c.stamp.1)),
            frame_id,
            width: uint("width") / factor.max(1),
            height: uint("height") / factor.max(1),
            distortion_model: v
                .field("distortion_model")
                .and_then(Value::as_str)
                .unwrap_or("")
                .to_string(),
            d: floats("d"),
            k: scale(floats("k"), 3),
            r: floats("r"),
            p: scale(floats("p"), 4),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::frame::OwnedPayload;
    use perturb_core::synthetic::{street_image, vlp32c_scan};

    #[test]
    fn a_frame_is_shrunk_by_its_factor_and_encoded_as_a_jpeg_of_that_size() {
        let p = OwnedPayload::Image {
            sec: 3,
            nanosec: 4,
            frame_id: "cam".into(),
            image: street_image(801, 503, 0),
        };
        let mut scratch = Scratch::new();
        let s = shrink(&p.payload(), 640, &mut scratch).unwrap();
        assert_eq!((s.image.width, s.image.height, s.factor), (400, 251, 2));
        let j = jpeg(&s, 80).unwrap();
        let back = perturb_core::formats::picture::decode(&j.data).unwrap();
        assert_eq!((back.width, back.height), (400, 251));
        assert_eq!((j.format.as_str(), j.frame_id.as_str()), ("jpeg", "cam"));
        let full = shrink(&p.payload(), 801, &mut scratch).unwrap();
        assert_eq!((full.image.width, full.image.height), (801, 503));
        assert_eq!(
            (factor(1920, 640), factor(1921, 640), factor(10, 640)),
            (3, 4, 1)
        );
    }

    #[test]
    fn a_cloud_keeps_its_fields_and_is_thinned_to_the_maximum() {
        let p = OwnedPayload::Cloud {
            sec: 1,
            nanosec: 0,
            frame_id: "velodyne".into(),
            cloud: vlp32c_scan(0),
        };
        let payload = p.payload();
        let Payload::Cloud(m) = &payload else {
            unreachable!()
        };
        let n = m.view().unwrap().len();
        let all = cloud(&payload, u32::MAX).unwrap();
        assert_eq!(all.data.len(), n * all.point_stride as usize);
        assert_eq!(all.fields[0].name, "x");
        let few = cloud(&payload, 1000).unwrap();
        let kept = few.data.len() / few.point_stride as usize;
        assert!(kept <= 1000 && kept > 500, "{kept} of {n}");
        assert!(matches!(
            shrink(&payload, 640, &mut Scratch::new()),
            Err(FrameError::WrongKind { .. })
        ));
    }
}
