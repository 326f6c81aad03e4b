//! `trispline curvature`: a `surface.json` of any kind in; `curvature.glb`,
//! `boundaries.json`, `boundaries.obj`, `boundaries.igs` and `regions.json` out.

use crate::bspline::{BSplineCurve, BSplineSurface};
use crate::curvature::planar::DmsPatch;
use crate::curvature::regions::{analyze, Analysis, AnalysisOptions};
use crate::curvature::{
    BezierPatch, DerivativeSurface, GridPatch, LoopMeshPatch, RegionKind, Triangular,
};
use crate::io::glb::{glb_bytes, GlbAttributes};
use crate::io::iges::{iges_bytes, IgesOptions, IgesUnits};
use crate::io::polylines::obj_polylines_bytes;
use crate::io::surface_json::{read_surface_json, SurfaceDescription};
use crate::io::write_atomic;
use crate::surface::box_spline::LatticeSpline;
use crate::TriMesh;
use anyhow::{bail, Context};
use glam::DVec3;
use serde_json::json;
use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Instant;

/// What the vertex colours of curvature.glb show (`--colour`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Colouring {
    /// The region kind: convex blue, concave red, saddle green.
    Region,
    /// Gaussian curvature K.
    Gaussian,
    /// Mean curvature H.
    Mean,
    /// The larger principal curvature.
    KMax,
    /// The smaller principal curvature.
    KMin,
}

/// Arguments of `trispline curvature`.
#[derive(clap::Args, Debug)]
pub struct CurvatureArgs {
    /// A surface.json written by `fit` (bezier, loop, bpatch, dms) or `bspline-fit`
    /// (bspline). B-patches are sampled on their domain triangle (barycentric parameters),
    /// DMS splines triangle by triangle over their domain (parameters: domain points).
    pub surface: PathBuf,
    /// Samples per side of the parameter lattice (N x N on a rectangle, a triangular
    /// lattice of N a side on the reference triangle).
    #[arg(long, default_value_t = 201)]
    pub grid: usize,
    /// K and H within eps / size^2 and eps / size of zero count as zero (size: the
    /// bounding-box diagonal of the samples).
    #[arg(long, default_value_t = 1e-6)]
    pub zero_eps: f64,
    /// Regions with fewer samples are merged into their main neighbour.
    #[arg(long, default_value_t = 8)]
    pub min_region: usize,
    /// What curvature.glb's colours show; the signed quantities run blue (negative) through
    /// white to red (positive), saturating at the 98th percentile of their magnitude.
    #[arg(long, value_enum, default_value = "region")]
    pub colour: Colouring,
    /// The length unit of the surface's coordinates (those of the input it was fitted to),
    /// declared in boundaries.igs so that CAD tools read the loops at true size: `m`
    /// (the scans' unit), `mm` or `in`. A size implausible in that unit is warned about.
    #[arg(long, value_parser = super::bspline_fit::units_parser(), default_value = "m")]
    pub units: IgesUnits,
    /// Output folder (created if missing): curvature.glb, boundaries.json, boundaries.obj,
    /// boundaries.igs and regions.json.
    #[arg(long)]
    pub out: PathBuf,
}

fn region_colour(k: RegionKind) -> [f32; 4] {
    match k {
        RegionKind::Convex => [0.15, 0.35, 0.9, 1.0],
        RegionKind::Concave => [0.9, 0.2, 0.15, 1.0],
        RegionKind::Saddle => [0.15, 0.7, 0.25, 1.0],
    }
}

/// Blue (negative) - white - red (positive), clamped at the 98th percentile of |x| so a
/// few extreme samples do not wash out the rest.
fn diverging(values: &[f64]) -> Vec<[f32; 4]> {
    let mut mags: Vec<f64> = values
        .iter()
        .map(|x| x.abs())
        .filter(|x| x.is_finite())
        .collect();
    mags.sort_by(f64::total_cmp);
    let scale = mags
        .get(mags.len().saturating_sub(1) * 98 / 100)
        .copied()
        .filter(|&s| s > 0.0)
        .unwrap_or(1.0);
    values
        .iter()
        .map(|&x| {
            let t = (x / scale).clamp(-1.0, 1.0) as f32;
            if t >= 0.0 {
                [1.0, 1.0 - t, 1.0 - t, 1.0]
            } else {
                [1.0 + t, 1.0 + t, 1.0, 1.0]
            }
        })
        .collect()
}

