//! Pushing and car simulators on rapier2d with hidden physical effects
#![warn(missing_docs)]
