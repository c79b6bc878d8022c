//! Small statistics for the comparison: robust ranges, bins, correlations at lags.

/// The `q`-quantile (0…1) of finite values (nearest rank); `None` when there are none.
pub fn quantile(values: &[f64], q: f64) -> Option<f64> {
    let mut v: Vec<f64> = values.iter().copied().filter(|x| x.is_finite()).collect();
    if v.is_empty() {
        return None;
    }
    let k = ((v.len() - 1) as f64 * q.clamp(0.0, 1.0)).round() as usize;
    let (_, x, _) = v.select_nth_unstable_by(k, f64::total_cmp);
    Some(*x)
}

/// `n` equal bins over the 1st…99th percentile of `values` (`n + 1` edges); values outside fall
/// into the end bins. `None` when there is no finite value. A constant quantity gets one bin of
/// width 1 around its value.
pub fn robust_edges(values: &[f64], n: usize) -> Option<Vec<f64>> {
    let lo = quantile(values, 0.01)?;
    let hi = quantile(values, 0.99)?;
    let n = n.max(1);
    if hi > lo {
        Some(
            (0..=n)
                .map(|i| lo + (hi - lo) * i as f64 / n as f64)
                .collect(),
        )
    } else {
        Some(vec![lo - 0.5, lo + 0.5])
    }
}

/// The bin of `v` for these edges (clamped to the end bins); `None` for a non-finite value.
pub fn bin_of(edges: &[f64], v: f64) -> Option<usize> {
    if !v.is_finite() || edges.len() < 2 {
        return None;
    }
    let n = edges.len() - 1;
    let i = edges[1..n].partition_point(|&e| e <= v);
    Some(i.min(n - 1))
}

/// Pooled correlation of `a_t` with `b_{t−lag}` over several sequences (each pair `(a, b)` of
/// equal length; lags never cross a sequence's end), for every lag in `−max_lag…=max_lag`.
/// Positive lag: `b` leads `a`. Means are pooled over all sequences. Returns the coefficients
/// and the number of samples `N` (for the ±1.96/√N band).
pub fn cross_correlation(pairs: &[(&[f64], &[f64])], max_lag: usize) -> (Vec<f64>, usize) {
    let l = max_lag as isize;
    let mut n = 0usize;
    let (mut sa, mut sb) = (0.0, 0.0);
    for (a, b) in pairs {
        n += a.len().min(b.len());
        sa += a.iter().sum::<f64>();
        sb += b.iter().sum::<f64>();
    }
    if n == 0 {
        return (vec![0.0; 2 * max_lag + 1], 0);
    }
    let (ma, mb) = (sa / n as f64, sb / n as f64);
    let (mut va, mut vb) = (0.0, 0.0);
    for (a, b) in pairs {
        va += a.iter().map(|x| (x - ma) * (x - ma)).sum::<f64>();
        vb += b.iter().map(|x| (x - mb) * (x - mb)).sum::<f64>();
    }
    let den = (va * vb).sqrt();
    let mut out = Vec::with_capacity(2 * max_lag + 1);
    for lag in -l..=l {
        let mut s = 0.0;
        for (a, b) in pairs {
            let m = a.len().min(b.len()) as isize;
            let (t0, t1) = (lag.max(0), (m + lag.min(0)).min(m));
            for t in t0..t1 {
                s += (a[t as usize] - ma) * (b[(t - lag) as usize] - mb);
            }
        }
        out.push(if den > 0.0 { s / den } else { 0.0 });
    }
    (out, n)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bins_clamp_to_the_ends() {
        let e = vec![0.0, 1.0, 2.0, 3.0];
        assert_eq!(bin_of(&e, -5.0), Some(0));
        assert_eq!(bin_of(&e, 0.5), Some(0));
        assert_eq!(bin_of(&e, 1.0), Some(1));
        assert_eq!(bin_of(&e, 2.9), Some(2));
        assert_eq!(bin_of(&e, 9.0), Some(2));
        assert_eq!(bin_of(&e, f64::NAN), None);
    }

    #[test]
    fn robust_edges_ignore_outliers_and_handle_constants() {
        let mut v: Vec<f64> = (0..1000).map(|i| i as f64 / 1000.0).collect();
        v.push(1e9);
        let e = robust_edges(&v, 4).unwrap();
        assert_eq!(e.len(), 5);
        assert!(e[4] < 1.0 + 1e-9, "{e:?}");
        let c = robust_edges(&[2.0; 10], 5).unwrap();
        assert_eq!(c, vec![1.5, 2.5]);
    }

    #[test]
    fn cross_correlation_finds_a_known_delay() {
        // a_t = b_{t-3} + small noise-free offset: peak at lag +3
        let b: Vec<f64> = (0..500)
            .map(|i| ((i * 7919) % 101) as f64 / 101.0 - 0.5)
            .collect();
        let a: Vec<f64> = (0..500)
            .map(|i| if i >= 3 { b[i - 3] } else { 0.0 })
            .collect();
        let (r, n) = cross_correlation(&[(&a, &b)], 5);
        assert_eq!(n, 500);
        let (imax, rmax) = r
            .iter()
            .enumerate()
            .max_by(|x, y| x.1.total_cmp(y.1))
            .unwrap();
        assert_eq!(imax as isize - 5, 3);
        assert!(*rmax > 0.95);
        // autocorrelation at lag 0 is 1
        let (ac, _) = cross_correlation(&[(&a, &a)], 2);
        assert!((ac[2] - 1.0).abs() < 1e-12);
    }
}
