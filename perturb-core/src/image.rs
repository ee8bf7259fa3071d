//! Image views over borrowed bytes, and an owned image.
//!
//! An image is `height` rows of `width` pixels, each row `stride` bytes apart (the ROS `step`),
//! in one of the [`PixelFormat`]s. The same view type wraps a shared-memory sample, a decoded PNG or
//! the data of a `sensor_msgs/Image` in a bag, so one perturbation implementation serves them all.
//!
//! ```
//! use perturb_core::image::{Image, ImageView, PixelFormat};
//! let bytes = vec![0u8; 4 * 3 + 2]; // 2 rows of 2 rgb8 pixels, stride 7 (one byte of padding)
//! let view = ImageView::new(&bytes, 2, 2, 7, PixelFormat::Rgb8).unwrap();
//! assert_eq!(view.row(1).len(), 6);
//! let owned = Image::from_view(&view);
//! assert_eq!(owned.stride, 6);
//! ```

use crate::error::{Error, Result};

/// The pixel layouts the project handles, named as in `sensor_msgs/Image.encoding`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum PixelFormat {
    /// Red, green, blue; one byte each.
    Rgb8,
    /// Blue, green, red; one byte each.
    Bgr8,
    /// Red, green, blue, alpha.
    Rgba8,
    /// Blue, green, red, alpha.
    Bgra8,
    /// One grey byte.
    Mono8,
}

impl PixelFormat {
    /// Every format, in a stable order.
    pub const ALL: [PixelFormat; 5] = [
        PixelFormat::Rgb8,
        PixelFormat::Bgr8,
        PixelFormat::Rgba8,
        PixelFormat::Bgra8,
        PixelFormat::Mono8,
    ];

    /// Bytes per pixel.
    pub const fn channels(self) -> usize {
        match self {
            PixelFormat::Rgb8 | PixelFormat::Bgr8 => 3,
            PixelFormat::Rgba8 | PixelFormat::Bgra8 => 4,
            PixelFormat::Mono8 => 1,
        }
    }

    /// Byte offsets of red, green and blue within a pixel; all three are 0 for mono8.
    pub const fn rgb_offsets(self) -> [usize; 3] {
        match self {
            PixelFormat::Rgb8 | PixelFormat::Rgba8 => [0, 1, 2],
            PixelFormat::Bgr8 | PixelFormat::Bgra8 => [2, 1, 0],
            PixelFormat::Mono8 => [0, 0, 0],
        }
    }

    /// Offset of the alpha byte, if the format has one.
    pub const fn alpha_offset(self) -> Option<usize> {
        match self {
            PixelFormat::Rgba8 | PixelFormat::Bgra8 => Some(3),
            _ => None,
        }
    }

    /// Number of colour channels (3, or 1 for mono8); alpha is not a colour channel.
    pub const fn color_channels(self) -> usize {
        match self {
            PixelFormat::Mono8 => 1,
            _ => 3,
        }
    }

    /// True for mono8.
    pub const fn is_mono(self) -> bool {
        matches!(self, PixelFormat::Mono8)
    }

    /// The `sensor_msgs/Image` encoding string.
    pub const fn ros_encoding(self) -> &'static str {
        match self {
            PixelFormat::Rgb8 => "rgb8",
            PixelFormat::Bgr8 => "bgr8",
            PixelFormat::Rgba8 => "rgba8",
            PixelFormat::Bgra8 => "bgra8",
            PixelFormat::Mono8 => "mono8",
        }
    }

    /// Parses a `sensor_msgs/Image` encoding string through the encoding table
    /// ([`crate::encoding::ENCODINGS`]; `8UC1`, `8UC3` and `8UC4` are mono8, bgr8 and bgra8, the
    /// OpenCV defaults). Encodings of the table that are not 8-bit working layouts (Bayer, YUV,
    /// 16-bit) are an error here: frames in them go through [`crate::encoding::EncodedView`].
    pub fn from_ros_encoding(encoding: &str) -> Result<Self> {
        let e = crate::encoding::Encoding::find(encoding)?;
        if e.is_working() {
            return Ok(e.working_format());
        }
        Err(Error::image(format!(
            "`{encoding}` is not one of the 8-bit working layouts (rgb8, bgr8, rgba8, bgra8, mono8): \
             read it as a perturb_core::encoding::EncodedView, which converts it"
        )))
    }
}

