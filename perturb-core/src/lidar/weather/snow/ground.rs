//! The ground's part: the sensor's noise floor fitted on the weakest ground returns, and the
//! wet road's dimming.

use crate::lidar::Points;
use crate::math::Portable;

/// The noise floor: 0.7 of a quadratic fit, over distance, of the weakest ground returns (the 5th
/// percentile of each 2 m distance bin), on 0..255. Without enough ground it is 0.
pub fn noise_floor(points: &Points, ground: &[bool], to255: f64) -> [f64; 3] {
    let mut bins: Vec<Vec<f64>> = vec![Vec::new(); 50];
    for (i, g) in ground.iter().enumerate() {
        if !g {
            continue;
        }
        let d = points.range(i) as f64;
        let b = (d / 2.0) as usize;
        if b < bins.len() {
            bins[b].push(points.intensity(i) as f64 * to255);
        }
    }
    let samples: Vec<(f64, f64)> = bins
        .iter_mut()
        .enumerate()
        .filter(|(_, v)| v.len() >= 20)
        .map(|(b, v)| {
            v.sort_by(f64::total_cmp);
            (b as f64 * 2.0 + 1.0, v[v.len() / 20])
        })
        .collect();
    if samples.len() < 3 {
        return [0.0; 3];
    }
    // Least squares for a + b d + c d^2.
    let mut m = [[0f64; 4]; 3];
    for &(d, y) in &samples {
        let row = [1.0, d, d * d];
        for r in 0..3 {
            for c in 0..3 {
                m[r][c] += row[r] * row[c];
            }
            m[r][3] += row[r] * y;
        }
    }
    for col in 0..3 {
        let piv = (col..3)
            .max_by(|&a, &b| m[a][col].abs().total_cmp(&m[b][col].abs()))
            .unwrap_or(col);
        m.swap(col, piv);
        if m[col][col].abs() < 1e-12 {
            return [0.0; 3];
        }
        for r in 0..3 {
            if r != col {
                let f = m[r][col] / m[col][col];
                let pivot_row = m[col];
                for (v, p) in m[r].iter_mut().zip(pivot_row).skip(col) {
                    *v -= f * p;
                }
            }
        }
    }
    [
        0.7 * m[0][3] / m[0][0],
        0.7 * m[1][3] / m[1][1],
        0.7 * m[2][3] / m[2][2],
    ]
}

/// Intensity factor of a wet road at incidence angle `theta` (radians from the surface normal):
/// the beam crosses the 1 mm water film twice; the share the water surface reflects away
/// (unpolarised Fresnel, n = 1.33) is lost to the sensor, so the diffuse return of the pavement
/// is scaled by the two-way transmittance (1 - R(theta))^2.
pub fn wet_ground_factor(theta: f64) -> f64 {
    let n = 1.33f64;
    let ci = theta.pcos().clamp(0.0, 1.0);
    let st = theta.psin() / n;
    let ct = (1.0 - st * st).max(0.0).sqrt();
    let rs = ((ci - n * ct) / (ci + n * ct)).powi(2);
    let rp = ((ct - n * ci) / (ct + n * ci)).powi(2);
    let r = 0.5 * (rs + rp);
    (1.0 - r).powi(2)
}
