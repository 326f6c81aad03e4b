//! Whole objects (closed, holed, any genus): the exact Loop limit surface of a control mesh
//! found by simplifying the data (Hoppe et al. 1994; Marinov & Kobbelt 2005), fitted to
//! every data point.
//!
//! Stages: clean and keep the largest component; simplify it by quadric edge collapse to
//! a share of the control budget (`mesh::simplify`: the topology is kept, so the control
//! mesh has the component's Euler characteristic and boundary loops, and every data vertex
//! is carried to a control face: its initial parameter); even the valences by edge flips
//! (`layout`); a point-to-point least-squares fit at those parameters with a small umbrella
//! fairness term; then rounds of foot points (Newton on the limit surface, crossing faces,
//! the data's rim held on the surface's boundary curve) and squared-distance minimisation
//! (point-to-plane with a small tangential share; with `curvature_floor`, the curvature's
//! tangential term of Pottmann's squared distance instead, as Cheng, Wang et al. 2004 fit
//! subdivision surfaces: `geometric::curvature_term`) until a round gains less than
//! `min_gain` of the RMS; then refinement rounds (`refine`) spend the rest of the budget
//! where the error is, each followed by a fit on the refined mesh.
//! Sharp edges of the data (`mesh::crease`) are kept through the simplification, the
//! flips and the splits, and become crease edges of the limit surface.

mod component;
mod corners;
mod data_side;
mod extend;
mod faceted;
mod fit_parts;
mod layout;
mod local;
mod model;
mod refine;
mod repair;
mod rim;
mod seam;
mod semi_regular;
mod shares;
mod simplification;
mod solve;
mod stray;
mod version;

use crate::fit::distance::CholeskyPattern;
use crate::fit::Collocation;
use crate::mesh::clean::CleanOptions;
use crate::mesh::crease::{crease_sets, detect_creases};
use crate::mesh::simplify::{fixed_crease_vertices, Simplified, SimplifyOptions, SurfaceTopology};
use crate::mesh::topology::Topology;
use crate::surface::loop_limit::LoopLimitSurface;
use crate::surface::SurfaceParam;
use crate::TriMesh;
pub use component::ObjectInput;
use corners::rim_corners;
use data_side::DataSide;
pub use extend::{extend_over_new_ground, NotExtended};
pub use faceted::is_faceted;
use fit_parts::{declined, FitStart, GoOn, RoundContext, Setup};
use glam::DVec3;
use layout::improve_layout;
pub use layout::{LayoutOptions, LayoutReport};
pub(crate) use local::{free_controls, refit_around, LocalFeet, LocalFit, LocalOptions};
use model::{control_target, landing_params, ms_since, MAX_REFUSALS};
pub use model::{
    FacetedChoice, LocalUpdate, ObjectError, ObjectFit, ObjectOptions, ObjectTimes, PreviousFit,
    RoundReport, RoundStop, StrayBudget, CURVATURE_FLOOR, STRAY_BUDGET_STEPS,
    STRAY_LATTICE_SEGMENTS, STRAY_LIMIT_SHARE,
};
use refine::{faces_beyond, refined_mesh, Fitted, Splits, MIN_FACES_BEYOND_SHARE};
pub use refine::{RefineOptions, RefineRound};
pub(crate) use repair::refine_where_far;
use rim::Rim;
use simplification::simplify_for_control;
use solve::{point_fit, rows_at, Feet};
use std::cell::Cell;
use std::time::Instant;
pub use stray::{farthest_from, farthest_from_data};
use stray::{grow_budget_while_straying, steady_share_while_straying};
pub use version::refit_where_changed;

/// The component of `mesh` [`fit_object`] fits: its cleaned largest component, repaired
/// to a manifold where cleaning alone leaves it not one; `None` when nothing is left.
pub fn fitted_component(mesh: &TriMesh, clean: &CleanOptions) -> Option<TriMesh> {
    ObjectInput::of(mesh, clean).map(|input| input.mesh)
}

