//! The plan of a setting (DESIGN §2): cameras, the scene-dependent blur weight, the seeded
//! sampling of views, and each degradation kind's levels (motion blur's trajectories and
//! latent frames; each other kind in `kinds/`, listed once in [`kinds`]).
pub mod camera;
pub mod choices;
pub mod config;
pub mod cost;
pub mod degradation;
pub mod kind;
pub mod kind_levels;
pub mod kinds;
pub mod motion;
pub mod options;
pub mod presets;
pub mod region;
pub mod render;
pub mod renders;
pub mod sampling;
pub mod sampling_config;
pub mod spec;
pub mod target;
pub mod weights;
