//! Stage 1 of a scan fit: clean the input, keep its largest component, close its holes and
//! map it to the plane.

use super::cold_start::ColdStart;
use super::components::cleaned_components;
use super::types::{Dropped, ScanOptions, ScanWarm};
use super::warm_guard::refuse_warm;
use crate::mesh::clean::{clean, CleanOptions};
use crate::pipeline::PipelineError;
use crate::remesh::planar::{
    evened_out, planar_map, projection_warp, MapMethod, PlanarMap, PlaneFrame,
};
use crate::remesh::{fill_holes, FilledPatch, RemeshError};
use crate::TriMesh;

/// The patch ready for a domain: the component fitted, its holes filled and its map.
pub(crate) struct Prepared {
    /// The largest component of the cleaned input: its vertices are the data.
    pub(crate) part: TriMesh,
    /// Components of the cleaned input.
    pub(crate) components: usize,
    /// The components left out.
    pub(crate) dropped: Dropped,
    /// `part` with its holes closed by virtual fans.
    pub(crate) patch: FilledPatch,
    /// The plane of the map.
    pub(crate) frame: PlaneFrame,
    /// The filled patch in the plane.
    pub(crate) map: PlanarMap,
    /// The data's sample spacing: the unit in which hole widths are judged.
    pub(crate) edge_length: f64,
    /// Why the previous version given was not used (the later stages then start cold).
    pub(crate) cold_start: Option<ColdStart>,
}

pub(crate) fn prepare(
    mesh: &TriMesh,
    scan: &ScanOptions,
    warm: Option<&ScanWarm>,
) -> Result<Prepared, PipelineError> {
    let cleaned = clean(mesh, &CleanOptions::default());
    let parts = cleaned_components(&cleaned);
    let components = parts.len();
    let total: usize = parts.iter().map(|p| p.positions.len()).sum();
    let mut parts = parts.into_iter();
    let part = parts.next().unwrap_or_default();
    if part.triangles.is_empty() {
        return Err(PipelineError::EmptyAfterCleaning);
    }
    let sizes: Vec<usize> = parts.map(|p| p.positions.len()).collect();
    let dropped = Dropped::of(&sizes, total);
    dropped.warn(components, total);
    let edge_length = median_edge_length(&part);
    let cold_start = warm.and_then(|w| refuse_warm(&part, &dropped, edge_length, w));
    if let Some(reason) = &cold_start {
        tracing::warn!(%reason, "the previous version is too different: starting cold");
    }
    let warm = warm.filter(|_| cold_start.is_none());
    let previous_warp = warm.and_then(|w| w.warp);
    // The plane's frame and warp read only the data triangles: found beside the filling of
    // the holes (a warp from the previous version is reused instead, when it covers).
    let frame_and_warp = || -> Result<_, PipelineError> {
        let frame = match warm.and_then(|w| w.frame) {
            Some(f) => f,
            None => PlaneFrame::fit_least_folds(&part).ok_or(PipelineError::DegeneratePatch)?,
        };
        let warp = match previous_warp {
            Some(_) => None,
            None => projection_warp(&part, &frame),
        };
        Ok((frame, warp))
    };
    let (filled, framed) = rayon::join(|| fill_holes(&part), frame_and_warp);
    let patch = filled.map_err(|source| PipelineError::NotDiskLike { source })?;
    // After the topology checks, whose reasons (closed, not disk-like) say more.
    if part.positions.len() < scan.min_component_vertices {
        return Err(PipelineError::TooFewVertices {
            vertices: part.positions.len(),
            min: scan.min_component_vertices,
        });
    }
    let (frame, early_warp) = framed?;
    let map = planar_map(&patch, &frame).map_err(|source| PipelineError::MapFailed { source })?;
    if scan.refuse_distorted && map.method == MapMethod::MeanValueDisk {
        let share = map.undersampled_share(SQUEEZE_FACTOR);
        if share > MAX_SQUEEZED_SHARE {
            return Err(PipelineError::NotDiskLike {
                source: RemeshError::Distorted {
                    share,
                    factor: SQUEEZE_FACTOR,
                },
            });
        }
    }
    let map = evened_out(map, &patch, previous_warp.or(early_warp.as_ref()));
    Ok(Prepared {
        part,
        components,
        dropped,
        patch,
        frame,
        map,
        edge_length,
        cold_start,
    })
}

/// A disk map that gives more than `MAX_SQUEEZED_SHARE` of the surface under
/// `1 / SQUEEZE_FACTOR` of its share of the domain is refused where a caller can fit the
/// surface whole: the lattice's controls are even over the domain, so such a part gets
/// under a tenth of the controls an even layout gives it (at 5 % controls, fewer than one
/// per 200 data points). Measured: camelhead (a head and neck, no height field) 47 % so
/// squeezed, grid fit 13 mm RMS against 0.24 mm fitted whole; a 300-degree tube 0.04 %,
/// grid fit 43 um.
const SQUEEZE_FACTOR: f64 = 10.0;
const MAX_SQUEEZED_SHARE: f64 = 0.1;

/// Triangles sampled for the median edge length: a scan's edges are of nearly one length, so
/// a sample spread over the mesh finds their median without sorting every edge.
const EDGE_SAMPLE_TRIANGLES: usize = 10_000;

/// Median edge length of a mesh, from at most ~30k edges spread over it: the data's
/// sample spacing, the unit in which hole widths are judged.
pub(crate) fn median_edge_length(mesh: &TriMesh) -> f64 {
    let stride = (mesh.triangles.len() / EDGE_SAMPLE_TRIANGLES).max(1);
    let mut lengths: Vec<f64> = mesh
        .triangles
        .iter()
        .step_by(stride)
        .flat_map(|t| {
            let p = t.map(|v| mesh.positions[v as usize]);
            [
                (p[1] - p[0]).length(),
                (p[2] - p[1]).length(),
                (p[0] - p[2]).length(),
            ]
        })
        .filter(|l| l.is_finite())
        .collect();
    if lengths.is_empty() {
        return 0.0;
    }
    let mid = lengths.len() / 2;
    *lengths.select_nth_unstable_by(mid, f64::total_cmp).1
}
