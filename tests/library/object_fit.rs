//! Whole objects: control meshes by simplification and the Loop limit surface fitted to
//! every data point (`pipeline::object`), on a generated torus and the shared models.

use crate::shared_mesh;
use glam::DVec3;
use std::time::Instant;
use trispline::fit::Budget;
use trispline::mesh::distance::MeshDistance;
use trispline::mesh::simplify::baseline::decimation_baselines;
use trispline::mesh::simplify::SurfaceTopology;
use trispline::pipeline::object::{
    extend_over_new_ground, farthest_from_data, fit_object, refit_where_changed, NotExtended,
    ObjectFit, ObjectOptions, PreviousFit, RoundStop, CURVATURE_FLOOR,
};
use trispline::surface::loop_limit::LoopLimitSurface;
use trispline::surface::{SurfaceParam, TriSurface};
use trispline::TriMesh;

const MAJOR: f64 = 1.0;
const MINOR: f64 = 0.35;

/// A torus sampled on an `n x m` grid, each quad split along alternating diagonals.
fn torus(n: usize, m: usize) -> TriMesh {
    let mut positions = Vec::new();
    for i in 0..n {
        for j in 0..m {
            let a = std::f64::consts::TAU * i as f64 / n as f64;
            let b = std::f64::consts::TAU * (j as f64 + 0.5 * (i % 2) as f64) / m as f64;
            let rad = MAJOR + MINOR * b.cos();
            positions.push(DVec3::new(rad * a.cos(), rad * a.sin(), MINOR * b.sin()));
        }
    }
    let at = |i: usize, j: usize| ((i % n) * m + j % m) as u32;
    let mut triangles = Vec::new();
    for i in 0..n {
        for j in 0..m {
            if i % 2 == 0 {
                triangles.push([at(i, j), at(i + 1, j), at(i, j + 1)]);
                triangles.push([at(i + 1, j), at(i + 1, j + 1), at(i, j + 1)]);
            } else {
                triangles.push([at(i, j), at(i + 1, j + 1), at(i, j + 1)]);
                triangles.push([at(i, j), at(i + 1, j), at(i + 1, j + 1)]);
            }
        }
    }
    TriMesh::new(positions, triangles)
}

fn distance_to_torus(p: DVec3) -> f64 {
    ((p.x.hypot(p.y) - MAJOR).hypot(p.z) - MINOR).abs()
}

/// RMS of the data's distances to a quadric decimation of the data with as many vertices
/// as the fit has controls (the mesh a user would otherwise keep): the better of the
/// decimations with and without the simplification's triangle-quality guard.
fn decimated_rms(fit: &ObjectFit) -> f64 {
    decimation_baselines(&fit.component, fit.controls.len())
        .into_iter()
        .map(|decimated| {
            let decimated = decimated.expect("decimated");
            let md = MeshDistance::new(&decimated.mesh);
            let sum: f64 = fit
                .data
                .iter()
                .map(|p| md.distance(*p).unwrap_or(f64::MAX).powi(2))
                .sum();
            (sum / fit.data.len() as f64).sqrt()
        })
        .fold(f64::INFINITY, f64::min)
}

/// RMS distance from the data vertices to a tessellation of the fitted surface with
/// `k` segments per control face edge: the measure of the quality goal, independent of
/// the fit's own foot points (Newton can stop in a local minimum farther than the
/// surface's nearest point).
fn tessellation_rms(fit: &ObjectFit, k: usize) -> f64 {
    let evaluate = fit.surface.evaluator(&fit.controls);
    let index = |i: usize, j: usize| (j * (2 * k + 3 - j) / 2 + i) as u32;
    let mut positions = Vec::new();
    let mut triangles = Vec::new();
    for face in 0..fit.surface.domain_face_count() as u32 {
        let base = positions.len() as u32;
        for j in 0..=k {
            for i in 0..=k - j {
                let (u, v) = (i as f64 / k as f64, j as f64 / k as f64);
                positions.push(evaluate(SurfaceParam { face, u, v }).position);
            }
        }
        for j in 0..k {
            for i in 0..k - j {
                triangles.push([index(i, j), index(i + 1, j), index(i, j + 1)].map(|c| base + c));
                if i + j + 1 < k {
                    let upper = [index(i + 1, j), index(i + 1, j + 1), index(i, j + 1)];
                    triangles.push(upper.map(|c| base + c));
                }
            }
        }
    }
    let tessellation = TriMesh::new(positions, triangles);
    let nearest = MeshDistance::new(&tessellation);
    let sum: f64 = fit
        .data
        .iter()
        .map(|p| nearest.distance(*p).unwrap_or(f64::MAX).powi(2))
        .sum();
    (sum / fit.data.len() as f64).sqrt()
}

