//! Trajectory optimisation through the learned car model.
