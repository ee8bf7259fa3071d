//! LISA: LiDAR light scattering augmentation (Kilic et al.), as 3D-Corruptions-AD uses it for
//! rain (L-A5, Marshall-Palmer drop sizes, water) and snow (L-A1, Marshall-Gunn, ice).
//!
//! For every point at range r the beam is a cone of divergence theta; the particles in it are a
//! Poisson process of density `rho = N0 e^(-Lambda Dmin) / Lambda`, at ranges `r U^(1/3)` and
//! diameters `Dmin + Exp(1/Lambda)`. The hard target returns `p_hard = i e^(-2 alpha r) / r^2`, a
//! particle `p_k = F e^(-2 alpha rho_k) min((D_k / (theta rho_k))^2, 1) / rho_k^2` (F the Fresnel
//! reflectance). In the 'strongest' mode the point is lost if everything is below the detection
//! floor `p_min = 0.9 / 120^2`, replaced by the strongest particle if one beats the hard target,
//! and otherwise kept with range noise and an attenuated intensity.
//!
//! Real-time form, exact in distribution: a particle only matters if `p_k > max(p_min, p_hard)`,
//! and `p_k <= F / rho_k^2`, so only particles closer than `sqrt(F / max(p_min, p_hard))` are
//! drawn: their number is the cone's count thinned binomially by the volume ratio, their ranges
//! uniform in that smaller cone. The reference draws all of them (thousands per distant point, a
//! Python call per point); here a cloud takes milliseconds.
//!
//! Deviations: a lost point is removed (a real sensor reports no return; the reference writes it
//! as x = y = z = 0 and keeps it); the extinction coefficient uses Q_ext = 2 (all drops are far
//! larger than the wavelength), `alpha = pi 1e-6 N0 / Lambda^3` per metre, instead of the
//! reference's tabulated Mie integral (they agree to within a few percent for these sizes).
//!
//! Severity: each point's range noise, particle count and particles take their own random
//! streams (common random numbers), so the severities of one seed differ by their physics only.
//! The detection floor removes the same dim distant returns at every rate, so retention moves
//! little (docs/lidar.md, "Weather and severity"). Snow (Marshall-Gunn: `N0 = 7.6e3 R^-0.87`,
//! `Lambda = 2.55 R^-0.48`) has fewer, larger flakes as the rate rises: 4236 / 2259 / 1308 per m^3
//! at 0.20 / 1.56 / 7.29 mm/h while `alpha` grows 5.8e-4 / 1.9e-3 / 4.5e-3 per m, so light snow
//! scatters as many near-field points as heavier snow and s1 and s2 are alike. Rain
//! (Marshall-Palmer, `N0 = 8000`, `Lambda = 4.1 R^-0.21`) has `alpha` 1.3e-4 / 4.8e-4 / 1.3e-3 per
//! m: from s2 to s3 the two-way loss at 50 m grows by 8 %, below the seed-to-seed spread.

use super::super::{LidarBuilder, LidarFrame, LidarPerturbation, Plan, Points};
use super::unit_intensity;
use crate::math::Portable;
use crate::rng::Rng;

/// Rain rates in mm/h of 3D-Corruptions-AD's five levels; severities 1, 2, 3 use levels 1, 3, 5.
pub const RAIN_RATE_MM_H: [f64; 5] = [0.20, 0.73, 1.5625, 3.125, 7.29];

/// Smallest particle diameter in mm.
pub const D_MIN_MM: f64 = 0.05;
/// Particles closer than this are ignored (metres).
pub const R_MIN_M: f64 = 0.9;
/// The detection floor: a return weaker than `0.9 / R_MAX^2` is not seen.
pub const R_MAX_M: f64 = 120.0;
/// Beam divergence (radians) of the reference.
pub const DIVERGENCE: f64 = 3e-3;

/// Which precipitation.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Precipitation {
    /// Snow: Marshall-Gunn distribution, ice (refractive index 1.3031).
    Snow,
    /// Rain: Marshall-Palmer distribution, water (refractive index 1.328).
    Rain,
}

/// The drop-size distribution and optics of one rain rate.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Medium {
    /// N0 in m^-3 mm^-1.
    pub n0: f64,
    /// Lambda in mm^-1.
    pub lambda: f64,
    /// Particle density in m^-3.
    pub density: f64,
    /// Fresnel reflectance of a particle.
    pub fresnel: f64,
    /// Extinction coefficient in m^-1.
    pub alpha: f64,
}

impl Medium {
    /// The medium of `kind` at rain rate `rate` mm/h.
    pub fn new(kind: Precipitation, rate: f64) -> Self {
        let (n0, lambda, m): (f64, f64, f64) = match kind {
            Precipitation::Snow => (7.6e3 * rate.ppowf(-0.87), 2.55 * rate.ppowf(-0.48), 1.3031),
            Precipitation::Rain => (8000.0, 4.1 * rate.ppowf(-0.21), 1.328),
        };
        Medium {
            n0,
            lambda,
            density: n0 * (-lambda * D_MIN_MM).pexp() / lambda,
            fresnel: ((m - 1.0) / (m + 1.0)).powi(2),
            alpha: std::f64::consts::PI * 1e-6 * n0 / lambda.powi(3),
        }
    }
}

/// L-A1 snow_lisa / L-A5 rain_lisa.
pub struct Lisa {
    seed: u64,
    salt: u64,
    medium: Medium,
    p_min: f64,
    /// Beam divergence (radians), from the sensor model.
    theta: f64,
}

fn build(kind: Precipitation, s: &super::super::LidarSetup) -> Lisa {
    Lisa {
        seed: s.seed,
        salt: if kind == Precipitation::Snow {
            0xA1
        } else {
            0xA5
        },
        medium: Medium::new(kind, RAIN_RATE_MM_H[s.level_of_five()]),
        p_min: 0.9 / (R_MAX_M * R_MAX_M),
        theta: s.sensor.beam_divergence as f64,
    }
}

