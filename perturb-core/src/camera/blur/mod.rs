//! Blur family (C-B): convolutions and resampling that remove detail.

mod gaussian;
mod lens;
mod motion;

pub use gaussian::*;
pub use lens::*;
pub use motion::*;

#[cfg(test)]
mod tests {
    use super::*;
    use crate::camera::CameraBuilder;
    use crate::image::{Image, PixelFormat};

    fn run(b: CameraBuilder, sev: u8, img: &Image) -> Image {
        crate::camera::apply_once(b, sev, 1, img, 0)
    }

    fn var(img: &Image) -> f64 {
        let n = img.data.len() as f64;
        let m = img.data.iter().map(|&v| v as f64).sum::<f64>() / n;
        img.data
            .iter()
            .map(|&v| (v as f64 - m).powi(2))
            .sum::<f64>()
            / n
    }

    #[test]
    fn blurs_keep_the_mean_and_lose_variance_with_severity() {
        let img = crate::synthetic::street_image(200, 120, 1);
        let mean = |i: &Image| i.data.iter().map(|&v| v as f64).sum::<f64>() / i.data.len() as f64;
        for b in [GAUSSIAN, DEFOCUS, MOTION_BLUR, ZOOM_BLUR] {
            let mut last = var(&img) + 1.0;
            for s in 1..=5 {
                let out = run(b, s, &img);
                assert!((mean(&out) - mean(&img)).abs() < 1.5, "mean kept");
                let v = var(&out);
                assert!(
                    v <= last + 1.0,
                    "variance falls with severity: s{s} {v} > {last}"
                );
                last = v;
            }
        }
    }

    #[test]
    fn motion_kernel_is_the_reference_line() {
        assert_eq!(
            motion_taps(15, 45.0),
            (0..15).map(|y| (y, y)).collect::<Vec<_>>()
        );
        assert_eq!(motion_taps(2, 5.0), vec![(0, 0), (1, 1)]);
        // Near-vertical: theta 12 degrees from vertical on a 4 x 4 kernel.
        assert_eq!(motion_taps(4, 12.0), vec![(0, 1), (1, 1), (2, 2), (3, 2)]);
    }

    #[test]
    fn zoom_factor_lists_match_numpy_arange() {
        let n: Vec<usize> = ZOOM
            .iter()
            .map(|&(e, s)| zoom_factors(e, s).len())
            .collect();
        // numpy: [2, 12, 8, 11, 11] (float error puts 1.01 and 1.11 inside the first two ranges).
        assert_eq!(n, vec![2, 12, 8, 11, 11]);
        assert!((zoom_factors(1.31, 0.03)[10] - 1.30).abs() < 1e-12);
    }

    #[test]
    fn defocus_is_a_disk_average() {
        // A single bright pixel spreads into a disk of the configured radius.
        let mut img = Image::new(41, 41, PixelFormat::Mono8);
        img.data[20 * 41 + 20] = 255;
        let out = run(DEFOCUS, 2, &img); // r = 5: 81 pixels
        let lit = out.data.iter().filter(|&&v| v > 0).count();
        assert_eq!(lit, 81);
        assert_eq!(out.data[20 * 41 + 25], 3, "edge of the disk");
        assert_eq!(out.data[20 * 41 + 26], 0, "outside the disk");
    }

    #[test]
    fn glass_blur_only_moves_pixels_within_reach() {
        let mut img = Image::new(64, 64, PixelFormat::Mono8);
        for (i, v) in img.data.iter_mut().enumerate() {
            *v = (i % 64) as u8 * 4; // value encodes the column
        }
        let out = run(GLASS, 1, &img); // d = 2
        for y in 0..64 {
            for x in 0..64 {
                let sx = out.data[y * 64 + x] as i64 / 4;
                assert!((sx - x as i64).abs() <= 2);
            }
        }
        assert_ne!(out, img);
    }

    #[test]
    fn high_pass_sharpens_edges() {
        let mut img = Image::new(80, 80, PixelFormat::Mono8);
        for (i, v) in img.data.iter_mut().enumerate() {
            *v = if i % 80 < 40 { 80 } else { 160 };
        }
        let out = run(HIGH_PASS, 1, &img);
        // Overshoot on both sides of the edge, flat far away.
        assert!(out.data[40 * 80 + 38] < 80 && out.data[40 * 80 + 41] > 160);
        assert_eq!(out.data[40 * 80 + 2], 80);
    }
}
