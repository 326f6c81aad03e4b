//! `trispline export`'s arguments, and the files every export writes: STEP (and IGES)
//! with a unit check, and names beside the STEP file.

use super::bspline_fit::{largest_side, units_parser};
use crate::bspline::BSplineSurface;
use crate::io::iges::{iges_bytes, IgesOptions, IgesUnits};
use crate::io::step::{step_bytes, StepOptions};
use crate::io::write_atomic;
use glam::DVec3;
use std::path::{Path, PathBuf};

/// Arguments of `trispline export`.
#[derive(clap::Args, Debug)]
pub struct ExportArgs {
    /// A surface.json of any kind (bspline, bezier, loop).
    pub surface: PathBuf,
    /// The STEP AP214 file to write. Beside it, NAME.json holds the B-spline written (the
    /// converted one for triangular surfaces) and NAME.report.json the conversion figures.
    #[arg(long, value_name = "OUT.stp")]
    pub step: PathBuf,
    /// Also write the same B-spline as IGES (entity 128).
    #[arg(long, value_name = "OUT.igs")]
    pub iges: Option<PathBuf>,
    /// Triangular surfaces: control points U x V of the B-spline fitted to them (more
    /// follow the surface more closely; the deviation is reported). Ignored for bspline and for
    /// Loop surfaces over a control mesh (written as patches).
    #[arg(long, value_name = "UxV", value_parser = parse_counts, default_value = "24x24")]
    pub control: (usize, usize),
    /// Triangular surfaces: samples across the domain (each triangle or cell side is cut
    /// into about this many pieces in all).
    #[arg(long, default_value_t = 60)]
    pub samples: usize,
    /// Triangular surfaces: weight of the control net's bending energy relative to the
    /// samples. It holds the net calm where the B-spline's rectangle has no samples
    /// (the extrapolated corners CAD users trim away); larger values cost accuracy.
    #[arg(long, default_value_t = 1e-6)]
    pub smoothing: f64,
    /// The surface's length unit (m, mm or in), declared in the STEP and IGES files so
    /// that CAD tools read true size; coordinates are written unscaled.
    #[arg(long, value_parser = units_parser(), default_value = "m")]
    pub units: IgesUnits,
    /// Loop surfaces over a control mesh (whole objects): split each control face this
    /// many times uniformly (4^depth patches per face, 0..=3; default 0).
    #[arg(long, value_name = "N")]
    pub depth: Option<u32>,
    /// Loop surfaces over a control mesh: then halve the edges at irregular vertices this
    /// many times (0..=8; each level adds two patches per face corner there and
    /// shrinks the largest deviation, which sits there). By default the fewest levels, up
    /// to 6, whose largest deviation meets --tolerance.
    #[arg(long, value_name = "L")]
    pub corner_levels: Option<u32>,
    /// Loop surfaces over a control mesh: the largest deviation of the patches from the
    /// surface that the default corner levels aim for, in the surface's unit. Default: the
    /// fit's own RMS error from surface.json (the conversion adds at its worst point no
    /// more than the fit's typical error), or 1e-4 of the bounding-box diagonal.
    #[arg(long, value_name = "DISTANCE")]
    pub tolerance: Option<f64>,
}

fn parse_counts(s: &str) -> Result<(usize, usize), String> {
    let (a, b) = s
        .to_ascii_lowercase()
        .split_once('x')
        .map(|(a, b)| (a.trim().to_string(), b.trim().to_string()))
        .ok_or("expected UxV, e.g. 24x24")?;
    let p = |x: &str| x.parse::<usize>().map_err(|e| format!("{x:?}: {e}"));
    Ok((p(&a)?, p(&b)?))
}

/// Writes the STEP file (and IGES if asked) of these surfaces, after warning when their
/// size makes the declared unit implausible.
pub(super) fn write_cad(args: &ExportArgs, surfaces: &[&BSplineSurface]) -> anyhow::Result<()> {
    let controls: Vec<DVec3> = surfaces
        .iter()
        .flat_map(|s| s.controls().iter().copied())
        .collect();
    if let Some(w) = args.units.size_warning(largest_side(&controls)) {
        eprintln!("warning: {w}");
    }
    let file_name = |p: &Path| {
        p.file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default()
    };
    let now = Some(std::time::SystemTime::now());
    let step = step_bytes(
        surfaces,
        &StepOptions {
            units: args.units,
            file_name: file_name(&args.step),
            time: now,
        },
    );
    write_atomic(&args.step, &step)?;
    if let Some(path) = &args.iges {
        let iges = iges_bytes(
            surfaces,
            &[],
            &IgesOptions {
                units: args.units,
                file_name: file_name(path),
                author: "trispline".into(),
                time: now,
            },
        );
        write_atomic(path, &iges)?;
    }
    Ok(())
}

/// `path` with its extension replaced by `suffix`.
pub(super) fn beside(path: &Path, suffix: &str) -> PathBuf {
    let stem = path
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|| "surface".into());
    path.with_file_name(format!("{stem}{suffix}"))
}
