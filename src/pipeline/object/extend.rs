//! A fitted object extended over new ground (an object session's new view, a new version
//! that covers more): the previous control mesh is kept face for face, the data beyond it
//! gets control faces of its own, and only the new controls and those around the seam are
//! solved (`local`); every other control keeps its position.
//!
//! The new region is every data face with a point on new ground. Its seam (its boundary
//! where older data goes on) lies along the previous rim, so a strip of triangles joins
//! the seam's vertices to the previous rim vertices nearest to them (at their limit
//! points, which lie on the previous surface), by arc length along both. The joined mesh
//! (previous control faces, the region at data resolution, the strip) is simplified with
//! every previous control vertex kept (`simplify_keeping`): the collapses fold the seam's
//! vertices onto the rim and thin the region out to the budget's density, with the
//! simplification's guards (manifold links, normals, triangle quality). The previous
//! vertices and faces keep their indices, so every old point keeps its foot and the
//! previous surface's patches are taken over. The region's points land on the new faces
//! as in a whole fit's simplification.
//!
//! Not done: a new region that does not meet the previous rim (an island), or meets two
//! rim loops in one seam, or a seam whose rim run overlaps another's, is refused (`None`):
//! the caller fits the whole object instead. So is an update whose old ground moved under
//! more than half the previous controls (`NotLocal`), judged before the join. Creases are
//! not detected on the new region.

use super::local::{free_controls, refit_around, LocalFeet, LocalOptions};
use super::model::ObjectOptions;
use super::model::{control_target, limit_surface, ms_since, ObjectError, ObjectFit, PreviousFit};
use super::refine::limit_positions;
use super::seam::{region_faces, seams, strip, Rims, Run, Seam, SeamMiss};
use super::version::{changed_points, Refitted, CHANGE_FACTOR, MAX_FREE_SHARE};
use crate::mesh::simplify::{simplify_keeping, SimplifyOptions, SurfaceTopology};
use crate::mesh::topology::{Topology, TopologyError, NONE};
use crate::surface::SurfaceParam;
use crate::TriMesh;
use glam::DVec3;
use std::time::Instant;

/// Why an object was not extended over its new ground (`extend_over_new_ground`); the
/// caller fits the whole object instead.
#[derive(Clone, Debug, PartialEq)]
#[non_exhaustive]
pub enum NotExtended {
    /// No point is on new ground, or the previous fit's RMS is unknown.
    NothingNew,
    /// A point's start lies off the previous control faces.
    StartOffFaces,
    /// A mesh the extension walks is not a manifold: the data, the previous control
    /// mesh, the new region's boundary or the joined mesh (`part`), with the walk's own
    /// reason where it gives one (a pinch vertex of the joined mesh: a strip that meets
    /// the previous faces at a vertex only).
    NotManifold {
        /// Which mesh.
        part: &'static str,
        /// Why, where the walk says.
        detail: Option<String>,
    },
    /// Seams of the new region have no run along the previous rim, and taking their parts
    /// to old ground would take more than a tenth of the new points.
    Unjoined {
        /// The region's seams.
        seams: usize,
        /// Seams without a rim run, by reason.
        missed: Vec<(&'static str, usize)>,
        /// New points their parts hold.
        demoted: usize,
        /// Points on new ground.
        new_points: usize,
    },
    /// The simplification of the joined mesh failed or changed previous faces.
    Simplification,
    /// The old ground moved under more than `MAX_FREE_SHARE` of the previous controls (a
    /// new view averaged into most of the object): a local refit would cost what the
    /// whole fit costs and keep the previous parameterisation, which measured worse (the
    /// bunny's fourth view: 46.0 um at 3893 controls against 35.2 um at 3686 from scratch).
    NotLocal {
        /// Old points that moved.
        moved: usize,
        /// Previous controls they free.
        free: usize,
        /// Previous controls.
        controls: usize,
    },
}

impl std::fmt::Display for NotExtended {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::NothingNew => write!(f, "no new ground to extend over"),
            Self::StartOffFaces => write!(f, "a point starts off the previous control faces"),
            Self::NotManifold { part, detail } => {
                write!(f, "{part} is not a manifold")?;
                match detail {
                    Some(d) => write!(f, ": {d}"),
                    None => Ok(()),
                }
            }
            Self::Unjoined {
                seams,
                missed,
                demoted,
                new_points,
            } => {
                let count: usize = missed.iter().map(|m| m.1).sum();
                let why: Vec<String> = missed.iter().map(|(w, n)| format!("{n} {w}")).collect();
                write!(
                    f,
                    "the new ground could not be joined to the previous rim: {count} of {seams} \
                     seams have no rim run ({}), and their parts hold {demoted} of {new_points} \
                     new points",
                    why.join(", ")
                )
            }
            Self::NotLocal {
                moved,
                free,
                controls,
            } => write!(
                f,
                "{moved} old points moved, freeing {free} of the {controls} previous controls \
                 (more than {MAX_FREE_SHARE} of them): not a local change"
            ),
            Self::Simplification => {
                write!(
                    f,
                    "the joined mesh's simplification failed or moved previous faces"
                )
            }
        }
    }
}