fn assert_topology_kept(fit: &ObjectFit) {
    assert_eq!(fit.control_topology, fit.data_topology);
    let t = SurfaceTopology::of(&fit.control_mesh()).expect("manifold control mesh");
    assert_eq!(t, fit.control_topology);
}

#[test]
fn a_torus_is_fitted_by_a_genus_one_control_mesh() {
    let mesh = torus(96, 40);
    let fit = fit_object(&mesh, &ObjectOptions::default()).expect("fitted");
    assert_topology_kept(&fit);
    assert_eq!(fit.control_topology.genus, 1);
    assert_eq!(fit.control_topology.boundary_loops, 0);
    assert!(fit.controls.len() <= mesh.positions.len() / 20);
    // The limit surface at the foot points, measured against the analytic torus.
    let evaluate = fit.surface.evaluator(&fit.controls);
    let analytic: Vec<f64> = fit
        .params
        .iter()
        .map(|p| distance_to_torus(evaluate(*p).position))
        .collect();
    let rms = (analytic.iter().map(|d| d * d).sum::<f64>() / analytic.len() as f64).sqrt();
    let max = analytic.iter().fold(0.0f64, |m, d| m.max(*d));
    eprintln!(
        "torus: {} controls, fit rms {:.2e} max {:.2e}, analytic rms {rms:.2e} max {max:.2e}, decimated rms {:.2e}, rounds {:?}",
        fit.controls.len(),
        fit.rms,
        fit.max,
        decimated_rms(&fit),
        fit.rounds
    );
    // Measured: analytic RMS 3.5e-4, max 1.5e-3; the decimated mesh 7.8e-3.
    assert!(rms < 6e-4 * MAJOR, "analytic rms {rms}");
    assert!(max < 3e-3 * MAJOR, "analytic max {max}");
    assert!(fit.rms < 0.1 * decimated_rms(&fit));
    assert_rounds_lower_the_rms(&fit);
}

/// The order a file lists a mesh in is not part of the object: the same torus with its
/// vertices permuted and its faces reversed in order, each with its corners rotated, is
/// fitted to the same surface to the last bit (the fit renumbers its data spatially).
#[test]
fn the_order_a_file_lists_the_mesh_in_does_not_change_the_fit() {
    let mesh = torus(40, 16);
    let n = mesh.positions.len();
    // A permutation (7919 is prime to n = 640) and its inverse.
    let new_of_old: Vec<u32> = (0..n).map(|i| ((i * 7919) % n) as u32).collect();
    let mut positions = vec![DVec3::ZERO; n];
    for (old, &new) in new_of_old.iter().enumerate() {
        positions[new as usize] = mesh.positions[old];
    }
    let triangles = mesh
        .triangles
        .iter()
        .rev()
        .enumerate()
        .map(|(k, t)| {
            let t = t.map(|v| new_of_old[v as usize]);
            [t[k % 3], t[(k + 1) % 3], t[(k + 2) % 3]]
        })
        .collect();
    let shuffled = TriMesh::new(positions, triangles);
    let a = fit_object(&mesh, &ObjectOptions::default()).expect("fitted");
    let b = fit_object(&shuffled, &ObjectOptions::default()).expect("fitted shuffled");
    assert!(a.controls.len() > 10);
    assert_eq!(a.controls, b.controls);
    assert_eq!(a.rms, b.rms);
}

