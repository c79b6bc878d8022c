//! Test vector fields with hand-written exact derivatives.
#![allow(dead_code)]

use dynlab_dynamics::ode::{InputTape, VectorField};
use dynlab_dynamics::real::Scalar;

/// `ṡ = A s + B u` with parameters `θ = [A (row-major), B (row-major)]`.
pub struct Linear<T> {
    pub ds: usize,
    pub du: usize,
    pub theta: Vec<T>,
}

impl<T: Scalar> Linear<T> {
    pub fn new(ds: usize, du: usize, a: &[f64], b: &[f64]) -> Self {
        let theta = a.iter().chain(b.iter()).map(|&v| T::from_f64(v)).collect();
        Self { ds, du, theta }
    }
    fn apply(&self, s: &[T], u: &[T], out: &mut [T]) {
        let (ds, du) = (self.ds, self.du);
        for r in 0..ds {
            let mut acc = T::zero();
            for c in 0..ds {
                acc += self.theta[r * ds + c] * s[c];
            }
            for c in 0..du {
                acc += self.theta[ds * ds + r * du + c] * u[c];
            }
            out[r] = acc;
        }
    }
}

impl<T: Scalar> VectorField<T> for Linear<T> {
    type Tape = InputTape<T>;
    fn dim_s(&self) -> usize {
        self.ds
    }
    fn dim_u(&self) -> usize {
        self.du
    }
    fn n_params(&self) -> usize {
        self.theta.len()
    }
    fn eval(&self, n: usize, s: &[T], u: &[T], out: &mut [T]) {
        let (ds, du) = (self.ds, self.du);
        for i in 0..n {
            self.apply(
                &s[i * ds..(i + 1) * ds],
                &u[i * du..(i + 1) * du],
                &mut out[i * ds..(i + 1) * ds],
            );
        }
    }
    fn eval_taped(&self, n: usize, s: &[T], u: &[T], out: &mut [T], tape: &mut Self::Tape) {
        tape.record(n, s, u);
        self.eval(n, s, u, out);
    }
    fn vjp(&self, tape: &Self::Tape, ybar: &[T], sbar: &mut [T], ubar: &mut [T], pbar: &mut [T]) {
        let (ds, du) = (self.ds, self.du);
        for i in 0..tape.n {
            let yb = &ybar[i * ds..(i + 1) * ds];
            for c in 0..ds {
                let mut acc = T::zero();
                for r in 0..ds {
                    acc += self.theta[r * ds + c] * yb[r];
                }
                sbar[i * ds + c] = acc;
            }
            for c in 0..du {
                let mut acc = T::zero();
                for r in 0..ds {
                    acc += self.theta[ds * ds + r * du + c] * yb[r];
                }
                ubar[i * du + c] = acc;
            }
            if !pbar.is_empty() {
                for r in 0..ds {
                    for c in 0..ds {
                        pbar[r * ds + c] += yb[r] * tape.s[i * ds + c];
                    }
                    for c in 0..du {
                        pbar[ds * ds + r * du + c] += yb[r] * tape.u[i * du + c];
                    }
                }
            }
        }
    }
    fn jvp(
        &self,
        n: usize,
        s: &[T],
        u: &[T],
        sdot: &[T],
        udot: &[T],
        out: &mut [T],
        out_dot: &mut [T],
    ) {
        self.eval(n, s, u, out);
        self.eval(n, sdot, udot, out_dot);
    }
}

/// A damped, driven pendulum: `ṡ0 = s1`, `ṡ1 = −θ0 sin s0 − θ1 s1 + θ2 u0·cos(s0)`.
pub struct Pendulum {
    pub theta: [f64; 3],
}

impl Pendulum {
    fn f(&self, s: &[f64], u: &[f64], out: &mut [f64]) {
        let [a, b, c] = self.theta;
        out[0] = s[1];
        out[1] = -a * s[0].sin() - b * s[1] + c * u[0] * s[0].cos();
    }
    /// Jacobian rows: ∂f/∂[s0, s1, u0, θ0, θ1, θ2].
    fn jac(&self, s: &[f64], u: &[f64]) -> [[f64; 6]; 2] {
        let [a, b, c] = self.theta;
        [
            [0.0, 1.0, 0.0, 0.0, 0.0, 0.0],
            [
                -a * s[0].cos() - c * u[0] * s[0].sin(),
                -b,
                c * s[0].cos(),
                -s[0].sin(),
                -s[1],
                u[0] * s[0].cos(),
            ],
        ]
    }
}

