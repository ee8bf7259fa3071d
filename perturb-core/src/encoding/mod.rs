//! The one table of `sensor_msgs/Image` encodings ([`ENCODINGS`]), and the conversions between
//! a frame in its own encoding and the 8-bit working view the camera perturbations run on.
//!
//! Every part of the project that needs to know about an encoding reads this table: the ROS
//! message views ([`crate::formats::ros::ImageMsg::view`]), the shared-memory frame header's check,
//! the daemon, `perturb apply` / `info` / `bench` and the Python package. Adding an encoding is
//! one row (and, for a new [`Layout`], its two conversions).
//!
//! A frame in an encoding that is not a working layout ([`PixelFormat`]: rgb8, bgr8, rgba8,
//! bgra8, mono8) is perturbed in three steps ([`Scratch`] holds the buffers, reused from frame to
//! frame):
//!
//! 1. **to the working view**: 16-bit samples are mapped to 8 bits (`v8 = round(v16 * 255 /
//!    max)`, `max = 2^bit_depth - 1`); a Bayer mosaic is demosaicked bilinearly (each missing
//!    colour the rounded mean of its two or four nearest samples of that colour, the image
//!    mirrored at its borders; OpenCV's `COLOR_Bayer*2BGR` gives the same bytes away from the
//!    one-pixel border); YUV 4:2:2 is converted with OpenCV's BT.601 limited-range integer
//!    arithmetic (the same bytes as `COLOR_YUV2RGB_UYVY` / `_YUY2`);
//! 2. the perturbation, on the working view;
//! 3. **back into the frame's own encoding, size and step** (row padding copied from the input):
//!    a Bayer site takes its own colour from the perturbed pixel; YUV and 16-bit samples take the
//!    input's value plus the change the perturbation made, in the encoding's units (see
//!    [`deep`] and [`yuv`]), so where the perturbation changed nothing the input's bytes come
//!    back exactly.
//!
//! Details, figures and the OpenCV comparison: `docs/encodings.md`.
//!
//! ```
//! use perturb_core::encoding::{EncodedView, Encoding};
//! let e = Encoding::find("bayer_rggb8").unwrap();
//! assert_eq!((e.bytes_per_pixel(), e.bits, e.working_format().ros_encoding()), (1, 8, "rgb8"));
//! let data = vec![0u8; 4 * 2];
//! let frame = EncodedView::new(&data, 4, 2, 4, e, false).unwrap();
//! assert_eq!(frame.working_geometry().to_string(), "4x2 rgb8");
//! assert!(EncodedView::new(&data, 3, 2, 4, e, false).unwrap_err().to_string().contains("width 3 is odd"));
//! ```

mod bayer;
pub mod deep;
pub mod yuv;

use crate::error::{Error, Result};
use crate::image::{Image, ImageGeometry, ImageView, ImageViewMut, PixelFormat};
use rayon::prelude::*;

pub use bayer::BayerPattern;
pub use yuv::YuvOrder;

/// How the samples of an encoding are laid out in a row.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Layout {
    /// Interleaved channels in the order of a working layout (rgb, bgr, rgba, bgra, mono).
    Direct(PixelFormat),
    /// A Bayer colour filter array: one sample per pixel, its colour given by the 2x2 tile.
    Bayer(BayerPattern),
    /// YUV 4:2:2: two pixels in four samples, the chroma shared by the pair.
    Yuv422(YuvOrder),
}

/// One row of the table: a `sensor_msgs/Image` encoding.
#[derive(Debug, PartialEq, Eq, Hash)]
pub struct Encoding {
    /// The name written in `sensor_msgs/Image.encoding` (as `sensor_msgs/image_encodings.h`
    /// spells it).
    pub name: &'static str,
    /// Other names of the same layout (OpenCV's `8UC3`, ROS 2's newer `uyvy`); a frame keeps the
    /// name it came with.
    pub aliases: &'static [&'static str],
    /// The sample layout.
    pub layout: Layout,
    /// Bits of a sample's container: 8 or 16.
    pub bits: u8,
    /// One line for `perturb info`, the docs and Python.
    pub summary: &'static str,
}

const fn row(
    name: &'static str,
    aliases: &'static [&'static str],
    layout: Layout,
    bits: u8,
    summary: &'static str,
) -> Encoding {
    Encoding {
        name,
        aliases,
        layout,
        bits,
        summary,
    }
}

