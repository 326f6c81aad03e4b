//! How far a fitted surface strays from its data: the one-sided distance from the surface
//! to the data mesh. The data-to-surface errors a fit minimises cannot see a surface that
//! bulges where no data is (over a hole, or a badly joined seam of an extension); this
//! measure does.

use super::data_side::DataSide;
use super::model::{
    ms_since, ObjectError, ObjectFit, ObjectOptions, StrayBudget, STRAY_LATTICE_SEGMENTS,
};
use crate::mesh::distance::MeshDistance;
use crate::mesh::simplify::{simplify, simplify_with_topology, SimplifyOptions};
use crate::mesh::topology::Topology;
use crate::pipeline::welded_lattice::weld_lattices;
use crate::surface::bezier::lattice_points;
use crate::surface::loop_limit::LoopLimitSurface;
use crate::surface::{SurfaceParam, TriSurface};
use crate::TriMesh;
use glam::DVec3;
use rayon::prelude::*;
use std::time::Instant;

/// The largest distance from the fitted surface to the data mesh (`face_strays`: a
/// lattice of `segments` segments per control face edge, and the local maxima above its
/// farthest samples; infinite when the data mesh is empty or a sample is not finite).
pub fn farthest_from_data(fit: &ObjectFit, segments: usize) -> f64 {
    farthest_of(fit, &MeshDistance::new(&fit.component), segments)
}

/// [`farthest_from_data`] against a data mesh whose index the caller has built already
/// (`DataSide::nearest`), over every face of the fit's surface.
pub(super) fn farthest_of(fit: &ObjectFit, data: &MeshDistance, segments: usize) -> f64 {
    let faces: Vec<u32> = (0..fit.surface.domain_face_count() as u32).collect();
    farthest_from(&fit.surface, &fit.controls, data, segments, &faces)
}

/// [`farthest_from_data`] for any Loop limit surface and data mesh, over `faces` only
/// (indices past the surface's faces are skipped).
pub fn farthest_from(
    surface: &LoopLimitSurface,
    controls: &[DVec3],
    data: &MeshDistance,
    segments: usize,
    faces: &[u32],
) -> f64 {
    face_strays(surface, controls, data, segments, faces)
        .into_iter()
        .fold(0.0, f64::max)
}

/// Per face of `faces`, the largest distance from the surface to the data mesh (0 for
/// indices past the surface's faces, infinite where a sample is not finite or the data
/// mesh is empty): the farthest sample of a lattice of `segments` segments per edge (each
/// sample shared by neighbouring faces measured once, `weld_lattices`), and on the faces
/// that may hold the surface's farthest point, the local maximum above it.
///
/// A lattice alone misses the top of a bulge between its samples: on decimated-max (5 %
/// controls, large faces) the 6-segment lattice put the farthest point at 0.493 % of the
/// diagonal and an 8-segment one at 0.570 %, so a repair that stopped at the bound on the
/// first left the surface past it. The ascent climbs from the face's farthest sample
/// (`ascend`); it runs on the faces whose lattice maximum is at least half the largest
/// one's, where the surface's farthest point (the figure reported and held to a bound)
/// can be, and costs a few dozen evaluations on each.
pub fn face_strays(
    surface: &LoopLimitSurface,
    controls: &[DVec3],
    data: &MeshDistance,
    segments: usize,
    faces: &[u32],
) -> Vec<f64> {
    let k = segments.max(1);
    let evaluate = surface.evaluator(controls);
    let count = surface.domain_face_count() as u32;
    // Successive samples lie close together, so each query starts from the data triangle
    // nearest the one before (`MeshDistance::closest_near`).
    let distance_at = |p: SurfaceParam, hint: &mut Option<u32>| {
        let q = evaluate(p).position;
        let Some(c) = data.closest_near(q, *hint) else {
            return f64::INFINITY;
        };
        *hint = Some(c.triangle);
        let d = (c.point - q).length();
        if d.is_finite() {
            d
        } else {
            f64::INFINITY
        }
    };
    // Each lattice point shared by neighbouring faces once (`weld_lattices`, as the
    // shown tessellation shares them; across a crease too: the surface is continuous
    // there), in the order the faces give them, so that a run of samples lies on one face
    // or its neighbour.
    let mut of_face: Vec<Vec<u32>> = Vec::with_capacity(faces.len());
    let samples = weld_lattices(
        surface.topology(),
        &[],
        k,
        faces.iter().copied(),
        |_, ids| of_face.push(ids.to_vec()),
    );
    let measured: Vec<(f64, Option<u32>)> = samples
        .par_chunks(LATTICE_CHUNK)
        .flat_map_iter(|chunk| {
            let mut hint = None;
            chunk
                .iter()
                .map(move |&p| {
                    let d = if p.face < count {
                        distance_at(p, &mut hint)
                    } else {
                        0.0
                    };
                    (d, hint)
                })
                .collect::<Vec<_>>()
        })
        .collect();
    let steps = lattice_points(k);
    let lattice: Vec<(f64, SurfaceParam, Option<u32>)> = faces
        .iter()
        .zip(&of_face)
        .map(|(&f, indices)| {
            // The face's own parameters of its samples: a shared one was measured as the
            // parameter of another face, and the ascent climbs in this face.
            let start = SurfaceParam {
                face: f,
                u: 0.0,
                v: 0.0,
            };
            steps
                .iter()
                .zip(indices)
                .fold((0.0f64, start, None), |farthest, (&(i, j), &s)| {
                    let (d, hint) = measured[s as usize];
                    if d > farthest.0 {
                        let p = SurfaceParam {
                            face: f,
                            u: i as f64 / k as f64,
                            v: j as f64 / k as f64,
                        };
                        (d, p, hint)
                    } else {
                        farthest
                    }
                })
        })
        .collect();
    let largest = lattice.iter().map(|l| l.0).fold(0.0, f64::max);
    if !largest.is_finite() {
        return lattice.into_iter().map(|l| l.0).collect();
    }
    lattice
        .into_par_iter()
        .with_min_len(64)
        .map(|(d, at, hint)| {
            if d > 0.0 && d >= 0.5 * largest {
                ascend(&distance_at, (at, hint), d, 1.0 / k as f64)
            } else {
                d
            }
        })
        .collect()
}

