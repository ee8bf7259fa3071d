//! Random noises drawn per colour byte from tabulated quantiles (C-A1 Gaussian, C-A2 Poisson,
//! C-A5 speckle) and impulse noise (C-A3).

use crate::camera::ops::{par_rows, row_rng, wide_fn};
use crate::camera::{CameraBuilder, CameraPerturbation};
use crate::image::{ImageView, ImageViewMut, PixelFormat};
use crate::rng::{Rng, normal_quantile};

/// Resolution of the per-value quantile tables: 2^QBITS equiprobable quantiles.
const QBITS: u32 = 11;
const QN: usize = 1 << QBITS;

/// For each input byte value, `QN` equiprobable output values (the midpoints of the quantile
/// bins of the output distribution).
struct QuantileTables(Box<[[u8; QN]; 256]>);

impl QuantileTables {
    /// Builds the tables from `quantile(v, p)`: the output value for input `v` at probability `p`.
    fn build(quantile: impl Fn(u8, f64) -> f64) -> Self {
        Self::build_indexed(|v, k| quantile(v, (k as f64 + 0.5) / QN as f64))
    }

    /// Builds the tables from `f(v, k)`: the output value for input `v` in quantile bin `k`.
    fn build_indexed(f: impl Fn(u8, usize) -> f64) -> Self {
        let mut t = vec![[0u8; QN]; 256].into_boxed_slice();
        for (v, row) in t.iter_mut().enumerate() {
            for (k, out) in row.iter_mut().enumerate() {
                *out = f(v as u8, k).round().clamp(0.0, 255.0) as u8;
            }
        }
        QuantileTables(t.try_into().expect("256 rows"))
    }

    /// Applies the tables to every colour byte, one independent draw per byte; alpha is copied.
    fn apply(
        &self,
        seed: u64,
        salt: u64,
        input: &ImageView<'_>,
        output: &mut ImageViewMut<'_>,
        seq: u64,
    ) {
        let format = input.format;
        let t = &self.0;
        par_rows(input, output, |y, src, dst| {
            let rng = row_rng(seed, seq, salt, y);
            table_row(t, rng, format.alpha_offset(), src, dst);
        });
    }
}

wide_fn! {
    /// One row of [`QuantileTables::apply`]: each colour byte `v` becomes `t[v][k]` for the next
    /// draw `k` of `rng`; the alpha byte (at `alpha` in 4-byte pixels) is copied.
    fn table_row(
        t: &[[u8; QN]; 256],
        rng: Rng,
        alpha: Option<usize>,
        src: &[u8],
        dst: &mut [u8],
    ) {
        let mut rng = rng;
        let mut draw = Draws::default();
        match alpha {
            None => {
                for (s, d) in src.iter().zip(dst.iter_mut()) {
                    *d = t[*s as usize][draw.next(&mut rng)];
                }
            }
            Some(a) => {
                for (s, d) in src.chunks_exact(4).zip(dst.chunks_exact_mut(4)) {
                    for c in 0..4 {
                        d[c] = if c == a {
                            s[c]
                        } else {
                            t[s[c] as usize][draw.next(&mut rng)]
                        };
                    }
                }
            }
        }
    }
}

/// Standard normal quantiles at the centres of the `QN` equiprobable bins.
fn normal_bins() -> Vec<f64> {
    (0..QN)
        .map(|k| normal_quantile((k as f64 + 0.5) / QN as f64))
        .collect()
}

/// Hands out `QBITS`-bit random indices, five per 64-bit draw.
#[derive(Default)]
struct Draws {
    bits: u64,
    left: u32,
}

impl Draws {
    #[inline]
    fn next(&mut self, rng: &mut Rng) -> usize {
        if self.left == 0 {
            self.bits = rng.next_u64();
            self.left = 64 / QBITS;
        }
        let v = (self.bits & (QN as u64 - 1)) as usize;
        self.bits >>= QBITS;
        self.left -= 1;
        v
    }
}

/// C-A1 gaussian_noise: standard deviation of the additive noise, in units of full scale (0..1),
/// severities 1..5 (PerturbationDrive `gaussian_noise`).
pub const GAUSSIAN_SIGMA: [f64; 5] = [0.03, 0.06, 0.12, 0.18, 0.22];

/// C-A1 gaussian_noise: `out = clip(x + N(0, sigma))` on every colour channel independently.
///
/// Tabulated as described in the module: for input value `v` the output is
/// `clip(round(v + 255 sigma z))`. The result is rounded where the reference's uint8 conversion
/// truncates (a -0.5 level bias the project does not copy). Alpha is copied.
pub struct GaussianNoise {
    seed: u64,
    tables: QuantileTables,
}

/// Registry constructor of C-A1.
pub const GAUSSIAN: CameraBuilder = |s| {
    let sigma = GAUSSIAN_SIGMA[s.level()] * 255.0;
    Ok(Box::new(GaussianNoise {
        seed: s.seed,
        tables: {
            let z = normal_bins();
            QuantileTables::build_indexed(|v, k| v as f64 + sigma * z[k])
        },
    }))
};

impl CameraPerturbation for GaussianNoise {
    fn apply(&self, input: &ImageView<'_>, output: &mut ImageViewMut<'_>, seq: u64) {
        self.tables.apply(self.seed, 0xA1, input, output, seq);
    }
}

