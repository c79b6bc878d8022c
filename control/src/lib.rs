//! Controllers over learned dynamics, without DDS: MPPI for pushing (Tu & Lin) and gradient-based
//! trajectory optimisation for racing (Kohler et al.).
//!
//! | module | what |
//! |---|---|
//! | [`mppi`] | model predictive path integral control of the pushed block |
//! | [`racing`] | trajectory optimisation through the learned car model: offline manoeuvres and receding-horizon racing |
#![warn(missing_docs)]

pub mod mppi;
pub mod racing;
