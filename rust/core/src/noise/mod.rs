//! Sensor noise (DESIGN §5): the model, its kernel, and noise from linear images.
pub mod kernel;
pub mod linear;
