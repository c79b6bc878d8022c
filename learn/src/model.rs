//! [`Model`]: every model kind behind one type, with batched steps, rollouts, exact input
//! Jacobians and a fast multi-threaded `f32` rollout for sampling controllers (MPPI).

use dynlab_dynamics::ode::{self, OdeStatus, Solver};
use dynlab_dynamics::physics::PhysicsModel;
use dynlab_nn::Workspace;
use dynlab_nn::parallel::Workers;
use serde::{Deserialize, Serialize};

use crate::net::{NetField, Network};
use crate::{LearnError, World};

/// The model kinds (names as on the command line and in model files).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum ModelKind {
    /// MLP predicts the change of the state per step: `z⁺ = z + f(z, u)`.
    Residual,
    /// NeuralODE, explicit Euler over the step (`ż = f(z, u)`, action held).
    NodeEuler,
    /// NeuralODE, classic RK4 over the step.
    NodeRk4,
    /// NeuralODE, adaptive Dormand–Prince 5(4) over the step (`rtol`/`atol` in the solver).
    NodeDopri5,
    /// The nominal physics model with fitted parameters and optional effects.
    Physics,
    /// Physics plus a learned residual: `z⁺ = Φ(s, u)_z + f(z, u)`.
    Hybrid,
}

impl ModelKind {
    /// All kinds.
    pub const ALL: [ModelKind; 6] = [
        ModelKind::Residual,
        ModelKind::NodeEuler,
        ModelKind::NodeRk4,
        ModelKind::NodeDopri5,
        ModelKind::Physics,
        ModelKind::Hybrid,
    ];

    /// Name as on the command line (`node-rk4`).
    pub fn name(self) -> &'static str {
        match self {
            ModelKind::Residual => "residual",
            ModelKind::NodeEuler => "node-euler",
            ModelKind::NodeRk4 => "node-rk4",
            ModelKind::NodeDopri5 => "node-dopri5",
            ModelKind::Physics => "physics",
            ModelKind::Hybrid => "hybrid",
        }
    }

    /// Parses a kind name.
    pub fn from_name(name: &str) -> Result<Self, LearnError> {
        ModelKind::ALL
            .into_iter()
            .find(|k| k.name() == name)
            .ok_or_else(|| LearnError::UnknownKind {
                name: name.to_string(),
            })
    }

    /// Whether the kind has a network.
    pub fn has_network(self) -> bool {
        self != ModelKind::Physics
    }

    /// Whether the kind has a physics model.
    pub fn has_physics(self) -> bool {
        matches!(self, ModelKind::Physics | ModelKind::Hybrid)
    }

    /// The solver integrating the network over the step (`None` for discrete kinds).
    /// Dopri5 defaults to `rtol = 1e-4`, `atol = 1e-6`: the network runs in `f32`, whose
    /// rounding (≈ 6e-8 relative) makes torchdiffeq's 1e-7/1e-9 unreachable.
    pub fn default_solver(self) -> Option<Solver> {
        match self {
            ModelKind::NodeEuler => Some(Solver::euler()),
            ModelKind::NodeRk4 => Some(Solver::rk4()),
            ModelKind::NodeDopri5 => Some(Solver::dopri5(1e-4, 1e-6)),
            _ => None,
        }
    }
}

impl std::fmt::Display for ModelKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// Input Jacobians of one model step for a batch.
#[derive(Clone, Debug, PartialEq)]
pub struct StepJacobians {
    /// Next states, `n × dim_s`.
    pub next: Vec<f64>,
    /// `∂s⁺/∂s`, `n × dim_s × dim_s` row-major.
    pub ds: Vec<f64>,
    /// `∂s⁺/∂u`, `n × dim_s × dim_u` row-major.
    pub du: Vec<f64>,
}

/// A dynamics model of either world, of any [`ModelKind`].
///
/// State and action layouts are those of [`World`]. Pushing models step one push; car models
/// step one pose interval `dt` and predict the body-frame velocities, from which the pose
/// integrates with the trapezoidal rule `p⁺ = p + dt/2·(R(ψ)v + R(ψ⁺)v⁺)` (Kohler et al. use
/// `p + dt·R(ψ)v⁺`; the trapezoid matches velocities estimated at the samples better).
#[derive(Clone, Debug, PartialEq)]
pub struct Model {
    kind: ModelKind,
    world: World,
    dt: f64,
    solver: Option<Solver>,
    net: Option<Network>,
    physics: Option<PhysicsModel>,
    physics_solver: Solver,
}

impl Model {
    /// Assembles a model; checks that the parts fit the kind and the world.
    pub fn new(
        kind: ModelKind,
        world: World,
        dt: f64,
        solver: Option<Solver>,
        net: Option<Network>,
        physics: Option<PhysicsModel>,
        physics_solver: Solver,
    ) -> Result<Self, LearnError> {
        if !(dt.is_finite() && dt > 0.0) {
            return Err(LearnError::setting(
                "dt",
                dt,
                "the model step must be finite and > 0",
            ));
        }
        if kind.has_network() != net.is_some() {
            return Err(LearnError::setting(
                "network",
                if net.is_some() { "present" } else { "missing" },
                format!(
                    "a {kind} model {} a network",
                    if kind.has_network() {
                        "needs"
                    } else {
                        "has no"
                    }
                ),
            ));
        }
        if kind.has_physics() != physics.is_some() {
            return Err(LearnError::setting(
                "physics",
                if physics.is_some() {
                    "present"
                } else {
                    "missing"
                },
                format!(
                    "a {kind} model {} a physics model",
                    if kind.has_physics() {
                        "needs"
                    } else {
                        "has no"
                    }
                ),
            ));
        }
        let is_node = matches!(
            kind,
            ModelKind::NodeEuler | ModelKind::NodeRk4 | ModelKind::NodeDopri5
        );
        let solver = if is_node {
            let s = solver.or(kind.default_solver());
            let ok = matches!(
                (kind, s),
                (ModelKind::NodeEuler, Some(Solver::Euler { .. }))
                    | (ModelKind::NodeRk4, Some(Solver::Rk4 { .. }))
                    | (ModelKind::NodeDopri5, Some(Solver::Dopri5(_)))
            );
            if !ok {
                return Err(LearnError::setting(
                    "solver",
                    format!("{s:?}"),
                    format!("a {kind} model integrates with the solver its name says"),
                ));
            }
            s
        } else {
            None
        };
        if let Some(net) = &net {
            let dz = world.learned_dims().len();
            if net.dz() != dz || net.mlp.n_in() != dz + world.action_dim() {
                return Err(LearnError::setting(
                    "network",
                    format!("{:?}", net.mlp.sizes()),
                    format!(
                        "a {world} network maps {} inputs to {dz} outputs",
                        dz + world.action_dim()
                    ),
                ));
            }
            let n = &net.norm;
            if n.input_mean.len() != net.mlp.n_in()
                || n.input_std.len() != net.mlp.n_in()
                || n.output_mean.len() != dz
                || n.output_std.len() != dz
            {
                return Err(LearnError::setting(
                    "normalization",
                    "wrong lengths",
                    format!("needs {} input and {dz} output statistics", net.mlp.n_in()),
                ));
            }
            if n.input_std
                .iter()
                .chain(&n.output_std)
                .any(|s| !(s.is_finite() && *s > 0.0))
                || n.input_mean
                    .iter()
                    .chain(&n.output_mean)
                    .any(|m| !m.is_finite())
            {
                return Err(LearnError::setting(
                    "normalization",
                    "non-finite or non-positive std",
                    "every mean must be finite and every std finite and > 0",
                ));
            }
        }
        if let Some(p) = &physics {
            if p.robot() != world.robot() {
                return Err(LearnError::WorldMismatch {
                    what: "the physics model".into(),
                    found: format!("{:?}", p.robot()),
                    expected: world.name().into(),
                    hint: "use the physics model of the same robot".into(),
                });
            }
            if p.effect_state_offset() != world.state_dim() {
                return Err(LearnError::setting(
                    "physics",
                    format!("{} states", p.effect_state_offset()),
                    format!(
                        "a {world} physics model has {} states before its effect states",
                        world.state_dim()
                    ),
                ));
            }
        }
        Ok(Self {
            kind,
            world,
            dt,
            solver,
            net,
            physics,
            physics_solver,
        })
    }