impl std::fmt::Display for PixelFormat {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.ros_encoding())
    }
}

impl std::str::FromStr for PixelFormat {
    type Err = Error;
    fn from_str(s: &str) -> Result<Self> {
        Self::from_ros_encoding(s)
    }
}

/// Width, height and pixel format: what a camera perturbation is configured for.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct ImageGeometry {
    /// Pixels per row.
    pub width: u32,
    /// Rows.
    pub height: u32,
    /// Pixel format.
    pub format: PixelFormat,
}

impl ImageGeometry {
    /// A geometry.
    pub fn new(width: u32, height: u32, format: PixelFormat) -> Self {
        ImageGeometry {
            width,
            height,
            format,
        }
    }

    /// Bytes of pixel data in one row (without padding).
    pub fn row_bytes(&self) -> usize {
        self.width as usize * self.format.channels()
    }

    /// Number of pixels.
    pub fn pixels(&self) -> usize {
        self.width as usize * self.height as usize
    }
}

impl std::fmt::Display for ImageGeometry {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}x{} {}", self.width, self.height, self.format)
    }
}

fn check_layout(
    len: usize,
    width: u32,
    height: u32,
    stride: usize,
    format: PixelFormat,
) -> Result<()> {
    let row = width as usize * format.channels();
    if stride < row {
        return Err(Error::image(format!(
            "row stride {stride} is smaller than width {width} x {} bytes per pixel = {row}",
            format.channels()
        )));
    }
    let needed = if height == 0 {
        0
    } else {
        stride * (height as usize - 1) + row
    };
    if len < needed {
        return Err(Error::image(format!(
            "buffer of {len} bytes is too small for {width}x{height} {format} with stride {stride} ({needed} bytes needed)"
        )));
    }
    Ok(())
}

/// A read-only view of an image in borrowed bytes.
#[derive(Clone, Copy, Debug)]
pub struct ImageView<'a> {
    data: &'a [u8],
    /// Pixels per row.
    pub width: u32,
    /// Rows.
    pub height: u32,
    /// Bytes from the start of one row to the start of the next.
    pub stride: usize,
    /// Pixel format.
    pub format: PixelFormat,
}

impl<'a> ImageView<'a> {
    /// Wraps `data`; fails if the stride is shorter than a row or the buffer shorter than the image.
    pub fn new(
        data: &'a [u8],
        width: u32,
        height: u32,
        stride: usize,
        format: PixelFormat,
    ) -> Result<Self> {
        check_layout(data.len(), width, height, stride, format)?;
        Ok(ImageView {
            data,
            width,
            height,
            stride,
            format,
        })
    }

    /// The geometry (width, height, format).
    pub fn geometry(&self) -> ImageGeometry {
        ImageGeometry::new(self.width, self.height, self.format)
    }

    /// The pixel bytes of row `y` (without padding).
    #[inline]
    pub fn row(&self, y: usize) -> &'a [u8] {
        let start = y * self.stride;
        &self.data[start..start + self.width as usize * self.format.channels()]
    }

    /// The underlying bytes, padding included.
    pub fn data(&self) -> &'a [u8] {
        self.data
    }

    /// Bytes per pixel.
    pub fn channels(&self) -> usize {
        self.format.channels()
    }
}

/// A writable view of an image in borrowed bytes (for example a loaned shared-memory sample).
#[derive(Debug)]
pub struct ImageViewMut<'a> {
    data: &'a mut [u8],
    /// Pixels per row.
    pub width: u32,
    /// Rows.
    pub height: u32,
    /// Bytes from the start of one row to the start of the next.
    pub stride: usize,
    /// Pixel format.
    pub format: PixelFormat,
}

impl<'a> ImageViewMut<'a> {
    /// Wraps `data`; fails if the stride is shorter than a row or the buffer shorter than the image.
    pub fn new(
        data: &'a mut [u8],
        width: u32,
        height: u32,
        stride: usize,
        format: PixelFormat,
    ) -> Result<Self> {
        check_layout(data.len(), width, height, stride, format)?;
        Ok(ImageViewMut {
            data,
            width,
            height,
            stride,
            format,
        })
    }