/// With `curvature_floor` the rounds minimise the squared distance with its curvature
/// term (SDM): on the torus the surface slides freely where the constant tangential share
/// held it back, and the same rounds end nearer the data and the analytic surface
/// (measured: RMS 2.07e-4 against 3.14e-4, 192 controls and 16 rounds each).
#[test]
fn the_curvature_term_brings_the_rounds_nearer_than_a_constant_share() {
    let mesh = torus(96, 40);
    let analytic_rms = |fit: &ObjectFit| {
        let evaluate = fit.surface.evaluator(&fit.controls);
        let sum: f64 = fit
            .params
            .iter()
            .map(|p| distance_to_torus(evaluate(*p).position).powi(2))
            .sum();
        (sum / fit.params.len() as f64).sqrt()
    };
    let sdm = fit_object(
        &mesh,
        &ObjectOptions {
            curvature_floor: Some(CURVATURE_FLOOR),
            ..Default::default()
        },
    )
    .expect("fitted");
    let constant = fit_object(&mesh, &ObjectOptions::default()).expect("fitted");
    eprintln!(
        "torus: curvature term rms {:.3e} (analytic {:.3e}, {} controls, {} rounds), constant share rms {:.3e} (analytic {:.3e}, {} controls, {} rounds)",
        sdm.rms,
        analytic_rms(&sdm),
        sdm.controls.len(),
        sdm.rounds.len(),
        constant.rms,
        analytic_rms(&constant),
        constant.controls.len(),
        constant.rounds.len(),
    );
    assert!(sdm.controls.len() <= constant.controls.len());
    assert!(sdm.rms < constant.rms);
    assert!(analytic_rms(&sdm) < analytic_rms(&constant));
}

/// A round is taken when it lowers the two-sided RMS (the data's distances and the
/// surface samples'), so the data's alone may rise a little in a round that pulls a patch
/// back onto the data (the outlier torus: 0.2 % once), never much, and fall overall.
fn assert_rounds_lower_the_rms(fit: &ObjectFit) {
    let r = &fit.rounds;
    assert!(r.windows(2).all(|w| w[1].rms < 1.01 * w[0].rms), "{r:?}");
    assert!(r.len() < 2 || r[r.len() - 1].rms < r[0].rms, "{r:?}");
}

#[test]
fn isolated_points_beyond_the_tolerance_end_refinement_and_the_rounds_run_on() {
    // One vertex pushed 0.1 off the torus: the only point a tolerance of 0.02 leaves
    // beyond. Splitting an edge under it would buy a whole refit for one outlier.
    let mut mesh = torus(96, 40);
    let outlier = 1000;
    let at = mesh.positions[outlier];
    mesh.positions[outlier] = at * (1.0 + 0.1 / at.length());
    // The surface's bump towards the spike strays from the spike's thin cone of data, so
    // the stray repair would split there (3 rounds, 4 controls); it is tested elsewhere,
    // this is the error-driven refinement's rule.
    let mut opts = ObjectOptions {
        max_stray_share: None,
        ..Default::default()
    };
    opts.refine.tolerance = Some(0.02);
    let fit = fit_object(&mesh, &opts).expect("fitted");
    eprintln!(
        "outlier: refinement {:?}, rounds {:?}",
        fit.refinement, fit.rounds
    );
    let first = fit.refinement[0];
    assert!((1..=3).contains(&first.beyond), "beyond: {}", first.beyond);
    assert_eq!(fit.refinement.len(), 1, "no refinement round ran");
    assert_eq!(fit.controls.len(), first.controls);
    // The fit before refinement ran only the intermediate rounds; the rest ran after.
    assert!(fit.rounds.len() > opts.refine.intermediate_rounds + 1);
    assert!(fit.rms < first.rms);
    assert_rounds_lower_the_rms(&fit);
}

#[test]
fn the_rounds_and_the_refinement_stop_where_the_budget_holds_or_time_is_up() {
    let mesh = torus(96, 40);
    let free = fit_object(&mesh, &ObjectOptions::default()).expect("fitted");
    // A max-error target the rounds reach part way (the free fit's own history meets it),
    // so the stop must end them there: fewer rounds, no more controls.
    let target = free.rounds[free.rounds.len() / 2].max;
    let budget = Budget {
        tolerance: target,
        max_error: Some(target),
        ..Budget::default()
    };
    let opts = ObjectOptions {
        stop: RoundStop {
            budget: Some(budget),
            deadline: None,
        },
        ..ObjectOptions::default()
    };
    let stopped = fit_object(&mesh, &opts).expect("fitted");
    eprintln!(
        "budget stop at max {target:.3e}: {} rounds (free {}), {} controls (free {}), max {:.3e}",
        stopped.rounds.len(),
        free.rounds.len(),
        stopped.controls.len(),
        free.controls.len(),
        stopped.max
    );
    assert!(stopped.max <= target, "max {} over {target}", stopped.max);
    assert!(stopped.rounds.len() < free.rounds.len());
    assert!(stopped.controls.len() <= free.controls.len());
    // A deadline already past: no round and no refinement after the first fit.
    let late = ObjectOptions {
        stop: RoundStop {
            budget: None,
            deadline: Some(Instant::now()),
        },
        ..ObjectOptions::default()
    };
    let capped = fit_object(&mesh, &late).expect("fitted");
    assert_eq!(capped.rounds.len(), 1, "rounds {:?}", capped.rounds);
    assert_eq!(capped.refinement.len(), 1);
    assert!(capped.rms > free.rms);
}