    /// The kind.
    pub fn kind(&self) -> ModelKind {
        self.kind
    }
    /// The world.
    pub fn world(&self) -> World {
        self.world
    }
    /// Model step \[s\] (pushing: the time between pushes; the dynamics step one push).
    pub fn dt(&self) -> f64 {
        self.dt
    }
    /// The network solver (NeuralODE kinds).
    pub fn solver(&self) -> Option<Solver> {
        self.solver
    }
    /// The network, if any.
    pub fn network(&self) -> Option<&Network> {
        self.net.as_ref()
    }
    /// Mutable network (training).
    pub fn network_mut(&mut self) -> Option<&mut Network> {
        self.net.as_mut()
    }
    /// The physics model, if any.
    pub fn physics(&self) -> Option<&PhysicsModel> {
        self.physics.as_ref()
    }
    /// The solver integrating the physics model over one step.
    pub fn physics_solver(&self) -> Solver {
        self.physics_solver
    }
    /// State dimension.
    pub fn dim_s(&self) -> usize {
        self.world.state_dim()
    }
    /// Action dimension.
    pub fn dim_u(&self) -> usize {
        self.world.action_dim()
    }
    /// Integration time of the physics model per step: one push (normalised) or `dt` seconds.
    pub fn physics_time(&self) -> f64 {
        match self.world {
            World::Push => 1.0,
            World::Car => self.dt,
        }
    }

    /// Number of effect states the model carries beside the world state (`d_f` of
    /// `motor_lag`, `delta_w` of `steering_lag`; 0 without such effects). They are not
    /// measured: they are rebuilt from the commands ([`Model::extra_states_along`]) and carried
    /// through rollouts ([`Model::rollout_with_extra`]).
    pub fn dim_extra(&self) -> usize {
        self.physics
            .as_ref()
            .map_or(0, PhysicsModel::dim_effect_states)
    }