/// The surface, its kind's name and, for the mesh layout, how `param_loops` pack the face.
type Loaded = (
    Box<dyn DerivativeSurface>,
    &'static str,
    Option<&'static str>,
);

fn load(args: &CurvatureArgs) -> anyhow::Result<Loaded> {
    let d = read_surface_json(&args.surface)?;
    let packing = matches!(d, SurfaceDescription::LoopMesh { .. }).then_some(
        "control face f at barycentric (u, v) is the point [2 f + u, v] (u, v in [0, 1])",
    );
    let (surface, kind): (Box<dyn DerivativeSurface>, &str) = match d {
        SurfaceDescription::BSpline(s) => (Box::new(s) as Box<dyn DerivativeSurface>, "bspline"),
        SurfaceDescription::Bezier { degree, controls } => {
            (Box::new(BezierPatch { degree, controls }), "bezier")
        }
        SurfaceDescription::LoopGrid { surface, controls } => {
            (Box::new(GridPatch { surface, controls }), "loop")
        }
        SurfaceDescription::BezierPatches { surface, controls } => {
            (Box::new(GridPatch { surface, controls }), "bezier")
        }
        SurfaceDescription::LoopMesh { surface, controls } => {
            (Box::new(LoopMeshPatch::new(surface, controls)), "loop")
        }
        SurfaceDescription::Loop {
            domain_segments,
            controls,
        } => (
            Box::new(Triangular {
                surface: LatticeSpline::new(domain_segments),
                controls,
            }),
            "loop",
        ),
        SurfaceDescription::BPatch { patch, controls } => (
            Box::new(Triangular {
                surface: patch,
                controls,
            }),
            "bpatch",
        ),
        SurfaceDescription::Dms { spline, controls } => {
            (Box::new(DmsPatch { spline, controls }), "dms")
        }
    };
    Ok((surface, kind, packing))
}

/// Runs `curvature`: samples the surface, classifies regions, writes the outputs.
pub fn run(args: &CurvatureArgs) -> anyhow::Result<ExitCode> {
    let t0 = Instant::now();
    if !(2..=4001).contains(&args.grid) {
        bail!("--grid must be in 2..=4001");
    }
    if !(args.zero_eps >= 0.0 && args.zero_eps.is_finite()) {
        bail!("--zero-eps must be a non-negative number");
    }
    let (surface, kind, packing) = load(args)?;
    let opts = AnalysisOptions {
        grid: args.grid,
        zero_eps: args.zero_eps,
        min_region: args.min_region.max(1),
    };
    let t = Instant::now();
    let a = analyze(surface.as_ref(), &opts);
    let analysis_ms = t.elapsed().as_secs_f64() * 1e3;
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("creating {}", args.out.display()))?;

    let loops: Vec<Vec<DVec3>> = a
        .regions
        .iter()
        .flat_map(|r| r.loops.iter().cloned())
        .collect();
    write_atomic(
        &args.out.join("curvature.glb"),
        &glb(&a, args.colour, &loops),
    )?;
    write_atomic(
        &args.out.join("boundaries.obj"),
        &obj_polylines_bytes(&loops),
    )?;
    let points: Vec<DVec3> = loops.iter().flatten().copied().collect();
    if let Some(w) = args
        .units
        .size_warning(super::bspline_fit::largest_side(&points))
    {
        eprintln!("warning: {w}");
    }
    // Degree-1 B-spline curves with chord-length knots are the polylines exactly.
    let curves: Vec<BSplineCurve> = loops.iter().filter_map(|l| polyline_curve(l)).collect();
    let iges = iges_bytes(
        &[] as &[&BSplineSurface],
        &curves.iter().collect::<Vec<_>>(),
        &IgesOptions {
            units: args.units,
            file_name: "boundaries.igs".into(),
            author: "trispline".into(),
            time: Some(std::time::SystemTime::now()),
        },
    );
    write_atomic(&args.out.join("boundaries.igs"), &iges)?;
    let mut boundaries = json!({
        "schema": "trispline.boundaries/1",
        "surface": args.surface.display().to_string(),
        "loops": "closed (last point = first), counter-clockwise in (u, v) around the region: outer boundaries counter-clockwise, holes clockwise",
        "regions": a.regions.iter().map(|r| json!({
            "id": r.id,
            "type": r.kind.name(),
            "code": r.kind as u8,
            "samples": r.samples,
            "loops": r.loops.iter().map(|l| l.iter().map(|p| [p.x, p.y, p.z]).collect::<Vec<_>>()).collect::<Vec<_>>(),
            "param_loops": r.param_loops.iter().map(|l| l.iter().map(|p| [p.0, p.1]).collect::<Vec<_>>()).collect::<Vec<_>>(),
        })).collect::<Vec<_>>(),
    });
    if let Some(p) = packing {
        boundaries["param_loops_encoding"] = json!(p);
    }
    write_atomic(
        &args.out.join("boundaries.json"),
        &serde_json::to_vec(&boundaries)?,
    )?;
    let range = |f: &dyn Fn(&crate::curvature::Curvature) -> f64| {
        let (lo, hi) = a
            .curvature
            .iter()
            .flatten()
            .map(f)
            .fold((f64::MAX, f64::MIN), |(lo, hi), x| (lo.min(x), hi.max(x)));
        json!([lo, hi])
    };
    let summary = json!({
        "convex": a.count(RegionKind::Convex),
        "concave": a.count(RegionKind::Concave),
        "saddle": a.count(RegionKind::Saddle),
        "surface_kind": kind,
        "grid": args.grid,
        "samples": a.positions.len(),
        "singular_samples": a.curvature.iter().filter(|c| c.is_none()).count(),
        "zero_tolerance": {"eps": args.zero_eps, "gaussian": a.tolerance.gaussian, "mean": a.tolerance.mean},
        "min_region": opts.min_region,
        "classification": "convex: K >= 0 and H <= 0; concave: K >= 0 and H > 0; saddle: K < 0; n = S_u x S_v / |S_u x S_v|",
        "curvature_range": {
            "gaussian": range(&|c| c.gaussian),
            "mean": range(&|c| c.mean),
            "k_max": range(&|c| c.k_max),
            "k_min": range(&|c| c.k_min),
        },
        "regions": a.regions.iter().map(|r| json!({
            "id": r.id, "type": r.kind.name(), "samples": r.samples,
            "loops": r.loops.len(), "boundary_points": r.loops.iter().map(Vec::len).sum::<usize>(),
        })).collect::<Vec<_>>(),
        "analysis_ms": analysis_ms,
        "analysis_phases_ms": a.timings_ms,
        "wall_ms": t0.elapsed().as_secs_f64() * 1e3,
    });
    // regions.json last: its presence marks a complete set.
    write_atomic(
        &args.out.join("regions.json"),
        &serde_json::to_vec_pretty(&summary)?,
    )?;
    Ok(ExitCode::SUCCESS)
}

