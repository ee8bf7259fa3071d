//! C-A4 JPEG compression: libjpeg-turbo's own encode and decode, the round trip of OpenCV's
//! `imencode` + `imdecode`.

use crate::camera::ops::copy_alpha;
use crate::camera::{CameraBuilder, CameraPerturbation};
use crate::error::{Error, Result};
use crate::image::{ImageView, ImageViewMut, PixelFormat};
use rayon::prelude::*;
use std::sync::Mutex;
use turbojpeg::{Compressor, Decompressor, Image, Subsamp};

/// C-A4 jpeg_compression: JPEG quality, severities 1..5 (PerturbationDrive `jpeg_filter`, which
/// round-trips through OpenCV's libjpeg).
pub const JPEG_QUALITY: [u8; 5] = [30, 18, 15, 10, 5];

/// The largest width or height a JPEG frame can have (libjpeg's `JPEG_MAX_DIMENSION`).
pub const JPEG_MAX_SIDE: u32 = 65_500;

/// Rows of one 4:2:0 MCU (two 8x8 luma blocks high, one chroma block): a frame split into
/// strips on these boundaries quantises every block as the whole frame does.
const MCU_ROWS: usize = 16;

/// Rows a strip must have before the frame is split between threads.
const MIN_STRIP_ROWS: usize = 4 * MCU_ROWS;

/// C-A4 jpeg_compression: the frame encoded as a baseline JPEG at the severity's quality and
/// decoded again, by libjpeg-turbo with the settings of OpenCV's `imencode(".jpg", img,
/// [IMWRITE_JPEG_QUALITY, q])` and `imdecode`: the Annex K tables scaled by libjpeg's quality
/// formula (limited to baseline values), JFIF YCbCr with 4:2:0 chroma subsampling, the accurate
/// integer DCT both ways, Huffman coding with the standard tables, "fancy" (triangular) chroma
/// upsampling. The bytes are OpenCV's for the frame handed to OpenCV in its true colours (BGR order
/// for a BGR Mat); Mono8 is a grayscale JPEG (one luma plane), as OpenCV writes a one-channel
/// Mat. An alpha channel is kept as it was. Deterministic (no random draw).
///
/// Deviation: PerturbationDrive's `jpeg_filter` hands OpenCV its RGB arrays as they are, so OpenCV
/// takes red for blue: luma is computed as 0.299 B + 0.587 G + 0.114 R and the two chroma planes
/// swap roles. The colours come back in place (the decode swaps them again) but the artefacts are
/// those of another image: on the two KITTI frames that round trip differs from the true-colour
/// one on 20-91 % of the pixels, by up to 61-121 levels (mean 2.7-6.3). This implements the
/// codec as a camera's own encoder sees the scene, in its true colours.
///
/// With more than one thread the frame is cut into strips on MCU boundaries (16 rows); each strip
/// is coded with the MCU row above and below it, which its edge rows' chroma upsampling reads, so
/// every output byte is the one the whole frame in one piece gives.
pub struct JpegCompression {
    quality: u8,
    /// Coders of earlier frames (one per strip in flight), reused: a frame allocates none.
    coders: Mutex<Vec<Coder>>,
}

/// One libjpeg-turbo encoder and decoder with their buffers.
struct Coder {
    compressor: Compressor,
    decompressor: Decompressor,
    /// The compressed strip (sized for the worst case of the largest strip seen).
    jpeg: Vec<u8>,
    /// A decoded strip with the rows around it, when the frame is split.
    rows: Vec<u8>,
}

/// A libjpeg-turbo failure (out of memory: the geometry is checked when the perturbation is
/// built) as the catalogue's error.
fn codec_error(e: turbojpeg::Error) -> Error {
    Error::InvalidConfig {
        reason: format!("C-A4 jpeg_compression: libjpeg-turbo failed: {e}"),
    }
}

impl Coder {
    fn new(quality: u8, mono: bool) -> Result<Self> {
        let mut compressor = Compressor::new().map_err(codec_error)?;
        compressor
            .set_quality(quality as i32)
            .map_err(codec_error)?;
        compressor
            .set_subsamp(if mono { Subsamp::Gray } else { Subsamp::Sub2x2 })
            .map_err(codec_error)?;
        Ok(Coder {
            compressor,
            decompressor: Decompressor::new().map_err(codec_error)?,
            jpeg: Vec::new(),
            rows: Vec::new(),
        })
    }

