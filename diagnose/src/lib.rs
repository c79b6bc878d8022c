//! Where a dynamics model fails and which physical effect it is missing, without DDS.
//!
//! | module | what |
//! |---|---|
//! | [`compare`] | a model held against measurements: errors per dimension, over time, binned against their causes, residual correlations, worst segments, the report |
//! | [`report`] | the offline HTML report builder (sections, tables, SVG figures) that `compare` and `diagnose` write |
//! | [`diagnosis`] | the residual explained by the effect library: fit each candidate effect, score it on held-out data, rank |
//! | [`discovery`] | beyond the library: a sparse search over named physics-informed terms on the residual, the discovered custom effect |
#![warn(missing_docs)]

pub mod compare;
pub mod diagnosis;
pub mod discovery;
pub mod report;
