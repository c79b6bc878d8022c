//! [`PhysicsModel`]: nominal model + enabled effects + flat parameter vector.

use super::JacobianTape;
use super::car::{self, CAR_NOMINAL_PARAMS, Slot};
use super::custom::{CustomEffect, CustomError, Target};
use super::features::{INPUT_LAG_STATES, INPUT_LAGS_S, input_lag_rates, input_lags_settled};
use super::push::{self, LimitSurface, PUSH_NOMINAL_PARAMS};
use super::{Effect, ParamSpec, Robot};
use crate::ode::VectorField;
use crate::real::{Dual, Real};
use std::fmt::Write as _;
use std::ops::Range;
use thiserror::Error;

/// Errors building or configuring a physics model.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum ModelError {
    /// An effect of the other robot.
    #[error(
        "effect {effect} belongs to the {effect_robot:?} model, not the {robot:?} model; choose from: {choices}"
    )]
    WrongRobot {
        /// The effect.
        effect: Effect,
        /// Its robot.
        effect_robot: Robot,
        /// The model's robot.
        robot: Robot,
        /// Effects available for the model.
        choices: String,
    },
    /// A limit surface chosen for the car.
    #[error("the limit surface '{0}' is a pushing model's; the car model has none")]
    NotPushing(LimitSurface),
    /// An effect listed twice.
    #[error("effect {0} is listed twice; list each effect once")]
    DuplicateEffect(Effect),
    /// An unknown effect name.
    #[error("unknown effect '{name}'; known effects: {known}")]
    UnknownEffect {
        /// The name given.
        name: String,
        /// All known names.
        known: String,
    },
    /// An unknown parameter name.
    #[error(
        "unknown parameter '{name}'; this model's parameters: {known} (an effect's parameters exist only with the effect added)"
    )]
    UnknownParam {
        /// The name given.
        name: String,
        /// The model's parameter names.
        known: String,
    },
    /// A parameter vector of the wrong length.
    #[error("expected {expected} parameters ({names}), got {got}")]
    ParamCount {
        /// Expected length.
        expected: usize,
        /// Given length.
        got: usize,
        /// Parameter names in order.
        names: String,
    },
    /// A parameter outside its bounds or not finite.
    #[error("parameter {name} = {value} is outside its bounds [{lower}, {upper}]")]
    ParamOutOfBounds {
        /// Qualified name (`aero_drag.c`).
        name: String,
        /// The value.
        value: f64,
        /// Lower bound.
        lower: f64,
        /// Upper bound.
        upper: f64,
    },
    /// A slice of the wrong length.
    #[error("{what} has length {got}, expected {expected}")]
    Dimension {
        /// Which argument.
        what: &'static str,
        /// Expected length.
        expected: usize,
        /// Given length.
        got: usize,
    },
    /// The effect is not enabled in this model.
    #[error("effect {0} is not enabled in this model; enable it first")]
    NotEnabled(Effect),
    /// A custom effect that cannot be added.
    #[error(transparent)]
    Custom(#[from] CustomError),
}

/// The contribution of one effect at a point, with its exact Jacobians.
#[derive(Clone, Debug, PartialEq)]
pub struct EffectTerm {
    /// The effect.
    pub effect: Effect,
    /// `Δf = f(s, u) − f_{without effect}(s, u)`, length `dim_s`.
    pub contribution: Vec<f64>,
    /// `∂Δf/∂s`, `dim_s × dim_s` row-major.
    pub d_state: Vec<f64>,
    /// `∂Δf/∂u`, `dim_s × dim_u` row-major.
    pub d_input: Vec<f64>,
    /// `∂Δf/∂θ_e` wrt the effect's own parameters, `dim_s × n_e` row-major.
    pub d_params: Vec<f64>,
}

/// A nominal physics model plus enabled effects, with a flat parameter vector
/// `θ = [nominal…, effect 1…, effect 2…, custom terms…]` (custom effects: see
/// [`PhysicsModel::add_custom`]). See the [module docs](super).
#[derive(Clone, Debug, PartialEq)]
pub struct PhysicsModel {
    robot: Robot,
    slots: Vec<Slot>,
    params: Vec<f64>,
    std_errors: Option<Vec<f64>>,
    dim_s: usize,
    /// Custom effects (their coefficients follow the library effects' parameters).
    custom: Vec<CustomEffect>,
    /// Whether the state ends with the lagged commands ([`INPUT_LAG_STATES`]), which a custom
    /// term on a lagged command needs.
    input_lags: bool,
    /// Pushing: how the pusher's force moves the block.
    limit_surface: LimitSurface,
}

impl PartialEq for Slot {
    fn eq(&self, o: &Self) -> bool {
        self.effect == o.effect && self.p_off == o.p_off && self.s_off == o.s_off
    }
}

const DIRS: usize = 8;

impl PhysicsModel {
    /// A model of `robot` with the given effects enabled, all parameters at their defaults.
    pub fn new(robot: Robot, effects: &[Effect]) -> Result<Self, ModelError> {
        let nominal = Self::nominal_specs(robot);
        let mut params: Vec<f64> = nominal.iter().map(|p| p.default).collect();
        let mut dim_s = match robot {
            Robot::Car => 6,
            Robot::Pushing => 3,
        };
        let mut slots = Vec::new();
        for &e in effects {
            if e.robot() != robot {
                return Err(ModelError::WrongRobot {
                    effect: e,
                    effect_robot: e.robot(),
                    robot,
                    choices: Self::available_effects(robot).join(", "),
                });
            }
            if slots.iter().any(|s: &Slot| s.effect == e) {
                return Err(ModelError::DuplicateEffect(e));
            }
            slots.push(Slot {
                effect: e,
                p_off: params.len(),
                s_off: dim_s,
            });
            params.extend(e.params().iter().map(|p| p.default));
            dim_s += e.extra_states().len();
        }
        Ok(Self {
            robot,
            slots,
            params,
            std_errors: None,
            dim_s,
            custom: Vec::new(),
            input_lags: false,
            limit_surface: LimitSurface::default(),
        })
    }