/// A new version refitted locally stops as a whole fit does: with the deadline already
/// past only its first round runs (a whole fit's first fit runs too) and neither further
/// rounds nor refinement; without one they take the bump in further. Taking over the
/// previous surface's quadtrees changes nothing in the result.
#[test]
fn a_local_refit_takes_no_round_once_time_is_up() {
    let fit = fit_object(&torus(96, 40), &ObjectOptions::default()).expect("fitted");
    let mut bumped = fit.component.clone();
    for p in bumped
        .positions
        .iter_mut()
        .filter(|p| p.x > 1.1 && p.y.abs() < 0.3)
    {
        let ring = DVec3::new(p.x, p.y, 0.0).normalize() * MAJOR;
        *p += (*p - ring).normalize() * 20.0 * fit.rms;
    }
    let refit = |opts: &ObjectOptions, reusing: Option<&LoopLimitSurface>| {
        let control_mesh = fit.control_mesh();
        let previous = PreviousFit {
            control_mesh: &control_mesh,
            crease_edges: fit.surface.crease_edges(),
            rms: fit.rms,
            surface: reusing,
        };
        refit_where_changed(
            bumped.clone(),
            previous,
            fit.params.clone(),
            &fit.data,
            opts,
        )
        .expect("refits")
        .expect("a local change")
    };
    let free = refit(&ObjectOptions::default(), None);
    let reusing = refit(&ObjectOptions::default(), Some(&fit.surface));
    assert_eq!(reusing.controls, free.controls);
    assert_eq!(reusing.distances, free.distances);
    let late = refit(
        &ObjectOptions {
            stop: RoundStop {
                budget: None,
                deadline: Some(Instant::now()),
            },
            ..ObjectOptions::default()
        },
        None,
    );
    eprintln!(
        "local refit: {} rounds, {} controls, rms {:.3e}; past deadline: {} rounds, {} controls, rms {:.3e}",
        free.rounds.len(),
        free.controls.len(),
        free.rms,
        late.rounds.len(),
        late.controls.len(),
        late.rms
    );
    // The rounds' history starts with the previous surface's entry.
    assert!(free.rounds.len() > 2, "{:?}", free.rounds);
    assert_eq!(late.rounds.len(), 2, "{:?}", late.rounds);
    assert_eq!(late.controls.len(), fit.controls.len());
    assert!(late.rms > free.rms);
}

/// New ground the previous control mesh has no rim beside (a patch of a closed object
/// marked new) cannot be joined: the refusal says which seams failed and why, and how many
/// new points their parts hold.
#[test]
fn new_ground_away_from_any_rim_is_refused_with_its_reason() {
    let fit = fit_object(&torus(96, 40), &ObjectOptions::default()).expect("fitted");
    let is_new: Vec<bool> = fit
        .component
        .positions
        .iter()
        .map(|p| p.x > 1.1 && p.y.abs() < 0.3)
        .collect();
    let new_points = is_new.iter().filter(|&&b| b).count();
    let control_mesh = fit.control_mesh();
    let previous = PreviousFit {
        control_mesh: &control_mesh,
        crease_edges: fit.surface.crease_edges(),
        rms: fit.rms,
        surface: Some(&fit.surface),
    };
    let extended = extend_over_new_ground(
        fit.component.clone(),
        previous,
        fit.params.clone(),
        &fit.data,
        &is_new,
        &ObjectOptions::default(),
    )
    .expect("no error");
    let Err(why) = extended else {
        panic!("extended over ground no rim joins");
    };
    assert_eq!(
        why,
        NotExtended::Unjoined {
            seams: 1,
            missed: vec![("too far from the previous rim", 1)],
            demoted: new_points,
            new_points,
        }
    );
    let text = why.to_string();
    assert!(
        text.contains("1 of 1 seams") && text.contains(&format!("{new_points} of {new_points}")),
        "{text}"
    );
}

