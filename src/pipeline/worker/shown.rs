//! What a grid or exact-subdivision surface's GLB shows, and how far that strays from the
//! data: measured once after the fit (a grid surface under `domain auto` by the stray
//! check, `grid_stray`, which may give it up for the object path's) and handed on to the
//! outputs (`FittedPatch`), which write the stray into report.json. And how fine a whole
//! object's tessellation is made (`object_tessellation`).

use super::stray_guard::MAX_STRAY_SHARE;
use crate::mesh::distance::MeshDistance;
use crate::pipeline::output::{tessellate, Coverage, Tessellation};
use crate::pipeline::scan::ScanFit;
use crate::pipeline::{PatchFit, SurfaceModel};
use crate::TriMesh;
use rayon::prelude::*;

/// A surface's farthest point from the data, measured on the tessellation the GLB shows.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ShownStray {
    /// The largest distance from a vertex of the shown tessellation to the data mesh
    /// (infinite when a vertex has no nearest point).
    pub max: f64,
    /// `max` as a share of the data's bounding-box diagonal.
    pub share_of_diagonal: f64,
}

/// The tessellation a surface's GLB shows, and how far it strays from the data.
pub struct ShownSurface {
    /// The shown tessellation (a grid surface's: the coverage's triangles).
    pub tessellation: Tessellation,
    /// Its farthest shown vertex from the data.
    pub stray: ShownStray,
    /// Why the object path was tried for the same input, when it was and its surface was
    /// not kept (report.json `object_path_tried`: the time it took is in the fit's).
    pub object_tried: Option<String>,
}

impl ShownSurface {
    /// The tessellation of `segments` the outputs show of `scan`'s grid surface (the
    /// coverage's triangles), and its stray from `data` (the input it was fitted to).
    pub(super) fn of_grid(data: &TriMesh, scan: &ScanFit, segments: usize) -> ShownSurface {
        let coverage = Coverage::of(&scan.fit, scan);
        let tessellation = tessellate(&scan.fit, segments.max(1), Some(&coverage));
        ShownSurface::measured(data, tessellation)
    }

    /// The whole tessellation of `segments` of `fit`'s surface (an exact-subdivision fit
    /// of `data`, shown whole), and its stray from `data`.
    pub(super) fn of_whole(data: &TriMesh, fit: &PatchFit, segments: usize) -> ShownSurface {
        ShownSurface::measured(data, tessellate(fit, segments.max(1), None))
    }

    fn measured(data: &TriMesh, tessellation: Tessellation) -> ShownSurface {
        ShownSurface {
            stray: ShownStray::of(data, &tessellation),
            tessellation,
            object_tried: None,
        }
    }
}

impl ShownStray {
    /// The largest distance from a shown vertex of `shown` (a corner of one of its
    /// triangles) to `data`.
    fn of(data: &TriMesh, shown: &Tessellation) -> ShownStray {
        let nearest = MeshDistance::new(data);
        // The coverage drops triangles, not vertices: only the kept triangles' corners
        // are shown.
        let mut corner = vec![false; shown.positions.len()];
        for &v in shown.triangles.iter().flatten() {
            if let Some(c) = corner.get_mut(v as usize) {
                *c = true;
            }
        }
        let max = shown
            .positions
            .par_iter()
            .zip(&corner)
            .with_min_len(256)
            .filter(|(_, &shown)| shown)
            .map(|(&p, _)| nearest.distance(p).unwrap_or(f64::INFINITY))
            .reduce(|| 0.0, f64::max);
        let diagonal = data.bounds_diagonal();
        let share_of_diagonal = if diagonal > 0.0 { max / diagonal } else { 0.0 };
        ShownStray {
            max,
            share_of_diagonal,
        }
    }

    /// Whether it is within the bound every whole fit is held to (an infinite or NaN
    /// share is not).
    pub(super) fn within(&self) -> bool {
        self.share_of_diagonal <= MAX_STRAY_SHARE
    }