    /// Pushing: how the pusher's force moves the block (default
    /// [`LimitSurface::Ellipsoid`]).
    pub fn limit_surface(&self) -> LimitSurface {
        self.limit_surface
    }

    /// Chooses how the pushing model moves the block; the car has no limit surface.
    pub fn set_limit_surface(&mut self, surface: LimitSurface) -> Result<(), ModelError> {
        if self.robot != Robot::Pushing && surface != LimitSurface::default() {
            return Err(ModelError::NotPushing(surface));
        }
        self.limit_surface = surface;
        Ok(())
    }

    /// The car model (dynamic bicycle, Pacejka tires, drivetrain) with the given effects.
    pub fn car(effects: &[Effect]) -> Result<Self, ModelError> {
        Self::new(Robot::Car, effects)
    }

    /// The quasi-static pusher–slider with the given effects.
    pub fn pushing(effects: &[Effect]) -> Result<Self, ModelError> {
        Self::new(Robot::Pushing, effects)
    }

    /// Parses effect names (`"aero_drag"`, …).
    pub fn parse_effects(names: &[&str]) -> Result<Vec<Effect>, ModelError> {
        names
            .iter()
            .map(|n| {
                Effect::from_name(n).ok_or_else(|| ModelError::UnknownEffect {
                    name: n.to_string(),
                    known: Effect::ALL
                        .iter()
                        .map(|e| e.name())
                        .collect::<Vec<_>>()
                        .join(", "),
                })
            })
            .collect()
    }

