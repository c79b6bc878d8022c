//! Dynamics models, solvers, state estimation and training data for the pushing and car robots.
//!
//! | module | what |
//! |---|---|
//! | [`conventions`] | state/action layouts of both robots, angle wrapping, pose error, `L_rel`, TVE, the discounted multi-step loss |
//! | [`data`] | poses + commands → trajectories (gaps, unwrap, zero-order hold, resampling), Savitzky–Golay velocities, k-step windows, seeded splits, normalisation |
//! | [`ode`] | the batched [`ode::VectorField`] trait; Euler, RK4, Dopri5; reverse mode, adjoint, forward mode and input Jacobians |
//! | [`physics`] | the car (dynamic bicycle, Pacejka, drivetrain) and pusher–slider models with named effects and exact Jacobians; residuals for fitting |
//! | [`real`] | `f32`/`f64` scalars for solvers, dual numbers for exact derivatives |
//!
//! Everything is plain numerics on slices: no DDS, no bag format, no clock, no unseeded
//! randomness.
//!
//! ```
//! use dynlab_dynamics::ode::{Solver, integrate};
//! use dynlab_dynamics::physics::{Effect, PhysicsModel};
//!
//! // the ORCA car with aerodynamic drag, one 20 ms step at 1.5 m/s, straight, half throttle
//! let mut car = PhysicsModel::car(&[Effect::AeroDrag])?;
//! car.set_param("aero_drag.c", 0.05)?;
//! let s0 = [0.0, 0.0, 0.0, 1.5, 0.0, 0.0];
//! let mut s1 = [0.0; 6];
//! let report = integrate(&car, &Solver::rk4(), 1, &s0, &[0.0, 0.5], 0.02, &mut s1);
//! assert!(report.is_success());
//! assert!((s1[0] - 0.03).abs() < 1e-3); // moved ≈ 1.5 m/s × 20 ms
//! println!("{car}");
//! # Ok::<(), dynlab_dynamics::physics::ModelError>(())
//! ```
#![warn(missing_docs)]
// Index loops mirror the equations (rows, columns, stages) in the numerical kernels.
#![allow(clippy::needless_range_loop)]

pub mod conventions;
pub mod data;
pub mod ode;
pub mod physics;
pub mod real;