    /// Names of the effect states (`d_f`, `delta_w`), in order.
    pub fn extra_state_names(&self) -> Vec<&'static str> {
        self.physics
            .as_ref()
            .map_or_else(Vec::new, PhysicsModel::effect_state_names)
    }

    /// The effect states at every sample of a command sequence (`u`: `len × dim_u`, one command
    /// per model step; result `len × dim_extra`), started settled at the first command: entry
    /// `a` is the initial effect state of a window starting at sample `a`. The one
    /// implementation of "the initial effect states of a window from the commands before it"
    /// ([`PhysicsModel::effect_states_along`]); empty for models without effect states.
    pub fn extra_states_along(&self, u: &[f64]) -> Vec<f64> {
        match &self.physics {
            Some(p) if p.dim_effect_states() > 0 => p.effect_states_along(u, self.physics_time()),
            _ => Vec::new(),
        }
    }

    /// The effect states after a command history (`history`: `m × dim_u`, oldest first, one per
    /// model step), in which `current` is applied next; settled at `current` when the history is
    /// empty. The same recursion as [`Model::extra_states_along`].
    pub fn extra_from_history(&self, history: &[f64], current: &[f64]) -> Vec<f64> {
        match &self.physics {
            Some(p) if p.dim_effect_states() > 0 => {
                p.effect_states_from_history(history, current, self.physics_time())
            }
            _ => Vec::new(),
        }
    }

    /// Advances effect states `e` (`dim_extra`) by one model step under the command `u`.
    pub fn advance_extra(&self, e: &mut [f64], u: &[f64]) {
        if let Some(p) = &self.physics {
            p.advance_effect_states(e, u, self.physics_time());
        }
    }

    /// The effect states settled under the held command `u` (what a single [`Model::step`]
    /// assumes, having no history).
    pub fn settled_extra(&self, u: &[f64]) -> Vec<f64> {
        self.physics
            .as_ref()
            .map_or_else(Vec::new, |p| p.settled_effect_states(u))
    }

    fn check_batch(&self, s: &[f64], u: &[f64]) -> Result<usize, LearnError> {
        let (ds, du) = (self.dim_s(), self.dim_u());
        if !s.len().is_multiple_of(ds) {
            return Err(LearnError::Shape {
                what: "states",
                expected: s.len().div_ceil(ds) * ds,
                got: s.len(),
                hint: "n × dim_s, row-major",
            });
        }
        let n = s.len() / ds;
        if u.len() != n * du {
            return Err(LearnError::Shape {
                what: "actions",
                expected: n * du,
                got: u.len(),
                hint: "n × dim_u, one action per state",
            });
        }
        check_finite("states", s)?;
        check_finite("actions", u)?;
        Ok(n)
    }

    /// One step for a batch: `out = f(s, u)` (`n × dim_s`). Returns the worst solver status
    /// (a NeuralODE or physics integration that failed leaves its last finite state). A model
    /// with effect states has no history here: they start settled at the command (use
    /// [`Model::step_with_extra`] to give them).
    pub fn step(&self, s: &[f64], u: &[f64], out: &mut [f64]) -> Result<OdeStatus, LearnError> {
        let n = self.check_batch(s, u)?;
        if out.len() != s.len() {
            return Err(LearnError::Shape {
                what: "out",
                expected: s.len(),
                got: out.len(),
                hint: "n × dim_s",
            });
        }
        Ok(self.step_unchecked(n, s, u, out))
    }

    /// One step for a batch carrying the effect states: `s` (`n × dim_s`) and `e`
    /// (`n × dim_extra`) at the step's start, `out` and `e_out` after it. Models without
    /// effect states take empty `e` and `e_out` and step as [`Model::step`].
    pub fn step_with_extra(
        &self,
        s: &[f64],
        e: &[f64],
        u: &[f64],
        out: &mut [f64],
        e_out: &mut [f64],
    ) -> Result<OdeStatus, LearnError> {
        let n = self.check_batch(s, u)?;
        let ne = self.dim_extra();
        for (what, v) in [
            ("effect states", e.len()),
            ("effect states out", e_out.len()),
        ] {
            if v != n * ne {
                return Err(LearnError::Shape {
                    what,
                    expected: n * ne,
                    got: v,
                    hint: "n × dim_extra, row-major (Model::extra_states_along gives them)",
                });
            }
        }
        check_finite("effect states", e)?;
        if out.len() != s.len() {
            return Err(LearnError::Shape {
                what: "out",
                expected: s.len(),
                got: out.len(),
                hint: "n × dim_s",
            });
        }
        Ok(self.step_core(n, s, Some(e), u, out, Some(e_out)))
    }

    pub(crate) fn step_unchecked(
        &self,
        n: usize,
        s: &[f64],
        u: &[f64],
        out: &mut [f64],
    ) -> OdeStatus {
        self.step_core(n, s, None, u, out, None)
    }

    /// The step: effect states from `e` when given, else settled at the command
    /// ([`pad_effect_states`]); their next values to `e_out` when given.
    fn step_core(
        &self,
        n: usize,
        s: &[f64],
        e: Option<&[f64]>,
        u: &[f64],
        out: &mut [f64],
        e_out: Option<&mut [f64]>,
    ) -> OdeStatus {
        let ds = self.dim_s();
        let lr = self.world.learned_dims();
        let dz = lr.len();
        let mut status = OdeStatus::Success;
        // physics part
        if let Some(p) = &self.physics {
            let rep = if p.dim_state() == ds {
                p.integrate_step(&self.physics_solver, n, s, u, self.physics_time(), out)
            } else {
                let dp = p.dim_state();
                let sp = match e {
                    Some(e) => join_effect_states(n, ds, dp, s, e),
                    None => pad_effect_states(p, n, s, u),
                };
                let mut op = vec![0.0; n * dp];
                let rep = p.integrate_step(
                    &self.physics_solver,
                    n,
                    &sp,
                    u,
                    self.physics_time(),
                    &mut op,
                );
                for i in 0..n {
                    out[i * ds..(i + 1) * ds].copy_from_slice(&op[i * dp..i * dp + ds]);
                }
                if let Some(eo) = e_out {
                    let ne = dp - ds;
                    for i in 0..n {
                        eo[i * ne..(i + 1) * ne].copy_from_slice(&op[i * dp + ds..(i + 1) * dp]);
                    }
                }
                rep
            };
            status = rep.status;
        }
        let Some(net) = &self.net else {
            return status;
        };
        let z: Vec<f32> = learned_part_f32(s, n, ds, lr.clone());
        let uf: Vec<f32> = u.iter().map(|&x| x as f32).collect();
        let mut zn = vec![0.0f32; n * dz];
        match self.kind {
            ModelKind::Residual | ModelKind::Hybrid => {
                let mut ws = net.mlp.workspace();
                let mut x = Vec::new();
                net.eval_with(n, &z, &uf, &mut zn, &mut ws, &mut x);
                if self.kind == ModelKind::Residual {
                    for (a, b) in zn.iter_mut().zip(&z) {
                        *a += b;
                    }
                }
            }
            _ => {
                let field = NetField::new(net);
                let solver = self.solver.unwrap_or(Solver::rk4());
                let rep = ode::integrate(&field, &solver, n, &z, &uf, 1.0, &mut zn);
                if rep.status != OdeStatus::Success {
                    status = rep.status;
                }
            }
        }
        if self.kind == ModelKind::Hybrid {
            for i in 0..n {
                for d in 0..dz {
                    out[i * ds + lr.start + d] += f64::from(zn[i * dz + d]);
                }
            }
            return status;
        }
        match self.world {
            World::Push => {
                for (o, v) in out.iter_mut().zip(&zn) {
                    *o = f64::from(*v);
                }
            }
            World::Car => {
                for i in 0..n {
                    let si = &s[i * 6..i * 6 + 6];
                    let vn = [
                        f64::from(zn[i * 3]),
                        f64::from(zn[i * 3 + 1]),
                        f64::from(zn[i * 3 + 2]),
                    ];
                    let p =
                        car_pose_update(self.dt, [si[0], si[1], si[2]], [si[3], si[4], si[5]], vn);
                    out[i * 6..i * 6 + 3].copy_from_slice(&p);
                    out[i * 6 + 3..i * 6 + 6].copy_from_slice(&vn);
                }
            }
        }
        if out.iter().any(|v| !v.is_finite()) {
            status = OdeStatus::NonFinite;
        }
        status
    }

    /// Open-loop rollout of `k` steps for `n` samples: `s0` is `n × dim_s`, `actions` is
    /// step-major `k × n × dim_u`, `out` receives `k × n × dim_s` (state after each step).
    /// Effect states start settled at each sample's first action and are carried through the
    /// rollout; with a command history use [`Model::rollout_with_extra`].
    pub fn rollout(
        &self,
        s0: &[f64],
        actions: &[f64],
        out: &mut [f64],
    ) -> Result<OdeStatus, LearnError> {
        let (ds, du) = (self.dim_s(), self.dim_u());
        if !s0.len().is_multiple_of(ds) || s0.is_empty() {
            return Err(LearnError::Shape {
                what: "s0",
                expected: ds,
                got: s0.len(),
                hint: "n × dim_s",
            });
        }
        let n = s0.len() / ds;
        if !actions.len().is_multiple_of(n * du) {
            return Err(LearnError::Shape {
                what: "actions",
                expected: n * du,
                got: actions.len(),
                hint: "k × n × dim_u, step-major",
            });
        }
        let k = actions.len() / (n * du);
        if out.len() != k * n * ds {
            return Err(LearnError::Shape {
                what: "out",
                expected: k * n * ds,
                got: out.len(),
                hint: "k × n × dim_s, step-major",
            });
        }
        check_finite("s0", s0)?;
        check_finite("actions", actions)?;
        let ne = self.dim_extra();
        if ne > 0 {
            // no history: the effect states start settled at each sample's first command
            let e0: Vec<f64> = (0..n)
                .flat_map(|i| self.settled_extra(&actions[i * du..(i + 1) * du]))
                .collect();
            return self.rollout_with_extra(s0, &e0, actions, out, None);
        }
        let mut status = OdeStatus::Success;
        let mut cur = s0.to_vec();
        for j in 0..k {
            let dst = &mut out[j * n * ds..(j + 1) * n * ds];
            let st = self.step_unchecked(n, &cur, &actions[j * n * du..(j + 1) * n * du], dst);
            if st != OdeStatus::Success {
                status = st;
            }
            cur.copy_from_slice(dst);
        }
        Ok(status)
    }

    /// Open-loop rollout carrying the effect states: as [`Model::rollout`] from the states `s0`
    /// (`n × dim_s`) and the effect states `e0` (`n × dim_extra`, from the commands before the
    /// rollout: [`Model::extra_states_along`], [`Model::extra_from_history`]). `extra_out`, if
    /// given, receives the effect states after each step (`k × n × dim_extra`). For a model
    /// without effect states `e0` is empty and this is [`Model::rollout`].
    pub fn rollout_with_extra(
        &self,
        s0: &[f64],
        e0: &[f64],
        actions: &[f64],
        out: &mut [f64],
        mut extra_out: Option<&mut [f64]>,
    ) -> Result<OdeStatus, LearnError> {
        let (ds, du, ne) = (self.dim_s(), self.dim_u(), self.dim_extra());
        if !s0.len().is_multiple_of(ds) || s0.is_empty() {
            return Err(LearnError::Shape {
                what: "s0",
                expected: ds,
                got: s0.len(),
                hint: "n × dim_s",
            });
        }
        let n = s0.len() / ds;
        if e0.len() != n * ne {
            return Err(LearnError::Shape {
                what: "e0",
                expected: n * ne,
                got: e0.len(),
                hint: "n × dim_extra effect states (Model::extra_states_along gives them)",
            });
        }
        if !actions.len().is_multiple_of(n * du) {
            return Err(LearnError::Shape {
                what: "actions",
                expected: n * du,
                got: actions.len(),
                hint: "k × n × dim_u, step-major",
            });
        }
        let k = actions.len() / (n * du);
        if out.len() != k * n * ds {
            return Err(LearnError::Shape {
                what: "out",
                expected: k * n * ds,
                got: out.len(),
                hint: "k × n × dim_s, step-major",
            });
        }
        if let Some(eo) = &extra_out
            && eo.len() != k * n * ne
        {
            return Err(LearnError::Shape {
                what: "extra_out",
                expected: k * n * ne,
                got: eo.len(),
                hint: "k × n × dim_extra, step-major",
            });
        }
        check_finite("s0", s0)?;
        check_finite("e0", e0)?;
        check_finite("actions", actions)?;
        let mut status = OdeStatus::Success;
        let mut cur = s0.to_vec();
        let mut cur_e = e0.to_vec();
        let mut next_e = vec![0.0; n * ne];
        for j in 0..k {
            let dst = &mut out[j * n * ds..(j + 1) * n * ds];
            let st = self.step_core(
                n,
                &cur,
                Some(&cur_e),
                &actions[j * n * du..(j + 1) * n * du],
                dst,
                Some(&mut next_e),
            );
            if st != OdeStatus::Success {
                status = st;
            }
            cur.copy_from_slice(dst);
            std::mem::swap(&mut cur_e, &mut next_e);
            if let Some(eo) = extra_out.as_deref_mut() {
                eo[j * n * ne..(j + 1) * n * ne].copy_from_slice(&cur_e);
            }
        }
        Ok(status)
    }

    /// Exact input Jacobians of one step for a batch: `∂s⁺/∂s` and `∂s⁺/∂u` (forward mode
    /// through the solver's steps for NeuralODEs and physics, reverse/forward mode of the network
    /// otherwise; the car pose kinematics by the chain rule).
    /// For a model with effect states, a single step has no history: they are taken settled at
    /// the command ([`pad_effect_states`]) and their columns fold into `∂s⁺/∂u`.
    pub fn jacobians(&self, s: &[f64], u: &[f64]) -> Result<StepJacobians, LearnError> {
        let n = self.check_batch(s, u)?;
        Ok(self.jacobians_core(n, s, None, u).0)
    }

    /// Exact Jacobians of one step over the augmented state `x = [s, e]` (world state and
    /// effect states, `nx = dim_s + dim_extra`): `next` is `n × nx`, `ds` = `∂x⁺/∂x`
    /// (`n × nx × nx`), `du` = `∂x⁺/∂u` (`n × nx × dim_u`). With no effect states this is
    /// [`Model::jacobians`].
    pub fn jacobians_with_extra(
        &self,
        s: &[f64],
        e: &[f64],
        u: &[f64],
    ) -> Result<StepJacobians, LearnError> {
        let n = self.check_batch(s, u)?;
        let (ds, du, ne) = (self.dim_s(), self.dim_u(), self.dim_extra());
        if e.len() != n * ne {
            return Err(LearnError::Shape {
                what: "effect states",
                expected: n * ne,
                got: e.len(),
                hint: "n × dim_extra, row-major",
            });
        }
        check_finite("effect states", e)?;
        let (j, phys) = self.jacobians_core(n, s, Some(e), u);
        let Some((np_, jsp, jup)) = phys else {
            return Ok(j);
        };
        let nx = ds + ne;
        let mut out = StepJacobians {
            next: vec![0.0; n * nx],
            ds: vec![0.0; n * nx * nx],
            du: vec![0.0; n * nx * du],
        };
        for b in 0..n {
            out.next[b * nx..b * nx + ds].copy_from_slice(&j.next[b * ds..(b + 1) * ds]);
            out.next[b * nx + ds..(b + 1) * nx].copy_from_slice(&np_[b * nx + ds..(b + 1) * nx]);
            for r in 0..nx {
                for c in 0..nx {
                    out.ds[b * nx * nx + r * nx + c] = if r < ds && c < ds {
                        j.ds[b * ds * ds + r * ds + c]
                    } else {
                        // the network reads no effect state: these are the physics' own
                        jsp[b * nx * nx + r * nx + c]
                    };
                }
                for c in 0..du {
                    out.du[b * nx * du + r * du + c] = if r < ds {
                        j.du[b * ds * du + r * du + c]
                    } else {
                        jup[b * nx * du + r * du + c]
                    };
                }
            }
        }
        Ok(out)
    }

    /// The Jacobians over the world state, and for a physics part with effect states its full
    /// step `(next, ∂/∂x, ∂/∂u)` over the augmented state. Effect states from `e`, else settled.
    #[allow(clippy::type_complexity)]
    fn jacobians_core(
        &self,
        n: usize,
        s: &[f64],
        e: Option<&[f64]>,
        u: &[f64],
    ) -> (StepJacobians, Option<(Vec<f64>, Vec<f64>, Vec<f64>)>) {
        let (ds, du) = (self.dim_s(), self.dim_u());
        let mut phys_full = None;
        let lr = self.world.learned_dims();
        let dz = lr.len();
        let mut next = vec![0.0; n * ds];
        let mut js = vec![0.0; n * ds * ds];
        let mut ju = vec![0.0; n * ds * du];
        if let Some(p) = &self.physics {
            if p.dim_state() == ds {
                p.step_jacobians(
                    &self.physics_solver,
                    n,
                    s,
                    u,
                    self.physics_time(),
                    &mut next,
                    &mut js,
                    &mut ju,
                );
            } else {
                // padded effect states are functions of the input (see `pad_effect_states`):
                // their columns fold into ∂/∂u by the chain rule
                let dp = p.dim_state();
                let sp = match e {
                    Some(e) => join_effect_states(n, ds, dp, s, e),
                    None => pad_effect_states(p, n, s, u),
                };
                let mut np_ = vec![0.0; n * dp];
                let mut jsp = vec![0.0; n * dp * dp];
                let mut jup = vec![0.0; n * dp * du];
                p.step_jacobians(
                    &self.physics_solver,
                    n,
                    &sp,
                    u,
                    self.physics_time(),
                    &mut np_,
                    &mut jsp,
                    &mut jup,
                );
                for b in 0..n {
                    next[b * ds..(b + 1) * ds].copy_from_slice(&np_[b * dp..b * dp + ds]);
                    // ∂e_settled/∂u when the effect states are padded
                    let pe = match e {
                        Some(_) => None,
                        None => Some(p.settled_effect_states_jacobian(&u[b * du..(b + 1) * du])),
                    };
                    for r in 0..ds {
                        for c in 0..ds {
                            js[b * ds * ds + r * ds + c] = jsp[b * dp * dp + r * dp + c];
                        }
                        for c in 0..du {
                            let mut v = jup[b * dp * du + r * du + c];
                            if let Some(pe) = &pe {
                                for q in ds..dp {
                                    v += jsp[b * dp * dp + r * dp + q] * pe[(q - ds) * du + c];
                                }
                            }
                            ju[b * ds * du + r * du + c] = v;
                        }
                    }
                }
                phys_full = Some((np_, jsp, jup));
            }
        }
        let Some(net) = &self.net else {
            return (
                StepJacobians {
                    next,
                    ds: js,
                    du: ju,
                },
                phys_full,
            );
        };
        let z: Vec<f32> = learned_part_f32(s, n, ds, lr.clone());
        let uf: Vec<f32> = u.iter().map(|&x| x as f32).collect();
        // core: z⁺ (or the residual for hybrid) and its Jacobians wrt z and u
        let mut zn = vec![0.0f64; n * dz];
        let mut jz = vec![0.0f64; n * dz * dz];
        let mut jzu = vec![0.0f64; n * dz * du];
        match self.kind {
            ModelKind::Residual | ModelKind::Hybrid => {
                let jn = net.input_jacobian(n, &z, &uf);
                let mut ws = net.mlp.workspace();
                let mut x = Vec::new();
                let mut y = vec![0.0f32; n * dz];
                net.eval_with(n, &z, &uf, &mut y, &mut ws, &mut x);
                let ni = dz + du;
                let residual = self.kind == ModelKind::Residual;
                for b in 0..n {
                    for o in 0..dz {
                        zn[b * dz + o] = f64::from(y[b * dz + o])
                            + if residual {
                                f64::from(z[b * dz + o])
                            } else {
                                0.0
                            };
                        for i in 0..dz {
                            jz[b * dz * dz + o * dz + i] = jn[b * dz * ni + o * ni + i]
                                + if residual && i == o { 1.0 } else { 0.0 };
                        }
                        for i in 0..du {
                            jzu[b * dz * du + o * du + i] = jn[b * dz * ni + o * ni + dz + i];
                        }
                    }
                }
            }
            _ => {
                let field = NetField::new(net);
                let solver = self.solver.unwrap_or(Solver::rk4());
                let mut o32 = vec![0.0f32; n * dz];
                let mut js32 = vec![0.0f32; n * dz * dz];
                let mut ju32 = vec![0.0f32; n * dz * du];
                ode::step_jacobians(
                    &field, &solver, n, &z, &uf, 1.0, &mut o32, &mut js32, &mut ju32,
                );
                for (a, b) in zn.iter_mut().zip(&o32) {
                    *a = f64::from(*b);
                }
                for (a, b) in jz.iter_mut().zip(&js32) {
                    *a = f64::from(*b);
                }
                for (a, b) in jzu.iter_mut().zip(&ju32) {
                    *a = f64::from(*b);
                }
            }
        }
        (
            self.finish_jacobians(n, s, &zn, &jz, &jzu, next, js, ju),
            phys_full,
        )
    }

    /// Completes [`Model::jacobians`] from the learned core `z⁺` (`zn`, or the residual for
    /// hybrids) and its Jacobians `jz`, `jzu`: adds the residual to the physics step (hybrid),
    /// copies (pushing) or applies the car pose kinematics by the chain rule (car).
    #[allow(clippy::too_many_arguments)]
    fn finish_jacobians(
        &self,
        n: usize,
        s: &[f64],
        zn: &[f64],
        jz: &[f64],
        jzu: &[f64],
        mut next: Vec<f64>,
        mut js: Vec<f64>,
        mut ju: Vec<f64>,
    ) -> StepJacobians {
        let (ds, du) = (self.dim_s(), self.dim_u());
        let lr = self.world.learned_dims();
        let dz = lr.len();
        if self.kind == ModelKind::Hybrid {
            for b in 0..n {
                for o in 0..dz {
                    let r = lr.start + o;
                    next[b * ds + r] += zn[b * dz + o];
                    for i in 0..dz {
                        js[b * ds * ds + r * ds + lr.start + i] += jz[b * dz * dz + o * dz + i];
                    }
                    for i in 0..du {
                        ju[b * ds * du + r * du + i] += jzu[b * dz * du + o * du + i];
                    }
                }
            }
            return StepJacobians {
                next,
                ds: js,
                du: ju,
            };
        }
        match self.world {
            World::Push => {
                next.copy_from_slice(zn);
                js.copy_from_slice(jz);
                ju.copy_from_slice(jzu);
            }
            World::Car => {
                for b in 0..n {
                    let si = &s[b * 6..b * 6 + 6];
                    let pose = [si[0], si[1], si[2]];
                    let v = [si[3], si[4], si[5]];
                    let vn = [zn[b * 3], zn[b * 3 + 1], zn[b * 3 + 2]];
                    let p = car_pose_update(self.dt, pose, v, vn);
                    let (pp, pv, pvn) = car_pose_partials(self.dt, pose, v, vn);
                    next[b * 6..b * 6 + 3].copy_from_slice(&p);
                    next[b * 6 + 3..b * 6 + 6].copy_from_slice(&vn);
                    let jsb = &mut js[b * 36..(b + 1) * 36];
                    let jub = &mut ju[b * 6 * du..(b + 1) * 6 * du];
                    let jzb = &jz[b * 9..(b + 1) * 9];
                    let jub_z = &jzu[b * 3 * du..(b + 1) * 3 * du];
                    for r in 0..3 {
                        for c in 0..3 {
                            jsb[r * 6 + c] = pp[r][c];
                            let mut acc = pv[r][c];
                            for m in 0..3 {
                                acc += pvn[r][m] * jzb[m * 3 + c];
                            }
                            jsb[r * 6 + 3 + c] = acc;
                            jsb[(3 + r) * 6 + c] = 0.0;
                            jsb[(3 + r) * 6 + 3 + c] = jzb[r * 3 + c];
                        }
                        for c in 0..du {
                            let mut acc = 0.0;
                            for m in 0..3 {
                                acc += pvn[r][m] * jub_z[m * du + c];
                            }
                            jub[r * du + c] = acc;
                            jub[(3 + r) * du + c] = jub_z[r * du + c];
                        }
                    }
                }
            }
        }
        StepJacobians {
            next,
            ds: js,
            du: ju,
        }
    }

    /// [`Model::jacobians`] with the NeuralODE step (Euler or RK4, fixed steps) differentiated
    /// stage by stage: at each stage the network's input Jacobian is evaluated once (reverse
    /// mode over the `dz` outputs, which also gives the stage output) and chained through the
    /// stage sums in `f64`, instead of one forward-mode pass through all stages per input
    /// direction. The same Jacobians to `f32` rounding of the network Jacobian; next states
    /// bit-identical to [`Model::step`] (the same stage arithmetic). Other kinds and solvers are
    /// [`Model::jacobians`] itself.
    pub fn jacobians_stagewise(&self, s: &[f64], u: &[f64]) -> Result<StepJacobians, LearnError> {
        // the solver as Model::jacobians uses it
        let fixed = match self.solver.unwrap_or(Solver::rk4()) {
            Solver::Rk4 { substeps } => Some((substeps.max(1) as usize, true)),
            Solver::Euler { substeps } => Some((substeps.max(1) as usize, false)),
            Solver::Dopri5(_) => None,
        };
        let (Some(net), Some((substeps, rk4)), true) = (
            &self.net,
            fixed,
            matches!(self.kind, ModelKind::NodeEuler | ModelKind::NodeRk4)
                && self.physics.is_none(),
        ) else {
            return self.jacobians(s, u);
        };
        let n = self.check_batch(s, u)?;
        let (ds, du) = (self.dim_s(), self.dim_u());
        let lr = self.world.learned_dims();
        let dz = lr.len();
        let ni = dz + du;
        // stage coefficients as the fixed-step solvers of dynlab-dynamics
        const RK4_A: [&[f64]; 4] = [&[], &[0.5], &[0.0, 0.5], &[0.0, 0.0, 1.0]];
        const RK4_B: [f64; 4] = [1.0 / 6.0, 1.0 / 3.0, 1.0 / 3.0, 1.0 / 6.0];
        const EULER_A: [&[f64]; 1] = [&[]];
        const EULER_B: [f64; 1] = [1.0];
        let (ta, tb): (&[&[f64]], &[f64]) = if rk4 {
            (&RK4_A, &RK4_B)
        } else {
            (&EULER_A, &EULER_B)
        };
        let h = 1.0 / substeps as f64;
        let stages = tb.len();
        // y: the state in f32 as the solver carries it; ty: ∂y/∂[z₀, u] (n × dz × ni, f64)
        let mut y: Vec<f32> = learned_part_f32(s, n, ds, lr.clone());
        let uf: Vec<f32> = u.iter().map(|&x| x as f32).collect();
        let mut ty = vec![0.0f64; n * dz * ni];
        for b in 0..n {
            for d in 0..dz {
                ty[b * dz * ni + d * ni + d] = 1.0;
            }
        }
        let mut ks = vec![vec![0.0f32; n * dz]; stages];
        let mut dks = vec![vec![0.0f64; n * dz * ni]; stages];
        let mut ytmp = vec![0.0f32; n * dz];
        let mut tstage = vec![0.0f64; n * dz * ni];
        let mut x = Vec::new();
        let mut ws = net.mlp.workspace();
        let mut jbuf: Vec<f32> = Vec::new();
        let mut jp = vec![0.0f64; ni];
        // the stage sum `y + Σ_j (h·a_j)·k_j` (f32, in order) and its tangent
        let combine = |y: &[f32],
                       ty: &[f64],
                       a: &[f64],
                       ks: &[Vec<f32>],
                       dks: &[Vec<f64>],
                       out: &mut [f32],
                       tout: &mut [f64]| {
            out.copy_from_slice(y);
            tout.copy_from_slice(ty);
            for (j, &aj) in a.iter().enumerate() {
                if aj != 0.0 {
                    let c = (h * aj) as f32;
                    for (o, k) in out.iter_mut().zip(&ks[j]) {
                        *o += c * *k;
                    }
                    let c = f64::from(c);
                    for (o, k) in tout.iter_mut().zip(&dks[j]) {
                        *o += c * *k;
                    }
                }
            }
        };
        for _ in 0..substeps {
            for i in 0..stages {
                combine(&y, &ty, ta[i], &ks, &dks, &mut ytmp, &mut tstage);
                net.fill_input(n, &ytmp, &uf, &mut x);
                let ok = match net.mlp.jacobian(&x, &mut ws) {
                    Ok(j) => {
                        jbuf.clear();
                        jbuf.extend_from_slice(j);
                        true
                    }
                    Err(_) => false,
                };
                let (k, dk) = (&mut ks[i], &mut dks[i]);
                if ok {
                    // k = out_mean + out_std · net (as Network::write_output)
                    let yout = ws.output();
                    for b in 0..n {
                        for o in 0..dz {
                            k[b * dz + o] = net.out_mean[o] + net.out_std[o] * yout[b * dz + o];
                        }
                    }
                    let j = &jbuf;
                    for b in 0..n {
                        let jb = &j[b * dz * ni..(b + 1) * dz * ni];
                        let tb_ = &tstage[b * dz * ni..(b + 1) * dz * ni];
                        for o in 0..dz {
                            let so = f64::from(net.out_std[o]);
                            for (c, v) in jp.iter_mut().enumerate() {
                                *v = f64::from(jb[o * ni + c]) * so * f64::from(net.in_inv_std[c]);
                            }
                            for c in 0..ni {
                                let mut acc = if c >= dz { jp[c] } else { 0.0 };
                                for m in 0..dz {
                                    acc += jp[m] * tb_[m * ni + c];
                                }
                                dk[b * dz * ni + o * ni + c] = acc;
                            }
                        }
                    }
                } else {
                    k.iter_mut().for_each(|v| *v = f32::NAN);
                    dk.iter_mut().for_each(|v| *v = f64::NAN);
                }
            }
            let ycur = y.clone();
            let tcur = ty.clone();
            combine(&ycur, &tcur, tb, &ks, &dks, &mut y, &mut ty);
        }
        let zn: Vec<f64> = y.iter().map(|&v| f64::from(v)).collect();
        let mut jz = vec![0.0f64; n * dz * dz];
        let mut jzu = vec![0.0f64; n * dz * du];
        for b in 0..n {
            for o in 0..dz {
                let row = &ty[b * dz * ni + o * ni..b * dz * ni + (o + 1) * ni];
                jz[b * dz * dz + o * dz..b * dz * dz + (o + 1) * dz].copy_from_slice(&row[..dz]);
                jzu[b * dz * du + o * du..b * dz * du + (o + 1) * du].copy_from_slice(&row[dz..]);
            }
        }
        let next = vec![0.0; n * ds];
        let js = vec![0.0; n * ds * ds];
        let ju = vec![0.0; n * ds * du];
        Ok(self.finish_jacobians(n, s, &zn, &jz, &jzu, next, js, ju))
    }

    /// Whether [`Model::rollout_f32`] runs the allocation-free batched path for this kind
    /// (residual, NeuralODE Euler and RK4); the other kinds fall back to [`Model::step`].
    pub fn has_fast_rollout(&self) -> bool {
        matches!(
            self.kind,
            ModelKind::Residual | ModelKind::NodeEuler | ModelKind::NodeRk4
        )
    }

    /// Batched open-loop rollout for sampling controllers, in `f32`: `n` samples (`s0`,
    /// `n × dim_s`), each with its own action sequence (`actions`, sample-major
    /// `n × horizon × dim_u`); `out` receives `n × horizon × dim_s`. Samples are split over
    /// `ws`'s threads in contiguous blocks; each sample's arithmetic does not depend on the split,
    /// so results are independent of the thread count. After the first call with a given batch
    /// size nothing is allocated per step.
    pub fn rollout_f32(
        &self,
        s0: &[f32],
        actions: &[f32],
        out: &mut [f32],
        ws: &mut RolloutWorkspace,
    ) -> Result<(), LearnError> {
        let (ds, du) = (self.dim_s(), self.dim_u());
        if s0.is_empty() || !s0.len().is_multiple_of(ds) {
            return Err(LearnError::Shape {
                what: "s0",
                expected: ds,
                got: s0.len(),
                hint: "n × dim_s",
            });
        }
        let n = s0.len() / ds;
        if !actions.len().is_multiple_of(n * du) || actions.is_empty() {
            return Err(LearnError::Shape {
                what: "actions",
                expected: n * du,
                got: actions.len(),
                hint: "n × horizon × dim_u, sample-major",
            });
        }
        let horizon = actions.len() / (n * du);
        if out.len() != n * horizon * ds {
            return Err(LearnError::Shape {
                what: "out",
                expected: n * horizon * ds,
                got: out.len(),
                hint: "n × horizon × dim_s, sample-major",
            });
        }
        let row = horizon * ds;
        if !self.has_fast_rollout() {
            return self.rollout_f32_fallback(n, horizon, s0, actions, out);
        }
        let Some(net) = &self.net else {
            return self.rollout_f32_fallback(n, horizon, s0, actions, out);
        };
        ws.prepare();
        let RolloutWorkspace { blocks, workers } = ws;
        workers.for_each_row_block(out, row, blocks, |rows, out, b| {
            self.fast_block(net, rows, horizon, s0, actions, out, b);
            Ok(())
        })?;
        Ok(())
    }

    fn rollout_f32_fallback(
        &self,
        n: usize,
        horizon: usize,
        s0: &[f32],
        actions: &[f32],
        out: &mut [f32],
    ) -> Result<(), LearnError> {
        let (ds, du, ne) = (self.dim_s(), self.dim_u(), self.dim_extra());
        let mut cur: Vec<f64> = s0.iter().map(|&x| f64::from(x)).collect();
        let mut next = vec![0.0; n * ds];
        let mut u = vec![0.0; n * du];
        // effect states, as Model::rollout: settled at each sample's first action, then carried
        let mut e: Vec<f64> = Vec::with_capacity(n * ne);
        let mut e_next = vec![0.0; n * ne];
        for t in 0..horizon {
            for i in 0..n {
                for d in 0..du {
                    u[i * du + d] = f64::from(actions[(i * horizon + t) * du + d]);
                }
            }
            if t == 0 {
                for i in 0..n {
                    e.extend(self.settled_extra(&u[i * du..(i + 1) * du]));
                }
            }
            self.step_with_extra(&cur, &e, &u, &mut next, &mut e_next)?;
            std::mem::swap(&mut e, &mut e_next);
            for i in 0..n {
                for d in 0..ds {
                    out[(i * horizon + t) * ds + d] = next[i * ds + d] as f32;
                }
            }
            std::mem::swap(&mut cur, &mut next);
        }
        Ok(())
    }

    #[allow(clippy::too_many_arguments)]
    fn fast_block(
        &self,
        net: &Network,
        rows: std::ops::Range<usize>,
        horizon: usize,
        s0: &[f32],
        actions: &[f32],
        out: &mut [f32],
        b: &mut BlockBuffers,
    ) {
        let (ds, du) = (self.dim_s(), self.dim_u());
        let lr = self.world.learned_dims();
        let dz = lr.len();
        let nb = rows.len();
        if nb == 0 {
            return;
        }
        b.reserve(nb, dz, du, net);
        let BlockBuffers {
            ws,
            x,
            z,
            zt,
            u,
            k,
            pose,
            vprev,
            ..
        } = b;
        let Some(ws) = ws.as_mut() else {
            return;
        };
        for (i, r) in rows.clone().enumerate() {
            z[i * dz..(i + 1) * dz].copy_from_slice(&s0[r * ds + lr.start..r * ds + lr.end]);
            if self.world == World::Car {
                pose[i * 3..i * 3 + 3].copy_from_slice(&s0[r * ds..r * ds + 3]);
            }
        }
        let (substeps, rk4) = match (self.kind, self.solver) {
            (ModelKind::NodeRk4, Some(Solver::Rk4 { substeps })) => (substeps.max(1), true),
            (ModelKind::NodeEuler, Some(Solver::Euler { substeps })) => (substeps.max(1), false),
            _ => (1, false),
        };
        let h = 1.0 / substeps as f32;
        let len = nb * dz;
        for t in 0..horizon {
            for i in 0..nb {
                let src = ((rows.start + i) * horizon + t) * du;
                u[i * du..(i + 1) * du].copy_from_slice(&actions[src..src + du]);
            }
            if self.world == World::Car {
                vprev[..len].copy_from_slice(&z[..len]);
            }
            for _ in 0..substeps {
                if rk4 {
                    let (k1, rest) = k.split_at_mut(1);
                    let (k2, rest) = rest.split_at_mut(1);
                    let (k3, k4) = rest.split_at_mut(1);
                    let (k1, k2, k3, k4) = (&mut k1[0], &mut k2[0], &mut k3[0], &mut k4[0]);
                    net.eval_with(nb, &z[..len], &u[..nb * du], &mut k1[..len], ws, x);
                    for j in 0..len {
                        zt[j] = z[j] + 0.5 * h * k1[j];
                    }
                    net.eval_with(nb, &zt[..len], &u[..nb * du], &mut k2[..len], ws, x);
                    for j in 0..len {
                        zt[j] = z[j] + 0.5 * h * k2[j];
                    }
                    net.eval_with(nb, &zt[..len], &u[..nb * du], &mut k3[..len], ws, x);
                    for j in 0..len {
                        zt[j] = z[j] + h * k3[j];
                    }
                    net.eval_with(nb, &zt[..len], &u[..nb * du], &mut k4[..len], ws, x);
                    let c = h / 6.0;
                    for j in 0..len {
                        z[j] += c * (k1[j] + 2.0 * k2[j] + 2.0 * k3[j] + k4[j]);
                    }
                } else {
                    let k1 = &mut k[0];
                    net.eval_with(nb, &z[..len], &u[..nb * du], &mut k1[..len], ws, x);
                    for j in 0..len {
                        z[j] += h * k1[j];
                    }
                }
            }
            for i in 0..nb {
                let o = &mut out[(i * horizon + t) * ds..(i * horizon + t + 1) * ds];
                match self.world {
                    World::Push => o.copy_from_slice(&z[i * 3..i * 3 + 3]),
                    World::Car => {
                        let v = &vprev[i * 3..i * 3 + 3];
                        let vn = &z[i * 3..i * 3 + 3];
                        let p = &mut pose[i * 3..i * 3 + 3];
                        let hd = self.dt as f32 * 0.5;
                        let psi_n = p[2] + hd * (v[2] + vn[2]);
                        let (s0_, c0) = p[2].sin_cos();
                        let (s1, c1) = psi_n.sin_cos();
                        p[0] += hd * (c0 * v[0] - s0_ * v[1] + c1 * vn[0] - s1 * vn[1]);
                        p[1] += hd * (s0_ * v[0] + c0 * v[1] + s1 * vn[0] + c1 * vn[1]);
                        p[2] = psi_n;
                        o[..3].copy_from_slice(p);
                        o[3..].copy_from_slice(vn);
                    }
                }
            }
        }
    }
}

