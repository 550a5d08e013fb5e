//! Ground utilities under every other module: atomic writes, names of a build's parts,
//! licence ids, the limits of what a file read may make blurset allocate.
//! They import nothing of blurset-core but `error`.
pub mod atomic;
pub mod license;
pub mod limits;
pub mod names;
