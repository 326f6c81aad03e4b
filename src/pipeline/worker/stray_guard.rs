//! The guard on a warm result (a local refit, an extension over new ground): its surface
//! must not stray from the data where the update moved it. A fit minimises the distance
//! from the data to the surface, which cannot see a surface bulging where no data is; a
//! local update keeps its previous faces and joins new ones by strips, so it can bulge
//! where a fit from scratch, whose control mesh follows the data, would not.

use crate::mesh::distance::MeshDistance;
use crate::pipeline::object::{
    farthest_from, farthest_from_data, ObjectError, ObjectFit, STRAY_LATTICE_SEGMENTS,
};
use crate::surface::loop_limit::LoopLimitSurface;
use crate::TriMesh;
use glam::DVec3;
use std::borrow::Borrow;

/// A warm result may stray from its data (the new version) by this share of the data's
/// bounding-box diagonal, the bound a whole fit is held to (no bulge over holes) ...
pub(crate) const MAX_STRAY_SHARE: f64 = crate::pipeline::object::STRAY_LIMIT_SHARE;

/// ... or by this many times what the previous surface strays from the same data (a
/// smooth surface over a coarse data mesh strays by the mesh's chordal error already);
/// farther, the whole fit runs. The fit's own errors (data to surface) cannot see a bulge.
pub(crate) const MAX_STRAY_GROWTH: f64 = 1.5;

/// Lattice segments per control face edge the stray check of an object session's local
/// refit samples (`stray_refusal`; coarser than the report's: it runs on every update
/// and measures nothing the report reads, and it compares like with like). A warm
/// version of a patch samples the report's lattice (`stays_on_data`), whose figures the
/// report takes over.
const STRAY_SEGMENTS: usize = 3;

/// How far an object's surface strays from its data, in the report: a fit minimises the
/// distance from the data to the surface, so only this says whether the surface bulges
/// over a hole or away from a coarse data mesh's large flat triangles.
#[derive(Clone, Copy, Debug, serde::Serialize)]
pub struct StrayReport {
    /// The largest distance from the surface (sampled on a lattice over each control
    /// face) to the data mesh.
    pub max: f64,
    /// `max` as a share of the data's bounding-box diagonal.
    pub share_of_diagonal: f64,
    /// The share a fit is held to.
    pub limit_share: f64,
    /// Whether `share_of_diagonal` is within `limit_share`.
    pub within: bool,
    /// Segments per control face edge of the sampled lattice (the farthest samples are
    /// then climbed to their local maxima: `object::farthest_from`).
    pub lattice_segments: usize,
}

impl StrayReport {
    /// The stray of `fit`'s whole surface: the fit's own measure when it took one (the
    /// stray repair of a whole fit), on the same lattice otherwise.
    pub(super) fn of(fit: &ObjectFit) -> StrayReport {
        let max = fit
            .stray
            .unwrap_or_else(|| farthest_from_data(fit, STRAY_LATTICE_SEGMENTS));
        let diagonal = fit.component.bounds_diagonal();
        let share_of_diagonal = if diagonal > 0.0 { max / diagonal } else { 0.0 };
        StrayReport {
            max,
            share_of_diagonal,
            limit_share: MAX_STRAY_SHARE,
            // An infinite or NaN max (a non-finite sample) is not within.
            within: share_of_diagonal <= MAX_STRAY_SHARE,
            lattice_segments: STRAY_LATTICE_SEGMENTS,
        }
    }
}

/// `fit` unless its surface strays from the data farther than `MAX_STRAY_SHARE` and
/// `MAX_STRAY_GROWTH` allow (a failed fit passes through: its error is reported as it is).
/// Only the faces an update can have moved are held to that: those around a control that
/// moved or is new (a patch depends on the controls of its face's 1-ring). They are
/// sampled on the report's lattice, and a fit let through has the other faces measured
/// too, with the same data index, as its `stray`: the report's whole-surface figure
/// (`StrayReport::of`) then costs nothing more, where it measured the guard's faces again.
pub(super) fn stays_on_data(
    fit: Result<ObjectFit, ObjectError>,
    previous_faces: &[[u32; 3]],
    previous_creases: &[[u32; 2]],
    previous_controls: &[DVec3],
) -> Result<Result<ObjectFit, ObjectError>, String> {
    let Ok(mut fit) = fit else {
        return Ok(fit);
    };
    // The previous surface over the faces of the same indices (those it has; an update
    // keeps the previous faces' indices except where it split faces).
    let previous = || {
        LoopLimitSurface::with_creases_reusing(
            previous_controls.len(),
            previous_faces,
            previous_creases,
            &fit.surface,
        )
        .ok()
    };
    let (surface, controls) = (&fit.surface, &fit.controls);
    let faces = faces_around_moved(surface.faces(), controls, previous_controls);
    let data = MeshDistance::new(&fit.component);
    let segments = STRAY_LATTICE_SEGMENTS;
    let farthest = farthest_from(surface, controls, &data, segments, &faces);
    let diagonal = fit.component.bounds_diagonal();
    let before = || {
        previous()
            .map(|s| farthest_from(&s, previous_controls, &data, segments, &faces))
            .unwrap_or(0.0)
    };
    if let Some(why) = refusal(farthest, diagonal, before) {
        return Err(why);
    }
    if fit.stray.is_none() {
        // `faces` is in ascending order (`faces_around_moved`).
        let rest: Vec<u32> = (0..surface.faces().len() as u32)
            .filter(|f| faces.binary_search(f).is_err())
            .collect();
        let others = farthest_from(surface, controls, &data, segments, &rest);
        fit.stray = Some(farthest.max(others));
    }
    Ok(Ok(fit))
}