use BayerPattern::{Bggr, Gbrg, Grbg, Rggb};
use Layout::{Bayer, Direct, Yuv422};
use PixelFormat::{Bgr8, Bgra8, Mono8, Rgb8, Rgba8};

/// Every encoding the project reads and writes, in a stable order (working layouts first).
#[rustfmt::skip]
pub static ENCODINGS: [Encoding; 20] = [
    row("rgb8", &[], Direct(Rgb8), 8, "red, green, blue"),
    row("bgr8", &["8UC3"], Direct(Bgr8), 8, "blue, green, red"),
    row("rgba8", &[], Direct(Rgba8), 8, "red, green, blue, alpha"),
    row("bgra8", &["8UC4"], Direct(Bgra8), 8, "blue, green, red, alpha"),
    row("mono8", &["8UC1"], Direct(Mono8), 8, "grey"),
    row("rgb16", &[], Direct(Rgb8), 16, "red, green, blue"),
    row("bgr16", &["16UC3"], Direct(Bgr8), 16, "blue, green, red"),
    row("rgba16", &[], Direct(Rgba8), 16, "red, green, blue, alpha"),
    row("bgra16", &["16UC4"], Direct(Bgra8), 16, "blue, green, red, alpha"),
    row("mono16", &["16UC1"], Direct(Mono8), 16, "grey"),
    row("bayer_rggb8", &[], Bayer(Rggb), 8, "Bayer mosaic, tile R G / G B"),
    row("bayer_bggr8", &[], Bayer(Bggr), 8, "Bayer mosaic, tile B G / G R"),
    row("bayer_gbrg8", &[], Bayer(Gbrg), 8, "Bayer mosaic, tile G B / R G"),
    row("bayer_grbg8", &[], Bayer(Grbg), 8, "Bayer mosaic, tile G R / B G"),
    row("bayer_rggb16", &[], Bayer(Rggb), 16, "Bayer mosaic, tile R G / G B"),
    row("bayer_bggr16", &[], Bayer(Bggr), 16, "Bayer mosaic, tile B G / G R"),
    row("bayer_gbrg16", &[], Bayer(Gbrg), 16, "Bayer mosaic, tile G B / R G"),
    row("bayer_grbg16", &[], Bayer(Grbg), 16, "Bayer mosaic, tile G R / B G"),
    row("yuv422", &["uyvy"], Yuv422(YuvOrder::Uyvy), 8, "YUV 4:2:2 UYVY (U0 Y0 V0 Y1), BT.601 limited range"),
    row("yuv422_yuy2", &["yuyv"], Yuv422(YuvOrder::Yuyv), 8, "YUV 4:2:2 YUYV (Y0 U0 Y1 V0), BT.601 limited range"),
];

/// The supported encodings' names, comma-separated (for error messages).
pub fn supported() -> String {
    ENCODINGS
        .iter()
        .map(|e| e.name)
        .collect::<Vec<_>>()
        .join(", ")
}

/// A field of an image, as named in errors.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum ImageField {
    /// `width`.
    Width,
    /// `height`.
    Height,
    /// `step`.
    Step,
    /// The length of `data`.
    Data,
    /// The significant bits of 16-bit samples (a stream or command-line setting).
    BitDepth,
}

impl std::fmt::Display for ImageField {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            ImageField::Width => "width",
            ImageField::Height => "height",
            ImageField::Step => "step",
            ImageField::Data => "data length",
            ImageField::BitDepth => "bit depth",
        })
    }
}

/// What is wrong with a field's value.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum FieldProblem {
    /// Odd where the encoding stores pixels in pairs or tiles; says why.
    Odd(&'static str),
    /// The step is shorter than a row of pixels.
    BelowRow {
        /// The width in pixels.
        width: u32,
        /// Bytes per pixel of the encoding.
        bytes_per_pixel: usize,
    },
    /// The data is shorter than the rows need.
    Short {
        /// Bytes needed.
        need: u64,
        /// Rows.
        height: u32,
        /// Bytes from row to row.
        step: u64,
    },
    /// A bit depth outside the range the encoding's samples can hold.
    OutOfRange {
        /// Smallest valid value.
        min: u8,
        /// Largest valid value.
        max: u8,
    },
}

