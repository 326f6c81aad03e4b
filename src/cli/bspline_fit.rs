//! `trispline bspline-fit`: grid or scattered points in; `surface.json`, `surface.igs`,
//! `surface.stp`, `surface.glb` and `report.json` out.

use crate::bspline::basis::ParamMethod;
use crate::bspline::fit::{adaptive_grid, fit_grid, ErrorStats, Grid, GridMethod};
use crate::bspline::scattered::{
    adaptive_scattered, fit_scattered, planar_parameters, ScatteredOptions, ScatteredSolver,
};
use crate::bspline::BSplineSurface;
use crate::io::glb::{glb_bytes, GlbAttributes};
use crate::io::iges::{iges_bytes, IgesOptions, IgesUnits};
use crate::io::step::{step_bytes, StepOptions};
use crate::io::surface_json::bspline_json;
use crate::io::{read_mesh_file, write_atomic, LoadOptions};
use crate::mesh::simplify::SurfaceTopology;
use anyhow::{bail, Context};
use glam::DVec3;
use serde_json::json;
use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Instant;

/// A value parser for a core enum that names its choices: `--help` lists `names`, and the
/// chosen one goes through the enum's own `FromStr` (the core carries no clap derive).
fn named_parser<T>(
    names: impl IntoIterator<Item = &'static str>,
) -> impl clap::builder::TypedValueParser<Value = T>
where
    T: std::str::FromStr + Clone + Send + Sync + 'static,
    T::Err: std::error::Error + Send + Sync + 'static,
{
    use clap::builder::TypedValueParser;
    clap::builder::PossibleValuesParser::new(names).try_map(|s| s.parse::<T>())
}

fn grid_method_parser() -> impl clap::builder::TypedValueParser<Value = GridMethod> {
    named_parser(GridMethod::ALL.map(GridMethod::name))
}

/// The `--units` parser, shared with `curvature`.
pub fn units_parser() -> impl clap::builder::TypedValueParser<Value = IgesUnits> {
    named_parser(IgesUnits::ALL.map(IgesUnits::name))
}

/// How grid points get their parameters (`--param`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Param {
    /// Parameter steps proportional to the distance between neighbouring points.
    Chord,
    /// Parameter steps proportional to the square root of that distance (steadier at sharp turns).
    Centripetal,
}

/// How a scattered fit's least-squares system is solved (`--solver`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Solver {
    /// Exact least squares by a banded QR of the whole system.
    Direct,
    /// Progressive iterative approximation (LSPIA) from the plane through the data.
    Lspia,
}