    /// The geometry (width, height, format).
    pub fn geometry(&self) -> ImageGeometry {
        ImageGeometry::new(self.width, self.height, self.format)
    }

    /// The pixel bytes of row `y` (without padding).
    #[inline]
    pub fn row_mut(&mut self, y: usize) -> &mut [u8] {
        let start = y * self.stride;
        let len = self.width as usize * self.format.channels();
        &mut self.data[start..start + len]
    }

    /// The pixel bytes of row `y` (without padding).
    #[inline]
    pub fn row(&self, y: usize) -> &[u8] {
        let start = y * self.stride;
        &self.data[start..start + self.width as usize * self.format.channels()]
    }

    /// The underlying bytes, padding included (for writers that go row by row themselves).
    pub fn data_mut(&mut self) -> &mut [u8] {
        self.data
    }

    /// A read-only view of the same bytes.
    pub fn as_view(&self) -> ImageView<'_> {
        ImageView {
            data: self.data,
            width: self.width,
            height: self.height,
            stride: self.stride,
            format: self.format,
        }
    }

    /// The rows as mutable slices (pixel bytes only), for parallel processing.
    pub fn rows_mut(&mut self) -> Vec<&mut [u8]> {
        let row_len = self.width as usize * self.format.channels();
        if self.height == 0 {
            return Vec::new();
        }
        let mut rows = Vec::with_capacity(self.height as usize);
        let mut rest: &mut [u8] = self.data;
        for y in 0..self.height as usize {
            if y + 1 < self.height as usize {
                let (head, tail) = rest.split_at_mut(self.stride);
                rows.push(&mut head[..row_len]);
                rest = tail;
            } else {
                rows.push(&mut rest[..row_len]);
                break;
            }
        }
        rows
    }

    /// Copies `src` (same width, height and format, any stride) into this view.
    pub fn copy_from(&mut self, src: &ImageView<'_>) -> Result<()> {
        if src.geometry() != self.geometry() {
            return Err(Error::GeometryMismatch {
                expected: self.geometry().to_string(),
                found: src.geometry().to_string(),
            });
        }
        for y in 0..self.height as usize {
            self.row_mut(y).copy_from_slice(src.row(y));
        }
        Ok(())
    }
}

/// An owned image with a tight or padded stride.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Image {
    /// The bytes, `stride * height` long.
    pub data: Vec<u8>,
    /// Pixels per row.
    pub width: u32,
    /// Rows.
    pub height: u32,
    /// Bytes from the start of one row to the start of the next.
    pub stride: usize,
    /// Pixel format.
    pub format: PixelFormat,
}

impl Image {
    /// A black image with a tight stride.
    pub fn new(width: u32, height: u32, format: PixelFormat) -> Self {
        let stride = width as usize * format.channels();
        Image {
            data: vec![0; stride * height as usize],
            width,
            height,
            stride,
            format,
        }
    }

    /// A black image of the given geometry with a tight stride.
    pub fn with_geometry(g: ImageGeometry) -> Self {
        Self::new(g.width, g.height, g.format)
    }

    /// Wraps owned bytes, checking the layout.
    pub fn from_vec(
        data: Vec<u8>,
        width: u32,
        height: u32,
        stride: usize,
        format: PixelFormat,
    ) -> Result<Self> {
        check_layout(data.len(), width, height, stride, format)?;
        Ok(Image {
            data,
            width,
            height,
            stride,
            format,
        })
    }

    /// A tightly packed copy of a view.
    pub fn from_view(v: &ImageView<'_>) -> Self {
        let mut img = Image::new(v.width, v.height, v.format);
        img.view_mut()
            .copy_from(v)
            .expect("same geometry by construction");
        img
    }

    /// The geometry.
    pub fn geometry(&self) -> ImageGeometry {
        ImageGeometry::new(self.width, self.height, self.format)
    }