    /// Encodes `src` and decodes it into `dst` (same size and pixel format).
    fn roundtrip(&mut self, src: Image<&[u8]>, dst: Image<&mut [u8]>) -> turbojpeg::Result<()> {
        let need = self.compressor.buf_len(src.width, src.height)?;
        if self.jpeg.len() < need {
            self.jpeg.resize(need, 0);
        }
        let n = self.compressor.compress_to_slice(src, &mut self.jpeg)?;
        self.decompressor.decompress(&self.jpeg[..n], dst)
    }
}

/// libjpeg-turbo's layout of a pixel format (the alpha byte is not coded: it comes out 255 and
/// is copied from the input afterwards).
fn tj_format(format: PixelFormat) -> turbojpeg::PixelFormat {
    match format {
        PixelFormat::Rgb8 => turbojpeg::PixelFormat::RGB,
        PixelFormat::Bgr8 => turbojpeg::PixelFormat::BGR,
        PixelFormat::Rgba8 => turbojpeg::PixelFormat::RGBX,
        PixelFormat::Bgra8 => turbojpeg::PixelFormat::BGRX,
        PixelFormat::Mono8 => turbojpeg::PixelFormat::GRAY,
    }
}

/// Registry constructor of C-A4.
pub const JPEG: CameraBuilder = |s| {
    let g = &s.geometry;
    if g.width > JPEG_MAX_SIDE || g.height > JPEG_MAX_SIDE {
        return Err(Error::InvalidImage {
            reason: format!(
                "C-A4 jpeg_compression codes frames of at most {JPEG_MAX_SIDE} pixels a side (the \
                 JPEG limit), this one is {}x{}",
                g.width, g.height
            ),
        });
    }
    let quality = JPEG_QUALITY[s.level()];
    // One coder now: a failure to start libjpeg-turbo shows here, not in the first frame.
    let first = Coder::new(quality, g.format.is_mono())?;
    Ok(Box::new(JpegCompression {
        quality,
        coders: Mutex::new(vec![first]),
    }))
};

impl JpegCompression {
    /// A coder from the pool (or a new one).
    fn coder(&self, mono: bool) -> Coder {
        let spare = self.coders.lock().ok().and_then(|mut v| v.pop());
        match spare {
            Some(c) => c,
            None => Coder::new(self.quality, mono)
                .unwrap_or_else(|e| panic!("C-A4: cannot start libjpeg-turbo: {e}")),
        }
    }

    fn give_back(&self, coder: Coder) {
        if let Ok(mut v) = self.coders.lock() {
            v.push(coder);
        }
    }
}

