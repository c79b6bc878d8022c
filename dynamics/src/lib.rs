//! Dynamics models, solvers, state estimation and training data for the pushing and car robots
#![warn(missing_docs)]