    /// report.json's `stray` for a grid or exact-subdivision surface: the figures of a
    /// whole fit's (`StrayReport`), and what they were measured on.
    pub(super) fn report(&self) -> serde_json::Value {
        serde_json::json!({
            "max": self.max,
            "share_of_diagonal": self.share_of_diagonal,
            "limit_share": MAX_STRAY_SHARE,
            "within": self.within(),
            "measured_on": "the vertices of the shown tessellation",
        })
    }

    /// Why the object path was tried, for report.json's `object.path_reason`.
    pub(super) fn reason(&self) -> String {
        format!(
            "the grid surface strays {:.2} % of the bounding-box diagonal from the data \
             (over {:.2} %)",
            100.0 * self.share_of_diagonal,
            100.0 * MAX_STRAY_SHARE
        )
    }
}

/// The tessellation of an object fit is refined until its flat triangles' own error (RMS
/// at their centroids) is at most this share of the fit's RMS: the shown surface then
/// differs from the fitted one far less than the fitted one from the data.
const CHORD_SHARE_OF_RMS: f64 = 0.1;
/// Segments per control-face side at most ...
const MAX_PER_FACE: usize = 64;
/// ... and triangles in all at most (about 30 MB of GLB; beyond that the file grows past
/// what a viewer opens quickly for a gain nobody sees).
const MAX_TRIANGLES: usize = 1_000_000;
/// Control faces sampled for the chord error.
const CHORD_SAMPLE_FACES: usize = 150;
/// Chord errors below this share of the data's diagonal are rounding: a fit that is exact
/// (a faceted part's facets, a smooth fit of exact data) has an RMS of that size, and held
/// to a tenth of it the tessellation went to its cap for nothing (a 160-point pipe: 55
/// segments per face, 480k flat triangles over flat faces, 0.36 s).
const CHORD_ROUNDING_SHARE: f64 = 1e-12;

/// How fine an object's tessellation is and what its triangles' own error measured.
#[derive(Clone, Copy, Debug, serde::Serialize)]
pub struct TessellationCheck {
    /// Segments per control-face side.
    pub per_face: usize,
    /// RMS of the chord error at the triangles' centroids (sampled faces).
    pub chord_rms: f64,
    /// Its largest value.
    pub chord_max: f64,
    /// The fit's geometric RMS it is held against.
    pub fit_rms: f64,
}

/// Segments per control-face side for an object fit: from `start` (what the configured
/// tessellation gives), refined until the chord error is a small share of the fit's RMS.
/// The chord error of a smooth surface falls with the square of the segments, so each
/// measurement predicts the count the next one checks.
pub(super) fn object_tessellation(fitted: &PatchFit, start: usize) -> TessellationCheck {
    let faces = match &fitted.model {
        SurfaceModel::Mesh(m) => m.faces().len().max(1),
        _ => 1,
    };
    let cap = ((MAX_TRIANGLES as f64 / faces as f64).sqrt() as usize).clamp(2, MAX_PER_FACE);
    let fit_rms = fitted.geometric_rms();
    let rounding = CHORD_ROUNDING_SHARE * crate::numeric::bounds_diagonal(&fitted.data);
    let target = (CHORD_SHARE_OF_RMS * fit_rms).max(rounding);
    let mut per_face = start.clamp(2, cap);
    loop {
        let errors = crate::pipeline::output::chord_errors(fitted, per_face, CHORD_SAMPLE_FACES);
        let n = errors.len().max(1) as f64;
        let check = TessellationCheck {
            per_face,
            chord_rms: (errors.iter().map(|e| e * e).sum::<f64>() / n).sqrt(),
            chord_max: errors.iter().cloned().fold(0.0, f64::max),
            fit_rms,
        };
        if check.chord_rms <= target || per_face >= cap {
            return check;
        }
        let predicted = (per_face as f64 * (check.chord_rms / target).sqrt()).ceil() as usize;
        per_face = predicted.clamp(per_face + 1, cap);
    }
}