impl CameraPerturbation for JpegCompression {
    fn apply(&self, input: &ImageView<'_>, output: &mut ImageViewMut<'_>, _seq: u64) {
        let (w, h) = (input.width as usize, input.height as usize);
        if w == 0 || h == 0 {
            return;
        }
        let format = tj_format(input.format);
        let mono = input.format.is_mono();
        let c = input.format.channels();
        let threads = rayon::current_num_threads();
        let strips = threads.min(h / MIN_STRIP_ROWS).max(1);
        let fail =
            |e: turbojpeg::Error| panic!("C-A4: libjpeg-turbo failed on a {w}x{h} frame: {e}");
        let src = |top: usize, rows: usize| Image {
            pixels: &input.data()[top * input.stride..],
            width: w,
            pitch: input.stride,
            height: rows,
            format,
        };
        if strips == 1 {
            // The whole frame, decoded straight into the output.
            let mut coder = self.coder(mono);
            let stride = output.stride;
            let dst = Image {
                pixels: output.data_mut(),
                width: w,
                pitch: stride,
                height: h,
                format,
            };
            coder.roundtrip(src(0, h), dst).unwrap_or_else(fail);
            self.give_back(coder);
            if input.format.alpha_offset().is_some() {
                for r in 0..h {
                    copy_alpha(input.format, input.row(r), output.row_mut(r));
                }
            }
            return;
        }
        // Strips of whole MCU rows; each is coded with one MCU row of context on either side.
        let mcus = h.div_ceil(MCU_ROWS);
        let mut rows = output.rows_mut();
        let mut tasks = Vec::with_capacity(strips);
        for i in (0..strips).rev() {
            let top = (i * mcus / strips) * MCU_ROWS;
            let bottom = ((i + 1) * mcus / strips * MCU_ROWS).min(h);
            tasks.push((top, bottom, rows.split_off(top)));
        }
        tasks.into_par_iter().for_each(|(top, bottom, mut out)| {
            let mut coder = self.coder(mono);
            let from = top.saturating_sub(MCU_ROWS);
            let to = (bottom + MCU_ROWS).min(h);
            let pitch = w * c;
            coder.rows.resize(pitch * (to - from), 0);
            let mut rows = std::mem::take(&mut coder.rows);
            let dst = Image {
                pixels: &mut rows[..],
                width: w,
                pitch,
                height: to - from,
                format,
            };
            coder
                .roundtrip(src(from, to - from), dst)
                .unwrap_or_else(fail);
            for (r, o) in (top..bottom).zip(out.iter_mut()) {
                let k = r - from;
                o.copy_from_slice(&rows[k * pitch..(k + 1) * pitch]);
                copy_alpha(input.format, input.row(r), o);
            }
            coder.rows = rows;
            self.give_back(coder);
        });
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::image::{Image, PixelFormat};

    #[test]
    fn flat_frames_move_by_the_dc_step_and_blocks_appear() {
        // A smooth horizontal ramp turns into 8-pixel blocks at quality 5, more than at 30.
        let mut ramp = Image::new(64, 16, PixelFormat::Mono8);
        for (i, v) in ramp.data.iter_mut().enumerate() {
            *v = ((i % 64) * 3) as u8;
        }
        let low = crate::camera::apply_once(JPEG, 5, 5, &ramp, 0);
        let high = crate::camera::apply_once(JPEG, 1, 5, &ramp, 0);
        let err = |o: &Image| {
            o.data
                .iter()
                .zip(&ramp.data)
                .map(|(a, b)| (*a as f64 - *b as f64).abs())
                .sum::<f64>()
        };
        assert!(
            err(&low) > err(&high),
            "quality 5 distorts more than quality 30"
        );
        // A flat grey frame stays flat; its level moves by the DC quantisation: at quality 5 the
        // luma DC step is 16 x 5000 / 5 / 100 = 160, so 77 (-51 after the level shift, DC -408)
        // becomes round(-408 / 160) x 160 / 8 + 128 = 68; chroma (128) is untouched.
        let mut flat = Image::new(24, 24, PixelFormat::Rgb8);
        flat.data.fill(77);
        let out = crate::camera::apply_once(JPEG, 5, 5, &flat, 0);
        assert!(out.data.iter().all(|&v| v == 68), "{:?}", &out.data[..6]);
        let out = crate::camera::apply_once(JPEG, 1, 5, &flat, 0);
        assert!(out.data.iter().all(|&v| v == 77), "{:?}", &out.data[..6]);
    }

    #[test]
    fn strips_give_the_bytes_of_the_whole_frame_and_alpha_stays() {
        // Tall odd frames cut into strips between 2 and 5 threads against the whole frame in one
        // piece on one thread, in every layout; alpha comes through untouched.
        let pool = |n| {
            rayon::ThreadPoolBuilder::new()
                .num_threads(n)
                .build()
                .unwrap()
        };
        for (w, h, format) in [
            (61, 301, PixelFormat::Rgb8),
            (33, 275, PixelFormat::Bgra8),
            (47, 259, PixelFormat::Mono8),
        ] {
            let mut img = Image::new(w, h, format);
            for (i, v) in img.data.iter_mut().enumerate() {
                *v = ((i * 7919) % 251) as u8 ^ (i / (4 * w as usize)) as u8;
            }
            for level in [1, 5] {
                let run =
                    |n| pool(n).install(|| crate::camera::apply_once(JPEG, level, 5, &img, 0));
                let one = run(1);
                assert_ne!(one.data, img.data, "{w}x{h} s{level}: unchanged");
                for n in [2, 3, 5] {
                    assert_eq!(
                        run(n).data,
                        one.data,
                        "{w}x{h} {format} s{level}: {n} threads"
                    );
                }
                if let Some(a) = format.alpha_offset() {
                    let c = format.channels();
                    let alpha = |d: &[u8]| d.iter().skip(a).step_by(c).copied().collect::<Vec<_>>();
                    assert_eq!(alpha(&one.data), alpha(&img.data), "{format}: alpha");
                }
            }
        }
    }

    #[test]
    fn frames_past_the_jpeg_limit_are_refused_by_name() {
        let setup = crate::camera::CameraSetup {
            severity: 3,
            seed: 0,
            geometry: crate::image::ImageGeometry::new(70_000, 8, PixelFormat::Rgb8),
        };
        let err = JPEG(&setup).err().expect("70000 pixels wide is refused");
        let text = err.to_string();
        assert!(text.contains("65500") && text.contains("70000x8"), "{text}");
    }
}
