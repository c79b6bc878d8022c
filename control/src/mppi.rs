//! Model predictive path integral control of the pushed block.