/// Fits the exact Loop limit surface of a simplified control mesh to the largest
/// component of `mesh`.
pub fn fit_object(mesh: &TriMesh, opts: &ObjectOptions) -> Result<ObjectFit, ObjectError> {
    let input = ObjectInput::of(mesh, &opts.clean).ok_or(ObjectError::Empty)?;
    fit_object_input(input, opts)
}

/// [`fit_object`] of an input already prepared (with `opts.clean`). Where the whole fit
/// and its stray repair leave the surface straying past `opts.max_stray_share` and the
/// budget cannot hold the shape, the object is fitted again from scratch at twice the
/// controls the fit before spent, `opts.stray_budget_steps` times at most, and the least
/// straying fit is kept (`grow_budget_while_straying`; why: `model::STRAY_BUDGET_STEPS`).
pub fn fit_object_input(
    input: ObjectInput,
    opts: &ObjectOptions,
) -> Result<ObjectFit, ObjectError> {
    let start = Instant::now();
    let ObjectInput {
        mesh: component,
        cleaning,
        topology: data_topo,
        prepare_ms,
        ..
    } = input;
    let t = Instant::now();
    let side = match &data_topo {
        Some(topo) => DataSide::of_built(&component, topo, opts),
        None => DataSide::new(&component, opts)?,
    };
    let side_ms = ms_since(t);
    let asked = control_target(component.positions.len(), opts);
    // The data's sharp edges, found once for every fit of the object.
    let sharp = data_topo.as_ref().map_or_else(Vec::new, |topo| {
        detect_creases(&component, topo, &opts.crease)
    });
    let topo = data_topo.as_ref();
    let fit = fit_at_target(&side, topo, &sharp, asked, opts)?;
    let (fit, opts) =
        steady_share_while_straying(fit, opts, |o| fit_at_target(&side, topo, &sharp, asked, o));
    let opts = &opts;
    let fit = grow_budget_while_straying(fit, asked, opts, &side, topo, |target| {
        fit_at_target(&side, topo, &sharp, target, opts)
    });
    let fit = faceted::keep_nearer(fit, &side, topo, &sharp, opts, |start, o| {
        fit_from(&side, start, o)
    });
    let mut fit = faceted::hold_bound(fit, &side, topo, opts, |start, o| fit_from(&side, start, o));
    // The data side is built once for every fit: reported with the kept fit's setup.
    fit.times.surface_ms += side_ms;
    fit.cleaning = Some(cleaning);
    fit.times.clean_ms = prepare_ms;
    fit.times.total_ms = prepare_ms + ms_since(start);
    Ok(fit)
}

