//! Subcommand implementations; main.rs only dispatches.