/// C-A2 poisson_noise: photon count scale lambda, severities 1..5 (PerturbationDrive
/// `poisson_noise`): lower lambda, fewer photons, stronger noise.
pub const POISSON_LAMBDA: [f64; 5] = [120.0, 105.0, 87.0, 55.0, 30.0];

/// C-A2 poisson_noise: `out = clip(Poisson(x lambda) / lambda)` with x = v / 255, per colour byte.
///
/// For each of the 256 input values the Poisson law of mean `v lambda / 255` is tabulated at
/// configuration time as a quantile table (the reference draws a float64 Poisson variate per
/// element, 60 ms at 640x480 in Python). Output rounded to the nearest level.
pub struct PoissonNoise {
    seed: u64,
    tables: QuantileTables,
}

fn poisson_quantile(mean: f64, p: f64) -> f64 {
    if mean <= 0.0 {
        return 0.0;
    }
    // Sequential search of the CDF from 0; means are at most 120 here.
    let mut k = 0.0;
    let mut pmf = crate::math::exp(-mean);
    let mut cdf = pmf;
    while cdf < p && k < 10_000.0 {
        k += 1.0;
        pmf *= mean / k;
        cdf += pmf;
    }
    k
}

/// Registry constructor of C-A2.
pub const POISSON: CameraBuilder = |s| {
    let lambda = POISSON_LAMBDA[s.level()];
    Ok(Box::new(PoissonNoise {
        seed: s.seed,
        tables: QuantileTables::build(|v, p| {
            poisson_quantile(v as f64 / 255.0 * lambda, p) / lambda * 255.0
        }),
    }))
};

impl CameraPerturbation for PoissonNoise {
    fn apply(&self, input: &ImageView<'_>, output: &mut ImageViewMut<'_>, seq: u64) {
        self.tables.apply(self.seed, 0xA2, input, output, seq);
    }
}

/// C-A5 speckle_noise: standard deviation of the multiplicative noise, severities 1..5
/// (PerturbationDrive `speckle_noise_filter`).
pub const SPECKLE_SIGMA: [f64; 5] = [0.02, 0.05, 0.09, 0.14, 0.20];

/// C-A5 speckle_noise: `out = clip(I N(1, sigma))` per colour byte (multiplicative Gaussian noise:
/// dark pixels stay dark, bright ones scatter most), tabulated per input value.
pub struct SpeckleNoise {
    seed: u64,
    tables: QuantileTables,
}

/// Registry constructor of C-A5.
pub const SPECKLE: CameraBuilder = |s| {
    let sigma = SPECKLE_SIGMA[s.level()];
    Ok(Box::new(SpeckleNoise {
        seed: s.seed,
        tables: {
            let z = normal_bins();
            QuantileTables::build_indexed(|v, k| v as f64 * (1.0 + sigma * z[k]))
        },
    }))
};

impl CameraPerturbation for SpeckleNoise {
    fn apply(&self, input: &ImageView<'_>, output: &mut ImageViewMut<'_>, seq: u64) {
        self.tables.apply(self.seed, 0xA5, input, output, seq);
    }
}

/// C-A3 impulse_noise: fraction p of the colour elements hit, severities 1..5 (PerturbationDrive
/// `impulse_noise`); half become salt (255), half pepper (0).
pub const IMPULSE_AMOUNT: [f64; 5] = [0.01, 0.02, 0.04, 0.065, 0.10];

/// C-A3 impulse_noise: `n = ceil(p H W C / 2)` element coordinates set to 255, then `n` set to 0
/// (C = colour channels), drawn uniformly with replacement, so later draws may overwrite earlier
/// ones as in the reference.
///
/// Deviation: the reference draws each index with an exclusive upper bound of `dim - 1`, so the
/// last row, the last column and the third channel are never hit; here every element can be.
pub struct ImpulseNoise {
    seed: u64,
    amount: f64,
}

/// Registry constructor of C-A3.
pub const IMPULSE: CameraBuilder = |s| {
    Ok(Box::new(ImpulseNoise {
        seed: s.seed,
        amount: IMPULSE_AMOUNT[s.level()],
    }))
};

impl ImpulseNoise {
    /// Number of salt (and of pepper) draws for a frame.
    pub fn draws(&self, width: u32, height: u32, format: PixelFormat) -> usize {
        (self.amount * width as f64 * height as f64 * format.color_channels() as f64 / 2.0).ceil()
            as usize
    }
}

impl CameraPerturbation for ImpulseNoise {
    fn apply(&self, input: &ImageView<'_>, output: &mut ImageViewMut<'_>, seq: u64) {
        par_rows(input, output, |_, s, d| d.copy_from_slice(s));
        let (w, h, f) = (input.width as u64, input.height as u64, input.format);
        let cc = f.color_channels() as u64;
        let offsets = f.rgb_offsets();
        let n = self.draws(input.width, input.height, f);
        let mut rng = Rng::for_frame(self.seed, seq, 0xA3);
        for (value, _) in [(255u8, 0), (0u8, 1)] {
            for _ in 0..n {
                let e = rng.below(w * h * cc);
                let (pix, ch) = (e / cc, (e % cc) as usize);
                let (y, x) = ((pix / w) as usize, (pix % w) as usize);
                let row = output.row_mut(y);
                row[x * f.channels() + offsets[ch]] = value;
            }
        }
    }
}
