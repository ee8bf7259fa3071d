//! The statistics of the transfer analysis: Spearman's rank correlation with its two-sided
//! p-value (Student's t with n - 2 degrees of freedom, as scipy's `spearmanr`), percentile
//! bootstrap confidence intervals, Benjamini-Hochberg q-values and top-k overlap; DBSCAN over
//! 2-D points for the failure hotspots.

/// Ranks 1..n, ties sharing their average rank.
pub fn ranks(v: &[f64]) -> Vec<f64> {
    let mut idx: Vec<usize> = (0..v.len()).collect();
    idx.sort_by(|&a, &b| v[a].total_cmp(&v[b]));
    let mut r = vec![0.0; v.len()];
    let mut i = 0;
    while i < idx.len() {
        let mut j = i;
        while j + 1 < idx.len() && v[idx[j + 1]] == v[idx[i]] {
            j += 1;
        }
        let avg = (i + j) as f64 / 2.0 + 1.0;
        for k in i..=j {
            r[idx[k]] = avg;
        }
        i = j + 1;
    }
    r
}

/// Pearson's correlation; None when either side is constant or there are fewer than 2 values.
pub fn pearson(x: &[f64], y: &[f64]) -> Option<f64> {
    let n = x.len();
    if n < 2 || n != y.len() {
        return None;
    }
    let mx = x.iter().sum::<f64>() / n as f64;
    let my = y.iter().sum::<f64>() / n as f64;
    let (mut sxy, mut sxx, mut syy) = (0.0, 0.0, 0.0);
    for i in 0..n {
        let (dx, dy) = (x[i] - mx, y[i] - my);
        sxy += dx * dy;
        sxx += dx * dx;
        syy += dy * dy;
    }
    if sxx <= 0.0 || syy <= 0.0 {
        return None;
    }
    Some((sxy / (sxx * syy).sqrt()).clamp(-1.0, 1.0))
}

/// Spearman's rho (Pearson's correlation of the ranks).
pub fn spearman(x: &[f64], y: &[f64]) -> Option<f64> {
    pearson(&ranks(x), &ranks(y))
}

/// ln Γ(x) for x > 0 (Lanczos approximation, g = 7, 9 coefficients).
fn ln_gamma(x: f64) -> f64 {
    const G: [f64; 9] = [
        0.999_999_999_999_809_9,
        676.520_368_121_885_1,
        -1_259.139_216_722_402_8,
        771.323_428_777_653_1,
        -176.615_029_162_140_6,
        12.507_343_278_686_905,
        -0.138_571_095_265_720_12,
        9.984_369_578_019_572e-6,
        1.505_632_735_149_311_6e-7,
    ];
    if x < 0.5 {
        // Reflection.
        let pi = std::f64::consts::PI;
        return (pi / (pi * x).sin()).ln() - ln_gamma(1.0 - x);
    }
    let x = x - 1.0;
    let mut a = G[0];
    let t = x + 7.5;
    for (i, g) in G.iter().enumerate().skip(1) {
        a += g / (x + i as f64);
    }
    0.5 * (2.0 * std::f64::consts::PI).ln() + (x + 0.5) * t.ln() - t + a.ln()
}

/// The continued fraction of the incomplete beta function (modified Lentz).
fn beta_cf(a: f64, b: f64, x: f64) -> f64 {
    const TINY: f64 = 1e-300;
    let (qab, qap, qam) = (a + b, a + 1.0, a - 1.0);
    let mut c = 1.0;
    let mut d = 1.0 - qab * x / qap;
    if d.abs() < TINY {
        d = TINY;
    }
    d = 1.0 / d;
    let mut h = d;
    for m in 1..=10_000 {
        let m = m as f64;
        let m2 = 2.0 * m;
        let aa = m * (b - m) * x / ((qam + m2) * (a + m2));
        d = 1.0 + aa * d;
        if d.abs() < TINY {
            d = TINY;
        }
        c = 1.0 + aa / c;
        if c.abs() < TINY {
            c = TINY;
        }
        d = 1.0 / d;
        h *= d * c;
        let aa = -(a + m) * (qab + m) * x / ((a + m2) * (qap + m2));
        d = 1.0 + aa * d;
        if d.abs() < TINY {
            d = TINY;
        }
        c = 1.0 + aa / c;
        if c.abs() < TINY {
            c = TINY;
        }
        d = 1.0 / d;
        let del = d * c;
        h *= del;
        if (del - 1.0).abs() < 1e-15 {
            break;
        }
    }
    h
}

