//! Learned and fitted dynamics models: model kinds, the model file, training and evaluation
#![warn(missing_docs)]
