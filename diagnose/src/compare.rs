//! A model held against measurements.