#[test]
fn fertility_keeps_genus_four() {
    let Some(mesh) = shared_mesh("models/fertility.off") else {
        return;
    };
    let fit = fit_object(&mesh, &ObjectOptions::default()).expect("fitted");
    assert_topology_kept(&fit);
    assert_eq!(fit.control_topology.genus, 4);
    let diag = mesh.bounds_diagonal();
    eprintln!(
        "fertility: {} controls, rms {:.2e} max {:.2e} (diag {diag:.3}), decimated rms {:.2e}",
        fit.controls.len(),
        fit.rms,
        fit.max,
        decimated_rms(&fit)
    );
    assert!(fit.rms < 1e-3 * diag);
    assert!(fit.rms < 0.5 * decimated_rms(&fit));
}

/// fertility at 2 % controls (90) webs across its handles: the surface strays about 1.2 %
/// of the diagonal from the data, past what the stray repair's tenth more controls mend.
/// A plain decimation of 90 vertices strays as far, so the budget cannot hold the shape:
/// the object is fitted again from scratch at twice the controls the first fit spent
/// (99 with the stray repair's), which stays within 0.5 %, and that fit is kept.
#[test]
fn a_budget_too_small_for_the_shape_grows_until_the_surface_stays_on_the_data() {
    let Some(mesh) = shared_mesh("models/fertility.off") else {
        return;
    };
    let opts = ObjectOptions {
        target_controls_pct: 2.0,
        ..ObjectOptions::default()
    };
    let fit = fit_object(&mesh, &opts).expect("fitted");
    assert_topology_kept(&fit);
    assert_eq!(fit.control_topology.genus, 4);
    let diag = fit.component.bounds_diagonal();
    let budgets = &fit.stray_budgets;
    eprintln!(
        "fertility at 2 %: {} controls, rms {:.3e}, stray {:.3} % of the diagonal, tried {budgets:?}",
        fit.controls.len(),
        fit.rms,
        100.0 * farthest_from_data(&fit, 8) / diag,
    );
    let asked = (0.02 * fit.data.len() as f64).round() as usize;
    assert_eq!(budgets[0].target, asked);
    assert!(budgets[0].stray > 5e-3 * diag, "the case no longer strays");
    let kept = budgets.last().expect("an escalation");
    // Twice the controls the first fit spent (its stray repair adds a few to the budget).
    assert_eq!(kept.target, 2 * budgets[0].controls, "{budgets:?}");
    assert!(budgets[0].controls >= asked);
    assert!(kept.kept);
    assert_eq!(fit.controls.len(), kept.controls);
    assert!(kept.stray <= 5e-3 * diag);
    // The fit's own measure, and a finer lattice than the repair's, agree.
    assert_eq!(fit.stray, Some(kept.stray));
    assert!(farthest_from_data(&fit, 8) <= 5.5e-3 * diag);
    assert!(fit.rms < budgets[0].rms);
    assert!(fit.times.stray_budget_ms > 0.0);
}

/// The broken bunny at 5 % (445 points, 22 controls asked) spends 28 controls on its 19
/// holes and strays 7.4 % of its diagonal. Each step fits it again at twice the controls
/// the fit before spent (56, not twice the 22 asked, a budget already passed), each
/// strays less, and the steps run out before one is within the bound: the least straying
/// fit is kept, and flagged.
#[test]
fn an_escalation_that_never_comes_within_the_bound_keeps_the_least_straying_fit() {
    let Some(mesh) = shared_mesh("models/bun_zipper_res4.ply") else {
        return;
    };
    // The smooth fits' escalation is the subject: at 248 controls for 445 points the
    // faceted candidate (`object_faceted`) is nearer still and would replace the kept fit.
    let opts = ObjectOptions {
        faceted_candidate: false,
        ..ObjectOptions::default()
    };
    let fit = fit_object(&mesh, &opts).expect("fitted");
    let diag = fit.component.bounds_diagonal();
    let budgets = &fit.stray_budgets;
    eprintln!("res4: {} controls, tried {budgets:?}", fit.controls.len());
    assert!(budgets.len() >= 3, "{budgets:?}");
    assert!(budgets[0].controls > budgets[0].target, "{budgets:?}");
    for pair in budgets.windows(2) {
        assert_eq!(pair[1].target, (2 * pair[0].controls).min(fit.data.len()));
        assert!(pair[1].stray < pair[0].stray, "{budgets:?}");
    }
    assert!(budgets.iter().all(|b| b.stray > 5e-3 * diag));
    let kept: Vec<_> = budgets.iter().filter(|b| b.kept).collect();
    assert_eq!(kept.len(), 1, "{budgets:?}");
    let least = budgets
        .iter()
        .map(|b| b.stray)
        .fold(f64::INFINITY, f64::min);
    assert_eq!(kept[0].stray, least);
    assert_eq!(fit.stray, Some(least));
    assert_eq!(fit.controls.len(), kept[0].controls);
    assert!(fit.rms < budgets[0].rms);
}

