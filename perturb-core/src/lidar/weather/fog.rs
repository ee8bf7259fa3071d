//! Hahner et al.'s LiDAR fog simulation (ICCV 2021), as 3D-Corruptions-AD (L-A7) and MultiCorrupt
//! (L-A8) use it.
//!
//! A return from a hard target at range `r0` is attenuated by fog to `i e^(-2 alpha r0)`. The fog
//! itself is a soft target: the received power over the pulse, integrated against the fog's
//! backscatter between the sensor and the target, peaks at a range `R_fog` with a height
//! `I(r0) i r0^2 beta / beta0`. When that fog peak is above the attenuated hard return, the sensor
//! reports the fog instead: the point moves to about `R_fog` with the fog's intensity.
//!
//! The table `T_alpha: r0 -> (R_fog, I)` is computed at configuration time from the published
//! integral (the references load pickled tables): for each `r0` on a 0.1 m grid, `R` runs over the
//! reference's grid `linspace(0, 200, 2000)` and
//! `P(R) = integral_0^{2 tau} sin^2(pi t / (2 tau)) e^(-2 alpha R') xi(R') / R'^2 H(r0 - R') dt`
//! with `R' = R - c t / 2`, `tau` = 20 ns, `xi` the transmitter/receiver overlap ramping from 0 at
//! 0.9 m to 1 at 1 m, H the step function, by Simpson's rule on 2000 samples; `R_fog` is the argmax
//! and `I` the maximum over R < r0 (the fog in front of the target). Beyond about 5 m the table is constant, so it is computed to 10 m and held.
//!
//! Both variants clamp fog intensities at the full scale (MultiCorrupt's code does not: a
//! documented deviation, [`FogModel::multicorrupt`]).
//!
//! Intensities are on 0..255, as the model's constants assume: clouds with 0..1 intensity (KITTI)
//! are scaled by their sensor model's explicit full scale and back (the references apply it to 0..1
//! values directly, which turns nearly every return into fog).

use super::super::{LidarBuilder, LidarFrame, LidarPerturbation, Plan, Points};
use super::C_LIGHT;
use crate::math::Portable;
use crate::rng::Rng;

/// 3D-Corruptions-AD's extinction coefficients (per metre) at levels 1..5; severities 1, 2, 3 use
/// levels 1, 3, 5.
pub const HAHNER_ALPHA: [f64; 5] = [0.005, 0.01, 0.02, 0.03, 0.06];
/// MultiCorrupt's (alpha, beta) at levels 1..3.
pub const MULTICORRUPT_ALPHA_BETA: [(f64, f64); 3] = [(0.02, 0.008), (0.03, 0.008), (0.06, 0.05)];
/// Half-power pulse width in seconds.
pub const TAU_H: f64 = 20e-9;
/// The differential reflectivity of the hard target, gamma; beta0 = gamma / pi.
pub const GAMMA: f64 = 1e-6;

/// The fog response table of one alpha: `(R_fog, I)` per 0.1 m of target range.
#[derive(Clone, Debug, PartialEq)]
pub struct FogTable {
    /// Entries for r0 = 0.0, 0.1, ..., the last one holding for every larger range.
    pub entries: Vec<(f64, f64)>,
}

fn xi(r: f64) -> f64 {
    ((r - 0.9) / 0.1).clamp(0.0, 1.0)
}

impl FogTable {
    /// Computes the table for extinction coefficient `alpha` up to `r0_max` metres.
    pub fn compute(alpha: f64, r0_max: f64) -> Self {
        const SAMPLES: usize = 2000;
        let t_end = 2.0 * TAU_H;
        let dt = t_end / (SAMPLES - 1) as f64;
        // Simpson weights over an even number of intervals (the last interval by the trapezoid
        // rule when the sample count is even, as scipy's simpson does by default is close enough).
        let weights: Vec<f64> = (0..SAMPLES)
            .map(|k| {
                if k == 0 || k == SAMPLES - 1 {
                    1.0
                } else if k % 2 == 1 {
                    4.0
                } else {
                    2.0
                }
            })
            .collect();
        let pulse: Vec<f64> = (0..SAMPLES)
            .map(|k| {
                (std::f64::consts::PI * k as f64 * dt / t_end)
                    .psin()
                    .powi(2)
            })
            .collect();
        let r_grid: Vec<f64> = (0..2000).map(|k| 200.0 * k as f64 / 1999.0).collect();
        let keys = (r0_max * 10.0).round() as usize + 1;
        let entries = (0..keys)
            .map(|key| {
                let r0 = key as f64 / 10.0;
                let mut best = (0.0, 0.0);
                // The fog peak is searched in front of the target (R < r0), as the reference
                // tables are: this is what makes I(2 m) = 3.2987e-10 and holds I constant from
                // r0 = 4.8 m, where R_fog (4.6 m) first lies in front of the target.
                for &r in &r_grid {
                    if r <= 0.9 || r >= r0 {
                        continue;
                    }
                    let mut acc = 0.0;
                    for k in 0..SAMPLES {
                        let rp = r - C_LIGHT * k as f64 * dt / 2.0;
                        if rp <= 0.9 || rp >= r0 {
                            continue;
                        }
                        acc +=
                            weights[k] * pulse[k] * (-2.0 * alpha * rp).pexp() * xi(rp) / (rp * rp);
                    }
                    let p = acc * dt / 3.0;
                    if p > best.1 {
                        best = (r, p);
                    }
                }
                best
            })
            .collect();
        FogTable { entries }
    }