/// Arguments of `trispline bspline-fit`.
#[derive(clap::Args, Debug)]
#[command(group(clap::ArgGroup::new("layout").required(true).args(["grid", "scattered"])))]
pub struct BsplineFitArgs {
    /// The point file (any mesh format trispline reads); only its vertices are used.
    pub input: PathBuf,
    /// The input's vertices are R rows of C points, row-major (a PLY range grid is read as
    /// its grid, or an R x C window of it with --window).
    #[arg(long, value_name = "RxC", value_parser = parse_pair_x)]
    pub grid: Option<(usize, usize)>,
    /// Range grids: the first row and column of the R x C window.
    #[arg(long, value_name = "ROW,COL", value_parser = parse_pair_comma, requires = "grid")]
    pub window: Option<(usize, usize)>,
    /// Every vertex is a data point; parameters by projection onto the best-fit plane.
    #[arg(long)]
    pub scattered: bool,
    /// Control points U x V (with --tolerance: the most the adaptive loop may use).
    #[arg(long, value_name = "UxV", value_parser = parse_pair_x)]
    pub control: (usize, usize),
    /// Polynomial degree in U and V (3,3 is bicubic).
    #[arg(long, value_name = "p,q", value_parser = parse_pair_comma, default_value = "3,3")]
    pub degree: (usize, usize),
    /// Grow the control net from the minimum until every point is within this distance.
    #[arg(long)]
    pub tolerance: Option<f64>,
    /// Grid fits: `lsq` is the exact least-squares surface; `two-pass` the documents'
    /// columns-then-rows approximation with interpolated ends.
    #[arg(long, value_parser = grid_method_parser(), default_value = "lsq")]
    pub method: GridMethod,
    /// Grid fits: how parameters are spaced along rows and columns.
    #[arg(long, value_enum, default_value = "chord")]
    pub param: Param,
    /// Scattered fits: weight of the control-net smoothing energy relative to the data
    /// (direct solver only).
    #[arg(long, default_value_t = 1e-6)]
    pub smoothing: f64,
    /// Scattered fits: how the least-squares system is solved.
    #[arg(long, value_enum, default_value = "direct")]
    pub solver: Solver,
    /// Scattered fits with --solver lspia: number of LSPIA steps.
    #[arg(long, default_value_t = 500)]
    pub lspia_iterations: usize,
    /// Scattered fits: rounds of foot-point parameter correction.
    #[arg(long, default_value_t = 2)]
    pub correction: usize,
    /// The input's length unit, declared in surface.igs and surface.stp so that CAD tools
    /// read true size (coordinates are written unscaled). Stanford scans are in metres.
    /// A warning is printed when the data's size is implausible in this unit.
    #[arg(long, value_parser = units_parser(), default_value = "m")]
    pub units: IgesUnits,
    /// Segments per side of the tessellation in surface.glb.
    #[arg(long, default_value_t = 64)]
    pub tessellation: usize,
    /// Output folder (created if missing): surface.json, surface.igs, surface.stp,
    /// surface.glb and report.json.
    #[arg(long)]
    pub out: PathBuf,
}

fn parse_pair(s: &str, sep: char) -> Result<(usize, usize), String> {
    let (a, b) = s
        .split_once(sep)
        .ok_or_else(|| format!("expected two integers separated by '{sep}'"))?;
    let p = |x: &str| x.trim().parse::<usize>().map_err(|e| format!("{x:?}: {e}"));
    Ok((p(a)?, p(b)?))
}
fn parse_pair_x(s: &str) -> Result<(usize, usize), String> {
    parse_pair(&s.to_ascii_lowercase(), 'x')
}
fn parse_pair_comma(s: &str) -> Result<(usize, usize), String> {
    parse_pair(s, ',')
}

/// The R x C grid of points the arguments describe.
fn grid_points(args: &BsplineFitArgs, rows: usize, cols: usize) -> anyhow::Result<Vec<DVec3>> {
    let loaded = read_mesh_file(&args.input, &LoadOptions::default())?;
    let name = args.input.display();
    match (&loaded.grid, args.window) {
        (Some(g), window) => {
            let (r0, c0) = window.unwrap_or((0, 0));
            if window.is_none() && (g.rows, g.cols) != (rows, cols) {
                bail!("{name}: range grid is {}x{}, not {rows}x{cols} (use --window ROW,COL for a part)", g.rows, g.cols);
            }
            if r0 + rows > g.rows || c0 + cols > g.cols {
                bail!(
                    "{name}: window {rows}x{cols} at {r0},{c0} leaves the {}x{} range grid",
                    g.rows,
                    g.cols
                );
            }
            let mut pts = Vec::with_capacity(rows * cols);
            let mut missing = 0;
            for r in r0..r0 + rows {
                for c in c0..c0 + cols {
                    match g.points[r * g.cols + c] {
                        Some(p) => pts.push(p),
                        None => missing += 1,
                    }
                }
            }
            if missing > 0 {
                bail!("{name}: {missing} cells of the {rows}x{cols} grid have no range data (grid fits need complete grids; use --scattered)");
            }
            Ok(pts)
        }
        (None, Some(_)) => bail!("{name}: --window needs a range grid input"),
        (None, None) => {
            let pts = loaded.mesh.positions;
            if pts.len() != rows * cols {
                bail!(
                    "{name}: {} vertices cannot be {rows}x{cols} grid points",
                    pts.len()
                );
            }
            Ok(pts)
        }
    }
}

