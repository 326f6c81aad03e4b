//! Local refits of a fitted control mesh: when new data differ from the old only in places
//! (a new version of an object with a part changed, a scan replaced in an object session),
//! only the controls whose support meets changed data, and one ring around them, are
//! solved again; every other control stays where it is, and so does the surface over it.
//!
//! Changed points find their feet on the previous surface; the free controls are those
//! their basis rows touch, plus their neighbours in the control mesh; the points over faces
//! whose patch depends on a free control (the only ones whose surface moves) enter
//! squared-distance rounds like the whole-object fit's (point-to-plane with a small
//! tangential share, the umbrella fairness), with the fixed controls' share of every row
//! moved to the right-hand side. The whole fit's surface-to-data samples are taken on the
//! moving faces when the data mesh is given, and with `hold_rim` the moving data's rim is
//! held on the surface's boundary curve and weighed as in a whole fit (an object session's
//! refits, where a scan's rim moves with its registration; a new version of an object
//! refitted by `version` does not hold it, and a change over much of its control mesh
//! goes to the whole fit instead).

use super::model::{limit_surface, ObjectOptions, RoundStop, MAX_REFUSALS};
use super::refine::{new_faces, Refined};
use super::rim::{near_boundary, FeetMut, Rim};
use super::solve::{foot, Samples};
use crate::fit::distance::{solve_distance_round, CholeskyPattern, DistanceProblem};
use crate::fit::engine::umbrella_laplacian_with_creases;
use crate::fit::Csr;
use crate::mesh::distance::MeshDistance;
use crate::mesh::topology::Topology;
use crate::surface::loop_limit::LoopLimitSurface;
use crate::surface::{SurfaceParam, TriSurface};
use crate::TriMesh;
use glam::DVec3;
use rayon::prelude::*;

/// How a local refit solves.
pub(crate) struct LocalOptions {
    /// Squared-distance rounds at most.
    pub rounds: usize,
    /// The rounds stop once one lowers the RMS of the moving points by less than this.
    pub min_gain: f64,
    /// Share of the point-to-point term beside the point-to-plane one in the first round.
    pub tangential: f64,
    /// The share each taken round halves down to (the whole fit's `tangential_floor`).
    pub share_floor: f64,
    /// Start the rounds at `share_floor` rather than `tangential`: for the refits of a new
    /// version (over changed data, its local refinement, an extension over new ground),
    /// whose previous fit's rounds ended at the floor. Starting above it, the first round
    /// pulls the feet back from where they had slid and the refit falls behind the fit it
    /// updates (a dented torus refitted: 1.50x the RMS of its fit from scratch, 1.44x
    /// from the floor). Off for the stray repair's refits, which hold the surface where it
    /// left the data: from the floor, decimated-max's repair no longer brought it within
    /// the bound.
    pub start_at_floor: bool,
    /// The whole fit's `curvature_floor`: away from the rim band, the share and the
    /// curvature's term of the squared distance in place of `tangential`.
    pub curvature_floor: Option<f64>,
    /// Fairness weight relative to the data (as the whole-object fit's `smoothing`).
    pub smoothing: f64,
    /// When no round after the first starts (the whole-object fit's `stop`): a new version
    /// refitted locally honours the budget and the time limit as a whole fit, which always
    /// takes its first fit, does.
    pub stop: RoundStop,
    /// With the data mesh: hold the moving data's rim on the surface's boundary curve and
    /// weigh the rim and the band next to it as a whole fit does (`tangential_edge`,
    /// `edge_rings`), so that a refit follows a rim that moved.
    pub hold_rim: bool,
    /// Share of the point-to-point term within `edge_rings` rings of the data's rim.
    pub tangential_edge: f64,
    /// Width of that band in vertex rings.
    pub edge_rings: usize,
    /// Weight, per data point a control stands for, of each free control's squared
    /// distance from where it was before the refit (0: off). The point-to-plane rounds
    /// leave a control free to slide along the surface; with its neighbours fixed, a slide
    /// folds the faces between them off the data where no point sees it (an object
    /// session's `SESSION_ANCHOR` says how strong).
    pub anchor: f64,
}

