//! Images: the sRGB encoding, accumulation of linear frames, EXR and PNG files, and
//! the QA numbers of a rendered view.
pub mod accumulate;
pub mod exr;
pub mod io;
pub mod qa;