/// Lattice samples measured in a run, each query starting from the data triangle nearest
/// the one before (neighbouring samples of the shared lattice lie close together).
const LATTICE_CHUNK: usize = 256;

/// Halvings of the ascent's step: from a lattice segment down to 1/64 of it.
const ASCENT_LEVELS: usize = 7;

/// Moves within the face, at most, per step size.
const ASCENT_MOVES: usize = 8;

/// The local maximum of `distance_at` over the face of `start` (u, v >= 0, u + v <= 1)
/// near `start`, whose distance is `d` (with the data triangle nearest it, the queries'
/// hint): a compass search along the lattice's three edge directions, from `step` down by
/// halves. It never returns less than `d`.
fn ascend(
    distance_at: &(impl Fn(SurfaceParam, &mut Option<u32>) -> f64 + Sync),
    (start, mut hint): (SurfaceParam, Option<u32>),
    d: f64,
    step: f64,
) -> f64 {
    const DIRECTIONS: [(f64, f64); 6] = [
        (1.0, 0.0),
        (-1.0, 0.0),
        (0.0, 1.0),
        (0.0, -1.0),
        (1.0, -1.0),
        (-1.0, 1.0),
    ];
    let (mut at, mut best) = (start, d);
    let mut h = step;
    for _ in 0..ASCENT_LEVELS {
        for _ in 0..ASCENT_MOVES {
            let mut moved = false;
            for (du, dv) in DIRECTIONS {
                let (u, v) = (at.u + h * du, at.v + h * dv);
                if u < 0.0 || v < 0.0 || u + v > 1.0 {
                    continue;
                }
                let p = SurfaceParam {
                    face: at.face,
                    u,
                    v,
                };
                let e = distance_at(p, &mut hint);
                if e > best {
                    (at, best, moved) = (p, e, true);
                }
            }
            if !moved {
                break;
            }
        }
        h *= 0.5;
    }
    best
}

/// Whether the quadric decimation of `mesh` to `vertices` vertices (`mesh::simplify` with
/// its default guards, no creases) strays farther than `limit` from the data (`data`, the
/// distance to `mesh`), on a lattice of `segments` segments per triangle edge: whether a
/// mesh of that budget can hold the shape at all. `topo`: `mesh`'s topology, where the
/// caller has it. Where it does, a surface of the same budget straying past
/// the bound strays by its own making (a boundary curve past a jagged rim), which more
/// controls do not mend. `true` when the decimation fails.
pub(super) fn decimation_strays(
    data: &MeshDistance,
    mesh: &TriMesh,
    topo: Option<&Topology>,
    vertices: usize,
    limit: f64,
    segments: usize,
) -> bool {
    let opts = SimplifyOptions {
        target_vertices: vertices,
        ..SimplifyOptions::default()
    };
    let decimated = match topo {
        Some(topo) => simplify_with_topology(mesh, topo, &opts, &[]),
        None => simplify(mesh, &opts),
    };
    let Ok(decimated) = decimated else {
        return true;
    };
    let k = segments.max(1);
    let corners = &decimated.mesh.positions;
    decimated
        .mesh
        .triangles
        .par_iter()
        .with_min_len(64)
        .any(|t| {
            let [a, b, c] = t.map(|v| corners[v as usize]);
            (0..=k).any(|j| {
                (0..=k - j).any(|i| {
                    let (u, v) = (i as f64 / k as f64, j as f64 / k as f64);
                    let p = a * (1.0 - u - v) + b * u + c * v;
                    data.distance(p).is_none_or(|d| d.is_nan() || d > limit)
                })
            })
        })
}

