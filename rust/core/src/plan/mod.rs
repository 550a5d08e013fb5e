//! The plan of a setting (DESIGN §2): cameras, the scene-dependent blur weight, the seeded
//! sampling of views, and each degradation kind's levels (motion blur's trajectories and
//! latent frames, defocus, camera shake).
pub mod camera;
pub mod choices;
pub mod config;
pub mod cost;
pub mod defocus;
pub mod degradation;
pub mod motion;
pub mod options;
pub mod presets;
pub mod region;
pub mod render;
pub mod renders;
pub mod sampling;
pub mod sampling_config;
pub mod shake;
pub mod spec;
pub mod target;
pub mod weights;
