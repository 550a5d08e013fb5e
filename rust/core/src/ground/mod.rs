//! Ground utilities under every other module: atomic writes, names of a build's parts,
//! licence ids. They import nothing of blurset-core but `error`.
pub mod atomic;
pub mod license;
pub mod names;