fn scattered_points(args: &BsplineFitArgs) -> anyhow::Result<Vec<DVec3>> {
    let loaded = read_mesh_file(&args.input, &LoadOptions::default())?;
    // A closed surface, or one with handles, projects onto no plane without folding: one
    // patch over planar parameters came out as a folded sheet (CGAL's two knots). Scans
    // with stray pieces, and meshes whose topology cannot be told, go ahead.
    let topology = SurfaceTopology::of(&loaded.mesh).ok();
    if let Some(t) = topology.filter(|_| !loaded.mesh.triangles.is_empty()) {
        if let Some(topology) = folding_topology(&t) {
            bail!(
                "{}: a closed surface or one with handles {topology} has no planar \
                parameters, so one B-spline patch cannot take it; `trispline fit` fits whole \
                objects",
                args.input.display()
            );
        }
    }
    // Range grids: the valid cells (vertices of the triangulation may be a subset).
    Ok(match loaded.grid {
        Some(g) => g.points.into_iter().flatten().collect(),
        None => loaded.mesh.positions,
    })
}

/// `t` in words, when a surface of that topology projects onto no plane without folding
/// (closed, or with handles), the rule one tensor-product patch over planar parameters
/// needs both for points (`bspline-fit --scattered`) and for a surface (`export`); holes
/// and stray pieces are fine. `None` when it does not fold.
pub(crate) fn folding_topology(t: &SurfaceTopology) -> Option<String> {
    (t.boundary_loops == 0 || t.genus > 0).then(|| {
        format!(
            "({} components, genus {}, {} boundary loops)",
            t.components, t.genus, t.boundary_loops
        )
    })
}

/// The largest side of the points' axis-aligned bounding box.
pub(crate) fn largest_side(points: &[DVec3]) -> f64 {
    let (lo, hi) = points.iter().fold(
        (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY)),
        |(lo, hi), p| (lo.min(*p), hi.max(*p)),
    );
    (hi - lo).max_element().max(0.0)
}

/// Runs `bspline-fit`: reads the points, fits, writes the outputs.
pub fn run(args: &BsplineFitArgs) -> anyhow::Result<ExitCode> {
    let t0 = Instant::now();
    let param = match args.param {
        Param::Chord => ParamMethod::ChordLength,
        Param::Centripetal => ParamMethod::Centripetal,
    };
    // Sizes that would only exhaust memory are refused up front.
    let (cu, cv) = args.control;
    if cu > 4096 || cv > 4096 || cu * cv > 1 << 20 {
        bail!("--control {cu}x{cv}: at most 4096 a side and 2^20 in all");
    }
    if !(1..=4096).contains(&args.tessellation) {
        bail!("--tessellation must be in 1..=4096");
    }
    if let Some(t) = args.tolerance {
        if !(t > 0.0 && t.is_finite()) {
            bail!("--tolerance must be a positive number");
        }
    }
    let name = args.input.display().to_string();
    let (surface, stats, points, layout, fit_ms) = if let Some((rows, cols)) = args.grid {
        let pts = grid_points(args, rows, cols)?;
        let grid = Grid {
            rows,
            cols,
            points: &pts,
        };
        let t = Instant::now();
        let fit = match args.tolerance {
            Some(tol) => adaptive_grid(&grid, args.degree, tol, param, args.method, args.control),
            None => fit_grid(&grid, args.control, args.degree, param, args.method),
        }
        .with_context(|| format!("{name}: grid fit"))?;
        let ms = t.elapsed().as_secs_f64() * 1e3;
        (
            fit.surface,
            fit.stats,
            pts.len(),
            json!({"grid": [rows, cols], "window": args.window}),
            ms,
        )
    } else {
        let pts = scattered_points(args)?;
        let t = Instant::now();
        let params = planar_parameters(&pts);
        let o = ScatteredOptions {
            counts: args.control,
            degrees: args.degree,
            smoothing: args.smoothing,
            solver: match args.solver {
                Solver::Direct => ScatteredSolver::Direct,
                Solver::Lspia => ScatteredSolver::Lspia {
                    iterations: args.lspia_iterations,
                },
            },
            parameter_correction: args.correction,
        };
        let fit = match args.tolerance {
            Some(tol) => adaptive_scattered(&pts, &params, &o, tol),
            None => fit_scattered(&pts, &params, &o),
        }
        .with_context(|| format!("{name}: scattered fit"))?;
        let ms = t.elapsed().as_secs_f64() * 1e3;
        (
            fit.surface,
            fit.stats,
            pts.len(),
            json!({"scattered": true, "smoothing": args.smoothing, "solver": o.solver, "parameter_correction": args.correction}),
            ms,
        )
    };
    if let Some(w) = args.units.size_warning(largest_side(surface.controls())) {
        eprintln!("warning: {w}");
    }
    write_outputs(args, &surface, stats, points, layout, fit_ms, t0)?;
    Ok(ExitCode::SUCCESS)
}

