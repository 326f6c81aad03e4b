//! Subcommand implementations; main.rs only dispatches.
pub mod mesh_tools;
