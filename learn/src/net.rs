//! The learned part of a model: an MLP with fixed input and output normalisation, and its
//! adapter to the ODE solvers ([`NetField`], a batched `VectorField<f32>`).
//!
//! The network maps `[z, u]` (the learned state dimensions and the action) to a change of `z`
//! per model step: `out = μ_o + σ_o ⊙ mlp((x − μ_i) / σ_i)`. A residual model adds it once, a
//! NeuralODE integrates it as a vector field over normalised step time τ ∈ [0, 1] (Tu & Lin
//! integrate from t = 0 to 1 as well), so the same output statistics fit both.

use std::cell::RefCell;

use dynlab_dynamics::ode::{Solver, VectorField};
use dynlab_nn::{Mlp, Workspace};
use serde::{Deserialize, Serialize};

/// Fixed affine normalisation of the network's inputs and outputs (fitted on the training data).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Normalization {
    /// Mean of each input `[z…, u…]`.
    pub input_mean: Vec<f64>,
    /// Standard deviation of each input (1 for constant inputs).
    pub input_std: Vec<f64>,
    /// Mean of each output (the change of `z` per step).
    pub output_mean: Vec<f64>,
    /// Standard deviation of each output.
    pub output_std: Vec<f64>,
}

impl Normalization {
    /// The identity normalisation for `n_in` inputs and `n_out` outputs.
    pub fn identity(n_in: usize, n_out: usize) -> Self {
        Self {
            input_mean: vec![0.0; n_in],
            input_std: vec![1.0; n_in],
            output_mean: vec![0.0; n_out],
            output_std: vec![1.0; n_out],
        }
    }
}

/// An MLP with its normalisation, in `f32`.
#[derive(Clone, Debug, PartialEq)]
pub struct Network {
    /// The network (`n_in = dz + du`, `n_out = dz`).
    pub mlp: Mlp,
    /// The normalisation as stored in the model file.
    pub norm: Normalization,
    pub(crate) in_mean: Vec<f32>,
    pub(crate) in_inv_std: Vec<f32>,
    pub(crate) out_mean: Vec<f32>,
    pub(crate) out_std: Vec<f32>,
    pub(crate) dz: usize,
}

impl Network {
    /// Wraps an MLP with a normalisation (lengths checked by the caller).
    pub fn new(mlp: Mlp, norm: Normalization) -> Self {
        let f = |v: &[f64]| v.iter().map(|&x| x as f32).collect::<Vec<f32>>();
        let dz = mlp.n_out();
        Self {
            in_mean: f(&norm.input_mean),
            in_inv_std: norm.input_std.iter().map(|&s| (1.0 / s) as f32).collect(),
            out_mean: f(&norm.output_mean),
            out_std: f(&norm.output_std),
            dz,
            mlp,
            norm,
        }
    }

    /// Learned state dimension.
    pub fn dz(&self) -> usize {
        self.dz
    }

    /// Action dimension.
    pub fn du(&self) -> usize {
        self.mlp.n_in() - self.dz
    }

    /// Writes the normalised network input of `n` samples into `x`.
    #[inline]
    pub(crate) fn fill_input(&self, n: usize, z: &[f32], u: &[f32], x: &mut Vec<f32>) {
        let (dz, du) = (self.dz, self.du());
        let ni = dz + du;
        x.resize(n * ni, 0.0);
        for i in 0..n {
            let row = &mut x[i * ni..(i + 1) * ni];
            for d in 0..dz {
                row[d] = (z[i * dz + d] - self.in_mean[d]) * self.in_inv_std[d];
            }
            for d in 0..du {
                row[dz + d] = (u[i * du + d] - self.in_mean[dz + d]) * self.in_inv_std[dz + d];
            }
        }
    }

    /// Denormalises network outputs into `out`.
    #[inline]
    pub(crate) fn write_output(&self, y: &[f32], out: &mut [f32]) {
        let dz = self.dz;
        for (o_row, y_row) in out.chunks_exact_mut(dz).zip(y.chunks_exact(dz)) {
            for d in 0..dz {
                o_row[d] = self.out_mean[d] + self.out_std[d] * y_row[d];
            }
        }
    }