impl LocalOptions {
    /// The rounds, gain, tangential share and fairness of a whole-object fit.
    pub(crate) fn of(opts: &ObjectOptions) -> Self {
        Self {
            rounds: opts.rounds.max(1),
            min_gain: opts.min_gain,
            tangential: opts.tangential,
            share_floor: opts.share_floor(),
            start_at_floor: false,
            curvature_floor: opts.curvature_floor,
            smoothing: opts.smoothing,
            stop: opts.stop.clone(),
            hold_rim: false,
            tangential_edge: opts.tangential_edge,
            edge_rings: opts.edge_rings,
            anchor: 0.0,
        }
    }

    /// [`LocalOptions::of`] for a new version of converged data (`start_at_floor`).
    pub(crate) fn version_of(opts: &ObjectOptions) -> Self {
        Self {
            start_at_floor: true,
            ..Self::of(opts)
        }
    }

    /// One point-to-point round (tangential share 1, no curvature term), as a whole
    /// fit's first fit, with `opts`' fairness and stop.
    pub(crate) fn point_to_point(opts: &ObjectOptions) -> Self {
        Self {
            rounds: 1,
            tangential: 1.0,
            share_floor: 1.0,
            curvature_floor: None,
            ..Self::of(opts)
        }
    }
}

/// Every data point's foot on a surface: parameter, unit normal and distance.
pub(crate) struct LocalFeet {
    pub params: Vec<SurfaceParam>,
    pub normals: Vec<DVec3>,
    pub errors: Vec<f64>,
    /// The curvature's term of each point's squared distance (zero until found; empty,
    /// and not found, without a curvature floor).
    pub curvature: Vec<[f64; 6]>,
}

impl LocalFeet {
    /// Feet at `params` with the distances `errors`, their normals not known yet (found
    /// again, with the feet, for every point a refit moves).
    pub(crate) fn at(params: Vec<SurfaceParam>, errors: Vec<f64>) -> Self {
        let normals = vec![DVec3::ZERO; params.len()];
        Self {
            params,
            normals,
            errors,
            curvature: Vec::new(),
        }
    }

    /// Finds the feet of `points` (indices into `data`) on the surface of `controls`,
    /// starting from their present parameters.
    pub(crate) fn find(
        &mut self,
        surface: &LoopLimitSurface,
        controls: &[DVec3],
        data: &[DVec3],
        points: &[usize],
    ) {
        let evaluate = surface.evaluator(controls);
        let with_curvature = !self.curvature.is_empty();
        let found: Vec<(SurfaceParam, DVec3, f64, [f64; 6])> = points
            .par_iter()
            .with_min_len(256)
            .map(|&i| foot(surface, &*evaluate, data[i], self.params[i], with_curvature))
            .collect();
        for (&i, (param, normal, distance, curvature)) in points.iter().zip(found) {
            self.params[i] = param;
            self.normals[i] = normal;
            self.errors[i] = distance;
            if let Some(slot) = self.curvature.get_mut(i) {
                *slot = curvature;
            }
        }
    }
}

/// The data's rim held on the surface's boundary curve in a local refit, and each data
/// point's class for its point-to-point share.
struct RimHold {
    rim: Rim,
    /// Per data point: 2 on the rim, 1 within the band next to it, 0 elsewhere.
    class: Vec<u8>,
}

impl RimHold {
    fn of(
        surface: &LoopLimitSurface,
        controls: &[DVec3],
        mesh: &TriMesh,
        rings: usize,
    ) -> Option<Self> {
        let control_mesh = TriMesh {
            positions: controls.to_vec(),
            triangles: surface.faces().to_vec(),
        };
        let twins = Topology::from_mesh(&control_mesh).ok()?.twin;
        let on_rim = near_boundary(mesh, 0);
        let band = near_boundary(mesh, rings);
        let class = on_rim
            .iter()
            .zip(&band)
            .map(|(&r, &b)| if r { 2 } else { u8::from(b) })
            .collect();
        Some(Self {
            rim: Rim::new(&control_mesh.triangles, &twins, &on_rim),
            class,
        })
    }

    fn hold(
        &self,
        feet: &mut LocalFeet,
        surface: &LoopLimitSurface,
        controls: &[DVec3],
        data: &[DVec3],
        moving: &[bool],
    ) {
        let parts = FeetMut {
            params: &mut feet.params,
            normals: &mut feet.normals,
            distances: &mut feet.errors,
        };
        self.rim
            .hold_where(parts, surface, controls, data, Some(moving));
    }