impl NotExtended {
    fn unjoined(seams: usize, misses: &mut [SeamMiss], demoted: usize, new_points: usize) -> Self {
        misses.sort_unstable();
        let mut missed: Vec<(&'static str, usize)> = Vec::new();
        for m in misses.iter() {
            match missed.last_mut() {
                Some(last) if last.0 == m.describe() => last.1 += 1,
                _ => missed.push((m.describe(), 1)),
            }
        }
        Self::Unjoined {
            seams,
            missed,
            demoted,
            new_points,
        }
    }
}

/// Extends `previous` over the points `is_new` marks (see the module docs). `params` holds
/// every point's start on the previous surface (the foot of the previous data point
/// nearest to it, `reference`; a new point's is read only if its part of the region cannot
/// be joined and it counts as old ground that changed). `Ok(Err(why))` when there is no
/// new point, a start lies off the previous control faces, or the region cannot be joined
/// to the previous rim.
pub fn extend_over_new_ground(
    component: TriMesh,
    previous: PreviousFit,
    params: Vec<SurfaceParam>,
    reference: &[DVec3],
    is_new: &[bool],
    opts: &ObjectOptions,
) -> Result<Result<ObjectFit, NotExtended>, ObjectError> {
    let start = Instant::now();
    let n = component.positions.len();
    if params.len() != n || reference.len() != n || is_new.len() != n {
        return Err(ObjectError::ParamCount {
            params: params.len().min(reference.len()).min(is_new.len()),
            points: n,
        });
    }
    if !is_new.iter().any(|&b| b)
        || previous.rms.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater)
    {
        return Ok(Err(NotExtended::NothingNew));
    }
    let old_mesh = previous.control_mesh;
    let m = old_mesh.positions.len();
    let old_faces = old_mesh.triangles.len();
    // Every start is read: points of a part the strip cannot join become old ground.
    if params.iter().any(|p| p.face as usize >= old_faces) {
        return Ok(Err(NotExtended::StartOffFaces));
    }
    let old_surface = limit_surface(old_mesh, previous.crease_edges, previous.surface)?;
    // Old points that moved (a view's samples averaged into old cells) change too, by the
    // rule of a new version (`version::changed_points`), on the previous surface. Judged
    // first: an update that moves most of the old ground is no local change.
    let t = Instant::now();
    let data = &component.positions;
    let mut new_params = params;
    let (moved, mut initial) = moved_on_old_ground(
        &old_surface,
        &previous,
        [data, reference],
        is_new,
        &mut new_params,
    );
    let old_free = free_controls(&old_surface, &new_params, &moved)
        .iter()
        .filter(|&&f| f)
        .count();
    if old_free as f64 > MAX_FREE_SHARE * m as f64 {
        return Ok(Err(NotExtended::NotLocal {
            moved: moved.len(),
            free: old_free,
            controls: m,
        }));
    }
    let moved_ms = ms_since(t);
    let t = Instant::now();
    let grown = grown_control_mesh(
        &component,
        is_new,
        (&previous, &old_surface),
        &mut new_params,
        opts,
    );
    let (joined, control_mesh, crease_edges) = match grown {
        Ok(grown) => grown,
        Err(why) => return Ok(Err(why)),
    };
    let controls = control_mesh.positions.clone();
    let demoted = feet_of_demoted(
        (&old_surface, &previous),
        data,
        [is_new, &joined.is_new],
        (&mut new_params, &mut initial),
    );
    let is_new = &joined.is_new[..];
    let simplify_ms = ms_since(t);