    /// `out = net(z, u)` for `n` samples with a caller-provided workspace and input buffer.
    pub(crate) fn eval_with(
        &self,
        n: usize,
        z: &[f32],
        u: &[f32],
        out: &mut [f32],
        ws: &mut Workspace,
        x: &mut Vec<f32>,
    ) {
        self.fill_input(n, z, u, x);
        match self.mlp.forward(x, ws) {
            Ok(y) => self.write_output(y, out),
            // shapes are fixed by construction; a mismatch would be a bug in this crate
            Err(_) => out.iter_mut().for_each(|o| *o = f32::NAN),
        }
    }

    /// Input Jacobian of the (denormalised) output wrt `[z, u]` for `n` samples:
    /// `n × dz × (dz + du)` row-major, in physical units.
    pub(crate) fn input_jacobian(&self, n: usize, z: &[f32], u: &[f32]) -> Vec<f64> {
        let mut x = Vec::new();
        self.fill_input(n, z, u, &mut x);
        let mut ws = self.mlp.workspace();
        let ni = self.mlp.n_in();
        let dz = self.dz;
        match self.mlp.jacobian(&x, &mut ws) {
            Ok(j) => {
                let mut out = vec![0.0; n * dz * ni];
                for b in 0..n {
                    for o in 0..dz {
                        for i in 0..ni {
                            let idx = b * dz * ni + o * ni + i;
                            out[idx] = f64::from(j[idx])
                                * f64::from(self.out_std[o])
                                * f64::from(self.in_inv_std[i]);
                        }
                    }
                }
                out
            }
            Err(_) => vec![f64::NAN; n * dz * ni],
        }
    }
}

/// What [`NetField`] records for its reverse pass: the network workspace (created on first
/// use: the solver tapes need `Default`) and scratch buffers.
#[derive(Debug, Default)]
pub struct NetTape(RefCell<NetTapeInner>);

#[derive(Debug, Default)]
struct NetTapeInner {
    ws: Option<Workspace>,
    sizes: Vec<usize>,
    x: Vec<f32>,
    dy: Vec<f32>,
    dx: Vec<f32>,
    n: usize,
}

/// A [`Network`] as a batched vector field `ż = net(z, u)` in `f32` for the solvers of
/// `dynlab-dynamics` (forward, reverse and forward mode).
pub struct NetField<'a> {
    net: &'a Network,
    scratch: RefCell<(Option<Workspace>, Vec<f32>, Vec<f32>)>,
}

impl<'a> NetField<'a> {
    /// The field of `net`.
    pub fn new(net: &'a Network) -> Self {
        Self {
            net,
            scratch: RefCell::new((None, Vec::new(), Vec::new())),
        }
    }
}