/// See `model::STRAY_BUDGET_STEPS`.
const STRAY_BUDGET_GROWTH: usize = 2;

/// `fit` (at the `asked` budget; the data are `side`'s, of topology `data_topo` where it
/// is a manifold) or, when its surface strays past the bound, a fit `fit_at` makes at
/// `STRAY_BUDGET_GROWTH` times the controls the fit before spent (its budget, where it
/// spent fewer), step after step until one is within the bound. The first step runs only
/// when a decimation of the data to the first fit's control count strays past the bound
/// as well (`stray::decimation_strays`: where such a mesh stays within it, the surface
/// strays by its own making, a boundary curve past a jagged rim, and more controls do
/// not mend it: chin_tri on the object path, 0.53 % at 2x as at 1x). Once a step has
/// brought the surface closer, more controls are shown to mend it and the steps go on
/// whatever a decimation does: femur (closed, genus 2) strayed 1.24 / 0.79 / 0.63 % of
/// its diagonal at 215 / 430 / 860 controls, where a decimation to 860 holds the bound,
/// and 0.49 % at 1721. The steps stop at a fit that strays no less than the one before.
/// The least straying fit is kept, within the bound or not: where the steps run out
/// first, each brought the surface closer (elk, 4.3 % of the diagonal at 82 controls,
/// 0.67 % at 772), which a user asking for a surface on the data would rather have than
/// the budget. The fits tried are listed in `stray_budgets`, the time beside the kept fit
/// in `times.stray_budget_ms`.
pub(super) fn grow_budget_while_straying(
    fit: ObjectFit,
    asked: usize,
    opts: &ObjectOptions,
    side: &DataSide,
    data_topo: Option<&Topology>,
    fit_at: impl Fn(usize) -> Result<ObjectFit, ObjectError>,
) -> ObjectFit {
    let Some(limit) = opts.stray_limit(&fit.component) else {
        return fit;
    };
    let points = fit.data.len();
    let mut tried = vec![StrayBudget::of(asked, &fit)];
    let start = Instant::now();
    // The last fit that strayed less than the one before (the least straying), and where
    // it is in `tried`.
    let mut closer = None;
    let mut last_stray = stray_of(&fit);
    let mut last_controls = fit.controls.len();
    let mut target = asked;
    for _ in 0..opts.stray_budget_steps {
        // Twice what the last fit spent: holes and handles can force more controls than
        // the budget asked (pinion: 68 for 17), and doubling the budget alone spent the
        // steps on budgets that fit had passed already.
        target = (target.max(last_controls) * STRAY_BUDGET_GROWTH).min(points);
        let late = opts.stop.deadline.is_some_and(|d| Instant::now() >= d);
        if last_stray <= limit || late || target <= last_controls {
            break;
        }
        let budget_cannot_hold = || {
            decimation_strays(
                side.nearest(),
                side.mesh,
                data_topo,
                last_controls,
                limit,
                STRAY_LATTICE_SEGMENTS,
            )
        };
        if !more_controls_may_mend(closer.is_some(), budget_cannot_hold) {
            break;
        }
        let Ok(next) = fit_at(target) else {
            break;
        };
        tried.push(StrayBudget::of(target, &next));
        let next_stray = stray_of(&next);
        if next_stray >= last_stray {
            break;
        }
        (last_stray, last_controls) = (next_stray, next.controls.len());
        closer = Some((tried.len() - 1, next));
    }
    // Everything but the kept fit's own time: the checks and the fits dropped.
    let mut spent_ms = ms_since(start);
    let mut kept = match closer {
        Some((at, next)) => {
            tried[at].kept = true;
            spent_ms += fit.times.total_ms - next.times.total_ms;
            next
        }
        None => {
            tried[0].kept = true;
            fit
        }
    };
    kept.times.stray_budget_ms = spent_ms;
    if tried.len() > 1 {
        kept.stray_budgets = tried;
    }
    kept
}