    let t = Instant::now();
    let topologies = [
        SurfaceTopology::of(&component).map_err(ObjectError::NotManifold)?,
        SurfaceTopology::of(&control_mesh).map_err(ObjectError::NotManifold)?,
    ];
    let surface = limit_surface(&control_mesh, &crease_edges, Some(&old_surface))?;
    let surface_ms = ms_since(t);

    let t = Instant::now();
    let mut changed = moved;
    changed.extend((0..n).filter(|&i| is_new[i]));
    changed.extend(demoted);
    changed.sort_unstable();
    let mut free = free_controls(&surface, &new_params, &changed);
    for v in (m..controls.len()).chain(joined.rim_run.iter().map(|&v| v as usize)) {
        free[v] = true;
    }
    // The new controls start on the data (the simplification's positions): a first
    // point-to-point round at the feet on that surface places them, as a whole fit's
    // first fit does, before the squared-distance rounds.
    let first_opts = LocalOptions::point_to_point(opts);
    let feet = LocalFeet::at(new_params, initial.clone());
    // No surface samples in this round, as in a whole fit's first point fit: pulled
    // point to point (tangential share 1), a sample drags its patch along the data.
    let placed = refit_around(
        &surface,
        &controls,
        data,
        None,
        feet,
        changed.len(),
        &free,
        &first_opts,
    );
    let first_fit_ms = ms_since(t);
    let t = Instant::now();
    let feet = LocalFeet::at(placed.params, placed.errors);
    let fitted = refit_around(
        &surface,
        &placed.controls,
        data,
        Some(&component),
        feet,
        changed.len(),
        &free,
        &LocalOptions::version_of(opts),
    );
    let rounds_ms = ms_since(t);
    let t = Instant::now();
    let mut state = Refitted::new(surface, control_mesh, fitted, free, opts.refine.tolerance);
    state.refine_where_changed(
        &component,
        &changed,
        &initial,
        CHANGE_FACTOR * previous.rms,
        opts,
    );
    let refine_ms = ms_since(t);
    let new_points = is_new.iter().filter(|&&b| b).count();
    let mut fit = state.into_fit(component, topologies);
    if let Some(local) = fit.local.as_mut() {
        local.added_controls += controls.len() - m;
        local.new_ground_points = new_points;
    }
    fit.times.simplify_ms = simplify_ms;
    fit.times.surface_ms = surface_ms;
    fit.times.first_fit_ms = moved_ms + first_fit_ms;
    fit.times.rounds_ms = rounds_ms;
    fit.times.refine_ms = refine_ms;
    fit.times.total_ms = ms_since(start);
    Ok(Ok(fit))
}

