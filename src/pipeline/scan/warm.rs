//! What a previous version of a scan leaves for the next: its controls as the starting net
//! and its data points' final parameters as the start of the new foot-point searches.

use super::domain::InitialNet;
use super::feet::WarmFeet;
use super::solve::rms;
use super::types::{Domain, ScanFit, ScanWarm};
use crate::remesh::planar::PlaneFrame;
use crate::surface::grid_spline::GridSpline;
use crate::surface::{SurfaceParam, TriSurface};
use glam::{DVec2, DVec3};
use rayon::prelude::*;

/// What a grid fit leaves for the next version's foot-point searches (`None` for other
/// domains).
pub(crate) fn warm_feet(fit: &ScanFit) -> Option<WarmFeet> {
    matches!(fit.domain, Domain::Grid { .. }).then(|| WarmFeet {
        points: fit
            .fit
            .data
            .iter()
            .map(|p| p.as_vec3().to_array())
            .collect(),
        params: fit
            .fit
            .params
            .iter()
            .map(|q| [q.u as f32, q.v as f32])
            .collect(),
        rms: rms(&fit.fit.geometric_errors),
    })
}

/// Start parameters from the nearest previous point within `reach` (searched over a bucket
/// grid of the plane `frame`); points with none keep theirs.
pub(super) fn params_from_previous(
    feet: &WarmFeet,
    frame: &PlaneFrame,
    data: &[DVec3],
    reach: f64,
    params: &mut [SurfaceParam],
) {
    if feet.points.len() != feet.params.len()
        || feet.points.is_empty()
        || reach.is_nan()
        || reach <= 0.0
    {
        return;
    }
    let old: Vec<DVec3> = feet
        .points
        .iter()
        .map(|p| glam::Vec3::from_array(*p).as_dvec3())
        .collect();
    let plane: Vec<DVec2> = old.iter().map(|p| frame.project(*p)).collect();
    let (lo, hi) = plane.iter().fold(
        (DVec2::splat(f64::MAX), DVec2::splat(f64::MIN)),
        |(lo, hi), p| (lo.min(*p), hi.max(*p)),
    );
    let size = ((hi - lo) / reach).ceil();
    if !(size.x.is_finite() && size.y.is_finite()) || size.x * size.y > 4e7 {
        return;
    }
    let (w, h) = ((size.x as usize).max(1), (size.y as usize).max(1));
    let bucket = |p: DVec2| -> Option<(usize, usize)> {
        let q = (p - lo) / reach;
        (q.x >= -1.0 && q.y >= -1.0).then(|| {
            (
                (q.x.max(0.0) as usize).min(w - 1),
                (q.y.max(0.0) as usize).min(h - 1),
            )
        })
    };
    let mut start = vec![0u32; w * h + 1];
    let cells: Vec<usize> = plane
        .iter()
        .map(|p| bucket(*p).map_or(0, |(x, y)| y * w + x))
        .collect();
    for &c in &cells {
        start[c + 1] += 1;
    }
    for c in 0..w * h {
        start[c + 1] += start[c];
    }
    let mut fill = start.clone();
    let mut order = vec![0u32; cells.len()];
    for (k, &c) in cells.iter().enumerate() {
        order[fill[c] as usize] = k as u32;
        fill[c] += 1;
    }
    let reach2 = reach * reach;
    data.par_iter()
        .zip(params.par_iter_mut())
        .for_each(|(p, param)| {
            let Some((x, y)) = bucket(frame.project(*p)) else {
                return;
            };
            let mut best = (reach2, None);
            for by in y.saturating_sub(1)..(y + 2).min(h) {
                for bx in x.saturating_sub(1)..(x + 2).min(w) {
                    let c = by * w + bx;
                    for &k in &order[start[c] as usize..start[c + 1] as usize] {
                        let d = (old[k as usize] - *p).length_squared();
                        if d < best.0 {
                            best = (d, Some(k as usize));
                        }
                    }
                }
            }
            if let Some(k) = best.1 {
                let [u, v] = feet.params[k];
                param.u = f64::from(u);
                param.v = f64::from(v);
            }
        });
}

/// Share of a grid's controls a previous version must provide for its net to replace the
/// resampled initial net.
const WARM_NET_MIN_SHARE: f64 = 0.9;

/// The previous version's controls at the same grid points as the starting net, when they
/// cover nearly all of `grid`: the rest take the mean of their known grid neighbours, ring
/// by ring. Resampling and inverse subdivision would only make a start the rounds replace.
pub(super) fn net_from_warm(grid: &GridSpline, warm: &ScanWarm) -> Option<InitialNet> {
    if warm.coords.len() != warm.controls.len() {
        return None;
    }
    let m = grid.control_count();
    let mut net: Vec<Option<DVec3>> = vec![None; m];
    for (&(i, j), &p) in warm.coords.iter().zip(warm.controls) {
        if let Some(k) = grid.control_at(i, j) {
            net[k as usize] = Some(p);
        }
    }
    let reused = net.iter().filter(|p| p.is_some()).count();
    if (reused as f64) < WARM_NET_MIN_SHARE * m as f64 || reused == 0 {
        return None;
    }
    const NEIGHBOURS: [(i64, i64); 6] = [(1, 0), (-1, 0), (0, 1), (0, -1), (1, -1), (-1, 1)];
    let coords = grid.control_coords();
    loop {
        let missing: Vec<usize> = (0..m).filter(|&k| net[k].is_none()).collect();
        if missing.is_empty() {
            break;
        }
        let filled: Vec<(usize, DVec3)> = missing
            .iter()
            .filter_map(|&k| {
                let (i, j) = coords[k];
                let known: Vec<DVec3> = NEIGHBOURS
                    .iter()
                    .filter_map(|(di, dj)| grid.control_at(i + di, j + dj))
                    .filter_map(|n| net[n as usize])
                    .collect();
                (!known.is_empty())
                    .then(|| (k, known.iter().copied().sum::<DVec3>() / known.len() as f64))
            })
            .collect();
        if filled.is_empty() {
            // Controls no known one reaches (a separate island of the grid).
            return None;
        }
        for (k, p) in filled {
            net[k] = Some(p);
        }
    }
    Some(InitialNet {
        controls: net.into_iter().map(|p| p.unwrap_or_default()).collect(),
        resample_points: 0,
        inverse: format!(
            "none: {reused} of {m} controls from the previous version, the rest from their neighbours"
        ),
    })
}