/// The regularised incomplete beta function I_x(a, b).
pub fn beta_inc(a: f64, b: f64, x: f64) -> f64 {
    if x <= 0.0 {
        return 0.0;
    }
    if x >= 1.0 {
        return 1.0;
    }
    let ln_front = ln_gamma(a + b) - ln_gamma(a) - ln_gamma(b) + a * x.ln() + b * (1.0 - x).ln();
    let front = ln_front.exp();
    if x < (a + 1.0) / (a + b + 2.0) {
        front * beta_cf(a, b, x) / a
    } else {
        1.0 - front * beta_cf(b, a, 1.0 - x) / b
    }
}

/// Two-sided p-value of Student's t with `df` degrees of freedom.
pub fn t_two_sided(t: f64, df: f64) -> f64 {
    if !t.is_finite() {
        return 0.0;
    }
    beta_inc(df / 2.0, 0.5, df / (df + t * t)).clamp(0.0, 1.0)
}

/// The two-sided p-value of Spearman's rho over n pairs (t = rho sqrt((n-2)/(1-rho^2)), n - 2
/// degrees of freedom; scipy's `spearmanr`). None for n < 3.
pub fn spearman_p(rho: f64, n: usize) -> Option<f64> {
    if n < 3 {
        return None;
    }
    let df = (n - 2) as f64;
    if (1.0 - rho.abs()) <= 0.0 {
        return Some(0.0);
    }
    let t = rho * (df / ((1.0 + rho) * (1.0 - rho))).sqrt();
    Some(t_two_sided(t, df))
}

/// Benjamini-Hochberg adjusted p-values (q-values), in the input order; NaN p-values stay NaN
/// and are not counted (scipy's `false_discovery_control(method='bh')` on the finite ones).
pub fn benjamini_hochberg(p: &[f64]) -> Vec<f64> {
    let idx: Vec<usize> = (0..p.len()).filter(|&i| p[i].is_finite()).collect();
    let m = idx.len() as f64;
    let mut order = idx.clone();
    order.sort_by(|&a, &b| p[a].total_cmp(&p[b]));
    let mut q = vec![f64::NAN; p.len()];
    let mut running = f64::INFINITY;
    for (rank, &i) in order.iter().enumerate().rev() {
        let v = p[i] * m / (rank + 1) as f64;
        running = running.min(v);
        q[i] = running.min(1.0);
    }
    q
}

/// The `q`-th percentile (0..100) of sorted values, linear between closest ranks (numpy's
/// default).
pub fn percentile(sorted: &[f64], q: f64) -> f64 {
    if sorted.is_empty() {
        return f64::NAN;
    }
    let pos = q / 100.0 * (sorted.len() - 1) as f64;
    let (lo, hi) = (pos.floor() as usize, pos.ceil() as usize);
    sorted[lo] + (sorted[hi] - sorted[lo]) * (pos - lo as f64)
}

/// The indices of bootstrap resample `k` of `n` items (drawn with replacement from `seed` with
/// the project's counter-keyed generator: resample k depends on (seed, k) only).
pub fn resample(n: usize, k: usize, seed: u64) -> impl Iterator<Item = usize> {
    let mut rng = perturb_core::rng::Rng::for_frame(seed, k as u64, 0xB007_57A9);
    (0..n).map(move |_| rng.below(n as u64) as usize)
}

/// A percentile bootstrap confidence interval of Spearman's rho: `resamples` resamples of the
/// pairs with replacement, drawn from `seed` (the project's counter-keyed generator, so the
/// interval is reproducible); resamples where rho is undefined (a constant side) are skipped.
/// Returns (low, high, resamples used), None when no resample had a defined rho.
pub fn bootstrap_spearman_ci(
    x: &[f64],
    y: &[f64],
    resamples: usize,
    seed: u64,
    level: f64,
) -> Option<(f64, f64, usize)> {
    let n = x.len();
    if n < 2 {
        return None;
    }
    let mut rhos = Vec::with_capacity(resamples);
    let (mut xs, mut ys) = (vec![0.0; n], vec![0.0; n]);
    for k in 0..resamples {
        for (i, j) in resample(n, k, seed).enumerate() {
            xs[i] = x[j];
            ys[i] = y[j];
        }
        if let Some(r) = spearman(&xs, &ys) {
            rhos.push(r);
        }
    }
    if rhos.is_empty() {
        return None;
    }
    rhos.sort_by(f64::total_cmp);
    let tail = (100.0 - level * 100.0) / 2.0;
    Some((
        percentile(&rhos, tail),
        percentile(&rhos, 100.0 - tail),
        rhos.len(),
    ))
}