/// The previous control mesh grown over the new region: the joined mesh simplified with
/// every previous vertex kept, the previous controls at their fitted positions, with its
/// crease edges; the new points' `params` where the simplification landed them.
fn grown_control_mesh(
    component: &TriMesh,
    is_new: &[bool],
    (previous, old_surface): (&PreviousFit, &crate::surface::loop_limit::LoopLimitSurface),
    params: &mut [SurfaceParam],
    opts: &ObjectOptions,
) -> Result<(Joined, TriMesh, Vec<[u32; 2]>), NotExtended> {
    let old_mesh = previous.control_mesh;
    let (m, old_faces) = (old_mesh.positions.len(), old_mesh.triangles.len());
    let joined = joined_mesh(component, is_new, old_mesh, old_surface)?;
    let target = new_controls(
        joined.region_vertices.len(),
        component.positions.len(),
        opts,
    );
    let simplify_opts = SimplifyOptions {
        target_vertices: m + target,
        ..opts.simplify.clone()
    };
    let keep = vec![true; m];
    let simplified = simplify_keeping(&joined.mesh, &simplify_opts, previous.crease_edges, &keep)
        .map_err(|_| NotExtended::Simplification)?;
    // The previous vertices and faces come first in the joined mesh and no collapse
    // touched them: their indices hold (checked, as the old feet depend on it).
    let mesh = &simplified.mesh;
    let kept = (0..m).all(|v| simplified.control_of[v] == v as u32)
        && mesh.triangles.len() >= old_faces
        && mesh.triangles[..old_faces] == old_mesh.triangles[..];
    if !kept {
        return Err(NotExtended::Simplification);
    }
    let mut controls = mesh.positions.clone();
    controls[..m].copy_from_slice(&old_mesh.positions);
    land_new_points(&joined, &simplified.landing[m..], params);
    let control_mesh = TriMesh::new(controls, mesh.triangles.clone());
    Ok((joined, control_mesh, simplified.crease_edges))
}

/// The old points that moved against the previous surface (`version::changed_points`) and
/// every point's distance to that surface (0 for new points); the old points' entries of
/// `params` become their feet there.
fn moved_on_old_ground(
    old_surface: &crate::surface::loop_limit::LoopLimitSurface,
    previous: &PreviousFit,
    [data, reference]: [&[DVec3]; 2],
    is_new: &[bool],
    params: &mut [SurfaceParam],
) -> (Vec<usize>, Vec<f64>) {
    let old: Vec<usize> = (0..data.len()).filter(|&i| !is_new[i]).collect();
    let pick = |v: &[DVec3]| old.iter().map(|&i| v[i]).collect::<Vec<_>>();
    let (old_data, old_reference) = (pick(data), pick(reference));
    let old_start: Vec<SurfaceParam> = old.iter().map(|&i| params[i]).collect();
    let mut old_feet = LocalFeet::at(old_start.clone(), vec![0.0; old.len()]);
    let all_old: Vec<usize> = (0..old.len()).collect();
    let controls = &previous.control_mesh.positions;
    old_feet.find(old_surface, controls, &old_data, &all_old);
    let moved = changed_points(
        old_surface,
        controls,
        [&old_data, &old_reference],
        &old_start,
        &old_feet,
        previous.rms,
    );
    let mut initial = vec![0.0; data.len()];
    for (k, &i) in old.iter().enumerate() {
        initial[i] = old_feet.errors[k];
        params[i] = old_feet.params[k];
    }
    (moved.iter().map(|&k| old[k]).collect(), initial)
}

/// The points new at first (`was_new`) but not in the joined region (`is_new`): new
/// ground whose part of the region could not be joined, old ground that changed. Their
/// feet on the previous surface and distances go into `params` and `initial`.
fn feet_of_demoted(
    (old_surface, previous): (&crate::surface::loop_limit::LoopLimitSurface, &PreviousFit),
    data: &[DVec3],
    [was_new, is_new]: [&[bool]; 2],
    (params, initial): (&mut [SurfaceParam], &mut [f64]),
) -> Vec<usize> {
    let demoted: Vec<usize> = (0..data.len())
        .filter(|&i| was_new[i] && !is_new[i])
        .collect();
    if demoted.is_empty() {
        return demoted;
    }
    let points: Vec<DVec3> = demoted.iter().map(|&i| data[i]).collect();
    let start: Vec<SurfaceParam> = demoted.iter().map(|&i| params[i]).collect();
    let mut feet = LocalFeet::at(start, vec![0.0; demoted.len()]);
    let all: Vec<usize> = (0..demoted.len()).collect();
    feet.find(old_surface, &previous.control_mesh.positions, &points, &all);
    for (k, &i) in demoted.iter().enumerate() {
        params[i] = feet.params[k];
        initial[i] = feet.errors[k];
    }
    demoted
}