/// Buffers of [`Model::rollout_f32`]: one set per thread, grown on first use, and the
/// persistent worker threads that roll out all but the first block (so a rollout starts no
/// thread; see [`dynlab_nn::parallel::Workers`]).
#[derive(Debug)]
pub struct RolloutWorkspace {
    blocks: Vec<BlockBuffers>,
    workers: Workers,
}

impl Default for RolloutWorkspace {
    fn default() -> Self {
        Self::new(1)
    }
}

impl RolloutWorkspace {
    /// Buffers for `threads` threads (at least 1); `threads − 1` worker threads are started.
    pub fn new(threads: usize) -> Self {
        Self {
            blocks: Vec::new(),
            workers: Workers::new(threads),
        }
    }

    /// The worker threads, for other batched work between rollouts (an MPPI step's sampling
    /// and scoring): one pool per controller, so no thread is started per step.
    pub fn workers(&mut self) -> &mut Workers {
        &mut self.workers
    }

    fn prepare(&mut self) {
        let threads = self.workers.threads();
        if self.blocks.len() != threads {
            self.blocks = (0..threads).map(|_| BlockBuffers::default()).collect();
        }
    }
}

#[derive(Debug, Default)]
struct BlockBuffers {
    ws: Option<Workspace>,
    spec: Vec<usize>,
    x: Vec<f32>,
    z: Vec<f32>,
    zt: Vec<f32>,
    u: Vec<f32>,
    k: [Vec<f32>; 4],
    pose: Vec<f32>,
    vprev: Vec<f32>,
}