impl VectorField<f32> for NetField<'_> {
    type Tape = NetTape;

    fn dim_s(&self) -> usize {
        self.net.dz
    }
    fn dim_u(&self) -> usize {
        self.net.du()
    }
    fn n_params(&self) -> usize {
        self.net.mlp.n_params()
    }
    fn eval(&self, n: usize, s: &[f32], u: &[f32], out: &mut [f32]) {
        let mut sc = self.scratch.borrow_mut();
        let (ws, x, _) = &mut *sc;
        let ws = ws.get_or_insert_with(|| self.net.mlp.workspace());
        self.net.eval_with(n, s, u, out, ws, x);
    }
    fn eval_taped(&self, n: usize, s: &[f32], u: &[f32], out: &mut [f32], tape: &mut NetTape) {
        let t = tape.0.get_mut();
        if t.sizes != self.net.mlp.sizes() {
            // a tape reused with another network (buffers are per architecture)
            t.ws = None;
            t.sizes = self.net.mlp.sizes().to_vec();
        }
        let ws = t.ws.get_or_insert_with(|| self.net.mlp.workspace());
        t.n = n;
        self.net.eval_with(n, s, u, out, ws, &mut t.x);
    }
    fn vjp(
        &self,
        tape: &NetTape,
        ybar: &[f32],
        sbar: &mut [f32],
        ubar: &mut [f32],
        pbar: &mut [f32],
    ) {
        let mut t = tape.0.borrow_mut();
        let t = &mut *t;
        let (n, dz, du) = (t.n, self.net.dz, self.net.du());
        let ni = dz + du;
        t.dy.clear();
        t.dy.extend(
            ybar.chunks_exact(dz)
                .flat_map(|r| r.iter().zip(&self.net.out_std).map(|(a, s)| a * s)),
        );
        t.dx.resize(n * ni, 0.0);
        let Some(ws) = t.ws.as_mut() else {
            return;
        };
        let mut scratch = Vec::new();
        let grad: &mut [f32] = if pbar.is_empty() {
            scratch.resize(self.net.mlp.n_params(), 0.0);
            &mut scratch
        } else {
            pbar
        };
        if self
            .net
            .mlp
            .backward(ws, &t.dy, grad, Some(&mut t.dx[..n * ni]))
            .is_err()
        {
            return;
        }
        for i in 0..n {
            for d in 0..dz {
                sbar[i * dz + d] = t.dx[i * ni + d] * self.net.in_inv_std[d];
            }
            for d in 0..du {
                ubar[i * du + d] = t.dx[i * ni + dz + d] * self.net.in_inv_std[dz + d];
            }
        }
    }
    fn jvp(
        &self,
        n: usize,
        s: &[f32],
        u: &[f32],
        sdot: &[f32],
        udot: &[f32],
        out: &mut [f32],
        out_dot: &mut [f32],
    ) {
        let mut sc = self.scratch.borrow_mut();
        let (ws, x, xd) = &mut *sc;
        let ws = ws.get_or_insert_with(|| self.net.mlp.workspace());
        let (dz, du) = (self.net.dz, self.net.du());
        let ni = dz + du;
        self.net.fill_input(n, s, u, x);
        xd.resize(n * ni, 0.0);
        for i in 0..n {
            for d in 0..dz {
                xd[i * ni + d] = sdot[i * dz + d] * self.net.in_inv_std[d];
            }
            for d in 0..du {
                xd[i * ni + dz + d] = udot[i * du + d] * self.net.in_inv_std[dz + d];
            }
        }
        match self.net.mlp.jvp(x, xd, ws) {
            Ok((y, dy)) => {
                self.net.write_output(y, out);
                for (o, (d, k)) in out_dot
                    .iter_mut()
                    .zip(dy.iter().zip(self.net.out_std.iter().cycle()))
                {
                    *o = d * k;
                }
            }
            Err(_) => {
                out.iter_mut().for_each(|o| *o = f32::NAN);
                out_dot.iter_mut().for_each(|o| *o = f32::NAN);
            }
        }
    }
}

/// Explicit Runge–Kutta coefficients of the fixed-step solvers (the same as `dynlab-dynamics`).
struct FixedTableau {
    a: &'static [&'static [f64]],
    b: &'static [f64],
}

static EULER: FixedTableau = FixedTableau {
    a: &[&[]],
    b: &[1.0],
};

static RK4: FixedTableau = FixedTableau {
    a: &[&[], &[0.5], &[0.0, 0.5], &[0.0, 0.0, 1.0]],
    b: &[1.0 / 6.0, 1.0 / 3.0, 1.0 / 3.0, 1.0 / 6.0],
};

/// One network evaluation recorded for the reverse pass: its workspace (the network's tape) and
/// the normalised input buffer.
#[derive(Debug, Default)]
struct StageTape {
    ws: Option<Workspace>,
    x: Vec<f32>,
}

/// A fixed-step NeuralODE step (Euler or RK4 with substeps) of a [`Network`] over normalised step
/// time τ ∈ [0, 1], recorded for backpropagation, with every buffer kept across calls.
///
/// The same arithmetic as `ode::integrate_taped` + `ode::integrate_vjp` of `dynlab-dynamics` on a
/// [`NetField`] (stage sums `y + Σ (h·a_j)·k_j` in stage order, reverse pass through the recorded
/// stages), but the network workspaces of every stage persist from one training batch to the
/// next: the generic solver tape creates fresh field tapes on every call, and growing the
/// workspaces again each time cost ≈ 10 % of a training step in page faults and zeroing.
#[derive(Debug, Default)]
pub(crate) struct FixedStepTape {
    stages: Vec<StageTape>,
    ks: Vec<Vec<f32>>,
    ytmp: Vec<f32>,
    ynew: Vec<f32>,
    kbar: Vec<f32>,
    ybars: Vec<Vec<f32>>,
    dy: Vec<f32>,
    dx: Vec<f32>,
    n: usize,
    h: f64,
    substeps: usize,
    rk4: bool,
}

