//! `trispline export`: any `surface.json` to STEP AP214 (and IGES) for CAD tools.
//!
//! A B-spline surface is written as it is. A Loop surface over a control mesh (a whole
//! object, of any topology) is written as one Bezier patch per control face, or per
//! sub-triangle (`export_patches`). Any other triangular surface (Bezier, Loop lattice,
//! grid) has no tensor-product form over its domain in general (a grid surface has
//! holes and ragged rims), so it is sampled densely over its whole
//! domain and a cubic B-spline is least-squares fitted to the samples, with parameters by
//! projection onto their best-fit plane and foot-point correction. The deviation reported
//! is the distance from every sample to the B-spline: the conversion error on the region
//! the triangular surface covers. Beyond it (the corners of the B-spline's rectangle that
//! hold no samples) the B-spline is an extrapolation; CAD users trim it there.

pub use super::export_args::ExportArgs;
use super::export_args::{beside, write_cad};
use crate::bspline::scattered::ScatteredSolver;
use crate::bspline::scattered::{fit_scattered, planar_parameters, ScatteredOptions};
use crate::bspline::BSplineSurface;
use crate::curvature::planar::DmsPatch;
use crate::curvature::{
    BezierPatch, DerivativeSurface, Domain, GridPatch, LoopMeshPatch, Triangular,
};
use crate::io::surface_json::{bspline_json, read_surface_json, SurfaceDescription};
use crate::io::write_atomic;
use crate::surface::box_spline::LatticeSpline;
use anyhow::{bail, Context};
use glam::DVec3;
use serde_json::json;
use std::path::Path;
use std::process::ExitCode;
use std::time::Instant;

/// The triangular surface of a description, with its kind's name (None for a B-spline).
fn triangular(d: SurfaceDescription) -> Result<Box<dyn DerivativeSurface>, BSplineSurface> {
    Ok(match d {
        SurfaceDescription::BSpline(s) => return Err(s),
        SurfaceDescription::Bezier { degree, controls } => {
            Box::new(BezierPatch { degree, controls })
        }
        SurfaceDescription::LoopGrid { surface, controls }
        | SurfaceDescription::BezierPatches { surface, controls } => {
            Box::new(GridPatch { surface, controls })
        }
        SurfaceDescription::LoopMesh { surface, controls } => {
            Box::new(LoopMeshPatch::new(surface, controls))
        }
        SurfaceDescription::Loop {
            domain_segments,
            controls,
        } => Box::new(Triangular {
            surface: LatticeSpline::new(domain_segments),
            controls,
        }),
        SurfaceDescription::BPatch { patch, controls } => Box::new(Triangular {
            surface: patch,
            controls,
        }),
        SurfaceDescription::Dms { spline, controls } => Box::new(DmsPatch { spline, controls }),
    })
}

/// The data region of a fitted patch: `surface.json`'s `trim` polygons, in the surface's
/// own parameters (grid (x, y) for grid surfaces, barycentric (u, v) for a Bezier
/// triangle). Outside it the triangular surface is an extrapolation over cells the
/// scan never reached, and converting that would make the CAD surface follow noise-free
/// but meaningless geometry (tens of metres off on a 15 m test patch).
struct Trim {
    outer: Vec<(f64, f64)>,
    holes: Vec<Vec<(f64, f64)>>,
}

impl Trim {
    fn read(path: &Path) -> anyhow::Result<Option<Trim>> {
        let bytes = std::fs::read(path).with_context(|| format!("reading {}", path.display()))?;
        let v: serde_json::Value = serde_json::from_slice(&bytes)
            .with_context(|| format!("{}: not JSON", path.display()))?;
        let ring = |r: &serde_json::Value| -> Vec<(f64, f64)> {
            r.as_array()
                .map(|pts| {
                    pts.iter()
                        .filter_map(|p| Some((p.get(0)?.as_f64()?, p.get(1)?.as_f64()?)))
                        .collect()
                })
                .unwrap_or_default()
        };
        let Some(t) = v.get("trim") else {
            return Ok(None);
        };
        let outer = t.get("outer").map(ring).unwrap_or_default();
        if outer.len() < 3 {
            return Ok(None);
        }
        let holes = t
            .get("holes")
            .and_then(|h| h.as_array())
            .map(|hs| hs.iter().map(ring).filter(|r| r.len() >= 3).collect())
            .unwrap_or_default();
        Ok(Some(Trim { outer, holes }))
    }

    fn contains(&self, p: (f64, f64)) -> bool {
        inside(&self.outer, p) && !self.holes.iter().any(|h| inside(h, p))
    }
}

/// Even-odd point-in-polygon test.
fn inside(ring: &[(f64, f64)], (x, y): (f64, f64)) -> bool {
    let mut odd = false;
    let mut j = ring.len() - 1;
    for i in 0..ring.len() {
        let ((xi, yi), (xj, yj)) = (ring[i], ring[j]);
        if (yi > y) != (yj > y) && x < xi + (y - yi) / (yj - yi) * (xj - xi) {
            odd = !odd;
        }
        j = i;
    }
    odd
}

