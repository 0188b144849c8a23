//! Correlation coefficients (used by the courtesy evaluation and the ground-truth check).

/// Pearson correlation; `None` with fewer than 2 points or a constant series.
pub fn pearson(x: &[f64], y: &[f64]) -> Option<f64> {
    let n = x.len().min(y.len());
    if n < 2 {
        return None;
    }
    let (mx, my) = (
        x[..n].iter().sum::<f64>() / n as f64,
        y[..n].iter().sum::<f64>() / n as f64,
    );
    let (mut sxy, mut sxx, mut syy) = (0.0, 0.0, 0.0);
    for i in 0..n {
        let (dx, dy) = (x[i] - mx, y[i] - my);
        sxy += dx * dy;
        sxx += dx * dx;
        syy += dy * dy;
    }
    (sxx > 0.0 && syy > 0.0).then(|| sxy / (sxx * syy).sqrt())
}

/// Ranks with ties given their average rank.
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
        for &k in &idx[i..=j] {
            r[k] = (i + j) as f64 / 2.0;
        }
        i = j + 1;
    }
    r
}

/// Spearman rank correlation (Pearson of average ranks).
pub fn spearman(x: &[f64], y: &[f64]) -> Option<f64> {
    pearson(&ranks(x), &ranks(y))
}

/// Spearman(x, y) of one group (one scene's courtesy knob) when `y` spans at least
/// `min_range`, else `None`: a group whose `y` does not respond to `x` has no rank order to
/// follow, and ties of float noise would give it an arbitrary one. `None` too when any `y` is
/// not finite.
pub fn spearman_if_responsive(x: &[f64], y: &[f64], min_range: f64) -> Option<f64> {
    if !y.iter().all(|v| v.is_finite()) {
        return None;
    }
    let (lo, hi) = y
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &v| {
            (lo.min(v), hi.max(v))
        });
    (hi - lo >= min_range).then(|| spearman(x, y)).flatten()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn spearman_of_a_responsive_group_only() {
        let x = [0.1, 0.5, 0.9];
        assert_eq!(spearman_if_responsive(&x, &[1.0, 1.005, 1.002], 0.01), None);
        assert_eq!(
            spearman_if_responsive(&x, &[1.0, 1.5, 2.0], 0.01),
            Some(1.0)
        );
        assert_eq!(
            spearman_if_responsive(&x, &[2.0, 1.5, 1.0], 0.01),
            Some(-1.0)
        );
        assert_eq!(spearman_if_responsive(&x, &[f64::NAN; 3], 0.01), None);
        assert_eq!(
            spearman_if_responsive(&x, &[1.0, f64::NAN, 2.0], 0.01),
            None
        );
    }

    #[test]
    fn known_values() {
        assert!((pearson(&[1.0, 2.0, 3.0], &[2.0, 4.0, 6.0]).unwrap() - 1.0).abs() < 1e-12);
        assert!(
            (spearman(&[1.0, 2.0, 3.0, 4.0], &[1.0, 8.0, 27.0, 64.0]).unwrap() - 1.0).abs() < 1e-12
        );
        assert!((spearman(&[1.0, 2.0, 3.0], &[3.0, 2.0, 1.0]).unwrap() + 1.0).abs() < 1e-12);
        // Ties: ranks (0, 1.5, 1.5, 3).
        assert_eq!(ranks(&[1.0, 2.0, 2.0, 5.0]), vec![0.0, 1.5, 1.5, 3.0]);
        // x = (1,2,3,4,5), y = (2,1,4,3,5): Σd² = 4, ρ = 1 − 6·4/(5·24) = 0.8.
        assert!(
            (spearman(&[1.0, 2.0, 3.0, 4.0, 5.0], &[2.0, 1.0, 4.0, 3.0, 5.0]).unwrap() - 0.8).abs()
                < 1e-12
        );
        assert_eq!(pearson(&[1.0, 1.0], &[1.0, 2.0]), None);
    }
}