    /// A read-only view.
    pub fn view(&self) -> ImageView<'_> {
        ImageView {
            data: &self.data,
            width: self.width,
            height: self.height,
            stride: self.stride,
            format: self.format,
        }
    }

    /// A writable view.
    pub fn view_mut(&mut self) -> ImageViewMut<'_> {
        ImageViewMut {
            data: &mut self.data,
            width: self.width,
            height: self.height,
            stride: self.stride,
            format: self.format,
        }
    }

    /// The same pixels converted to another format (colour to grey by BT.601 luma, grey to colour by
    /// replication, alpha 255 where it appears).
    pub fn convert(&self, format: PixelFormat) -> Image {
        let mut out = Image::new(self.width, self.height, format);
        let (si, so) = (self.format.rgb_offsets(), format.rgb_offsets());
        let (ci, co) = (self.format.channels(), format.channels());
        for y in 0..self.height as usize {
            let src = self.view().row(y);
            let mut ov = out.view_mut();
            let dst = ov.row_mut(y);
            for (s, d) in src.chunks_exact(ci).zip(dst.chunks_exact_mut(co)) {
                let (r, g, b) = (s[si[0]], s[si[1]], s[si[2]]);
                if format.is_mono() {
                    d[0] = luma(r, g, b);
                } else {
                    d[so[0]] = r;
                    d[so[1]] = g;
                    d[so[2]] = b;
                    if let Some(a) = format.alpha_offset() {
                        d[a] = self.format.alpha_offset().map_or(255, |ai| s[ai]);
                    }
                }
            }
        }
        out
    }
}

/// BT.601 luma of an RGB triple, rounded: 0.299 R + 0.587 G + 0.114 B.
#[inline]
pub fn luma(r: u8, g: u8, b: u8) -> u8 {
    ((r as u32 * 19595 + g as u32 * 38470 + b as u32 * 7471 + 32768) >> 16) as u8
}

/// [`luma`] of every pixel of a row of `format` into `dst`, one byte per pixel (mono8 is copied).
/// Each colour format gets its own loop with the channel positions known at compile time, which
/// lets the compiler vectorise it.
pub fn luma_row(src: &[u8], format: PixelFormat, dst: &mut [u8]) {
    fn each<const C: usize, const R: usize, const B: usize>(src: &[u8], dst: &mut [u8]) {
        for (d, p) in dst.iter_mut().zip(src.chunks_exact(C)) {
            *d = luma(p[R], p[1], p[B]);
        }
    }
    match format {
        PixelFormat::Rgb8 => each::<3, 0, 2>(src, dst),
        PixelFormat::Bgr8 => each::<3, 2, 0>(src, dst),
        PixelFormat::Rgba8 => each::<4, 0, 2>(src, dst),
        PixelFormat::Bgra8 => each::<4, 2, 0>(src, dst),
        PixelFormat::Mono8 => {
            let n = dst.len().min(src.len());
            dst[..n].copy_from_slice(&src[..n]);
        }
    }
}

/// Bilinear resize (pixel centres aligned, as OpenCV's INTER_LINEAR), any format; alpha is
/// resampled like the colour channels. Used to bring real frames to benchmark sizes.
pub fn resize_bilinear(src: &ImageView<'_>, width: u32, height: u32) -> Image {
    let mut out = Image::new(width, height, src.format);
    if src.width == 0 || src.height == 0 || width == 0 || height == 0 {
        return out;
    }
    let c = src.format.channels();
    let sx = src.width as f32 / width as f32;
    let sy = src.height as f32 / height as f32;
    let xmap: Vec<(usize, usize, f32)> = (0..width)
        .map(|x| {
            let fx = ((x as f32 + 0.5) * sx - 0.5).max(0.0);
            let x0 = (fx as usize).min(src.width as usize - 1);
            let x1 = (x0 + 1).min(src.width as usize - 1);
            (x0, x1, fx - x0 as f32)
        })
        .collect();
    let stride = out.stride;
    for (y, row) in out.data.chunks_exact_mut(stride).enumerate() {
        let fy = ((y as f32 + 0.5) * sy - 0.5).max(0.0);
        let y0 = (fy as usize).min(src.height as usize - 1);
        let y1 = (y0 + 1).min(src.height as usize - 1);
        let wy = fy - y0 as f32;
        let (r0, r1) = (src.row(y0), src.row(y1));
        for (x, &(x0, x1, wx)) in xmap.iter().enumerate() {
            for ch in 0..c {
                let a = r0[x0 * c + ch] as f32 * (1.0 - wx) + r0[x1 * c + ch] as f32 * wx;
                let b = r1[x0 * c + ch] as f32 * (1.0 - wx) + r1[x1 * c + ch] as f32 * wx;
                row[x * c + ch] = (a * (1.0 - wy) + b * wy + 0.5) as u8;
            }
        }
    }
    out
}

