//! Shared test helpers: an independent `f64` reference MLP written with plain loops, an `f64` erf,
//! seeded test data and finite differences.
#![allow(dead_code)]

pub mod rk4;

use dynlab_nn::{Activation, Mlp};

/// Seeded test data in [lo, hi) from SplitMix64 (the crate's own generator is not under test here
/// beyond producing numbers).
pub fn data(seed: u64, n: usize, lo: f32, hi: f32) -> Vec<f32> {
    let mut rng = dynlab_nn::rng::SplitMix64::new(seed);
    (0..n)
        .map(|_| lo + (hi - lo) * rng.next_f64() as f32)
        .collect()
}

/// erf(x) in f64 from the all-positive series erf(x) = 2/√π · e^{−x²} · Σ 2ⁿx^{2n+1}/(1·3·…·(2n+1))
/// (no cancellation; accurate to ~1e-15 for |x| ≤ 6, and erf = ±1 to f64 precision beyond).
pub fn erf64(x: f64) -> f64 {
    if x.abs() > 6.0 {
        return x.signum();
    }
    let x2 = x * x;
    let mut term = x;
    let mut sum = x;
    let mut n = 0.0;
    while term.abs() > 1e-17 * sum.abs() {
        n += 1.0;
        term *= 2.0 * x2 / (2.0 * n + 1.0);
        sum += term;
    }
    2.0 / std::f64::consts::PI.sqrt() * (-x2).exp() * sum
}

/// GELU in f64, exact erf form.
pub fn gelu64(x: f64) -> f64 {
    0.5 * x * (1.0 + erf64(x / std::f64::consts::SQRT_2))
}

/// d/dx GELU in f64.
pub fn gelu_derivative64(x: f64) -> f64 {
    0.5 * (1.0 + erf64(x / std::f64::consts::SQRT_2))
        + x * (-0.5 * x * x).exp() / (2.0 * std::f64::consts::PI).sqrt()
}

pub fn act64(a: Activation, x: f64) -> f64 {
    match a {
        Activation::Tanh => x.tanh(),
        Activation::Gelu => gelu64(x),
        Activation::Relu => x.max(0.0),
        Activation::Identity => x,
    }
}

/// The same network in f64, evaluated with textbook loops and libm/series activations.
pub struct Reference {
    pub sizes: Vec<usize>,
    pub acts: Vec<Activation>,
    pub params: Vec<f64>,
}

impl Reference {
    pub fn of(mlp: &Mlp) -> Self {
        Self {
            sizes: mlp.sizes().to_vec(),
            acts: mlp.spec().activations().to_vec(),
            params: mlp.params().iter().map(|&p| f64::from(p)).collect(),
        }
    }

    pub fn n_in(&self) -> usize {
        self.sizes[0]
    }

    pub fn n_out(&self) -> usize {
        *self.sizes.last().unwrap()
    }

    /// One sample.
    pub fn eval(&self, params: &[f64], x: &[f64]) -> Vec<f64> {
        let mut h = x.to_vec();
        let mut off = 0;
        let n_layers = self.sizes.len() - 1;
        for l in 0..n_layers {
            let (n_in, n_out) = (self.sizes[l], self.sizes[l + 1]);
            let w = &params[off..off + n_in * n_out];
            let b = &params[off + n_in * n_out..off + n_in * n_out + n_out];
            off += n_in * n_out + n_out;
            let mut next = vec![0.0; n_out];
            for o in 0..n_out {
                let mut s = b[o];
                for i in 0..n_in {
                    s += w[o * n_in + i] * h[i];
                }
                next[o] = if l + 1 < n_layers {
                    act64(self.acts[l], s)
                } else {
                    s
                };
            }
            h = next;
        }
        h
    }

    /// A batch, row-major.
    pub fn eval_batch(&self, x: &[f32]) -> Vec<f64> {
        x.chunks(self.n_in())
            .flat_map(|r| {
                let r: Vec<f64> = r.iter().map(|&v| f64::from(v)).collect();
                self.eval(&self.params, &r)
            })
            .collect()
    }

    /// Central-difference Jacobian ∂f/∂x (n_out × n_in) at one sample, step h.
    pub fn fd_jacobian(&self, x: &[f64], h: f64) -> Vec<f64> {
        let (n_in, n_out) = (self.n_in(), self.n_out());
        let mut j = vec![0.0; n_out * n_in];
        for i in 0..n_in {
            let mut xp = x.to_vec();
            let mut xm = x.to_vec();
            xp[i] += h;
            xm[i] -= h;
            let (fp, fm) = (self.eval(&self.params, &xp), self.eval(&self.params, &xm));
            for o in 0..n_out {
                j[o * n_in + i] = (fp[o] - fm[o]) / (2.0 * h);
            }
        }
        j
    }

    /// Central-difference gradient of L(θ) = Σ_batch dy·f(x; θ) with respect to parameter k.
    pub fn fd_param_grad(&self, x: &[f32], dy: &[f32], k: usize, h: f64) -> f64 {
        let loss = |p: &[f64]| -> f64 {
            x.chunks(self.n_in())
                .zip(dy.chunks(self.n_out()))
                .map(|(r, d)| {
                    let r: Vec<f64> = r.iter().map(|&v| f64::from(v)).collect();
                    self.eval(p, &r)
                        .iter()
                        .zip(d)
                        .map(|(y, &d)| y * f64::from(d))
                        .sum::<f64>()
                })
                .sum()
        };
        let mut pp = self.params.clone();
        let mut pm = self.params.clone();
        pp[k] += h;
        pm[k] -= h;
        (loss(&pp) - loss(&pm)) / (2.0 * h)
    }
}

/// max |a − b| relative to max(|b|, floor) over the slices.
pub fn max_rel_err(a: &[f32], b: &[f64], floor: f64) -> f64 {
    assert_eq!(a.len(), b.len());
    let scale = b.iter().fold(floor, |m, v| m.max(v.abs()));
    a.iter()
        .zip(b)
        .map(|(&a, &b)| (f64::from(a) - b).abs())
        .fold(0.0, f64::max)
        / scale
}
