//! PNG and JPEG images through the `image` crate (decode and encode only).

use crate::error::{Error, Result};
use crate::image::{Image, ImageView, PixelFormat};
use ::image::{DynamicImage, ImageFormat};

/// Decodes a PNG or JPEG into rgb8, rgba8 or mono8 (16-bit and palette images are converted to
/// 8 bits; grey with alpha becomes rgba8).
pub fn decode(bytes: &[u8]) -> Result<Image> {
    let fmt = ::image::guess_format(bytes)
        .map_err(|e| Error::malformed("image", format!("not a PNG or JPEG: {e}")))?;
    let name = match fmt {
        ImageFormat::Png => "PNG",
        ImageFormat::Jpeg => "JPEG",
        _ => {
            return Err(Error::malformed(
                "image",
                format!("{fmt:?} is not supported (PNG and JPEG are)"),
            ));
        }
    };
    let img = ::image::load_from_memory_with_format(bytes, fmt)
        .map_err(|e| Error::malformed(name, e.to_string()))?;
    Ok(from_dynamic(img))
}

fn from_dynamic(img: DynamicImage) -> Image {
    let (w, h) = (img.width(), img.height());
    match img {
        DynamicImage::ImageLuma8(b) => {
            Image::from_vec(b.into_raw(), w, h, w as usize, PixelFormat::Mono8)
        }
        DynamicImage::ImageRgb8(b) => {
            Image::from_vec(b.into_raw(), w, h, w as usize * 3, PixelFormat::Rgb8)
        }
        DynamicImage::ImageRgba8(b) => {
            Image::from_vec(b.into_raw(), w, h, w as usize * 4, PixelFormat::Rgba8)
        }
        DynamicImage::ImageLuma16(_) => {
            let b = img.to_luma8();
            Image::from_vec(b.into_raw(), w, h, w as usize, PixelFormat::Mono8)
        }
        other if other.color().has_alpha() => {
            let b = other.to_rgba8();
            Image::from_vec(b.into_raw(), w, h, w as usize * 4, PixelFormat::Rgba8)
        }
        other => {
            let b = other.to_rgb8();
            Image::from_vec(b.into_raw(), w, h, w as usize * 3, PixelFormat::Rgb8)
        }
    }
    .expect("tight buffers from the decoder")
}

/// Tightly packed rgb8/rgba8/mono8 bytes for the encoder (bgr formats are swapped to rgb).
fn for_encoder(view: &ImageView<'_>, allow_alpha: bool) -> (Vec<u8>, ::image::ExtendedColorType) {
    use ::image::ExtendedColorType as C;
    let target = match view.format {
        PixelFormat::Mono8 => PixelFormat::Mono8,
        PixelFormat::Rgb8 | PixelFormat::Bgr8 => PixelFormat::Rgb8,
        PixelFormat::Rgba8 | PixelFormat::Bgra8 if allow_alpha => PixelFormat::Rgba8,
        _ => PixelFormat::Rgb8,
    };
    let img = Image::from_view(view).convert(target);
    let color = match target {
        PixelFormat::Mono8 => C::L8,
        PixelFormat::Rgba8 => C::Rgba8,
        _ => C::Rgb8,
    };
    (img.data, color)
}

/// Encodes as PNG (lossless; bgr is stored as rgb, alpha kept).
pub fn encode_png(view: &ImageView<'_>) -> Result<Vec<u8>> {
    use ::image::ImageEncoder;
    let (data, color) = for_encoder(view, true);
    let mut out = Vec::new();
    ::image::codecs::png::PngEncoder::new(&mut out)
        .write_image(&data, view.width, view.height, color)
        .map_err(|e| Error::malformed("PNG", format!("encoding failed: {e}")))?;
    Ok(out)
}

/// Encodes as JPEG at `quality` (1..=100; alpha is dropped, as JPEG has none).
pub fn encode_jpeg(view: &ImageView<'_>, quality: u8) -> Result<Vec<u8>> {
    use ::image::ImageEncoder;
    let (data, color) = for_encoder(view, false);
    let mut out = Vec::new();
    ::image::codecs::jpeg::JpegEncoder::new_with_quality(&mut out, quality.clamp(1, 100))
        .write_image(&data, view.width, view.height, color)
        .map_err(|e| Error::malformed("JPEG", format!("encoding failed: {e}")))?;
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn png_round_trip_is_lossless_and_bgr_is_swapped() {
        let mut img = Image::new(3, 2, PixelFormat::Bgr8);
        for (i, b) in img.data.iter_mut().enumerate() {
            *b = (i * 13) as u8;
        }
        let png = encode_png(&img.view()).unwrap();
        let back = decode(&png).unwrap();
        assert_eq!(back.format, PixelFormat::Rgb8);
        assert_eq!(back.convert(PixelFormat::Bgr8), img);
    }

    #[test]
    fn garbage_and_truncation_are_errors() {
        assert!(decode(b"hello").is_err());
        let img = Image::new(8, 8, PixelFormat::Rgb8);
        let png = encode_png(&img.view()).unwrap();
        let err = decode(&png[..png.len() / 2]).unwrap_err();
        assert!(err.to_string().contains("PNG"), "{err}");
    }
}