#[test]
fn bun_zipper_keeps_its_five_holes() {
    let Some(mesh) = shared_mesh("models/bun_zipper.ply") else {
        return;
    };
    let fit = fit_object(&mesh, &ObjectOptions::default()).expect("fitted");
    assert_topology_kept(&fit);
    assert_eq!(fit.control_topology.boundary_loops, 5);
    assert_eq!(fit.control_topology.genus, 0);
    let diag = fit.component.bounds_diagonal();
    let stray = farthest_from_data(&fit, 6);
    eprintln!(
        "bun_zipper: {} controls, rms {:.2e} max {:.2e}, decimated rms {:.2e}, stray {:.2e} of diag {diag:.3}, times {:?}, layout {:?}, refinement {:?}",
        fit.controls.len(),
        fit.rms,
        fit.max,
        decimated_rms(&fit),
        stray,
        fit.times,
        fit.layout,
        fit.refinement,
    );
    // Measured before layout and refinement: 62 um against the decimated control mesh's
    // 127 um; max 0.67 mm.
    assert!(fit.rms < 8e-5, "rms {} m", fit.rms);
    assert!(fit.max < 2e-3, "max {} m", fit.max);
    assert!(fit.rms < 0.6 * decimated_rms(&fit));
    assert!(fit.controls.len() <= mesh.positions.len() / 20 + 1);
    // No bulge over the holes: the shown surface stays near the data everywhere.
    assert!(stray <= 5e-3 * diag, "stray {stray} of diagonal {diag}");
}

/// decimated-max is closed, and a decimation's large flat triangles leave a smooth
/// surface of 5 % controls 0.83 % of the diagonal off them between their corners (the
/// data-to-surface error cannot see it). The stray repair splits the faces that stray and
/// refits the controls around them, a few controls past the budget, until the surface is
/// within 0.5 % (measured: 0.45 % at 278 controls for 264, RMS 0.417 against 0.429).
#[test]
fn decimated_max_stays_closed_and_within_half_a_percent_of_its_data() {
    let Some(mesh) = shared_mesh("models/decimated-max.obj") else {
        return;
    };
    let fit = fit_object(&mesh, &ObjectOptions::default()).expect("fitted");
    assert_topology_kept(&fit);
    assert_eq!(fit.control_topology.boundary_loops, 0);
    let diag = fit.component.bounds_diagonal();
    // Measured on a finer lattice than the repair's (6 segments per edge).
    let stray = farthest_from_data(&fit, 8);
    let unrepaired = fit_object(
        &mesh,
        &ObjectOptions {
            max_stray_share: None,
            ..Default::default()
        },
    )
    .expect("fitted");
    let stray_before = farthest_from_data(&unrepaired, 8);
    let target = unrepaired.controls.len();
    eprintln!(
        "decimated-max: {} controls (budget {target}), rms {:.2e} max {:.2e} (diag {diag:.3}), \
         decimated rms {:.2e}, stray {:.3} % of diag (without the repair {:.3} %, rms {:.2e}), \
         refinement {:?}",
        fit.controls.len(),
        fit.rms,
        fit.max,
        decimated_rms(&fit),
        100.0 * stray / diag,
        100.0 * stray_before / diag,
        unrepaired.rms,
        fit.refinement
    );
    assert!(fit.rms < 2e-3 * diag);
    assert!(
        stray_before > 5e-3 * diag,
        "the case no longer needs a repair"
    );
    assert!(stray <= 5e-3 * diag, "stray {stray} of diagonal {diag}");
    assert!(fit.refinement.iter().any(|r| r.stray_repair));
    assert!(fit.controls.len() > target);
    assert!(fit.controls.len() as f64 <= 1.1 * target as f64 + 1.0);
    assert!(fit.rms <= unrepaired.rms);
    assert_eq!(fit.stray.map(|s| s <= 5e-3 * diag), Some(true));
}

