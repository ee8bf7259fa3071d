//! Colour and tone family (C-F): changes of hue, saturation and tone.

mod histogram;
mod phase;
mod tone;

pub use histogram::*;
pub use phase::*;
pub use tone::*;

use super::CameraSetup;
use crate::error::Error;

pub(crate) fn refuse_mono(id: &'static str, s: &CameraSetup) -> Result<(), Error> {
    if s.geometry.format.is_mono() {
        return Err(Error::UnsupportedPixelFormat {
            id,
            format: "mono8 (it has no colour)",
        });
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::camera::CameraBuilder;
    use crate::image::{Image, PixelFormat};

    fn run(b: CameraBuilder, sev: u8, img: &Image) -> Image {
        crate::camera::apply_once(b, sev, 1, img, 0)
    }

    fn px(r: u8, g: u8, b: u8) -> Image {
        Image::from_vec(vec![r, g, b], 1, 1, 3, PixelFormat::Rgb8).unwrap()
    }

    #[test]
    fn false_color_modes() {
        let i = px(200, 100, 50);
        assert_eq!(run(FALSE_COLOR, 1, &i).data, vec![100, 50, 200]);
        assert_eq!(run(FALSE_COLOR, 2, &i).data, vec![100, 200, 50]);
        assert_eq!(run(FALSE_COLOR, 3, &i).data, vec![50, 100, 200]);
        assert_eq!(run(FALSE_COLOR, 4, &i).data, vec![55, 155, 205]);
        assert_eq!(
            run(FALSE_COLOR, 5, &i).data,
            vec![150, 75, 125],
            "no uint8 wrap-around"
        );
    }

    #[test]
    fn posterize_levels_match_the_reference_table() {
        let distinct = |l| {
            let t = posterize_lut(l);
            let mut v: Vec<u8> = t.to_vec();
            v.dedup();
            v
        };
        assert_eq!(distinct(4), vec![0, 85, 170, 255]);
        assert_eq!(distinct(8).len(), 9);
        // The reference formula reaches L at v = 255, so L + 1 levels for L = 128, 64, 32
        // (numpy: 129, 65, 33, 9, 4 distinct values).
        assert_eq!(distinct(128).len(), 129);
        assert_eq!(distinct(64).len(), 65);
        assert_eq!(distinct(32).len(), 33);
    }

    #[test]
    fn saturation_scales_colourfulness_and_keeps_value_and_grey() {
        let i = px(200, 120, 80);
        let up = run(SATURATION_UP, 5, &i);
        let down = run(SATURATION_DOWN, 5, &i);
        assert_eq!(up.data[0], 200);
        assert_eq!(down.data[0], 200, "value (max) kept");
        assert!(
            up.data[2] < 80 && down.data[2] > 180,
            "{:?} {:?}",
            up.data,
            down.data
        );
        // Decrease at s5 keeps 10% of the saturation: the channels nearly meet at V.
        assert!(down.data.iter().all(|&v| v >= 188));
        assert_eq!(
            run(SATURATION_UP, 5, &px(90, 90, 90)).data,
            vec![90, 90, 90]
        );
    }

    #[test]
    fn white_balance_evens_out_a_colour_cast() {
        let mut img = Image::new(8, 8, PixelFormat::Rgb8);
        for p in img.data.chunks_exact_mut(3) {
            p.copy_from_slice(&[180, 120, 60]);
        }
        let out = run(WHITE_BALANCE, 5, &img);
        let p = &out.data[..3];
        assert!(p.iter().all(|&v| (v as i32 - 120).abs() <= 2), "{p:?}");
        let mild = run(WHITE_BALANCE, 1, &img);
        assert!(
            mild.data[0] < 180 && mild.data[0] > 170,
            "{:?}",
            &mild.data[..3]
        );
    }

    #[test]
    fn clahe_behaves_as_opencv() {
        // A low-contrast ramp: CLAHE spreads its values; higher clip limits spread them more.
        let (w, h) = (64, 64);
        let plane: Vec<u8> = (0..w * h).map(|i| 100 + ((i % w) / 8) as u8).collect();
        let spread = |clip| {
            let o = clahe(&plane, w, h, clip, 8);
            let (mn, mx) = (
                o.iter().min().copied().unwrap(),
                o.iter().max().copied().unwrap(),
            );
            // Along a row the mapping keeps the order of the input values.
            let row = &o[32 * w..33 * w];
            assert!(row.windows(2).all(|p| p[0] <= p[1] + 1), "{row:?}");
            (mx - mn) as i32
        };
        // The 8-value ramp stays 6-7 levels wide (OpenCV gives spreads 6 and 7 for clips 1 and 10):
        // within each tile the ramp has one value per column band, so clipping limits the gain.
        let (s1, s10) = (spread(1.0), spread(10.0));
        assert!((5..=7).contains(&s1) && s10 >= s1, "{s1} {s10}");
        // A random plane is stretched to the full range, as OpenCV does.
        let mut r = crate::rng::Rng::for_setup(4, 4);
        let noise: Vec<u8> = (0..100 * 75).map(|_| 40 + r.below(160) as u8).collect();
        let o = clahe(&noise, 100, 75, 3.0, 8);
        assert!(o.iter().max().unwrap() - o.iter().min().unwrap() > 230);
    }

    #[test]
    fn phase_scrambling_keeps_the_mean_and_scrambles_more_with_severity() {
        let img = crate::synthetic::street_image(96, 60, 0);
        let mean = |i: &Image| i.data.iter().map(|&v| v as f64).sum::<f64>() / i.data.len() as f64;
        let mad = |o: &Image| {
            o.data
                .iter()
                .zip(&img.data)
                .map(|(a, b)| (*a as f64 - *b as f64).abs())
                .sum::<f64>()
                / o.data.len() as f64
        };
        let mut last = 0.0;
        for s in 1..=5 {
            let p = PHASE_SCRAMBLING(&CameraSetup {
                severity: s,
                seed: 2,
                geometry: img.geometry(),
            })
            .unwrap();
            let mut out = Image::with_geometry(img.geometry());
            p.apply(&img.view(), &mut out.view_mut(), 0);
            // The DC bin is scaled by cos(theta_0), theta_0 in [0, s pi]: the mean can only shrink,
            // and by no more than that factor (clipping at 0 and 255 aside).
            let ratio = mean(&out) / mean(&img);
            let lowest = (PHASE_SCRAMBLE[s as usize - 1] * std::f32::consts::PI).cos() as f64;
            assert!(ratio <= 1.02 && ratio >= lowest - 0.05, "s{s}: {ratio}");
            let d = mad(&out);
            assert!(d > last, "s{s}: {d} <= {last}");
            last = d;
        }
    }

    #[test]
    fn grayscale_top_severity_is_near_neutral() {
        let out = run(GRAYSCALE, 5, &px(200, 40, 90));
        let spread = out.data.iter().max().unwrap() - out.data.iter().min().unwrap();
        assert!(spread <= 24, "{:?}", out.data);
        assert!(run(GRAYSCALE, 1, &px(200, 40, 90)).data[0] > 180);
    }
}