    /// `(R_fog, I)` for target range `r0` (rounded to 0.1 m, held beyond the table).
    pub fn lookup(&self, r0: f64) -> (f64, f64) {
        let k = ((r0 * 10.0).round().max(0.0) as usize).min(self.entries.len() - 1);
        self.entries[k]
    }
}

/// One configuration of the fog model.
#[derive(Clone, Debug, PartialEq)]
pub struct FogModel {
    /// Extinction coefficient per metre.
    pub alpha: f64,
    /// Backscatter coefficient per metre.
    pub beta: f64,
    /// Range noise half-width in metres of a fog return.
    pub noise: f64,
    /// Clamp fog intensities at 255, the full scale (3D-Corruptions-AD does; MultiCorrupt does
    /// not, see [`FogModel::multicorrupt`]).
    pub clamp: bool,
    /// The response table.
    pub table: FogTable,
}

/// What happened to one point.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum FogOutcome {
    /// The hard target, attenuated (intensity on 0..255).
    Attenuated(f64),
    /// A fog return.
    Fog {
        /// Range of the return in metres.
        range: f64,
        /// Intensity on 0..255.
        intensity: f64,
    },
}

impl FogModel {
    /// 3D-Corruptions-AD's parameters for extinction `alpha`: beta = 0.046 / MOR with
    /// MOR = ln 20 / alpha, noise 1 m, fog intensities clamped at 255.
    pub fn hahner(alpha: f64) -> Self {
        FogModel {
            alpha,
            beta: 0.046 * alpha / 20f64.pln(),
            noise: 1.0,
            clamp: true,
            table: FogTable::compute(alpha, 10.0),
        }
    }

    /// MultiCorrupt's parameters: explicit beta, noise 10 m.
    ///
    /// Deviation: MultiCorrupt omits 3D-Corruptions-AD's clamp of the fog intensity at 255, so at
    /// its severity 3 (beta 0.05) fog returns reach about 2.8 times the full scale (724 on a
    /// 0..255 cloud, 2.38 on KITTI's 0..1), values no sensor reports. Here they are clamped at the
    /// sensor's full scale, as 3D-Corruptions-AD does (issue 16).
    pub fn multicorrupt(alpha: f64, beta: f64) -> Self {
        FogModel {
            alpha,
            beta,
            noise: 10.0,
            clamp: true,
            table: FogTable::compute(alpha, 10.0),
        }
    }

    /// The deterministic part: the fog peak and whether it wins over the attenuated hard return
    /// (intensity `i` on 0..255, range `r0`).
    pub fn decide(&self, r0: f64, i: f64) -> (f64, f64, f64, bool) {
        let hard = (i * (-2.0 * self.alpha * r0).pexp()).round();
        let (r_fog, peak) = self.table.lookup(r0);
        let fog = peak * i * r0 * r0 * self.beta / (GAMMA / std::f64::consts::PI);
        (hard, r_fog, fog, fog > hard)
    }

    /// Simulates one return (intensity on 0..255).
    pub fn simulate(&self, r0: f64, i: f64, rng: &mut Rng) -> FogOutcome {
        let (hard, r_fog, fog, is_fog) = self.decide(r0, i);
        if !is_fog {
            return FogOutcome::Attenuated(hard);
        }
        // The reference scales the point by (R_fog / r0) (r0 / u), u uniform in r0 +- noise: a fog
        // return at R_fog r0 / u. With MultiCorrupt's 10 m noise u can reach 0 for near targets;
        // it is kept at 0.5 m or more here.
        let u = rng.uniform(r0 - self.noise, r0 + self.noise).max(0.5);
        FogOutcome::Fog {
            range: r_fog * r0 / u,
            intensity: if self.clamp {
                fog.clamp(0.0, 255.0)
            } else {
                fog
            },
        }
    }