impl std::fmt::Display for FieldProblem {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match *self {
            FieldProblem::Odd(why) => write!(f, "is odd: {why}"),
            FieldProblem::BelowRow {
                width,
                bytes_per_pixel,
            } => write!(
                f,
                "is smaller than width {width} x {bytes_per_pixel} bytes per pixel = {}",
                width as usize * bytes_per_pixel
            ),
            FieldProblem::Short { need, height, step } => write!(
                f,
                "is shorter than the {need} bytes of {height} rows of step {step}"
            ),
            FieldProblem::OutOfRange { min, max } => {
                write!(f, "is outside {min}..={max} for this encoding")
            }
        }
    }
}

impl Encoding {
    /// The encoding named `name` (or one of its aliases); a clear error naming it otherwise.
    pub fn find(name: &str) -> Result<&'static Encoding> {
        ENCODINGS
            .iter()
            .find(|e| e.name == name || e.aliases.contains(&name))
            .ok_or_else(|| Error::UnsupportedEncoding {
                encoding: name.to_string(),
            })
    }

    /// The 8-bit working layout of `format` (rgb8 for Rgb8, ...).
    pub fn of_format(format: PixelFormat) -> &'static Encoding {
        ENCODINGS
            .iter()
            .find(|e| e.layout == Direct(format) && e.bits == 8)
            .expect("every working layout has its 8-bit row")
    }

    /// Samples per pixel: the channels of a direct layout, 1 for Bayer, 2 for YUV 4:2:2 (four
    /// samples per pixel pair).
    pub const fn samples_per_pixel(&self) -> usize {
        match self.layout {
            Direct(f) => f.channels(),
            Bayer(_) => 1,
            Yuv422(_) => 2,
        }
    }

    /// Bytes per pixel (the minimum step is `width` times this).
    pub const fn bytes_per_pixel(&self) -> usize {
        self.samples_per_pixel() * (self.bits as usize / 8)
    }

    /// Pixel bytes of a row of `width` pixels (the minimum `step`).
    pub const fn row_bytes(&self, width: u32) -> usize {
        width as usize * self.bytes_per_pixel()
    }

    /// The 8-bit layout perturbations run on for frames of this encoding: a direct layout's own
    /// order, rgb8 for Bayer and YUV.
    pub const fn working_format(&self) -> PixelFormat {
        match self.layout {
            Direct(f) => f,
            Bayer(_) | Yuv422(_) => Rgb8,
        }
    }

    /// True when frames of this encoding are their own working view (the 8-bit direct layouts).
    pub const fn is_working(&self) -> bool {
        matches!(self.layout, Direct(_)) && self.bits == 8
    }

    /// The same layout with 8-bit samples (itself for 8-bit encodings).
    pub fn eight_bit(&'static self) -> &'static Encoding {
        if self.bits == 8 {
            return self;
        }
        ENCODINGS
            .iter()
            .find(|e| e.layout == self.layout && e.bits == 8)
            .expect("every 16-bit layout has its 8-bit row")
    }

    /// How many pixels a width and a height must be multiples of, and why.
    pub const fn tile(&self) -> (u32, u32, &'static str) {
        match self.layout {
            Direct(_) => (1, 1, ""),
            Bayer(_) => (2, 2, "a Bayer tile is 2x2 pixels"),
            Yuv422(_) => (2, 1, "YUV 4:2:2 stores pixels in pairs"),
        }
    }

    /// The OpenCV conversion code cv_bridge uses to turn this encoding into BGR (for the docs and
    /// the comparison with OpenCV), if it needs one.
    pub const fn opencv_to_bgr(&self) -> Option<&'static str> {
        match self.layout {
            Direct(_) => None,
            Bayer(p) => Some(p.opencv_to_bgr()),
            Yuv422(o) => Some(o.opencv_to_bgr()),
        }
    }

    fn field_error(&'static self, field: ImageField, value: u64, problem: FieldProblem) -> Error {
        Error::ImageField {
            encoding: self.name,
            field,
            value,
            problem,
        }
    }

    /// Checks that `width` x `height` pixels, rows `step` bytes apart, fit this encoding and `len`
    /// bytes of data (the last row needs no padding). Errors name the field and its value.
    pub fn check(&'static self, width: u32, height: u32, step: usize, len: usize) -> Result<()> {
        let (tw, th, why) = self.tile();
        if !width.is_multiple_of(tw) {
            return Err(self.field_error(ImageField::Width, width as u64, FieldProblem::Odd(why)));
        }
        if !height.is_multiple_of(th) {
            return Err(self.field_error(
                ImageField::Height,
                height as u64,
                FieldProblem::Odd(why),
            ));
        }
        let row = self.row_bytes(width);
        if step < row {
            return Err(self.field_error(
                ImageField::Step,
                step as u64,
                FieldProblem::BelowRow {
                    width,
                    bytes_per_pixel: self.bytes_per_pixel(),
                },
            ));
        }
        let need = image_bytes(height, step, row);
        if len < need {
            return Err(self.field_error(
                ImageField::Data,
                len as u64,
                FieldProblem::Short {
                    need: need as u64,
                    height,
                    step: step as u64,
                },
            ));
        }
        Ok(())
    }

    /// Checks a bit depth for this encoding's samples: 8 for 8-bit encodings, 9..=16 for 16-bit
    /// ones.
    pub fn check_bit_depth(&'static self, bit_depth: u8) -> Result<()> {
        let (min, max) = if self.bits == 8 { (8, 8) } else { (9, 16) };
        if !(min..=max).contains(&bit_depth) {
            return Err(self.field_error(
                ImageField::BitDepth,
                bit_depth as u64,
                FieldProblem::OutOfRange { min, max },
            ));
        }
        Ok(())
    }
}

