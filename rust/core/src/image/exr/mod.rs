//! Linear float images on disk (OpenEXR): the reader of latent frames and the writers.
pub mod passes;
pub mod read;
pub mod write;