/// Substeps and tableau of a fixed-step solver (`None` for Dopri5).
fn fixed(solver: &Solver) -> Option<(usize, &'static FixedTableau, bool)> {
    match *solver {
        Solver::Euler { substeps } => Some((substeps.max(1) as usize, &EULER, false)),
        Solver::Rk4 { substeps } => Some((substeps.max(1) as usize, &RK4, true)),
        Solver::Dopri5(_) => None,
    }
}

/// `out = y + Σ_j (h·a_j)·k_j` over the non-zero `a_j`, in order (as the generic solver).
fn combine(y: &[f32], h: f64, a: &[f64], ks: &[Vec<f32>], out: &mut [f32]) {
    out.copy_from_slice(y);
    for (j, &aj) in a.iter().enumerate() {
        if aj != 0.0 {
            let c = (h * aj) as f32;
            for (o, k) in out.iter_mut().zip(ks[j].iter()) {
                *o += c * *k;
            }
        }
    }
}

impl FixedStepTape {
    /// Whether `solver` has a fixed-step path.
    pub(crate) fn supports(solver: &Solver) -> bool {
        fixed(solver).is_some()
    }

    /// `out = z(1)` from `z(0) = z` with `u` held, for `n` samples, recording the stages.
    /// Returns false (and leaves `out` unspecified) for a solver without a fixed-step path.
    pub(crate) fn forward(
        &mut self,
        net: &Network,
        solver: &Solver,
        n: usize,
        z: &[f32],
        u: &[f32],
        out: &mut [f32],
    ) -> bool {
        let Some((substeps, tab, rk4)) = fixed(solver) else {
            return false;
        };
        let stages = tab.b.len();
        let len = n * net.dz;
        self.n = n;
        self.h = 1.0 / substeps as f64;
        self.substeps = substeps;
        self.rk4 = rk4;
        if self.stages.len() < substeps * stages {
            self.stages
                .resize_with(substeps * stages, StageTape::default);
        }
        self.ks.resize_with(stages, Vec::new);
        for k in &mut self.ks {
            k.resize(len, 0.0);
        }
        self.ytmp.resize(len, 0.0);
        self.ynew.resize(len, 0.0);
        out.copy_from_slice(z);
        for s in 0..substeps {
            for i in 0..stages {
                combine(out, self.h, tab.a[i], &self.ks, &mut self.ytmp);
                let st = &mut self.stages[s * stages + i];
                let ws = st.ws.get_or_insert_with(|| net.mlp.workspace());
                net.eval_with(n, &self.ytmp, u, &mut self.ks[i], ws, &mut st.x);
            }
            combine(out, self.h, tab.b, &self.ks, &mut self.ynew);
            out.copy_from_slice(&self.ynew);
        }
        true
    }