/// The whole fit at `target` controls of the data `side` holds (`data_topo`: its topology,
/// when it is a manifold; `sharp`: its sharp edges, `detect_creases`), repaired where it
/// strays.
fn fit_at_target(
    side: &DataSide,
    data_topo: Option<&Topology>,
    sharp: &[[u32; 2]],
    target: usize,
    opts: &ObjectOptions,
) -> Result<ObjectFit, ObjectError> {
    let start = Instant::now();
    let mut times = ObjectTimes::default();
    let component = side.mesh;
    let t = Instant::now();
    // With refinement on, the simplification keeps a share of the budget and the rounds
    // spend the rest where the first fit leaves the error.
    let first_target = if opts.refine.rounds > 0 {
        ((target as f64 * opts.refine.start_share).round() as usize).clamp(4.min(target), target)
    } else {
        target
    };
    let split_factor = 4usize.saturating_pow(opts.domain_levels as u32);
    let first_target = (first_target / split_factor).max(4.min(first_target));
    // The holes' minimum never takes more than a quarter of the budget (a broken scan can
    // have dozens of tiny holes).
    let loops = data_topo.map_or(0, |topo| {
        SurfaceTopology::of_built(component, topo).boundary_loops
    });
    let min_boundary_loop = opts
        .simplify
        .min_boundary_loop
        .min(first_target / (4 * loops.max(1)))
        .max(3);
    let simplify_opts = SimplifyOptions {
        target_vertices: first_target,
        min_boundary_loop,
        ..opts.simplify.clone()
    };
    let data_creases = match data_topo {
        Some(topo) => feature_line_creases(component, topo, sharp, &simplify_opts),
        None => Vec::new(),
    };
    let (simplified, guard_dropped) =
        simplify_for_control(component, data_topo, &simplify_opts, &data_creases)
            .map_err(ObjectError::Simplify)?;
    times.simplify_ms = ms_since(t);

    let Simplified {
        mesh: control_mesh,
        landing,
        crease_edges,
        control_of,
        ..
    } = simplified;
    let corners = match data_topo {
        Some(topo) => rim_corners(
            component,
            topo,
            &control_mesh,
            &control_of,
            opts.simplify.corner_turn_deg,
        ),
        None => Vec::new(),
    };
    let params = landing_params(&landing);
    let t = Instant::now();
    let (control_mesh, params, crease_edges, mut layout) = improve_layout(
        component,
        control_mesh,
        params,
        &crease_edges,
        &corners,
        &opts.layout,
    );
    layout.quality_guard_dropped = guard_dropped;
    let (control_mesh, params, crease_edges) =
        semi_regular::split_domain(control_mesh, params, crease_edges, opts.domain_levels)
            .map_err(ObjectError::NotManifold)?;
    times.layout_ms = ms_since(t);
    let refining = opts.refine.rounds > 0 && first_target < target;
    let first_opts = if refining {
        intermediate(opts)
    } else {
        opts.clone()
    };
    let go_on = GoOn {
        rounds: opts.rounds,
        cap: target,
        declined_at: Cell::new(None),
    };
    let first = FitStart {
        go_on: refining.then_some(&go_on),
        ..FitStart::new(control_mesh, &crease_edges, params)
    };
    let mut fit = fit_from(side, first, &first_opts)?;
    if let Some(declined_at) = go_on.declined_at.get() {
        fit.refinement = vec![declined_at];
    } else if refining {
        fit = refine_fit(fit, target, opts, side);
    }
    let mut fit = repair::keep_near_data(fit, target, opts, side);
    fit.layout = layout;
    fit.times.simplify_ms = times.simplify_ms;
    fit.times.layout_ms = times.layout_ms;
    fit.times.total_ms = ms_since(start);
    Ok(fit)
}

/// The data's crease sets that are feature lines: sets where at most
/// `MAX_FIXED_SHARE` of the vertices are fixed by the simplification (corners, chain
/// ends, sharp turns: `fixed_crease_vertices`), so that the runs between them are long.
fn feature_line_creases(
    component: &TriMesh,
    topo: &Topology,
    creases: &[[u32; 2]],
    simplify_opts: &SimplifyOptions,
) -> Vec<[u32; 2]> {
    let fixed = fixed_crease_vertices(component, topo, creases, simplify_opts);
    let mut kept = Vec::new();
    for set in crease_sets(creases, &component.positions) {
        let mut vertices: Vec<u32> = set.iter().flatten().copied().collect();
        vertices.sort_unstable();
        vertices.dedup();
        let own = vertices.iter().filter(|&&v| fixed[v as usize]).count();
        if own as f64 <= MAX_FIXED_SHARE * vertices.len() as f64 {
            kept.extend(set);
        }
    }
    kept.sort_unstable();
    kept
}

