//! Subcommand implementations; main.rs only dispatches.
pub mod bspline_fit;
pub mod curvature;
pub mod export;
mod export_args;
mod export_patches;
pub mod fit;
pub mod mesh_tools;
pub mod progress;
pub mod watch;
pub mod worker;