    /// Point `i`'s point-to-point share in a round of share `share`, as a whole fit's.
    fn share(&self, i: usize, share: f64, edge_factor: f64) -> f64 {
        match self.class.get(i) {
            Some(2) => 1.0,
            Some(1) => share * edge_factor,
            _ => share,
        }
    }
}

/// The moving points' tangential shares in a round of share `share` (`RimHold::share`, as
/// a whole fit's) and, with `opts.curvature_floor`, their curvature terms, in `moving`'s
/// order: away from the rim band the share is the floor and the term is added, both
/// scaled as the whole fit's (`shares_and_curvature`).
fn local_shares(
    moving: &[usize],
    feet: &LocalFeet,
    hold: Option<&RimHold>,
    share: f64,
    opts: &LocalOptions,
) -> (Vec<f64>, Option<Vec<[f64; 6]>>) {
    let edge_factor = opts.tangential_edge / opts.tangential.max(f64::MIN_POSITIVE);
    let class = |i: usize| hold.and_then(|h| h.class.get(i).copied()).unwrap_or(0);
    let shares = moving
        .iter()
        .map(|&i| match hold {
            Some(h) => h.share(i, share, edge_factor),
            None => share,
        })
        .collect();
    let Some(floor) = opts.curvature_floor else {
        return (shares, None);
    };
    let damping = share / opts.tangential.max(f64::MIN_POSITIVE);
    let mut shares = shares;
    let mut curvature = vec![[0.0; 6]; moving.len()];
    for (k, &i) in moving.iter().enumerate() {
        if class(i) != 0 {
            continue;
        }
        shares[k] = floor * damping;
        if let Some(c) = feet.curvature.get(i) {
            curvature[k] = c.map(|x| x * damping);
        }
    }
    (shares, Some(curvature))
}

/// A local refit's result: the controls and feet, and what it touched.
pub(crate) struct LocalFit {
    pub controls: Vec<DVec3>,
    pub params: Vec<SurfaceParam>,
    pub errors: Vec<f64>,
    /// The controls solved again (sorted).
    pub free_controls: Vec<u32>,
    /// Data points that changed.
    pub changed_points: usize,
    /// Data points whose surface may move (their feet were found again).
    pub moving_points: usize,
    /// RMS and largest distance of the moving points on the previous surface, then after
    /// each round taken.
    pub rounds: Vec<(f64, f64)>,
}

/// RMS and largest of the `points`' errors.
fn rms_of(errors: &[f64], points: &[usize]) -> (f64, f64) {
    let sum: f64 = points.iter().map(|&i| errors[i] * errors[i]).sum();
    let max = points.iter().fold(0.0f64, |m, &i| m.max(errors[i]));
    ((sum / points.len().max(1) as f64).sqrt(), max)
}