    /// Names of the effects available for a robot.
    pub fn available_effects(robot: Robot) -> Vec<&'static str> {
        Effect::ALL
            .iter()
            .filter(|e| e.robot() == robot)
            .map(|e| e.name())
            .collect()
    }

    /// The nominal parameter specs of a robot.
    pub fn nominal_specs(robot: Robot) -> &'static [ParamSpec] {
        match robot {
            Robot::Car => &CAR_NOMINAL_PARAMS,
            Robot::Pushing => &PUSH_NOMINAL_PARAMS,
        }
    }

    pub(crate) fn slots(&self) -> &[Slot] {
        &self.slots
    }

    /// The robot.
    pub fn robot(&self) -> Robot {
        self.robot
    }

    /// Enabled effects in order.
    pub fn effects(&self) -> Vec<Effect> {
        self.slots.iter().map(|s| s.effect).collect()
    }

    /// State dimension (the robot's state plus effect states such as `d_f`).
    pub fn dim_state(&self) -> usize {
        self.dim_s
    }

    /// Input dimension.
    pub fn dim_input(&self) -> usize {
        match self.robot {
            Robot::Car => 2,
            Robot::Pushing => 3,
        }
    }

    /// State names (`x, y, ψ, vx, vy, ω, d_f` / `x, y, θ`).
    pub fn state_names(&self) -> Vec<&'static str> {
        let mut v: Vec<&'static str> = match self.robot {
            Robot::Car => vec!["x", "y", "ψ", "vx", "vy", "ω"],
            Robot::Pushing => vec!["x", "y", "θ"],
        };
        for s in &self.slots {
            v.extend_from_slice(s.effect.extra_states());
        }
        if self.input_lags {
            v.extend_from_slice(&INPUT_LAG_STATES);
        }
        v
    }

    /// Input names.
    pub fn input_names(&self) -> Vec<&'static str> {
        match self.robot {
            Robot::Car => vec!["δ", "d"],
            Robot::Pushing => vec!["p", "φ", "ℓ"],
        }
    }

    /// State dimensions that are angles (errors wrap).
    pub fn angle_dims(&self) -> Vec<usize> {
        vec![2]
    }

    /// The parameter vector.
    pub fn params(&self) -> &[f64] {
        &self.params
    }

    /// Every parameter with its owner (`None` for the nominal model), in vector order. Custom
    /// coefficients come last, also with owner `None` (name: the term index, unit: the
    /// coefficient's); [`PhysicsModel::custom_param_range`] tells them apart.
    pub fn param_specs(&self) -> Vec<(Option<Effect>, ParamSpec)> {
        let mut v: Vec<(Option<Effect>, ParamSpec)> = Self::nominal_specs(self.robot)
            .iter()
            .map(|p| (None, *p))
            .collect();
        for s in &self.slots {
            v.extend(s.effect.params().iter().map(|p| (Some(s.effect), *p)));
        }
        for c in &self.custom {
            v.extend(c.terms().iter().enumerate().map(|(j, t)| {
                let unit = t
                    .coefficient_unit()
                    .format(super::features::time_unit(self.robot));
                (
                    None,
                    ParamSpec {
                        name: intern(j.to_string()),
                        symbol: "θ",
                        unit: intern(unit),
                        lower: t.bounds().0,
                        upper: t.bounds().1,
                        default: 0.0,
                        description: "coefficient of a custom term",
                    },
                )
            }));
        }
        v
    }

    /// Qualified parameter names (`m`, `aero_drag.c`, `custom.<name>.<j>`) in vector order.
    pub fn param_names(&self) -> Vec<String> {
        let mut v: Vec<String> = self
            .param_specs()
            .iter()
            .take(self.custom_start())
            .map(|(e, p)| match e {
                Some(e) => format!("{}.{}", e.name(), p.name),
                None => p.name.to_string(),
            })
            .collect();
        for c in &self.custom {
            v.extend((0..c.terms().len()).map(|j| format!("custom.{}.{j}", c.name())));
        }
        v
    }

    /// Index of the first custom coefficient (= number of nominal and library effect
    /// parameters).
    fn custom_start(&self) -> usize {
        self.params.len() - self.custom.iter().map(|c| c.terms().len()).sum::<usize>()
    }

    /// Adds a custom effect (see [`CustomEffect`]): its coefficients (start values from the
    /// effect) are appended to the parameter vector as `custom.<name>.<j>`; standard errors, if
    /// set, get `NaN` for them. The first effect with a term on a lagged command appends the
    /// lagged commands ([`INPUT_LAG_STATES`]) to the state.
    pub fn add_custom(&mut self, c: CustomEffect) -> Result<(), ModelError> {
        if c.robot() != self.robot {
            return Err(CustomError::WrongRobot {
                effect: c.name().to_string(),
                effect_robot: c.robot(),
                robot: self.robot,
            }
            .into());
        }
        if self.custom.iter().any(|o| o.name() == c.name()) {
            return Err(CustomError::Duplicate(c.name().to_string()).into());
        }
        if c.uses_input_lags() && !self.input_lags {
            self.input_lags = true;
            self.dim_s += INPUT_LAG_STATES.len();
        }
        self.params.extend(c.terms().iter().map(|t| t.coefficient));
        if let Some(s) = &mut self.std_errors {
            s.extend(c.terms().iter().map(|_| f64::NAN));
        }
        self.custom.push(c);
        Ok(())
    }

    /// The custom effects in order, with their coefficients at the model's current values.
    pub fn custom_effects(&self) -> Vec<CustomEffect> {
        self.custom
            .iter()
            .filter_map(|c| {
                let r = self.custom_param_range(c.name())?;
                Some(c.with_coefficients(&self.params[r]))
            })
            .collect()
    }

    /// The index range of a custom effect's coefficients.
    pub fn custom_param_range(&self, name: &str) -> Option<Range<usize>> {
        let mut off = self.custom_start();
        for c in &self.custom {
            let n = c.terms().len();
            if c.name() == name {
                return Some(off..off + n);
            }
            off += n;
        }
        None
    }

    /// A copy of this model with the library effects `extra` enabled as well: every parameter
    /// (nominal, effect, custom) keeps its value, the new effects start at their defaults.
    /// Use this rather than [`PhysicsModel::new`] to extend a model that may hold custom
    /// effects (their coefficients move behind the new effects' parameters).
    pub fn with_effects(&self, extra: &[Effect]) -> Result<PhysicsModel, ModelError> {
        let mut effects = self.effects();
        effects.extend_from_slice(extra);
        self.with_library(&effects)
    }

    /// A copy of this model without the library effects `drop`: every other parameter
    /// (nominal, effect, custom) keeps its value.
    pub fn without_effects(&self, drop: &[Effect]) -> Result<PhysicsModel, ModelError> {
        let mut effects = self.effects();
        effects.retain(|e| !drop.contains(e));
        self.with_library(&effects)
    }

    /// A copy of this model with the library effects `effects`; parameters kept by name.
    fn with_library(&self, effects: &[Effect]) -> Result<PhysicsModel, ModelError> {
        let mut m = PhysicsModel::new(self.robot, effects)?;
        m.limit_surface = self.limit_surface;
        for c in self.custom_effects() {
            m.add_custom(c)?;
        }
        let names = self.param_names();
        let mut p = m.params().to_vec();
        for (i, n) in m.param_names().iter().enumerate() {
            if let Some(k) = names.iter().position(|a| a == n) {
                p[i] = self.params[k];
            }
        }
        m.set_params(&p)?;
        Ok(m)
    }

    /// Index of a parameter by qualified name.
    pub fn param_index(&self, name: &str) -> Option<usize> {
        self.param_names().iter().position(|n| n == name)
    }

    /// The index range of an enabled effect's parameters.
    pub fn effect_param_range(&self, e: Effect) -> Option<Range<usize>> {
        self.slots
            .iter()
            .find(|s| s.effect == e)
            .map(|s| s.p_off..s.p_off + e.params().len())
    }

    /// Which parameters a fit frees by default, in vector order: the identifiable nominal
    /// parameters ([`CAR_FITTED_PARAMS`](super::CAR_FITTED_PARAMS),
    /// [`PUSH_FITTED_PARAMS`](super::PUSH_FITTED_PARAMS)) and every effect parameter except the
    /// width `w` of a patch's smooth edge (a modelling choice, not a physical quantity), and the
    /// nominal parameters an enabled effect is fitted with ([`Effect::coupled_nominal`]: the
    /// car's `ellipse` with a grip patch; [`CustomEffect::coupled_nominal`]: with a grip term). Measured values (mass, inertia, geometry, published
    /// drag) stay fixed.
    pub fn default_free(&self) -> Vec<bool> {
        let fitted: &[&str] = match self.robot {
            Robot::Car => &super::CAR_FITTED_PARAMS,
            Robot::Pushing => &super::PUSH_FITTED_PARAMS,
        };
        let coupled = |name: &str| {
            self.effects()
                .iter()
                .any(|e| e.coupled_nominal().contains(&name))
                || self
                    .custom_effects()
                    .iter()
                    .any(|c| c.coupled_nominal().contains(&name))
        };
        let start = self.custom_start();
        self.param_specs()
            .iter()
            .enumerate()
            .map(|(i, (e, p))| match e {
                _ if i >= start => true,
                None => fitted.contains(&p.name) || coupled(p.name),
                Some(_) => p.name != "w",
            })
            .collect()
    }

    /// Sets all parameters, checking length, finiteness and bounds.
    pub fn set_params(&mut self, p: &[f64]) -> Result<(), ModelError> {
        if p.len() != self.params.len() {
            return Err(ModelError::ParamCount {
                expected: self.params.len(),
                got: p.len(),
                names: self.param_names().join(", "),
            });
        }
        for ((v, (_, spec)), name) in p.iter().zip(self.param_specs()).zip(self.param_names()) {
            if !(v.is_finite() && *v >= spec.lower && *v <= spec.upper) {
                return Err(ModelError::ParamOutOfBounds {
                    name,
                    value: *v,
                    lower: spec.lower,
                    upper: spec.upper,
                });
            }
        }
        self.params.copy_from_slice(p);
        Ok(())
    }

    /// Sets one parameter by qualified name (bounds checked).
    pub fn set_param(&mut self, name: &str, value: f64) -> Result<(), ModelError> {
        let i = self
            .param_index(name)
            .ok_or_else(|| ModelError::UnknownParam {
                name: name.to_string(),
                known: self.param_names().join(", "),
            })?;
        let mut p = self.params.clone();
        p[i] = value;
        self.set_params(&p)
    }

    /// Standard errors of the parameters (from a fit), printed as `±` by
    /// [`PhysicsModel::equations`].
    pub fn set_std_errors(&mut self, std: Option<Vec<f64>>) -> Result<(), ModelError> {
        if let Some(s) = &std
            && s.len() != self.params.len()
        {
            return Err(ModelError::Dimension {
                what: "std_errors",
                expected: self.params.len(),
                got: s.len(),
            });
        }
        self.std_errors = std;
        Ok(())
    }

    /// Writes a full parameter vector `p` and its standard errors `std` (same length, or
    /// empty) of this model in each effect's canonical form ([`Effect::canonical`]): the same
    /// model, told one way.
    pub fn canonical(&self, p: &mut [f64], std: &mut [f64]) {
        for sl in &self.slots {
            let r = sl.p_off..sl.p_off + sl.effect.params().len();
            let mut none = [];
            let s = match std.len() == p.len() {
                true => &mut std[r.clone()],
                false => &mut none[..],
            };
            sl.effect.canonical(&mut p[r], s);
        }
    }

    /// The standard errors, if set.
    pub fn std_errors(&self) -> Option<&[f64]> {
        self.std_errors.as_deref()
    }

    /// The vector field at one point over any [`Real`], with parameters `p` and the effects
    /// whose `active` flag is set.
    pub fn eval_generic<R: Real>(&self, p: &[R], active: &[bool], s: &[R], u: &[R], out: &mut [R]) {
        match self.robot {
            Robot::Car => {
                // the custom terms read the lagged commands, if any, after the commands
                let mut ext = [R::cst(0.0); 2 + INPUT_LAG_STATES.len()];
                let terms_u = match self.input_lags_at() {
                    Some(off) => {
                        ext[..2].copy_from_slice(&u[..2]);
                        ext[2..].copy_from_slice(&s[off..self.dim_s]);
                        &ext[..]
                    }
                    None => u,
                };
                let inputs = car::Inputs {
                    steer: self.custom_input(Target::Delta, p, s, terms_u),
                    grip: self.custom_input(Target::Grip, p, s, terms_u),
                };
                car::rhs(p, &self.slots, active, s, u, inputs, out);
                self.add_custom_terms(p, s, terms_u, out);
                if let Some(off) = self.input_lags_at() {
                    input_lag_rates(&s[off..self.dim_s], u, &mut out[off..self.dim_s]);
                }
            }
            Robot::Pushing => {
                push::rhs(p, self, active, s, u, out);
                self.add_custom_terms(p, s, u, out);
            }
        }
    }

    /// Where the lagged commands ([`INPUT_LAG_STATES`]) start in the state, when the model
    /// carries them (last in the state).
    fn input_lags_at(&self) -> Option<usize> {
        self.input_lags.then(|| self.dim_s - INPUT_LAG_STATES.len())
    }

    /// Adds the custom effects' terms (always on) to `out`.
    pub(crate) fn add_custom_terms<R: Real>(&self, p: &[R], s: &[R], u: &[R], out: &mut [R]) {
        let mut off = self.custom_start();
        for c in &self.custom {
            let n = c.terms().len();
            c.add_to(&p[off..off + n], p, s, u, out);
            off += n;
        }
    }

    /// Whether a custom effect has a term on `target`.
    pub(crate) fn has_custom_target(&self, target: Target) -> bool {
        self.custom.iter().any(|c| c.acts_on(target))
    }

    /// The custom effects' correction of the input `target` (`δ`, `μ` terms).
    pub(crate) fn custom_input<R: Real>(&self, target: Target, p: &[R], s: &[R], u: &[R]) -> R {
        let mut off = self.custom_start();
        let mut d = R::cst(0.0);
        for c in &self.custom {
            let n = c.terms().len();
            d = d + c.input(target, &p[off..off + n], p, s, u);
            off += n;
        }
        d
    }

    fn all_active(&self) -> Vec<bool> {
        vec![true; self.slots.len()]
    }

    /// `f(s, u)` for one sample with the model's parameters.
    pub fn eval_one(&self, s: &[f64], u: &[f64], out: &mut [f64]) {
        let act = self.all_active();
        self.eval_generic(&self.params, &act, s, u, out);
    }

    /// Value and Jacobian of one sample: `f` and `J = ∂f/∂[s, u, θ]` (`dim_s × nz` row-major with
    /// `nz = dim_s + dim_u + n_params`, or without the θ block when `with_params` is false), by
    /// forward-mode dual numbers in passes of 8 directions.
    pub fn jacobian_full(
        &self,
        s: &[f64],
        u: &[f64],
        active: &[bool],
        with_params: bool,
        f: &mut [f64],
        j: &mut [f64],
    ) {
        let (ds, du) = (self.dim_s, self.dim_input());
        let np = if with_params { self.params.len() } else { 0 };
        let nz = ds + du + np;
        let mut sd = vec![Dual::<DIRS>::cst(0.0); ds];
        let mut ud = vec![Dual::<DIRS>::cst(0.0); du];
        let mut pd = vec![Dual::<DIRS>::cst(0.0); self.params.len()];
        let mut out = vec![Dual::<DIRS>::cst(0.0); ds];
        let mut base = 0;
        while base < nz.max(1) {
            let seed = |z: usize| z.wrapping_sub(base);
            for (i, x) in sd.iter_mut().enumerate() {
                *x = Dual::var(s[i], seed(i));
            }
            for (i, x) in ud.iter_mut().enumerate() {
                *x = Dual::var(u[i], seed(ds + i));
            }
            for (i, x) in pd.iter_mut().enumerate() {
                *x = if with_params {
                    Dual::var(self.params[i], seed(ds + du + i))
                } else {
                    Dual::cst(self.params[i])
                };
            }
            self.eval_generic(&pd, active, &sd, &ud, &mut out);
            super::scatter_duals(&out, base, nz, f, j);
            base += DIRS;
        }
    }

    /// The contribution of enabled effect `e` at `(s, u)` and its exact Jacobians wrt state,
    /// input and the effect's own parameters.
    pub fn effect_term(&self, e: Effect, s: &[f64], u: &[f64]) -> Result<EffectTerm, ModelError> {
        let idx = self
            .slots
            .iter()
            .position(|sl| sl.effect == e)
            .ok_or(ModelError::NotEnabled(e))?;
        self.check_dims(s, u)?;
        let (ds, du, np) = (self.dim_s, self.dim_input(), self.params.len());
        let nz = ds + du + np;
        let on = self.all_active();
        let mut off = on.clone();
        off[idx] = false;
        let (mut f1, mut f0) = (vec![0.0; ds], vec![0.0; ds]);
        let (mut j1, mut j0) = (vec![0.0; ds * nz], vec![0.0; ds * nz]);
        self.jacobian_full(s, u, &on, true, &mut f1, &mut j1);
        self.jacobian_full(s, u, &off, true, &mut f0, &mut j0);
        let range = self.slots[idx].p_off..self.slots[idx].p_off + e.params().len();
        let ne = range.len();
        let mut t = EffectTerm {
            effect: e,
            contribution: f1.iter().zip(&f0).map(|(a, b)| a - b).collect(),
            d_state: vec![0.0; ds * ds],
            d_input: vec![0.0; ds * du],
            d_params: vec![0.0; ds * ne],
        };
        for r in 0..ds {
            let d = |c: usize| j1[r * nz + c] - j0[r * nz + c];
            for c in 0..ds {
                t.d_state[r * ds + c] = d(c);
            }
            for c in 0..du {
                t.d_input[r * du + c] = d(ds + c);
            }
            for (k, c) in range.clone().enumerate() {
                t.d_params[r * ne + k] = d(ds + du + c);
            }
        }
        Ok(t)
    }

    fn check_dims(&self, s: &[f64], u: &[f64]) -> Result<(), ModelError> {
        if s.len() != self.dim_s {
            return Err(ModelError::Dimension {
                what: "state",
                expected: self.dim_s,
                got: s.len(),
            });
        }
        if u.len() != self.dim_input() {
            return Err(ModelError::Dimension {
                what: "input",
                expected: self.dim_input(),
                got: u.len(),
            });
        }
        Ok(())
    }

    /// The filtered throttle of the `motor_lag` effect along a command sequence held over steps
    /// of `dt`: the exact solution of `ḋ_f = (d − d_f)/τ` under zero-order hold,
    /// `d_f[i+1] = d[i] + (d_f[i] − d[i])·e^(−dt/τ)`, from `d_f[0] = d_f0`. It depends only on the
    /// commands and `τ`, which is what makes the lag identifiable from pose data: the initial
    /// extra state of every training window is reconstructed from the command log.
    pub fn motor_lag_filter(throttle: &[f64], dt: f64, tau: f64, d_f0: f64) -> Vec<f64> {
        let a = (-dt / tau.max(1e-9)).exp();
        let mut out = Vec::with_capacity(throttle.len());
        let mut df = d_f0;
        for &d in throttle {
            out.push(df);
            df = d + (df - d) * a;
        }
        out
    }

    /// Index of the first effect state in the model state: the robot's own state dimension
    /// (car 6, pushing 3).
    pub fn effect_state_offset(&self) -> usize {
        match self.robot {
            Robot::Car => 6,
            Robot::Pushing => 3,
        }
    }

    /// Number of effect states (`d_f` of `motor_lag`, `delta_w` of `steering_lag`).
    pub fn dim_effect_states(&self) -> usize {
        self.dim_s - self.effect_state_offset()
    }

    /// Names of the effect states, in state order.
    pub fn effect_state_names(&self) -> Vec<&'static str> {
        self.state_names()[self.effect_state_offset()..].to_vec()
    }

    /// The effect states settled under the held input `u` (`d_f = d`, `δ_w = δ + δ₀`): the
    /// start of a command history.
    pub fn settled_effect_states(&self, u: &[f64]) -> Vec<f64> {
        let ur: Vec<f64> = u.to_vec();
        self.settled_generic(&self.params, &ur)
    }

    /// `∂e/∂u` of [`PhysicsModel::settled_effect_states`] (`dim_effect_states × dim_input`,
    /// row-major): how a padded effect state moves with the input it settles to.
    pub fn settled_effect_states_jacobian(&self, u: &[f64]) -> Vec<f64> {
        let (ne, du) = (self.dim_effect_states(), self.dim_input());
        let ud: Vec<Dual<DIRS>> = u
            .iter()
            .enumerate()
            .map(|(i, &x)| Dual::var(x, i))
            .collect();
        let pd: Vec<Dual<DIRS>> = self.params.iter().map(|&x| Dual::cst(x)).collect();
        let e = self.settled_generic(&pd, &ud);
        let mut j = vec![0.0; ne * du];
        for r in 0..ne {
            for c in 0..du.min(DIRS) {
                j[r * du + c] = e[r].d[c];
            }
        }
        j
    }

    fn settled_generic<R: Real>(&self, p: &[R], u: &[R]) -> Vec<R> {
        let off = self.effect_state_offset();
        let mut full = vec![R::cst(0.0); self.dim_s];
        if self.robot == Robot::Car && self.dim_s > off {
            car::settled_effect_states(p, &self.slots, u, &mut full);
        }
        if let Some(at) = self.input_lags_at() {
            input_lags_settled(u, &mut full[at..]);
        }
        full[off..].to_vec()
    }

    /// Advances the effect states `e` over `dt` under the held input `u`, integrating only the
    /// effect states' own equations (they do not depend on the robot's state): classic RK4 with
    /// substeps of at most a quarter of the smallest time constant the effects allow (their lower
    /// bounds).
    pub fn advance_effect_states(&self, e: &mut [f64], u: &[f64], dt: f64) {
        self.advance_generic(&self.params, e, u, dt);
    }

    fn advance_generic<R: Real>(&self, p: &[R], e: &mut [R], u: &[f64], dt: f64) {
        let off = self.effect_state_offset();
        let ne = self.dim_s - off;
        if ne == 0 || self.robot != Robot::Car || dt.is_nan() || dt <= 0.0 {
            return;
        }
        // the substeps follow from the time constants' lower bounds, not their values: the
        // effect states then vary smoothly with the parameters (a fit differentiates them)
        let lags = self.input_lags_at().map_or(&[][..], |_| &INPUT_LAGS_S[..]);
        let tau_min = self
            .slots
            .iter()
            .filter_map(|sl| sl.effect.shortest_time_constant())
            .chain(lags.iter().copied())
            .fold(f64::INFINITY, f64::min)
            .max(1e-6);
        let substeps = (4.0 * dt / tau_min).ceil().clamp(1.0, 1000.0) as usize;
        let h = dt / substeps as f64;
        let active = vec![true; self.slots.len()];
        let ur: Vec<R> = u.iter().map(|&x| R::cst(x)).collect();
        let mut s = vec![R::cst(0.0); self.dim_s];
        let mut k = [
            vec![R::cst(0.0); self.dim_s],
            vec![R::cst(0.0); self.dim_s],
            vec![R::cst(0.0); self.dim_s],
            vec![R::cst(0.0); self.dim_s],
        ];
        let lagged = self.input_lags_at();
        let rates = |s: &[R], out: &mut [R]| {
            car::effect_state_rates(p, &self.slots, &active, s, &ur, out);
            if let Some(at) = lagged {
                input_lag_rates(&s[at..], &ur, &mut out[at..]);
            }
        };
        for _ in 0..substeps {
            let e0: Vec<R> = e.to_vec();
            for (stage, c) in [0.0, 0.5, 0.5, 1.0].into_iter().enumerate() {
                for i in 0..ne {
                    s[off + i] = if stage == 0 {
                        e0[i]
                    } else {
                        e0[i] + k[stage - 1][off + i] * (c * h)
                    };
                }
                let (_, rest) = k.split_at_mut(stage);
                rates(&s, &mut rest[0]);
            }
            for i in 0..ne {
                e[i] = e0[i]
                    + (k[0][off + i] + k[1][off + i] * 2.0 + k[2][off + i] * 2.0 + k[3][off + i])
                        * (h / 6.0);
            }
        }
    }

    /// **The initial effect states of every sample of a command sequence**: `u` holds `len`
    /// commands (`len × dim_input`, one per sample, each held for `dt` until the next sample)
    /// and the result `len × dim_effect_states` the effect states at each sample, started
    /// settled at the first command and advanced over the commands before each sample. Entry
    /// `a` is the initial effect state of a window starting at sample `a`. This is the one
    /// place that rebuilds effect states from commands: training, the physics fit, evaluation,
    /// comparison, the diagnosis, the live predictor and the racer all use it (or
    /// [`PhysicsModel::effect_states_from_history`], the same recursion).
    pub fn effect_states_along(&self, u: &[f64], dt: f64) -> Vec<f64> {
        self.effect_states_along_generic(&self.params, u, dt)
    }

    /// [`PhysicsModel::effect_states_along`] at parameters `p` over any [`Real`] (dual numbers
    /// give the states' derivatives wrt the parameters).
    pub fn effect_states_along_generic<R: Real>(&self, p: &[R], u: &[f64], dt: f64) -> Vec<R> {
        let du = self.dim_input();
        let ne = self.dim_effect_states();
        let len = u.len() / du.max(1);
        if ne == 0 || len == 0 {
            return Vec::new();
        }
        let mut out = Vec::with_capacity(len * ne);
        let u0: Vec<R> = u[..du].iter().map(|&x| R::cst(x)).collect();
        let mut e = self.settled_generic(p, &u0);
        for i in 0..len {
            out.extend_from_slice(&e);
            if i + 1 < len {
                self.advance_generic(p, &mut e, &u[i * du..(i + 1) * du], dt);
            }
        }
        out
    }

    /// The effect states after a command history (`history`, `m × dim_input`, each held for
    /// `dt`), started settled at its first command: the state in which the next command is
    /// applied. With an empty history, the states settled at `current`.
    pub fn effect_states_from_history(
        &self,
        history: &[f64],
        current: &[f64],
        dt: f64,
    ) -> Vec<f64> {
        let du = self.dim_input();
        if history.len() < du {
            return self.settled_effect_states(current);
        }
        let mut e = self.settled_effect_states(&history[..du]);
        for u in history.chunks_exact(du) {
            self.advance_effect_states(&mut e, u, dt);
        }
        e
    }

    fn fmt_param(&self, i: usize) -> String {
        let (_, spec) = self.param_specs()[i];
        let v = self.params[i];
        match self.std_errors.as_ref().map(|s| s[i]) {
            Some(se) if se > 0.0 => {
                format!("{} = {} ± {} {}", spec.symbol, num(v), num(se), spec.unit)
            }
            _ => format!("{} = {} {}", spec.symbol, num(v), spec.unit),
        }
    }

    /// The model's equations with the effect terms inlined and every parameter listed with its
    /// value (and `±` standard error after a fit), in the spirit of pysindy's `print()`.
    pub fn equations(&self) -> String {
        let mut o = String::new();
        let has = |e: Effect| self.slots.iter().find(|s| s.effect == e);
        let pv = |e: Effect, k: usize| has(e).map(|s| self.params[s.p_off + k]).unwrap_or(0.0);
        let tag = |e: Effect| -> String {
            match has(e) {
                Some(s) => {
                    let items: Vec<String> = (0..e.params().len())
                        .map(|k| self.fmt_param(s.p_off + k))
                        .collect();
                    format!("   ({} {})", e.name(), items.join(", "))
                }
                None => String::new(),
            }
        };
        match self.robot {
            Robot::Car => {
                let delay = has(Effect::CommandDelay).is_some();
                // the commands as they reach the car, before the servo's and the motor's lags
                let (d_in, target) = match (delay, has(Effect::SteeringOffset).is_some()) {
                    (true, _) => ("d̃", "δ̃".to_string()),
                    (false, true) => (
                        "d",
                        format!(
                            "(δ {} {})",
                            sign(pv(Effect::SteeringOffset, 0)),
                            num(pv(Effect::SteeringOffset, 0).abs())
                        ),
                    ),
                    (false, false) => ("d", "δ".to_string()),
                };
                let d = if has(Effect::MotorLag).is_some() {
                    "d_f"
                } else {
                    d_in
                };
                let delta = if has(Effect::SteeringLag).is_some() {
                    "δ_w".to_string()
                } else {
                    target
                };
                let _ = writeln!(
                    o,
                    "car: dynamic bicycle, Pacejka tires, drivetrain (time in s)"
                );
                let _ = writeln!(o, "  ẋ   = vx·cos ψ − vy·sin ψ");
                let _ = writeln!(o, "  ẏ   = vx·sin ψ + vy·cos ψ");
                let _ = writeln!(o, "  ψ̇   = ω");
                let drag = match has(Effect::AeroDrag) {
                    Some(_) => format!(" − {}·|v|·vx/m", num(pv(Effect::AeroDrag, 0))),
                    None => String::new(),
                };
                let _ = writeln!(
                    o,
                    "  v̇x  = (F_rx − F_fy·sin {delta})/m + vy·ω{drag}{}",
                    tag(Effect::AeroDrag)
                );
                let drag_y = match has(Effect::AeroDrag) {
                    Some(_) => format!(" − {}·|v|·vy/m", num(pv(Effect::AeroDrag, 0))),
                    None => String::new(),
                };
                let _ = writeln!(o, "  v̇y  = (F_ry + F_fy·cos {delta})/m − vx·ω{drag_y}");
                let _ = writeln!(o, "  ω̇   = (F_fy·l_f·cos {delta} − F_ry·l_r)/I_z");
                if has(Effect::MotorLag).is_some() {
                    let _ = writeln!(
                        o,
                        "  ḋ_f = ({d_in} − d_f)/{}{}",
                        num(pv(Effect::MotorLag, 0)),
                        tag(Effect::MotorLag)
                    );
                }
                if delay {
                    let td = pv(Effect::CommandDelay, 0);
                    let command = if has(Effect::SteeringOffset).is_some() {
                        "δ + δ₀"
                    } else {
                        "δ"
                    };
                    let (k, a, b) = (num(6.0 / (td * td)), num(2.0 * td / 3.0), num(td / 3.0));
                    let _ = writeln!(
                        o,
                        "  δ̈_c = {k}·({command} − δ_c − {a}·δ̇_c),  δ̃ = δ_c − {b}·δ̇_c   (the commands {} s late: second-order Padé){}",
                        num(td),
                        tag(Effect::CommandDelay)
                    );
                    let _ = writeln!(o, "  d̈_c = {k}·(d − d_c − {a}·ḋ_c),  d̃ = d_c − {b}·ḋ_c");
                }
                if has(Effect::SteeringLag).is_some() {
                    let target = match (delay, has(Effect::SteeringOffset).is_some()) {
                        (true, _) => "δ̃",
                        (false, true) => "δ + δ₀",
                        (false, false) => "δ",
                    };
                    let _ = writeln!(
                        o,
                        "  δ̇_w = {}·tanh(({target} − δ_w)/({}·{})){}",
                        num(pv(Effect::SteeringLag, 1)),
                        num(pv(Effect::SteeringLag, 1)),
                        num(pv(Effect::SteeringLag, 0)),
                        tag(Effect::SteeringLag)
                    );
                }
                let g = if has(Effect::GripPatch).is_some() {
                    "g·"
                } else {
                    ""
                };
                let _ = writeln!(
                    o,
                    "  F_fy = {g}D_f·sin(C_f·atan(B_f·α_f)),  α_f = −atan(v_lat,f / √(v_long,f² + v_reg²))"
                );
                let _ = writeln!(
                    o,
                    "  F_ry = {g}D_r·sin(C_r·atan(B_r·α_r)),  α_r = −atan((vy − l_r·ω) / √(vx² + v_reg²))"
                );
                let _ = writeln!(
                    o,
                    "  F_rx = (C_m1 − C_m2·vx)·{d} − C_r0·tanh(vx/v_reg) − C_r2·vx|vx|"
                );
                if has(Effect::SteeringOffset).is_some() {
                    let _ = writeln!(o, "  δ → δ + δ₀{}", tag(Effect::SteeringOffset));
                }
                if has(Effect::GripPatch).is_some() {
                    let _ = writeln!(
                        o,
                        "  g = 1 + (k − 1)·σ((r − ‖(x, y) − c‖)/w){}",
                        tag(Effect::GripPatch)
                    );
                }
            }
            Robot::Pushing => {
                let surface = match self.limit_surface {
                    LimitSurface::Ellipsoid => "ellipsoidal limit surface",
                    LimitSurface::SupportPoints => {
                        "the 5 × 5 support points' Coulomb friction solved exactly"
                    }
                };
                let _ = writeln!(
                    o,
                    "pushing: quasi-static pusher–slider, {surface} (time in pushes)"
                );
                let _ = writeln!(
                    o,
                    "  pusher on a world line: ψ = θ₀ + φ, start q = (x₀, y₀) + R(θ₀)·(−a/2 − r_p, κ·p·b/2), speed ℓ·L"
                );
                let _ = writeln!(
                    o,
                    "  contact: σ = (−a/2 − r_p − n·(q − o))/(n·d),  p_y = t·(q + σ·d − o),  v_p = ℓ·L·(cos(ψ − θ), sin(ψ − θ))"
                );
                let _ = writeln!(o, "  (ẋ, ẏ) = R(θ)·(v_cof + ω × (o − cof)),  θ̇ = ω");
                match has(Effect::PusherFriction) {
                    Some(_) => {
                        let _ = writeln!(
                            o,
                            "  F = M⁻¹·v_p if |F_y| ≤ μ_p·F_x (sticking), else F = f·(1, ±μ_p) (sliding){}",
                            tag(Effect::PusherFriction)
                        );
                    }
                    None => {
                        let _ =
                            writeln!(o, "  F = (v_px / (1 + p_y²/c²), 0)   (frictionless pusher)");
                    }
                }
                let _ = writeln!(o, "  v_cof = (F_x, F_y),  ω = (p_x·F_y − p_y·F_x)/c²");
                if has(Effect::ComOffset).is_some() {
                    let _ = writeln!(
                        o,
                        "  centre of friction = load centroid at (o_x, o_y) (block frame){}",
                        tag(Effect::ComOffset)
                    );
                }
                if has(Effect::FlatPusher).is_some() {
                    let _ = writeln!(
                        o,
                        "  flat pusher at world yaw ψ_f ({}), half width w, half thickness t: β = ψ_f − θ, r_p → t·|cos β| + w·|sin β|, p_y += t·sin β·sgn(cos β) − w·cos β·sgn(sin β){}",
                        num(pv(Effect::FlatPusher, 0)),
                        tag(Effect::FlatPusher)
                    );
                }
                if has(Effect::FrictionPatch).is_some() {
                    let _ = writeln!(
                        o,
                        "  μ_i/μ = 1 + (k − 1)·σ((r − ‖p_i − c‖)/w) per support point → centre of friction, c{}",
                        tag(Effect::FrictionPatch)
                    );
                }
                if has(Effect::TableTilt).is_some() {
                    let _ = writeln!(
                        o,
                        "  tilt: wrench f·(F̂, m̂) + R(θ)ᵀ(g_x, g_y) on the limit surface, twist scaled to v_px ({}, {}){}",
                        num(pv(Effect::TableTilt, 0)),
                        num(pv(Effect::TableTilt, 1)),
                        tag(Effect::TableTilt)
                    );
                }
            }
        }
        for c in self.custom_effects() {
            let r = self.custom_param_range(c.name()).unwrap_or(0..0);
            let _ = writeln!(o, "custom effect {}:", c.name());
            for (j, i) in r.enumerate() {
                let std = self.std_errors.as_ref().map(|s| s[i]);
                let _ = writeln!(
                    o,
                    "  {}   (custom.{}.{j})",
                    c.term_equation(j, self.params[i], std),
                    c.name()
                );
            }
        }
        if self.input_lags {
            let taus: Vec<String> = INPUT_LAGS_S.iter().map(|t| t.to_string()).collect();
            let _ = writeln!(
                o,
                "  lagged commands (effect states): u̇_τ = (u − u_τ)/τ for δ and d, τ = {} s",
                taus.join(", ")
            );
        }
        let _ = writeln!(o, "nominal parameters:");
        for i in 0..Self::nominal_specs(self.robot).len() {
            let (_, spec) = self.param_specs()[i];
            let _ = writeln!(o, "  {:<28} {}", self.fmt_param(i), spec.description);
        }
        o
    }
}