/// A fit whose rounds halved their tangential share below `opts.tangential` and left the
/// surface straying past the bound, fitted again (`fit_with`, the same budget) with the
/// share held at `opts.tangential`. The small share lets a surface slide along its data,
/// which converges further where the data holds it and bulges where the data is too
/// sparse to (a decimation's long triangles): the steady fit may keep the bound without
/// more controls. The less straying fit is kept with the options it was made with, which
/// the budget's growth goes on with; the time of the one dropped is added to the kept
/// fit's `times.stray_budget_ms`.
pub(super) fn steady_share_while_straying(
    fit: ObjectFit,
    opts: &ObjectOptions,
    fit_with: impl Fn(&ObjectOptions) -> Result<ObjectFit, ObjectError>,
) -> (ObjectFit, ObjectOptions) {
    let straying = opts
        .stray_limit(&fit.component)
        .is_some_and(|limit| stray_of(&fit) > limit);
    let late = opts.stop.deadline.is_some_and(|d| Instant::now() >= d);
    if !straying || late || opts.share_floor() >= opts.tangential {
        return (fit, opts.clone());
    }
    let steady_opts = ObjectOptions {
        tangential_floor: opts.tangential,
        ..opts.clone()
    };
    let Ok(mut steady) = fit_with(&steady_opts) else {
        return (fit, opts.clone());
    };
    if stray_of(&steady) < stray_of(&fit) {
        steady.times.stray_budget_ms += fit.times.total_ms;
        (steady, steady_opts)
    } else {
        let mut fit = fit;
        fit.times.stray_budget_ms += steady.times.total_ms;
        (fit, opts.clone())
    }
}

/// How far a fit's surface strays from its data; infinite where it was not measured.
fn stray_of(fit: &ObjectFit) -> f64 {
    fit.stray.unwrap_or(f64::INFINITY)
}

/// Whether a fit straying past the bound is worth another step of the escalation: where
/// a step has brought the surface closer already (`brought_closer`), more controls are
/// seen to mend it; before that, only where a decimation to its count strays too
/// (`budget_cannot_hold`, which is not asked where the answer is known: it decimates the
/// data).
fn more_controls_may_mend(brought_closer: bool, budget_cannot_hold: impl FnOnce() -> bool) -> bool {
    brought_closer || budget_cannot_hold()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testdata::icosahedron;

    /// The unit sphere: the icosahedron's faces split 1-to-4 `levels` times, every vertex
    /// pushed out onto the sphere.
    fn sphere(levels: usize) -> TriMesh {
        let (mut positions, mut faces) = icosahedron();
        for _ in 0..levels {
            let mut middle = std::collections::HashMap::new();
            let mut split = Vec::with_capacity(4 * faces.len());
            for [a, b, c] in faces {
                let mut mid = |p: u32, q: u32| {
                    *middle.entry((p.min(q), p.max(q))).or_insert_with(|| {
                        positions.push((positions[p as usize] + positions[q as usize]) * 0.5);
                        positions.len() as u32 - 1
                    })
                };
                let (ab, bc, ca) = (mid(a, b), mid(b, c), mid(c, a));
                split.extend([[a, ab, ca], [ab, b, bc], [ca, bc, c], [ab, bc, ca]]);
            }
            faces = split;
        }
        TriMesh::new(positions.iter().map(|p| p.normalize()).collect(), faces)
    }

    #[test]
    fn a_step_that_brought_the_surface_closer_is_followed_whatever_a_decimation_does() {
        let asked = std::cell::Cell::new(0);
        let decimation = |strays: bool| {
            let asked = &asked;
            move || {
                asked.set(asked.get() + 1);
                strays
            }
        };
        // Before any step: the decimation decides.
        assert!(more_controls_may_mend(false, decimation(true)));
        assert!(!more_controls_may_mend(false, decimation(false)));
        assert_eq!(asked.get(), 2);
        // After a step that brought the surface closer: on, and nothing decimated.
        assert!(more_controls_may_mend(true, decimation(false)));
        assert!(more_controls_may_mend(true, decimation(true)));
        assert_eq!(asked.get(), 2);
    }

    #[test]
    fn a_decimation_strays_only_where_its_budget_cannot_hold_the_shape() {
        let mesh = sphere(3);
        let data = MeshDistance::new(&mesh);
        let n = mesh.positions.len();
        // Every vertex kept: the lattice lies on the data's own triangles.
        assert!(!decimation_strays(&data, &mesh, None, n, 1e-9, 6));
        // 12 vertices: flat faces (an icosahedron's lie 0.21 inside the unit sphere) ...
        assert!(decimation_strays(&data, &mesh, None, 12, 0.1, 6));
        // ... but no face of a decimation that keeps the sphere's shape lies at its centre,
        // with the topology given or built.
        let topo = Topology::from_mesh(&mesh).expect("manifold");
        assert!(!decimation_strays(&data, &mesh, None, 12, 0.6, 6));
        assert!(!decimation_strays(&data, &mesh, Some(&topo), 12, 0.6, 6));
        assert!(decimation_strays(&data, &mesh, Some(&topo), 12, 0.1, 6));
    }
}