/// camelhead's surface ran 0.58 % of the diagonal past its sparse rim, at boundary controls
/// of 3-4 neighbours whose faces held 1-4 feet: the boundary curve there was held by the
/// few rim points alone. With the boundary curve sampled it stays within 0.5 %.
#[test]
fn camelhead_stays_on_its_sparse_rim() {
    let Some(mesh) = shared_mesh("models/camelhead.off") else {
        return;
    };
    let fit = fit_object(&mesh, &ObjectOptions::default()).expect("fitted");
    assert_topology_kept(&fit);
    assert_eq!(fit.control_topology.boundary_loops, 1);
    let diag = fit.component.bounds_diagonal();
    let stray = farthest_from_data(&fit, 6);
    eprintln!(
        "camelhead: {} controls, rms {:.3e}, decimated rms {:.3e}, stray {:.3} % of diag",
        fit.controls.len(),
        fit.rms,
        decimated_rms(&fit),
        100.0 * stray / diag
    );
    assert!(fit.rms < 0.25 * decimated_rms(&fit));
    assert!(stray <= 5e-3 * diag, "stray {stray} of diagonal {diag}");
}

#[test]
fn a_broken_bunny_is_cleaned_and_fitted() {
    let Some(mesh) = shared_mesh("models/bun_zipper_res4.ply") else {
        return;
    };
    // The fit at the budget asked: the stray escalation takes it to 248 controls (see
    // `an_escalation_that_never_comes_within_the_bound_keeps_the_least_straying_fit`),
    // where a decimation of as many of the 445 points is nearly the data (RMS 7.6e-4
    // against the surface's 5.3e-4 to its tessellation).
    let opts = ObjectOptions {
        stray_budget_steps: 0,
        ..ObjectOptions::default()
    };
    let fit = fit_object(&mesh, &opts).expect("fitted");
    assert_topology_kept(&fit);
    let diag = mesh.bounds_diagonal();
    assert!(fit.distances.iter().all(|d| d.is_finite()));
    // 445 vertices: 5 % is a couple of dozen controls (its holes keep more: 28), so only
    // a coarse fit, but one far nearer the data than the decimated mesh of as many
    // vertices. (Its sharp edges are a fragmented net, no crease: tagged, they took the
    // control mesh to 53 vertices, and the ratio to the decimated mesh was 0.55.)
    let (tessellated, decimated) = (tessellation_rms(&fit, 8), decimated_rms(&fit));
    eprintln!(
        "res4: {} points, {} controls, rms {:.2e} (diag {diag:.3}), to the tessellation \
         {tessellated:.2e}, decimated rms {decimated:.2e}",
        fit.data.len(),
        fit.controls.len(),
        fit.rms,
    );
    assert!(fit.rms < 3e-2 * diag, "rms {} of diag {diag}", fit.rms);
    assert!(
        tessellated < 0.5 * decimated,
        "{tessellated} vs {decimated}"
    );
}

/// With 40 % controls the broken bunny's first point fit bulges where its control faces
/// hold no data point (17.7 % of the diagonal); the rounds' surface-to-data samples pull
/// that back only when a round is judged by both sides of the distance, not by the data
/// points' distances alone, which such a round raises a little.
#[test]
fn rounds_pull_a_bulge_back_onto_the_data() {
    let Some(mesh) = shared_mesh("models/bun_zipper_res4.ply") else {
        return;
    };
    let opts = ObjectOptions {
        target_controls_pct: 40.0,
        ..ObjectOptions::default()
    };
    let fit = fit_object(&mesh, &opts).expect("fitted");
    let diag = mesh.bounds_diagonal();
    let stray = farthest_from_data(&fit, 4);
    eprintln!(
        "res4 at 40 %: {} controls, rms {:.2e}, stray {:.2} % of the diagonal",
        fit.controls.len(),
        fit.rms,
        100.0 * stray / diag
    );
    assert!(stray < 0.05 * diag, "stray {stray} of diag {diag}");
}