/// Refits the controls `free` (see [`free_controls`]) of the surface of `controls` to
/// `data`, every other control kept; `feet` holds every point's foot on that surface
/// (those of the `changed` points found on it).
///
/// With `data_mesh` (the mesh of `data`), every round also pulls the moving faces' parts no
/// foot point sees to the data mesh (the whole fit's surface-to-data samples, `Samples`,
/// inside the faces only, see `Rim::without_boundary`): without them a free control next
/// to a face without data swings that face off the data.
#[allow(clippy::too_many_arguments)]
pub(crate) fn refit_around(
    surface: &LoopLimitSurface,
    controls: &[DVec3],
    data: &[DVec3],
    data_mesh: Option<&TriMesh>,
    mut feet: LocalFeet,
    changed: usize,
    free: &[bool],
    opts: &LocalOptions,
) -> LocalFit {
    let n = data.len();
    let m = surface.control_count();
    // Where the controls stood before the refit: what `LocalOptions::anchor` holds to.
    let anchor_at = controls;
    let mut controls = controls.to_vec();
    let moving_face = moving_faces(surface, free);
    let sampling = data_mesh.map(|mesh| {
        (
            mesh,
            MeshDistance::new(mesh),
            Rim::without_boundary(surface.faces().len()),
        )
    });
    let moving: Vec<usize> = (0..n)
        .filter(|&i| moving_face[feet.params[i].face as usize])
        .collect();
    let hold = data_mesh
        .filter(|m| opts.hold_rim && m.positions.len() == n)
        .and_then(|m| RimHold::of(surface, &controls, m, opts.edge_rings));
    let mut is_moving = vec![false; n];
    for &i in &moving {
        is_moving[i] = true;
    }
    let find = |feet: &mut LocalFeet, controls: &[DVec3]| {
        feet.find(surface, controls, data, &moving);
        if let Some(h) = &hold {
            h.hold(feet, surface, controls, data, &is_moving);
        }
    };
    if opts.curvature_floor.is_some() {
        feet.curvature = vec![[0.0; 6]; n];
    }
    find(&mut feet, &controls);
    let mut rounds = vec![rms_of(&feet.errors, &moving)];

    let column: Vec<Option<u32>> = {
        let mut next = 0u32;
        free.iter()
            .map(|&f| {
                f.then(|| {
                    next += 1;
                    next - 1
                })
            })
            .collect()
    };
    let free_ids: Vec<u32> = (0..m as u32).filter(|&c| free[c as usize]).collect();
    let laplacian = umbrella_laplacian_with_creases(m, surface.faces(), surface.crease_edges());
    let system = System {
        surface,
        column: &column,
        free_count: free_ids.len(),
        laplacian: &laplacian,
        fairness_scale: (opts.smoothing * n as f64 / m.max(1) as f64).sqrt(),
        anchor: (anchor_at, (opts.anchor * n as f64 / m.max(1) as f64).sqrt()),
    };
    // One symbolic analysis (and warm starts) across the rounds, as in a whole fit.
    let mut pattern = CholeskyPattern::default();
    // Levenberg-Marquardt on the tangential share, as in a whole fit (`fit_from`): a
    // round that does not lower the RMS is taken again with four times the share, one
    // that does halves it down to the floor.
    let floor = opts.share_floor.min(opts.tangential);
    let mut share = if opts.start_at_floor {
        floor
    } else {
        opts.tangential
    };
    let (mut taken, mut refusals, mut tried) = (0, 0, 0);
    while taken < opts.rounds && refusals < MAX_REFUSALS {
        // The first round is the changed region's first fit, which a whole fit always
        // takes too; the stop applies from the second.
        if free_ids.is_empty() || (tried > 0 && opts.stop.reached(&feet.errors)) {
            break;
        }
        tried += 1;
        let samples = match &sampling {
            Some((mesh, nearest, rim)) => Samples::find(
                surface,
                &controls,
                &feet.params,
                rim,
                mesh,
                nearest,
                Some(&moving_face),
            ),
            None => Samples::none(),
        };
        let (shares, curvature) = local_shares(&moving, &feet, hold.as_ref(), share, opts);
        let solved = system.solve(
            data,
            (&moving, &feet),
            &samples,
            &controls,
            (share, &shares, curvature.as_deref()),
            &mut pattern,
        );
        let Some(solved) = solved else {
            break;
        };
        let mut next = controls.clone();
        for (&c, x) in free_ids.iter().zip(solved) {
            next[c as usize] = x;
        }
        let mut trial = LocalFeet {
            params: feet.params.clone(),
            normals: feet.normals.clone(),
            errors: feet.errors.clone(),
            curvature: feet.curvature.clone(),
        };
        find(&mut trial, &next);
        let before = rounds[rounds.len() - 1].0;
        let (after, max) = rms_of(&trial.errors, &moving);
        if after.is_nan() || after >= before {
            refusals += 1;
            share *= 4.0;
            continue;
        }
        controls = next;
        feet = trial;
        rounds.push((after, max));
        taken += 1;
        share = (share * 0.5).max(floor);
        if before - after < opts.min_gain * before {
            break;
        }
    }
    LocalFit {
        controls,
        params: feet.params,
        errors: feet.errors,
        free_controls: free_ids,
        changed_points: changed,
        moving_points: moving.len(),
        rounds,
    }
}

/// The controls the basis rows of the `changed` points touch, and their neighbours.
pub(crate) fn free_controls(
    surface: &LoopLimitSurface,
    params: &[SurfaceParam],
    changed: &[usize],
) -> Vec<bool> {
    let m = surface.control_count();
    let mut touched = vec![false; m];
    let mut row = Vec::new();
    for &i in changed {
        surface.basis_row(params[i], &mut row);
        for &(c, w) in &row {
            if w != 0.0 {
                touched[c as usize] = true;
            }
        }
    }
    with_neighbours(surface.faces(), &touched)
}