/// Why the surface `controls` give `surface` strays from the data mesh farther than
/// `MAX_STRAY_SHARE` and `MAX_STRAY_GROWTH` allow, if it does, against the previous
/// surface (`previous_surface`, with `previous_controls`; `None`: it strayed nowhere)
/// over the same faces (those around a control that moved or is new) and the same data.
pub(crate) fn stray_refusal<S: Borrow<LoopLimitSurface>>(
    surface: &LoopLimitSurface,
    controls: &[DVec3],
    data_mesh: &TriMesh,
    previous_controls: &[DVec3],
    previous_surface: impl FnOnce() -> Option<S>,
) -> Option<String> {
    let faces = faces_around_moved(surface.faces(), controls, previous_controls);
    if faces.is_empty() {
        return None;
    }
    let data = MeshDistance::new(data_mesh);
    let farthest = farthest_from(surface, controls, &data, STRAY_SEGMENTS, &faces);
    refusal(farthest, data_mesh.bounds_diagonal(), || {
        previous_surface()
            .map(|s| farthest_from(s.borrow(), previous_controls, &data, STRAY_SEGMENTS, &faces))
            .unwrap_or(0.0)
    })
}

/// Why a surface straying `farthest` from data of bounding-box diagonal `diagonal` over the
/// faces an update moved is refused, if it is, where the previous surface strayed
/// `before()` over the same faces (measured only when `farthest` is past the share).
fn refusal(farthest: f64, diagonal: f64, before: impl FnOnce() -> f64) -> Option<String> {
    let share = MAX_STRAY_SHARE * diagonal;
    if farthest <= share {
        return None;
    }
    let before = before();
    if farthest <= MAX_STRAY_GROWTH * before {
        return None;
    }
    Some(format!(
        "the updated surface strays {farthest:.3e} from the data (the previous one \
         {before:.3e} there; at most {share:.3e}, {MAX_STRAY_SHARE} of the bounding-box \
         diagonal, or {MAX_STRAY_GROWTH} times the previous)"
    ))
}

/// The control faces with a vertex next to (or at) a control that is new or moved against
/// `previous`, in ascending order.
fn faces_around_moved(faces: &[[u32; 3]], controls: &[DVec3], previous: &[DVec3]) -> Vec<u32> {
    let moved: Vec<bool> = (0..controls.len())
        .map(|v| previous.get(v) != Some(&controls[v]))
        .collect();
    let mut near = vec![false; controls.len()];
    for t in faces
        .iter()
        .filter(|t| t.iter().any(|&v| moved[v as usize]))
    {
        for &v in t {
            near[v as usize] = true;
        }
    }
    (0..faces.len() as u32)
        .filter(|&f| faces[f as usize].iter().any(|&v| near[v as usize]))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::simplify::tests::torus;
    use crate::pipeline::object::{fit_object, ObjectOptions};

    #[test]
    fn a_control_moved_off_the_data_is_refused_and_an_untouched_fit_passes() {
        let mesh = torus(60, 20);
        let fit = fit_object(&mesh, &ObjectOptions::default()).expect("the torus fits");
        let faces = fit.surface.faces().to_vec();
        let creases = fit.surface.crease_edges().to_vec();
        let previous = fit.controls.clone();
        let diagonal = mesh.bounds_diagonal();
        // Nothing moved: nothing to sample, the fit passes.
        let same = stays_on_data(Ok(fit), &faces, &creases, &previous);
        let Ok(Ok(mut fit)) = same else {
            panic!("an unchanged fit is refused");
        };
        // One control pushed along z by 5 % of the diagonal: its patches leave the data
        // by far more than the bound, and the previous surface there did not.
        fit.controls[0].z += 0.05 * diagonal;
        let why = match stays_on_data(Ok(fit), &faces, &creases, &previous) {
            Err(why) => why,
            Ok(_) => panic!("a surface pushed off its data passes"),
        };
        assert!(why.contains("strays"), "{why}");
        // A push well inside the bound passes.
        let mut fit = fit_object(&mesh, &ObjectOptions::default()).expect("the torus fits");
        let previous = fit.controls.clone();
        fit.controls[0].z += 1e-4 * diagonal;
        assert!(matches!(
            stays_on_data(Ok(fit), &faces, &creases, &previous),
            Ok(Ok(_))
        ));
    }
}