/// The new points' parameters: where the simplification landed them (`landing`, from the
/// first region vertex on).
fn land_new_points(
    joined: &Joined,
    landing: &[crate::mesh::simplify::Landing],
    params: &mut [SurfaceParam],
) {
    for (&v, l) in joined.region_vertices.iter().zip(landing) {
        if joined.is_new[v as usize] {
            params[v as usize] = SurfaceParam {
                face: l.face,
                u: l.u,
                v: l.v,
            };
        }
    }
}

/// Controls for a new region of `vertices` of the object's `points`: their share of the
/// whole object's budget (a percentage or an explicit count), less what the local
/// refinement may add where the fit misses.
fn new_controls(vertices: usize, points: usize, opts: &ObjectOptions) -> usize {
    let all = control_target(points, opts) as f64 * vertices as f64 / points.max(1) as f64;
    let share = if opts.refine.rounds > 0 && opts.refine.tolerance.is_some() {
        opts.refine.start_share
    } else {
        1.0
    };
    ((all * share).round() as usize).max(4)
}

/// The previous control faces, the new region and the strip between them, in one mesh:
/// vertices `0..m` the previous controls at their limit points, then the region's points.
struct Joined {
    mesh: TriMesh,
    /// The data points of the region, in the joined mesh's order from `m` on.
    region_vertices: Vec<u32>,
    /// The previous rim vertices the strip joins.
    rim_run: Vec<u32>,
    /// The points still on new ground (less those of parts that could not be joined).
    is_new: Vec<bool>,
}

fn joined_mesh(
    component: &TriMesh,
    is_new: &[bool],
    old_mesh: &TriMesh,
    old_surface: &crate::surface::loop_limit::LoopLimitSurface,
) -> Result<Joined, NotExtended> {
    let topo = Topology::from_mesh(component).map_err(|e| not_manifold("the data", e))?;
    let limit = limit_positions(old_surface, &old_mesh.positions);
    let old_topo =
        Topology::from_mesh(old_mesh).map_err(|e| not_manifold("the previous control mesh", e))?;
    let rims = Rims::new(&old_topo, &limit);
    let m = old_mesh.positions.len();
    let all_new = is_new.iter().filter(|&&b| b).count();
    let mut is_new = is_new.to_vec();
    let mut demotion_rounds = 0;
    loop {
        let in_region = region_faces(component, &topo, &is_new);
        let seams = seams(&topo, &in_region).ok_or(NotExtended::NotManifold {
            part: "the new region's boundary",
            detail: Some("it meets itself at a vertex".into()),
        })?;
        let mut used = vec![false; m];
        let mut runs = Vec::with_capacity(seams.len());
        let mut failed = Vec::new();
        let mut misses = Vec::new();
        for seam in &seams {
            match rims.run_along(seam, &component.positions) {
                Ok(run) if run.vertices.iter().all(|&p| !used[p as usize]) => {
                    for &p in &run.vertices {
                        used[p as usize] = true;
                    }
                    runs.push(run);
                }
                found => {
                    failed.push(seam);
                    misses.push(found.err().unwrap_or(SeamMiss::SharedRun));
                }
            }
        }
        if failed.is_empty() {
            return joined(
                component,
                &is_new,
                &in_region,
                old_mesh,
                limit,
                (&seams, runs),
            )
            .map_err(|e| not_manifold("the joined mesh", e));
        }
        // A part of the region the strip cannot join (an island inside the old ground, a
        // second seam on the same rim run) is old ground whose data changed, as long as
        // it is a small part of the new ground.
        let demoted = demote(component, &topo, &in_region, &failed, &mut is_new);
        let still_new = is_new.iter().filter(|&&b| b).count();
        demotion_rounds += 1;
        if demotion_rounds >= MAX_DEMOTION_ROUNDS
            || demoted as f64 > MAX_DEMOTED_SHARE * all_new as f64
        {
            let demoted_points = all_new - still_new;
            return Err(NotExtended::unjoined(
                seams.len(),
                &mut misses,
                demoted_points,
                all_new,
            ));
        }
    }
}