/// A refined control mesh's surface and the local refit on it (`refit_refined`).
pub(super) struct RefinedRefit {
    /// The refined mesh's limit surface.
    pub surface: LoopLimitSurface,
    /// The controls the refit solved.
    pub free: Vec<bool>,
    /// The refit.
    pub fit: LocalFit,
}

/// The surface of `refined` (a refinement of the surface `previous`, whose data points
/// had the distances `errors`), with the controls around its new faces refitted to the
/// vertices of `component` from `refined.warm`, every other control kept: the feet of the
/// points on new faces are found again, and the controls their rows reach, plus a ring,
/// are freed. With `free_new_faces` (the stray repair), the points on every face with a
/// corner within a ring of a new face's corners are found again too, and those faces'
/// controls and a ring are freed, so a new face without data is held as well. `None`
/// when the surface cannot be built.
pub(super) fn refit_refined(
    previous: &LoopLimitSurface,
    refined: &Refined,
    component: &TriMesh,
    errors: &[f64],
    free_new_faces: bool,
    opts: &LocalOptions,
) -> Option<RefinedRefit> {
    let data = &component.positions;
    let surface = limit_surface(&refined.mesh, &refined.creases, Some(previous)).ok()?;
    let mut new_face = new_faces(previous, &surface);
    // A split raises the valence of its edge's far corners and the flips after it change
    // more, and a Loop patch depends on its corners' rings: the patch of every face with
    // a corner within a ring of a new face's corners changes too. A repair that refits
    // only the points on the new faces leaves the points there on their old feet
    // (cheburashka, 16 rounds: each repair round 0.35-1.4 % worse in RMS, refused; with
    // them decimated-max, chin_tri and cheburashka all end nearer their data).
    if free_new_faces {
        let corners = corners_of(surface.faces(), &new_face, refined.mesh.positions.len());
        new_face = moving_faces(&surface, &corners);
    }
    let touched: Vec<usize> = (0..data.len())
        .filter(|&i| new_face[refined.params[i].face as usize])
        .collect();
    let mut feet = LocalFeet::at(refined.params.clone(), errors.to_vec());
    feet.find(&surface, &refined.warm, data, &touched);
    let mut free = free_controls(&surface, &feet.params, &touched);
    if free_new_faces {
        let corners = corners_of(surface.faces(), &new_face, free.len());
        for (free, corner) in free
            .iter_mut()
            .zip(with_neighbours(surface.faces(), &corners))
        {
            *free |= corner;
        }
    }
    let fit = refit_around(
        &surface,
        &refined.warm,
        data,
        Some(component),
        feet,
        touched.len(),
        &free,
        opts,
    );
    Some(RefinedRefit { surface, free, fit })
}

/// Per vertex (of `vertex_count`), whether it is a corner of a face `marked`.
fn corners_of(faces: &[[u32; 3]], marked: &[bool], vertex_count: usize) -> Vec<bool> {
    let mut corners = vec![false; vertex_count];
    for (f, _) in faces.iter().zip(marked).filter(|(_, &m)| m) {
        for &v in f {
            corners[v as usize] = true;
        }
    }
    corners
}

/// `marked` with every vertex of a face holding a marked vertex: one ring more.
fn with_neighbours(faces: &[[u32; 3]], marked: &[bool]) -> Vec<bool> {
    let mut grown = marked.to_vec();
    for f in faces {
        if f.iter().any(|&v| marked[v as usize]) {
            for &v in f {
                grown[v as usize] = true;
            }
        }
    }
    grown
}

/// Per control face, whether its patch depends on a free control: a Loop patch depends on
/// its corners and their neighbours.
fn moving_faces(surface: &LoopLimitSurface, free: &[bool]) -> Vec<bool> {
    let near_free = with_neighbours(surface.faces(), free);
    surface
        .faces()
        .iter()
        .map(|f| f.iter().any(|&v| near_free[v as usize]))
        .collect()
}