impl std::fmt::Display for Encoding {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name)
    }
}

/// Bytes of `height` rows `step` apart, the last one `row` bytes long.
pub const fn image_bytes(height: u32, step: usize, row: usize) -> usize {
    if height == 0 {
        0
    } else {
        step * (height as usize - 1) + row
    }
}

/// A read-only view of a frame in its own encoding, over borrowed bytes (a shared-memory sample,
/// the data of a `sensor_msgs/Image`), checked against the table.
#[derive(Clone, Copy, Debug)]
pub struct EncodedView<'a> {
    data: &'a [u8],
    /// Pixels per row.
    pub width: u32,
    /// Rows.
    pub height: u32,
    /// Bytes from the start of one row to the start of the next.
    pub step: usize,
    /// The encoding.
    pub encoding: &'static Encoding,
    /// 16-bit samples are big-endian (`is_bigendian = 1`); ignored for 8-bit encodings.
    pub big_endian: bool,
    /// Significant bits of a 16-bit sample (values `0..2^bit_depth`, the low bits of the
    /// container); 8 for 8-bit encodings, 16 by default.
    pub bit_depth: u8,
}

impl<'a> EncodedView<'a> {
    /// Wraps `data`; fails, naming the field, when the width or height does not fit the
    /// encoding's tile, the step is shorter than a row or the data shorter than the rows.
    pub fn new(
        data: &'a [u8],
        width: u32,
        height: u32,
        step: usize,
        encoding: &'static Encoding,
        big_endian: bool,
    ) -> Result<Self> {
        encoding.check(width, height, step, data.len())?;
        Ok(EncodedView {
            data,
            width,
            height,
            step,
            encoding,
            big_endian,
            bit_depth: encoding.bits,
        })
    }

    /// The view of a `sensor_msgs/Image`'s fields: the encoding by name (or alias), ROS's
    /// `is_bigendian` byte, and `step * height` bytes of data as ROS requires (the last row's
    /// padding included).
    pub fn from_ros(
        data: &'a [u8],
        width: u32,
        height: u32,
        step: usize,
        encoding: &str,
        is_bigendian: u8,
    ) -> Result<Self> {
        let e = Encoding::find(encoding)?;
        let need = step as u64 * height as u64;
        if (data.len() as u64) < need {
            return Err(e.field_error(
                ImageField::Data,
                data.len() as u64,
                FieldProblem::Short {
                    need,
                    height,
                    step: step as u64,
                },
            ));
        }
        Self::new(data, width, height, step, e, is_bigendian != 0)
    }

    /// The same view with 16-bit samples read as `bit_depth`-bit values (9..=16; 8 for 8-bit
    /// encodings).
    pub fn with_bit_depth(mut self, bit_depth: u8) -> Result<Self> {
        self.encoding.check_bit_depth(bit_depth)?;
        self.bit_depth = bit_depth;
        Ok(self)
    }

    /// A view of a working-layout image.
    pub fn of_image(view: &ImageView<'a>) -> Self {
        EncodedView {
            data: view.data(),
            width: view.width,
            height: view.height,
            step: view.stride,
            encoding: Encoding::of_format(view.format),
            big_endian: false,
            bit_depth: 8,
        }
    }

