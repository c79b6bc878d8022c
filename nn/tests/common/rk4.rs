//! A minimal NeuralODE RK4 unroll with backpropagation through the solver steps, on top of
//! `dynlab-nn` (test and benchmark helper; the models crate has the real solvers).
//!
//! The vector field is an MLP f([s, u]) → ds/dt with state width `ns` and action width `nu`
//! (`n_in = ns + nu`, `n_out = ns`); the action is held over each step.
#![allow(dead_code)]

use dynlab_nn::{Mlp, NnError, Workspace};

/// Everything one RK4 unroll records for the backward pass (reused across calls).
pub struct Rk4Tape {
    ns: usize,
    nu: usize,
    batch: usize,
    steps: usize,
    /// One workspace per stage per step (4·steps).
    ws: Vec<Workspace>,
    /// s_0 … s_K, each batch × ns.
    pub states: Vec<Vec<f32>>,
    /// Actions per step, batch × nu.
    actions: Vec<Vec<f32>>,
    xin: Vec<f32>,
    k: [Vec<f32>; 4],
    // backward scratch
    dx: Vec<f32>,
    dk: [Vec<f32>; 4],
}

impl Rk4Tape {
    pub fn new(mlp: &Mlp, ns: usize, nu: usize) -> Self {
        assert_eq!(mlp.n_in(), ns + nu);
        assert_eq!(mlp.n_out(), ns);
        Self {
            ns,
            nu,
            batch: 0,
            steps: 0,
            ws: Vec::new(),
            states: Vec::new(),
            actions: Vec::new(),
            xin: Vec::new(),
            k: Default::default(),
            dx: Vec::new(),
            dk: Default::default(),
        }
    }

    fn prepare(&mut self, mlp: &Mlp, batch: usize, steps: usize) {
        while self.ws.len() < 4 * steps {
            self.ws.push(mlp.workspace());
        }
        while self.states.len() < steps + 1 {
            self.states.push(Vec::new());
        }
        while self.actions.len() < steps {
            self.actions.push(Vec::new());
        }
        for s in &mut self.states[..=steps] {
            s.resize(batch * self.ns, 0.0);
        }
        for a in &mut self.actions[..steps] {
            a.resize(batch * self.nu, 0.0);
        }
        self.xin.resize(batch * (self.ns + self.nu), 0.0);
        self.dx.resize(batch * (self.ns + self.nu), 0.0);
        for k in self.k.iter_mut().chain(self.dk.iter_mut()) {
            k.resize(batch * self.ns, 0.0);
        }
        self.batch = batch;
        self.steps = steps;
    }

    /// Rolls out `steps` RK4 steps of size `dt` from `s0` (batch × ns) with actions
    /// `actions[n]` (batch × nu) held over step n, recording everything for
    /// [`Rk4Tape::backward`]. The states are in `self.states[1..=steps]`.
    pub fn forward(
        &mut self,
        mlp: &Mlp,
        s0: &[f32],
        actions: &[&[f32]],
        dt: f32,
    ) -> Result<(), NnError> {
        let (ns, nu) = (self.ns, self.nu);
        let batch = s0.len() / ns;
        let steps = actions.len();
        self.prepare(mlp, batch, steps);
        self.states[0].copy_from_slice(s0);
        for n in 0..steps {
            self.actions[n].copy_from_slice(actions[n]);
            for stage in 0..4 {
                let c = [0.0, 0.5, 0.5, 1.0][stage] * dt;
                // xin = [s_n + c·k_{stage−1}, u_n]
                let s = &self.states[n];
                for b in 0..batch {
                    let row = &mut self.xin[b * (ns + nu)..(b + 1) * (ns + nu)];
                    for j in 0..ns {
                        let kprev = if stage == 0 {
                            0.0
                        } else {
                            self.k[stage - 1][b * ns + j]
                        };
                        row[j] = s[b * ns + j] + c * kprev;
                    }
                    row[ns..].copy_from_slice(&self.actions[n][b * nu..(b + 1) * nu]);
                }
                let y = mlp.forward(&self.xin, &mut self.ws[4 * n + stage])?;
                self.k[stage].copy_from_slice(y);
            }
            let (prev, next) = self.states.split_at_mut(n + 1);
            for (i, s1) in next[0].iter_mut().enumerate() {
                *s1 = prev[n][i]
                    + dt / 6.0
                        * (self.k[0][i] + 2.0 * self.k[1][i] + 2.0 * self.k[2][i] + self.k[3][i]);
            }
        }
        Ok(())
    }

    /// Backpropagates ∂L/∂s_n (given for n = 1…steps in `d_states[n − 1]`, batch × ns) through
    /// the recorded unroll: adds ∂L/∂θ to `grad` and returns ∂L/∂s_0 in `ds0`.
    pub fn backward(
        &mut self,
        mlp: &Mlp,
        dt: f32,
        d_states: &[&[f32]],
        grad: &mut [f32],
        ds0: &mut [f32],
    ) -> Result<(), NnError> {
        let (ns, nu) = (self.ns, self.nu);
        let batch = self.batch;
        // a = adjoint of s_{n+1}
        let mut a = d_states[self.steps - 1].to_vec();
        for n in (0..self.steps).rev() {
            // s_{n+1} = s_n + dt/6 (k1 + 2k2 + 2k3 + k4)
            for (i, &ai) in a.iter().enumerate() {
                self.dk[0][i] = dt / 6.0 * ai;
                self.dk[1][i] = dt / 3.0 * ai;
                self.dk[2][i] = dt / 3.0 * ai;
                self.dk[3][i] = dt / 6.0 * ai;
            }
            let mut ds = a.clone();
            for stage in (0..4).rev() {
                mlp.backward(
                    &mut self.ws[4 * n + stage],
                    &self.dk[stage],
                    grad,
                    Some(&mut self.dx),
                )?;
                let c = [0.0, 0.5, 0.5, 1.0][stage] * dt;
                for b in 0..batch {
                    for j in 0..ns {
                        let d = self.dx[b * (ns + nu) + j];
                        ds[b * ns + j] += d;
                        if stage > 0 {
                            self.dk[stage - 1][b * ns + j] += c * d;
                        }
                    }
                }
            }
            if n > 0 {
                for (ai, (&di, &li)) in a.iter_mut().zip(ds.iter().zip(d_states[n - 1])) {
                    *ai = di + li;
                }
            } else {
                ds0.copy_from_slice(&ds);
            }
        }
        Ok(())
    }
}