impl BlockBuffers {
    fn reserve(&mut self, nb: usize, dz: usize, du: usize, net: &Network) {
        if self.ws.is_none() || self.spec != net.mlp.sizes() {
            self.ws = Some(net.mlp.workspace());
            self.spec = net.mlp.sizes().to_vec();
        }
        let grow = |v: &mut Vec<f32>, n: usize| {
            if v.len() < n {
                v.resize(n, 0.0);
            }
        };
        grow(&mut self.z, nb * dz);
        grow(&mut self.zt, nb * dz);
        grow(&mut self.u, nb * du);
        grow(&mut self.pose, nb * 3);
        grow(&mut self.vprev, nb * dz);
        for k in &mut self.k {
            grow(k, nb * dz);
        }
        grow(&mut self.x, nb * (dz + du));
        if let Some(ws) = &mut self.ws {
            ws.reserve(nb);
        }
    }
}

/// The physics state of a batch with the effect states appended, settled at each sample's
/// command ([`PhysicsModel::settled_effect_states`]: `d_f = d`, `δ_w = δ + δ₀`). A single step
/// sees only the measured state, not the command history, so this is all it can assume; within
/// the step the lags then act only through the command change. Everything that has the history
/// (training, the fit, evaluation, comparison, the diagnosis, the live predictor, the racer)
/// rebuilds the effect states with [`PhysicsModel::effect_states_along`] instead.
pub fn pad_effect_states(p: &PhysicsModel, n: usize, s: &[f64], u: &[f64]) -> Vec<f64> {
    let dp = p.dim_state();
    let ds = s.len() / n.max(1);
    let du = u.len() / n.max(1);
    let mut out = Vec::with_capacity(n * dp);
    for i in 0..n {
        out.extend_from_slice(&s[i * ds..(i + 1) * ds]);
        out.extend(p.settled_effect_states(&u[i * du..(i + 1) * du]));
    }
    out
}