/// A `'static` copy of a short string, made once per distinct text (units and term indices of
/// custom coefficients, which [`ParamSpec`] holds as `&'static str`): the set of distinct texts
/// is small and bounded by the features' units.
fn intern(s: String) -> &'static str {
    use std::collections::HashSet;
    use std::sync::{Mutex, OnceLock};
    static SET: OnceLock<Mutex<HashSet<&'static str>>> = OnceLock::new();
    let mut set = SET
        .get_or_init(|| Mutex::new(HashSet::new()))
        .lock()
        .unwrap_or_else(|e| e.into_inner());
    if let Some(&v) = set.get(s.as_str()) {
        return v;
    }
    let v: &'static str = Box::leak(s.into_boxed_str());
    set.insert(v);
    v
}

fn sign(v: f64) -> &'static str {
    if v < 0.0 { "−" } else { "+" }
}

/// Compact number formatting: 4 significant digits, scientific outside [1e-4, 1e4).
fn num(v: f64) -> String {
    let a = v.abs();
    if v == 0.0 {
        "0".into()
    } else if !(1e-4..1e4).contains(&a) {
        format!("{v:.3e}")
    } else {
        let digits = (3 - a.log10().floor() as i32).max(0) as usize;
        format!("{v:.digits$}")
    }
}

