//! Tests that run the `trispline` binary as a process (CLI commands, the daemon).
//! Kept apart from the in-process numeric tests so that their timing-sensitive checks
//! do not share the cores with heavy solves.

mod cli_bspline;
mod cli_curvature;
mod cli_export;
mod cli_fit;
mod cli_fit_scan;
mod cli_mesh;
mod cli_object;
mod cluster;
mod cluster_ops;
mod components;
mod daemon_crash;
mod daemon_harden;
mod daemon_objects;
mod daemon_ops;
mod daemon_pipe;
mod daemon_process;
mod daemon_support;
mod daemon_trust;
mod daemon_watch;
mod planar_kinds;
mod point_clouds;
mod schemas;
