//! `inspect`, `subdivide` and `coarsen`.

use crate::io::{read_mesh_file, write_mesh_file, LoadOptions};
use crate::mesh::inverse::{coarsen, InverseError, InverseMethod};
use crate::mesh::loop_subdiv::subdivide;
use crate::mesh::stats::mesh_stats;
use crate::pipeline::worker::{point_cloud_route, WorkerConfig};
use anyhow::Context;
use std::path::PathBuf;
use std::process::ExitCode;

/// Arguments of `trispline inspect`.
#[derive(clap::Args, Debug)]
pub struct InspectArgs {
    /// The mesh or point cloud file to inspect (a point cloud also gets the triangulation
    /// `fit` would use, or the reason it is refused).
    pub input: PathBuf,
    /// Deepest level of subdivision connectivity to look for.
    #[arg(long, default_value_t = 8)]
    pub max_depth: usize,
}

/// Arguments of `trispline subdivide`.
#[derive(clap::Args, Debug)]
pub struct SubdivideArgs {
    /// The mesh file to subdivide.
    pub input: PathBuf,
    /// Loop subdivision steps; each one multiplies the face count by 4.
    #[arg(long, default_value_t = 1)]
    pub levels: usize,
    /// The mesh file to write: .obj, .ply or .glb.
    #[arg(short = 'o', long)]
    pub output: PathBuf,
}

/// Arguments of `trispline coarsen`.
#[derive(clap::Args, Debug)]
pub struct CoarsenArgs {
    /// A mesh with Loop subdivision connectivity.
    pub input: PathBuf,
    /// Inverse subdivision steps; each one divides the face count by 4.
    #[arg(long, default_value_t = 1)]
    pub levels: usize,
    /// How coarse positions are recovered: `exact` (the inverse of the subdivision rules)
    /// or `lsq` (the coarse net whose subdivision is closest in least squares).
    #[arg(long, default_value = "exact")]
    pub method: InverseMethod,
    /// The mesh file to write: .obj, .ply or .glb.
    #[arg(short = 'o', long)]
    pub output: PathBuf,
}

/// Runs `inspect`: prints the mesh's counts and subdivision depth as JSON.
pub fn inspect(args: &InspectArgs) -> anyhow::Result<ExitCode> {
    let loaded = read_mesh_file(&args.input, &LoadOptions::default())?;
    let mut stats = serde_json::to_value(mesh_stats(&loaded.mesh, args.max_depth))?;
    if loaded.is_point_cloud() {
        // What `fit` would make of it: the triangulation it fits through, the
        // reconstruction when it is no height field, or why neither.
        stats["point_cloud"] =
            point_cloud_route(&loaded.mesh, &WorkerConfig::default()).unwrap_or_default();
    }
    println!("{}", serde_json::to_string_pretty(&stats)?);
    Ok(ExitCode::SUCCESS)
}

/// Faces a subdivision writes at most: as many as the finest lattice `fit` resamples
/// (1e8 points), some 5 GB of mesh in memory before the file. Nine levels of a 320-face
/// sphere (84M faces) ran past a minute before this refused it.
const MAX_SUBDIVIDED_FACES: usize = 100_000_000;

/// Runs `subdivide`; refuses, before any work, a result over `MAX_SUBDIVIDED_FACES`.
pub fn subdivide_cmd(args: &SubdivideArgs) -> anyhow::Result<ExitCode> {
    let mesh = read_mesh_file(&args.input, &LoadOptions::default())?.mesh;
    let faces = u32::try_from(args.levels)
        .ok()
        .and_then(|l| 4usize.checked_pow(l))
        .and_then(|k| k.checked_mul(mesh.triangles.len()));
    if faces.is_none_or(|f| f > MAX_SUBDIVIDED_FACES) {
        anyhow::bail!(
            "{}: {} levels would make {} faces from {}, over the limit of {MAX_SUBDIVIDED_FACES} \
            (lower --levels)",
            args.input.display(),
            args.levels,
            faces.map_or("more than usize::MAX".into(), |f| f.to_string()),
            mesh.triangles.len()
        );
    }
    let fine = subdivide(&mesh, args.levels)
        .with_context(|| format!("{}: cannot subdivide", args.input.display()))?;
    write_mesh_file(&args.output, &fine)?;
    Ok(ExitCode::SUCCESS)
}

/// Runs `coarsen`; exit code 2 when the input lacks subdivision connectivity.
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