impl std::fmt::Display for PhysicsModel {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.equations())
    }
}

impl VectorField<f64> for PhysicsModel {
    type Tape = JacobianTape;

    fn dim_s(&self) -> usize {
        self.dim_s
    }
    fn dim_u(&self) -> usize {
        self.dim_input()
    }
    fn n_params(&self) -> usize {
        self.params.len()
    }
    fn eval(&self, n: usize, s: &[f64], u: &[f64], out: &mut [f64]) {
        let (ds, du) = (self.dim_s, self.dim_input());
        let act = self.all_active();
        for i in 0..n {
            self.eval_generic(
                &self.params,
                &act,
                &s[i * ds..(i + 1) * ds],
                &u[i * du..(i + 1) * du],
                &mut out[i * ds..(i + 1) * ds],
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
        let act = self.all_active();
        tape.vjp(
            (self.dim_s, self.dim_input(), self.params.len()),
            |s, u, with_p, f, j| self.jacobian_full(s, u, &act, with_p, f, j),
            ybar,
            sbar,
            ubar,
            pbar,
        );
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
        let (ds, du) = (self.dim_s, self.dim_input());
        let act = self.all_active();
        let pd: Vec<Dual<1>> = self.params.iter().map(|&p| Dual::cst(p)).collect();
        let mut sd = vec![Dual::<1>::cst(0.0); ds];
        let mut ud = vec![Dual::<1>::cst(0.0); du];
        let mut od = vec![Dual::<1>::cst(0.0); ds];
        for i in 0..n {
            for k in 0..ds {
                sd[k] = Dual {
                    v: s[i * ds + k],
                    d: [sdot[i * ds + k]],
                };
            }
            for k in 0..du {
                ud[k] = Dual {
                    v: u[i * du + k],
                    d: [udot[i * du + k]],
                };
            }
            self.eval_generic(&pd, &act, &sd, &ud, &mut od);
            for k in 0..ds {
                out[i * ds + k] = od[k].v;
                out_dot[i * ds + k] = od[k].d[0];
            }
        }
    }
}
