//! The residual explained by the effect library.
