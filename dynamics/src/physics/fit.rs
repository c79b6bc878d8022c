//! Residuals of a physics model on measured transitions and their exact Jacobian wrt the
//! parameters: the inputs of a Gauss–Newton / Levenberg–Marquardt fit.

use super::model::{ModelError, PhysicsModel};
use crate::conventions::wrap_angle;
use crate::ode::{OdeReport, OdeStatus, Solver};

/// One measured transition: from `s0` under input `u` held for `dt` to the measured `s1`.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Transition {
    /// Initial model state (full: effect states such as `d_f` included, e.g. from
    /// [`PhysicsModel::motor_lag_filter`]).
    pub s0: Vec<f64>,
    /// Input held over the step.
    pub u: Vec<f64>,
    /// Measured next state: at least as many values as there are residual weights.
    pub s1: Vec<f64>,
    /// Step \[s\] (pushing: 1 push).
    pub dt: f64,
}

/// Residuals and Jacobian of a batch.
#[derive(Clone, Debug, PartialEq)]
pub struct ResidualJacobian {
    /// `r[i·m + d] = w_d · (ŝ1_d − s1_d)` (angles wrapped), `m = weights.len()`.
    pub residuals: Vec<f64>,
    /// `∂r/∂θ`, `residuals.len() × n_params`, row-major.
    pub jacobian: Vec<f64>,
    /// Number of parameters (columns).
    pub cols: usize,
    /// Transitions whose integration did not succeed (their rows use the last finite state).
    pub failed: Vec<(usize, OdeReport)>,
}

fn check(model: &PhysicsModel, tr: &Transition, m: usize) -> Result<(), ModelError> {
    let ds = model.dim_state();
    if tr.s0.len() != ds {
        return Err(ModelError::Dimension {
            what: "transition.s0",
            expected: ds,
            got: tr.s0.len(),
        });
    }
    if tr.u.len() != model.dim_input() {
        return Err(ModelError::Dimension {
            what: "transition.u",
            expected: model.dim_input(),
            got: tr.u.len(),
        });
    }
    if tr.s1.len() < m {
        return Err(ModelError::Dimension {
            what: "transition.s1",
            expected: m,
            got: tr.s1.len(),
        });
    }
    Ok(())
}

fn residual_rows(model: &PhysicsModel, pred: &[f64], s1: &[f64], w: &[f64], out: &mut Vec<f64>) {
    let angles = model.angle_dims();
    for (d, wd) in w.iter().enumerate() {
        let e = pred[d] - s1[d];
        out.push(
            wd * if angles.contains(&d) {
                wrap_angle(e)
            } else {
                e
            },
        );
    }
}

/// Weighted one-step residuals `w ⊙ (ŝ1 − s1)` of a batch (angles wrapped), with the
/// integration reports. `weights` has one entry per compared state dimension (the first
/// `weights.len()` state dimensions; give 0 to ignore one).
pub fn residuals(
    model: &PhysicsModel,
    solver: &Solver,
    transitions: &[Transition],
    weights: &[f64],
) -> Result<(Vec<f64>, Vec<OdeReport>), ModelError> {
    let m = weights.len();
    let mut r = Vec::with_capacity(transitions.len() * m);
    let mut reps = Vec::with_capacity(transitions.len());
    let mut pred = vec![0.0; model.dim_state()];
    for tr in transitions {
        check(model, tr, m)?;
        reps.push(model.integrate_step(solver, 1, &tr.s0, &tr.u, tr.dt, &mut pred));
        residual_rows(model, &pred, &tr.s1, weights, &mut r);
    }
    Ok((r, reps))
}

/// [`residuals`] and their exact Jacobian wrt all model parameters, by reverse mode through the
/// solver's accepted steps (one reverse pass per compared dimension and transition; the
/// wrapped angle error has derivative 1). A fit selects the columns of the parameters it frees.
pub fn residuals_and_jacobian(
    model: &PhysicsModel,
    solver: &Solver,
    transitions: &[Transition],
    weights: &[f64],
) -> Result<ResidualJacobian, ModelError> {
    let m = weights.len();
    let (ds, du, np) = (model.dim_state(), model.dim_input(), model.params().len());
    let mut out = ResidualJacobian {
        residuals: Vec::with_capacity(transitions.len() * m),
        jacobian: Vec::with_capacity(transitions.len() * m * np),
        cols: np,
        failed: Vec::new(),
    };
    let mut pred = vec![0.0; ds];
    let mut tape = super::StepTape::default();
    let mut ybar = vec![0.0; ds];
    let mut sbar0 = vec![0.0; ds];
    let mut ubar = vec![0.0; du];
    let mut pbar = vec![0.0; np];
    for (i, tr) in transitions.iter().enumerate() {
        check(model, tr, m)?;
        let rep = model.integrate_step_taped(solver, 1, &tr.s0, &tr.u, tr.dt, &mut pred, &mut tape);
        if rep.status != OdeStatus::Success {
            out.failed.push((i, rep));
        }
        residual_rows(model, &pred, &tr.s1, weights, &mut out.residuals);
        for (d, &wd) in weights.iter().enumerate() {
            pbar.iter_mut().for_each(|x| *x = 0.0);
            if wd != 0.0 {
                ybar.iter_mut().for_each(|x| *x = 0.0);
                ybar[d] = wd;
                model.integrate_step_vjp(&tape, &ybar, &mut sbar0, &mut ubar, &mut pbar);
            }
            out.jacobian.extend_from_slice(&pbar);
        }
    }
    Ok(out)
}
