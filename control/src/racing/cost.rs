//! The cost `ℓ(x, u)`: targets (Kohler eq. 4), regulariser (eq. 5), input barriers (eq. 6),
//! progress along a track and the excursion cost beyond its borders.

use dynlab_sim::{Track, TrackLocation, wrap_angle};

use super::plant::{Input, State};

/// Input limits (the ORCA car's by default).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default)]
pub struct InputLimits {
    /// Largest steering magnitude \[rad\]. Default 0.35.
    pub steering_max: f64,
    /// Lowest throttle. Default −0.1.
    pub throttle_min: f64,
    /// Highest throttle. Default 1.
    pub throttle_max: f64,
}

impl Default for InputLimits {
    fn default() -> Self {
        Self {
            steering_max: 0.35,
            throttle_min: -0.1,
            throttle_max: 1.0,
        }
    }
}

impl InputLimits {
    /// Lower bounds `[δ, d]`.
    pub fn lower(&self) -> Input {
        [-self.steering_max, self.throttle_min]
    }
    /// Upper bounds `[δ, d]`.
    pub fn upper(&self) -> Input {
        [self.steering_max, self.throttle_max]
    }
    /// `u` clamped into the limits.
    pub fn clamp(&self, u: Input) -> Input {
        let (lo, hi) = (self.lower(), self.upper());
        [u[0].clamp(lo[0], hi[0]), u[1].clamp(lo[1], hi[1])]
    }
}

/// Input regulariser and barrier weights (eqs. 5 and 6).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default)]
pub struct Regulariser {
    /// Weight on `u_k²` per input `[δ, d]`. Default `[0.01, 0.01]`.
    pub magnitude: [f64; 2],
    /// Weight on `(u_k − u_{k−1})²` per input. Default `[0.1, 0.1]`.
    pub rate: [f64; 2],
    /// Weight of the one-sided quadratic barrier `max(0, u − u_max)² + max(0, u_min − u)²`.
    /// Default 1000.
    pub barrier: f64,
}

impl Default for Regulariser {
    fn default() -> Self {
        Self {
            magnitude: [0.01, 0.01],
            rate: [0.1, 0.1],
            barrier: 1000.0,
        }
    }
}

/// A target state at control step `step` (1 … n) with per-dimension weights (eq. 4; the
/// heading error is wrapped).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Target {
    /// Control step the target applies to (1 = after the first input).
    pub step: usize,
    /// Target state.
    pub state: State,
    /// Weights on `(x − x̄)²` per dimension.
    pub weight: State,
}

/// Racing terms: progress along the centre line at the last step and the excursion cost.
#[derive(Debug, Clone, Copy)]
pub struct TrackTerms<'t> {
    /// The track.
    pub track: &'t Track,
    /// Reward per metre of progress of `x_n` along the centre line (from `x₀`).
    pub progress_weight: f64,
    /// Distance kept from the borders \[m\] (constraint and excursion cost use
    /// `half_width − margin`).
    pub margin: f64,
    /// Growth of the margin per control step along the horizon \[m\]: step k keeps
    /// `margin + k · margin_growth` from the borders (see [`TrackTerms::margin_at`]; 0:
    /// constant). A model's prediction error grows with the horizon; a plan that keeps room
    /// in proportion to it stays feasible when the car does not follow the plan exactly.
    pub margin_growth: f64,
    /// Weight of `max(0, |lateral| − (half_width − margin))²` at every step (the paper's
    /// excursion cost; the SQP also imposes the borders as hard constraints).
    pub excursion_weight: f64,
    /// Weight of `(s_k − s₀ − k·reference_step)²` at every step: advance at a reference speed
    /// over the whole horizon, as the paper's racing cost does (0: off).
    pub reference_weight: f64,
    /// Reference progress per control step \[m\] (reference speed × control period).
    pub reference_step: f64,
    /// Reference progress from `x₀` after each control step \[m\] (step 1 first), e.g. from a
    /// curvature-aware [`SpeedProfile`](super::SpeedProfile); replaces `k · reference_step`
    /// for the steps it covers. Empty: constant reference speed.
    pub reference_progress: &'t [f64],
    /// Weight of the body-frame lateral velocity `v_y²` at every step \[s²/m²\] (0: off): keeps
    /// the plan in the tyres' linear range, away from slides and spins (which a learned model
    /// predicts worst and a receding horizon cannot recover from).
    pub slip_weight: f64,
}