impl VectorField<f64> for Pendulum {
    type Tape = InputTape<f64>;
    fn dim_s(&self) -> usize {
        2
    }
    fn dim_u(&self) -> usize {
        1
    }
    fn n_params(&self) -> usize {
        3
    }
    fn eval(&self, n: usize, s: &[f64], u: &[f64], out: &mut [f64]) {
        for i in 0..n {
            self.f(
                &s[2 * i..2 * i + 2],
                &u[i..i + 1],
                &mut out[2 * i..2 * i + 2],
            );
        }
    }
    fn eval_taped(&self, n: usize, s: &[f64], u: &[f64], out: &mut [f64], tape: &mut Self::Tape) {
        tape.record(n, s, u);
        self.eval(n, s, u, out);
    }
    fn vjp(
        &self,
        tape: &Self::Tape,
        ybar: &[f64],
        sbar: &mut [f64],
        ubar: &mut [f64],
        pbar: &mut [f64],
    ) {
        for i in 0..tape.n {
            let j = self.jac(&tape.s[2 * i..2 * i + 2], &tape.u[i..i + 1]);
            let yb = &ybar[2 * i..2 * i + 2];
            let g = |c: usize| yb[0] * j[0][c] + yb[1] * j[1][c];
            sbar[2 * i] = g(0);
            sbar[2 * i + 1] = g(1);
            ubar[i] = g(2);
            if !pbar.is_empty() {
                for k in 0..3 {
                    pbar[k] += g(3 + k);
                }
            }
        }
    }
    fn jvp(
        &self,
        n: usize,
        s: &[f64],
        u: &[f64],
        sdot: &[f64],
        udot: &[f64],
        out: &mut [f64],
        out_dot: &mut [f64],
    ) {
        self.eval(n, s, u, out);
        for i in 0..n {
            let j = self.jac(&s[2 * i..2 * i + 2], &u[i..i + 1]);
            for r in 0..2 {
                out_dot[2 * i + r] =
                    j[r][0] * sdot[2 * i] + j[r][1] * sdot[2 * i + 1] + j[r][2] * udot[i];
            }
        }
    }
}

/// `ṡ = s²`: blows up at `t = 1/s0`.
pub struct BlowUp;

impl VectorField<f64> for BlowUp {
    type Tape = InputTape<f64>;
    fn dim_s(&self) -> usize {
        1
    }
    fn dim_u(&self) -> usize {
        0
    }
    fn n_params(&self) -> usize {
        0
    }
    fn eval(&self, n: usize, s: &[f64], _u: &[f64], out: &mut [f64]) {
        for i in 0..n {
            out[i] = s[i] * s[i];
        }
    }
    fn eval_taped(&self, n: usize, s: &[f64], u: &[f64], out: &mut [f64], tape: &mut Self::Tape) {
        tape.record(n, s, u);
        self.eval(n, s, u, out);
    }
    fn vjp(
        &self,
        tape: &Self::Tape,
        ybar: &[f64],
        sbar: &mut [f64],
        _ubar: &mut [f64],
        _pbar: &mut [f64],
    ) {
        for i in 0..tape.n {
            sbar[i] = 2.0 * tape.s[i] * ybar[i];
        }
    }
    fn jvp(
        &self,
        n: usize,
        s: &[f64],
        u: &[f64],
        sdot: &[f64],
        _udot: &[f64],
        out: &mut [f64],
        out_dot: &mut [f64],
    ) {
        self.eval(n, s, u, out);
        for i in 0..n {
            out_dot[i] = 2.0 * s[i] * sdot[i];
        }
    }
}

/// Largest absolute difference, relative to `max(1, |b|)`.
pub fn max_rel_diff(a: &[f64], b: &[f64]) -> f64 {
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - y).abs() / y.abs().max(1.0))
        .fold(0.0, f64::max)
}