/// `[s_i, e_i]` per sample: world states `s` (`n × ds`) with effect states `e`
/// (`n × (dp − ds)`).
fn join_effect_states(n: usize, ds: usize, dp: usize, s: &[f64], e: &[f64]) -> Vec<f64> {
    let ne = dp - ds;
    let mut out = Vec::with_capacity(n * dp);
    for i in 0..n {
        out.extend_from_slice(&s[i * ds..(i + 1) * ds]);
        out.extend_from_slice(&e[i * ne..(i + 1) * ne]);
    }
    out
}

/// The learned part `lr` of each of the `n` states of dimension `ds` in `s`, in f32, row after row.
fn learned_part_f32(s: &[f64], n: usize, ds: usize, lr: std::ops::Range<usize>) -> Vec<f32> {
    (0..n)
        .flat_map(|i| {
            s[i * ds + lr.start..i * ds + lr.end]
                .iter()
                .map(|&x| x as f32)
        })
        .collect()
}

fn check_finite(what: &'static str, v: &[f64]) -> Result<(), LearnError> {
    match v.iter().position(|x| !x.is_finite()) {
        Some(index) => Err(LearnError::NonFinite {
            what,
            index,
            value: v[index],
        }),
        None => Ok(()),
    }
}

/// Car pose after one step by the trapezoidal rule:
/// `ψ⁺ = ψ + h/2 (ω + ω⁺)`, `p⁺ = p + h/2 (R(ψ) v + R(ψ⁺) v⁺)`.
pub fn car_pose_update(h: f64, pose: [f64; 3], v: [f64; 3], vn: [f64; 3]) -> [f64; 3] {
    let hd = 0.5 * h;
    let psi_n = pose[2] + hd * (v[2] + vn[2]);
    let (s0, c0) = pose[2].sin_cos();
    let (s1, c1) = psi_n.sin_cos();
    [
        pose[0] + hd * (c0 * v[0] - s0 * v[1] + c1 * vn[0] - s1 * vn[1]),
        pose[1] + hd * (s0 * v[0] + c0 * v[1] + s1 * vn[0] + c1 * vn[1]),
        psi_n,
    ]
}