impl TrackTerms<'_> {
    /// Distance kept from the borders at control step `k` of the horizon \[m\]:
    /// `margin + k · margin_growth`.
    pub fn margin_at(&self, k: usize) -> f64 {
        self.margin + k as f64 * self.margin_growth
    }
}

/// The total cost `ℓ(x(u), u)`.
#[derive(Debug, Clone)]
pub struct Objective<'t> {
    /// Target states.
    pub targets: Vec<Target>,
    /// Racing terms, if racing.
    pub track: Option<TrackTerms<'t>>,
    /// Input limits (barriers here; hard constraints in the SQP).
    pub limits: InputLimits,
    /// Regulariser weights.
    pub reg: Regulariser,
    /// The input applied before step 0 (for the rate term of `u₀`); `None`: no rate term on u₀.
    pub u_prev: Option<Input>,
    /// Track segment near `x₀` (from the previous cycle): `x₀` is then located by a local search
    /// around it, so that a track whose parts run close together is not confused; `None`: a
    /// full search.
    pub start_segment: Option<usize>,
}

/// Per-step state cost: value, gradient and Gauss–Newton Hessian wrt the state.
pub(crate) struct StateTerm {
    pub value: f64,
    pub grad: [f64; 6],
    pub hess: [f64; 36],
}

impl<'t> Objective<'t> {
    /// Locates every state on the track (chained local searches), if racing.
    pub(crate) fn locate(&self, states: &[State]) -> Vec<TrackLocation> {
        let Some(t) = &self.track else {
            return Vec::new();
        };
        let mut out = Vec::with_capacity(states.len());
        let mut hint = self.start_segment;
        for s in states {
            let loc = match hint {
                None => t.track.locate([s[0], s[1]]),
                Some(h) => t.track.locate_near([s[0], s[1]], h, 12),
            };
            hint = Some(loc.segment);
            out.push(loc);
        }
        out
    }

    /// Progress of `x_n` along the centre line from `x₀` \[m\] (0 when not racing).
    pub fn progress(&self, states: &[State]) -> f64 {
        let Some(t) = &self.track else { return 0.0 };
        let locs = self.locate(states);
        progress_between(t.track, &locs[0], &locs[locs.len() - 1])
    }

    /// Cost of state `x_k` (k ≥ 1) with its gradient and Gauss–Newton Hessian.
    #[allow(clippy::needless_range_loop)] // index loops mirror the equations
    pub(crate) fn state_term(
        &self,
        k: usize,
        n: usize,
        x: &State,
        loc: Option<(&TrackLocation, &TrackLocation)>,
    ) -> StateTerm {
        let mut st = StateTerm {
            value: 0.0,
            grad: [0.0; 6],
            hess: [0.0; 36],
        };
        for t in self.targets.iter().filter(|t| t.step == k) {
            for i in 0..6 {
                let mut r = x[i] - t.state[i];
                if i == 2 {
                    r = wrap_angle(r);
                }
                st.value += t.weight[i] * r * r;
                st.grad[i] += 2.0 * t.weight[i] * r;
                st.hess[i * 6 + i] += 2.0 * t.weight[i];
            }
        }
        if let (Some(tt), Some((l0, l))) = (&self.track, loc) {
            if tt.reference_weight > 0.0 {
                let goal = tt
                    .reference_progress
                    .get(k - 1)
                    .copied()
                    .unwrap_or(k as f64 * tt.reference_step);
                let r = progress_between(tt.track, l0, l) - goal;
                let c = tt.reference_weight;
                st.value += c * r * r;
                st.grad[0] += 2.0 * c * r * l.tangent[0];
                st.grad[1] += 2.0 * c * r * l.tangent[1];
                for a in 0..2 {
                    for b in 0..2 {
                        st.hess[a * 6 + b] += 2.0 * c * l.tangent[a] * l.tangent[b];
                    }
                }
            }
            if k == n {
                let prog = progress_between(tt.track, l0, l);
                st.value -= tt.progress_weight * prog;
                st.grad[0] -= tt.progress_weight * l.tangent[0];
                st.grad[1] -= tt.progress_weight * l.tangent[1];
            }
            if tt.slip_weight > 0.0 {
                let c = tt.slip_weight;
                st.value += c * x[4] * x[4];
                st.grad[4] += 2.0 * c * x[4];
                st.hess[4 * 6 + 4] += 2.0 * c;
            }
            let w = l.half_width - tt.margin_at(k);
            let e = l.lateral.abs() - w;
            if e > 0.0 {
                let sg = l.lateral.signum();
                let c = tt.excursion_weight;
                st.value += c * e * e;
                st.grad[0] += 2.0 * c * e * sg * l.normal[0];
                st.grad[1] += 2.0 * c * e * sg * l.normal[1];
                for r in 0..2 {
                    for q in 0..2 {
                        st.hess[r * 6 + q] += 2.0 * c * l.normal[r] * l.normal[q];
                    }
                }
            }
        }
        st
    }