    /// The bytes, padding included.
    pub fn data(&self) -> &'a [u8] {
        self.data
    }

    /// Bytes from the first pixel to the last row's last pixel.
    pub fn len(&self) -> usize {
        image_bytes(self.height, self.step, self.row_bytes())
    }

    /// True for an image without pixels.
    pub fn is_empty(&self) -> bool {
        self.width == 0 || self.height == 0
    }

    /// Pixel bytes of one row.
    pub fn row_bytes(&self) -> usize {
        self.encoding.row_bytes(self.width)
    }

    /// The pixel bytes of row `y` (without padding).
    pub fn row(&self, y: usize) -> &'a [u8] {
        let start = y * self.step;
        &self.data[start..start + self.row_bytes()]
    }

    /// The geometry of the working view (width, height, working layout).
    pub fn working_geometry(&self) -> ImageGeometry {
        ImageGeometry::new(self.width, self.height, self.encoding.working_format())
    }

    /// The frame as an [`ImageView`] when it is its own working view (8-bit direct layouts).
    pub fn as_working(&self) -> Option<ImageView<'a>> {
        if !self.encoding.is_working() {
            return None;
        }
        ImageView::new(
            self.data,
            self.width,
            self.height,
            self.step,
            self.encoding.working_format(),
        )
        .ok()
    }

    /// The `data` rows' byte planes: `row_bytes` bytes of each row, `step` apart.
    fn plane(&self) -> Plane<'a> {
        Plane {
            data: self.data,
            stride: self.step,
            len: self.row_bytes(),
            height: self.height as usize,
        }
    }
}

/// Rows of bytes `stride` apart, `len` bytes each.
#[derive(Clone, Copy)]
struct Plane<'a> {
    data: &'a [u8],
    stride: usize,
    len: usize,
    height: usize,
}

impl<'a> Plane<'a> {
    fn row(&self, y: usize) -> &'a [u8] {
        &self.data[y * self.stride..y * self.stride + self.len]
    }
}

/// Rows handed to one rayon task by the conversions.
const ROWS_PER_TASK: usize = 8;

/// Calls `f(y, row)` on every row of `out` (`len` pixel bytes of each row, rows `stride` apart),
/// in parallel on the current rayon pool.
fn par_rows_mut(
    out: &mut [u8],
    stride: usize,
    len: usize,
    height: usize,
    f: impl Fn(usize, &mut [u8]) + Send + Sync,
) {
    if height == 0 || len == 0 {
        return;
    }
    let end = image_bytes(height as u32, stride, len);
    out[..end]
        .par_chunks_mut(stride.max(1))
        .with_min_len(ROWS_PER_TASK)
        .enumerate()
        .for_each(|(y, row)| f(y, &mut row[..len]));
}

/// Copies the bytes that are not pixels from `input` to `out`: each row's padding, and what
/// follows the last row's pixels (its padding in a ROS message, `step * height` bytes long) as
/// far as both reach.
fn copy_padding(input: &EncodedView<'_>, out: &mut [u8]) {
    let (step, row) = (input.step, input.row_bytes());
    if step > row {
        for y in 0..(input.height as usize).saturating_sub(1) {
            let r = y * step + row..(y + 1) * step;
            out[r.clone()].copy_from_slice(&input.data[r]);
        }
    }
    let (end, tail) = (input.len(), input.data.len().min(out.len()));
    if tail > end {
        out[end..tail].copy_from_slice(&input.data[end..tail]);
    }
}

/// The buffers a frame in a non-working encoding is converted through: reused from frame to
/// frame (per stream in the daemon), grown only when a larger frame arrives.
#[derive(Default)]
pub struct Scratch {
    /// A 16-bit frame's samples mapped to 8 bits, same layout, tight rows.
    reduced: Vec<u8>,
    /// The perturbed 8-bit samples of a 16-bit non-direct frame (same layout as `reduced`).
    reduced_out: Vec<u8>,
    /// The working view the perturbation reads.
    work_in: Option<Image>,
    /// The working view the perturbation writes.
    work_out: Option<Image>,
}