/// Overlap of the top `k` items of two rankings (largest values first; ties broken by the
/// item's position): shared items / k.
pub fn top_k_overlap(a: &[f64], b: &[f64], k: usize) -> Option<f64> {
    if k == 0 || a.len() != b.len() || a.len() < k {
        return None;
    }
    let top = |v: &[f64]| {
        let mut idx: Vec<usize> = (0..v.len()).collect();
        idx.sort_by(|&i, &j| v[j].total_cmp(&v[i]).then(i.cmp(&j)));
        idx.truncate(k);
        idx
    };
    let (ta, tb) = (top(a), top(b));
    Some(ta.iter().filter(|i| tb.contains(i)).count() as f64 / k as f64)
}

/// DBSCAN over 2-D points: `eps` neighbourhood radius, `min_points` neighbours (the point
/// itself included) that make a core point. Returns each point's cluster (0, 1, ... in order of
/// discovery) or None for noise.
pub fn dbscan(points: &[[f64; 2]], eps: f64, min_points: usize) -> Vec<Option<usize>> {
    let n = points.len();
    let near = |i: usize| -> Vec<usize> {
        (0..n)
            .filter(|&j| (points[i][0] - points[j][0]).hypot(points[i][1] - points[j][1]) <= eps)
            .collect()
    };
    let mut label: Vec<Option<usize>> = vec![None; n];
    let mut visited = vec![false; n];
    let mut next = 0;
    for i in 0..n {
        if visited[i] {
            continue;
        }
        visited[i] = true;
        let nb = near(i);
        if nb.len() < min_points {
            continue;
        }
        let c = next;
        next += 1;
        label[i] = Some(c);
        let mut queue = nb;
        let mut k = 0;
        while k < queue.len() {
            let j = queue[k];
            k += 1;
            if label[j].is_none() {
                label[j] = Some(c);
            }
            if visited[j] {
                continue;
            }
            visited[j] = true;
            let nb = near(j);
            if nb.len() >= min_points {
                queue.extend(nb.into_iter().filter(|q| label[*q].is_none()));
            }
        }
    }
    label
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ranks_average_ties() {
        assert_eq!(ranks(&[3.0, 1.0, 3.0, 2.0]), vec![3.5, 1.0, 3.5, 2.0]);
    }

    #[test]
    fn incomplete_beta_known_values() {
        // I_x(1, 1) = x; I_0.5(a, a) = 0.5; I_x(2, 3) = P(Binomial(4, x) >= 2).
        assert!((beta_inc(1.0, 1.0, 0.3) - 0.3).abs() < 1e-12);
        assert!((beta_inc(4.5, 4.5, 0.5) - 0.5).abs() < 1e-12);
        let x: f64 = 0.4;
        let exact = 6.0 * x.powi(2) * (1.0 - x).powi(2) + 4.0 * x.powi(3) * (1.0 - x) + x.powi(4);
        assert!((beta_inc(2.0, 3.0, x) - exact).abs() < 1e-12);
        // t = 2.0 with 10 degrees of freedom: two-sided p = 0.07338803...
        assert!((t_two_sided(2.0, 10.0) - 0.073_388_034_770_740_3).abs() < 1e-9);
    }

    #[test]
    fn bh_matches_the_definition() {
        let q = benjamini_hochberg(&[0.01, 0.04, 0.03, 0.2]);
        // sorted 0.01, 0.03, 0.04, 0.2 -> 0.04, 0.0533, 0.0533, 0.2
        let want = [0.04, 0.16 / 3.0, 0.16 / 3.0, 0.2];
        for (a, b) in q.iter().zip(want) {
            assert!((a - b).abs() < 1e-12, "{q:?}");
        }
    }

    #[test]
    fn top_k_counts_shared_items() {
        let a = [5.0, 4.0, 3.0, 2.0, 1.0];
        let b = [1.0, 4.0, 5.0, 2.0, 3.0];
        assert_eq!(top_k_overlap(&a, &b, 2), Some(0.5));
        assert_eq!(top_k_overlap(&a, &b, 6), None);
    }
}