    /// Input cost (regulariser and barriers) with gradient (`2n`) and Hessian (`2n × 2n`,
    /// row-major; the barrier by Gauss–Newton).
    pub(crate) fn input_terms(&self, u: &[Input]) -> (f64, Vec<f64>, Vec<f64>) {
        let n = u.len();
        let m = 2 * n;
        let mut g = vec![0.0; m];
        let mut h = vec![0.0; m * m];
        let mut v = 0.0;
        let (lo, hi) = (self.limits.lower(), self.limits.upper());
        for k in 0..n {
            for i in 0..2 {
                let a = k * 2 + i;
                let r = self.reg.magnitude[i];
                v += r * u[k][i] * u[k][i];
                g[a] += 2.0 * r * u[k][i];
                h[a * m + a] += 2.0 * r;
                let q = self.reg.rate[i];
                let prev = if k > 0 {
                    Some(u[k - 1][i])
                } else {
                    self.u_prev.map(|p| p[i])
                };
                if let Some(p) = prev {
                    let d = u[k][i] - p;
                    v += q * d * d;
                    g[a] += 2.0 * q * d;
                    h[a * m + a] += 2.0 * q;
                    if k > 0 {
                        let b = (k - 1) * 2 + i;
                        g[b] -= 2.0 * q * d;
                        h[b * m + b] += 2.0 * q;
                        h[a * m + b] -= 2.0 * q;
                        h[b * m + a] -= 2.0 * q;
                    }
                }
                let over = (u[k][i] - hi[i]).max(0.0) - (lo[i] - u[k][i]).max(0.0);
                if over != 0.0 {
                    let c = self.reg.barrier;
                    v += c * over * over;
                    g[a] += 2.0 * c * over;
                    h[a * m + a] += 2.0 * c;
                }
            }
        }
        (v, g, h)
    }

    /// Total cost of a trajectory (`states` = `x₀ … x_n`); infinite for non-finite states.
    pub fn cost(&self, states: &[State], u: &[Input]) -> f64 {
        if states.iter().flatten().any(|v| !v.is_finite()) {
            return f64::INFINITY;
        }
        let n = u.len();
        let locs = self.locate(states);
        let mut total = self.input_terms(u).0;
        for k in 1..=n {
            let loc = if locs.is_empty() {
                None
            } else {
                Some((&locs[0], &locs[k]))
            };
            total += self.state_term(k, n, &states[k], loc).value;
        }
        total
    }
}

/// Arc length from `a` to `b` along the track, wrapped into `(−L/2, L/2]`.
pub(crate) fn progress_between(track: &Track, a: &TrackLocation, b: &TrackLocation) -> f64 {
    let len = track.length();
    let mut d = (b.arc - a.arc) % len;
    if d > 0.5 * len {
        d -= len;
    } else if d <= -0.5 * len {
        d += len;
    }
    d
}