impl std::fmt::Debug for Scratch {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let g = |i: &Option<Image>| i.as_ref().map(|i| i.geometry().to_string());
        f.debug_struct("Scratch")
            .field("reduced_bytes", &self.reduced.len())
            .field("reduced_out_bytes", &self.reduced_out.len())
            .field("work_in", &g(&self.work_in))
            .field("work_out", &g(&self.work_out))
            .finish()
    }
}

/// An image of geometry `g` in `slot`, reused when it has that geometry.
fn image_in(slot: &mut Option<Image>, g: ImageGeometry) -> &mut Image {
    if slot.as_ref().map(|i| i.geometry()) != Some(g) {
        *slot = Some(Image::with_geometry(g));
    }
    slot.as_mut().expect("set above")
}

impl Scratch {
    /// Empty buffers; the first frame sizes them.
    pub fn new() -> Self {
        Self::default()
    }

    /// The 8-bit frame a conversion starts from: `input` itself, or for 16-bit encodings its
    /// samples mapped to 8 bits (into `reduced`).
    fn eight_bit<'s>(reduced: &'s mut Vec<u8>, input: &EncodedView<'s>) -> EncodedView<'s> {
        if input.encoding.bits == 8 {
            return *input;
        }
        let e8 = input.encoding.eight_bit();
        let row = e8.row_bytes(input.width);
        reduced.resize(row * input.height as usize, 0);
        deep::reduce(input, reduced, row);
        EncodedView {
            data: reduced,
            width: input.width,
            height: input.height,
            step: row,
            encoding: e8,
            big_endian: false,
            bit_depth: 8,
        }
    }

    /// Converts `input` into the working view and returns it: the input's own bytes for the
    /// working layouts, else the view in this scratch. [`Scratch::from_working`] needs the
    /// conversion of the same frame.
    pub fn to_working<'s>(&'s mut self, input: &EncodedView<'s>) -> ImageView<'s> {
        if let Some(v) = input.as_working() {
            return v;
        }
        let Scratch {
            reduced, work_in, ..
        } = self;
        let e8 = Self::eight_bit(reduced, input);
        if let Some(v) = e8.as_working() {
            return v;
        }
        let work = image_in(work_in, input.working_geometry());
        let src = e8.plane();
        let mut view = work.view_mut();
        match input.encoding.layout {
            Bayer(p) => bayer::demosaic(&src, p, &mut view),
            Yuv422(o) => yuv::to_rgb(&src, o, &mut view),
            Direct(_) => unreachable!("direct layouts are their own working view at 8 bits"),
        }
        work.view()
    }

    /// Writes the perturbed working view `working` back into `out` in `input`'s encoding, size
    /// and step (the bytes between rows copied from `input`). `self` must hold the conversion
    /// of `input` by [`Scratch::to_working`] (it reads the unperturbed working view from it).
    pub fn from_working(
        &mut self,
        input: &EncodedView<'_>,
        working: &ImageView<'_>,
        out: &mut [u8],
    ) -> Result<()> {
        self.check_output(input, working, out)?;
        let n = input.len();
        let Scratch {
            reduced,
            reduced_out,
            work_in,
            ..
        } = self;
        if input.encoding.is_working() {
            let mut o = ImageViewMut::new(
                &mut out[..n],
                input.width,
                input.height,
                input.step,
                working.format,
            )?;
            o.copy_from(working)?;
        } else {
            let before = || {
                work_in
                    .as_ref()
                    .map(|i| i.view())
                    .filter(|v| v.geometry() == working.geometry())
                    .ok_or_else(|| {
                        Error::image("from_working without the frame's to_working".to_string())
                    })
            };
            if input.encoding.bits == 8 {
                write_eight_bit(input, before()?, working, out);
            } else {
                let e8 = input.encoding.eight_bit();
                let row = e8.row_bytes(input.width);
                if reduced.len() != row * input.height as usize {
                    return Err(Error::image(
                        "from_working without the frame's to_working".to_string(),
                    ));
                }
                let v8 = EncodedView {
                    data: reduced,
                    width: input.width,
                    height: input.height,
                    step: row,
                    encoding: e8,
                    big_endian: false,
                    bit_depth: 8,
                };
                let p8: &[u8] = if e8.is_working() {
                    // The perturbation's output is the 8-bit frame itself (tight rows).
                    if working.stride != row {
                        return Err(Error::image(format!(
                            "working view stride {} is not the tight {row}",
                            working.stride
                        )));
                    }
                    working.data()
                } else {
                    reduced_out.resize(row * input.height as usize, 0);
                    write_eight_bit(&v8, before()?, working, reduced_out);
                    reduced_out
                };
                deep::write_back(input, v8.data, p8, row, out);
            }
        }
        copy_padding(input, out);
        Ok(())
    }