    /// Reverse pass of the last [`FixedStepTape::forward`]: `zbar0 = (∂z(1)/∂z(0))ᵀ·zbar_end`,
    /// and `grad += (∂z(1)/∂θ)ᵀ·zbar_end` (the network parameters).
    pub(crate) fn backward(
        &mut self,
        net: &Network,
        zbar_end: &[f32],
        zbar0: &mut [f32],
        grad: &mut [f32],
    ) {
        let tab = if self.rk4 { &RK4 } else { &EULER };
        let stages = tab.b.len();
        let (n, dz, du) = (self.n, net.dz, net.du());
        let ni = dz + du;
        let len = n * dz;
        let h = self.h;
        zbar0.copy_from_slice(zbar_end);
        self.ybars.resize_with(stages, Vec::new);
        for y in &mut self.ybars {
            y.resize(len, 0.0);
        }
        self.kbar.resize(len, 0.0);
        self.dy.resize(len, 0.0);
        self.dx.resize(n * ni, 0.0);
        for s in (0..self.substeps).rev() {
            for i in (0..stages).rev() {
                let cb = (h * tab.b[i]) as f32;
                for (kb, sb) in self.kbar.iter_mut().zip(zbar0.iter()) {
                    *kb = cb * *sb;
                }
                for l in i + 1..stages {
                    let a = tab.a[l][i];
                    if a != 0.0 {
                        let c = (h * a) as f32;
                        for (kb, y) in self.kbar.iter_mut().zip(self.ybars[l].iter()) {
                            *kb += c * *y;
                        }
                    }
                }
                // through the output scaling, the network, and the input scaling
                for (d, (kb, sd)) in self
                    .dy
                    .iter_mut()
                    .zip(self.kbar.iter().zip(net.out_std.iter().cycle()))
                {
                    *d = kb * sd;
                }
                let st = &mut self.stages[s * stages + i];
                let ok = match st.ws.as_mut() {
                    Some(ws) => net
                        .mlp
                        .backward(ws, &self.dy, grad, Some(&mut self.dx[..n * ni]))
                        .is_ok(),
                    None => false,
                };
                let yb = &mut self.ybars[i];
                if ok {
                    for r in 0..n {
                        for d in 0..dz {
                            yb[r * dz + d] = self.dx[r * ni + d] * net.in_inv_std[d];
                        }
                    }
                } else {
                    // shapes are fixed by construction; a failure would be a bug in this crate
                    yb.iter_mut().for_each(|v| *v = f32::NAN);
                }
            }
            for yb in &self.ybars {
                for (a, b) in zbar0.iter_mut().zip(yb.iter()) {
                    *a += *b;
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use dynlab_dynamics::ode::{self, SolverTape};
    use dynlab_nn::{Activation, Init, MlpSpec};

    use super::*;

    fn data(seed: u64, n: usize) -> Vec<f32> {
        let mut rng = dynlab_nn::rng::SplitMix64::new(seed);
        (0..n).map(|_| rng.uniform_symmetric(1.0)).collect()
    }

    #[test]
    fn fixed_step_tape_is_bit_identical_to_the_generic_solver_tape() {
        let spec = MlpSpec::uniform(6, &[32, 32], 3, Activation::Tanh).unwrap();
        let norm = Normalization {
            input_mean: vec![0.1, -0.2, 0.3, 0.0, 0.5, -0.1],
            input_std: vec![0.5, 2.0, 1.5, 1.0, 0.7, 1.2],
            output_mean: vec![0.01, -0.02, 0.03],
            output_std: vec![0.2, 0.3, 0.1],
        };
        let net = Network::new(Mlp::new(spec, Init::Auto, 5), norm);
        let n = 37;
        let z = data(1, n * 3);
        let u = data(2, n * 3);
        let zbar = data(3, n * 3);
        for solver in [
            Solver::euler(),
            Solver::rk4(),
            Solver::Rk4 { substeps: 3 },
            Solver::Euler { substeps: 2 },
        ] {
            let field = NetField::new(&net);
            let mut tape = SolverTape::default();
            let mut want = vec![0.0f32; n * 3];
            ode::integrate_taped(&field, &solver, n, &z, &u, 1.0, &mut want, &mut tape);
            let mut want_z0 = vec![0.0f32; n * 3];
            let mut ubar = vec![0.0f32; n * 3];
            let mut want_g = vec![0.0f32; net.mlp.n_params()];
            ode::integrate_vjp(&field, &tape, &zbar, &mut want_z0, &mut ubar, &mut want_g);

            let mut fixed = FixedStepTape::default();
            // twice: the second call reuses the recorded workspaces
            for _ in 0..2 {
                let mut got = vec![0.0f32; n * 3];
                assert!(fixed.forward(&net, &solver, n, &z, &u, &mut got));
                assert_eq!(got, want, "{solver:?} forward");
                let mut got_z0 = vec![0.0f32; n * 3];
                let mut got_g = vec![0.0f32; net.mlp.n_params()];
                fixed.backward(&net, &zbar, &mut got_z0, &mut got_g);
                assert_eq!(got_z0, want_z0, "{solver:?} state gradient");
                assert_eq!(got_g, want_g, "{solver:?} parameter gradient");
            }
        }
        assert!(!FixedStepTape::supports(&Solver::dopri5(1e-4, 1e-6)));
    }
}
