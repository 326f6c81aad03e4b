use clap::{Parser, Subcommand};
use std::process::ExitCode;
use trispline::cli;

// A fit allocates and frees tens of MB per round; glibc maps each large block fresh and
// the kernel faults every page in again (38k page faults, ~30 % of a 40k-point scan's CPU
// time on this machine). mimalloc keeps freed memory for reuse (never purged: see
// `trispline::allocator`).
#[global_allocator]
static ALLOCATOR: mimalloc::MiMalloc = mimalloc::MiMalloc;

/// Scan patches in, smooth triangular surfaces out.
#[derive(Parser)]
#[command(name = "trispline", version, about)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Counts on the raw input as one JSON object.
    Inspect(cli::mesh_tools::InspectArgs),
    /// Forward Loop subdivision.
    Subdivide(cli::mesh_tools::SubdivideArgs),
    /// Inverse Loop subdivision (exit 2 without subdivision connectivity).
    Coarsen(cli::mesh_tools::CoarsenArgs),
    /// Fit a smooth triangular surface to a mesh: a scan patch, a whole object (closed,
    /// holed, any genus) or a mesh with subdivision connectivity.
    Fit(cli::fit::FitArgs),
    /// The daemon: watch a folder, fit every patch that arrives.
    Watch(cli::watch::WatchArgs),
    /// A cluster worker: fit jobs from a NATS JetStream queue (`watch --queue`) into a shared OUT.
    Worker(cli::worker::WorkerArgs),
    /// Fit a tensor-product B-spline surface to grid or scattered points (JSON, IGES, STEP, GLB).
    BsplineFit(cli::bspline_fit::BsplineFitArgs),
    /// Curvature, convex/concave/saddle regions and their boundaries of a surface.json.
    Curvature(cli::curvature::CurvatureArgs),
    /// Convert a surface.json of any kind to STEP AP214 (and IGES) for CAD tools.
    Export(cli::export::ExportArgs),
}

fn main() -> ExitCode {
    trispline::allocator::small_pages_only();
    trispline::allocator::keep_freed_memory();
    let cli = Cli::parse();
    let result = match &cli.command {
        Command::Inspect(a) => cli::mesh_tools::inspect(a),
        Command::Subdivide(a) => cli::mesh_tools::subdivide_cmd(a),
        Command::Coarsen(a) => cli::mesh_tools::coarsen_cmd(a),
        Command::Fit(a) => cli::fit::run(a),
        Command::Watch(a) => cli::watch::run_watch(a),
        Command::Worker(a) => cli::worker::run(a),
        Command::BsplineFit(a) => cli::bspline_fit::run(a),
        Command::Curvature(a) => cli::curvature::run(a),
        Command::Export(a) => cli::export::run(a),
    };
    match result {
        Ok(code) => code,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::from(2)
        }
    }
}
