//! `inspect`, `subdivide` and `coarsen`.

use crate::io::{read_mesh_file, write_mesh_file, LoadOptions};
use crate::mesh::inverse::{coarsen, InverseError, InverseMethod};
use crate::mesh::loop_subdiv::subdivide;
use crate::mesh::stats::mesh_stats;
use anyhow::Context;
use std::path::PathBuf;
use std::process::ExitCode;

#[derive(clap::Args, Debug)]
pub struct InspectArgs {
    pub input: PathBuf,
    /// Deepest level of subdivision connectivity to look for.
    #[arg(long, default_value_t = 8)]
    pub max_depth: usize,
}

#[derive(clap::Args, Debug)]
pub struct SubdivideArgs {
    pub input: PathBuf,
    #[arg(long, default_value_t = 1)]
    pub levels: usize,
    #[arg(short = 'o', long)]
    pub output: PathBuf,
}

#[derive(clap::Args, Debug)]
pub struct CoarsenArgs {
    pub input: PathBuf,
    #[arg(long, default_value_t = 1)]
    pub levels: usize,
    #[arg(long, default_value = "exact")]
    pub method: InverseMethod,
    #[arg(short = 'o', long)]
    pub output: PathBuf,
}

pub fn inspect(args: &InspectArgs) -> anyhow::Result<ExitCode> {
    let loaded = read_mesh_file(&args.input, &LoadOptions::default())?;
    let stats = mesh_stats(&loaded.mesh, args.max_depth);
    println!("{}", serde_json::to_string_pretty(&stats)?);
    Ok(ExitCode::SUCCESS)
}

pub fn subdivide_cmd(args: &SubdivideArgs) -> anyhow::Result<ExitCode> {
    let mesh = read_mesh_file(&args.input, &LoadOptions::default())?.mesh;
    let fine = subdivide(&mesh, args.levels)
        .with_context(|| format!("{}: cannot subdivide", args.input.display()))?;
    write_mesh_file(&args.output, &fine)?;
    Ok(ExitCode::SUCCESS)
}

pub fn coarsen_cmd(args: &CoarsenArgs) -> anyhow::Result<ExitCode> {
    let mesh = read_mesh_file(&args.input, &LoadOptions::default())?.mesh;
    match coarsen(&mesh, args.levels, args.method) {
        Ok(c) => {
            write_mesh_file(&args.output, &c.mesh)?;
            Ok(ExitCode::SUCCESS)
        }
        Err(e @ (InverseError::NotSubdivided { .. } | InverseError::Topology(_))) => {
            eprintln!("{}: {e}", args.input.display());
            Ok(ExitCode::from(2))
        }
    }
}