/// A one-row RGB test image of `w` pixels whose bytes step by `step` (mod 256), so that every
/// channel differs from its neighbours and format conversions show.
#[cfg(test)]
pub(crate) fn rgb_test_row(w: u32, step: usize) -> Image {
    let n = w as usize * 3;
    Image::from_vec(
        (0..n).map(|i| (i * step % 256) as u8).collect(),
        w,
        1,
        n,
        PixelFormat::Rgb8,
    )
    .expect("a valid one-row image")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rejects_short_stride_and_short_buffer() {
        let data = vec![0u8; 10];
        assert!(ImageView::new(&data, 4, 1, 11, PixelFormat::Rgb8).is_err());
        assert!(ImageView::new(&data, 2, 2, 5, PixelFormat::Rgb8).is_err());
        assert!(ImageView::new(&data, 2, 1, 6, PixelFormat::Rgb8).is_ok());
        // The last row needs no padding.
        assert!(ImageView::new(&data, 1, 2, 7, PixelFormat::Rgb8).is_ok());
        assert!(ImageView::new(&[], 0, 0, 0, PixelFormat::Mono8).is_ok());
    }

    #[test]
    fn encodings_round_trip() {
        for f in PixelFormat::ALL {
            assert_eq!(PixelFormat::from_ros_encoding(f.ros_encoding()).unwrap(), f);
        }
        let err = PixelFormat::from_ros_encoding("nv21").unwrap_err();
        assert!(err.to_string().contains("nv21"));
        let err = PixelFormat::from_ros_encoding("yuv422").unwrap_err();
        assert!(err.to_string().contains("EncodedView"), "{err}");
        assert_eq!(
            PixelFormat::from_ros_encoding("8UC3").unwrap(),
            PixelFormat::Bgr8
        );
    }

    #[test]
    fn convert_keeps_colours() {
        let mut img = Image::new(2, 1, PixelFormat::Rgb8);
        img.data.copy_from_slice(&[10, 20, 30, 200, 100, 0]);
        let bgra = img.convert(PixelFormat::Bgra8);
        assert_eq!(bgra.data, vec![30, 20, 10, 255, 0, 100, 200, 255]);
        assert_eq!(bgra.convert(PixelFormat::Rgb8), img);
        assert_eq!(luma(255, 255, 255), 255);
    }

    #[test]
    fn luma_row_matches_luma_in_every_format() {
        let rgb = rgb_test_row(7, 37);
        let want: Vec<u8> = rgb
            .data
            .chunks_exact(3)
            .map(|p| luma(p[0], p[1], p[2]))
            .collect();
        for format in PixelFormat::ALL {
            let img = rgb.convert(format);
            let mut got = vec![0u8; 7];
            luma_row(&img.data, format, &mut got);
            let expected = if format.is_mono() { &img.data } else { &want };
            assert_eq!(&got, expected, "{format:?}");
        }
    }

    #[test]
    fn rows_mut_split_padded_rows() {
        let mut data = vec![0u8; 3 * 8];
        let mut v = ImageViewMut::new(&mut data, 2, 3, 8, PixelFormat::Rgb8).unwrap();
        for (y, row) in v.rows_mut().into_iter().enumerate() {
            assert_eq!(row.len(), 6);
            row.fill(y as u8 + 1);
        }
        assert_eq!(&data[..8], &[1, 1, 1, 1, 1, 1, 0, 0]);
        assert_eq!(&data[16..22], &[3; 6]);
    }
}