/// The squared-distance problem over the free controls.
struct System<'a> {
    surface: &'a LoopLimitSurface,
    /// Each control's column among the free ones.
    column: &'a [Option<u32>],
    free_count: usize,
    laplacian: &'a Csr,
    /// sqrt of the fairness weight: the umbrella rows are scaled by it.
    fairness_scale: f64,
    /// The controls before the refit and the scale of the rows holding each free
    /// control near its place there.
    anchor: (&'a [DVec3], f64),
}

impl System<'_> {
    /// The free controls minimising the distance of the `moving` points at their feet and
    /// the fairness of the rows that hold a free control; `None` if the solve fails.
    fn solve(
        &self,
        data: &[DVec3],
        (moving, feet): (&[usize], &LocalFeet),
        samples: &Samples,
        controls: &[DVec3],
        (share, shares, curvature): (f64, &[f64], Option<&[[f64; 6]]>),
        pattern: &mut CholeskyPattern,
    ) -> Option<Vec<DVec3>> {
        let mut basis = Csr {
            nrows: 0,
            ncols: self.free_count,
            row_ptr: vec![0],
            ..Default::default()
        };
        let (mut targets, mut normals, mut tangential) = (vec![], vec![], vec![]);
        let push_row = |entries: &mut dyn Iterator<Item = (u32, f64)>,
                        target: DVec3,
                        scale: f64,
                        basis: &mut Csr| {
            let mut fixed = DVec3::ZERO;
            for (c, w) in entries {
                match self.column[c as usize] {
                    Some(col) => {
                        basis.col_idx.push(col);
                        basis.values.push(w * scale);
                    }
                    None => fixed += w * controls[c as usize],
                }
            }
            basis.row_ptr.push(basis.col_idx.len());
            basis.nrows += 1;
            (target - fixed) * scale
        };
        let mut row = Vec::new();
        for (&i, &point_share) in moving.iter().zip(shares) {
            self.surface.basis_row(feet.params[i], &mut row);
            let mut entries = row.iter().copied().filter(|e| e.1 != 0.0);
            targets.push(push_row(&mut entries, data[i], 1.0, &mut basis));
            normals.push(feet.normals[i]);
            tangential.push(point_share);
        }
        for ((&param, &target), &normal) in samples
            .params
            .iter()
            .zip(&samples.targets)
            .zip(&samples.normals)
        {
            self.surface.basis_row(param, &mut row);
            let mut entries = row.iter().copied().filter(|e| e.1 != 0.0);
            targets.push(push_row(&mut entries, target, 1.0, &mut basis));
            normals.push(normal);
            tangential.push(share);
        }
        // The umbrella rows holding a free control, once per axis: three point-to-plane
        // rows along x, y and z weigh |L P|^2 as the whole-object fit's fairness does.
        let l = self.laplacian;
        for r in 0..l.nrows {
            let span = l.row_ptr[r]..l.row_ptr[r + 1];
            if !l.col_idx[span.clone()]
                .iter()
                .any(|&c| self.column[c as usize].is_some())
            {
                continue;
            }
            for axis in [DVec3::X, DVec3::Y, DVec3::Z] {
                let mut entries = span.clone().map(|e| (l.col_idx[e], l.values[e]));
                targets.push(push_row(
                    &mut entries,
                    DVec3::ZERO,
                    self.fairness_scale,
                    &mut basis,
                ));
                normals.push(axis);
                tangential.push(0.0);
            }
        }
        let (anchor, anchor_scale) = self.anchor;
        if anchor_scale > 0.0 {
            for (c, at) in anchor.iter().enumerate() {
                if self.column[c].is_none() {
                    continue;
                }
                for axis in [DVec3::X, DVec3::Y, DVec3::Z] {
                    let mut entries = std::iter::once((c as u32, 1.0));
                    targets.push(push_row(&mut entries, *at, anchor_scale, &mut basis));
                    normals.push(axis);
                    tangential.push(0.0);
                }
            }
        }
        let problem = DistanceProblem {
            basis: &basis,
            data: &targets,
            normals: &normals,
            tangential: &tangential,
            curvature,
            fairness: None,
            smoothing: 0.0,
        };
        let start: Vec<DVec3> = self
            .column
            .iter()
            .zip(controls)
            .filter(|(c, _)| c.is_some())
            .map(|(_, p)| *p)
            .collect();
        let x = solve_distance_round(&problem, pattern, Some(&start))?;
        (x.len() == self.free_count && x.iter().all(|p| p.is_finite())).then_some(x)
    }
}