/// Points of the surface at about `n` samples across its domain, inside `trim` if given.
fn sample(surface: &dyn DerivativeSurface, n: usize, trim: Option<&Trim>) -> Vec<DVec3> {
    let params: Vec<(f64, f64)> = match surface.domain() {
        Domain::Rectangle { u, v } => (0..=n)
            .flat_map(|i| {
                (0..=n).map(move |j| {
                    let (a, b) = (i as f64 / n as f64, j as f64 / n as f64);
                    (u.0 + (u.1 - u.0) * a, v.0 + (v.1 - v.0) * b)
                })
            })
            .collect(),
        Domain::Triangle => (0..=n)
            .flat_map(|i| (0..=n - i).map(move |j| (i as f64 / n as f64, j as f64 / n as f64)))
            .collect(),
        Domain::Cells => surface.own_lattice(n).params,
    };
    let params: Vec<(f64, f64)> = match trim {
        Some(t) => params.into_iter().filter(|&p| t.contains(p)).collect(),
        None => params,
    };
    surface
        .derivatives_at(&params)
        .into_iter()
        .map(|d| d.position)
        .collect()
}

/// What the conversion of a triangular surface measured.
struct Conversion {
    samples: usize,
    trimmed: bool,
    max: f64,
    rms: f64,
}

fn convert(
    surface: &dyn DerivativeSurface,
    trim: Option<&Trim>,
    args: &ExportArgs,
) -> anyhow::Result<(BSplineSurface, Conversion)> {
    let points = sample(surface, args.samples, trim);
    if points.len() < 16 {
        bail!(
            "only {} samples inside the surface's trim region (raise --samples)",
            points.len()
        );
    }
    let o = ScatteredOptions {
        counts: args.control,
        degrees: (3, 3),
        smoothing: args.smoothing,
        solver: ScatteredSolver::Direct,
        parameter_correction: 3,
    };
    let fit = fit_scattered(&points, &planar_parameters(&points), &o)
        .context("fitting a B-spline to the triangular surface")?;
    Ok((
        fit.surface,
        Conversion {
            samples: points.len(),
            trimmed: trim.is_some(),
            max: fit.stats.max_error,
            rms: fit.stats.rms_error,
        },
    ))
}

/// Runs `export`: converts the surface to a B-spline if needed, writes STEP (and IGES).
pub fn run(args: &ExportArgs) -> anyhow::Result<ExitCode> {
    let t0 = Instant::now();
    let (cu, cv) = args.control;
    if !(4..=1024).contains(&cu) || !(4..=1024).contains(&cv) {
        bail!("--control {cu}x{cv}: each side must be in 4..=1024 (cubic)");
    }
    if !(args.smoothing >= 0.0 && args.smoothing.is_finite()) {
        bail!("--smoothing must be a non-negative number");
    }
    if !(4..=2000).contains(&args.samples) {
        bail!("--samples must be in 4..=2000");
    }
    super::export_patches::check_flags(args)?;
    let description = read_surface_json(&args.surface)?;
    if let Some(dir) = args.step.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    }
    // A Loop surface over a control mesh (any topology) goes patch by patch, exactly
    // where its faces are regular; one tensor-product patch could not take a closed
    // surface or one with handles, and would span holes by extrapolation.
    if let SurfaceDescription::LoopMesh { surface, controls } = &description {
        return super::export_patches::run(args, surface, controls, t0);
    }
    let trim = match description {
        SurfaceDescription::BSpline(_) => None,
        _ => Trim::read(&args.surface)?,
    };
    let (bspline, conversion, kind) = match triangular(description) {
        Err(s) => (s, None, "bspline"),
        Ok(tri) => {
            let (s, c) = convert(tri.as_ref(), trim.as_ref(), args)?;
            (s, Some(c), "triangular")
        }
    };
    write_cad(args, &[&bspline])?;
    write_atomic(
        &beside(&args.step, ".json"),
        &serde_json::to_vec_pretty(&bspline_json(&bspline))?,
    )?;
    let deviation = conversion.as_ref().map(|c| {
        json!({
            "samples": c.samples,
            "region": if c.trimmed { "inside the surface's trim (the data region)" } else { "the whole domain" },
            "max": c.max,
            "rms": c.rms,
            "measure": "distance from each sample of the triangular surface (over the region above) to the B-spline at the sample's foot-point parameters, in the surface's unit",
        })
    });
    let report = json!({
        "input": args.surface.display().to_string(),
        "input_kind": kind,
        "step": args.step.display().to_string(),
        "units": args.units.name(),
        "control_grid": [bspline.counts().0, bspline.counts().1],
        "deviation": deviation,
        "wall_ms": t0.elapsed().as_secs_f64() * 1e3,
    });
    write_atomic(
        &beside(&args.step, ".report.json"),
        &serde_json::to_vec_pretty(&report)?,
    )?;
    match conversion {
        Some(c) => println!(
            "exported {}: {cu}x{cv} B-spline from the {kind} surface, deviation over {} samples max {:.3e} {u}, RMS {:.3e} {u}",
            args.step.display(),
            c.samples,
            c.max,
            c.rms,
            u = args.units
        ),
        None => println!("exported {}: the B-spline as it is", args.step.display()),
    }
    Ok(ExitCode::SUCCESS)
}
