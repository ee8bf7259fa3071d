//! Per-pixel colour and tone kernels that run near the speed of a frame copy, with the same bytes
//! as the tables that define them.
//!
//! A perturbation whose output byte depends on one input byte is defined by a 256-entry table; a
//! table lookup per byte costs a load and does not vectorise. Most of these tables follow a simple
//! formula (a straight line clamped to 0..=255, a staircase), so [`ByteMap`] looks, once at
//! configuration time, for integer arithmetic in 16-bit lanes that gives exactly the table's 256
//! outputs (the few inputs where the nearest line misses by one, exact halves that the table's
//! float arithmetic rounded the other way, are patched afterwards), and keeps the lookup where
//! none fits. [`fit_fixed`] does the same for tables of 16-bit values in 16.16 fixed point.
//!
//! Every kernel here is checked against its table over all 256 inputs when it is built, so what
//! runs is always what the table says.

mod avx2;
mod bytemap;
mod mix;
mod value;

pub use bytemap::*;
pub use mix::*;
pub use value::*;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_posterize_staircase_gives_the_tables_bytes() {
        // Every level count gives the table's bytes; the powers of two (the severities' counts,
        // whose step 255 / L the table's float division represents exactly) as arithmetic.
        for levels in 2..=256u32 {
            let lut = crate::camera::color::posterize_lut(levels);
            let scale = 255 / (levels - 1);
            let m = ByteMap::steps(lut, levels, scale);
            assert!(
                m.is_arithmetic() || !levels.is_power_of_two(),
                "{levels} levels"
            );
            let src: Vec<u8> = (0..=255).collect();
            let mut dst = vec![0; 256];
            m.row(&src, &mut dst);
            assert_eq!(dst, lut, "{levels} levels");
        }
    }

    #[test]
    fn every_form_gives_its_table_at_every_length_and_offset() {
        // The AVX2 blocks, the scalar tail and the patches of each form, on rows of every length
        // up to three blocks and then some, starting at every offset within a block.
        let contrast: [u8; 256] = std::array::from_fn(|v| {
            (127.5 + (v as f32 - 127.5) * 1.2).round().clamp(0.0, 255.0) as u8
        });
        let wild: [u8; 256] = std::array::from_fn(|v| (v * 97 % 256) as u8);
        let mut masked: [u8; 256] = std::array::from_fn(|v| v as u8 & 0xf0);
        masked[7] = 200;
        let maps = [
            ByteMap::line(contrast, 1.2, 127.5 * (1.0 - 1.2)),
            ByteMap::steps(crate::camera::color::posterize_lut(32), 32, 8),
            ByteMap::steps(crate::camera::color::posterize_lut(8), 8, 36),
            ByteMap::steps(crate::camera::color::posterize_lut(6), 6, 51),
            ByteMap::table(masked),
            ByteMap::table(wild),
        ];
        let src: Vec<u8> = (0..1024u32).map(|i| (i * 131 + i / 256) as u8).collect();
        for m in &maps {
            for start in 0..32 {
                for len in (0..=100).chain([255, 256, 511]) {
                    let s = &src[start..start + len];
                    let mut dst = vec![0; len];
                    m.row(s, &mut dst);
                    let want: Vec<u8> = s.iter().map(|&v| m.lut()[v as usize]).collect();
                    assert_eq!(dst, want, "{m:?} start {start} len {len}");
                }
            }
        }
        assert!(maps[..5].iter().all(ByteMap::is_arithmetic));
    }

    #[test]
    fn posterize_runs_as_a_mask_or_a_nibble_table() {
        // Each severity's staircase is one AND (32 levels and more) or one 16-entry lookup (8
        // and 4 levels), with at most one patched input.
        for levels in crate::camera::color::POSTERIZE_LEVELS {
            let lut = crate::camera::color::posterize_lut(levels);
            let m = ByteMap::steps(lut, levels, 255 / (levels - 1));
            let form = format!("{m:?}");
            assert!(
                form.contains("Mask") || form.contains("Nibble"),
                "{levels} levels: {form}"
            );
        }
    }

    #[test]
    fn lines_reproduce_their_tables_including_the_float_ties() {
        // Contrast tables (f32 arithmetic, whose ties at f = 1.2 round both ways) and a few
        // clamped lines of other slopes and offsets.
        let contrast = |f: f32| -> [u8; 256] {
            std::array::from_fn(|v| {
                (127.5 + (v as f32 - 127.5) * f).round().clamp(0.0, 255.0) as u8
            })
        };
        let mut cases: Vec<([u8; 256], f64, f64)> = [1.1f32, 1.2, 1.3, 1.5, 1.7, 0.8, 0.5]
            .map(|f| (contrast(f), f as f64, 127.5 * (1.0 - f as f64)))
            .to_vec();
        for (a, b) in [(0.9f64, 12.0f64), (1.05, -3.0), (0.3, 100.0)] {
            let lut = std::array::from_fn(|v| (a * v as f64 + b).round().clamp(0.0, 255.0) as u8);
            cases.push((lut, a, b));
        }
        let src: Vec<u8> = (0..=255).rev().chain(0..=255).collect();
        for (lut, slope, offset) in cases {
            let m = ByteMap::line(lut, slope, offset);
            assert!(m.is_arithmetic(), "slope {slope} offset {offset}");
            let mut dst = vec![0; src.len()];
            m.row(&src, &mut dst);
            let want: Vec<u8> = src.iter().map(|&v| lut[v as usize]).collect();
            assert_eq!(dst, want, "slope {slope} offset {offset}");
        }
        // A table that is no line keeps the lookup, and still maps right.
        let wild: [u8; 256] = std::array::from_fn(|v| (v * 97 % 256) as u8);
        let m = ByteMap::line(wild, 1.0, 0.0);
        assert!(!m.is_arithmetic());
        let mut dst = vec![0; src.len()];
        m.row(&src, &mut dst);
        assert!(src.iter().zip(&dst).all(|(&s, &d)| d == wild[s as usize]));
    }

    #[test]
    fn fixed_point_fits_are_exact_or_absent() {
        for c in [0.1f32, 0.35, 0.55, 0.9, 0.999, 1.0] {
            let table: [u32; 256] = std::array::from_fn(|v| (c * v as f32 * 256.0).round() as u32);
            let (mul, add) = fit_fixed(&table).unwrap_or_else(|| panic!("no fit for {c}"));
            for (v, &t) in table.iter().enumerate() {
                assert_eq!((v as u32 * mul + add) >> 16, t, "c {c} v {v}");
            }
        }
        // Too steep for 32 bits, or not a line: no fit.
        let steep: [u32; 256] = std::array::from_fn(|v| (1.7 * v as f32 * 256.0).round() as u32);
        assert_eq!(fit_fixed(&steep), None);
        let bent: [u32; 256] = std::array::from_fn(|v| (v * v) as u32);
        assert_eq!(fit_fixed(&bent), None);
    }
}