type M3 = [[f64; 3]; 3];

/// Partials of [`car_pose_update`] wrt the pose, `v` and `v⁺` (3 × 3 each).
pub fn car_pose_partials(h: f64, pose: [f64; 3], v: [f64; 3], vn: [f64; 3]) -> (M3, M3, M3) {
    let hd = 0.5 * h;
    let psi_n = pose[2] + hd * (v[2] + vn[2]);
    let (s0, c0) = pose[2].sin_cos();
    let (s1, c1) = psi_n.sin_cos();
    let a0 = -s0 * v[0] - c0 * v[1];
    let b0 = c0 * v[0] - s0 * v[1];
    let a1 = -s1 * vn[0] - c1 * vn[1];
    let b1 = c1 * vn[0] - s1 * vn[1];
    let pp = [
        [1.0, 0.0, hd * (a0 + a1)],
        [0.0, 1.0, hd * (b0 + b1)],
        [0.0, 0.0, 1.0],
    ];
    let pv = [
        [hd * c0, -hd * s0, hd * a1 * hd],
        [hd * s0, hd * c0, hd * b1 * hd],
        [0.0, 0.0, hd],
    ];
    let pvn = [
        [hd * c1, -hd * s1, hd * a1 * hd],
        [hd * s1, hd * c1, hd * b1 * hd],
        [0.0, 0.0, hd],
    ];
    (pp, pv, pvn)
}
