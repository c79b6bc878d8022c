//! Standard errors of the physics fits, clustered by trajectory: the delete-one-cluster
//! jackknife against refits without each cluster, and against the sandwich where one cluster
//! carries the fit.

use dynlab_learn::fit::{cluster_jackknife_std, cluster_std};

/// Uniform draws in `[lo, hi)` from a seeded xorshift generator.
struct Draws(u64);

impl Draws {
    fn uniform(&mut self, lo: f64, hi: f64) -> f64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        lo + (hi - lo) * (self.0 >> 11) as f64 / (1u64 << 53) as f64
    }
}

/// `y = 1 + 2x + noise`, clusters of 20 points; `x` of cluster `lever` scaled by 50.
fn line(clusters: usize, lever: Option<usize>, seed: u64) -> (Vec<f64>, Vec<f64>, Vec<usize>) {
    let mut rng = Draws(0x9E37_79B9_7F4A_7C15 ^ seed);
    let (mut x, mut y, mut c) = (Vec::new(), Vec::new(), Vec::new());
    for g in 0..clusters {
        let shift = rng.uniform(-0.3, 0.3); // correlated within the cluster
        for _ in 0..20 {
            let scale = if Some(g) == lever { 50.0 } else { 1.0 };
            let xi = scale * rng.uniform(-1.0, 1.0);
            x.push(xi);
            y.push(1.0 + 2.0 * xi + shift + rng.uniform(-0.1, 0.1));
            c.push(g);
        }
    }
    (x, y, c)
}

/// Least squares of `y` on `(1, x)` over the points `keep`.
fn fit(x: &[f64], y: &[f64], keep: impl Fn(usize) -> bool) -> [f64; 2] {
    let (mut n, mut sx, mut sxx, mut sy, mut sxy) = (0.0, 0.0, 0.0, 0.0, 0.0);
    for i in (0..x.len()).filter(|&i| keep(i)) {
        n += 1.0;
        sx += x[i];
        sxx += x[i] * x[i];
        sy += y[i];
        sxy += x[i] * y[i];
    }
    let det = n * sxx - sx * sx;
    [(sxx * sy - sx * sxy) / det, (n * sxy - sx * sy) / det]
}

/// The Jacobian (`m × 2`) and residuals `model − data` at `theta`.
fn jac_res(x: &[f64], y: &[f64], theta: [f64; 2]) -> (Vec<f64>, Vec<f64>) {
    let jac = x.iter().flat_map(|&xi| [1.0, xi]).collect();
    let r = x
        .iter()
        .zip(y)
        .map(|(xi, yi)| theta[0] + theta[1] * xi - yi)
        .collect();
    (jac, r)
}

/// A line fitted to [`line`]'s points: the points, their clusters, and the Jacobian and
/// residuals at the fit.
struct Fitted {
    x: Vec<f64>,
    y: Vec<f64>,
    c: Vec<usize>,
    jac: Vec<f64>,
    r: Vec<f64>,
}

fn fitted(clusters: usize, lever: Option<usize>, seed: u64) -> Fitted {
    let (x, y, c) = line(clusters, lever, seed);
    let (jac, r) = jac_res(&x, &y, fit(&x, &y, |_| true));
    Fitted { x, y, c, jac, r }
}

#[test]
fn the_jackknife_of_a_linear_fit_is_that_of_its_refits_without_each_cluster() {
    let Fitted { x, y, c, jac, r } = fitted(8, Some(3), 7);
    let std = cluster_jackknife_std(&jac, &r, 2, &[true, true], &c);
    let g = 8.0;
    for (k, got) in std.iter().enumerate() {
        let est: Vec<f64> = (0..8).map(|h| fit(&x, &y, |i| c[i] != h)[k]).collect();
        let mean = est.iter().sum::<f64>() / g;
        let var = est.iter().map(|e| (e - mean).powi(2)).sum::<f64>() * (g - 1.0) / g;
        let want = var.sqrt();
        assert!(
            (got - want).abs() <= 1e-6 * want,
            "parameter {k}: {got} against {want}"
        );
    }
}

#[test]
fn one_cluster_that_carries_the_slope_widens_the_jackknife_not_the_sandwich() {
    let Fitted { c, jac, r, .. } = fitted(8, Some(3), 7);
    let jack = cluster_jackknife_std(&jac, &r, 2, &[true, true], &c);
    let sandwich = cluster_std(&jac, &r, 2, &[true, true], &c);
    assert!(
        jack[1] > 3.0 * sandwich[1],
        "slope: jackknife {} sandwich {}",
        jack[1],
        sandwich[1]
    );
    // balanced clusters: the two agree
    let Fitted { c, jac, r, .. } = fitted(30, None, 8);
    let jack = cluster_jackknife_std(&jac, &r, 2, &[true, true], &c);
    let sandwich = cluster_std(&jac, &r, 2, &[true, true], &c);
    for k in 0..2 {
        let ratio = jack[k] / sandwich[k];
        assert!((0.8..1.5).contains(&ratio), "parameter {k}: ratio {ratio}");
    }
}

#[test]
fn fixed_parameters_get_zero_and_a_single_cluster_nothing() {
    let Fitted { c, jac, r, .. } = fitted(4, None, 9);
    let std = cluster_jackknife_std(&jac, &r, 2, &[false, true], &c);
    assert_eq!(std[0], 0.0);
    assert!(std[1] > 0.0 && std[1].is_finite());
    let one = vec![0; c.len()];
    let std = cluster_jackknife_std(&jac, &r, 2, &[true, true], &one);
    assert!(std.iter().all(|v| v.is_nan()));
}
