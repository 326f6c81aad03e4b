//! Stage 3 of a scan fit: where the fit starts. The initial net, with the previous version's
//! controls put in where they sit on the same domain; the data parameters from the map, or
//! from the previous version's foot points where those are known.

use super::feet::WarmFeet;
use super::prepare::Prepared;
use super::resample::Resampled;
use super::types::ScanWarm;
use super::warm::params_from_previous;
use crate::pipeline::SurfaceModel;
use crate::surface::SurfaceParam;
use glam::DVec3;

/// The start of the first fit.
pub(super) struct Seed<'w> {
    /// The starting net.
    pub(super) start: Vec<DVec3>,
    /// Controls of `start` taken from the previous version.
    pub(super) reused: usize,
    /// Each data point's starting parameter.
    pub(super) params: Vec<SurfaceParam>,
    /// The previous version's feet, when it had the same domain.
    pub(super) previous_feet: Option<&'w WarmFeet>,
}

/// Reach of the search for a previous version's point, in median edge lengths: a rescan's
/// points sit within a sample spacing of the previous ones; further off they are other
/// points, whose parameters would mislead.
const PREVIOUS_POINT_REACH_EDGES: f64 = 2.0;

pub(super) fn seed<'w>(
    prepared: &Prepared,
    resampled: &Resampled,
    warm: Option<&ScanWarm<'w>>,
) -> Seed<'w> {
    let Resampled {
        model,
        domain,
        initial,
        ..
    } = resampled;
    let plane = &prepared.map.plane;
    let real = prepared.patch.real_vertices;
    // Warm start: the previous control at the same place of the same domain.
    let mut start = initial.controls.clone();
    let mut reused = 0;
    if let Some(w) = warm.filter(|w| w.domain == Some(domain)) {
        match model {
            SurfaceModel::Bezier(_) if w.controls.len() == start.len() => {
                start = w.controls.to_vec();
                reused = start.len();
            }
            SurfaceModel::Grid(grid) if w.coords.len() == w.controls.len() => {
                for (&(i, j), &p) in w.coords.iter().zip(w.controls) {
                    if let Some(k) = grid.control_at(i, j) {
                        start[k as usize] = p;
                        reused += 1;
                    }
                }
            }
            _ => {}
        }
    }

    let mut params: Vec<SurfaceParam> = plane[..real]
        .iter()
        .map(|p| {
            let (u, v) = domain.param(*p);
            SurfaceParam { face: 0, u, v }
        })
        .collect();
    let previous_feet = warm
        .filter(|w| w.domain == Some(domain))
        .and_then(|w| w.feet);
    if let (Some(feet), SurfaceModel::Grid(grid)) = (previous_feet, model) {
        params_from_previous(
            feet,
            &prepared.frame,
            &prepared.part.positions,
            PREVIOUS_POINT_REACH_EDGES * prepared.edge_length,
            &mut params,
        );
        // A parameter the grid does not cover (the previous grid was larger) goes back.
        for (p, mapped) in params.iter_mut().zip(&plane[..real]) {
            if !grid.covers(p.u, p.v) {
                let (u, v) = domain.param(*mapped);
                *p = SurfaceParam { face: 0, u, v };
            }
        }
    }
    Seed {
        start,
        reused,
        params,
        previous_feet,
    }
}