/// A crease set where more of its vertices than this are corners, chain ends or sharp
/// turns is a net of short sharp runs, not feature lines, and is no crease. A machined
/// part's lines run on between corners: fandisk's one set of 806 vertices has 33 such
/// vertices (4 %), cheburashka's ear rims at most 19 %. The sharp sets of scans are
/// fragmented: camelhead's 60 %, chin_tri's 40 %, the dragon's at 5k and 23k vertices
/// 36-100 %, a messy head scan's (snowden, 54k vertices) 43 % in all, where each fixed
/// vertex cost a control and the fit came out at 1.5 times the decimated mesh's RMS.
const MAX_FIXED_SHARE: f64 = 0.25;

/// The fit stages after the control mesh is chosen: the limit surface of `control_mesh`
/// fitted to the vertices of `component` from the initial parameters `params` (one per
/// vertex, on the control faces), the control positions initialised by a least-squares
/// fit there.
pub fn fit_on_control_mesh(
    component: TriMesh,
    control_mesh: TriMesh,
    params: Vec<SurfaceParam>,
    opts: &ObjectOptions,
) -> Result<ObjectFit, ObjectError> {
    fit_on_creased_control_mesh(component, control_mesh, &[], params, None, opts)
}

/// [`fit_on_control_mesh`] with crease edges (pairs of control indices) on the limit
/// surface, taking over the quadtrees of `reusing` (a surface of an earlier control mesh,
/// such as the previous version's) where they fit.
pub fn fit_on_creased_control_mesh(
    component: TriMesh,
    control_mesh: TriMesh,
    crease_edges: &[[u32; 2]],
    params: Vec<SurfaceParam>,
    reusing: Option<&LoopLimitSurface>,
    opts: &ObjectOptions,
) -> Result<ObjectFit, ObjectError> {
    let side = DataSide::new(&component, opts)?;
    let start = FitStart {
        previous: reusing,
        ..FitStart::new(control_mesh, crease_edges, params)
    };
    fit_from(&side, start, opts)
}

/// [`fit_on_creased_control_mesh`] from `start`, on the data of `side`.
fn fit_from(
    side: &DataSide,
    start_from: FitStart,
    opts: &ObjectOptions,
) -> Result<ObjectFit, ObjectError> {
    let FitStart {
        control_mesh,
        crease_edges,
        params,
        warm,
        previous,
        go_on,
    } = start_from;
    let start = Instant::now();
    let mut times = ObjectTimes::default();
    let component = side.mesh;
    let n = component.positions.len();
    one_param_per_point(&params, n)?;
    let data_topology = side.topology;
    let Setup {
        surface,
        control_topology,
        rim,
        fairness,
        smoothing,
    } = Setup::new(side, &control_mesh, crease_edges, previous, opts)?;
    let m = control_mesh.positions.len();
    times.surface_ms = ms_since(start);

    let t = Instant::now();
    let data = component.positions.clone();
    let warm = warm.filter(|w| w.len() == m);
    let first = FirstFit {
        surface: &surface,
        control_mesh: &control_mesh,
        data: &data,
        rim: &rim,
        fairness: &fairness,
        smoothing,
    };
    let (mut controls, mut feet) = match warm {
        Some(controls) => warm_start(&first, controls, &params, opts),
        None => first_fit(first, params, opts)?,
    };
    times.first_fit_ms = ms_since(t);

    let t = Instant::now();
    let mut rounds = vec![RoundReport {
        rms: feet.rms(),
        max: feet.max(),
    }];
    // Levenberg-Marquardt on the tangential share: a round that does not lower the
    // (two-sided) RMS is taken again with four times the share (the surface slides less
    // per round), a round that does halves it down to `opts.tangential_floor`. Controls
    // far from their final parameterization need long slides that a fixed small share
    // makes unstable and a fixed large share makes slow.
    let mut share = opts.tangential;
    let near_edge = side.near_edge(opts.edge_rings);
    let context = RoundContext {
        surface: &surface,
        data: &data,
        component,
        rim: &rim,
        fairness: &fairness,
        smoothing,
        near_edge: &near_edge,
        on_rim: &rim.marks(n),
        nearest: opts.surface_samples.then(|| side.nearest()),
        opts,
    };
    let (mut refusals, mut taken) = (0, 0);
    let mut sampled_faces = 0;
    let mut pattern = CholeskyPattern::default();
    let mut go_on = go_on;
    let mut limit = opts.rounds;
    while refusals < MAX_REFUSALS {
        if taken >= limit {
            let fitted = Fitted {
                component,
                surface: &surface,
                controls: &controls,
                params: &feet.params,
                distances: &feet.distances,
            };
            match go_on.take().and_then(|g| g.raised(limit, &fitted, opts)) {
                Some(raised) => limit = raised,
                None => break,
            }
        }
        if opts.stop.reached(&feet.distances) {
            break;
        }
        let tried = context.round(&controls, &feet, share, &mut pattern);
        sampled_faces = tried.sampled_faces;
        let before = tried.before;
        let Some((next_feet, next, after)) = tried.next else {
            refusals += 1;
            share *= 4.0;
            continue;
        };
        controls = next;
        feet = next_feet;
        taken += 1;
        rounds.push(RoundReport {
            rms: feet.rms(),
            max: feet.max(),
        });
        share = (share * 0.5).max(opts.share_floor());
        if before - after < opts.min_gain * before {
            break;
        }
    }
    times.rounds_ms = ms_since(t);
    times.total_ms = ms_since(start);
    Ok(ObjectFit {
        sampled_faces,
        data,
        component: component.clone(),
        simplified: control_mesh,
        rms: feet.rms(),
        max: feet.max(),
        surface,
        controls,
        params: feet.params,
        distances: feet.distances,
        rounds,
        data_topology,
        control_topology,
        times,
        layout: LayoutReport::default(),
        refinement: Vec::new(),
        local: None,
        stray: None,
        cleaning: None,
        stray_budgets: Vec::new(),
        faceted: None,
    })
}