fn write_outputs(
    args: &BsplineFitArgs,
    surface: &BSplineSurface,
    stats: ErrorStats,
    points: usize,
    layout: serde_json::Value,
    fit_ms: f64,
    t0: Instant,
) -> anyhow::Result<()> {
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("creating {}", args.out.display()))?;
    let (cu, cv) = surface.counts();
    let within = args.tolerance.is_none_or(|t| stats.max_error <= t);
    let fit = json!({
        "max_error": stats.max_error,
        "rms_error": stats.rms_error,
        "mean_error": stats.mean_error,
        "error_measure": "distance between each data point and the surface at its parameters",
    });
    let mut sj = bspline_json(surface);
    sj["fit"] = fit.clone();
    let iges = iges_bytes(
        &[surface],
        &[],
        &IgesOptions {
            units: args.units,
            file_name: "surface.igs".into(),
            author: "trispline".into(),
            time: Some(std::time::SystemTime::now()),
        },
    );
    let (mesh, normals) = surface.tessellate(args.tessellation, args.tessellation);
    let glb = glb_bytes(
        &mesh,
        &GlbAttributes {
            normals: Some(&normals),
            ..Default::default()
        },
    );
    let step = step_bytes(
        &[surface],
        &StepOptions {
            units: args.units,
            file_name: "surface.stp".into(),
            time: Some(std::time::SystemTime::now()),
        },
    );
    write_atomic(&args.out.join("surface.igs"), &iges)?;
    write_atomic(&args.out.join("surface.stp"), &step)?;
    write_atomic(&args.out.join("surface.glb"), &glb)?;
    let report = json!({
        "input": args.input.display().to_string(),
        "points": points,
        "layout": layout,
        "degree": [surface.degrees().0, surface.degrees().1],
        "control_grid": [cu, cv],
        "control_points": cu * cv,
        "units": args.units.name(),
        "method": if args.grid.is_some() { json!(args.method) } else { json!("scattered-lsq") },
        "tolerance": args.tolerance,
        "within_tolerance": within,
        "max_error": stats.max_error,
        "rms_error": stats.rms_error,
        "mean_error": stats.mean_error,
        "fit_ms": fit_ms,
        "wall_ms": t0.elapsed().as_secs_f64() * 1e3,
    });
    write_atomic(
        &args.out.join("report.json"),
        &serde_json::to_vec_pretty(&report)?,
    )?;
    // surface.json last: its presence marks a complete set.
    write_atomic(
        &args.out.join("surface.json"),
        &serde_json::to_vec_pretty(&sj)?,
    )?;
    Ok(())
}