fn glb(a: &Analysis, colouring: Colouring, loops: &[Vec<DVec3>]) -> Vec<u8> {
    let mesh = TriMesh::new(a.positions.clone(), a.lattice.triangles.clone());
    let normals: Vec<DVec3> = a
        .curvature
        .iter()
        .map(|c| c.map_or(DVec3::ZERO, |c| c.normal))
        .collect();
    let value = |f: fn(&crate::curvature::Curvature) -> f64| -> Vec<f64> {
        a.curvature
            .iter()
            .map(|c| c.as_ref().map_or(0.0, f))
            .collect()
    };
    let colours = match colouring {
        Colouring::Region => a.kinds.iter().map(|&k| region_colour(k)).collect(),
        Colouring::Gaussian => diverging(&value(|c| c.gaussian)),
        Colouring::Mean => diverging(&value(|c| c.mean)),
        Colouring::KMax => diverging(&value(|c| c.k_max)),
        Colouring::KMin => diverging(&value(|c| c.k_min)),
    };
    glb_bytes(
        &mesh,
        &GlbAttributes {
            normals: Some(&normals),
            colors: Some(&colours),
            polylines: loops,
        },
    )
}

fn polyline_curve(points: &[DVec3]) -> Option<BSplineCurve> {
    // Repeated points would give repeated interior knots of multiplicity > 1.
    let mut pts: Vec<DVec3> = Vec::with_capacity(points.len());
    for &p in points {
        if pts.last().is_none_or(|q: &DVec3| (*q - p).length() > 0.0) {
            pts.push(p);
        }
    }
    if pts.len() < 2 {
        return None;
    }
    let t = crate::bspline::basis::parameters(&pts, crate::bspline::ParamMethod::ChordLength);
    let mut knots = vec![0.0];
    knots.extend_from_slice(&t);
    knots.push(1.0);
    BSplineCurve::new(1, knots, pts).ok()
}