/// A fit needs one initial parameter per data point.
fn one_param_per_point(params: &[SurfaceParam], points: usize) -> Result<(), ObjectError> {
    if params.len() == points {
        return Ok(());
    }
    Err(ObjectError::ParamCount {
        params: params.len(),
        points,
    })
}

/// What the first point fit works on.
struct FirstFit<'a> {
    surface: &'a LoopLimitSurface,
    control_mesh: &'a TriMesh,
    data: &'a [DVec3],
    rim: &'a Rim,
    fairness: &'a Collocation,
    smoothing: f64,
}

/// A warm start's first fit: the previous controls as they are, and the data's feet on
/// their surface from `params`, the rim held.
fn warm_start(
    f: &FirstFit,
    controls: Vec<DVec3>,
    params: &[SurfaceParam],
    opts: &ObjectOptions,
) -> (Vec<DVec3>, Feet) {
    let with_curvature = opts.curvature_floor.is_some();
    let mut feet = Feet::find(f.surface, &controls, f.data, (params, with_curvature));
    feet.hold_rim(f.rim, f.surface, &controls, f.data);
    (controls, feet)
}

/// The point-to-point fit at the initial parameters (or, with `limit_start`, at their foot
/// points on the initial control mesh's limit surface) and the data's foot points on it.
fn first_fit(
    f: FirstFit,
    params: Vec<SurfaceParam>,
    opts: &ObjectOptions,
) -> Result<(Vec<DVec3>, Feet), ObjectError> {
    let positions = &f.control_mesh.positions;
    let params = if opts.limit_start {
        let mut start = Feet::find(f.surface, positions, f.data, (&params, false));
        start.hold_rim(f.rim, f.surface, positions, f.data);
        start.params
    } else {
        params
    };
    let rows = rows_at(f.surface, &params);
    let controls = point_fit(
        &rows,
        f.data,
        f.fairness,
        f.smoothing,
        positions.clone(),
        opts.max_iterations,
    )
    .ok_or(ObjectError::Solve { stage: "first" })?;
    drop(rows);
    let mut feet = Feet::find(
        f.surface,
        &controls,
        f.data,
        (&params, opts.curvature_floor.is_some()),
    );
    feet.hold_rim(f.rim, f.surface, &controls, f.data);
    Ok((controls, feet))
}

