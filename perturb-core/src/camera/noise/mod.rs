//! Noise family (C-A): sensor noise and compression artefacts added to the pixel values.
//!
//! The random noises (gaussian, poisson, speckle) draw, for every colour byte, a value from the
//! distribution of the reference's output given that byte's input value. The distributions are
//! tabulated at configuration time as quantile tables (inverse CDFs), so a frame costs one random
//! draw and one table read per byte, whatever the distribution.

mod jpeg;
mod random;

pub use jpeg::*;
pub use random::*;

#[cfg(test)]
mod tests {
    use super::*;
    use crate::camera::CameraBuilder;
    use crate::image::{Image, PixelFormat};

    fn flat(v: u8, w: u32, h: u32) -> Image {
        let mut img = Image::new(w, h, PixelFormat::Rgb8);
        img.data.fill(v);
        img
    }

    fn stats(img: &Image) -> (f64, f64) {
        let n = img.data.len() as f64;
        let m = img.data.iter().map(|&v| v as f64).sum::<f64>() / n;
        let var = img
            .data
            .iter()
            .map(|&v| (v as f64 - m).powi(2))
            .sum::<f64>()
            / n;
        (m, var.sqrt())
    }

    fn run(b: CameraBuilder, sev: u8, img: &Image, seq: u64) -> Image {
        crate::camera::apply_once(b, sev, 5, img, seq)
    }

    #[test]
    fn gaussian_noise_has_the_configured_sigma() {
        let img = flat(128, 300, 200);
        for s in 1..=5u8 {
            let (m, sd) = stats(&run(GAUSSIAN, s, &img, 0));
            let want = GAUSSIAN_SIGMA[s as usize - 1] * 255.0;
            assert!((m - 128.0).abs() < 0.3, "s{s} mean {m}");
            // Clipping at 0/255 shrinks the tails slightly at the top severities.
            assert!((sd - want).abs() / want < 0.03, "s{s} sd {sd} want {want}");
        }
    }

    #[test]
    fn poisson_noise_variance_follows_the_photon_count() {
        // Var(k / lambda * 255) = 255^2 x / lambda for k ~ Poisson(x lambda).
        let img = flat(100, 300, 200);
        for s in 1..=5u8 {
            let lambda = POISSON_LAMBDA[s as usize - 1];
            let (m, sd) = stats(&run(POISSON, s, &img, 0));
            let want = 255.0 * (100.0 / 255.0 / lambda).sqrt();
            assert!((m - 100.0).abs() < 1.0, "s{s} mean {m}");
            assert!((sd - want).abs() / want < 0.05, "s{s} sd {sd} want {want}");
        }
    }

    #[test]
    fn speckle_noise_is_multiplicative() {
        // 100 x (1 + 0.2 z) stays inside 0..255 for |z| < 7, so no clipping distorts the spread.
        let bright = run(SPECKLE, 5, &flat(100, 200, 100), 0);
        let dark = run(SPECKLE, 5, &flat(20, 200, 100), 0);
        let (_, sb) = stats(&bright);
        let (_, sd) = stats(&dark);
        assert!((sb - 100.0 * 0.2).abs() < 1.0, "{sb}");
        assert!((sd - 20.0 * 0.2).abs() < 0.6, "{sd}");
    }

    #[test]
    fn impulse_noise_hits_the_configured_count_everywhere() {
        let img = flat(128, 101, 67);
        for s in 1..=5u8 {
            let out = run(IMPULSE, s, &img, 3);
            let p = IMPULSE_AMOUNT[s as usize - 1];
            let n = (p * 101.0 * 67.0 * 3.0 / 2.0).ceil();
            let salt = out.data.iter().filter(|&&v| v == 255).count() as f64;
            let pepper = out.data.iter().filter(|&&v| v == 0).count() as f64;
            // Draws with replacement collide (and pepper overwrites salt) a little.
            let total = 101.0 * 67.0 * 3.0;
            assert!(
                salt <= n && salt > n * (1.0 - 2.0 * n / total) - 10.0,
                "s{s} salt {salt} of {n}"
            );
            assert!(
                pepper <= n && pepper > n * (1.0 - n / total) - 10.0,
                "s{s} pepper {pepper} of {n}"
            );
        }
        // The reference's blind spots (last row, last column, third channel) are hit here.
        let out = run(IMPULSE, 5, &img, 1);
        let last_row = out.view().row(66).iter().any(|&v| v != 128);
        let last_col = (0..67).any(|y| out.view().row(y)[100 * 3..].iter().any(|&v| v != 128));
        let blue = out.data.chunks_exact(3).any(|p| p[2] != 128);
        assert!(last_row && last_col && blue);
    }
}