    /// The range beyond which every return of intensity `i` becomes fog (None within `limit`).
    pub fn all_fog_beyond(&self, i: f64, limit: f64) -> Option<f64> {
        if !self.decide(limit, i).3 {
            return None;
        }
        let mut r = limit;
        while r > 1.0 && self.decide(r - 0.1, i).3 {
            r -= 0.1;
        }
        Some(r)
    }
}

/// L-A7 fog_hahner / L-A8 fog_multicorrupt.
pub struct HahnerFog {
    seed: u64,
    salt: u64,
    model: FogModel,
}

/// Registry constructor of L-A7.
pub const FOG_HAHNER: LidarBuilder = |s| {
    Ok(Box::new(HahnerFog {
        seed: s.seed,
        salt: 0xA7,
        model: FogModel::hahner(HAHNER_ALPHA[s.level_of_five()]),
    }))
};

/// Registry constructor of L-A8.
pub const FOG_MULTICORRUPT: LidarBuilder = |s| {
    let (alpha, beta) = MULTICORRUPT_ALPHA_BETA[s.level()];
    Ok(Box::new(HahnerFog {
        seed: s.seed,
        salt: 0xA8,
        model: FogModel::multicorrupt(alpha, beta),
    }))
};

impl HahnerFog {
    /// The model.
    pub fn model(&self) -> &FogModel {
        &self.model
    }
}

impl LidarPerturbation for HahnerFog {
    fn plan(&self, points: &Points, frame: &LidarFrame<'_>, plan: &mut Plan) {
        let to255 = 255.0 / points.intensity_max.max(1e-6) as f64;
        let base = Rng::for_frame(self.seed, frame.seq, self.salt);
        for i in 0..points.len() {
            let r0 = points.range(i) as f64;
            if !r0.is_finite() || r0 <= 0.0 {
                plan.keep(i);
                continue;
            }
            let inten = points
                .intensity
                .as_ref()
                .map_or(127.5, |v| v[i] as f64 * to255);
            let mut rng = base.fork(i as u64);
            match self.model.simulate(r0, inten, &mut rng) {
                FogOutcome::Attenuated(v) => plan.dimmed(i, (v / to255) as f32),
                FogOutcome::Fog { range, intensity } => {
                    let p = points.xyz(i);
                    let k = (range / r0) as f32;
                    plan.emit(
                        i,
                        [p[0] * k, p[1] * k, p[2] * k],
                        (intensity / to255) as f32,
                    );
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn table_matches_the_reference_pickles() {
        // lidar.md: I(2 m) = 3.2987e-10 and I(>= 5 m) = 3.8156e-9, R_fog = 4.60 m at alpha = 0.06;
        // I is 0 below 1.1 m.
        let t = FogTable::compute(0.06, 10.0);
        let (r_fog, i_far) = t.lookup(8.0);
        assert!((i_far - 3.8156e-9).abs() / 3.8156e-9 < 0.01, "{i_far}");
        assert!((r_fog - 4.60).abs() < 0.06, "{r_fog}");
        assert!(
            (t.lookup(2.0).1 - 3.2987e-10).abs() / 3.2987e-10 < 0.02,
            "{}",
            t.lookup(2.0).1
        );
        assert_eq!(t.lookup(1.0).1, 0.0);
        assert!((FogTable::compute(0.005, 10.0).lookup(9.0).0 - 4.70).abs() < 0.06);
    }

    #[test]
    fn every_return_is_fog_beyond_the_reference_ranges() {
        // lidar.md's table (intensity > 0 makes the test independent of it apart from rounding).
        let cases = [
            (FogModel::hahner(0.02), 86.6),
            (FogModel::hahner(0.06), 35.6),
            (FogModel::multicorrupt(0.02, 0.008), 41.7),
            (FogModel::multicorrupt(0.06, 0.05), 15.9),
        ];
        for (m, want) in cases {
            let got = m.all_fog_beyond(200.0, 200.0).unwrap();
            assert!(
                (got - want).abs() < 1.5,
                "alpha {} beta {}: {got} vs {want}",
                m.alpha,
                m.beta
            );
        }
        assert_eq!(
            FogModel::hahner(0.005).all_fog_beyond(200.0, 200.0),
            None,
            "never at alpha 0.005"
        );
    }
}
