//! PNG and JPEG images through the `image` crate (decode and encode only).

use crate::error::{Error, Result};
use crate::image::{Image, ImageView, PixelFormat};
use ::image::{DynamicImage, ImageFormat};

/// Decodes a PNG or JPEG into rgb8, rgba8 or mono8, as stored (palette images are expanded to
/// the rgb8 or rgba8 they stand for, which loses nothing).
///
/// Images the perturbations cannot keep in their format are refused with an error naming the
/// format, instead of being converted behind the caller's back: 16-bit grey or colour (it would
/// lose its low byte) and grey with alpha (it would come back as rgba8).
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
    from_dynamic(img, name)
}

/// Describes a colour type the perturbations do not handle, and what to do about it.
fn unsupported(color: ::image::ColorType) -> String {
    use ::image::ColorType as C;
    let what = match color {
        C::L16 => "16-bit grey",
        C::La8 => "8-bit grey with alpha",
        C::La16 => "16-bit grey with alpha",
        C::Rgb16 => "16-bit RGB",
        C::Rgba16 => "16-bit RGBA",
        C::Rgb32F => "32-bit float RGB",
        C::Rgba32F => "32-bit float RGBA",
        _ => "an unusual colour type",
    };
    format!(
        "the image is {what} ({color:?}); the perturbations work on 8-bit grey, RGB and RGBA images and would have to convert it, changing its format: convert it yourself first (e.g. to 8 bits per channel, or grey with alpha to RGBA)"
    )
}

fn from_dynamic(img: DynamicImage, name: &'static str) -> Result<Image> {
    let (w, h) = (img.width(), img.height());
    let color = img.color();
    let image = match img {
        DynamicImage::ImageLuma8(b) => {
            Image::from_vec(b.into_raw(), w, h, w as usize, PixelFormat::Mono8)
        }
        DynamicImage::ImageRgb8(b) => {
            Image::from_vec(b.into_raw(), w, h, w as usize * 3, PixelFormat::Rgb8)
        }
        DynamicImage::ImageRgba8(b) => {
            Image::from_vec(b.into_raw(), w, h, w as usize * 4, PixelFormat::Rgba8)
        }
        _ => return Err(Error::malformed(name, unsupported(color))),
    };
    Ok(image.expect("tight buffers from the decoder"))
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

    fn png_of(data: &[u8], w: u32, h: u32, color: ::image::ExtendedColorType) -> Vec<u8> {
        use ::image::ImageEncoder;
        let mut out = Vec::new();
        ::image::codecs::png::PngEncoder::new(&mut out)
            .write_image(data, w, h, color)
            .unwrap();
        out
    }

    #[test]
    fn sixteen_bit_and_grey_alpha_are_refused_not_converted() {
        use ::image::ExtendedColorType as C;
        for (color, bytes_per_pixel, says) in [
            (C::L16, 2, "16-bit grey"),
            (C::Rgb16, 6, "16-bit RGB"),
            (C::La8, 2, "grey with alpha"),
        ] {
            let png = png_of(&vec![7u8; 4 * 3 * bytes_per_pixel], 4, 3, color);
            let err = decode(&png).unwrap_err().to_string();
            assert!(err.contains(says) && err.contains("PNG"), "{err}");
        }
        // 8-bit grey, RGB and RGBA keep their format.
        for (color, n, format) in [
            (C::L8, 1, PixelFormat::Mono8),
            (C::Rgb8, 3, PixelFormat::Rgb8),
            (C::Rgba8, 4, PixelFormat::Rgba8),
        ] {
            let png = png_of(&vec![9u8; 4 * 3 * n], 4, 3, color);
            assert_eq!(decode(&png).unwrap().format, format);
        }
    }
}