fn not_manifold(part: &'static str, e: TopologyError) -> NotExtended {
    NotExtended::NotManifold {
        part,
        detail: Some(e.to_string()),
    }
}

/// Rounds of taking unjoinable parts out of the region at most (the first always runs).
const MAX_DEMOTION_ROUNDS: usize = 4;

/// Share of the new points that may be taken out of the region as unjoinable.
const MAX_DEMOTED_SHARE: f64 = 0.1;

/// Takes the region's parts around the `failed` seams out of it (their points no longer
/// new); returns how many new points that took.
fn demote(
    component: &TriMesh,
    topo: &Topology,
    in_region: &[bool],
    failed: &[&Seam],
    is_new: &mut [bool],
) -> usize {
    let mut on_seam = vec![false; component.positions.len()];
    for seam in failed {
        for &v in &seam.vertices {
            on_seam[v as usize] = true;
        }
    }
    let mut taken = vec![false; component.triangles.len()];
    let mut stack: Vec<usize> = (0..component.triangles.len())
        .filter(|&f| in_region[f] && component.triangles[f].iter().any(|&v| on_seam[v as usize]))
        .collect();
    while let Some(f) = stack.pop() {
        if std::mem::replace(&mut taken[f], true) {
            continue;
        }
        for k in 0..3 {
            let twin = topo.twin[3 * f + k];
            if twin != NONE && in_region[twin as usize / 3] && !taken[twin as usize / 3] {
                stack.push(twin as usize / 3);
            }
        }
    }
    let mut demoted = 0;
    for (t, _) in component.triangles.iter().zip(&taken).filter(|(_, &x)| x) {
        for &v in t {
            if std::mem::replace(&mut is_new[v as usize], false) {
                demoted += 1;
            }
        }
    }
    demoted
}

/// The joined mesh of a region whose every seam has its rim run.
fn joined(
    component: &TriMesh,
    is_new: &[bool],
    in_region: &[bool],
    old_mesh: &TriMesh,
    limit: Vec<DVec3>,
    (seams, runs): (&[Seam], Vec<Run>),
) -> Result<Joined, TopologyError> {
    let m = old_mesh.positions.len();
    let mut local = vec![NONE; component.positions.len()];
    let mut region_vertices = Vec::new();
    let mut faces = old_mesh.triangles.clone();
    for (t, _) in component
        .triangles
        .iter()
        .zip(in_region)
        .filter(|(_, &r)| r)
    {
        faces.push(t.map(|v| {
            if local[v as usize] == NONE {
                local[v as usize] = region_vertices.len() as u32;
                region_vertices.push(v);
            }
            (m as u32) + local[v as usize]
        }));
    }
    let mut rim_run = Vec::new();
    for (seam, run) in seams.iter().zip(runs) {
        let q: Vec<u32> = seam
            .vertices
            .iter()
            .map(|&v| m as u32 + local[v as usize])
            .collect();
        let q_at: Vec<DVec3> = seam
            .vertices
            .iter()
            .map(|&v| component.positions[v as usize])
            .collect();
        let p_at: Vec<DVec3> = run.vertices.iter().map(|&v| limit[v as usize]).collect();
        faces.extend(strip(&run.vertices, &p_at, &q, &q_at, seam.closed));
        rim_run.extend(run.vertices);
    }
    let mut positions = limit;
    positions.extend(
        region_vertices
            .iter()
            .map(|&v| component.positions[v as usize]),
    );
    let mesh = TriMesh::new(positions, faces);
    Topology::from_mesh(&mesh)?;
    Ok(Joined {
        mesh,
        region_vertices,
        rim_run,
        is_new: is_new.to_vec(),
    })
}