/// Registry constructor of L-A1.
pub const SNOW_LISA: LidarBuilder = |s| Ok(Box::new(build(Precipitation::Snow, s)));
/// Registry constructor of L-A5.
pub const RAIN_LISA: LidarBuilder = |s| Ok(Box::new(build(Precipitation::Rain, s)));

/// What happened to one point.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Outcome {
    /// No return above the detection floor.
    Lost,
    /// Replaced by a particle return.
    Scattered {
        /// Range of the particle in metres.
        range: f64,
        /// Reflectance on 0..1.
        intensity: f64,
    },
    /// The hard target, with range noise and attenuation.
    Kept {
        /// Range in metres.
        range: f64,
        /// Reflectance on 0..1.
        intensity: f64,
    },
}

impl Lisa {
    /// The model of `kind` for a configuration (rain rate from the severity, beam divergence from
    /// the sensor model).
    pub fn new(kind: Precipitation, s: &super::super::LidarSetup) -> Self {
        build(kind, s)
    }

    /// The medium.
    pub fn medium(&self) -> &Medium {
        &self.medium
    }

    /// Simulates one beam returning from range `r` with reflectance `i` (0..1).
    pub fn simulate(&self, r: f64, i: f64, rng: &mut Rng) -> Outcome {
        let m = &self.medium;
        if r <= R_MIN_M || !r.is_finite() {
            return Outcome::Kept {
                range: r,
                intensity: i,
            };
        }
        // Common random numbers: the range noise, the particle count and the particles each take
        // their own stream (the k-th particle its k-th draws), so that a point meets the same
        // draws at every rain rate and the severities differ by their physics, not by which draws
        // the sampling of another rate happened to consume. The distribution is unchanged.
        let noise = rng.normal();
        let (mut counts, mut particles) = (rng.fork(1), rng.fork(2));
        let p_hard = i * (-2.0 * m.alpha * r).pexp() / (r * r);
        let threshold = self.p_min.max(p_hard);
        // Only particles closer than rho_lim can beat the threshold.
        let rho_lim = (m.fresnel / threshold).sqrt().min(r);
        let mut best: Option<(f64, f64)> = None;
        if rho_lim > R_MIN_M {
            let tan_half = self.theta.ptan();
            let volume = std::f64::consts::PI / 3.0 * r * (tan_half * r / 2.0).powi(2);
            let mean = m.density * volume;
            let whole = mean.floor();
            let count = whole as u64 + counts.chance(mean - whole) as u64;
            let near = counts.binomial(count, (rho_lim / r).powi(3));
            for _ in 0..near {
                let rho = rho_lim * particles.f64().pcbrt();
                let d = D_MIN_MM + particles.exponential(1.0 / m.lambda);
                if rho <= R_MIN_M {
                    continue;
                }
                let beam_mm = self.theta * 1e3 * rho;
                let p =
                    m.fresnel * (-2.0 * m.alpha * rho).pexp() * ((d / beam_mm).powi(2)).min(1.0)
                        / (rho * rho);
                if best.is_none_or(|(bp, _)| p > bp) {
                    best = Some((p, rho));
                }
            }
        }
        let max_p = best.map_or(0.0, |b| b.0);
        if p_hard < self.p_min && max_p < self.p_min {
            return Outcome::Lost;
        }
        if let Some((p, rho)) = best
            && p > p_hard
        {
            // The particle's return intensity: its reflectance times the two-way loss.
            return Outcome::Scattered {
                range: rho,
                intensity: (p * rho * rho).min(1.0),
            };
        }
        let sigma = 0.09 / (2.0 * p_hard / self.p_min).max(1e-12).sqrt();
        Outcome::Kept {
            range: r + noise * sigma.min(1.0),
            intensity: i * (-2.0 * m.alpha * r).pexp(),
        }
    }
}

impl LidarPerturbation for Lisa {
    fn plan(&self, points: &Points, frame: &LidarFrame<'_>, plan: &mut Plan) {
        let base = Rng::for_frame(self.seed, frame.seq, self.salt);
        let scale = points.intensity_max as f64;
        let has_i = points.intensity.is_some();
        for i in 0..points.len() {
            // One stream per point: any point can be recomputed on its own.
            let mut rng = base.fork(i as u64);
            let r = points.range(i) as f64;
            let p = points.xyz(i);
            match self.simulate(r, unit_intensity(points, i), &mut rng) {
                Outcome::Lost => {}
                Outcome::Scattered { range, intensity } | Outcome::Kept { range, intensity } => {
                    let k = (range / r.max(1e-9)) as f32;
                    let xyz = [p[0] * k, p[1] * k, p[2] * k];
                    if has_i {
                        plan.emit(i, xyz, (intensity * scale) as f32);
                    } else {
                        plan.moved(i, xyz);
                    }
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn extinction_matches_the_reference_values() {
        // lidar.md: snow R = 0.2 -> 5.8e-4, R = 7.29 -> 4.5e-3; rain R = 7.29 -> 1.3e-3 per metre.
        let a = |k, r| Medium::new(k, r).alpha;
        assert!((a(Precipitation::Snow, 0.2) - 5.8e-4).abs() < 0.1e-4);
        assert!((a(Precipitation::Snow, 7.29) - 4.5e-3).abs() < 0.1e-3);
        assert!((a(Precipitation::Rain, 7.29) - 1.3e-3).abs() < 0.1e-3);
        // Fresnel reflectance of ice and water.
        assert!((Medium::new(Precipitation::Snow, 1.0).fresnel - 0.01732).abs() < 1e-4);
    }
}