/// Refinement rounds after the first fit (see `refine`): each refines the control mesh
/// where the error is and fits again; a round that fails or does not lower the RMS ends
/// them, its fit dropped.
fn refine_fit(first: ObjectFit, cap: usize, opts: &ObjectOptions, side: &DataSide) -> ObjectFit {
    let t = Instant::now();
    let tolerance = opts.refine.tolerance;
    let first_times = first.times.clone();
    let round_of =
        |f: &ObjectFit| RefineRound::of(f.controls.len(), f.rms, f.max, &f.distances, tolerance);
    let mut stages = vec![round_of(&first)];
    let mut fit = first;
    // Whether `fit` ran only the intermediate rounds (it shows where to refine but is not
    // converged): then the rest of its rounds run after the refinement.
    let mut unfinished = true;
    for round in 0..opts.refine.rounds {
        let fitted = fit.fitted();
        if declined(&fitted, cap, opts) {
            break;
        }
        let room = cap - fit.controls.len();
        let share = room.div_ceil(opts.refine.rounds - round);
        // As many splits as faces miss the tolerance (up to the round's share of the room):
        // the misfit says how much to refine, the squared error where.
        let beyond = faces_beyond(&fitted, tolerance);
        let add = share.min(beyond);
        let Some(refined) = refined_mesh(&fitted, add, &opts.layout, Splits::ByError) else {
            break;
        };
        let splits = refined
            .mesh
            .positions
            .len()
            .saturating_sub(fit.controls.len());
        if splits * MIN_FACES_BEYOND_SHARE < fit.controls.len() {
            break;
        }
        // Only the last fit runs all its rounds: the ones before only show where to refine.
        let last = round + 1 == opts.refine.rounds || add == room;
        let round_opts = if last {
            opts.clone()
        } else {
            intermediate(opts)
        };
        let start = FitStart {
            warm: opts.refine.warm.then_some(refined.warm),
            previous: Some(&fit.surface),
            ..FitStart::new(refined.mesh, &refined.creases, refined.params)
        };
        let Ok(next) = fit_from(side, start, &round_opts) else {
            break;
        };
        stages.push(round_of(&next));
        if next.rms >= fit.rms {
            break;
        }
        fit = next;
        unfinished = !last;
    }
    if unfinished {
        fit = finish_rounds(fit, opts, side);
    }
    fit.times = first_times;
    fit.times.refine_ms = ms_since(t);
    fit.refinement = stages;
    fit
}

/// `fit`'s remaining foot-point rounds: the rounds run again from its controls and foot
/// points on the same control mesh (every patch taken over) with all of `opts.rounds`;
/// `fit` itself when that fails or does not lower the RMS.
fn finish_rounds(fit: ObjectFit, opts: &ObjectOptions, side: &DataSide) -> ObjectFit {
    let start = FitStart {
        warm: Some(fit.controls.clone()),
        previous: Some(&fit.surface),
        ..FitStart::new(
            fit.control_mesh(),
            fit.surface.crease_edges(),
            fit.params.clone(),
        )
    };
    let finished = fit_from(side, start, opts);
    match finished {
        Ok(mut next) if next.rms < fit.rms => {
            let mut rounds = fit.rounds;
            rounds.extend(next.rounds.drain(1..));
            next.rounds = rounds;
            next.simplified = fit.simplified;
            next
        }
        _ => fit,
    }
}

/// The options of a fit that only shows where to refine.
fn intermediate(opts: &ObjectOptions) -> ObjectOptions {
    ObjectOptions {
        rounds: opts.rounds.min(opts.refine.intermediate_rounds),
        ..opts.clone()
    }
}