    fn check_output(
        &self,
        input: &EncodedView<'_>,
        working: &ImageView<'_>,
        out: &[u8],
    ) -> Result<()> {
        if working.geometry() != input.working_geometry() {
            return Err(Error::GeometryMismatch {
                expected: input.working_geometry().to_string(),
                found: format!("working view {}", working.geometry()),
            });
        }
        if out.len() < input.len() {
            return Err(Error::OutputTooSmall {
                needed: input.len(),
                available: out.len(),
            });
        }
        Ok(())
    }

    /// Converts `input` to the working view, runs `perturb(working_in, working_out)` and writes
    /// the result back into `out` (at least [`EncodedView::len`] bytes) in `input`'s encoding,
    /// size and step, the bytes between rows copied from `input`. A working-layout frame is
    /// perturbed straight into `out`.
    pub fn perturb(
        &mut self,
        input: &EncodedView<'_>,
        out: &mut [u8],
        perturb: impl FnOnce(&ImageView<'_>, &mut ImageViewMut<'_>) -> Result<()>,
    ) -> Result<()> {
        let n = input.len();
        if out.len() < n {
            return Err(Error::OutputTooSmall {
                needed: n,
                available: out.len(),
            });
        }
        if let Some(v) = input.as_working() {
            let mut o = ImageViewMut::new(&mut out[..n], v.width, v.height, v.stride, v.format)?;
            perturb(&v, &mut o)?;
            copy_padding(input, out);
            return Ok(());
        }
        let mut work_out = self.work_out.take();
        let result = (|| {
            let wo = image_in(&mut work_out, input.working_geometry());
            let wi = self.to_working(input);
            perturb(&wi, &mut wo.view_mut())?;
            self.from_working(input, &wo.view(), out)
        })();
        self.work_out = work_out;
        result
    }
}

/// A frame of `encoding` (rows `step` bytes apart, `step * height` bytes, padding zero) holding
/// the colours of `image` (any working layout): each encoding's write-back applied to a black
/// frame, so a Bayer site takes its own colour, YUV the BT.601 limited-range values (the pair's
/// mean chroma) and 16-bit samples `round(v8 * max / 255)` (`v8 * 257` at 16 bits). Makes test
/// and benchmark frames from real images (mosaicking, subsampling).
pub fn from_image(
    image: &ImageView<'_>,
    encoding: &'static Encoding,
    step: usize,
    big_endian: bool,
) -> Result<Vec<u8>> {
    let (w, h) = (image.width, image.height);
    let mut black = vec![0u8; step * h as usize];
    if let Yuv422(o) = encoding.layout {
        let [y0, u, y1, v] = o.offsets();
        let row = encoding.row_bytes(w);
        for r in black.chunks_mut(step.max(1)) {
            let n = row.min(r.len());
            for q in r[..n].chunks_exact_mut(4) {
                (q[y0], q[u], q[y1], q[v]) = (16, 128, 16, 128);
            }
        }
    }
    let input = EncodedView::new(&black, w, h, step, encoding, big_endian)?;
    let colours = if image.format == encoding.working_format() {
        Image::from_view(image)
    } else {
        Image::from_view(image).convert(encoding.working_format())
    };
    let mut out = vec![0u8; black.len()];
    let mut scratch = Scratch::new();
    scratch.to_working(&input);
    scratch.from_working(&input, &colours.view(), &mut out)?;
    Ok(out)
}

/// The 8-bit write-back of a non-direct layout: `after` (the perturbed working view) into `out`
/// (tight or padded rows `input.step` apart), `before` being the unperturbed working view.
fn write_eight_bit(
    input: &EncodedView<'_>,
    before: ImageView<'_>,
    after: &ImageView<'_>,
    out: &mut [u8],
) {
    let src = input.plane();
    match input.encoding.layout {
        Bayer(p) => bayer::mosaic(after, p, out, input.step),
        Yuv422(o) => yuv::write_back(&src, o, &before, after, out, input.step),
        Direct(_) => unreachable!("direct 8-bit layouts are written by the perturbation"),
    }
}

#[cfg(test)]
mod tests;
